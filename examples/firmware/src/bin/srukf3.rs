//! Filter-only firmware: the 3-state square-root UKF over Lu's recorded fixes (`estim_firmware::minimal`).
#![no_std]
#![no_main]

estim_firmware::minimal!(srukf, prior3, process3, gps3, |fix| {
    estim_core::nalgebra::Vector2::from(*fix)
});
