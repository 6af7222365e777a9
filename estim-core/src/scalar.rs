//! The scalar type.

use nalgebra::RealField;

/// A real scalar: `f32` or `f64` (anything that is a `nalgebra::RealField` and `Copy`).
pub trait Real: RealField + Copy {}

impl<T: RealField + Copy> Real for T {}

/// Converts an `f64` constant into `T` (exact for `f64`, rounded for `f32`).
#[inline]
pub fn real<T: Real>(x: f64) -> T {
    nalgebra::convert(x)
}
