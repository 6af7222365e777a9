//! Small numerical kernels shared by the estim crates: finiteness and shape checks, a
//! semi-definite Cholesky factor, symmetrisation.
//!
//! All of them work in place or on the stack for static sizes: none allocates unless the
//! matrix type itself lives on the heap (`Dyn`).

use nalgebra::{
    DefaultAllocator, Dim, IsContiguous, Matrix, OMatrix, OVector, RawStorage, U1,
    allocator::Allocator,
};

use crate::error::{Error, Quantity, Result, Stage};
use crate::kernel::{CholeskyScratch, cholesky_in_place, copy, is_static};
use crate::scalar::{Real, real};

/// Whether every entry of `m` is finite. A branch-free scan of the contiguous storage (it
/// vectorises; an early-exit `iter().all()` over nalgebra's generic iterator costs ≈ 4× more,
/// which is a fifth of a small filter step). Needs contiguous storage (owned matrices and
/// vectors); for a strided view use `view.iter().all(|v| v.is_finite())`.
#[inline(always)]
pub fn all_finite<T: Real, R: Dim, C: Dim, S: RawStorage<T, R, C> + IsContiguous>(
    m: &Matrix<T, R, C, S>,
) -> bool {
    m.as_slice().iter().fold(true, |ok, v| ok & v.is_finite())
}

/// `Ok(())` if every entry of `m` is finite, else [`Error::NonFinite`].
#[inline(always)]
pub fn ensure_finite<T: Real, R: Dim, C: Dim, S: RawStorage<T, R, C> + IsContiguous>(
    m: &Matrix<T, R, C, S>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()> {
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::NonFinite { stage, quantity })
    }
}

/// `Ok(())` if `m` is `rows × cols`, else [`Error::DimensionMismatch`].
///
/// Static sizes always pass; the check matters for runtime (`Dyn`) sizes.
#[inline]
pub fn ensure_shape<T, R: Dim, C: Dim, S: RawStorage<T, R, C>>(
    m: &Matrix<T, R, C, S>,
    rows: usize,
    cols: usize,
    stage: Stage,
    quantity: Quantity,
) -> Result<()> {
    let (found_rows, found_cols) = m.shape();
    if (found_rows, found_cols) == (rows, cols) {
        Ok(())
    } else {
        Err(Error::DimensionMismatch {
            stage,
            quantity,
            expected_rows: rows,
            expected_cols: cols,
            found_rows,
            found_cols,
        })
    }
}

/// The tolerance below which a pivot of a covariance factorisation counts as zero:
/// `16 n ε max|Cᵢᵢ|`. Round-off in forming a rank-deficient covariance stays below it.
#[inline]
pub fn psd_tolerance<T: Real, D: Dim>(c: &OMatrix<T, D, D>) -> T
where
    DefaultAllocator: Allocator<D, D>,
{
    tolerance_for(c.nrows(), max_abs_diagonal(c))
}

/// max |Cᵢᵢ|.
fn max_abs_diagonal<T: Real, D: Dim>(c: &OMatrix<T, D, D>) -> T
where
    DefaultAllocator: Allocator<D, D>,
{
    (0..c.nrows()).fold(T::zero(), |m, i| m.max(c[(i, i)].abs()))
}

/// 16 n ε max|Cᵢᵢ| (see [`psd_tolerance`]).
fn tolerance_for<T: Real>(n: usize, max_diag: T) -> T {
    real::<T>(16.0 * n as f64) * T::default_epsilon() * max_diag
}

/// A square root S with S Sᵀ = C of a symmetric positive **semi**-definite C.
///
/// First a Cholesky factorisation that accepts zero pivots: a pivot within [`psd_tolerance`] of
/// zero gives a zero column (that direction has no variance). This is the ordinary lower
/// Cholesky factor whenever C is positive definite, so sigma points are the textbook ones.
/// Without pivoting, round-off in an ill-conditioned leading block can push a later pivot of an
/// exactly singular C below −tolerance; then the factorisation is repeated with diagonal
/// pivoting (as LAPACK's `dpstrf`), which takes the largest remaining pivot first and so stops
/// cleanly at the rank: S = Pᵀ L, no longer triangular. Only if that also finds a clearly
/// negative direction is C rejected. Either way the unscented and sampled propagators get a
/// valid square root, and states that are known exactly (zero variance) are allowed.
pub fn psd_factor<T: Real, D: Dim>(c: &OMatrix<T, D, D>, stage: Stage) -> Result<OMatrix<T, D, D>>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    unpivoted_psd_factor(c)
        .or_else(|()| pivoted_psd_factor(c))
        .map_err(|()| Error::NotPositiveSemiDefinite {
            stage,
            quantity: Quantity::Covariance,
        })
}

/// [`psd_factor`] into `out`. For runtime sizes it first tries faer's Cholesky factorisation in
/// place (allocation-free with a sized `scratch`), which succeeds for every positive definite C
/// and gives the same lower factor up to round-off; only a semi-definite C falls back to
/// [`psd_factor`] (which allocates). Static sizes use [`psd_factor`] directly.
pub fn psd_factor_into<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
    out: &mut OMatrix<T, D, D>,
    scratch: &mut CholeskyScratch,
    stage: Stage,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    if !is_static::<D>() && out.shape() == c.shape() {
        copy(out, c);
        if cholesky_in_place(out, scratch) {
            out.fill_upper_triangle(T::zero(), 1);
            return Ok(());
        }
    }
    *out = psd_factor(c, stage)?;
    Ok(())
}

/// Largest |Cᵢᵢ| and the entry bound for a zero-variance direction: |cᵢⱼ|² ≤ dᵢ dⱼ, so with a
/// pivot within `tol` of zero the remaining covariances must be within √(tol · max Cᵢᵢ).
fn zero_pivot_bounds<T: Real, D: Dim>(c: &OMatrix<T, D, D>) -> (T, T)
where
    DefaultAllocator: Allocator<D, D>,
{
    let max_diag = max_abs_diagonal(c);
    let tol = tolerance_for(c.nrows(), max_diag);
    (tol, (tol * max_diag).sqrt() + tol)
}

/// Lower Cholesky factor accepting zero pivots; `Err(())` on a pivot below −tolerance.
fn unpivoted_psd_factor<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
) -> core::result::Result<OMatrix<T, D, D>, ()>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = c.nrows();
    let (tol, off_tol) = zero_pivot_bounds(c);
    let mut l = c.clone_owned();
    l.fill(T::zero());
    for j in 0..n {
        let mut d = c[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if d < -tol || !d.is_finite() {
            return Err(());
        }
        let zero_pivot = d <= tol;
        let ljj = d.sqrt();
        if !zero_pivot {
            l[(j, j)] = ljj;
        }
        for i in (j + 1)..n {
            let mut s = c[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            if zero_pivot {
                // The column stays zero: consistent only if these covariances vanish too.
                if s.abs() > off_tol || !s.is_finite() {
                    return Err(());
                }
            } else {
                l[(i, j)] = s / ljj;
            }
        }
    }
    Ok(l)
}

/// S = Pᵀ L from the diagonally pivoted factorisation P C Pᵀ = L Lᵀ; `Err(())` if C has a
/// direction with variance below −tolerance or is not finite.
fn pivoted_psd_factor<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
) -> core::result::Result<OMatrix<T, D, D>, ()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    let n = c.nrows();
    let (tol, off_tol) = zero_pivot_bounds(c);
    // `a` holds L in columns < j and the symmetric Schur complement in rows/columns ≥ j;
    // `perm[i]` is the row of C that row i of `a` came from.
    let mut a = c.clone_owned();
    let mut perm = OVector::<usize, D>::from_fn_generic(c.shape_generic().0, U1, |i, _| i);
    let mut rank = n;
    for j in 0..n {
        let mut p = j;
        for i in j..n {
            let d = a[(i, i)];
            if !d.is_finite() || d < -tol {
                return Err(());
            }
            if d > a[(p, p)] {
                p = i;
            }
        }
        if a[(p, p)] <= tol {
            // The rest has (numerically) zero variance: every remaining covariance must vanish.
            for k in j..n {
                for i in k..n {
                    if a[(i, k)].abs() > off_tol {
                        return Err(());
                    }
                }
            }
            rank = j;
            break;
        }
        if p != j {
            a.swap_rows(j, p);
            a.swap_columns(j, p);
            perm.swap_rows(j, p);
        }
        let ljj = a[(j, j)].sqrt();
        a[(j, j)] = ljj;
        for i in (j + 1)..n {
            a[(i, j)] /= ljj;
        }
        for k in (j + 1)..n {
            for i in k..n {
                let v = a[(i, k)] - a[(i, j)] * a[(k, j)];
                a[(i, k)] = v;
                a[(k, i)] = v;
            }
        }
    }
    // Row i of L is row perm[i] of S; columns ≥ rank and the upper triangle are zero.
    let mut root = c.clone_owned();
    root.fill(T::zero());
    for i in 0..n {
        for k in 0..rank.min(i + 1) {
            root[(perm[i], k)] = a[(i, k)];
        }
    }
    Ok(root)
}

/// Replaces `m` by (m + mᵀ)/2, in place.
#[inline]
pub fn symmetrize<T: Real, D: Dim>(m: &mut OMatrix<T, D, D>)
where
    DefaultAllocator: Allocator<D, D>,
{
    let half = real::<T>(0.5);
    let n = m.nrows();
    for j in 0..n {
        for i in (j + 1)..n {
            let v = (m[(i, j)] + m[(j, i)]) * half;
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

/// Visits every pair (i, j), i ≥ j, of an n × n column-major matrix once: `f(data, ij, ji)`
/// gets the two storage indices (equal on the diagonal), may read `data` at those two indices
/// only, and returns the symmetric value written to both. The result is true if every written
/// value is finite. One pass where a symmetrisation, an addition and a finiteness scan would
/// otherwise each sweep the matrix (measured: those sweeps were a quarter of a runtime-size
/// filter step at n = 50, the strided symmetrisation the largest).
///
/// The pairs are visited in 8 × 8 tiles (a tile and its mirror image): the strided half of
/// each pair then touches 8 cache lines per tile and uses them whole, instead of one line per
/// element (measured: `perf record` on the n = 50 KF step of `benches/dynamic.rs` had the
/// strided stores of the untiled loop at ~15 % of the step).
#[inline(always)]
pub fn for_each_symmetric_pair<T: Real>(
    n: usize,
    data: &mut [T],
    mut f: impl FnMut(&[T], usize, usize) -> T,
) -> bool {
    const TILE: usize = 8;
    assert_eq!(data.len(), n * n, "for_each_symmetric_pair: not n × n");
    let mut finite = true;
    for jb in (0..n).step_by(TILE) {
        let j_end = (jb + TILE).min(n);
        for ib in (jb..n).step_by(TILE) {
            let i_end = (ib + TILE).min(n);
            for j in jb..j_end {
                for i in ib.max(j)..i_end {
                    let (ij, ji) = (i + j * n, j + i * n);
                    let v = f(data, ij, ji);
                    data[ij] = v;
                    data[ji] = v;
                    finite &= v.is_finite();
                }
            }
        }
    }
    finite
}

/// Copies the lower triangle of `m` to its upper triangle (after a product that computed only
/// the lower one, [`crate::kernel::mul_lower`]); true if the result is finite.
#[inline(always)]
pub fn mirror_lower_checked<T: Real, D: Dim>(m: &mut OMatrix<T, D, D>) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    for_each_symmetric_pair(n, m.as_mut_slice(), |d, ij, _| d[ij])
}

/// m ← ((m + a) + (m + a)ᵀ)/2 in one pass (the same arithmetic as `m += a` then
/// [`symmetrize`]); true if the result is finite.
#[inline(always)]
#[track_caller]
pub fn symmetrize_add_checked<T: Real, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    a: &OMatrix<T, D, D>,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    assert_eq!(
        m.shape(),
        a.shape(),
        "symmetrize_add_checked: shapes differ"
    );
    let half = real::<T>(0.5);
    let n = m.nrows();
    let a = a.as_slice();
    for_each_symmetric_pair(n, m.as_mut_slice(), |d, ij, ji| {
        ((d[ij] + a[ij]) + (d[ji] + a[ji])) * half
    })
}

/// dst ← ((a + b) + (a + b)ᵀ)/2 in one pass; true if the result is finite.
#[inline(always)]
#[track_caller]
pub fn symmetric_sum_into_checked<T: Real, D: Dim>(
    dst: &mut OMatrix<T, D, D>,
    a: &OMatrix<T, D, D>,
    b: &OMatrix<T, D, D>,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    assert!(
        dst.shape() == a.shape() && a.shape() == b.shape(),
        "symmetric_sum_into_checked: shapes differ"
    );
    let half = real::<T>(0.5);
    let n = dst.nrows();
    let (a, b) = (a.as_slice(), b.as_slice());
    for_each_symmetric_pair(n, dst.as_mut_slice(), |_, ij, ji| {
        ((a[ij] + b[ij]) + (a[ji] + b[ji])) * half
    })
}

/// `Ok(())` if `m` is symmetric within `√ε · max|mᵢⱼ|`, else [`Error::NotSymmetric`] naming
/// the worst pair.
pub fn ensure_symmetric<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    let scale = m.iter().fold(T::zero(), |a, v| a.max(v.abs()));
    let tol = T::default_epsilon().sqrt() * scale;
    let mut worst = (T::zero(), 0, 0);
    for j in 0..n {
        for i in (j + 1)..n {
            let gap = (m[(i, j)] - m[(j, i)]).abs();
            if gap > worst.0 {
                worst = (gap, i, j);
            }
        }
    }
    if worst.0 > tol {
        Err(Error::NotSymmetric {
            stage,
            quantity,
            row: worst.1,
            col: worst.2,
        })
    } else {
        Ok(())
    }
}

/// `Ok(())` if the symmetric `m` is positive semi-definite within [`psd_tolerance`].
pub fn ensure_psd<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    psd_factor(m, stage)
        .map(|_| ())
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
}
