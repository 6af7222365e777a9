//! Internal, not public API (hidden from the docs; estim-filters uses it): the dense kernels
//! behind every filter step, namely products into a destination ([`mul`] and its kin, module
//! `product`), the Cholesky factor in place and triangular solves (module `cholesky`). Three
//! routes, chosen from the dimension types and sizes (`D::try_to_usize()` and the static sizes
//! fold at compile time):
//!
//! - **Small static sizes** (every dimension a `Const<N>`, the largest ≤
//!   [`STATIC_NALGEBRA_MAX`]): nalgebra's fixed-size code on the stack. Nothing is faster for
//!   small matrices, and nothing allocates.
//! - **Small runtime sizes** (at most [`SMALL_RUNTIME_WORK`] multiply–adds, or a Cholesky
//!   factor of order ≤ [`SMALL_RUNTIME_CHOLESKY`]): plain loops over the column-major storage
//!   (module `loops`, our left-looking Cholesky, nalgebra's triangular solve). faer's per-call
//!   set-up costs more than such an operation's arithmetic (60 % of the `Dyn` KF step at n = 2
//!   before this route). The same loops serve every runtime size without the `dense` feature.
//! - **Larger runtime sizes** (any dimension `Dyn`) and larger static sizes, with the `dense`
//!   feature: faer's products, over zero-copy views of the same column-major storage, writing
//!   into the destination (one-column products: our `Matvec` sweep). Static sizes take this
//!   route above [`STATIC_NALGEBRA_MAX`]: nalgebra's fixed-size products are not blocked and
//!   lose to faer's there.
//! - **Cholesky**: faer's for runtime sizes above [`SMALL_RUNTIME_CHOLESKY`] (its scratch lives
//!   in a [`CholeskyScratch`] the caller keeps, so nothing allocates after the first use), our
//!   inlined left-looking loop for static sizes up to 16 and small runtime sizes.
//!
//! The faer route runs on the dense backend (`crate::dense`): faer, reached through [`Real`]'s
//! sealed supertrait, compiled once for `f32` and once for `f64` in this crate, and
//! single-threaded unless the `parallel` feature is on *and* the operation is at least
//! [`PARALLEL_THRESHOLD`] on its smallest side.
//!
//! Without the `dense` feature there is no faer: static sizes take nalgebra's fixed-size code
//! whatever their size, runtime sizes (with `std`) the loops. Without `std`
//! [`Alloc`](crate::Alloc) holds for static sizes only, so the loops are never reached.
//!
//! All shapes must agree (the callers check model outputs first); a mismatch here is a
//! programmer error and panics.

use nalgebra::{DefaultAllocator, Dim, OMatrix, allocator::Allocator};

use crate::scalar::Real;

mod cholesky;
mod loops;
mod product;
#[cfg(all(test, feature = "dense"))]
mod tests;

pub use crate::dense::{Accum, PARALLEL_THRESHOLD};
pub use cholesky::{
    CholeskyScratch, cholesky_in_place, solve_lower_in_place, solve_right_lower_in_place,
    solve_right_lower_transpose_in_place,
};
pub use product::{mul, mul_lower, mul_tr, mul_tr_lower};

/// dst ← src, one `memcpy` of the contiguous storage (nalgebra's `copy_from` copies element by
/// element through generic indexing, measurably slower on the small static filter steps).
/// The shapes must agree.
#[cfg_attr(not(debug_assertions), inline(always))]
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
/// operation would (with `dense`; without it, nalgebra always). nalgebra's fixed-size products
/// are unrolled, not blocked, and lose to faer's from n ≈ 12 (BENCHMARKS.md, "Static or
/// dynamic").
pub const STATIC_NALGEBRA_MAX: usize = 8;

/// Runtime-size products (and triangular solves) of at most this many multiply–adds run plain
/// loops (module `loops`) instead of faer, whose per-call set-up costs about as many
/// instructions as that much scalar arithmetic (≈ 250 per call; the loops run without AVX,
/// faer's kernels with it, so beyond this faer wins). Measured: BENCHMARKS.md, "Runtime-size
/// steps at small n".
pub const SMALL_RUNTIME_WORK: usize = 64;

/// Runtime-size Cholesky factors up to this order run our left-looking loop instead of faer's.
pub const SMALL_RUNTIME_CHOLESKY: usize = 8;

/// Whether an operation whose dimensions are all static (`fixed`) and whose largest dimension
/// is `size` runs nalgebra's fixed-size code ([`STATIC_NALGEBRA_MAX`]); folded by the compiler
/// for static sizes.
#[cfg_attr(not(debug_assertions), inline(always))]
fn fixed_route(fixed: bool, size: usize) -> bool {
    fixed && (!cfg!(feature = "dense") || lean_routes() || size <= STATIC_NALGEBRA_MAX)
}

/// Whether a runtime-size operation of `work` multiply–adds runs faer (above
/// [`SMALL_RUNTIME_WORK`]) rather than the loops.
#[cfg(feature = "dense")]
#[cfg_attr(not(debug_assertions), inline(always))]
fn dense_route(work: usize) -> bool {
    work > SMALL_RUNTIME_WORK && !lean_routes()
}

// The kernels' own tests set this on their thread to run every operation on the routes a
// build without `dense` takes (static sizes on nalgebra's fixed-size code, runtime sizes on
// the loops), so that the one test build checks both (`tests::on_both_routes`).
#[cfg(all(test, feature = "dense"))]
std::thread_local! {
    static LEAN_ROUTES: core::cell::Cell<bool> = const { core::cell::Cell::new(false) };
}

/// Whether this operation takes the routes of a build without `dense` whatever the sizes:
/// never, outside the kernels' tests (a constant `false`, folded away).
#[cfg_attr(not(debug_assertions), inline(always))]
fn lean_routes() -> bool {
    #[cfg(all(test, feature = "dense"))]
    return LEAN_ROUTES.with(core::cell::Cell::get);
    #[cfg(not(all(test, feature = "dense")))]
    false
}

/// `true` when `D` is a compile-time dimension.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn is_static<D: Dim>() -> bool {
    D::try_to_usize().is_some()
}
