//! The ensemble statistics of a Monte Carlo experiment and their verdict: per slot, the
//! estimate and NIS statistics, per residual pair the cross-correlation, with their bands.

use estim_core::checks::ensure_shape;
use estim_core::nalgebra::{DMatrix, DVector};
use estim_core::{Quantity, Stage};

use crate::consistency::{
    Check, ChiSquareBand, FamilyRule, FamilyTest, Location, Verdict, dist, validate_confidence,
};
use crate::validation::{Result, Setting, ValidationError};

use super::accumulator::{PairAcc, SlotAcc};

/// The ensemble statistics of the estimates recorded at one slot, over the N runs that
/// recorded one. e = x − x̂ is the error, P the filter's covariance.
///
/// Its matrices are n × n, n the length of [`mean_error`](Self::mean_error). The fields are
/// public (and deserialise from any file): [`EnsembleStats::verdict`] checks the shapes, the
/// accessors below panic on statistics whose shapes disagree.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EstimateStats {
    /// N.
    pub samples: usize,
    /// The ensemble mean error ē = (1/N) Σ eˡ (Lu's e^ave).
    pub mean_error: DVector<f64>,
    /// The ensemble error covariance P_ens = 1/(N − 1) Σ (eˡ − ē)(eˡ − ē)ᵀ (Lu's P^ave);
    /// NaN when N < 2.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub error_covariance: DMatrix<f64>,
    /// The mean filter covariance P̄ = (1/N) Σ Pˡ, which P_ens should match.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub mean_covariance: DMatrix<f64>,
    /// The average NEES ε̄ = (1/N) Σ eˡᵀ (Pˡ)⁻¹ eˡ, ~ χ²_{N·n}/N when consistent.
    pub mean_nees: f64,
    /// Lu's orthogonality matrix (1/N) Σ (eˡ − ē) x̂ˡᵀ = (1/N) Σ (eˡ − ē)(x̂ˡ − x̄)ᵀ, entry
    /// (i, j) pairing error component i with estimate component j.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub orthogonality: DMatrix<f64>,
    /// Its normalised version: the sample correlation of eᵢ and x̂ⱼ across runs, in [−1, 1];
    /// NaN where either has no spread (e.g. x̂ at the prior, the same in every run).
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub orthogonality_correlation: DMatrix<f64>,
    /// The sample variance of each estimate component across runs, 1/(N − 1) Σ (x̂ˡ − x̄)².
    pub estimate_variance: DVector<f64>,
}

impl EstimateStats {
    pub(super) fn from_acc(acc: &SlotAcc) -> Self {
        let n = acc.n;
        let count = acc.count as f64;
        let dof = count - 1.0;
        let unbiased = |v: f64| if acc.count >= 2 { v / dof } else { f64::NAN };
        let c_ee = DMatrix::from_column_slice(n, n, &acc.c_ee);
        let c_ex = DMatrix::from_column_slice(n, n, &acc.c_ex);
        let correlation = DMatrix::from_fn(n, n, |i, j| {
            let denominator = (c_ee[(i, i)] * acc.m2_x[j]).sqrt();
            if denominator > 0.0 {
                c_ex[(i, j)] / denominator
            } else {
                f64::NAN
            }
        });
        Self {
            samples: acc.count,
            mean_error: DVector::from_column_slice(&acc.mean_e),
            error_covariance: c_ee.map(unbiased),
            mean_covariance: DMatrix::from_column_slice(n, n, &acc.sum_p) / count,
            mean_nees: acc.sum_nees / count,
            orthogonality: c_ex / count,
            orthogonality_correlation: correlation,
            estimate_variance: DVector::from_iterator(n, acc.m2_x.iter().map(|&v| unbiased(v))),
        }
    }

    /// The state dimension n.
    pub fn state_dim(&self) -> usize {
        self.mean_error.nrows()
    }

    /// The band of [`mean_nees`](Self::mean_nees): χ²_{N·n}/N at `confidence`.
    pub fn nees_band(&self, confidence: f64) -> Result<ChiSquareBand> {
        ChiSquareBand::two_sided(self.state_dim(), self.samples, confidence)
    }

    /// The ratios (P_ens)ᵢᵢ / (P̄)ᵢᵢ, ≈ 1 when consistent.
    ///
    /// # Panics
    /// When the two covariances are not n × n (statistics edited by hand).
    #[track_caller]
    pub fn covariance_ratio(&self) -> DVector<f64> {
        let n = self.state_dim();
        assert!(
            self.error_covariance.shape() == (n, n) && self.mean_covariance.shape() == (n, n),
            "covariance_ratio: covariances of another size than the {n} components of the mean error"
        );
        DVector::from_fn(n, |i, _| {
            self.error_covariance[(i, i)] / self.mean_covariance[(i, i)]
        })
    }

    /// The band of each [`covariance_ratio`](Self::covariance_ratio) at `confidence`:
    /// χ²_{N−1}((1 ∓ c)/2)/(N − 1) (exact for Gaussian errors and a covariance that does not
    /// depend on the run, as in a linear Kalman filter). Needs N ≥ 2.
    pub fn covariance_ratio_band(&self, confidence: f64) -> Result<(f64, f64)> {
        let band = ChiSquareBand::for_sum(self.samples.saturating_sub(1), 1, confidence)?;
        let dof = (self.samples - 1) as f64;
        Ok((band.lower / dof, band.upper / dof))
    }

    /// The half-width of each component's band for [`mean_error`](Self::mean_error):
    /// t_{N−1,(1+c)/2} · sᵢ / √N with sᵢ² = (P_ens)ᵢᵢ. Needs N ≥ 2 and an n × n P_ens
    /// ([`Error::DimensionMismatch`](estim_core::Error::DimensionMismatch) otherwise).
    pub fn mean_error_bound(&self, confidence: f64) -> Result<DVector<f64>> {
        let n = self.state_dim();
        let (stage, quantity) = (Stage::ConsistencyCheck, Quantity::Covariance);
        ensure_shape(&self.error_covariance, n, n, stage, quantity)?;
        let t = dist::t_two_sided(
            validate_confidence(confidence)?,
            self.samples.saturating_sub(1),
        )?;
        let root_n = (self.samples as f64).sqrt();
        Ok(DVector::from_fn(self.state_dim(), |i, _| {
            t * self.error_covariance[(i, i)].sqrt() / root_n
        }))
    }

    /// The bound on each entry of
    /// [`orthogonality_correlation`](Self::orthogonality_correlation) at `confidence`: the
    /// sample correlation r of independent Gaussians satisfies r √(N−2)/√(1−r²) ~ t_{N−2}, so
    /// |r| ≤ t/√(N − 2 + t²) with t = t_{N−2,(1+c)/2} (≈ z/√N). Needs N ≥ 3.
    pub fn orthogonality_bound(&self, confidence: f64) -> Result<f64> {
        let dof = self.samples.saturating_sub(2);
        let t = dist::t_two_sided(validate_confidence(confidence)?, dof)?;
        Ok(t / (dof as f64 + t * t).sqrt())
    }
}

/// The NIS statistics recorded at one slot.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct InnovationStats {
    /// Number of innovations recorded N.
    pub samples: usize,
    /// Σ m over them (N·m for a fixed measurement size m).
    pub degrees_of_freedom: usize,
    /// The average NIS (1/N) Σ νᵀS⁻¹ν, ~ χ²_{N·m}/N when consistent.
    pub mean_nis: f64,
    /// The average log-likelihood of the measurement at this slot.
    pub mean_log_likelihood: f64,
}

impl InnovationStats {
    /// The band of [`mean_nis`](Self::mean_nis) at `confidence`.
    pub fn nis_band(&self, confidence: f64) -> Result<ChiSquareBand> {
        ChiSquareBand::for_sum(self.degrees_of_freedom, self.samples, confidence)
    }
}

/// The statistics of one slot.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SlotStats {
    /// The slot index.
    pub slot: usize,
    /// Estimate statistics, if any run recorded an estimate here.
    pub estimate: Option<EstimateStats>,
    /// NIS statistics, if any run recorded an innovation here.
    pub innovation: Option<InnovationStats>,
}

/// Lu's residual check between slots a and b: (1/N) Σ r(a) r(b)ᵀ ≈ 0 for a consistent filter,
/// whose innovations are white.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ResidualPairStats {
    /// The first slot a.
    pub first: usize,
    /// The second slot b.
    pub second: usize,
    /// Number of runs that recorded both N.
    pub samples: usize,
    /// (1/N) Σ r(a) r(b)ᵀ (m_a × m_b; 0 × 0 when N = 0).
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub cross_correlation: DMatrix<f64>,
    /// Entry (i, j) normalised as in Bar-Shalom et al. eq 5.4.2-12:
    /// Σ rᵢ(a) rⱼ(b) / √(Σ rᵢ(a)² Σ rⱼ(b)²), ≈ N(0, 1/N) when r(a) and r(b) are independent
    /// and zero-mean; NaN where a component is identically 0.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub normalized: DMatrix<f64>,
}

impl ResidualPairStats {
    pub(super) fn from_acc(first: usize, second: usize, acc: &PairAcc) -> Self {
        let (ma, mb) = (acc.ma, acc.mb);
        let sum = DMatrix::from_column_slice(ma, mb, &acc.sum_ab);
        let normalized = DMatrix::from_fn(ma, mb, |i, j| {
            let d = (acc.sum_a2[i] * acc.sum_b2[j]).sqrt();
            if d > 0.0 { sum[(i, j)] / d } else { f64::NAN }
        });
        Self {
            first,
            second,
            samples: acc.count,
            cross_correlation: sum / (acc.count.max(1) as f64),
            normalized,
        }
    }

    /// The bound z₍₁₊c₎/₂ / √N on each entry of [`normalized`](Self::normalized).
    pub fn bound(&self, confidence: f64) -> Result<f64> {
        crate::consistency::autocorrelation_bound(self.samples, confidence)
    }
}

/// What [`MonteCarlo::run`](super::MonteCarlo::run) returns: per-slot ensemble statistics and the residual pairs.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EnsembleStats {
    /// The number of runs N.
    pub runs: usize,
    /// One entry per slot, in slot order.
    pub slots: Vec<SlotStats>,
    /// One entry per requested residual pair, in request order.
    pub residual_pairs: Vec<ResidualPairStats>,
}

impl EnsembleStats {
    /// Runs every check at `confidence` (e.g. 0.95: a consistent filter fails each check with
    /// probability at most 5%), combining each check's single tests by Simes' rule
    /// ([`FamilyRule::Simes`]). See [`verdict_with`](Self::verdict_with).
    pub fn verdict(&self, confidence: f64) -> Result<Verdict> {
        self.verdict_with(confidence, FamilyRule::Simes)
    }

    /// Runs every check at `confidence`, combining each check's single tests by `rule`.
    ///
    /// Each single test has a two-sided band at c (= `confidence` under Simes, the rule's
    /// `test_confidence` under the binomial rule) and a two-sided p-value from the same
    /// distribution; the rule turns a check's p-values into its decision:
    ///
    /// | check | single test (one per slot and component or entry) | band at c |
    /// |---|---|---|
    /// | [`MeanError`](Check::MeanError) | t = ēᵢ / (sᵢ/√N), sᵢ² = (P_ens)ᵢᵢ | ±t_{N−1,(1+c)/2} |
    /// | [`ErrorCovariance`](Check::ErrorCovariance) | (P_ens)ᵢᵢ / (P̄)ᵢᵢ | χ²_{N−1}((1∓c)/2)/(N−1) |
    /// | [`Nees`](Check::Nees) | ε̄ | χ²_{N·n}((1∓c)/2)/N |
    /// | [`Nis`](Check::Nis) | average NIS | χ²_{N·m}((1∓c)/2)/N |
    /// | [`Orthogonality`](Check::Orthogonality) | corr(eᵢ, x̂ⱼ) | ±t/√(N−2+t²), t = t_{N−2,(1+c)/2} |
    /// | [`ResidualCorrelation`](Check::ResidualCorrelation) | normalised Σ rᵢ(a) rⱼ(b) | ±z_{(1+c)/2}/√N |
    ///
    /// The mean-error test uses the ensemble spread, not the filter's P, so it tests bias
    /// alone (a filter that is unbiased but over-confident fails only the covariance and NEES
    /// checks). Tests whose statistic is undefined (a component with no spread, e.g. x̂ at the
    /// prior) are skipped; a check with no test is [`NotRun`](crate::consistency::Outcome::NotRun).
    ///
    /// The bands are exact for a linear-Gaussian system and a Kalman filter whose model is
    /// the truth's (errors Gaussian, P the same in every run), and asymptotic otherwise. They
    /// assume the truth's initial state is drawn from the filter's prior: with a fixed initial
    /// truth, e and x̂ are correlated through the prior, and the orthogonality, covariance and
    /// NEES checks can fail for a correct filter until the prior is forgotten.
    ///
    /// Errors: a `confidence` outside (0, 1) ([`Setting::Confidence`]); statistics whose
    /// matrices are not n × n ([`Error::DimensionMismatch`](estim_core::Error::DimensionMismatch),
    /// stage [`ConsistencyCheck`](Stage::ConsistencyCheck)) or whose degrees of freedom
    /// overflow or exceed [`MAX_DEGREES_OF_FREEDOM`](crate::consistency::MAX_DEGREES_OF_FREEDOM)
    /// (statistics edited by hand or read from a damaged file).
    pub fn verdict_with(&self, confidence: f64, rule: FamilyRule) -> Result<Verdict> {
        let family = |check| FamilyTest::new(check, confidence, rule);
        let mut mean = family(Check::MeanError)?;
        let mut cov = family(Check::ErrorCovariance)?;
        let mut nees = family(Check::Nees)?;
        let mut nis = family(Check::Nis)?;
        let mut orth = family(Check::Orthogonality)?;
        let mut resid = family(Check::ResidualCorrelation)?;
        let c = mean.band_confidence();
        let mut nees_band: Option<ChiSquareBand> = None;
        let mut nis_band: Option<ChiSquareBand> = None;
        for s in &self.slots {
            if let Some(e) = &s.estimate {
                estimate_tests(s.slot, e, c, &mut mean, &mut cov, &mut orth)?;
                let dof = e.state_dim().checked_mul(e.samples).ok_or(
                    ValidationError::InvalidSetting {
                        setting: Setting::RunCount,
                        value: e.samples as f64,
                    },
                )?;
                let band = cached_band(&mut nees_band, dof, e.samples, c)?;
                nees.add(
                    Location::Slot { slot: s.slot },
                    e.mean_nees,
                    band.lower,
                    band.upper,
                    band.p_value(e.mean_nees)?,
                );
            }
            if let Some(i) = &s.innovation {
                let band = cached_band(&mut nis_band, i.degrees_of_freedom, i.samples, c)?;
                nis.add(
                    Location::Slot { slot: s.slot },
                    i.mean_nis,
                    band.lower,
                    band.upper,
                    band.p_value(i.mean_nis)?,
                );
            }
        }
        for p in &self.residual_pairs {
            if p.samples == 0 {
                continue;
            }
            let bound = p.bound(c)?;
            let root_n = (p.samples as f64).sqrt();
            for j in 0..p.normalized.ncols() {
                for i in 0..p.normalized.nrows() {
                    let rho = p.normalized[(i, j)];
                    if rho.is_nan() {
                        continue;
                    }
                    let location = Location::Pair {
                        first: p.first,
                        second: p.second,
                        row: i,
                        col: j,
                    };
                    resid.add(
                        location,
                        rho,
                        -bound,
                        bound,
                        dist::normal_p_value(rho * root_n),
                    );
                }
            }
        }
        Ok(Verdict {
            runs: self.runs,
            confidence,
            rule,
            checks: vec![
                mean.finish(),
                cov.finish(),
                nees.finish(),
                nis.finish(),
                orth.finish(),
                resid.finish(),
            ],
        })
    }
}

/// The χ² band for (dof, terms), recomputed only when they change (usually they never do).
fn cached_band(
    cache: &mut Option<ChiSquareBand>,
    dof: usize,
    terms: usize,
    confidence: f64,
) -> Result<ChiSquareBand> {
    match cache {
        Some(b) if b.degrees_of_freedom == dof && b.terms == terms => Ok(*b),
        _ => {
            let b = ChiSquareBand::for_sum(dof, terms, confidence)?;
            *cache = Some(b);
            Ok(b)
        }
    }
}

/// The mean-error, covariance and orthogonality tests of one slot.
fn estimate_tests(
    slot: usize,
    e: &EstimateStats,
    confidence: f64,
    mean: &mut FamilyTest,
    cov: &mut FamilyTest,
    orth: &mut FamilyTest,
) -> Result<()> {
    let n = e.state_dim();
    // Statistics read back from a file may have any shapes: checked before indexing.
    let stage = Stage::ConsistencyCheck;
    ensure_shape(&e.error_covariance, n, n, stage, Quantity::Covariance)?;
    ensure_shape(&e.mean_covariance, n, n, stage, Quantity::Covariance)?;
    ensure_shape(
        &e.orthogonality_correlation,
        n,
        n,
        stage,
        Quantity::CrossCovariance,
    )?;
    let samples = e.samples;
    if samples >= 2 {
        let dof = samples - 1;
        let t_crit = dist::t_two_sided(confidence, dof)?;
        let (lo, hi) = e.covariance_ratio_band(confidence)?;
        let root_n = (samples as f64).sqrt();
        for i in 0..n {
            let location = Location::Component { slot, component: i };
            let (m, var, p) = (
                e.mean_error[i],
                e.error_covariance[(i, i)],
                e.mean_covariance[(i, i)],
            );
            if !(m == 0.0 && var == 0.0) {
                let t = m / (var.sqrt() / root_n);
                mean.add(location, t, -t_crit, t_crit, dist::t_p_value(t, dof)?);
            }
            if !(var == 0.0 && p == 0.0) {
                let ratio = var / p;
                let p_value = dist::chi2_p_value(ratio * dof as f64, dof)?;
                cov.add(location, ratio, lo, hi, p_value);
            }
        }
    }
    if samples >= 3 {
        let dof = samples - 2;
        let bound = e.orthogonality_bound(confidence)?;
        for j in 0..n {
            for i in 0..n {
                let r = e.orthogonality_correlation[(i, j)];
                if r.is_nan() {
                    continue;
                }
                let t = r * (dof as f64 / (1.0 - r * r)).sqrt();
                let location = Location::Entry {
                    slot,
                    row: i,
                    col: j,
                };
                orth.add(location, r, -bound, bound, dist::t_p_value(t, dof)?);
            }
        }
    }
    Ok(())
}
