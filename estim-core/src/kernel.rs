//! Internal, not public API (hidden from the docs; estim-filters uses it): the dense kernels
//! behind every filter step, namely products into a destination, the Cholesky factor in place
//! and triangular solves. Two routes, chosen from the dimension types and sizes
//! (`D::try_to_usize()` and the static sizes fold at compile time):
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
//! faer is reached through [`Real`]'s sealed supertrait `Dense`, implemented once for `f32`
//! and once for `f64` here: faer's generic code is compiled in this crate only, not again in
//! every crate that calls a kernel. faer runs single-threaded (`Par::Seq`) unless the
//! `parallel` feature is on *and* the operation is at least [`PARALLEL_THRESHOLD`] on its
//! smallest side.
//!
//! Without the `std` feature there is no faer and [`Alloc`](crate::Alloc) holds for static
//! sizes only, so every call takes the static route whatever its size; the runtime branches
//! fall back to generic loops (correct, unoptimised) that estim then never reaches.
//!
//! All shapes must agree (the callers check model outputs first); a mismatch here is a
//! programmer error and panics.

#[cfg(feature = "std")]
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
#[cfg(feature = "std")]
use faer::linalg::cholesky::llt::factor::{LltRegularization, cholesky_in_place_scratch};
#[cfg(feature = "std")]
use faer::linalg::matmul::triangular::{self, BlockStructure};
#[cfg(feature = "std")]
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
#[cfg(feature = "std")]
use faer::{MatMut, MatRef, Par};
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, allocator::Allocator};

use crate::scalar::Real;

pub(crate) use sealed::Dense;

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

/// Whether a product overwrites its destination or adds to it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Accum {
    /// dst ← α op(a) op(b).
    Replace,
    /// dst ← dst + α op(a) op(b).
    Add,
}

/// With the `parallel` feature, faer's threads are used for a kernel whose smallest dimension
/// is at least this: below it thread start-up costs more than it saves (BENCHMARKS.md,
/// "Parallel threshold").
pub const PARALLEL_THRESHOLD: usize = 256;

/// Below this order a lower-triangle product ([`mul_lower`]) is faer's full product, faster
/// there than its triangular-destination kernel (`a294f26`: KF step at n = 12 14 % faster, EKF
/// 10 %, UKF 6 %).
#[cfg(feature = "std")]
const LOWER_TRIANGLE_MIN: usize = 32;

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

/// faer's parallelism for an operation whose smallest dimension is `size`.
#[cfg(feature = "std")]
#[inline(always)]
fn par(size: usize) -> Par {
    #[cfg(feature = "parallel")]
    if size >= PARALLEL_THRESHOLD {
        return Par::rayon(0);
    }
    let _ = size;
    Par::Seq
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

mod sealed {
    #[cfg(feature = "std")]
    use super::*;

    /// Without std (no faer): only the seal of [`Real`](crate::Real) to `f32` and `f64`.
    #[cfg(not(feature = "std"))]
    pub trait Dense: Sized {}
    #[cfg(not(feature = "std"))]
    impl Dense for f32 {}
    #[cfg(not(feature = "std"))]
    impl Dense for f64 {}

    /// faer's runtime-size operations for one scalar type: the supertrait that seals
    /// [`Real`] to `f32` and `f64`. Non-generic methods, so faer's generic code is compiled
    /// once, here (each integration test used to carry its own copy; `d3eba7e` halved the
    /// build of the two largest test binaries).
    #[cfg(feature = "std")]
    pub trait Dense: Sized {
        /// dst (+)= α A B, only the lower triangle of the (square) dst if `lower`.
        fn matmul(
            dst: MatMut<'_, Self>,
            accum: Accum,
            alpha: Self,
            a: MatRef<'_, Self>,
            b: MatRef<'_, Self>,
            lower: bool,
        );

        /// y (+)= α A x, A column-major with `y.len()` rows and `x.len()` columns ([`Matvec`]).
        fn matvec(y: &mut [Self], accum: Accum, alpha: Self, a: &[Self], x: &[Self]);

        /// The lower Cholesky factor of `a` in place; `false` if not positive definite.
        fn cholesky(a: MatMut<'_, Self>, stack: &mut MemStack) -> bool;

        /// The scratch [`cholesky`](Self::cholesky) needs at order `dim`.
        fn cholesky_scratch(dim: usize) -> StackReq;

        /// rhs ← L⁻¹ rhs, or L⁻ᵀ rhs with `transpose` (L the lower triangle of `l`).
        fn solve_lower(l: MatRef<'_, Self>, rhs: MatMut<'_, Self>, transpose: bool);
    }

    #[cfg(feature = "std")]
    macro_rules! dense {
        ($($t:ty),*) => {$(
            impl Dense for $t {
                fn matmul(
                    dst: MatMut<'_, $t>,
                    accum: Accum,
                    alpha: $t,
                    a: MatRef<'_, $t>,
                    b: MatRef<'_, $t>,
                    lower: bool,
                ) {
                    let size = dst.nrows().min(dst.ncols()).min(a.ncols());
                    let accum = match accum {
                        Accum::Replace => faer::Accum::Replace,
                        Accum::Add => faer::Accum::Add,
                    };
                    if lower && size >= LOWER_TRIANGLE_MIN {
                        let full = BlockStructure::Rectangular;
                        let tri = BlockStructure::TriangularLower;
                        triangular::matmul(dst, tri, accum, a, full, b, full, alpha, par(size));
                    } else {
                        faer::linalg::matmul::matmul(dst, accum, a, b, alpha, par(size));
                    }
                }

                fn matvec(y: &mut [$t], accum: Accum, alpha: $t, a: &[$t], x: &[$t]) {
                    assert_eq!(a.len(), y.len() * x.len(), "matrix × vector: shapes differ");
                    pulp::Arch::new().dispatch(Matvec { y, accum, alpha, a, x });
                }

                fn cholesky(a: MatMut<'_, $t>, stack: &mut MemStack) -> bool {
                    let par = par(a.nrows());
                    let regularization = LltRegularization::default();
                    faer::linalg::cholesky::llt::factor::cholesky_in_place(
                        a,
                        regularization,
                        par,
                        stack,
                        Default::default(),
                    )
                    .is_ok()
                }

                fn cholesky_scratch(dim: usize) -> StackReq {
                    cholesky_in_place_scratch::<$t>(dim, par(dim), Default::default())
                }

                fn solve_lower(l: MatRef<'_, $t>, rhs: MatMut<'_, $t>, transpose: bool) {
                    let par = par(l.nrows().min(rhs.ncols()));
                    if transpose {
                        solve_upper_triangular_in_place(l.transpose(), rhs, par);
                    } else {
                        solve_lower_triangular_in_place(l, rhs, par);
                    }
                }
            }
        )*};
    }

    #[cfg(feature = "std")]
    dense!(f32, f64);
}

/// y (+)= α A x on runtime sizes, A column-major: rows in panels of up to 4 SIMD vectors held
/// in registers across all the columns, y_P ← (y_P +) (Σ_even a_Pj (αxⱼ) + Σ_odd a_Pj (αxⱼ)),
/// each sum a chain of fused multiply–adds (two chains hide their latency). The last
/// `rows mod lanes` rows are one whole vector ending at the last row (one row at a time below
/// one vector). Compiled for the CPU's widest SIMD by pulp's runtime dispatch (AVX2 at most:
/// pulp's `x86-v4` is off), so the last bits depend on the instruction set. Our own kernel
/// because faer's product costs 2–3× for one column: the UKF step at n = 50 is 24 % faster
/// with it (BENCHMARKS.md, "Runtime-size kernels of our own").
#[cfg(feature = "std")]
struct Matvec<'a, T> {
    y: &'a mut [T],
    accum: Accum,
    alpha: T,
    a: &'a [T],
    x: &'a [T],
}

#[cfg(feature = "std")]
macro_rules! matvec {
    ($t:ty, $ts:ident, $splat:ident, $fma:ident, $add:ident, $as_simd:ident, $as_mut:ident) => {
        impl Matvec<'_, $t> {
            /// (y (+)) α A x on the V vectors of rows from `start`.
            #[inline(always)]
            fn sums<S: pulp::Simd, const V: usize>(&self, simd: S, start: usize) -> [S::$ts; V] {
                let (rows, end) = (
                    self.y.len(),
                    start + V * size_of::<S::$ts>() / size_of::<$t>(),
                );
                let zero = simd.$splat(0.0);
                let (mut even, mut odd) = ([zero; V], [zero; V]);
                let mut columns = self.a.chunks_exact(rows).zip(self.x);
                while let Some((c0, &x0)) = columns.next() {
                    let s0 = simd.$splat(self.alpha * x0);
                    for (acc, &v) in even.iter_mut().zip(S::$as_simd(&c0[start..end]).0) {
                        *acc = simd.$fma(v, s0, *acc);
                    }
                    let Some((c1, &x1)) = columns.next() else {
                        break;
                    };
                    let s1 = simd.$splat(self.alpha * x1);
                    for (acc, &v) in odd.iter_mut().zip(S::$as_simd(&c1[start..end]).0) {
                        *acc = simd.$fma(v, s1, *acc);
                    }
                }
                let y = S::$as_simd(&self.y[start..end]).0;
                for ((e, &d), &yi) in even.iter_mut().zip(&odd).zip(y) {
                    *e = simd.$add(*e, d);
                    if self.accum == Accum::Add {
                        *e = simd.$add(yi, *e);
                    }
                }
                even
            }

            /// Rows of y from `start`, V vectors of them, ← (y +) α A x.
            #[inline(always)]
            fn panel<S: pulp::Simd, const V: usize>(&mut self, simd: S, start: usize) -> usize {
                let sums = self.sums::<S, V>(simd, start);
                let end = start + V * size_of::<S::$ts>() / size_of::<$t>();
                S::$as_mut(&mut self.y[start..end]).0.copy_from_slice(&sums);
                end
            }
        }

        impl pulp::WithSimd for Matvec<'_, $t> {
            type Output = ();

            #[inline(always)]
            fn with_simd<S: pulp::Simd>(mut self, simd: S) {
                let (rows, lanes) = (self.y.len(), size_of::<S::$ts>() / size_of::<$t>());
                let vectors = rows / lanes;
                // The last rows mod lanes rows: a whole vector ending at the last row, computed
                // before the panels overwrite the y it reads and stored after them (the rows it
                // shares with the last panel get the same bits). No closure: a closure would not
                // get the SIMD target features pulp compiles this function with.
                let last = if vectors > 0 && rows % lanes != 0 {
                    Some(self.sums::<S, 1>(simd, rows - lanes))
                } else {
                    None
                };
                let mut start = 0;
                for _ in 0..vectors / 4 {
                    start = self.panel::<S, 4>(simd, start);
                }
                match vectors % 4 {
                    3 => self.panel::<S, 3>(simd, start),
                    2 => self.panel::<S, 2>(simd, start),
                    1 => self.panel::<S, 1>(simd, start),
                    _ => 0,
                };
                if let Some([v]) = last {
                    S::$as_mut(&mut self.y[rows - lanes..]).0[0] = v;
                    return;
                }
                // Fewer rows than lanes: one at a time.
                for i in vectors * lanes..rows {
                    let mut sum: $t = 0.0;
                    for (column, &xj) in self.a.chunks_exact(rows).zip(self.x) {
                        sum += column[i] * (self.alpha * xj);
                    }
                    let yi = &mut self.y[i];
                    *yi = match self.accum {
                        Accum::Add => *yi + sum,
                        Accum::Replace => sum,
                    };
                }
            }
        }
    };
}

#[cfg(feature = "std")]
matvec!(
    f64,
    f64s,
    splat_f64s,
    mul_add_e_f64s,
    add_f64s,
    as_simd_f64s,
    as_mut_simd_f64s
);
#[cfg(feature = "std")]
matvec!(
    f32,
    f32s,
    splat_f32s,
    mul_add_e_f32s,
    add_f32s,
    as_simd_f32s,
    as_mut_simd_f32s
);

/// dst (+)= α op(a) op(b) on runtime sizes, op a transpose where asked; only the lower
/// triangle of dst if `lower`. One-column products without transposes go to [`Matvec`], the
/// rest to faer.
#[cfg(feature = "std")]
#[inline(always)]
#[track_caller]
#[allow(clippy::too_many_arguments)]
fn runtime_product<T, R, C, RA, CA, RB, CB>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, RA, CA>,
    transpose_a: bool,
    b: &OMatrix<T, RB, CB>,
    transpose_b: bool,
    lower: bool,
) where
    T: Real,
    R: Dim,
    C: Dim,
    RA: Dim,
    CA: Dim,
    RB: Dim,
    CB: Dim,
    DefaultAllocator: Allocator<R, C> + Allocator<RA, CA> + Allocator<RB, CB>,
{
    if dst.ncols() == 1 && !(transpose_a || transpose_b || lower) {
        assert!(
            a.shape() == (dst.nrows(), b.nrows()) && b.ncols() == 1,
            "matrix × vector: {:?} ← {:?} × {:?}",
            dst.shape(),
            a.shape(),
            b.shape()
        );
        return T::matvec(dst.as_mut_slice(), accum, alpha, a.as_slice(), b.as_slice());
    }
    let (a, b) = (view(a), view(b));
    let a = if transpose_a { a.transpose() } else { a };
    let b = if transpose_b { b.transpose() } else { b };
    T::matmul(view_mut(dst), accum, alpha, a, b, lower);
}

/// [`runtime_product`] without faer (no `std`): one dot product per entry, generic over the
/// dimensions. Unreached by estim without std (its bounds admit static sizes only); there so
/// that the kernels keep one body for both builds.
#[cfg(not(feature = "std"))]
#[track_caller]
#[allow(clippy::too_many_arguments)]
fn runtime_product<T, R, C, RA, CA, RB, CB>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, RA, CA>,
    transpose_a: bool,
    b: &OMatrix<T, RB, CB>,
    transpose_b: bool,
    lower: bool,
) where
    T: Real,
    R: Dim,
    C: Dim,
    RA: Dim,
    CA: Dim,
    RB: Dim,
    CB: Dim,
    DefaultAllocator: Allocator<R, C> + Allocator<RA, CA> + Allocator<RB, CB>,
{
    let _ = lower;
    let at = |i: usize, k: usize| if transpose_a { a[(k, i)] } else { a[(i, k)] };
    let bt = |k: usize, j: usize| if transpose_b { b[(j, k)] } else { b[(k, j)] };
    let inner = if transpose_a { a.nrows() } else { a.ncols() };
    let (rows, cols) = dst.shape();
    assert!(
        (if transpose_a { a.ncols() } else { a.nrows() }) == rows
            && (if transpose_b { b.nrows() } else { b.ncols() }) == cols
            && (if transpose_b { b.ncols() } else { b.nrows() }) == inner,
        "kernel product: shapes differ"
    );
    for j in 0..cols {
        for i in 0..rows {
            let sum = (0..inner).fold(T::zero(), |sum, k| sum + at(i, k) * bt(k, j));
            let d = &mut dst[(i, j)];
            *d = match accum {
                Accum::Add => *d + alpha * sum,
                Accum::Replace => alpha * sum,
            };
        }
    }
}

/// Writes or adds α · `value` into `dst` (static sizes), skipping the scaling when α = 1.
#[inline(always)]
fn store<T: Real, R: Dim, C: Dim>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    value: OMatrix<T, R, C>,
) where
    DefaultAllocator: Allocator<R, C>,
{
    let value = if alpha == T::one() {
        value
    } else {
        value * alpha
    };
    match accum {
        Accum::Replace => *dst = value,
        Accum::Add => *dst += value,
    }
}

/// dst (+)= α a b.
#[inline(always)]
#[track_caller]
pub fn mul<T, R, K, C>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, R, K>,
    b: &OMatrix<T, K, C>,
) where
    T: Real,
    R: Dim,
    K: Dim,
    C: Dim,
    DefaultAllocator: Allocator<R, C> + Allocator<R, K> + Allocator<K, C>,
{
    let fixed = is_static::<R>() && is_static::<K>() && is_static::<C>();
    if fixed_route(fixed, a.nrows().max(a.ncols()).max(b.ncols())) {
        store(dst, accum, alpha, a * b);
    } else {
        runtime_product(dst, accum, alpha, a, false, b, false, false);
    }
}

/// dst (+)= α a bᵀ.
#[inline(always)]
#[track_caller]
pub fn mul_tr<T, R, K, C>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, R, K>,
    b: &OMatrix<T, C, K>,
) where
    T: Real,
    R: Dim,
    K: Dim,
    C: Dim,
    DefaultAllocator: Allocator<R, C> + Allocator<R, K> + Allocator<C, K> + Allocator<K, C>,
{
    let fixed = is_static::<R>() && is_static::<K>() && is_static::<C>();
    if fixed_route(fixed, a.nrows().max(a.ncols()).max(b.nrows())) {
        // The operator form: for small static sizes it unrolls, where nalgebra's generic
        // `gemm` loops column by column (measured: the filters bench).
        store(dst, accum, alpha, a * b.transpose());
    } else {
        runtime_product(dst, accum, alpha, a, false, b, true, false);
    }
}

/// The lower triangle (diagonal included) of dst (+)= α a b, for a product known to be
/// symmetric (such as J (C Jᵀ)): on runtime sizes only that triangle is computed, about half
/// the work. The strict upper triangle of `dst` is unspecified afterwards (static sizes compute
/// the whole product, which is cheaper than selecting a triangle there); mirror the lower
/// triangle ([`crate::linalg::mirror_lower_checked`]) before using it.
#[inline(always)]
#[track_caller]
pub fn mul_lower<T, D, K>(
    dst: &mut OMatrix<T, D, D>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, D, K>,
    b: &OMatrix<T, K, D>,
) where
    T: Real,
    D: Dim,
    K: Dim,
    DefaultAllocator: Allocator<D, D> + Allocator<D, K> + Allocator<K, D>,
{
    let fixed = is_static::<D>() && is_static::<K>();
    if fixed_route(fixed, a.nrows().max(a.ncols())) {
        store(dst, accum, alpha, a * b);
    } else {
        runtime_product(dst, accum, alpha, a, false, b, false, true);
    }
}

/// The lower triangle of dst (+)= α a bᵀ (see [`mul_lower`]; e.g. w D Dᵀ or (K S) Kᵀ).
#[inline(always)]
#[track_caller]
pub fn mul_tr_lower<T, D, K>(
    dst: &mut OMatrix<T, D, D>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, D, K>,
    b: &OMatrix<T, D, K>,
) where
    T: Real,
    D: Dim,
    K: Dim,
    DefaultAllocator: Allocator<D, D> + Allocator<D, K> + Allocator<K, D>,
{
    let fixed = is_static::<D>() && is_static::<K>();
    if fixed_route(fixed, a.nrows().max(a.ncols())) {
        store(dst, accum, alpha, a * b.transpose());
    } else {
        runtime_product(dst, accum, alpha, a, false, b, true, true);
    }
}

/// Column `column` of `dst` (+)= α A x: [`Matvec`] on runtime sizes, one dot product per row
/// on static sizes.
///
/// # Panics
/// If the shapes do not agree or `column` is out of range (a programmer error).
#[track_caller]
pub(crate) fn mul_into_column<T: Real, R: Dim, C: Dim, RA: Dim, CA: Dim, RX: Dim>(
    dst: &mut OMatrix<T, R, C>,
    column: usize,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, RA, CA>,
    x: &OVector<T, RX>,
) where
    DefaultAllocator: Allocator<R, C> + Allocator<RA, CA> + Allocator<RX>,
{
    let rows = dst.nrows();
    assert!(
        column < dst.ncols() && a.shape() == (rows, x.nrows()),
        "mul_into_column: column {column} of {:?} ← {:?} × {:?}",
        dst.shape(),
        a.shape(),
        x.shape()
    );
    #[cfg(feature = "std")]
    {
        let fixed = is_static::<R>() && is_static::<RA>() && is_static::<CA>();
        let size = rows.max(x.nrows());
        if !fixed_route(fixed, size) {
            let y = &mut dst.as_mut_slice()[column * rows..(column + 1) * rows];
            return T::matvec(y, accum, alpha, a.as_slice(), x.as_slice());
        }
    }
    column_by_dot_products(dst, column, accum, alpha, a, x);
}

/// [`mul_into_column`] on static sizes: one dot product per row.
fn column_by_dot_products<T: Real, R: Dim, C: Dim, RA: Dim, CA: Dim, RX: Dim>(
    dst: &mut OMatrix<T, R, C>,
    column: usize,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, RA, CA>,
    x: &OVector<T, RX>,
) where
    DefaultAllocator: Allocator<R, C> + Allocator<RA, CA> + Allocator<RX>,
{
    for i in 0..dst.nrows() {
        let sum = (0..x.nrows()).fold(T::zero(), |sum, j| sum + a[(i, j)] * x[j]);
        let d = &mut dst[(i, column)];
        *d = match accum {
            Accum::Add => *d + alpha * sum,
            Accum::Replace => alpha * sum,
        };
    }
}

/// Scratch memory for [`cholesky_in_place`]'s faer route (runtime sizes), grown on first use
/// for a dimension and reused after (static sizes never touch it).
#[derive(Default)]
pub struct CholeskyScratch {
    #[cfg(feature = "std")]
    buffer: Option<MemBuffer>,
    capacity: usize,
}

impl core::fmt::Debug for CholeskyScratch {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("CholeskyScratch")
            .field("capacity", &self.capacity)
            .finish()
    }
}

#[cfg(feature = "std")]
impl CholeskyScratch {
    /// Room for factorising `dim × dim` matrices of `T`.
    fn stack<T: Real>(&mut self, dim: usize) -> &mut MemStack {
        let req = T::cholesky_scratch(dim);
        let bytes = req.size_bytes();
        if self.capacity < bytes {
            self.buffer = None;
            self.capacity = bytes;
        }
        MemStack::new(self.buffer.get_or_insert_with(|| MemBuffer::new(req)))
    }
}

/// Replaces the lower triangle of the symmetric positive definite `a` by its Cholesky factor L
/// (a = L Lᵀ): faer's for runtime sizes (scratch from `scratch`) and for static sizes above 16
/// with `std` (scratch on the stack: a static-size step's buffers are locals, and allocating
/// there at every call is what static sizes promise not to do); our inlined left-looking loop
/// for static sizes up to 16 (`left_looking_cholesky`, the same factor to round-off). The
/// strict upper
/// triangle is left unspecified. `false` if `a` is not (numerically) positive definite or not
/// finite, and then `a` is unspecified. (A covariance that may be only semi-definite goes to
/// [`crate::linalg::psd_factor`] instead.)
#[inline(always)]
pub fn cholesky_in_place<T: Real, D: Dim>(
    a: &mut OMatrix<T, D, D>,
    scratch: &mut CholeskyScratch,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let _ = &scratch;
    #[cfg(feature = "std")]
    if !is_static::<D>() {
        let n = a.nrows();
        let ok = T::cholesky(view_mut(a), scratch.stack::<T>(n));
        // faer leaves NaN pivots unreported on some paths; a factor must be finite.
        return ok && (0..n).all(|i| a[(i, i)].is_finite());
    }
    #[cfg(feature = "std")]
    if a.nrows() > FAER_STATIC_CHOLESKY_MIN
        && let Some(ok) = static_faer_cholesky(a)
    {
        return ok;
    }
    left_looking_cholesky(a)
}

/// Static sizes above this factorise by faer's blocked Cholesky (with the `std` feature),
/// up to it by the register-resident [`left_looking_cholesky`].
#[cfg(feature = "std")]
const FAER_STATIC_CHOLESKY_MIN: usize = 16;

/// Bytes of stack a static-size factorisation lends faer's Cholesky (which needs n floats):
/// enough up to n ≈ 500 in f64.
#[cfg(feature = "std")]
const STATIC_CHOLESKY_STACK: usize = 4096;

/// faer's blocked Cholesky for a static size, its scratch on the stack (so nothing is
/// allocated); `None` if the scratch would not fit in [`STATIC_CHOLESKY_STACK`].
#[cfg(feature = "std")]
#[inline(never)]
fn static_faer_cholesky<T: Real, D: Dim>(a: &mut OMatrix<T, D, D>) -> Option<bool>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = a.nrows();
    let req = T::cholesky_scratch(n);
    if req.size_bytes() + req.align_bytes() > STATIC_CHOLESKY_STACK {
        return None;
    }
    let mut buffer = [core::mem::MaybeUninit::<u8>::uninit(); STATIC_CHOLESKY_STACK];
    let ok = T::cholesky(view_mut(a), MemStack::new(&mut buffer));
    Some(ok && (0..n).all(|i| a[(i, i)].is_finite()))
}

/// [`cholesky_in_place`] for static sizes: column j of L from the finished columns, lᵢⱼ = (aᵢⱼ − Σₖ₍ⱼ lᵢₖ lⱼₖ) /
/// lⱼⱼ, each sum in a register, in place (column j reads only the original column j and the
/// finished columns before it). The operations and order of [`crate::linalg::psd_factor`]'s
/// loop, so a positive definite matrix gets the same bits from both, without its tolerance,
/// pivoting and closures. Inlined, it replaced nalgebra's out-of-line `Cholesky::new` (with
/// its copies in and out): the KF 3/2 step 933 → 908 instructions, the UKF 6/4 step 14,671 →
/// 14,600 (commit `b1972b9`). `false` at a pivot that is not finite and
/// > 0.
#[inline(always)]
fn left_looking_cholesky<T: Real, D: Dim>(a: &mut OMatrix<T, D, D>) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = a.nrows();
    for j in 0..n {
        let d = (0..j).fold(a[(j, j)], |d, k| d - a[(j, k)] * a[(j, k)]);
        if !(d > T::zero() && d.is_finite()) {
            return false;
        }
        let ljj = d.sqrt();
        a[(j, j)] = ljj;
        for i in (j + 1)..n {
            let s = (0..j).fold(a[(i, j)], |s, k| s - a[(i, k)] * a[(j, k)]);
            a[(i, j)] = s / ljj;
        }
    }
    true
}

/// Solves L X = B in place (`b` ← L⁻¹ b) with L the lower triangle of `l` (its diagonal nonzero,
/// as after a successful [`cholesky_in_place`]).
#[inline(always)]
pub fn solve_lower_in_place<T: Real, D: Dim, C: Dim>(l: &OMatrix<T, D, D>, b: &mut OMatrix<T, D, C>)
where
    DefaultAllocator: Allocator<D, D> + Allocator<D, C>,
{
    #[cfg(feature = "std")]
    {
        let size = b.nrows().max(b.ncols());
        if !fixed_route(is_static::<D>() && is_static::<C>(), size) {
            return T::solve_lower(view(l), view_mut(b), false);
        }
    }
    l.solve_lower_triangular_unchecked_mut(b);
}

/// Solves X Lᵀ = B in place (`b` ← B L⁻ᵀ) with L the lower triangle of `l`: the first half of
/// a gain K = Pₓᵤ S⁻¹ = Pₓᵤ L⁻ᵀ L⁻¹, solved in K's own n × m storage (no transposed copy).
/// Runtime sizes: faer's left solve on the transposed view, (B L⁻ᵀ)ᵀ = L⁻¹ Bᵀ.
#[inline(always)]
pub fn solve_right_lower_transpose_in_place<T: Real, R: Dim, D: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, R, D>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    #[cfg(feature = "std")]
    {
        let size = b.nrows().max(b.ncols());
        if !fixed_route(is_static::<D>() && is_static::<R>(), size) {
            return T::solve_lower(view(l), view_mut(b).transpose_mut(), false);
        }
    }
    // Column j of X Lᵀ = B: Σₖ≤ⱼ Lⱼₖ X[:, k] = B[:, j], forward over the columns.
    let (rows, n) = b.shape();
    let b = b.as_mut_slice();
    for j in 0..n {
        let (done, rest) = b.split_at_mut(j * rows);
        let column = &mut rest[..rows];
        for k in 0..j {
            axpy(column, -l[(j, k)], &done[k * rows..(k + 1) * rows]);
        }
        scale(column, T::one() / l[(j, j)]);
    }
}

/// Solves X L = B in place (`b` ← B L⁻¹) with L the lower triangle of `l` (the second half of
/// the gain, see [`solve_right_lower_transpose_in_place`]; (B L⁻¹)ᵀ = L⁻ᵀ Bᵀ).
#[inline(always)]
pub fn solve_right_lower_in_place<T: Real, R: Dim, D: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, R, D>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    #[cfg(feature = "std")]
    {
        let size = b.nrows().max(b.ncols());
        if !fixed_route(is_static::<D>() && is_static::<R>(), size) {
            return T::solve_lower(view(l), view_mut(b).transpose_mut(), true);
        }
    }
    // Column j of X L = B: Σₖ≥ⱼ Lₖⱼ X[:, k] = B[:, j], backward over the columns.
    let (rows, n) = b.shape();
    let b = b.as_mut_slice();
    for j in (0..n).rev() {
        let (head, done) = b.split_at_mut((j + 1) * rows);
        let column = &mut head[j * rows..];
        for k in (j + 1)..n {
            let offset = (k - j - 1) * rows;
            axpy(column, -l[(k, j)], &done[offset..offset + rows]);
        }
        scale(column, T::one() / l[(j, j)]);
    }
}

/// y ← y + a x over two columns (slices of equal length).
#[inline(always)]
fn axpy<T: Real>(y: &mut [T], a: T, x: &[T]) {
    for (yi, &xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

/// y ← a y.
#[inline(always)]
fn scale<T: Real>(y: &mut [T], a: T) {
    for yi in y {
        *yi *= a;
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x2};

    fn spd(n: usize) -> DMatrix<f64> {
        let g = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 5) as f64 - 2.0);
        &g * g.transpose() + DMatrix::identity(n, n)
    }

    #[test]
    fn dynamic_products_match_nalgebra() {
        let a = DMatrix::from_fn(4, 3, |i, j| (i as f64) - 0.5 * j as f64);
        let b = DMatrix::from_fn(3, 5, |i, j| 1.0 + (i * j) as f64);
        let mut dst = DMatrix::from_element(4, 5, 1.0);
        mul(&mut dst, Accum::Add, 2.0, &a, &b);
        let expected = DMatrix::from_element(4, 5, 1.0) + 2.0 * &a * &b;
        assert!((dst - expected).amax() < 1e-12);

        let bt = b.transpose();
        let mut dst = DMatrix::zeros(4, 5);
        mul_tr(&mut dst, Accum::Replace, 1.0, &a, &bt);
        assert!((dst - &a * &b).amax() < 1e-12);
    }

    /// `Matvec` on one instruction set, as `kernel::mul` runs it on the best one.
    fn matvec_on<S: pulp::Simd>(
        simd: S,
        y: &mut [f64],
        accum: Accum,
        alpha: f64,
        a: &[f64],
        x: &[f64],
    ) {
        pulp::WithSimd::with_simd(
            Matvec {
                y,
                accum,
                alpha,
                a,
                x,
            },
            simd,
        );
    }

    /// The matrix–vector kernel against nalgebra's product, on the instruction set `mul`
    /// dispatches to and on scalar and AVX2 code if the CPU has it, on shapes around its panels
    /// (1–8 vectors and a remainder of rows, empty ones), both accumulations, α = 1 and not;
    /// the bound is the usual dot-product one, |error| ≤ k ε Σ |α aᵢⱼ xⱼ| (+ |y| ε for the
    /// accumulation). Also `mul_into_column` in f32 and its static-size path.
    #[test]
    fn matrix_vector_products_match_nalgebra_on_every_instruction_set() {
        let mut row_counts: Vec<usize> = (0..=9).collect();
        row_counts.extend([
            15, 16, 17, 31, 32, 33, 47, 63, 64, 65, 71, 130, 256, 263, 300,
        ]);
        for &rows in &row_counts {
            for cols in [0, 1, 2, 3, 4, 5, 9, 13] {
                let a = DMatrix::from_fn(rows, cols, |i, j| ((i * 5 + j * 3) as f64 * 0.7).sin());
                let x = DVector::from_fn(cols, |i, _| (i as f64 * 1.3).cos() * 1e3);
                let y0 = DVector::from_fn(rows, |i, _| 0.25 * i as f64 - 1.0);
                for (accum, alpha) in [(Accum::Replace, 1.0), (Accum::Add, -0.3)] {
                    let base = if accum == Accum::Add {
                        y0.clone()
                    } else {
                        y0.map(|_| 0.0)
                    };
                    let expected = &base + alpha * (&a * &x);
                    let scale = base.abs() + (alpha.abs() * a.abs() * x.abs());
                    let k = (cols + 2) as f64;
                    let check = |y: &DVector<f64>, set: &str| {
                        for i in 0..rows {
                            let bound = k * f64::EPSILON * scale[i];
                            assert!(
                                (y[i] - expected[i]).abs() <= bound,
                                "{set} {rows}×{cols} row {i}: {} vs {} bound {bound}",
                                y[i],
                                expected[i]
                            );
                        }
                    };
                    let mut y = y0.clone();
                    mul(&mut y, accum, alpha, &a, &x);
                    check(&y, "dispatched");
                    let (a_, x_) = (a.as_slice(), x.as_slice());
                    let mut y = y0.clone();
                    matvec_on(pulp::Scalar::new(), y.as_mut_slice(), accum, alpha, a_, x_);
                    check(&y, "scalar");
                    #[cfg(target_arch = "x86_64")]
                    if let Some(simd) = pulp::x86::V3::try_new() {
                        let mut y = y0.clone();
                        matvec_on(simd, y.as_mut_slice(), accum, alpha, a_, x_);
                        check(&y, "AVX2");
                    }
                    // The static-size path of mul_into_column (run here on f64).
                    let mut d = DMatrix::from_fn(rows, 2, |i, j| if j == 0 { y0[i] } else { 7.0 });
                    column_by_dot_products(&mut d, 0, accum, alpha, &a, &x);
                    check(&d.column(0).into_owned(), "dot products");
                    assert!(d.column(1).iter().all(|&v| v == 7.0));
                    // f32 through mul_into_column (column 1 of 3; the others untouched).
                    let (a32, x32) = (a.map(|v| v as f32), x.map(|v| v as f32));
                    let mut d =
                        DMatrix::from_fn(rows, 3, |i, j| if j == 1 { y0[i] as f32 } else { 7.0 });
                    mul_into_column(&mut d, 1, accum, alpha as f32, &a32, &x32);
                    for i in 0..rows {
                        let bound = 4.0 * k * f32::EPSILON as f64 * scale[i];
                        assert!(
                            (d[(i, 1)] as f64 - expected[i]).abs() <= bound,
                            "f32 {rows}×{cols} row {i}"
                        );
                        assert!(d[(i, 0)] == 7.0 && d[(i, 2)] == 7.0);
                    }
                }
            }
        }
    }

    #[test]
    fn cholesky_and_solves_agree_static_and_dynamic() {
        let s = spd(3);
        let b = DMatrix::from_fn(3, 2, |i, j| (i + 2 * j) as f64);
        let mut scratch = CholeskyScratch::default();

        let mut l = s.clone();
        assert!(cholesky_in_place(&mut l, &mut scratch));
        let mut x = b.clone();
        solve_lower_in_place(&l, &mut x);
        assert!((l.lower_triangle() * &x - &b).amax() < 1e-10);
        assert!((l.lower_triangle() * l.lower_triangle().transpose() - &s).amax() < 1e-10);

        let mut ls = Matrix3::from_iterator(s.iter().copied());
        assert!(cholesky_in_place(&mut ls, &mut scratch));
        let mut xs = Matrix3x2::from_iterator(b.iter().copied());
        solve_lower_in_place(&ls, &mut xs);
        for i in 0..3 {
            for j in 0..2 {
                assert!((xs[(i, j)] - x[(i, j)]).abs() < 1e-12);
            }
        }
    }

    /// The runtime-size Cholesky factor (faer's) on orders from 0 to past 96 (where our own
    /// column kernel used to hand over to faer's), f64 and f32: lower triangular with a positive
    /// diagonal, and a backward error within Higham's bound |L Lᵀ − A| ≤ γₙ₊₁ |L| |L|ᵀ
    /// (elementwise, γₖ = kε / (1 − kε)); a matrix that fails the pivot test at its first,
    /// middle or last column, or holds a NaN or infinity below the diagonal, is refused.
    #[test]
    fn cholesky_factors_have_a_small_backward_error() {
        let mut scratch = CholeskyScratch::default();
        let below = 96;
        for n in [
            0,
            1,
            2,
            3,
            4,
            5,
            7,
            8,
            9,
            17,
            33,
            50,
            below - 1,
            below,
            below + 5,
        ] {
            // A spread-out spectrum: eigenvalues of G Gᵀ / n plus 10⁻³.
            let g = DMatrix::from_fn(n, n, |i, j| ((i * 13 + j * 7) as f64 * 0.37).sin());
            let a = &g * g.transpose() / n.max(1) as f64 + DMatrix::identity(n, n) * 1e-3;
            let mut l = a.clone();
            assert!(cholesky_in_place(&mut l, &mut scratch), "n = {n}");
            let l = l.lower_triangle();
            let gamma = |eps: f64| (n + 1) as f64 * eps / (1.0 - (n + 1) as f64 * eps);
            let residual = &l * l.transpose() - &a;
            let scale = l.abs() * l.abs().transpose();
            for i in 0..n {
                assert!(l[(i, i)] > 0.0);
                for j in 0..n {
                    let bound = gamma(f64::EPSILON) * scale[(i, j)];
                    assert!(residual[(i, j)].abs() <= bound, "n = {n} ({i}, {j})");
                }
            }
            let a32 = a.map(|v| v as f32);
            let mut l32 = a32.clone();
            assert!(cholesky_in_place(&mut l32, &mut scratch), "f32 n = {n}");
            let l32 = l32.lower_triangle().map(f64::from);
            let residual = &l32 * l32.transpose() - a32.map(f64::from);
            let scale = l32.abs() * l32.abs().transpose();
            for (r, s) in residual.iter().zip(scale.iter()) {
                assert!(r.abs() <= gamma(f32::EPSILON as f64) * s, "f32 n = {n}");
            }
            if n < 2 {
                continue;
            }
            for k in [0, n / 2, n - 1] {
                // Pivot k non-positive: a_kk lowered to the sum of squares it must exceed.
                let mut bad = a.clone();
                bad[(k, k)] = l.row(k).columns(0, k).norm_squared() - 1e-3;
                assert!(
                    !cholesky_in_place(&mut bad, &mut scratch),
                    "n = {n} pivot {k}"
                );
            }
            for v in [f64::NAN, f64::INFINITY] {
                let mut bad = a.clone();
                bad[(n - 1, n / 2 - 1)] = v;
                assert!(!cholesky_in_place(&mut bad, &mut scratch), "n = {n} {v}");
            }
        }
    }

    #[test]
    fn lower_products_match_the_full_product_on_the_lower_triangle() {
        // Below and above LOWER_TRIANGLE_MIN: full product, triangular kernel.
        for n in [5, LOWER_TRIANGLE_MIN + 7] {
            lower_products_match_at(n);
        }
    }

    /// `mul_tr_lower` on orders around [`LOWER_TRIANGLE_MIN`] and beyond, k = 0, 1, 7, 50,
    /// both accumulations, f64 and f32, against nalgebra's full product on the lower
    /// triangle: |error| ≤ (k + 2) ε (|start| + |α| |A| |B|ᵀ).
    #[test]
    fn lower_triangle_products_match_nalgebra() {
        let orders = [
            15, 16, 17, 20, 23, 24, 25, 31, 32, 33, 47, 48, 49, 50, 55, 63, 64, 65, 100, 127, 128,
            129,
        ];
        for n in orders {
            for k in [0, 1, 7, 50] {
                let a = DMatrix::from_fn(n, k, |i, j| ((i * 3 + j * 5) as f64 * 0.61).sin());
                let b = DMatrix::from_fn(n, k, |i, j| ((i * 7 + j * 2) as f64 * 0.37).cos());
                let start = DMatrix::from_fn(n, n, |i, j| 0.5 * i as f64 - 0.25 * j as f64);
                for (accum, alpha) in [(Accum::Replace, 1.0), (Accum::Add, -0.7)] {
                    let base = match accum {
                        Accum::Replace => DMatrix::zeros(n, n),
                        Accum::Add => start.clone(),
                    };
                    let expected = &base + alpha * &a * b.transpose();
                    let scale = base.abs() + alpha.abs() * a.abs() * b.abs().transpose();
                    let check = |dst: &DMatrix<f64>, eps: f64, set: &str| {
                        for j in 0..n {
                            for i in j..n {
                                let bound = (k + 2) as f64 * eps * scale[(i, j)];
                                let error = (dst[(i, j)] - expected[(i, j)]).abs();
                                assert!(error <= bound, "{set} n = {n} k = {k} ({i}, {j})");
                            }
                        }
                    };
                    let mut dst = start.clone();
                    mul_tr_lower(&mut dst, accum, alpha, &a, &b);
                    check(&dst, f64::EPSILON, "mul_tr_lower");
                    // f32: the inputs rounded to f32 first, so the bound is in f32's ε.
                    let (a32, b32) = (a.map(|v| v as f32), b.map(|v| v as f32));
                    let mut dst32 = start.map(|v| v as f32);
                    mul_tr_lower(&mut dst32, accum, alpha as f32, &a32, &b32);
                    check(&dst32.map(f64::from), 2.0 * f32::EPSILON as f64, "f32");
                }
            }
        }
    }

    fn lower_products_match_at(n: usize) {
        let a = DMatrix::from_fn(n, 3, |i, j| (i as f64) - 0.7 * j as f64 + 0.1);
        let b = DMatrix::from_fn(3, n, |i, j| 1.0 + (i * j) as f64 - 0.3 * i as f64);
        let full = &a * &b;
        for accum in [Accum::Replace, Accum::Add] {
            let start = DMatrix::from_fn(n, n, |i, j| (i + 2 * j) as f64);
            let expected = match accum {
                Accum::Replace => 2.0 * &full,
                Accum::Add => &start + 2.0 * &full,
            };
            let mut dst = start.clone();
            mul_lower(&mut dst, accum, 2.0, &a, &b);
            let mut dst_tr = start.clone();
            mul_tr_lower(&mut dst_tr, accum, 2.0, &a, &b.transpose());
            // Each entry sums 3 products (plus the start value): a few ulps of the largest.
            let tol = 8.0 * f64::EPSILON * expected.amax();
            for j in 0..n {
                for i in j..n {
                    assert!(
                        (dst[(i, j)] - expected[(i, j)]).abs() <= tol,
                        "n = {n}, ({i}, {j})"
                    );
                    assert!(
                        (dst_tr[(i, j)] - expected[(i, j)]).abs() <= tol,
                        "n = {n}, ({i}, {j})"
                    );
                }
            }
        }
    }

    /// A static size above [`STATIC_NALGEBRA_MAX`] (12 × 12, 12 × 5) takes the runtime-size
    /// kernels on its own storage: products, the Cholesky factor and the solves agree with
    /// nalgebra's own fixed-size operators and `Cholesky` to round-off.
    #[test]
    fn large_static_sizes_match_nalgebra() {
        use nalgebra::{SMatrix, SVector};
        let a = SMatrix::<f64, 12, 12>::from_fn(|i, j| ((i * 5 + j * 3) as f64 * 0.7).sin());
        let b = SMatrix::<f64, 12, 5>::from_fn(|i, j| ((i * 2 + j * 7) as f64 * 0.3).cos());
        let s = a * a.transpose() + SMatrix::<f64, 12, 12>::identity();
        let mut dst = SMatrix::<f64, 12, 5>::from_element(1.0);
        mul(&mut dst, Accum::Add, 2.0, &a, &b);
        let expected = SMatrix::<f64, 12, 5>::from_element(1.0) + 2.0 * a * b;
        assert!((dst - expected).amax() < 1e-12);
        let mut aat = SMatrix::<f64, 12, 12>::zeros();
        mul_tr(&mut aat, Accum::Replace, 1.0, &a, &a);
        assert!((aat - a * a.transpose()).amax() < 1e-12);
        let mut x = SVector::<f64, 12>::zeros();
        let v = SVector::<f64, 12>::from_fn(|i, _| i as f64 - 5.5);
        mul(&mut x, Accum::Replace, 1.0, &a, &v);
        assert!((x - a * v).amax() < 1e-12);
        let mut l = s;
        let mut scratch = CholeskyScratch::default();
        assert!(cholesky_in_place(&mut l, &mut scratch));
        let reference = s.cholesky().expect("positive definite").unpack();
        assert!((l.lower_triangle() - reference).amax() < 1e-12);
        let mut y = b;
        solve_lower_in_place(&l, &mut y);
        assert!((reference * y - b).amax() < 1e-10);
        let mut bad = s;
        bad[(11, 11)] = -1.0;
        assert!(!cholesky_in_place(&mut bad, &mut scratch));
    }

    #[test]
    fn right_solves_agree_static_and_dynamic() {
        let s = spd(4);
        let b = DMatrix::from_fn(3, 4, |i, j| (i + 2 * j) as f64 - 1.5);
        let mut scratch = CholeskyScratch::default();
        let mut l = s.clone();
        assert!(cholesky_in_place(&mut l, &mut scratch));
        // B S⁻¹ = B L⁻ᵀ L⁻¹.
        let mut x = b.clone();
        solve_right_lower_transpose_in_place(&l, &mut x);
        solve_right_lower_in_place(&l, &mut x);
        assert!((&x * &s - &b).amax() < 1e-10);

        let ls = nalgebra::Matrix4::from_iterator(l.iter().copied());
        let mut xs = nalgebra::Matrix3x4::from_iterator(b.iter().copied());
        solve_right_lower_transpose_in_place(&ls, &mut xs);
        let mut half = b.clone();
        solve_right_lower_transpose_in_place(&l, &mut half);
        let lower = l.lower_triangle();
        assert!((&half * lower.transpose() - &b).amax() < 1e-10);
        solve_right_lower_in_place(&ls, &mut xs);
        for i in 0..3 {
            for j in 0..4 {
                assert!((xs[(i, j)] - x[(i, j)]).abs() < 1e-12);
            }
        }
    }

    /// A runtime-size matrix times a vector whose shapes disagree but whose entry counts
    /// match (4 × 6 times 4 into 6) panics, as every other product does, instead of running.
    #[test]
    #[should_panic(expected = "matrix × vector")]
    fn matrix_vector_shape_mismatch_panics() {
        let a = DMatrix::<f64>::zeros(4, 6);
        let x = DVector::<f64>::zeros(4);
        let mut y = DVector::<f64>::zeros(6);
        mul(&mut y, Accum::Replace, 1.0, &a, &x);
    }

    #[test]
    fn cholesky_rejects_indefinite_and_non_finite() {
        let mut scratch = CholeskyScratch::default();
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(!cholesky_in_place(&mut a, &mut scratch));
        let mut a = DMatrix::from_row_slice(2, 2, &[f64::NAN, 0.0, 0.0, 1.0]);
        assert!(!cholesky_in_place(&mut a, &mut scratch));
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, f64::NAN]);
        assert!(!cholesky_in_place(&mut a, &mut scratch));
    }

    /// Static sizes above 16 factorise by faer's Cholesky (scratch on the stack): the same
    /// factor as the inlined loop to round-off, with the same refusals; at 16 the loop's bits.
    #[test]
    fn large_static_cholesky_is_faers_and_agrees_with_the_loop() {
        use nalgebra::{Const, SMatrix};
        fn at<const N: usize>() {
            let g = SMatrix::<f64, N, N>::from_fn(|i, j| {
                (((i * 7 + j * 3) % 11) as f64 - 5.0) / 3.0 + 0.01 * (i * j) as f64
            });
            let spd = g * g.transpose() + SMatrix::<f64, N, N>::identity() * 1e-3;
            let mut scratch = CholeskyScratch::default();
            let (mut library, mut rows) = (spd, spd);
            assert!(cholesky_in_place(&mut library, &mut scratch));
            assert!(left_looking_cholesky::<f64, Const<N>>(&mut rows));
            let (library, rows) = (library.lower_triangle(), rows.lower_triangle());
            if N <= FAER_STATIC_CHOLESKY_MIN {
                assert_eq!(library, rows, "{N}");
            }
            // Backward stable: L Lᵀ = A + E with |E| ≲ n ε |L| |L|ᵀ; ‖A‖ ≈ 25 n here.
            let bound = 4.0 * N as f64 * f64::EPSILON * (rows.abs() * rows.abs().transpose()).max();
            assert!(
                (library * library.transpose() - spd).abs().max() < bound,
                "{N}"
            );
            assert!((rows * rows.transpose() - spd).abs().max() < bound, "{N}");
            // Indefinite (a large negative shift) and NaN: refused by both.
            for bad in [spd - SMatrix::<f64, N, N>::identity() * 1e3, {
                let mut m = spd;
                m[(N - 1, N - 1)] = f64::NAN;
                m
            }] {
                let (mut l, mut r) = (bad, bad);
                assert!(!cholesky_in_place(&mut l, &mut scratch), "{N}");
                assert!(!left_looking_cholesky::<f64, Const<N>>(&mut r), "{N}");
            }
        }
        at::<3>();
        at::<16>();
        at::<17>();
        at::<24>();
        at::<50>();
    }
}
