//! The Cholesky factor in place and the triangular solves with it: faer's on larger runtime
//! sizes (`dense` feature), our loops (and nalgebra's triangular solve) on static and small
//! runtime ones.

#[cfg(feature = "dense")]
use faer::dyn_stack::{MemBuffer, MemStack};
use nalgebra::{DefaultAllocator, Dim, OMatrix, allocator::Allocator};

#[cfg(feature = "dense")]
use super::{SMALL_RUNTIME_CHOLESKY, dense_route, fixed_route, is_static, lean_routes};
#[cfg(feature = "dense")]
use crate::dense::{Operand, view, view_mut};
use crate::scalar::Real;

/// Scratch memory for [`cholesky_in_place`]'s faer route (runtime sizes), grown on first use
/// for a dimension and reused after (static sizes never touch it).
#[derive(Default)]
pub struct CholeskyScratch {
    #[cfg(feature = "dense")]
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

#[cfg(feature = "dense")]
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
/// (a = L Lᵀ): faer's for runtime sizes above [`SMALL_RUNTIME_CHOLESKY`](super::SMALL_RUNTIME_CHOLESKY)
/// (scratch from `scratch`) and for static sizes above 16 (scratch on the stack: a static-size
/// step's buffers are locals, and allocating there at every call is what static sizes promise
/// not to do), both with the `dense` feature; our inlined left-looking loop otherwise
/// (`left_looking_cholesky`, the same factor to round-off). The strict upper triangle is left
/// unspecified. `false` if `a` is not (numerically) positive definite or not finite, and then
/// `a` is unspecified. (A covariance that may be only semi-definite goes to
/// [`crate::linalg::psd_factor`] instead.)
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn cholesky_in_place<T: Real, D: Dim>(
    a: &mut OMatrix<T, D, D>,
    scratch: &mut CholeskyScratch,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let _ = &scratch;
    #[cfg(feature = "dense")]
    if !is_static::<D>() && a.nrows() > SMALL_RUNTIME_CHOLESKY && !lean_routes() {
        let n = a.nrows();
        let ok = T::cholesky(view_mut(a), scratch.stack::<T>(n));
        // faer leaves NaN pivots unreported on some paths; a factor must be finite.
        return ok && (0..n).all(|i| a[(i, i)].is_finite());
    }
    #[cfg(feature = "dense")]
    if is_static::<D>()
        && a.nrows() > FAER_STATIC_CHOLESKY_MIN
        && !lean_routes()
        && let Some(ok) = static_faer_cholesky(a)
    {
        return ok;
    }
    left_looking_cholesky(a)
}

/// Static sizes above this factorise by faer's blocked Cholesky (with the `dense` feature),
/// up to it by the register-resident [`left_looking_cholesky`].
#[cfg(feature = "dense")]
pub(super) const FAER_STATIC_CHOLESKY_MIN: usize = 16;

/// Bytes of stack a static-size factorisation lends faer's Cholesky (which needs n floats):
/// enough up to n ≈ 500 in f64.
#[cfg(feature = "dense")]
const STATIC_CHOLESKY_STACK: usize = 4096;

/// faer's blocked Cholesky for a static size, its scratch on the stack (so nothing is
/// allocated); `None` if the scratch would not fit in [`STATIC_CHOLESKY_STACK`].
#[cfg(feature = "dense")]
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

/// [`cholesky_in_place`] for static and small runtime sizes: column j of L from the finished
/// columns, lᵢⱼ = (aᵢⱼ − Σ_{k<j} lᵢₖ lⱼₖ) / lⱼⱼ, each sum in a register, in place (column j
/// reads only the original column j and the finished columns before it). The operations and
/// order of [`crate::linalg::psd_factor`]'s loop, so a positive definite matrix gets the same
/// bits from both, without its tolerance, pivoting and closures. Inlined, it replaced
/// nalgebra's out-of-line `Cholesky::new` and its copies (KF 3/2 step 933 → 908 instructions,
/// UKF 6/4 14,671 → 14,600: `b1972b9`). `false` at a pivot that is not finite and positive.
#[cfg_attr(not(debug_assertions), inline(always))]
pub(super) fn left_looking_cholesky<T: Real, D: Dim>(a: &mut OMatrix<T, D, D>) -> bool
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
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn solve_lower_in_place<T: Real, D: Dim, C: Dim>(l: &OMatrix<T, D, D>, b: &mut OMatrix<T, D, C>)
where
    DefaultAllocator: Allocator<D, D> + Allocator<D, C>,
{
    #[cfg(feature = "dense")]
    {
        let (size, work) = (b.nrows().max(b.ncols()), b.nrows() * b.len() / 2);
        if !fixed_route(is_static::<D>() && is_static::<C>(), size) && dense_route(work) {
            return T::solve_lower(view(l), view_mut(b), Operand::AsIs);
        }
    }
    l.solve_lower_triangular_unchecked_mut(b);
}

/// Solves X Lᵀ = B in place (`b` ← B L⁻ᵀ) with L the lower triangle of `l`: the first half of
/// a gain K = Pₓᵤ S⁻¹ = Pₓᵤ L⁻ᵀ L⁻¹, solved in K's own n × m storage (no transposed copy).
/// Larger runtime sizes (`dense`): faer's left solve on the transposed view, (B L⁻ᵀ)ᵀ = L⁻¹ Bᵀ.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn solve_right_lower_transpose_in_place<T: Real, R: Dim, D: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, R, D>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    #[cfg(feature = "dense")]
    {
        let (size, work) = (b.nrows().max(b.ncols()), b.ncols() * b.len() / 2);
        if !fixed_route(is_static::<D>() && is_static::<R>(), size) && dense_route(work) {
            return T::solve_lower(view(l), view_mut(b).transpose_mut(), Operand::AsIs);
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
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn solve_right_lower_in_place<T: Real, R: Dim, D: Dim>(
    l: &OMatrix<T, D, D>,
    b: &mut OMatrix<T, R, D>,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    #[cfg(feature = "dense")]
    {
        let (size, work) = (b.nrows().max(b.ncols()), b.ncols() * b.len() / 2);
        if !fixed_route(is_static::<D>() && is_static::<R>(), size) && dense_route(work) {
            return T::solve_lower(view(l), view_mut(b).transpose_mut(), Operand::Transposed);
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
#[cfg_attr(not(debug_assertions), inline(always))]
fn axpy<T: Real>(y: &mut [T], a: T, x: &[T]) {
    for (yi, &xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

/// y ← a y.
#[cfg_attr(not(debug_assertions), inline(always))]
fn scale<T: Real>(y: &mut [T], a: T) {
    for yi in y {
        *yi *= a;
    }
}
