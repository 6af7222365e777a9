//! The scalar type.

use nalgebra::RealField;

/// A real scalar: `f32` or `f64`.
///
/// Sealed to these two. On runtime sizes (with the `dense` feature) the kernels run on faer
/// (products, Cholesky factor, triangular solves) or on our matrix × vector kernel, and the
/// sealed supertrait carries that code compiled once per scalar in this crate; a third type
/// would need its own kernels or a slower generic fallback that every crate compiles again.
/// Other number types a model may need (dual numbers for automatic derivatives, say) live
/// inside the model's evaluation, not in a filter's state.
pub trait Real: RealField + Copy + crate::dense::Dense {}

impl Real for f32 {}
impl Real for f64 {}

/// Converts an `f64` constant into `T` (exact for `f64`, rounded for `f32`).
#[inline]
pub fn real<T: Real>(x: f64) -> T {
    nalgebra::convert(x)
}
