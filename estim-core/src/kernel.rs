//! The heavy dense kernels behind every filter step: products into a destination, Cholesky
//! factorisation in place, triangular solves.
//!
//! Each kernel takes nalgebra matrices and picks its backend from the types:
//!
//! - **static sizes** (every dimension a `Const<N>`): nalgebra, on the stack. Nothing is faster
//!   for small matrices, and nothing allocates.
//! - **runtime sizes** (any dimension `Dyn`) with `f32` or `f64`: faer, over zero-copy views of
//!   the same column-major storage, writing into the destination; a matrix times a vector is
//!   a register-blocked kernel of our own, compiled per instruction set (faer's general
//!   product is 2–3× slower there at filter sizes), and so is a Cholesky factor below
//!   n = 96 (faer's costs up to 2.2× as much there) and, in `f64` on a CPU with AVX-512, the
//!   lower triangle of a product A Bᵀ for 16 ≤ n ≤ 128 (faer's: up to 1.8×). Nothing
//!   allocates (the Cholesky kernel's scratch lives in a [`CholeskyScratch`] the caller
//!   keeps).
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

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::{
    LltRegularization, cholesky_in_place as faer_cholesky, cholesky_in_place_scratch,
};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{MatMut, MatRef, Par};
use nalgebra::{Cholesky, DefaultAllocator, Dim, OMatrix, OVector, Scalar, allocator::Allocator};

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

/// Below this dimension a runtime-size Cholesky factor is computed by our own column kernel
/// ([`FaerScalar::lower_cholesky`]) rather than by faer, whose factor costs 2–2.2× as much
/// from n = 25 to 50. Measured (faer 0.24, one core, AVX2, best of 7 loops of a copy and a
/// factor in a scratch crate), faer vs ours: n = 12 236 vs 218 ns, 25 1.22 vs 0.62 µs, 50 5.8
/// vs 2.6, 64 7.3 vs 4.5, 80 9.7 vs 8.0, 96 12.6 vs 12.3, 112 16.2 vs 18.6, 128 23.4 vs
/// 41.4 µs. See BENCHMARKS.md ("Our own Cholesky factor below n = 96").
const OWN_CHOLESKY_BELOW: usize = 96;

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
trait FaerScalar: Real + faer::traits::ComplexField {
    /// y (+)= α A x for a column-major `a` of `y.len()` rows and `x.len()` columns (see
    /// [`Matvec`]).
    fn matvec(y: &mut [Self], accum: Accum, alpha: Self, a: &[Self], x: &[Self]);

    /// Replaces the lower triangle of the column-major n × n `a` by its Cholesky factor L,
    /// column by column (left-looking): a_(j..n, j) ← a_(j..n, j) − L_(j..n, ..j) L_(j, ..j)ᵀ
    /// on [`Matvec`], then l_jj = √a_jj and l_(j+1..n, j) = a_(j+1..n, j) / l_jj. `row` is
    /// scratch for at least n values (row j of L). `false` at the first pivot a_jj that is not
    /// positive and finite (a NaN or infinity anywhere in L reaches a later pivot), and then
    /// `a` is unspecified. Used below [`OWN_CHOLESKY_BELOW`].
    fn lower_cholesky(a: &mut [Self], n: usize, row: &mut [Self]) -> bool;

    /// y (+)= α A x by [`Sweep`] (out of line: compiled once, here).
    fn sweep(y: &mut [Self], accum: Accum, alpha: Self, a: &[Self], x: &[Self]);

    /// dst (+)= α A B by faer's product, of the lower triangle only if `lower` (faer's
    /// triangular product from [`LOWER_TRIANGLE_MIN`]). This and the three below are the only
    /// calls into faer's generic code, and each is out of line, so that code is compiled once,
    /// in this crate, instead of in every crate that uses a kernel (each integration test was
    /// its own copy; see `BENCHMARKS.md`, "Kernels compiled once").
    fn faer_matmul(
        dst: MatMut<'_, Self>,
        accum: Accum,
        alpha: Self,
        a: MatRef<'_, Self>,
        b: MatRef<'_, Self>,
        lower: bool,
    );

    /// faer's Cholesky factor of `a` in place with `stack` (room for
    /// [`cholesky_scratch`](Self::cholesky_scratch)); `false` if not positive definite.
    fn faer_cholesky(a: MatMut<'_, Self>, stack: &mut MemStack) -> bool;

    /// The scratch [`faer_cholesky`](Self::faer_cholesky) and
    /// [`lower_cholesky`](Self::lower_cholesky) need at order `dim`.
    fn cholesky_scratch(dim: usize) -> StackReq;

    /// rhs ← L⁻¹ rhs, or L⁻ᵀ rhs with `transpose`, by faer (L the lower triangle of `l`).
    fn faer_triangular_solve(l: MatRef<'_, Self>, rhs: MatMut<'_, Self>, transpose: bool);

    /// The lower triangle of the n × n C (+)= α A Bᵀ (A, B n × k) on our own AVX-512 kernel
    /// (`f64`, 16 ≤ n ≤ 128, a CPU with AVX-512) and `true`; `false` (nothing done) otherwise.
    fn lower_product_tr(
        c: &mut [Self],
        n: usize,
        accum: Accum,
        alpha: Self,
        a: &[Self],
        b: &[Self],
    ) -> bool;
}

/// From this many rows a matrix × vector product is [`Sweep`] rather than [`Matvec`]'s panels,
/// which read a tall A one panel's rows of each column at a time. Measured (`kernel::mul` in a
/// loop, best of 5, five alternating runs of the builds, scratch crate; sweep vs panels in ns):
/// 96 × 96 678 vs 676, 100 × 100 619 vs 621, 128 × 128 907 vs 1202, 150 × 150 1490 vs 1559,
/// 200 × 200 2376 vs 2960, 256 × 256 4694 vs 4976, 400 × 400 11003 vs 13528, 800 × 800
/// 50870 vs 61352 (300 × 300: 6462 vs 6058).
const SWEEP_MIN_ROWS: usize = 128;

/// y (+)= α A x for tall A (at least [`SWEEP_MIN_ROWS`] rows): y ← y + Σ αxⱼ aⱼ over the whole
/// of y, four columns at a time, so each pass streams four whole columns of A (y stays in L1).
/// The loop is plain Rust, vectorised by the compiler for the instruction set pulp dispatches
/// to (AVX2 here). This was the kernel for every size before [`Matvec`], whose operands it
/// takes.
struct Sweep<'a, U>(Matvec<'a, U>);

impl<U: Real> pulp::WithSimd for Sweep<'_, U> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let Matvec {
            y,
            accum,
            alpha,
            a,
            x,
        } = self.0;
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
            let scale = alpha * xj;
            for (yi, &v) in y.iter_mut().zip(column) {
                *yi += v * scale;
            }
        }
    }
}

/// y (+)= α A x, the kernel behind every runtime-size matrix × vector product: rows in panels
/// of whole SIMD vectors held in registers across all the columns, y_P ← (y_P +) (Σ_even
/// a_P,j (αx_j) + Σ_odd a_P,j (αx_j)), each sum a chain of fused multiply–adds (plain on CPUs
/// without FMA). The last `rows mod lanes` rows are one whole vector ending at the last row
/// (one at a time if there are fewer rows than lanes). Compiled for the widest SIMD the CPU has
/// (`pulp`'s runtime dispatch), so the last bits depend on the instruction set.
///
/// A panel is 4 vectors (16 f64 rows on AVX2: 2 × 4 accumulators of 16 registers), or 8 with
/// AVX-512 (32 registers), which pulp dispatches to only if its `x86-v4` feature is on: we
/// leave it off, since it made the test build ~1.5× slower (BENCHMARKS.md). For `f64` with at
/// least 16 rows on a CPU with AVX-512 the same kernel runs instead from `kernel::avx512`
/// (`std::arch`, one function, so no such build cost). Two chains per row hide the FMA
/// latency. The four-column sweep this replaced (y ← y + a₀x₀ + … + a₃x₃ over the whole of
/// y, four columns at a time) waited on each block's store of y and was latency-bound at
/// filter sizes. Time against it (`kernel::mul` in a loop, best of 5, three builds alternating
/// five times in a scratch crate; AVX2 panels below 16 rows, AVX-512 from there): 6 × 6 0.47,
/// 12 × 12 0.52, 24 × 24 0.56, 25 × 50 0.61, 50 × 50 0.52 (179 → 93 ns), 64 × 64 0.51,
/// 100 × 100 0.98. From 128 rows, where the panels read A from L2 one panel's rows of each
/// column at a time, the sweep is kept ([`Sweep`], [`SWEEP_MIN_ROWS`]). faer's general product
/// costs 2–3× the sweep at these sizes, so it is not used for one column.
struct Matvec<'a, U> {
    y: &'a mut [U],
    accum: Accum,
    alpha: U,
    /// A, column-major (or the matrix A is a block of: [`BlockMatvec`]).
    a: &'a [U],
    x: &'a [U],
}

/// [`Matvec`] with A the rows `first..first + y.len()` of the column-major matrix `matvec.a`
/// with `stride` rows: the column updates of [`FaerScalar::lower_cholesky`]. A type of its
/// own so that the whole-matrix products keep their constant offsets (fields in `Matvec` cost
/// ≈ 1 ns a call at 6 × 6 and 12 × 12, measured).
struct BlockMatvec<'a, U> {
    matvec: Matvec<'a, U>,
    stride: usize,
    first: usize,
}

#[cfg(target_arch = "x86_64")]
mod avx512;

/// y (+)= α A x with A rows `first..first + y.len()` of the column-major `a` with `stride`
/// rows, on AVX-512 if the CPU has it and y has at least 8 rows (`true`), else nothing done
/// (`false`; [`Matvec`] on pulp's best instruction set then).
#[inline(always)]
fn matvec_avx512_f64(
    y: &mut [f64],
    accum: Accum,
    alpha: f64,
    (a, stride, first): (&[f64], usize, usize),
    x: &[f64],
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let block = avx512::Block { a, stride, first };
        avx512::matvec(y, accum, alpha, block, x)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (y, accum, alpha, a, stride, first, x);
        false
    }
}

/// [`FaerScalar::lower_product_tr`] for `f64`.
#[inline(always)]
fn lower_product_tr_f64(
    c: &mut [f64],
    n: usize,
    accum: Accum,
    alpha: f64,
    a: &[f64],
    b: &[f64],
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        avx512::lower_product_tr(c, n, accum, alpha, a, b)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (c, n, accum, alpha, a, b);
        false
    }
}

/// No AVX-512 lower-triangle kernel (`f32`): always `false`.
#[inline(always)]
fn lower_product_tr_none<U>(_: &mut [U], _: usize, _: Accum, _: U, _: &[U], _: &[U]) -> bool {
    false
}

/// No AVX-512 kernel (`f32`): always `false`.
#[inline(always)]
fn matvec_avx512_none<U>(_: &mut [U], _: Accum, _: U, _: (&[U], usize, usize), _: &[U]) -> bool {
    false
}

macro_rules! impl_matvec {
    ($t:ty, $ts:ident, $splat:ident, $fma:ident, $add:ident, $as_simd:ident, $as_mut_simd:ident, $wide:ident, $lower:ident) => {
        impl FaerScalar for $t {
            #[inline(always)]
            fn lower_product_tr(
                c: &mut [$t],
                n: usize,
                accum: Accum,
                alpha: $t,
                a: &[$t],
                b: &[$t],
            ) -> bool {
                $lower(c, n, accum, alpha, a, b)
            }

            fn matvec(y: &mut [$t], accum: Accum, alpha: $t, a: &[$t], x: &[$t]) {
                assert_eq!(a.len(), y.len() * x.len(), "matvec: shapes differ");
                let rows = y.len();
                if rows >= SWEEP_MIN_ROWS {
                    return Self::sweep(y, accum, alpha, a, x);
                }
                if $wide(y, accum, alpha, (a, rows, 0), x) {
                    return;
                }
                pulp::Arch::new().dispatch(Matvec {
                    y,
                    accum,
                    alpha,
                    a,
                    x,
                });
            }

            fn sweep(y: &mut [$t], accum: Accum, alpha: $t, a: &[$t], x: &[$t]) {
                pulp::Arch::new().dispatch(Sweep(Matvec {
                    y,
                    accum,
                    alpha,
                    a,
                    x,
                }));
            }

            fn faer_matmul(
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
                    triangular::matmul(
                        dst,
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
                    matmul(dst, accum, a, b, alpha, par(size));
                }
            }

            fn faer_cholesky(a: MatMut<'_, $t>, stack: &mut MemStack) -> bool {
                let par = par(a.nrows());
                faer_cholesky(
                    a,
                    LltRegularization::default(),
                    par,
                    stack,
                    Default::default(),
                )
                .is_ok()
            }

            fn cholesky_scratch(dim: usize) -> StackReq {
                cholesky_in_place_scratch::<$t>(dim, par(dim), Default::default())
                    .or(StackReq::new::<$t>(dim))
            }

            fn faer_triangular_solve(l: MatRef<'_, $t>, rhs: MatMut<'_, $t>, transpose: bool) {
                let par = par(l.nrows().min(rhs.ncols()));
                if transpose {
                    solve_upper_triangular_in_place(l.transpose(), rhs, par);
                } else {
                    solve_lower_triangular_in_place(l, rhs, par);
                }
            }

            fn lower_cholesky(a: &mut [$t], n: usize, row: &mut [$t]) -> bool {
                assert!(
                    a.len() == n * n && row.len() >= n,
                    "lower_cholesky: shapes differ"
                );
                let arch = pulp::Arch::new();
                for j in 0..n {
                    // Column j below the diagonal: a_j ← a_j − L_(j.., ..j) L_(j, ..j)ᵀ.
                    let (left, right) = a.split_at_mut(j * n);
                    if j > 0 {
                        for (r, column) in row.iter_mut().zip(left.chunks_exact(n)) {
                            *r = column[j];
                        }
                        let (y, x) = (&mut right[j..n], &row[..j]);
                        if !$wide(y, Accum::Add, -1.0, (left, n, j), x) {
                            arch.dispatch(BlockMatvec {
                                matvec: Matvec {
                                    y,
                                    accum: Accum::Add,
                                    alpha: -1.0,
                                    a: left,
                                    x,
                                },
                                stride: n,
                                first: j,
                            });
                        }
                    }
                    let pivot = right[j];
                    if !(pivot > 0.0 && pivot.is_finite()) {
                        return false;
                    }
                    let d = pivot.sqrt();
                    right[j] = d;
                    let inverse = 1.0 / d;
                    for v in &mut right[j + 1..n] {
                        *v *= inverse;
                    }
                }
                true
            }
        }

        impl Matvec<'_, $t> {
            /// Values per SIMD vector of `S`.
            #[inline(always)]
            fn lanes<S: pulp::Simd>() -> usize {
                size_of::<S::$ts>() / size_of::<$t>()
            }

            /// (y (+)) α A x on rows `start..start + V·lanes`: V vectors of accumulators per
            /// column parity. `block` is A's first row in `a` and the rows of `a`.
            #[inline(always)]
            fn sums<S: pulp::Simd, const V: usize>(
                &self,
                simd: S,
                start: usize,
                (first, stride): (usize, usize),
            ) -> [S::$ts; V] {
                let end = start + V * Self::lanes::<S>();
                let (a_start, a_end) = (first + start, first + end);
                let zero = simd.$splat(0.0);
                let (mut even, mut odd) = ([zero; V], [zero; V]);
                let mut columns = self.a.chunks_exact(stride).zip(self.x);
                while let Some((c0, &x0)) = columns.next() {
                    let s0 = simd.$splat(self.alpha * x0);
                    for (acc, &v) in even.iter_mut().zip(S::$as_simd(&c0[a_start..a_end]).0) {
                        *acc = simd.$fma(v, s0, *acc);
                    }
                    let Some((c1, &x1)) = columns.next() else {
                        break;
                    };
                    let s1 = simd.$splat(self.alpha * x1);
                    for (acc, &v) in odd.iter_mut().zip(S::$as_simd(&c1[a_start..a_end]).0) {
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

            /// Rows `start..start + V·lanes` of y ← (y +) α A x.
            #[inline(always)]
            fn panel<S: pulp::Simd, const V: usize>(
                &mut self,
                simd: S,
                start: usize,
                block: (usize, usize),
            ) {
                let sums = self.sums::<S, V>(simd, start, block);
                let end = start + V * Self::lanes::<S>();
                for (o, v) in S::$as_mut_simd(&mut self.y[start..end])
                    .0
                    .iter_mut()
                    .zip(sums)
                {
                    *o = v;
                }
            }

            /// The first `vectors` vectors of rows, in panels of `V` vectors and one of the rest.
            #[inline(always)]
            fn panels<S: pulp::Simd, const V: usize>(
                &mut self,
                simd: S,
                vectors: usize,
                block: (usize, usize),
            ) {
                let lanes = Self::lanes::<S>();
                let mut start = 0;
                for _ in 0..vectors / V {
                    self.panel::<S, V>(simd, start, block);
                    start += V * lanes;
                }
                match vectors % V {
                    7 => self.panel::<S, 7>(simd, start, block),
                    6 => self.panel::<S, 6>(simd, start, block),
                    5 => self.panel::<S, 5>(simd, start, block),
                    4 => self.panel::<S, 4>(simd, start, block),
                    3 => self.panel::<S, 3>(simd, start, block),
                    2 => self.panel::<S, 2>(simd, start, block),
                    1 => self.panel::<S, 1>(simd, start, block),
                    _ => {}
                }
            }
        }

        impl pulp::WithSimd for Matvec<'_, $t> {
            type Output = ();

            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, simd: S) {
                let rows = self.y.len();
                self.run(simd, (0, rows));
            }
        }

        impl pulp::WithSimd for BlockMatvec<'_, $t> {
            type Output = ();

            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, simd: S) {
                self.matvec.run(simd, (self.first, self.stride));
            }
        }

        impl Matvec<'_, $t> {
            /// The product, A in `a` as `block` says (see [`Matvec::sums`]).
            #[inline(always)]
            fn run<S: pulp::Simd>(mut self, simd: S, block: (usize, usize)) {
                let rows = self.y.len();
                if rows == 0 {
                    return;
                }
                let lanes = Self::lanes::<S>();
                let vectors = rows / lanes;
                // The last rows mod lanes rows: a whole vector ending at the last row, computed
                // before the panels overwrite the y it reads and stored after them (the rows it
                // shares with the last panel get the same bits: same operations, same order).
                // No closure here: a closure does not get the SIMD target features of the
                // function pulp compiles this into, and if the compiler keeps it out of line,
                // every SIMD intrinsic in it becomes a call (6 × 6 took 79 ns instead of 7).
                let last = if vectors > 0 && rows % lanes != 0 {
                    Some(self.sums::<S, 1>(simd, rows - lanes, block))
                } else {
                    None
                };
                if size_of::<S::$ts>() >= 64 {
                    self.panels::<S, 8>(simd, vectors, block);
                } else {
                    self.panels::<S, 4>(simd, vectors, block);
                }
                if let Some([v]) = last {
                    S::$as_mut_simd(&mut self.y[rows - lanes..]).0[0] = v;
                    return;
                }
                // Fewer rows than lanes: one at a time.
                let (alpha, a, x) = (self.alpha, self.a, self.x);
                let (first, stride) = block;
                for i in vectors * lanes..rows {
                    let mut sum: $t = 0.0;
                    for (column, &xj) in a.chunks_exact(stride).zip(x) {
                        sum += column[first + i] * (alpha * xj);
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

impl_matvec!(
    f64,
    f64s,
    splat_f64s,
    mul_add_e_f64s,
    add_f64s,
    as_simd_f64s,
    as_mut_simd_f64s,
    matvec_avx512_f64,
    lower_product_tr_f64
);
impl_matvec!(
    f32,
    f32s,
    splat_f32s,
    mul_add_e_f32s,
    add_f32s,
    as_simd_f32s,
    as_mut_simd_f32s,
    matvec_avx512_none,
    lower_product_tr_none
);

/// dst (+)= α op(a) op(b) on faer (a matrix times a vector: [`Matvec`]) if `T` is `U`;
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
        // A matrix times a vector: faer's general product costs 2–3× the panel kernel here
        // (see `Matvec`), which checks only the number of entries.
        assert!(
            a.shape() == (dst.nrows(), b.nrows()) && b.ncols() == 1,
            "matrix × vector: {:?} ← {:?} × {:?}",
            dst.shape(),
            a.shape(),
            b.shape()
        );
        U::matvec(dst.as_mut_slice(), accum, alpha, a.as_slice(), b.as_slice());
        return true;
    }
    let n = dst.nrows();
    if lower
        && !transpose_a
        && transpose_b
        && (a.nrows(), b.nrows(), a.ncols()) == (n, n, b.ncols())
        && U::lower_product_tr(
            dst.as_mut_slice(),
            n,
            accum,
            alpha,
            a.as_slice(),
            b.as_slice(),
        )
    {
        return true;
    }
    let (a, b) = (view(a), view(b));
    let a = if transpose_a { a.transpose() } else { a };
    let b = if transpose_b { b.transpose() } else { b };
    U::faer_matmul(view_mut(dst), accum, alpha, a, b, lower);
    true
}

/// Column `column` of `dst` (+)= α A x: [`Matvec`] for `f32`/`f64`, a plain loop of dot
/// products for other scalars.
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
    assert!(
        column < dst.ncols() && a.shape() == (dst.nrows(), x.nrows()),
        "mul_into_column: column {column} of {:?} ← {:?} × {:?}",
        dst.shape(),
        a.shape(),
        x.shape()
    );
    if column_on_kernel::<f64, _, _, _, _, _, _>(dst, column, accum, alpha, a, x)
        || column_on_kernel::<f32, _, _, _, _, _, _>(dst, column, accum, alpha, a, x)
    {
        return;
    }
    column_by_dot_products(dst, column, accum, alpha, a, x);
}

/// [`mul_into_column`] for any scalar: one dot product per row.
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
        let mut sum = T::zero();
        for j in 0..x.nrows() {
            sum += a[(i, j)] * x[j];
        }
        let d = &mut dst[(i, column)];
        *d = match accum {
            Accum::Add => *d + alpha * sum,
            Accum::Replace => alpha * sum,
        };
    }
}

/// [`mul_into_column`] on [`Matvec`] if `T` is `U`; `false` (nothing done) otherwise.
#[inline(always)]
fn column_on_kernel<U: FaerScalar, T: Real, R: Dim, C: Dim, RA: Dim, CA: Dim, RX: Dim>(
    dst: &mut OMatrix<T, R, C>,
    column: usize,
    accum: Accum,
    alpha: T,
    a: &OMatrix<T, RA, CA>,
    x: &OVector<T, RX>,
) -> bool
where
    DefaultAllocator: Allocator<R, C> + Allocator<RA, CA> + Allocator<RX>,
{
    let (Some(dst), Some(a), Some(x), Some(&alpha)) = (
        cast_mut::<T, U, R, C>(dst),
        cast::<T, U, RA, CA>(a),
        cast::<T, U, RX, nalgebra::U1>(x),
        (&alpha as &dyn Any).downcast_ref::<U>(),
    ) else {
        return false;
    };
    let rows = dst.nrows();
    let y = &mut dst.as_mut_slice()[column * rows..(column + 1) * rows];
    U::matvec(y, accum, alpha, a.as_slice(), x.as_slice());
    true
}

/// `true` if the product was done on the runtime-size kernels (faer, or [`Matvec`]; runtime
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
    fn stack<U: FaerScalar>(&mut self, dim: usize) -> &mut MemStack {
        let req = U::cholesky_scratch(dim);
        let bytes = req.size_bytes();
        if self.capacity < bytes {
            self.buffer = None;
            self.capacity = bytes;
        }
        MemStack::new(self.buffer.get_or_insert_with(|| MemBuffer::new(req)))
    }
}

/// The runtime-size Cholesky factorisation if `T` is `U` (ours below [`OWN_CHOLESKY_BELOW`],
/// faer's from there): `Some(success)`, or `None` if `T` is not `U`.
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
    let stack = scratch.stack::<U>(n);
    let ok = if n < OWN_CHOLESKY_BELOW {
        let (mut row, _) = stack.make_with(n, |_| U::zero());
        U::lower_cholesky(a.as_mut_slice(), n, &mut row)
    } else {
        U::faer_cholesky(view_mut(a), stack)
    };
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
    U::faer_triangular_solve(view(l), view_mut(b).transpose_mut(), !transpose);
    true
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
    U::faer_triangular_solve(view(l), view_mut(b), transpose);
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

    /// `Matvec` on one instruction set, as `kernel::mul` runs it on the best one: A all of
    /// `a`, or (`block`: `Some((stride, first))`) rows `first..first + y.len()` of the matrix
    /// `a` with `stride` rows, as `lower_cholesky` runs it.
    fn matvec_on<S: pulp::Simd>(
        simd: S,
        y: &mut [f64],
        accum: Accum,
        alpha: f64,
        (a, block): (&[f64], Option<(usize, usize)>),
        x: &[f64],
    ) {
        let matvec = Matvec {
            y,
            accum,
            alpha,
            a,
            x,
        };
        match block {
            None => pulp::WithSimd::with_simd(matvec, simd),
            Some((stride, first)) => pulp::WithSimd::with_simd(
                BlockMatvec {
                    matvec,
                    stride,
                    first,
                },
                simd,
            ),
        }
    }

    /// The matrix–vector kernel against nalgebra's product, on the instruction set `mul`
    /// dispatches to, and on scalar, AVX2 and (f64, from 16 rows) AVX-512 if the CPU has them,
    /// on shapes around its panels (1–8 vectors and a remainder of rows, empty ones), both
    /// accumulations, α = 1 and not; the bound is the usual
    /// dot-product one, |error| ≤ k ε Σ |α aᵢⱼ xⱼ| (+ |y| ε for the accumulation). Also
    /// `kernel::mul` itself, `mul_into_column` in f32 and its any-scalar fallback.
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
                    // A alone, and A as rows 2..rows + 2 of a matrix with 5 more rows (as
                    // lower_cholesky reads it).
                    let mut big = DMatrix::from_element(rows + 5, cols, f64::NAN);
                    big.rows_mut(2, rows).copy_from(&a);
                    let blocks = [(a.as_slice(), None), (big.as_slice(), Some((rows + 5, 2)))];
                    let x_ = x.as_slice();
                    let mut y = y0.clone();
                    mul(&mut y, accum, alpha, &a, &x);
                    check(&y, "dispatched");
                    for block in blocks {
                        let mut y = y0.clone();
                        matvec_on(
                            pulp::Scalar::new(),
                            y.as_mut_slice(),
                            accum,
                            alpha,
                            block,
                            x_,
                        );
                        check(&y, "scalar");
                        #[cfg(target_arch = "x86_64")]
                        if let Some(simd) = pulp::x86::V3::try_new() {
                            let mut y = y0.clone();
                            matvec_on(simd, y.as_mut_slice(), accum, alpha, block, x_);
                            check(&y, "AVX2");
                        }
                        #[cfg(target_arch = "x86_64")]
                        if avx512::available() {
                            let (a, place) = block;
                            let (stride, first) = place.unwrap_or((rows, 0));
                            let block = avx512::Block { a, stride, first };
                            let mut y = y0.clone();
                            let done = avx512::matvec(y.as_mut_slice(), accum, alpha, block, x_);
                            assert_eq!(done, rows >= 16, "AVX-512 runs from 16 rows");
                            if done {
                                check(&y, "AVX-512");
                            } else {
                                assert_eq!(y, y0, "nothing done below 16 rows");
                            }
                        }
                    }
                    // The any-scalar fallback of mul_into_column (run here on f64).
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

    /// The Cholesky factor on both sides of [`OWN_CHOLESKY_BELOW`] (`lower_cholesky` below it,
    /// faer above), f64 and f32: lower triangular with a positive diagonal, and a backward
    /// error within Higham's bound |L Lᵀ − A| ≤ γₙ₊₁ |L| |L|ᵀ (elementwise, γₖ = kε / (1 − kε));
    /// a matrix that fails the pivot test at its first, middle or last column, or holds a NaN
    /// or infinity below the diagonal, is refused.
    #[test]
    fn cholesky_factors_have_a_small_backward_error_on_both_paths() {
        let mut scratch = CholeskyScratch::default();
        let below = OWN_CHOLESKY_BELOW;
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
        // Below and above LOWER_TRIANGLE_MIN: full small-matrix product, triangular kernel.
        for n in [5, LOWER_TRIANGLE_MIN + 7] {
            lower_products_match_at(n);
        }
    }

    /// `mul_tr_lower` on the orders around the AVX-512 lower-triangle kernel's panels and
    /// limits (16 ≤ n ≤ 128, 4-column blocks, 8-row vectors, panels of 6, a last vector that
    /// must not write rows twice) and beyond, k = 0, 1, 7, 50, both accumulations, against
    /// nalgebra's full product on the lower triangle: |error| ≤ (k + 2) ε (|start| + |α| |A| |B|ᵀ).
    /// The AVX-512 kernel itself (when the CPU has it) is run directly too.
    #[test]
    fn lower_triangle_products_match_nalgebra_around_the_avx512_kernel() {
        let orders = [
            15, 16, 17, 20, 23, 24, 25, 31, 47, 48, 49, 50, 55, 63, 64, 65, 100, 127, 128, 129,
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
                    let check = |dst: &DMatrix<f64>, set: &str| {
                        for j in 0..n {
                            for i in j..n {
                                let bound = (k + 2) as f64 * f64::EPSILON * scale[(i, j)];
                                let error = (dst[(i, j)] - expected[(i, j)]).abs();
                                assert!(error <= bound, "{set} n = {n} k = {k} ({i}, {j})");
                            }
                        }
                    };
                    let mut dst = start.clone();
                    mul_tr_lower(&mut dst, accum, alpha, &a, &b);
                    check(&dst, "mul_tr_lower");
                    #[cfg(target_arch = "x86_64")]
                    if avx512::available() {
                        let mut dst = start.clone();
                        let (a_, b_) = (a.as_slice(), b.as_slice());
                        let done =
                            avx512::lower_product_tr(dst.as_mut_slice(), n, accum, alpha, a_, b_);
                        assert_eq!(done, (16..=avx512::LOWER_MAX).contains(&n), "n = {n}");
                        if done {
                            check(&dst, "AVX-512");
                        } else {
                            assert_eq!(dst, start);
                        }
                    }
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
}
