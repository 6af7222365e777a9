//! The dense backend of the kernels ([`crate::kernel`]) on runtime sizes: faer's products,
//! Cholesky factor and triangular solves, and our matrix × vector kernel ([`Matvec`]), for
//! one scalar type each through the sealed trait [`Dense`], the supertrait of
//! [`Real`](crate::Real); and the faer views (`view`, `view_mut`) of nalgebra's storage
//! they run on.
//!
//! [`Dense`] is implemented once for `f32` and once for `f64` here: faer's generic code is
//! compiled in this crate only, not again in every crate that calls a kernel. faer runs
//! single-threaded (`Par::Seq`) unless the `parallel` feature is on *and* the operation is at
//! least [`PARALLEL_THRESHOLD`] on its smallest side. Without the `dense` feature there is no
//! faer and [`Dense`] is only the seal.
//!
//! This module uses nothing of the scalar or kernel modules: `Real` builds on it, and the
//! kernels on `Real`.

#[cfg(feature = "dense")]
use faer::dyn_stack::{MemStack, StackReq};
#[cfg(feature = "dense")]
use faer::linalg::cholesky::llt::factor::{LltRegularization, cholesky_in_place_scratch};
#[cfg(feature = "dense")]
use faer::linalg::matmul::triangular::{self, BlockStructure};
#[cfg(feature = "dense")]
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
#[cfg(feature = "dense")]
use faer::{MatMut, MatRef, Par};
#[cfg(feature = "dense")]
use nalgebra::{DefaultAllocator, Dim, OMatrix, Scalar, allocator::Allocator};

/// A faer view of the column-major storage of `m`.
#[cfg(feature = "dense")]
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn view<T: Scalar, R: Dim, C: Dim>(m: &OMatrix<T, R, C>) -> MatRef<'_, T>
where
    DefaultAllocator: Allocator<R, C>,
{
    MatRef::from_column_major_slice(m.as_slice(), m.nrows(), m.ncols())
}

/// A mutable faer view of the column-major storage of `m`.
#[cfg(feature = "dense")]
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn view_mut<T: Scalar, R: Dim, C: Dim>(m: &mut OMatrix<T, R, C>) -> MatMut<'_, T>
where
    DefaultAllocator: Allocator<R, C>,
{
    let (r, c) = m.shape();
    MatMut::from_column_major_slice_mut(m.as_mut_slice(), r, c)
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

/// Below this order a lower-triangle product ([`mul_lower`](crate::kernel::mul_lower)) is faer's full product, faster
/// there than its triangular-destination kernel (`a294f26`: KF step at n = 12 14 % faster, EKF
/// 10 %, UKF 6 %).
#[cfg(feature = "dense")]
pub(crate) const LOWER_TRIANGLE_MIN: usize = 32;

/// How an operand enters a product or a triangular solve: as it is, or transposed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Operand {
    /// As it is.
    AsIs,
    /// Transposed.
    Transposed,
}

/// Which part of the destination a product writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// Every entry.
    Whole,
    /// The lower triangle (diagonal included) of a square destination, for a product known to
    /// be symmetric; the strict upper triangle is unspecified afterwards.
    Lower,
}

/// faer's parallelism for an operation whose smallest dimension is `size`.
#[cfg(feature = "dense")]
#[cfg_attr(not(debug_assertions), inline(always))]
fn par(size: usize) -> Par {
    #[cfg(feature = "parallel")]
    if size >= PARALLEL_THRESHOLD {
        return Par::rayon(0);
    }
    let _ = size;
    Par::Seq
}

pub(crate) use sealed::Dense;

mod sealed {
    #[cfg(feature = "dense")]
    use super::*;

    /// Without the `dense` feature (no faer): only the seal of [`Real`](crate::Real) to `f32` and `f64`.
    #[cfg(not(feature = "dense"))]
    pub trait Dense: Sized {}
    #[cfg(not(feature = "dense"))]
    impl Dense for f32 {}
    #[cfg(not(feature = "dense"))]
    impl Dense for f64 {}

    /// faer's runtime-size operations for one scalar type: the supertrait that seals
    /// [`Real`](crate::Real) to `f32` and `f64`. Non-generic methods, so faer's generic code is compiled
    /// once, here (each integration test used to carry its own copy; `d3eba7e` halved the
    /// build of the two largest test binaries).
    #[cfg(feature = "dense")]
    pub trait Dense: Sized {
        /// dst (+)= α A B, only the lower triangle of the (square) dst for [`Part::Lower`].
        fn matmul(
            dst: MatMut<'_, Self>,
            accum: Accum,
            alpha: Self,
            a: MatRef<'_, Self>,
            b: MatRef<'_, Self>,
            part: Part,
        );

        /// y (+)= α A x, A column-major with `y.len()` rows and `x.len()` columns ([`Matvec`]).
        fn matvec(y: &mut [Self], accum: Accum, alpha: Self, a: &[Self], x: &[Self]);

        /// The lower Cholesky factor of `a` in place; `false` if not positive definite.
        fn cholesky(a: MatMut<'_, Self>, stack: &mut MemStack) -> bool;

        /// The scratch [`cholesky`](Self::cholesky) needs at order `dim`.
        fn cholesky_scratch(dim: usize) -> StackReq;

        /// rhs ← L⁻¹ rhs, or L⁻ᵀ rhs for [`Operand::Transposed`] (L the lower triangle of `l`).
        fn solve_lower(l: MatRef<'_, Self>, rhs: MatMut<'_, Self>, l_as: Operand);
    }

    #[cfg(feature = "dense")]
    macro_rules! dense {
        ($($t:ty),*) => {$(
            impl Dense for $t {
                fn matmul(
                    dst: MatMut<'_, $t>,
                    accum: Accum,
                    alpha: $t,
                    a: MatRef<'_, $t>,
                    b: MatRef<'_, $t>,
                    part: Part,
                ) {
                    let size = dst.nrows().min(dst.ncols()).min(a.ncols());
                    let accum = match accum {
                        Accum::Replace => faer::Accum::Replace,
                        Accum::Add => faer::Accum::Add,
                    };
                    if part == Part::Lower && size >= LOWER_TRIANGLE_MIN {
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

                fn solve_lower(l: MatRef<'_, $t>, rhs: MatMut<'_, $t>, l_as: Operand) {
                    let par = par(l.nrows().min(rhs.ncols()));
                    match l_as {
                        Operand::Transposed => {
                            solve_upper_triangular_in_place(l.transpose(), rhs, par)
                        }
                        Operand::AsIs => solve_lower_triangular_in_place(l, rhs, par),
                    }
                }
            }
        )*};
    }

    #[cfg(feature = "dense")]
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
#[cfg(feature = "dense")]
pub(crate) struct Matvec<'a, T> {
    pub(crate) y: &'a mut [T],
    pub(crate) accum: Accum,
    pub(crate) alpha: T,
    pub(crate) a: &'a [T],
    pub(crate) x: &'a [T],
}

#[cfg(feature = "dense")]
macro_rules! matvec {
    ($t:ty, $ts:ident, $splat:ident, $fma:ident, $add:ident, $as_simd:ident, $as_mut:ident) => {
        impl Matvec<'_, $t> {
            /// (y (+)) α A x on the V vectors of rows from `start`.
            #[cfg_attr(not(debug_assertions), inline(always))]
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
            #[cfg_attr(not(debug_assertions), inline(always))]
            fn panel<S: pulp::Simd, const V: usize>(&mut self, simd: S, start: usize) -> usize {
                let sums = self.sums::<S, V>(simd, start);
                let end = start + V * size_of::<S::$ts>() / size_of::<$t>();
                S::$as_mut(&mut self.y[start..end]).0.copy_from_slice(&sums);
                end
            }
        }

        impl pulp::WithSimd for Matvec<'_, $t> {
            type Output = ();

            #[cfg_attr(not(debug_assertions), inline(always))]
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

#[cfg(feature = "dense")]
matvec!(
    f64,
    f64s,
    splat_f64s,
    mul_add_e_f64s,
    add_f64s,
    as_simd_f64s,
    as_mut_simd_f64s
);
#[cfg(feature = "dense")]
matvec!(
    f32,
    f32s,
    splat_f32s,
    mul_add_e_f32s,
    add_f32s,
    as_simd_f32s,
    as_mut_simd_f32s
);
