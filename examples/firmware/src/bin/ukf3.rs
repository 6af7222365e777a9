//! Filter-only firmware: the 3-state UKF over Lu's recorded fixes (`estim_firmware::minimal`).
#![no_std]
#![no_main]

estim_firmware::minimal!(ukf, prior3, process3, gps3, |fix| {
    estim_core::nalgebra::Vector2::from(*fix)
});
