//! The checks a filter runs on what a model or a caller hands it, each answering with the
//! crate's typed [`Error`] (naming the [`Stage`] and the [`Quantity`]): every entry finite
//! ([`ensure_finite`], [`all_finite`]), the expected shape ([`ensure_shape`]), symmetric
//! ([`ensure_symmetric`]), positive semi-definite ([`ensure_psd`], and for a noise matrix met
//! every step the cheaper [`ensure_nonnegative_diagonal`] and [`ensure_semidefinite_noise`]);
//! and [`symmetrize`], which makes a matrix symmetric when round-off has made it not quite.
//!
//! Models written outside estim (estim-models, your own) use them to refuse bad input the way
//! the filters do. None allocates unless the matrix type itself lives on the heap (`Dyn`), and
//! none changes its input except [`symmetrize`] and the `work` buffer of
//! [`ensure_semidefinite_noise`].
//!
//! ```
//! use estim_core::checks::{ensure_finite, ensure_shape};
//! use estim_core::nalgebra::{DMatrix, Vector2};
//! use estim_core::{Error, Quantity, Stage};
//!
//! let stage = Stage::Update;
//! let z = Vector2::new(1.0, f64::NAN);
//! assert_eq!(
//!     ensure_finite(&z, stage, Quantity::Measurement),
//!     Err(Error::NonFinite { stage, quantity: Quantity::Measurement })
//! );
//! let h = DMatrix::<f64>::zeros(2, 3);
//! assert!(ensure_shape(&h, 2, 3, stage, Quantity::Jacobian).is_ok());
//! assert!(ensure_shape(&h, 3, 3, stage, Quantity::Jacobian).is_err());
//! ```

use nalgebra::{
    DefaultAllocator, Dim, IsContiguous, Matrix, OMatrix, RawStorage, allocator::Allocator,
};

use crate::error::{Error, Quantity, Result, Stage};
use crate::linalg::{psd_factor, psd_tolerance, tolerance_for};
use crate::scalar::{Real, real};

/// Whether every entry of `m` is finite. A branch-free scan of the contiguous storage
/// ([`slice_finite`]; an early-exit `iter().all()` over nalgebra's generic iterator costs ≈ 4×
/// more, which is a fifth of a small filter step). Needs contiguous storage (owned matrices and
/// vectors); for a strided view use `view.iter().all(|v| v.is_finite())`.
///
/// ```
/// use estim_core::checks::all_finite;
/// use estim_core::nalgebra::Matrix2;
///
/// assert!(all_finite(&Matrix2::new(1.0, 2.0, 3.0, 4.0)));
/// assert!(!all_finite(&Matrix2::new(1.0, f64::INFINITY, 3.0, 4.0)));
/// ```
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn all_finite<T: Real, R: Dim, C: Dim, S: RawStorage<T, R, C> + IsContiguous>(
    m: &Matrix<T, R, C, S>,
) -> bool {
    slice_finite(m.as_slice())
}

/// Whether every value is finite, without branching: Σ (v − v) over the values is 0 when all
/// are finite and NaN otherwise (v − v is 0 for a finite v, NaN for ±∞ and NaN), summed in 8
/// independent lanes so that it vectorises. Two flops per value, where `is_finite` costs an
/// absolute value, two comparisons and two masks.
///
/// ```
/// use estim_core::checks::slice_finite;
///
/// assert!(slice_finite(&[1.0, f64::MAX, -f64::MAX]));
/// let mut values = vec![0.5; 20];
/// values[17] = f64::NAN;
/// assert!(!slice_finite(&values));
/// ```
#[cfg_attr(not(debug_assertions), inline(always))]
#[allow(clippy::eq_op)] // v − v is the test: it is not 0 for ±∞ and NaN.
pub fn slice_finite<T: Real>(values: &[T]) -> bool {
    const LANES: usize = 8;
    if values.len() < 2 * LANES {
        // Short (mostly static-size) scans: the plain fold unrolls into less code (the lanes
        // cost the 3/2 static KF step 12 %).
        return values.iter().fold(true, |ok, v| ok & v.is_finite());
    }
    let mut lanes = [T::zero(); LANES];
    let mut chunks = values.chunks_exact(LANES);
    for chunk in &mut chunks {
        for (lane, &v) in lanes.iter_mut().zip(chunk) {
            *lane += v - v;
        }
    }
    for (lane, &v) in lanes.iter_mut().zip(chunks.remainder()) {
        *lane += v - v;
    }
    lanes.iter().fold(T::zero(), |sum, &lane| sum + lane) == T::zero()
}

/// `Ok(())` if every entry of `m` is finite, else [`Error::NonFinite`].
///
/// ```
/// use estim_core::checks::ensure_finite;
/// use estim_core::nalgebra::Vector2;
/// use estim_core::{Error, Quantity, Stage};
///
/// let (stage, quantity) = (Stage::Update, Quantity::Measurement);
/// assert!(ensure_finite(&Vector2::new(1.0, 2.0), stage, quantity).is_ok());
/// assert_eq!(
///     ensure_finite(&Vector2::new(1.0, f64::NEG_INFINITY), stage, quantity),
///     Err(Error::NonFinite { stage, quantity })
/// );
/// ```
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn ensure_finite<T: Real, R: Dim, C: Dim, S: RawStorage<T, R, C> + IsContiguous>(
    m: &Matrix<T, R, C, S>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()> {
    finite_or_error(all_finite(m), stage, quantity)
}

/// `Ok(())` if `finite`, else [`Error::NonFinite`]: for passes that check finiteness as they
/// write (e.g. the filters' symmetric maps).
///
/// ```
/// use estim_core::checks::finite_or_error;
/// use estim_core::{Error, Quantity, Stage};
///
/// let (stage, quantity) = (Stage::Update, Quantity::Innovation);
/// assert!(finite_or_error(true, stage, quantity).is_ok());
/// assert_eq!(
///     finite_or_error(false, stage, quantity),
///     Err(Error::NonFinite { stage, quantity })
/// );
/// ```
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn finite_or_error(finite: bool, stage: Stage, quantity: Quantity) -> Result<()> {
    if finite {
        Ok(())
    } else {
        Err(Error::NonFinite { stage, quantity })
    }
}

/// `Ok(())` if `m` is `rows × cols`, else [`Error::DimensionMismatch`].
///
/// Static sizes always pass; the check matters for runtime (`Dyn`) sizes.
///
/// ```
/// use estim_core::checks::ensure_shape;
/// use estim_core::nalgebra::DVector;
/// use estim_core::{Error, Quantity, Stage};
///
/// let (stage, quantity) = (Stage::Update, Quantity::Measurement);
/// let z = DVector::<f64>::zeros(3);
/// assert!(ensure_shape(&z, 3, 1, stage, quantity).is_ok());
/// assert_eq!(
///     ensure_shape(&z, 2, 1, stage, quantity),
///     Err(Error::DimensionMismatch {
///         stage,
///         quantity,
///         expected_rows: 2,
///         expected_cols: 1,
///         found_rows: 3,
///         found_cols: 1,
///     })
/// );
/// ```
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

/// Replaces `m` by (m + mᵀ)/2, in place.
///
/// # Panics
/// When `m` is not square (runtime sizes only: a programmer error, as any shape misuse).
///
/// ```
/// use estim_core::checks::symmetrize;
/// use estim_core::nalgebra::Matrix2;
///
/// let mut m = Matrix2::new(2.0, 1.0, 0.5, 2.0);
/// symmetrize(&mut m);
/// assert_eq!(m, Matrix2::new(2.0, 0.75, 0.75, 2.0));
/// ```
#[inline]
#[track_caller]
pub fn symmetrize<T: Real, D: Dim>(m: &mut OMatrix<T, D, D>)
where
    DefaultAllocator: Allocator<D, D>,
{
    let half = real::<T>(0.5);
    let n = m.nrows();
    assert_eq!(
        n,
        m.ncols(),
        "symmetrize: a {n} × {} matrix is not square",
        m.ncols()
    );
    for j in 0..n {
        for i in (j + 1)..n {
            let v = (m[(i, j)] + m[(j, i)]) * half;
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

/// `Ok(())` if `m` is symmetric within `√ε · max|mᵢⱼ|` (the largest finite entry), else
/// [`Error::NotSymmetric`] naming the worst pair. A pair is symmetric if equal (±∞ included)
/// or within that tolerance; a pair with a NaN never is, and is the worst. A runtime-sized `m`
/// that is not square is an [`Error::DimensionMismatch`].
///
/// ```
/// use estim_core::checks::ensure_symmetric;
/// use estim_core::nalgebra::Matrix2;
/// use estim_core::{Error, Quantity, Stage};
///
/// let (stage, quantity) = (Stage::Update, Quantity::MeasurementNoise);
/// // Asymmetric by round-off only (10⁻¹², far below √ε · 2): accepted.
/// assert!(ensure_symmetric(&Matrix2::new(2.0, 1.0, 1.0 + 1e-12, 2.0), stage, quantity).is_ok());
/// assert_eq!(
///     ensure_symmetric(&Matrix2::new(2.0, 1.0, 0.5, 2.0), stage, quantity),
///     Err(Error::NotSymmetric { stage, quantity, row: 1, col: 0 })
/// );
/// ```
pub fn ensure_symmetric<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D, D>,
{
    ensure_square(m, stage, quantity)?;
    let n = m.nrows();
    let scale = m
        .iter()
        .filter(|v| v.is_finite())
        .fold(T::zero(), |a, v| a.max(v.abs()));
    let tol = T::default_epsilon().sqrt() * scale;
    // The worst asymmetric pair so far: its gap and position; a NaN gap (a NaN entry)
    // outranks every other, ∞ included.
    let is_nan = |x: T| x.partial_cmp(&x).is_none();
    let mut worst: Option<(T, usize, usize)> = None;
    for j in 0..n {
        for i in (j + 1)..n {
            let (lower, upper) = (m[(i, j)], m[(j, i)]);
            let gap = (lower - upper).abs();
            if lower == upper || gap <= tol {
                continue;
            }
            let worse = worst.is_none_or(|(w, _, _)| !is_nan(w) && (is_nan(gap) || gap > w));
            if worse {
                worst = Some((gap, i, j));
            }
        }
    }
    match worst {
        Some((_, row, col)) => Err(Error::NotSymmetric {
            stage,
            quantity,
            row,
            col,
        }),
        None => Ok(()),
    }
}

/// `Ok(())` unless a diagonal entry of the square `m` is below −τ (τ = 16 n ε max|mᵢᵢ|, the tolerance of [`psd_factor`]), else
/// [`Error::NotPositiveSemiDefinite`]. A necessary condition for positive semi-definiteness
/// (variances are not negative) in O(n): for noise matrices met every step, where
/// [`ensure_psd`] would cost a factorisation. NaN entries pass (finiteness is checked
/// separately). A runtime-sized `m` that is not square is an [`Error::DimensionMismatch`].
///
/// ```
/// use estim_core::checks::ensure_nonnegative_diagonal;
/// use estim_core::nalgebra::Matrix2;
/// use estim_core::{Error, Quantity, Stage};
///
/// let (stage, quantity) = (Stage::Prediction, Quantity::ProcessNoise);
/// // −10⁻²⁰ is round-off (the tolerance is 32 ε here): accepted.
/// assert!(ensure_nonnegative_diagonal(&Matrix2::new(1.0, 0.0, 0.0, -1e-20), stage, quantity).is_ok());
/// assert_eq!(
///     ensure_nonnegative_diagonal(&Matrix2::new(1.0, 0.0, 0.0, -0.1), stage, quantity),
///     Err(Error::NotPositiveSemiDefinite { stage, quantity })
/// );
/// ```
pub fn ensure_nonnegative_diagonal<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D, D>,
{
    /// The rare case: some variance is negative; is it beyond round-off?
    #[cold]
    fn beyond_round_off<T: Real, D: Dim>(m: &OMatrix<T, D, D>) -> bool
    where
        DefaultAllocator: Allocator<D, D>,
    {
        let floor = -psd_tolerance(m);
        (0..m.nrows()).any(|i| m[(i, i)] < floor)
    }
    ensure_square(m, stage, quantity)?;
    let negative = (0..m.nrows()).any(|i| m[(i, i)] < T::zero());
    if negative && beyond_round_off(m) {
        Err(Error::NotPositiveSemiDefinite { stage, quantity })
    } else {
        Ok(())
    }
}

/// `Ok(())` if the noise covariance `m` (a Q(x, u, Δt) or R(x) evaluated at a step) is
/// positive semi-definite by [`psd_factor`]'s rule, else [`Error::NotPositiveSemiDefinite`]
/// naming `quantity`. The rule, with τ = 16 n ε max|sᵢᵢ|: every pivot of
/// S = L D Lᵀ is ≥ −τ, and where a pivot is within τ of zero (a direction without variance)
/// its remaining covariances are within √(τ max|sᵢᵢ|) + τ. That second bound is of order
/// √ε max|sᵢᵢ|, so where the diagonal has zeros an eigenvalue about that negative can pass
/// (S with s₁₂ = s₂₁ = 10⁻⁸, s₃₃ = 1 and zeros elsewhere, eigenvalue −10⁻⁸ against
/// √(τ · 1) ≈ 10⁻⁷); the filters' own covariance factorisations use the same rule.
/// Non-finite entries pass, as in [`ensure_nonnegative_diagonal`]: the filters check
/// finiteness where it costs nothing extra and name the culprit then. The filters use the
/// symmetric part S = (M + Mᵀ)/2, so that is what is checked (formed as M/2 + Mᵀ/2, which
/// does not overflow). Cheapest test first:
///
/// 1. **Diagonally dominant** (Gershgorin: every eigenvalue of S lies in some disc
///    [sᵢᵢ − rᵢ, sᵢᵢ + rᵢ], rᵢ = Σⱼ≠ᵢ |sᵢⱼ|, so sᵢᵢ ≥ rᵢ for all i gives λ ≥ 0): O(n²) additions
///    and comparisons, no factorisation. Every diagonal noise passes here.
/// 2. Otherwise S = L D Lᵀ without pivoting or square roots, in `work` (its shape is made
///    m's, allocating only if it differs), with [`psd_factor`]'s rule for a pivot within the
///    tolerance of zero: a direction without variance, whose remaining covariances must
///    vanish (|sᵢⱼ|² ≤ sᵢᵢ sⱼⱼ). A rank-deficient Γ W Γᵀ (white-acceleration noise) passes
///    here; n³/6 multiply-adds, inlined.
/// 3. Only if a pivot is below −tolerance or a zero-variance column does not vanish (which
///    round-off in an unpivoted order can cause for a singular S), [`psd_factor`] with
///    diagonal pivoting decides (it allocates for runtime sizes: the rare case).
///
/// Semi-definite noise is legitimate (a bias without process noise, a component measured
/// exactly); the filters check S = cov ẑ + R positive definite separately. `work` is
/// unspecified afterwards.
///
/// ```
/// use estim_core::checks::ensure_semidefinite_noise;
/// use estim_core::nalgebra::Matrix2;
/// use estim_core::{Error, Quantity, Stage};
///
/// let mut work = Matrix2::zeros();
/// let stage = Stage::Prediction;
/// let q = Quantity::ProcessNoise;
/// // Rank one: x₂ = 2 x₁ exactly. Semi-definite, accepted.
/// assert!(ensure_semidefinite_noise(&Matrix2::new(1.0, 2.0, 2.0, 4.0), &mut work, stage, q).is_ok());
/// // A positive diagonal but an eigenvalue of −1: refused.
/// assert_eq!(
///     ensure_semidefinite_noise(&Matrix2::new(1.0, 2.0, 2.0, 1.0), &mut work, stage, q),
///     Err(Error::NotPositiveSemiDefinite { stage, quantity: q })
/// );
/// ```
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn ensure_semidefinite_noise<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    work: &mut OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    let n = m.nrows();
    let (mut dominant, mut max_diag) = (true, T::zero());
    for i in 0..n {
        let mut radius = T::zero();
        for j in 0..n {
            if j != i {
                radius += symmetric_entry(m, i, j).abs();
            }
        }
        dominant &= m[(i, i)] >= radius;
        max_diag = max_diag.max(m[(i, i)].abs());
    }
    if dominant {
        return Ok(());
    }
    if work.shape() != m.shape() {
        *work = m.clone_owned();
    }
    if semidefinite_ldl(m, work, max_diag) {
        return Ok(());
    }
    pivoted_noise_check(m, work, stage, quantity)
}

/// sᵢⱼ = (mᵢⱼ + mⱼᵢ)/2, formed as mᵢⱼ/2 + mⱼᵢ/2 so that finite entries cannot overflow.
#[cfg_attr(not(debug_assertions), inline(always))]
fn symmetric_entry<T: Real, D: Dim>(m: &OMatrix<T, D, D>, i: usize, j: usize) -> T
where
    DefaultAllocator: Allocator<D, D>,
{
    let half = real::<T>(0.5);
    m[(i, j)] * half + m[(j, i)] * half
}

/// Tier 2 of [`ensure_semidefinite_noise`]: S = (M + Mᵀ)/2 = L D Lᵀ, dⱼ = sⱼⱼ − Σₖ₍ⱼ lⱼₖ² dₖ
/// and lᵢⱼ = (sᵢⱼ − Σₖ₍ⱼ lᵢₖ lⱼₖ dₖ) / dⱼ, with lᵢⱼ below the diagonal of `work` and dⱼ on it.
/// `true` if every pivot is above the tolerance or within it with a vanishing column (then
/// set to zero, as the PSD factorisation does); `false` at a pivot below −tolerance, a
/// non-vanishing zero-variance column, or a NaN.
#[cfg_attr(not(debug_assertions), inline(always))]
fn semidefinite_ldl<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    work: &mut OMatrix<T, D, D>,
    max_diag: T,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    let tol = tolerance_for(n, max_diag);
    let off_tol = (tol * max_diag).sqrt() + tol;
    for j in 0..n {
        let d = (0..j).fold(m[(j, j)], |d, k| {
            let l = work[(j, k)];
            d - l * l * work[(k, k)]
        });
        if !(d >= -tol) {
            return false;
        }
        let zero = d <= tol;
        let scale = if zero { T::zero() } else { T::one() / d };
        work[(j, j)] = if zero { T::zero() } else { d };
        for i in (j + 1)..n {
            let s = symmetric_entry(m, i, j);
            let w = (0..j).fold(s, |w, k| w - work[(i, k)] * work[(j, k)] * work[(k, k)]);
            // A zero-variance direction: its covariances must vanish (negated: NaN fails).
            if zero && !(w.abs() <= off_tol) {
                return false;
            }
            work[(i, j)] = w * scale;
        }
    }
    true
}

/// Tier 3 of [`ensure_semidefinite_noise`], out of line (the rare case): non-finite entries
/// pass (left to the finiteness checks); otherwise [`psd_factor`] decides (its Cholesky with
/// zero pivots, then, if that fails, with diagonal pivoting).
#[cold]
#[inline(never)]
fn pivoted_noise_check<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    work: &mut OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    if !all_finite(m) {
        return Ok(());
    }
    let n = m.nrows();
    for j in 0..n {
        for i in 0..n {
            work[(i, j)] = symmetric_entry(m, i, j);
        }
    }
    psd_factor(work, stage)
        .map(|_| ())
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
}

/// `Ok(())` if the symmetric `m` is positive semi-definite within τ = 16 n ε max|mᵢᵢ| ([`psd_factor`]'s rule).
/// A runtime-sized `m` that is not square is an [`Error::DimensionMismatch`].
///
/// ```
/// use estim_core::checks::ensure_psd;
/// use estim_core::nalgebra::Matrix2;
/// use estim_core::{Error, Quantity, Stage};
///
/// let (stage, quantity) = (Stage::Update, Quantity::Covariance);
/// // Rank one, semi-definite: accepted.
/// assert!(ensure_psd(&Matrix2::new(1.0, 1.0, 1.0, 1.0), stage, quantity).is_ok());
/// // Eigenvalues 3 and −1: refused.
/// assert_eq!(
///     ensure_psd(&Matrix2::new(1.0, 2.0, 2.0, 1.0), stage, quantity),
///     Err(Error::NotPositiveSemiDefinite { stage, quantity })
/// );
/// ```
pub fn ensure_psd<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    ensure_square(m, stage, quantity)?;
    psd_factor(m, stage)
        .map(|_| ())
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
}

/// `Ok(())` if `m` is square, else the [`Error::DimensionMismatch`] of an n × n matrix with
/// its n rows (a runtime-sized matrix the checks above would index out of bounds).
#[inline]
fn ensure_square<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D, D>,
{
    ensure_shape(m, m.nrows(), m.nrows(), stage, quantity)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// Negative variances are rejected, round-off below the PSD tolerance and NaN are not.
    #[test]
    fn ensure_nonnegative_diagonal_rejects_negative_variances() {
        let check = |d: &[f64]| {
            let m = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(d));
            ensure_nonnegative_diagonal(&m, Stage::Update, Quantity::MeasurementNoise)
        };
        let rejected = Err(Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        });
        assert_eq!(check(&[-0.5, 0.09]), rejected);
        assert_eq!(check(&[1.0, 2.0, -1e-6]), rejected);
        assert_eq!(check(&[1.0, 2.0, -1e-17]), Ok(()));
        assert_eq!(check(&[1.0, 0.0, f64::NAN]), Ok(()));
        assert_eq!(check(&[]), Ok(()));
    }

    /// The per-step noise check against the eigenvalues of the symmetric part, through each
    /// tier: diagonally dominant (with an asymmetric matrix), rank-deficient Γ Γᵀ (the
    /// factorisation tier), a rank-deficient matrix whose unpivoted factorisation stops at a
    /// zero pivot, indefinite with a positive diagonal, and a negative variance beyond
    /// round-off; runtime and static sizes, f64 and f32, and a `work` of the wrong size.
    #[test]
    fn ensure_semidefinite_noise_agrees_with_the_eigenvalues() {
        let (stage, q) = (Stage::Prediction, Quantity::ProcessNoise);
        let refused = Err(Error::NotPositiveSemiDefinite { stage, quantity: q });
        let g = DMatrix::from_row_slice(3, 1, &[0.3, -1.2, 0.7]);
        let cases: Vec<(DMatrix<f64>, bool)> = vec![
            (DMatrix::from_diagonal_element(3, 3, 0.0), true),
            (
                DMatrix::from_row_slice(3, 3, &[2.0, 0.5, -1.0, 0.3, 1.0, 0.2, -1.0, 0.4, 1.5]),
                true,
            ),
            (&g * g.transpose(), true),
            // Zero first pivot with a vanishing column, then a rank-one block.
            (
                DMatrix::from_row_slice(3, 3, &[0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 2.0, 4.0]),
                true,
            ),
            (
                DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
                false,
            ),
            // Zero pivot whose column does not vanish: indefinite.
            (
                DMatrix::from_row_slice(3, 3, &[0.0, 0.1, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0, 1.0]),
                false,
            ),
            (
                DMatrix::from_diagonal(&DVector::from_row_slice(&[1.0, -1e-3, 1.0])),
                false,
            ),
        ];
        for (m, psd) in cases {
            let sym = (&m + m.transpose()) * 0.5;
            let lambda = sym.clone().symmetric_eigenvalues().min();
            assert_eq!(lambda >= -1e-12, psd, "{m}: λ_min {lambda}");
            let expected = if psd { Ok(()) } else { refused };
            assert_eq!(
                ensure_semidefinite_noise(&m, &mut m.clone(), stage, q),
                expected
            );
            assert_eq!(
                ensure_semidefinite_noise(&m, &mut DMatrix::zeros(1, 1), stage, q),
                expected
            );
            let fixed = nalgebra::Matrix3::from_iterator(m.iter().copied());
            assert_eq!(
                ensure_semidefinite_noise(&fixed, &mut nalgebra::Matrix3::zeros(), stage, q),
                expected
            );
            let single = m.map(|v| v as f32);
            assert_eq!(
                ensure_semidefinite_noise(&single, &mut single.clone(), stage, q),
                expected
            );
        }
        // Rank one with entries near the largest finite value (2 × 2 and 3 × 3: tiers 2 and 3
        // after Gershgorin fails on the asymmetric one): the symmetric part is formed as
        // M/2 + Mᵀ/2, so it does not overflow into a refusal.
        let huge = DMatrix::from_element(2, 2, 1e308);
        assert_eq!(
            ensure_semidefinite_noise(&huge, &mut huge.clone(), stage, q),
            Ok(())
        );
        let huge = nalgebra::Matrix3::new(1e308, 1e308, 0.0, 1e308, 1e308, 0.0, 0.0, 0.0, 1.0);
        assert_eq!(
            ensure_semidefinite_noise(&huge, &mut nalgebra::Matrix3::zeros(), stage, q),
            Ok(())
        );
        // A A ᵀ of rank 2 with columns of very different scales (found by a random search):
        // round-off in the unpivoted L D Lᵀ leaves a non-vanishing zero-variance column, so
        // tier 2 fails it and the pivoted factorisation (tier 3) accepts it.
        let singular = DMatrix::<f64>::from_column_slice(
            3,
            3,
            &[
                916.5783855043492,
                -641611.052442303,
                -0.7516908505295964,
                -641611.052442303,
                449132098.4113805,
                0.1123807364296523,
                -0.7516908505295964,
                0.1123807364296523,
                8176.54452238597,
            ],
        );
        let lambda = singular.clone().symmetric_eigenvalues();
        assert!(lambda.min().abs() < 1e-6 * lambda.max(), "{lambda}");
        let max_diag = 449132098.4113805;
        assert!(!semidefinite_ldl(
            &singular,
            &mut singular.clone(),
            max_diag
        ));
        assert_eq!(
            ensure_semidefinite_noise(&singular, &mut singular.clone(), stage, q),
            Ok(())
        );
        // Non-finite entries are left to the finiteness checks.
        let nan = DMatrix::from_row_slice(2, 2, &[1.0, f64::NAN, f64::NAN, 1.0]);
        assert_eq!(
            ensure_semidefinite_noise(&nan, &mut nan.clone(), stage, q),
            Ok(())
        );
    }

    /// A NaN or an infinite entry makes a pair asymmetric unless both entries are the same
    /// infinity; a NaN pair is named before a larger finite or infinite gap.
    #[test]
    fn ensure_symmetric_sees_non_finite_pairs() {
        let check = |rows: &[f64]| {
            let m = DMatrix::from_row_slice(3, 3, rows);
            match ensure_symmetric(&m, Stage::Construction, Quantity::Covariance) {
                Ok(()) => None,
                Err(Error::NotSymmetric { row, col, .. }) => Some((row, col)),
                Err(e) => panic!("unexpected {e:?}"),
            }
        };
        let (nan, inf) = (f64::NAN, f64::INFINITY);
        assert_eq!(
            check(&[1.0, 0.0, 0.0, nan, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((1, 0))
        );
        assert_eq!(
            check(&[1.0, 5.0, 0.0, inf, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((1, 0))
        );
        assert_eq!(
            check(&[1.0, 9.0, nan, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((2, 0))
        );
        assert_eq!(
            check(&[1.0, inf, 0.0, 0.0, 1.0, nan, 0.0, 0.0, 1.0]),
            Some((2, 1))
        );
        assert_eq!(check(&[1.0, inf, 0.0, inf, 1.0, 0.0, 0.0, 0.0, 1.0]), None);
        assert_eq!(check(&[inf, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0]), None);
        // Finite gaps: still against √ε of the largest (finite) entry.
        assert_eq!(
            check(&[4.0, 1.0, 0.0, 1.0 + 1e-9, 1.0, 0.0, 0.0, 0.0, 1.0]),
            None
        );
        assert_eq!(
            check(&[4.0, 1.0, 0.0, 1.0 + 1e-6, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((1, 0))
        );
    }

    /// Every length around the 8 lanes, every position, each kind of non-finite value; the
    /// extreme finite values (whose sum would overflow) still count as finite.
    #[test]
    fn slice_finite_finds_any_non_finite_value() {
        for len in 0..=19 {
            let finite: Vec<f64> = (0..len)
                .map(|k| [f64::MAX, -f64::MAX, f64::MIN_POSITIVE, -0.0, 1.5][k % 5])
                .collect();
            assert!(slice_finite(&finite), "len {len}");
            for at in 0..len {
                for bad in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
                    let mut values = finite.clone();
                    values[at] = bad;
                    assert!(!slice_finite(&values), "len {len}, {bad} at {at}");
                }
            }
        }
    }
}
