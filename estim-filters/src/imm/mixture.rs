//! The arithmetic of a multiple-model estimator: checks of Π and μ, the Markov prediction of
//! μ, the moments of a Gaussian mixture and Bayes' rule for μ in logs.

use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::scalar::real;
use estim_core::{Alloc, Error, Parameter, Quantity, Real, Stage, error::Result};

use crate::report::{UpdateOutcome, UpdateReport};

/// How far a row of Π (or μ) may sum from 1: 64 m ulps, room for the rounding of m entries
/// typed as decimals (0.95 + 0.05 is 1 within one ulp) and nothing that is a real mistake.
fn sum_tolerance<T: Real>(m: usize) -> T {
    T::default_epsilon() * real::<T>(64.0 * m.max(1) as f64)
}

fn as_f64<T: Real>(x: T) -> f64 {
    estim_core::nalgebra::try_convert::<T, f64>(x).unwrap_or(f64::NAN)
}

fn invalid<T: Real>(parameter: Parameter, value: T) -> Error {
    Error::InvalidParameter {
        parameter,
        value: as_f64(value),
    }
}

/// Π must be m × m, finite, with entries in [0, 1] and rows summing to 1 (row-stochastic:
/// πᵢⱼ = P(mode j at k+1 | mode i at k)).
pub(crate) fn check_transition<T: Real>(pi: &DMatrix<T>, m: usize, stage: Stage) -> Result<()> {
    if pi.shape() != (m, m) {
        return Err(Error::DimensionMismatch {
            stage,
            quantity: Quantity::TransitionMatrix,
            expected_rows: m,
            expected_cols: m,
            found_rows: pi.nrows(),
            found_cols: pi.ncols(),
        });
    }
    if pi.iter().any(|p| !p.is_finite()) {
        return Err(Error::NonFinite {
            stage,
            quantity: Quantity::TransitionMatrix,
        });
    }
    if let Some(&p) = pi.iter().find(|&&p| p < T::zero() || p > T::one()) {
        return Err(invalid(Parameter::TransitionProbability, p));
    }
    for row in pi.row_iter() {
        let sum = row.sum();
        if (sum - T::one()).abs() > sum_tolerance::<T>(m) {
            return Err(invalid(Parameter::TransitionProbability, sum));
        }
    }
    Ok(())
}

/// μ must have m entries, finite, each in [0, 1], summing to 1.
pub(crate) fn check_probabilities<T: Real>(mu: &DVector<T>, m: usize) -> Result<()> {
    let stage = Stage::Construction;
    if mu.nrows() != m {
        return Err(Error::DimensionMismatch {
            stage,
            quantity: Quantity::ModeProbabilities,
            expected_rows: m,
            expected_cols: 1,
            found_rows: mu.nrows(),
            found_cols: 1,
        });
    }
    if mu.iter().any(|p| !p.is_finite()) {
        return Err(Error::NonFinite {
            stage,
            quantity: Quantity::ModeProbabilities,
        });
    }
    if let Some(&p) = mu.iter().find(|&&p| p < T::zero() || p > T::one()) {
        return Err(invalid(Parameter::ModeProbability, p));
    }
    let sum = mu.sum();
    if (sum - T::one()).abs() > sum_tolerance::<T>(m) {
        return Err(invalid(Parameter::ModeProbability, sum));
    }
    Ok(())
}

/// c̄ⱼ = Σᵢ πᵢⱼ μᵢ (the chain's one-step prediction, c̄ = Πᵀ μ), into `out`.
pub(crate) fn predict_probabilities<T: Real>(
    pi: &DMatrix<T>,
    mu: &DVector<T>,
    out: &mut DVector<T>,
) {
    for (j, c) in out.iter_mut().enumerate() {
        *c = (0..mu.nrows()).fold(T::zero(), |acc, i| acc + pi[(i, j)] * mu[i]);
    }
}

/// Bayes' rule for the mode probabilities in logs: μⱼ ∝ c̄ⱼ exp(ℓⱼ) with c̄ the prior `mu`
/// (overwritten by the posterior) and ℓ the modes' log-likelihoods. Computed as
/// exp(ℓⱼ + ln c̄ⱼ − max) over their sum, so likelihoods of 10⁻⁴⁰⁰ neither underflow nor lose
/// their ratios. Returns ln Σⱼ c̄ⱼ exp(ℓⱼ), the log-likelihood of the measurement under the
/// mixture. A NaN ℓ, or no mode with both c̄ⱼ > 0 and ℓⱼ > −∞ (the measurement impossible
/// under every mode that can be active), is an error and leaves `mu` unchanged.
/// `log_likelihoods` is overwritten (with the unnormalised weights on success).
pub(crate) fn bayes_in_logs<T: Real>(
    mu: &mut DVector<T>,
    log_likelihoods: &mut DVector<T>,
) -> Result<T> {
    let refused = Error::NonFinite {
        stage: Stage::Update,
        quantity: Quantity::ModeProbabilities,
    };
    // Plain slices: nalgebra's element iterators cost more than these few entries.
    let (mu, log_likelihoods) = (mu.as_mut_slice(), log_likelihoods.as_mut_slice());
    // NaN (and +∞, a degenerate innovation covariance) is refused; −∞ is an impossible z.
    if (log_likelihoods.iter()).any(|&l| !l.is_finite() && !(l < T::zero())) {
        return Err(refused);
    }
    let minus_infinity = -(T::one() / T::zero());
    // ℓⱼ + ln c̄ⱼ in place; a mode with c̄ⱼ = 0 is −∞ whatever its ℓ.
    for (l, &c) in log_likelihoods.iter_mut().zip(mu.iter()) {
        *l = if c > T::zero() {
            *l + c.ln()
        } else {
            minus_infinity
        };
    }
    let max = log_likelihoods
        .iter()
        .fold(minus_infinity, |a, &b| if b > a { b } else { a });
    if !max.is_finite() {
        return Err(refused);
    }
    // exp(ℓⱼ + ln c̄ⱼ − max) once per mode, kept in the buffer (which the caller reuses as
    // scratch) for the division: the same values and the same order of the sum as taking
    // them twice, m calls of exp fewer.
    let mut sum = T::zero();
    for l in log_likelihoods.iter_mut() {
        *l = (*l - max).exp();
        sum += *l;
    }
    for (p, &w) in mu.iter_mut().zip(log_likelihoods.iter()) {
        *p = w / sum;
    }
    Ok(max + sum.ln())
}

/// The update of a set of weighted hypotheses (the IMM's modes, GPB2's and the Gaussian
/// sum's components), shared by the three: `update(i, report)` updates hypothesis i with the
/// measurement (skipped where `prior[i] = 0`: its ℓᵢ is −∞, so its weight stays 0 and a NaN
/// it might give is never seen), then the posterior weights by [`bayes_in_logs`] into
/// `posterior` and the mixture's report (see [`RunningMoments::into_report`]) into `report`.
/// `rows` is the measurement's size; `log_likelihoods` is a buffer of the prior's length. Returns whether any hypothesis
/// applied the update; on an error the caller puts the hypotheses back (`posterior` is then
/// unspecified).
pub(crate) fn update_weighted<T: Real, M: Dim>(
    rows: M,
    prior: &DVector<T>,
    posterior: &mut DVector<T>,
    log_likelihoods: &mut DVector<T>,
    report: &mut UpdateReport<T, M>,
    mut update: impl FnMut(usize, &mut UpdateReport<T, M>) -> Result<()>,
) -> Result<bool>
where
    DefaultAllocator: Alloc<M>,
{
    let mut moments = RunningMoments::<T, M>::new(rows);
    let mut applied = false;
    let logs = log_likelihoods.as_mut_slice();
    for (i, (&w, log)) in prior.as_slice().iter().zip(logs.iter_mut()).enumerate() {
        if w == T::zero() {
            *log = -(T::one() / T::zero());
            continue;
        }
        update(i, report)?;
        *log = report.log_likelihood;
        applied |= report.applied();
        moments.add(w, &report.innovation, &report.innovation_covariance);
    }
    moments.finish();
    posterior.copy_from(prior);
    let log_likelihood = bayes_in_logs(posterior, log_likelihoods)?;
    moments.into_report(log_likelihood, applied, report)?;
    Ok(applied)
}

/// The moments of the Gaussian mixture Σᵢ wᵢ N(xᵢ, Pᵢ) (weights summing to 1), into `mean`
/// and `covariance`:
///
/// ```text
/// x̄ = Σᵢ wᵢ xᵢ,    P̄ = Σᵢ wᵢ (Pᵢ + (xᵢ − x̄)(xᵢ − x̄)ᵀ)
/// ```
///
/// When one component has weight exactly 1 (the others 0) its moments are copied bit for bit.
/// `spread` is a buffer of the state's length.
pub(crate) fn mixture_into<'a, T, N>(
    components: impl Iterator<Item = (T, &'a OVector<T, N>, &'a OMatrix<T, N, N>)> + Clone,
    mean: &mut OVector<T, N>,
    covariance: &mut OMatrix<T, N, N>,
    spread: &mut OVector<T, N>,
) where
    T: Real,
    N: Dim,
    DefaultAllocator: Alloc<N>,
{
    if let Some((_, x, p)) = components.clone().find(|(w, _, _)| *w == T::one()) {
        mean.copy_from(x);
        covariance.copy_from(p);
        return;
    }
    mean.fill(T::zero());
    for (w, x, _) in components.clone() {
        mean.axpy(w, x, T::one());
    }
    covariance.fill(T::zero());
    for (w, x, p) in components {
        if w == T::zero() {
            continue;
        }
        spread.copy_from(x);
        *spread -= &*mean;
        covariance.zip_apply(p, |c, p| *c += w * p);
        covariance.ger(w, spread, spread, T::one());
    }
}

/// The moments of a mixture of measurement predictions, accumulated one component at a time
/// (West's weighted update, one pass, no cancellation): after components (wⱼ, νⱼ, Sⱼ),
/// `mean` is Σ wⱼ νⱼ / W and [`covariance`](Self::finish) Σ wⱼ (Sⱼ + (νⱼ − ν̄)(νⱼ − ν̄)ᵀ) / W.
pub(crate) struct RunningMoments<T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    pub(crate) mean: OVector<T, M>,
    pub(crate) covariance: OMatrix<T, M, M>,
    delta: OVector<T, M>,
    total: T,
}

impl<T: Real, M: Dim> RunningMoments<T, M>
where
    DefaultAllocator: Alloc<M>,
{
    /// Nothing accumulated, for `m` components.
    pub(crate) fn new(m: M) -> Self {
        Self {
            mean: OVector::zeros_generic(m, estim_core::nalgebra::U1),
            covariance: OMatrix::zeros_generic(m, m),
            delta: OVector::zeros_generic(m, estim_core::nalgebra::U1),
            total: T::zero(),
        }
    }

    /// Adds the component N(ν, S) with weight w ≥ 0.
    pub(crate) fn add(&mut self, w: T, nu: &OVector<T, M>, s: &OMatrix<T, M, M>) {
        if w <= T::zero() {
            return;
        }
        self.total += w;
        self.delta.copy_from(nu);
        self.delta -= &self.mean;
        let share = w / self.total;
        self.mean.axpy(share, &self.delta, T::one());
        self.covariance.zip_apply(s, |c, s| *c += w * s);
        let delta = &self.delta;
        self.covariance
            .ger(w * (T::one() - share), delta, delta, T::one());
    }

    /// Divides the accumulated covariance by the total weight (if any).
    pub(crate) fn finish(&mut self) {
        if self.total > T::zero() && self.total != T::one() {
            self.covariance /= self.total;
        }
    }

    /// The mixture's update report from the finished moments: ν̄, S̄, NIS = ν̄ᵀ S̄⁻¹ ν̄,
    /// `log_likelihood` (the mixture's, from [`bayes_in_logs`]) and the outcome (`Applied`
    /// if any component applied the update, else `Gated`). A singular S̄ is
    /// `NotPositiveDefinite` (`InnovationCovariance`), the report then unspecified.
    pub(crate) fn into_report(
        self,
        log_likelihood: T,
        applied: bool,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        let mut factor = self.covariance.clone();
        let mut whitened = self.mean.clone();
        let nis = estim_core::linalg::inverse_quadratic_form(&mut factor, &mut whitened).ok_or(
            Error::NotPositiveDefinite {
                stage: Stage::Update,
                quantity: Quantity::InnovationCovariance,
            },
        )?;
        report.innovation = self.mean;
        report.innovation_covariance = self.covariance;
        report.nis = nis;
        report.log_likelihood = log_likelihood;
        report.iterations = None;
        report.outcome = if applied {
            UpdateOutcome::Applied
        } else {
            UpdateOutcome::Gated
        };
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bayes_in_logs_keeps_ratios_of_likelihoods_that_underflow() {
        // e⁻¹⁰⁰⁰ underflows to 0 in f64; the ratio e¹ of the two likelihoods must survive.
        let mut mu = DVector::from_vec(vec![0.5, 0.5]);
        let mut ll = DVector::from_vec(vec![-1000.0, -1001.0]);
        let total = bayes_in_logs(&mut mu, &mut ll).unwrap();
        let e = core::f64::consts::E;
        // A few ulps of exp and the division.
        assert!((mu[0] - e / (1.0 + e)).abs() < 4.0 * f64::EPSILON);
        assert!((mu[1] - 1.0 / (1.0 + e)).abs() < 4.0 * f64::EPSILON);
        let expected = -1000.0 + (0.5 * (1.0 + (-1.0f64).exp())).ln();
        assert!((total - expected).abs() < 1e3 * f64::EPSILON);
    }

    #[test]
    fn bayes_in_logs_refuses_nan_and_impossible_measurements_unchanged() {
        let mu0 = DVector::from_vec(vec![0.3, 0.7]);
        for ll in [[f64::NAN, -1.0], [f64::NEG_INFINITY, f64::NEG_INFINITY]] {
            let mut mu = mu0.clone();
            let mut ll = DVector::from_vec(ll.to_vec());
            assert!(matches!(
                bayes_in_logs(&mut mu, &mut ll),
                Err(Error::NonFinite {
                    quantity: Quantity::ModeProbabilities,
                    ..
                })
            ));
            assert_eq!(mu, mu0);
        }
        // Possible only under a mode that cannot be active: refused too.
        let mut mu = DVector::from_vec(vec![1.0, 0.0]);
        let mut ll = DVector::from_vec(vec![f64::NEG_INFINITY, 0.0]);
        assert!(bayes_in_logs(&mut mu, &mut ll).is_err());
        // A zero-probability mode stays at zero whatever its likelihood.
        let mut mu = DVector::from_vec(vec![1.0, 0.0]);
        let mut ll = DVector::from_vec(vec![-5.0, 0.0]);
        bayes_in_logs(&mut mu, &mut ll).unwrap();
        assert_eq!(mu, DVector::from_vec(vec![1.0, 0.0]));
    }
}
