//! The heavy dense kernels behind every filter step: products into a destination, Cholesky
//! factorisation in place, triangular solves.
//!
//! Each kernel takes nalgebra matrices and picks its backend from the types:
//!
//! - **static sizes** (every dimension a `Const<N>`): nalgebra, on the stack. Nothing is faster
//!   for small matrices, and nothing allocates.
//! - **runtime sizes** (any dimension `Dyn`) with `f32` or `f64`: faer, over zero-copy views of
//!   the same column-major storage, writing into the destination; a matrix times a vector is
//!   a column sweep of our own, compiled per instruction set (faer's general product is 2–3×
//!   slower there at filter sizes). Nothing allocates (the Cholesky kernel's scratch lives in a
//!   [`CholeskyScratch`] the caller keeps).
//! - runtime sizes with another scalar type: nalgebra (which may allocate temporaries).
//!
//! The choice is made per call from the types (a `TypeId` comparison the compiler folds), so
//! static-size code compiles to pure nalgebra. faer runs single-threaded (`Par::Seq`) unless the
//! `parallel` feature is on *and* the product is at least [`PARALLEL_THRESHOLD`] on its
//! smallest side (see that constant for the measurement that chose it).
//!
//! All shapes must agree (the callers check model outputs first); a mismatch here is a
//! programmer error and panics.

use core::any::Any;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{
    LltRegularization, cholesky_in_place as faer_cholesky, cholesky_in_place_scratch,
};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{MatMut, MatRef, Par};
use nalgebra::{Cholesky, DefaultAllocator, Dim, OMatrix, Scalar, allocator::Allocator};

use crate::scalar::Real;

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
/// is at least this. Below it, thread start-up costs more than it saves.
///
/// Chosen from `cargo bench -p estim-filters --features parallel --bench dynamic` (threshold
/// set to 0) against the sequential build, 2 threads on the 2-core reference machine: threads
/// made the KF step 2.2× slower at n = 50, 1.2× at 100 and broke even at 200, so every size up
/// to 200 stays single-threaded. See BENCHMARKS.md ("Parallel threshold").
pub const PARALLEL_THRESHOLD: usize = 256;

/// Below this size a lower-triangle product ([`mul_lower`]) computes the whole product on
/// faer's small-matrix kernels, which are faster there than its triangular-destination
/// kernel. Measured (counted runs of `benches/dynamic.rs`, 3 interleaved per binary, against
/// the triangular kernel at every size): the step 14 % faster for the KF at n = 12, 10 % for
/// the EKF, 6 % for the UKF, 5 % for the KF at n = 24; 32 and 64 tie at n = 50.
const LOWER_TRIANGLE_MIN: usize = 32;

/// `true` when `D` is a compile-time dimension.
#[inline(always)]
pub fn is_static<D: Dim>() -> bool {
    D::try_to_usize().is_some()
}

/// faer's parallelism for a kernel whose smallest dimension is `size`.
#[inline(always)]
fn par(size: usize) -> Par {
    #[cfg(feature = "parallel")]
    if size >= PARALLEL_THRESHOLD {
        return Par::rayon(0);
    }
    let _ = size;
    Par::Seq
}

/// `m` as the matrix type with scalar `U`, if `T` is `U`.
#[inline(always)]
fn cast<T: Scalar, U: Scalar, R: Dim, C: Dim>(m: &OMatrix<T, R, C>) -> Option<&OMatrix<U, R, C>>
where
    DefaultAllocator: Allocator<R, C>,
{
    (m as &dyn Any).downcast_ref()
}

/// `m` as the matrix type with scalar `U`, if `T` is `U`.
#[inline(always)]
fn cast_mut<T: Scalar, U: Scalar, R: Dim, C: Dim>(
    m: &mut OMatrix<T, R, C>,
) -> Option<&mut OMatrix<U, R, C>>
where
    DefaultAllocator: Allocator<R, C>,
{
    (m as &mut dyn Any).downcast_mut()
}

/// A faer view of the column-major storage of `m`.
#[inline(always)]
fn view<U: Scalar, R: Dim, C: Dim>(m: &OMatrix<U, R, C>) -> MatRef<'_, U>
where
    DefaultAllocator: Allocator<R, C>,
{
    MatRef::from_column_major_slice(m.as_slice(), m.nrows(), m.ncols())
}

/// A mutable faer view of the column-major storage of `m`.
#[inline(always)]
fn view_mut<U: Scalar, R: Dim, C: Dim>(m: &mut OMatrix<U, R, C>) -> MatMut<'_, U>
where
    DefaultAllocator: Allocator<R, C>,
{
    let (r, c) = m.shape();
    MatMut::from_column_major_slice_mut(m.as_mut_slice(), r, c)
}

/// The scalar types faer computes in.
trait FaerScalar: Real + faer::traits::ComplexField {}
impl FaerScalar for f32 {}
impl FaerScalar for f64 {}

/// dst (+)= α op(a) op(b) on faer (a matrix times a vector: [`matvec`]) if `T` is `U`;
/// `false` (nothing done) otherwise.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn faer_product<U, T, R, C, RA, CA, RB, CB>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, RA, CA>,
    transpose_a: bool,
    b: &OMatrix<T, RB, CB>,
    transpose_b: bool,
    lower: bool,
) -> bool
where
    U: FaerScalar,
    T: Real,
    R: Dim,
    C: Dim,
    RA: Dim,
    CA: Dim,
    RB: Dim,
    CB: Dim,
    DefaultAllocator: Allocator<R, C> + Allocator<RA, CA> + Allocator<RB, CB>,
{
    let (Some(dst), Some(a), Some(b), Some(&alpha)) = (
        cast_mut::<T, U, R, C>(dst),
        cast::<T, U, RA, CA>(a),
        cast::<T, U, RB, CB>(b),
        (&alpha as &dyn Any).downcast_ref::<U>(),
    ) else {
        return false;
    };
    if dst.ncols() == 1 && !transpose_a && !transpose_b && !lower {
        // A matrix times a vector: faer's general product costs 2–3× a plain column sweep
        // here (see `matvec`).
        matvec(dst.as_mut_slice(), accum, alpha, a.as_slice(), b.as_slice());
        return true;
    }
    let (a, b) = (view(a), view(b));
    let a = if transpose_a { a.transpose() } else { a };
    let b = if transpose_b { b.transpose() } else { b };
    let size = dst.nrows().min(dst.ncols()).min(a.ncols());
    let accum = match accum {
        Accum::Replace => faer::Accum::Replace,
        Accum::Add => faer::Accum::Add,
    };
    if lower && size >= LOWER_TRIANGLE_MIN {
        triangular::matmul(
            view_mut(dst),
            BlockStructure::TriangularLower,
            accum,
            a,
            BlockStructure::Rectangular,
            b,
            BlockStructure::Rectangular,
            alpha,
            par(size),
        );
    } else {
        matmul(view_mut(dst), accum, a, b, alpha, par(size));
    }
    true
}

/// y (+)= α A x for a column-major `a` of `y.len()` rows and `x.len()` columns: a sweep over
/// the columns four at a time, y ← y + a₀(αx₀) + a₁(αx₁) + a₂(αx₂) + a₃(αx₃), compiled for the
/// widest SIMD the CPU has (`pulp`'s runtime dispatch; the sums are in the same order on every
/// instruction set, so the result is too).
///
/// faer's general product for a single column costs 2–3× this sweep at filter sizes (a
/// one-off loop of 10⁵ calls, AVX2: 50 × 50 in 157 ns against 290 ns, 25 × 50 88 against 260,
/// 12 × 12 22 against 67; equal from n = 100). In the filters it is the model's F x and H x at
/// every sigma point of a UKF and x + K ν in every update: the dynamic bench's UKF step
/// 24 % faster at n = 50 and 18 % at n = 12, the KF 6 % at n = 12 (BENCHMARKS.md, "Matrix–
/// vector products").
#[inline(always)]
pub(crate) fn matvec<U: Real>(y: &mut [U], accum: Accum, alpha: U, a: &[U], x: &[U]) {
    assert_eq!(a.len(), y.len() * x.len(), "matvec: shapes differ");
    pulp::Arch::new().dispatch(Matvec {
        y,
        accum,
        alpha,
        a,
        x,
    });
}

/// The operands of [`matvec`], as the `pulp` operation compiled per instruction set.
struct Matvec<'a, U> {
    y: &'a mut [U],
    accum: Accum,
    alpha: U,
    a: &'a [U],
    x: &'a [U],
}

impl<U: Real> pulp::WithSimd for Matvec<'_, U> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let Self {
            y,
            accum,
            alpha,
            a,
            x,
        } = self;
        let rows = y.len();
        if accum == Accum::Replace {
            y.fill(U::zero());
        }
        if rows == 0 {
            return;
        }
        let mut blocks = a.chunks_exact(4 * rows);
        let mut xs = x.chunks_exact(4);
        for (block, xb) in (&mut blocks).zip(&mut xs) {
            let (a0, rest) = block.split_at(rows);
            let (a1, rest) = rest.split_at(rows);
            let (a2, a3) = rest.split_at(rows);
            let (x0, x1, x2, x3) = (alpha * xb[0], alpha * xb[1], alpha * xb[2], alpha * xb[3]);
            let columns = a0.iter().zip(a1).zip(a2).zip(a3);
            for (yi, (((&v0, &v1), &v2), &v3)) in y.iter_mut().zip(columns) {
                *yi = *yi + v0 * x0 + v1 * x1 + v2 * x2 + v3 * x3;
            }
        }
        for (column, &xj) in blocks.remainder().chunks_exact(rows).zip(xs.remainder()) {
            axpy(y, alpha * xj, column);
        }
    }
}

/// `true` if the product was done on the runtime-size kernels (faer, or [`matvec`]; runtime
/// sizes, `f32`/`f64`).
/// `$lower`: only the lower triangle of the (square) destination is computed.
macro_rules! on_faer {
    ($dims:expr, $dst:expr, $accum:expr, $alpha:expr, $a:expr, $ta:expr, $b:expr, $tb:expr) => {
        on_faer!($dims, $dst, $accum, $alpha, $a, $ta, $b, $tb, false)
    };
    ($dims:expr, $dst:expr, $accum:expr, $alpha:expr, $a:expr, $ta:expr, $b:expr, $tb:expr,
     $lower:expr) => {
        $dims
            && (faer_product::<f64, _, _, _, _, _, _, _>(
                $dst, $accum, $alpha, $a, $ta, $b, $tb, $lower,
            ) || faer_product::<f32, _, _, _, _, _, _, _>(
                $dst, $accum, $alpha, $a, $ta, $b, $tb, $lower,
            ))
    };
}

/// Writes or adds `value` (already scaled) into `dst`.
#[inline(always)]
fn store<T: Real, R: Dim, C: Dim>(dst: &mut OMatrix<T, R, C>, accum: Accum, value: OMatrix<T, R, C>)
where
    DefaultAllocator: Allocator<R, C>,
{
    match accum {
        Accum::Replace => *dst = value,
        Accum::Add => *dst += value,
    }
}

/// α · `value`, skipping the multiplication when α = 1.
#[inline(always)]
fn scaled<T: Real, R: Dim, C: Dim>(alpha: T, value: OMatrix<T, R, C>) -> OMatrix<T, R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    if alpha == T::one() {
        value
    } else {
        value * alpha
    }
}

/// dst (+)= α a b.
#[inline(always)]
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
    let dynamic = !(is_static::<R>() && is_static::<K>() && is_static::<C>());
    if !on_faer!(dynamic, dst, accum, alpha, a, false, b, false) {
        store(dst, accum, scaled(alpha, a * b));
    }
}

/// dst (+)= α a bᵀ.
#[inline(always)]
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
    let dynamic = !(is_static::<R>() && is_static::<K>() && is_static::<C>());
    if !on_faer!(dynamic, dst, accum, alpha, a, false, b, true) {
        // The operator form: for small static sizes it unrolls, where nalgebra's generic
        // `gemm` loops column by column (measured: the filters bench).
        store(dst, accum, scaled(alpha, a * b.transpose()));
    }
}

/// dst (+)= α aᵀ b.
#[inline(always)]
pub fn tr_mul<T, R, K, C>(
    dst: &mut OMatrix<T, R, C>,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, K, R>,
    b: &OMatrix<T, K, C>,
) where
    T: Real,
    R: Dim,
    K: Dim,
    C: Dim,
    DefaultAllocator: Allocator<R, C> + Allocator<K, R> + Allocator<K, C>,
{
    let dynamic = !(is_static::<R>() && is_static::<K>() && is_static::<C>());
    if !on_faer!(dynamic, dst, accum, alpha, a, true, b, false) {
        store(dst, accum, scaled(alpha, a.tr_mul(b)));
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
    let dynamic = !(is_static::<D>() && is_static::<K>());
    if !on_faer!(dynamic, dst, accum, alpha, a, false, b, false, true) {
        store(dst, accum, scaled(alpha, a * b));
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
    let dynamic = !(is_static::<D>() && is_static::<K>());
    if !on_faer!(dynamic, dst, accum, alpha, a, false, b, true, true) {
        store(dst, accum, scaled(alpha, a * b.transpose()));
    }
}

/// Scratch memory for [`cholesky_in_place`] on runtime sizes, grown on first use for a
/// dimension and reused after (static sizes never touch it).
#[derive(Default)]
pub struct CholeskyScratch {
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

impl CholeskyScratch {
    /// Room for factorising `dim × dim` matrices of `U`.
    fn stack<U: FaerScalar>(&mut self, dim: usize, par: Par) -> &mut MemStack {
        let req = cholesky_in_place_scratch::<U>(dim, par, Default::default());
        let bytes = req.size_bytes();
        if self.capacity < bytes {
            self.buffer = None;
            self.capacity = bytes;
        }
        MemStack::new(self.buffer.get_or_insert_with(|| MemBuffer::new(req)))
    }
}

/// The faer Cholesky factorisation if `T` is `U`: `Some(success)`, or `None` if `T` is not `U`.
#[inline(always)]
fn faer_cholesky_in_place<U: FaerScalar, T: Real, D: Dim>(
    a: &mut OMatrix<T, D, D>,
    scratch: &mut CholeskyScratch,
) -> Option<bool>
where
    DefaultAllocator: Allocator<D, D>,
{
    let a = cast_mut::<T, U, D, D>(a)?;
    let n = a.nrows();
    let par = par(n);
    let stack = scratch.stack::<U>(n, par);
    let ok = faer_cholesky(
        view_mut(a),
        LltRegularization::default(),
        par,
        stack,
        Default::default(),
    )
    .is_ok();
    // faer leaves NaN pivots unreported on some paths; a factor must be finite to be used.
    Some(ok && (0..n).all(|i| nalgebra::ComplexField::is_finite(&a[(i, i)])))
}

/// Replaces the lower triangle of the symmetric positive definite `a` by its Cholesky factor L
/// (a = L Lᵀ); the strict upper triangle is left unspecified. `false` if `a` is not
/// (numerically) positive definite or not finite, and then `a` is unspecified.
#[inline(always)]
pub fn cholesky_in_place<T: Real, D: Dim>(
    a: &mut OMatrix<T, D, D>,
    scratch: &mut CholeskyScratch,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    if !is_static::<D>()
        && let Some(ok) = faer_cholesky_in_place::<f64, T, D>(a, scratch)
            .or_else(|| faer_cholesky_in_place::<f32, T, D>(a, scratch))
    {
        return ok;
    }
    match Cholesky::new(a.clone_owned()) {
        Some(chol) => {
            *a = chol.unpack_dirty();
            true
        }
        None => false,
    }
}

/// Solves L X = B in place (`b` ← L⁻¹ b) with L the lower triangle of `l` (its diagonal nonzero,
/// as after a successful [`cholesky_in_place`]).
#[inline(always)]
pub fn solve_lower_in_place<T: Real, D: Dim, C: Dim>(l: &OMatrix<T, D, D>, b: &mut OMatrix<T, D, C>)
where
    DefaultAllocator: Allocator<D, D> + Allocator<D, C>,
{
    if !(is_static::<D>() && is_static::<C>())
        && (faer_solve::<f64, _, _, _>(l, b, false) || faer_solve::<f32, _, _, _>(l, b, false))
    {
        return;
    }
    l.solve_lower_triangular_unchecked_mut(b);
}

/// Solves Lᵀ X = B in place (`b` ← L⁻ᵀ b) with L the lower triangle of `l`.
#[inline(always)]
pub fn solve_lower_transpose_in_place<T: Real, D: Dim, C: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, D, C>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<D, C>,
{
    if !(is_static::<D>() && is_static::<C>())
        && (faer_solve::<f64, _, _, _>(l, b, true) || faer_solve::<f32, _, _, _>(l, b, true))
    {
        return;
    }
    l.tr_solve_lower_triangular_unchecked_mut(b);
}

/// Solves X Lᵀ = B in place (`b` ← B L⁻ᵀ) with L the lower triangle of `l`: the first half of
/// a gain K = Pₓᵤ S⁻¹ = Pₓᵤ L⁻ᵀ L⁻¹, solved in K's own n × m storage (no transposed copy).
#[inline(always)]
pub fn solve_right_lower_transpose_in_place<T: Real, R: Dim, D: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, R, D>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    if !(is_static::<D>() && is_static::<R>())
        && (faer_solve_right::<f64, _, _, _>(l, b, true)
            || faer_solve_right::<f32, _, _, _>(l, b, true))
    {
        return;
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

/// Solves X L = B in place (`b` ← B L⁻¹) with L the lower triangle of `l` (the second half of
/// the gain, see [`solve_right_lower_transpose_in_place`]).
#[inline(always)]
pub fn solve_right_lower_in_place<T: Real, R: Dim, D: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, R, D>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    if !(is_static::<D>() && is_static::<R>())
        && (faer_solve_right::<f64, _, _, _>(l, b, false)
            || faer_solve_right::<f32, _, _, _>(l, b, false))
    {
        return;
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

/// B L⁻ᵀ (`transpose`) or B L⁻¹ on faer if `T` is `U`, as the left solve on the transposed
/// view of `b`: (B L⁻ᵀ)ᵀ = L⁻¹ Bᵀ and (B L⁻¹)ᵀ = L⁻ᵀ Bᵀ.
#[inline(always)]
fn faer_solve_right<U: FaerScalar, T: Real, R: Dim, D: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, R, D>,
    transpose: bool,
) -> bool
where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    let (Some(l), Some(b)) = (cast::<T, U, D, D>(l), cast_mut::<T, U, R, D>(b)) else {
        return false;
    };
    triangular_solve(view(l), view_mut(b).transpose_mut(), !transpose);
    true
}

/// rhs ← L⁻¹ rhs, or L⁻ᵀ rhs with `transpose`, on faer (L the lower triangle of `l`); the one
/// place the left and right solves choose faer's kernel and its parallelism.
#[inline(always)]
fn triangular_solve<U: FaerScalar>(l: MatRef<'_, U>, rhs: MatMut<'_, U>, transpose: bool) {
    let par = par(l.nrows().min(rhs.ncols()));
    if transpose {
        solve_upper_triangular_in_place(l.transpose(), rhs, par);
    } else {
        solve_lower_triangular_in_place(l, rhs, par);
    }
}

/// The faer triangular solve with L (`transpose`: Lᵀ) if `T` is `U`.
#[inline(always)]
fn faer_solve<U: FaerScalar, T: Real, D: Dim, C: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, D, C>,
    transpose: bool,
) -> bool
where
    DefaultAllocator: Allocator<D, D> + Allocator<D, C>,
{
    let (Some(l), Some(b)) = (cast::<T, U, D, D>(l), cast_mut::<T, U, D, C>(b)) else {
        return false;
    };
    triangular_solve(view(l), view_mut(b), transpose);
    true
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

        let at = a.transpose();
        let mut dst = DMatrix::zeros(4, 5);
        tr_mul(&mut dst, Accum::Replace, -1.0, &at, &b);
        assert!((dst + &a * &b).amax() < 1e-12);
    }

    /// The matrix–vector kernel against nalgebra's product, on every shape around its
    /// four-column blocks (and empty ones), both accumulations, α = 1 and not; the bound is the
    /// usual dot-product one, |error| ≤ k ε Σ |α aᵢⱼ xⱼ| (+ |y| ε for the accumulation).
    /// And the dispatched result equals the scalar build's bit for bit (same sums, same order).
    #[test]
    fn matrix_vector_products_match_nalgebra_and_every_instruction_set() {
        for rows in 0..=9 {
            for cols in 0..=9 {
                let a = DMatrix::from_fn(rows, cols, |i, j| ((i * 5 + j * 3) as f64 * 0.7).sin());
                let x = DVector::from_fn(cols, |i, _| (i as f64 * 1.3).cos() * 1e3);
                let y0 = DVector::from_fn(rows, |i, _| 0.25 * i as f64 - 1.0);
                for (accum, alpha) in [(Accum::Replace, 1.0), (Accum::Add, -0.3)] {
                    let mut y = y0.clone();
                    mul(&mut y, accum, alpha, &a, &x);
                    let base = if accum == Accum::Add {
                        y0.clone()
                    } else {
                        y0.map(|_| 0.0)
                    };
                    let expected = &base + alpha * (&a * &x);
                    let scale = base.abs() + (alpha.abs() * a.abs() * x.abs());
                    let k = (cols + 2) as f64;
                    for i in 0..rows {
                        let bound = k * f64::EPSILON * scale[i];
                        assert!(
                            (y[i] - expected[i]).abs() <= bound,
                            "{rows}×{cols} row {i}: {} vs {} bound {bound}",
                            y[i],
                            expected[i]
                        );
                    }
                    let mut scalar = y0.clone();
                    pulp::WithSimd::with_simd(
                        Matvec {
                            y: scalar.as_mut_slice(),
                            accum,
                            alpha,
                            a: a.as_slice(),
                            x: x.as_slice(),
                        },
                        pulp::Scalar::new(),
                    );
                    for (u, v) in y.iter().zip(scalar.iter()) {
                        assert_eq!(u.to_bits(), v.to_bits(), "{rows}×{cols}");
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
        solve_lower_transpose_in_place(&l, &mut x);
        assert!((&s * &x - &b).amax() < 1e-10);

        let mut ls = Matrix3::from_iterator(s.iter().copied());
        assert!(cholesky_in_place(&mut ls, &mut scratch));
        let mut xs = Matrix3x2::from_iterator(b.iter().copied());
        solve_lower_in_place(&ls, &mut xs);
        solve_lower_transpose_in_place(&ls, &mut xs);
        for i in 0..3 {
            for j in 0..2 {
                assert!((xs[(i, j)] - x[(i, j)]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn lower_products_match_the_full_product_on_the_lower_triangle() {
        // Below and above LOWER_TRIANGLE_MIN: full small-matrix product, triangular kernel.
        for n in [5, LOWER_TRIANGLE_MIN + 7] {
            lower_products_match_at(n);
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
}
