//! Small numerical kernels shared by the estim crates: finiteness and shape checks, a
//! semi-definite Cholesky factor, symmetrisation.
//!
//! All of them work in place or on the stack for static sizes: none allocates unless the
//! matrix type itself lives on the heap (`Dyn`).

use nalgebra::{DefaultAllocator, Dim, Matrix, OMatrix, RawStorage, allocator::Allocator};

use crate::error::{Error, Quantity, Result, Stage};
use crate::scalar::{Real, real};

/// `Ok(())` if every entry of `m` is finite, else [`Error::NonFinite`].
#[inline]
pub fn ensure_finite<T: Real, R: Dim, C: Dim, S: RawStorage<T, R, C>>(
    m: &Matrix<T, R, C, S>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()> {
    if m.iter().all(|v| v.is_finite()) {
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
    let n = c.nrows();
    let max_diag = (0..n).fold(T::zero(), |m, i| m.max(c[(i, i)].abs()));
    real::<T>(16.0 * n as f64) * T::default_epsilon() * max_diag
}

/// Lower-triangular L with L Lᵀ = C for a symmetric positive **semi**-definite C.
///
/// A Cholesky factorisation that accepts zero pivots: a pivot within [`psd_tolerance`] of
/// zero gives a zero column (that direction has no variance), a pivot below `−tolerance`
/// is an error. This lets the unscented and sampled propagators handle states that are known
/// exactly (zero variance), which the plain Cholesky rejects. Only the lower triangle of C is
/// read.
pub fn psd_factor<T: Real, D: Dim>(c: &OMatrix<T, D, D>, stage: Stage) -> Result<OMatrix<T, D, D>>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = c.nrows();
    let tol = psd_tolerance(c);
    let max_diag = (0..n).fold(T::zero(), |m, i| m.max(c[(i, i)].abs()));
    let mut l = c.clone_owned();
    l.fill(T::zero());
    for j in 0..n {
        let mut d = c[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if d < -tol || !d.is_finite() {
            return Err(Error::NotPositiveSemiDefinite {
                stage,
                quantity: Quantity::Covariance,
            });
        }
        if d <= tol {
            // Zero variance in this direction: the column stays zero, which is only consistent
            // if the remaining covariances with this direction vanish too (|cᵢⱼ|² ≤ dᵢ dⱼ).
            let off_tol = (tol * max_diag).sqrt() + tol;
            for i in (j + 1)..n {
                let mut s = c[(i, j)];
                for k in 0..j {
                    s -= l[(i, k)] * l[(j, k)];
                }
                if s.abs() > off_tol || !s.is_finite() {
                    return Err(Error::NotPositiveSemiDefinite {
                        stage,
                        quantity: Quantity::Covariance,
                    });
                }
            }
            continue;
        }
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        for i in (j + 1)..n {
            let mut s = c[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / ljj;
        }
    }
    Ok(l)
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
    DefaultAllocator: Allocator<D, D>,
{
    psd_factor(m, stage)
        .map(|_| ())
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
}
