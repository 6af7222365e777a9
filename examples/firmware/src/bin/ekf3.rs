//! Filter-only firmware: the 3-state EKF over Lu's recorded fixes (`estim_firmware::minimal`).
#![no_std]
#![no_main]

estim_firmware::minimal!(ekf, prior3, process3, gps3, |fix| {
    estim_core::nalgebra::Vector2::from(*fix)
});
