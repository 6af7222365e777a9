//! Internal, not public API (hidden from the docs; estim-filters uses it): the dense kernels
//! behind every filter step, namely products into a destination ([`mul`] and its kin, module
//! `product`), the Cholesky factor in place and triangular solves (module `cholesky`). Two
//! routes, chosen from the dimension types and sizes (`D::try_to_usize()` and the static sizes
//! fold at compile time):
//!
//! - **Small static sizes** (every dimension a `Const<N>`, the largest ≤
//!   [`STATIC_NALGEBRA_MAX`]): nalgebra's fixed-size code on the stack. Nothing is faster for
//!   small matrices, and nothing allocates.
//! - **Runtime sizes** (any dimension `Dyn`) and larger static sizes: faer's products, over
//!   zero-copy views of the same column-major storage, writing into the destination
//!   (one-column products: our `Matvec` sweep). Static sizes take this route above
//!   [`STATIC_NALGEBRA_MAX`]: nalgebra's fixed-size products are not blocked and lose to
//!   faer's there.
//! - **Cholesky**: faer's for runtime sizes (its scratch lives in a [`CholeskyScratch`] the
//!   caller keeps, so nothing allocates after the first use), our inlined left-looking loop for
//!   static sizes of every size (no scratch: a static-size step allocates nothing).
//!
//! The runtime route runs on the dense backend (`crate::dense`): faer, reached through
//! [`Real`]'s sealed supertrait, compiled once for `f32` and once for `f64` in this crate, and
//! single-threaded unless the `parallel` feature is on *and* the operation is at least
//! [`PARALLEL_THRESHOLD`] on its smallest side.
//!
//! Without the `std` feature there is no faer and [`Alloc`](crate::Alloc) holds for static
//! sizes only, so every call takes the static route whatever its size; the runtime branches
//! fall back to generic loops (correct, unoptimised) that estim then never reaches.
//!
//! All shapes must agree (the callers check model outputs first); a mismatch here is a
//! programmer error and panics.

#[cfg(feature = "std")]
use faer::{MatMut, MatRef};
use nalgebra::{DefaultAllocator, Dim, OMatrix, allocator::Allocator};

use crate::scalar::Real;

mod cholesky;
mod product;
#[cfg(test)]
mod tests;

pub use crate::dense::{Accum, PARALLEL_THRESHOLD};
pub use cholesky::{
    CholeskyScratch, cholesky_in_place, solve_lower_in_place, solve_right_lower_in_place,
    solve_right_lower_transpose_in_place,
};
// Unused since the model traits lost their batch sigma-point hooks; kept for its tests.
#[cfg(test)]
pub(crate) use product::mul_into_column;
pub use product::{mul, mul_lower, mul_tr, mul_tr_lower};

/// dst ← src, one `memcpy` of the contiguous storage (nalgebra's `copy_from` copies element by
/// element through generic indexing, measurably slower on the small static filter steps).
/// The shapes must agree.
#[inline(always)]
#[track_caller]
pub fn copy<T: Real, R: Dim, C: Dim>(dst: &mut OMatrix<T, R, C>, src: &OMatrix<T, R, C>)
where
    DefaultAllocator: Allocator<R, C>,
{
    assert_eq!(dst.shape(), src.shape(), "kernel::copy: shapes differ");
    dst.as_mut_slice().copy_from_slice(src.as_slice());
}

/// Static-size operations whose largest dimension is at most this run nalgebra's fixed-size
/// code; larger ones run the runtime-size kernels on views of the same storage, as a `Dyn`
/// operation would (with `std`; without it, nalgebra always). nalgebra's fixed-size products
/// are unrolled, not blocked, and lose to faer's from n ≈ 12 (BENCHMARKS.md, "Static or
/// dynamic").
pub const STATIC_NALGEBRA_MAX: usize = 8;

/// Whether an operation whose dimensions are all static (`fixed`) and whose largest dimension
/// is `size` runs nalgebra's fixed-size code ([`STATIC_NALGEBRA_MAX`]); folded by the compiler
/// for static sizes.
#[inline(always)]
fn fixed_route(fixed: bool, size: usize) -> bool {
    fixed && (!cfg!(feature = "std") || size <= STATIC_NALGEBRA_MAX)
}

/// `true` when `D` is a compile-time dimension.
#[inline(always)]
pub fn is_static<D: Dim>() -> bool {
    D::try_to_usize().is_some()
}

/// A faer view of the column-major storage of `m`.
#[cfg(feature = "std")]
#[inline(always)]
fn view<T: Real, R: Dim, C: Dim>(m: &OMatrix<T, R, C>) -> MatRef<'_, T>
where
    DefaultAllocator: Allocator<R, C>,
{
    MatRef::from_column_major_slice(m.as_slice(), m.nrows(), m.ncols())
}

/// A mutable faer view of the column-major storage of `m`.
#[cfg(feature = "std")]
#[inline(always)]
fn view_mut<T: Real, R: Dim, C: Dim>(m: &mut OMatrix<T, R, C>) -> MatMut<'_, T>
where
    DefaultAllocator: Allocator<R, C>,
{
    let (r, c) = m.shape();
    MatMut::from_column_major_slice_mut(m.as_mut_slice(), r, c)
}
