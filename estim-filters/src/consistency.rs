//! Consistency statistics: is the filter's covariance an honest account of its error?
//!
//! A filter is *consistent* when its errors are zero-mean with the covariance it reports and
//! its innovations are white with the covariance it predicts (Bar-Shalom, Li & Kirubarajan,
//! *Estimation with Applications to Tracking and Navigation*, 2001, §5.4). The statistics here
//! test that, one run or many:
//!
//! | statistic | formula | distribution when consistent |
//! |---|---|---|
//! | [`nees`] | ε = eᵀ P⁻¹ e, e = x − x̂ | χ²ₙ |
//! | [`nis`] | ε_ν = νᵀ S⁻¹ ν | χ²ₘ (also in every [`UpdateReport`]) |
//! | average of `runs` of them | ε̄ = (1/N) Σ εᵢ | χ²_{N·n} / N: [`ChiSquareBand`] |
//! | [`normalized_autocorrelation`] | ρ(l), see there | ≈ N(0, 1/K): [`autocorrelation_bound`] |
//! | [`LogLikelihood`] | Σ ln p(zₖ \| Zₖ₋₁) | (for model comparison) |
//!
//! Every statistic is computed in `f64` whatever the filter's scalar: they are summaries, and
//! the χ² quantiles come from [`statrs`] in `f64`.
//!
//! The Monte Carlo runner ([`crate::monte_carlo`]) accumulates these over many realizations;
//! its [`EnsembleStats::verdict`](crate::monte_carlo::EnsembleStats::verdict) turns them into
//! a [`Verdict`], which this module defines together with the rule that decides a check made
//! of many single tests ([`FamilyRule`]).
//!
//! ```
//! use estim_filters::consistency::{nees, ChiSquareBand};
//! use estim_core::nalgebra::{Matrix2, Vector2};
//!
//! let p = Matrix2::new(4.0, 0.0, 0.0, 1.0);
//! assert_eq!(nees(&Vector2::new(2.0, 1.0), &p)?, 2.0);
//! // The average NEES of 50 runs of a 2-state filter lies in this band with probability 95%:
//! let band = ChiSquareBand::two_sided(2, 50, 0.95)?;
//! assert!(band.lower < 2.0 && 2.0 < band.upper);
//! # Ok::<(), estim_filters::ValidationError>(())
//! ```

use estim_core::checks::ensure_shape;
use estim_core::linalg::inverse_quadratic_form;
use estim_core::nalgebra::{self, DefaultAllocator, Dim, OMatrix, OVector, allocator::Allocator};
use estim_core::{Error, Quantity, Real, Stage};

use crate::validation::{Result, Setting, ValidationError};

use crate::report::UpdateReport;

mod verdict;

pub use crate::chi_square::MAX_DEGREES_OF_FREEDOM;
pub(crate) use verdict::FamilyTest;
pub use verdict::{Check, CheckResult, FamilyRule, Location, Outcome, Verdict, Worst};

pub(crate) const STAGE: Stage = Stage::ConsistencyCheck;

/// `T` → `f64` (NaN if the conversion is impossible, which the finiteness checks then catch).
#[inline]
pub(crate) fn to_f64<T: Real>(v: T) -> f64 {
    nalgebra::try_convert::<T, f64>(v).unwrap_or(f64::NAN)
}

/// `Ok(c)` if 0 < c < 1.
pub(crate) fn validate_confidence(confidence: f64) -> Result<f64> {
    if confidence > 0.0 && confidence < 1.0 {
        Ok(confidence)
    } else {
        Err(ValidationError::InvalidSetting {
            setting: Setting::Confidence,
            value: confidence,
        })
    }
}

/// Quantiles and two-sided p-values of the reference distributions, from statrs.
pub(crate) mod dist {
    use super::{Result, Setting, ValidationError};
    use statrs::distribution::{ChiSquared, ContinuousCDF, Normal, StudentsT};

    use crate::chi_square;

    fn dof_error(dof: f64) -> ValidationError {
        ValidationError::InvalidSetting {
            setting: Setting::DegreesOfFreedom,
            value: dof,
        }
    }

    fn chi2(dof: usize) -> Result<ChiSquared> {
        chi_square::distribution(dof).ok_or_else(|| dof_error(dof as f64))
    }

    fn student(dof: usize) -> Result<StudentsT> {
        if dof == 0 {
            return Err(dof_error(0.0));
        }
        StudentsT::new(0.0, 1.0, dof as f64).map_err(|_| dof_error(dof as f64))
    }

    /// The `p` quantile of χ²_dof; `p` must be in (0, 1).
    pub(crate) fn chi2_quantile(dof: usize, p: f64) -> Result<f64> {
        Ok(chi2(dof)?.inverse_cdf(p))
    }

    /// Two-sided p-value of an observed χ²_dof value x: 2 min(F(x), 1 − F(x)).
    pub(crate) fn chi2_p_value(x: f64, dof: usize) -> Result<f64> {
        let d = chi2(dof)?;
        if x.is_nan() {
            return Ok(0.0);
        }
        Ok((2.0 * d.cdf(x).min(d.sf(x))).min(1.0))
    }

    /// The `(1 + confidence)/2` quantile of N(0, 1).
    pub(crate) fn normal_two_sided(confidence: f64) -> f64 {
        Normal::standard().inverse_cdf(0.5 + 0.5 * confidence)
    }

    /// 2 (1 − Φ(|z|)).
    pub(crate) fn normal_p_value(z: f64) -> f64 {
        if z.is_nan() {
            return 0.0;
        }
        (2.0 * Normal::standard().sf(z.abs())).min(1.0)
    }

    /// From this many degrees of freedom Student's t quantile is [`t_quantile_expansion`]:
    /// statrs 0.19's inversion drifts from about 2¹⁴ (6.5 · 10⁻⁷ at 2¹⁵ and p = 0.975,
    /// 1.2 · 10⁻⁴ at 10⁶, 6 · 10⁻³ at 4 · 10⁶) and from about 1.7 · 10⁷ never returns, while
    /// the expansion's next term is below 10⁻¹⁵ here (the two agree to 2 · 10⁻¹² at 2¹²–2¹³
    /// for p ≥ 0.975; at p = 0.8 statrs is off by 2 · 10⁻⁹ from 2¹⁰ on).
    pub(crate) const T_QUANTILE_EXPANSION: usize = 1 << 12;

    /// From this many degrees of freedom Student's t tail is [`t_tail_expansion`]: statrs'
    /// drifts with ν (1.4 · 10⁻¹⁰ relative here at |t| = 1, 3 · 10⁻⁷ at 2³⁰, 0.6 at 2⁵⁰; 0.5
    /// for every t at 2⁶⁰), while the expansion's next term, O(x¹¹/ν³), is below 10⁻¹¹
    /// relative for |t| ≤ 4 here.
    pub(crate) const T_TAIL_EXPANSION: usize = 1 << 16;

    /// The p quantile of Student's t with ν degrees of freedom from that of N(0, 1), z:
    /// t_p ≈ z + g₁/ν + g₂/ν² + g₃/ν³ + g₄/ν⁴ (Abramowitz & Stegun 26.7.5), with
    /// g₁ = (z³ + z)/4, g₂ = (5z⁵ + 16z³ + 3z)/96, g₃ = (3z⁷ + 19z⁵ + 17z³ − 15z)/384,
    /// g₄ = (79z⁹ + 776z⁷ + 1482z⁵ − 1920z³ − 945z)/92160.
    pub(crate) fn t_quantile_expansion(p: f64, dof: usize) -> f64 {
        let z = Normal::standard().inverse_cdf(p);
        let (z2, v) = (z * z, dof as f64);
        let g1 = z * (z2 + 1.0) / 4.0;
        let g2 = z * ((5.0 * z2 + 16.0) * z2 + 3.0) / 96.0;
        let g3 = z * (((3.0 * z2 + 19.0) * z2 + 17.0) * z2 - 15.0) / 384.0;
        let g4 = z * ((((79.0 * z2 + 776.0) * z2 + 1482.0) * z2 - 1920.0) * z2 - 945.0) / 92160.0;
        z + (g1 + (g2 + (g3 + g4 / v) / v) / v) / v
    }

    /// P(T > x) for Student's t with ν degrees of freedom, x ≥ 0, to second order in 1/ν:
    /// Q(x) + φ(x) [(x³ + x)/(4ν) + (3x⁷ − 7x⁵ − 5x³ − 3x)/(96ν²)] (Q and φ the standard
    /// normal tail and density; the second-order term checked against statrs at ν = 2⁸–2¹²,
    /// where their difference shrinks as 1/ν³).
    pub(crate) fn t_tail_expansion(x: f64, dof: usize) -> f64 {
        let (x2, v) = (x * x, dof as f64);
        let density = (-0.5 * x2).exp() / (2.0 * core::f64::consts::PI).sqrt();
        let first = x * (x2 + 1.0) / 4.0;
        let second = x * (((3.0 * x2 - 7.0) * x2 - 5.0) * x2 - 3.0) / 96.0;
        Normal::standard().sf(x) + density * (first + second / v) / v
    }

    /// The `(1 + confidence)/2` quantile of Student's t with `dof` degrees of freedom.
    pub(crate) fn t_two_sided(confidence: f64, dof: usize) -> Result<f64> {
        let p = 0.5 + 0.5 * confidence;
        if dof >= T_QUANTILE_EXPANSION {
            return Ok(t_quantile_expansion(p, dof));
        }
        Ok(student(dof)?.inverse_cdf(p))
    }

    /// 2 (1 − F_t(|t|)).
    pub(crate) fn t_p_value(t: f64, dof: usize) -> Result<f64> {
        let d = student(dof)?;
        // Before either route: statrs' incomplete beta panics on NaN.
        if t.is_nan() {
            return Ok(0.0);
        }
        let tail = if dof >= T_TAIL_EXPANSION {
            t_tail_expansion(t.abs(), dof)
        } else {
            d.sf(t.abs())
        };
        Ok((2.0 * tail).min(1.0))
    }
}

/// vᵀ A⁻¹ v for the symmetric `n × n` matrix `a` (column-major; only the lower triangle is
/// read), by the library's one covariance factorisation with a zero tolerance
/// ([`inverse_quadratic_form`] on views of the buffers): `a` is overwritten by its Cholesky
/// factor L and `v` by L⁻¹ v. `None` if `a` is not positive definite (a pivot ≤ 0 or not
/// finite).
pub(crate) fn cholesky_quadratic_form(a: &mut [f64], v: &mut [f64], n: usize) -> Option<f64> {
    let mut a = nalgebra::DMatrixViewMut::from_slice(&mut a[..n * n], n, n);
    let mut v = nalgebra::DVectorViewMut::from_slice(&mut v[..n], n);
    inverse_quadratic_form(&mut a, &mut v)
}

fn normalized_square<T: Real, N: Dim>(
    v: &OVector<T, N>,
    c: &OMatrix<T, N, N>,
    vector: Quantity,
    matrix: Quantity,
) -> Result<f64>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    let n = v.nrows();
    ensure_shape(c, n, n, STAGE, matrix)?;
    let mut x: Vec<f64> = v.iter().map(|&t| to_f64(t)).collect();
    let mut a: Vec<f64> = c.iter().map(|&t| to_f64(t)).collect();
    if !x.iter().all(|t| t.is_finite()) {
        return Err(Error::NonFinite {
            stage: STAGE,
            quantity: vector,
        }
        .into());
    }
    if !a.iter().all(|t| t.is_finite()) {
        return Err(Error::NonFinite {
            stage: STAGE,
            quantity: matrix,
        }
        .into());
    }
    cholesky_quadratic_form(&mut a, &mut x, n).ok_or(ValidationError::Estimation(
        Error::NotPositiveDefinite {
            stage: STAGE,
            quantity: matrix,
        },
    ))
}

/// The normalised estimation error squared ε = eᵀ P⁻¹ e of an error e = x − x̂ and the
/// covariance P the filter reported for it (Bar-Shalom et al. §5.4.2).
///
/// If the filter is consistent and its error Gaussian, ε ~ χ²ₙ (mean n). P is factorised by
/// Cholesky (only its lower triangle is read), never inverted. Computed in `f64`.
///
/// Errors: [`Error::NotPositiveDefinite`] if P is not positive definite, [`Error::NonFinite`],
/// [`Error::DimensionMismatch`] for runtime sizes that disagree.
pub fn nees<T: Real, N: Dim>(error: &OVector<T, N>, covariance: &OMatrix<T, N, N>) -> Result<f64>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    normalized_square(error, covariance, Quantity::Mean, Quantity::Covariance)
}

/// The normalised innovation squared νᵀ S⁻¹ ν of an innovation ν with predicted covariance S
/// (what [`UpdateReport::nis`] holds; this recomputes it in `f64` from any ν and S). χ²ₘ when
/// the filter is consistent. Errors as [`nees`].
pub fn nis<T: Real, M: Dim>(
    innovation: &OVector<T, M>,
    innovation_covariance: &OMatrix<T, M, M>,
) -> Result<f64>
where
    DefaultAllocator: Allocator<M> + Allocator<M, M>,
{
    normalized_square(
        innovation,
        innovation_covariance,
        Quantity::Innovation,
        Quantity::InnovationCovariance,
    )
}

/// The two-sided acceptance region of an average of χ² variables.
///
/// If ε₁ … ε_N are independent χ²_d (the NEES or NIS of N Monte Carlo runs of a consistent
/// filter, d = n or m), then N ε̄ = Σ εᵢ ~ χ²_{N·d}, and
///
/// ```text
/// P( lower ≤ ε̄ ≤ upper ) = confidence,   lower = χ²_{N·d}((1 − c)/2) / N,   upper = χ²_{N·d}((1 + c)/2) / N
/// ```
///
/// (Bar-Shalom et al. eq 5.4.2-8). The same holds for a time average over K steps of one run
/// (N ↦ K), and for terms of unequal dimension when `degrees_of_freedom` is their total
/// ([`ChiSquareBand::for_sum`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ChiSquareBand {
    /// Degrees of freedom of the *sum*, N·d.
    pub degrees_of_freedom: usize,
    /// Number of averaged terms N (the divisor).
    pub terms: usize,
    /// The probability the band holds, e.g. 0.95.
    pub confidence: f64,
    /// Lower end for the average: χ²_{N·d}((1 − c)/2) / N.
    pub lower: f64,
    /// Upper end for the average: χ²_{N·d}((1 + c)/2) / N.
    pub upper: f64,
}

impl ChiSquareBand {
    /// The band for the average of `runs` independent χ²_`dof` variables. Needs `dof` ≥ 1,
    /// `runs` ≥ 1, `dof` · `runs` ≤ [`MAX_DEGREES_OF_FREEDOM`] and 0 < `confidence` < 1.
    ///
    /// Example: 2 states, 50 runs, 95%: χ²₁₀₀(0.025)/50 = 1.48, χ²₁₀₀(0.975)/50 = 2.59.
    pub fn two_sided(dof: usize, runs: usize, confidence: f64) -> Result<Self> {
        if dof == 0 {
            return Err(ValidationError::InvalidSetting {
                setting: Setting::DegreesOfFreedom,
                value: 0.0,
            });
        }
        let total = dof
            .checked_mul(runs)
            .ok_or(ValidationError::InvalidSetting {
                setting: Setting::RunCount,
                value: runs as f64,
            })?;
        Self::for_sum(total, runs, confidence)
    }

    /// The band for (1/`terms`) × a χ² variable with `degrees_of_freedom` degrees of freedom:
    /// the average of `terms` independent χ² variables whose dimensions add up to
    /// `degrees_of_freedom` (e.g. NIS of measurements of different sizes).
    ///
    /// Errors: [`Setting::DegreesOfFreedom`] for 0 or more than [`MAX_DEGREES_OF_FREEDOM`]
    /// degrees of freedom, [`Setting::RunCount`] for `terms` = 0, [`Setting::Confidence`]
    /// outside (0, 1).
    pub fn for_sum(degrees_of_freedom: usize, terms: usize, confidence: f64) -> Result<Self> {
        let confidence = validate_confidence(confidence)?;
        if terms == 0 {
            return Err(ValidationError::InvalidSetting {
                setting: Setting::RunCount,
                value: 0.0,
            });
        }
        let alpha = 1.0 - confidence;
        let n = terms as f64;
        Ok(Self {
            degrees_of_freedom,
            terms,
            confidence,
            lower: dist::chi2_quantile(degrees_of_freedom, 0.5 * alpha)? / n,
            upper: dist::chi2_quantile(degrees_of_freedom, 1.0 - 0.5 * alpha)? / n,
        })
    }

    /// Whether `average` lies in [lower, upper] (`false` for NaN).
    pub fn contains(&self, average: f64) -> bool {
        self.lower <= average && average <= self.upper
    }

    /// The expected value of the average when consistent: `degrees_of_freedom / terms`.
    pub fn expected(&self) -> f64 {
        self.degrees_of_freedom as f64 / self.terms as f64
    }

    /// The two-sided p-value of `average`: 2 min(F(N ε̄), 1 − F(N ε̄)) with F the χ²_{N·d}
    /// distribution function. `average` is inside the band iff the p-value is at least
    /// 1 − confidence.
    pub fn p_value(&self, average: f64) -> Result<f64> {
        dist::chi2_p_value(average * self.terms as f64, self.degrees_of_freedom)
    }
}

/// The band and what it is for, e.g. for 2 states over 50 runs at 95 %:
///
/// ```
/// use estim_filters::consistency::ChiSquareBand;
/// let band = ChiSquareBand::two_sided(2, 50, 0.95)?;
/// assert_eq!(
///     band.to_string(),
///     "[1.48, 2.59] (95% band for the average of 50 terms, chi-square with 100 dof in all; expected 2)"
/// );
/// # Ok::<(), estim_filters::ValidationError>(())
/// ```
impl core::fmt::Display for ChiSquareBand {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let digits = f.precision().unwrap_or(3);
        let sig = |v: f64| format_significant(v, digits);
        write!(
            f,
            "[{}, {}] ({}% band for the average of {} terms, chi-square with {} dof in all; expected {})",
            sig(self.lower),
            sig(self.upper),
            self.confidence * 100.0,
            self.terms,
            self.degrees_of_freedom,
            sig(self.expected()),
        )
    }
}

/// `v` with `digits` significant digits, trailing zeros dropped (2.590 → 2.59, 2.000 → 2).
fn format_significant(v: f64, digits: usize) -> String {
    if v == 0.0 || !v.is_finite() {
        return v.to_string();
    }
    let magnitude = v.abs().log10().floor() as i32;
    let decimals = (digits as i32 - 1 - magnitude).max(0) as usize;
    let text = format!("{v:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// Running average of χ² statistics (NEES or NIS) of possibly different dimensions, e.g. the
/// NIS over the K updates of one run: Σ εₖ ~ χ²_{Σ dₖ} when consistent.
///
/// ```
/// use estim_filters::consistency::ChiSquareAverage;
/// let mut avg = ChiSquareAverage::new();
/// for nis in [0.5, 1.5, 0.75, 1.25] { avg.push(nis, 1)?; }
/// assert_eq!(avg.mean(), Some(1.0));
/// // Σ ~ χ²₄ when consistent: the average lies in [χ²₄(0.025), χ²₄(0.975)]/4 = [0.12, 2.79].
/// assert!(avg.band(0.95)?.contains(1.0));
/// # Ok::<(), estim_filters::ValidationError>(())
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChiSquareAverage {
    sum: f64,
    terms: usize,
    degrees_of_freedom: usize,
}

impl ChiSquareAverage {
    /// An empty average.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one statistic `value` ~ χ²_`dof` (`value` finite and ≥ 0, `dof` ≥ 1).
    ///
    /// Errors (nothing added): a negative or non-finite `value`
    /// ([`Error::NonFinite`]); `dof` = 0, or a total above `usize::MAX`
    /// ([`Setting::DegreesOfFreedom`]).
    pub fn push(&mut self, value: f64, dof: usize) -> Result<()> {
        if !(value >= 0.0) || !value.is_finite() {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Innovation,
            }
            .into());
        }
        if dof == 0 {
            return Err(ValidationError::InvalidSetting {
                setting: Setting::DegreesOfFreedom,
                value: 0.0,
            });
        }
        let degrees_of_freedom = self.total_dof(dof)?;
        self.sum += value;
        self.terms += 1;
        self.degrees_of_freedom = degrees_of_freedom;
        Ok(())
    }

    /// Adds the NIS of an update report (m = the innovation's dimension).
    pub fn push_report<T: Real, M: Dim>(&mut self, report: &UpdateReport<T, M>) -> Result<()>
    where
        DefaultAllocator: Allocator<M> + Allocator<M, M>,
    {
        self.push(to_f64(report.nis), report.innovation.nrows())
    }

    /// Adds everything `other` holds.
    ///
    /// Errors (nothing added): [`Setting::DegreesOfFreedom`] when the total would exceed
    /// `usize::MAX`.
    pub fn merge(&mut self, other: &Self) -> Result<()> {
        let degrees_of_freedom = self.total_dof(other.degrees_of_freedom)?;
        self.sum += other.sum;
        // terms ≤ degrees of freedom (every term has at least one), so this cannot overflow.
        self.terms += other.terms;
        self.degrees_of_freedom = degrees_of_freedom;
        Ok(())
    }

    /// The degrees of freedom with `more` added, if they fit in a `usize`.
    fn total_dof(&self, more: usize) -> Result<usize> {
        self.degrees_of_freedom
            .checked_add(more)
            .ok_or(ValidationError::InvalidSetting {
                setting: Setting::DegreesOfFreedom,
                value: more as f64,
            })
    }

    /// The average (1/K) Σ εₖ, `None` when empty.
    pub fn mean(&self) -> Option<f64> {
        (self.terms > 0).then(|| self.sum / self.terms as f64)
    }

    /// Σ εₖ.
    pub fn sum(&self) -> f64 {
        self.sum
    }

    /// The number of statistics K.
    pub fn terms(&self) -> usize {
        self.terms
    }

    /// Σ dₖ.
    pub fn degrees_of_freedom(&self) -> usize {
        self.degrees_of_freedom
    }

    /// The two-sided band of the average at `confidence` ([`ChiSquareBand::for_sum`]).
    /// Errors when empty, or above [`MAX_DEGREES_OF_FREEDOM`] degrees of freedom.
    pub fn band(&self, confidence: f64) -> Result<ChiSquareBand> {
        ChiSquareBand::for_sum(self.degrees_of_freedom, self.terms, confidence)
    }
}

/// The normalised sample autocorrelation of an innovation sequence ν₀ … ν_{K−1} at `lag` l
/// (Bar-Shalom et al. §5.4.2, eq 5.4.2-12, with the ensemble sum replaced by the time sum):
///
/// ```text
///            Σₖ νₖᵀ νₖ₊ₗ
/// ρ(l) = ─────────────────────────────────── ,   k = 0 … K − 1 − l
///        √( Σₖ νₖᵀ νₖ · Σₖ νₖ₊ₗᵀ νₖ₊ₗ )
/// ```
///
/// For a white, zero-mean sequence ρ(l), l ≥ 1, is approximately N(0, 1/K) for large K
/// (scalar innovations, or ones with equal, uncorrelated components); compare it with
/// [`autocorrelation_bound`]. For vector innovations with covariance S the variance is
/// tr(S²) / (K (tr S)²) ≤ 1/K, so the bound is conservative; whiten them first
/// (νₖ ↦ Lₖ⁻¹ νₖ with Sₖ = Lₖ Lₖᵀ) to make all components count equally.
///
/// Errors: `lag` ≥ K ([`Setting::Lag`]), innovations of different lengths, non-finite
/// values, or an all-zero sequence (ρ undefined: [`Error::NonFinite`]).
pub fn normalized_autocorrelation<T: Real, M: Dim>(
    innovations: &[OVector<T, M>],
    lag: usize,
) -> Result<f64>
where
    DefaultAllocator: Allocator<M>,
{
    let k = innovations.len();
    if lag >= k {
        return Err(ValidationError::setting(Setting::Lag, lag));
    }
    let m = innovations[0].nrows();
    for nu in innovations {
        ensure_shape(nu, m, 1, STAGE, Quantity::Innovation)?;
    }
    let dot = |a: &OVector<T, M>, b: &OVector<T, M>| -> f64 {
        a.iter()
            .zip(b.iter())
            .map(|(&x, &y)| to_f64(x) * to_f64(y))
            .sum()
    };
    let (mut cross, mut head, mut tail) = (0.0, 0.0, 0.0);
    for i in 0..(k - lag) {
        let (a, b) = (&innovations[i], &innovations[i + lag]);
        cross += dot(a, b);
        head += dot(a, a);
        tail += dot(b, b);
    }
    let rho = cross / (head * tail).sqrt();
    if rho.is_finite() {
        Ok(rho)
    } else {
        Err(Error::NonFinite {
            stage: STAGE,
            quantity: Quantity::Innovation,
        }
        .into())
    }
}

/// The two-sided bound r = z₍₁₊c₎/₂ / √K on [`normalized_autocorrelation`] for a white
/// sequence of `samples` = K innovations: P(|ρ(l)| ≤ r) ≈ `confidence` (e.g. 1.96/√K at 95%).
pub fn autocorrelation_bound(samples: usize, confidence: f64) -> Result<f64> {
    let confidence = validate_confidence(confidence)?;
    if samples == 0 {
        return Err(ValidationError::InvalidSetting {
            setting: Setting::RunCount,
            value: 0.0,
        });
    }
    Ok(dist::normal_two_sided(confidence) / (samples as f64).sqrt())
}

/// The normalised autocorrelation at one lag with its bound.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagCorrelation {
    /// The lag l ≥ 1.
    pub lag: usize,
    /// ρ(l).
    pub value: f64,
    /// z₍₁₊c₎/₂ / √K.
    pub bound: f64,
}

impl LagCorrelation {
    /// |ρ(l)| ≤ bound.
    pub fn inside(&self) -> bool {
        self.value.abs() <= self.bound
    }
}

/// The whiteness test of one innovation sequence at several lags.
#[derive(Clone, Debug, PartialEq)]
pub struct Whiteness {
    /// Number of innovations K.
    pub samples: usize,
    /// The per-lag confidence of the bounds.
    pub confidence: f64,
    /// ρ(l) for each requested lag.
    pub lags: Vec<LagCorrelation>,
}

/// Tests an innovation sequence for whiteness at each of `lags` (each ≥ 1 and < K):
/// ρ(l) from [`normalized_autocorrelation`], bound from [`autocorrelation_bound`].
///
/// ```
/// use estim_filters::consistency::{whiteness, FamilyRule};
/// use estim_core::nalgebra::Vector1;
/// // A deterministic, strongly correlated sequence: a slow sine.
/// let seq: Vec<_> = (0..200).map(|k| Vector1::new((k as f64 * 0.05).sin())).collect();
/// let test = whiteness(&seq, [1, 2, 3], 0.95)?;
/// assert!(test.lags.iter().all(|l| !l.inside()));
/// assert!(!test.check(FamilyRule::Simes)?.passed());
/// # Ok::<(), estim_filters::ValidationError>(())
/// ```
pub fn whiteness<T: Real, M: Dim>(
    innovations: &[OVector<T, M>],
    lags: impl IntoIterator<Item = usize>,
    confidence: f64,
) -> Result<Whiteness>
where
    DefaultAllocator: Allocator<M>,
{
    let samples = innovations.len();
    let bound = autocorrelation_bound(samples, confidence)?;
    let mut out = Vec::new();
    for lag in lags {
        if lag == 0 {
            return Err(ValidationError::setting(Setting::Lag, 0));
        }
        out.push(LagCorrelation {
            lag,
            value: normalized_autocorrelation(innovations, lag)?,
            bound,
        });
    }
    Ok(Whiteness {
        samples,
        confidence,
        lags: out,
    })
}

impl Whiteness {
    /// The lags as one [`Check::Whiteness`] at the sequence's confidence, its single tests
    /// combined by `rule` ([`FamilyRule::Simes`] unless the lags are known to be
    /// independent; for white noise they asymptotically are).
    pub fn check(&self, rule: FamilyRule) -> Result<CheckResult> {
        let mut family = FamilyTest::new(Check::Whiteness, self.confidence, rule)?;
        let bound = autocorrelation_bound(self.samples, family.band_confidence())?;
        let scale = (self.samples as f64).sqrt();
        for l in &self.lags {
            family.add(
                Location::Lag { lag: l.lag },
                l.value,
                -bound,
                bound,
                dist::normal_p_value(l.value * scale),
            );
        }
        Ok(family.finish())
    }
}

/// Sum of the log-likelihoods ln p(zₖ | z₁ … zₖ₋₁) = −½ (νᵀS⁻¹ν + ln det S + m ln 2π) of a run's
/// measurements, as each [`UpdateReport`] gives them: the log-likelihood of the whole
/// measurement record under the filter's model (prediction error decomposition), for comparing
/// models or tuning by maximum likelihood.
///
/// ```
/// use estim_filters::consistency::LogLikelihood;
/// let mut ll = LogLikelihood::new();
/// ll.add_value(-1.5);
/// ll.add_value(-0.5);
/// assert_eq!((ll.total(), ll.count(), ll.mean()), (-2.0, 2, Some(-1.0)));
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LogLikelihood {
    total: f64,
    count: usize,
}

impl LogLikelihood {
    /// Zero measurements, total 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the log-likelihood of one update (gated updates included: their likelihood was
    /// computed from the same prediction).
    pub fn add<T: Real, M: Dim>(&mut self, report: &UpdateReport<T, M>)
    where
        DefaultAllocator: Allocator<M> + Allocator<M, M>,
    {
        self.add_value(to_f64(report.log_likelihood));
    }

    /// Adds one log-likelihood value.
    pub fn add_value(&mut self, log_likelihood: f64) {
        self.total += log_likelihood;
        self.count += 1;
    }

    /// Adds everything `other` holds.
    pub fn merge(&mut self, other: &Self) {
        self.total += other.total;
        self.count += other.count;
    }

    /// Σ ln p(zₖ | Zₖ₋₁).
    pub fn total(&self) -> f64 {
        self.total
    }

    /// The number of measurements added.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The average per measurement, `None` when empty.
    pub fn mean(&self) -> Option<f64> {
        (self.count > 0).then(|| self.total / self.count as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_quadratic_form_matches_inverse() {
        // A = [[4, 2], [2, 3]], v = (1, 2): A⁻¹ = [[3, −2], [−2, 4]]/8, vᵀA⁻¹v = (3 − 8 + 16)/8.
        let mut a = [4.0, 2.0, 2.0, 3.0];
        let mut v = [1.0, 2.0];
        let q = cholesky_quadratic_form(&mut a, &mut v, 2).unwrap();
        assert!((q - 11.0 / 8.0).abs() < 1e-15);
        let mut bad = [1.0, 2.0, 2.0, 1.0];
        assert!(cholesky_quadratic_form(&mut bad, &mut [1.0, 0.0], 2).is_none());
    }

    /// An undefined t statistic (NaN) has p-value 0 on both routes, without reaching statrs
    /// (whose incomplete beta panics on NaN), and dof = 0 is refused on both.
    #[test]
    fn t_p_value_of_nan_and_of_no_degrees_of_freedom() {
        for dof in [10, dist::T_TAIL_EXPANSION] {
            assert_eq!(dist::t_p_value(f64::NAN, dof).unwrap(), 0.0);
            let p = dist::t_p_value(0.0, dof).unwrap();
            assert!((p - 1.0).abs() < 1e-12, "{p}");
        }
        assert!(dist::t_p_value(f64::NAN, 0).is_err());
        assert!(dist::t_p_value(1.0, 0).is_err());
    }

    /// Where Student's t switches from statrs to its expansions, the two agree (quantiles
    /// to 10⁻¹¹ at p ≥ 0.975, tails to 10⁻⁹ relative for |t| ≤ 4, statrs' own drift), so no
    /// band or p-value jumps at the switch.
    #[test]
    fn t_expansions_meet_statrs_at_the_switch() {
        use statrs::distribution::{ContinuousCDF, StudentsT};
        let v = dist::T_QUANTILE_EXPANSION;
        let t = StudentsT::new(0.0, 1.0, v as f64).unwrap();
        for p in [0.975, 0.995, 0.9995, 0.999_995] {
            let (a, b) = (t.inverse_cdf(p), dist::t_quantile_expansion(p, v));
            assert!((a - b).abs() < 1e-11, "p = {p}: {a} vs {b}");
        }
        let v = dist::T_TAIL_EXPANSION;
        let t = StudentsT::new(0.0, 1.0, v as f64).unwrap();
        for x in [0.0, 0.5, 1.0, 2.5, 4.0] {
            let (a, b) = (t.sf(x), dist::t_tail_expansion(x, v));
            assert!((a - b).abs() < 1e-9 * a, "x = {x}: {a} vs {b}");
        }
    }
}
