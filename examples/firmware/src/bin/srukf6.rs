//! Filter-only firmware: the 6-state square-root UKF over Lu's recorded fixes, each fix on
//! both axes (`estim_firmware::minimal`).
#![no_std]
#![no_main]

estim_firmware::minimal!(srukf, prior6, process6, gps6, |fix| {
    estim_core::nalgebra::Vector4::new(fix[0], fix[1], fix[0], fix[1])
});
