//! Resampling schemes and the log-domain weight arithmetic of the particle filters.
//!
//! Each scheme draws M ancestor indices aⱼ from normalised weights W (Σ Wᵢ = 1) so that the
//! offspring count Oᵢ = #{j : aⱼ = i} has E[Oᵢ] = M Wᵢ. They differ in the variance of Oᵢ
//! (Douc, Cappé & Moulines 2005; Chopin & Papaspiliopoulos 2020, §9.4):
//!
//! | scheme | uniforms | Var Oᵢ |
//! |---|---|---|
//! | [`Multinomial`](Resampling::Multinomial) | M sorted i.i.d. U(0,1) | M Wᵢ (1 − Wᵢ) |
//! | [`Stratified`](Resampling::Stratified) | (j + Uⱼ)/M | ≤ multinomial |
//! | [`Systematic`](Resampling::Systematic) | (j + U)/M, one U | ≤ multinomial (not always ≤ stratified) |
//! | [`Residual`](Resampling::Residual) | ⌊M Wᵢ⌋ copies, then multinomial on the rest | ≤ multinomial |
//!
//! All are the inverse-CDF map aⱼ = min{i : Σₖ₍ᵢ Wₖ ≥ uⱼ} of sorted uniforms; the multinomial's
//! sorted uniforms come from normalised cumulative sums of M + 1 exponentials (O(M), no sort).
//! The uniforms are compared against the running sum scaled by the total, so round-off never
//! selects a particle of weight zero.

use estim_core::error::Result;
use estim_core::{Error, Parameter, Quantity, Stage};

use super::rng::ParticleRng;

/// How the particle cloud is resampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Resampling {
    /// Ancestors i.i.d. from the weights: Var Oᵢ = M Wᵢ (1 − Wᵢ).
    Multinomial,
    /// One uniform per stratum [j/M, (j+1)/M).
    Stratified,
    /// One uniform shifted through every stratum: the lowest variance in practice, the default.
    #[default]
    Systematic,
    /// ⌊M Wᵢ⌋ deterministic copies, the remainder multinomial on the residual weights.
    Residual,
}

/// When the cloud is resampled: checked before each propagation, on the weights the filter
/// holds then (so an update's weights stay readable until the next prediction).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum ResampleWhen {
    /// Every step (the classic bootstrap filter).
    Always,
    /// When the effective sample size 1/Σ Wᵢ² falls below this fraction of the particle count
    /// (in (0, 1]; 0.5 is the usual choice and the default).
    EssBelow(f64),
    /// Never (sequential importance sampling: the weights degenerate; for tests and studies).
    Never,
}

impl ResampleWhen {
    /// The default policy, [`EssBelow(0.5)`](Self::EssBelow).
    pub const DEFAULT: Self = Self::EssBelow(0.5);

    /// Whether to resample a cloud of `count` particles with effective sample size `ess()`
    /// (computed only for [`EssBelow`](Self::EssBelow): an O(N) pass the other policies skip).
    #[inline]
    pub(crate) fn fires(self, ess: impl FnOnce() -> f64, count: usize) -> bool {
        match self {
            Self::Always => true,
            Self::EssBelow(fraction) => ess() < fraction * count as f64,
            Self::Never => false,
        }
    }
}

impl Default for ResampleWhen {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Draws `ancestors.len()` ancestor indices from `weights` by `scheme`, with uniforms from
/// `rng`: aⱼ = i with probability Wᵢ / Σₖ Wₖ (the weights are normalised by their sum here, so
/// they need not sum to 1). Sorted ancestors for every scheme but
/// [`Residual`](Resampling::Residual) (sorted within its deterministic and random parts).
/// With no ancestors to draw, nothing is checked or drawn.
///
/// Errors (`ancestors` unchanged): no weights ([`Error::InvalidParameter`] with
/// [`Parameter::SampleCount`]); a negative weight ([`Parameter::Weight`], the most negative
/// one as the value); a NaN or infinite weight, a sum that overflows, or every weight zero
/// ([`Error::NonFinite`] with [`Quantity::Weights`], at [`Stage::Prediction`], where the
/// filters resample).
///
/// ```
/// use estim_filters::particle::{ParticleRng, Resampling, resample};
///
/// let weights = [0.5, 0.0, 0.25, 0.25];
/// let mut ancestors = [0; 4];
/// resample(Resampling::Systematic, &weights, &mut ParticleRng::stream(1, 0, 0), &mut ancestors);
/// // Systematic resampling gives each particle ⌊4 Wᵢ⌋ or ⌈4 Wᵢ⌉ offspring.
/// assert_eq!(ancestors.iter().filter(|&&a| a == 0).count(), 2);
/// assert!(!ancestors.contains(&1));
/// // Unnormalised weights are normalised; bad ones are typed errors.
/// resample(Resampling::Systematic, &[2.0, 0.0, 1.0, 1.0], &mut ParticleRng::stream(1, 0, 0), &mut ancestors)?;
/// assert_eq!(ancestors.iter().filter(|&&a| a == 0).count(), 2);
/// let mut rng = ParticleRng::stream(1, 0, 0);
/// assert!(resample(Resampling::Systematic, &[], &mut rng, &mut ancestors).is_err());
/// assert!(resample(Resampling::Systematic, &[0.5, -0.1], &mut rng, &mut ancestors).is_err());
/// assert!(resample(Resampling::Systematic, &[0.0, 0.0], &mut rng, &mut ancestors).is_err());
/// assert!(resample(Resampling::Systematic, &[f64::NAN, 1.0], &mut rng, &mut ancestors).is_err());
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn resample(
    scheme: Resampling,
    weights: &[f64],
    rng: &mut ParticleRng,
    ancestors: &mut [usize],
) -> Result<()> {
    resample_with(scheme, weights, rng, ancestors, &mut Vec::new())
}

/// [`resample`] with a scratch buffer the caller keeps (grown to at most N + M entries once).
pub(crate) fn resample_with(
    scheme: Resampling,
    weights: &[f64],
    rng: &mut ParticleRng,
    ancestors: &mut [usize],
    scratch: &mut Vec<f64>,
) -> Result<()> {
    let m = ancestors.len();
    if m == 0 {
        return Ok(());
    }
    if weights.is_empty() {
        return Err(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: 0.0,
        });
    }
    // The sum (which the inverse CDF needs anyway): a NaN or ±∞ weight makes it NaN or
    // infinite. A negative weight has its sign bit set: the OR of all the bits (a vectorised
    // integer pass) shows one, and only then (−0.0 sets it too, and is valid) is the most
    // negative weight looked for.
    let total: f64 = weights.iter().sum();
    let bits = weights.iter().fold(0u64, |b, w| b | w.to_bits());
    if bits >> 63 == 1 {
        let least = weights.iter().fold(f64::INFINITY, |l, &w| l.min(w));
        if least < 0.0 {
            return Err(Error::InvalidParameter {
                parameter: Parameter::Weight,
                value: least,
            });
        }
    }
    if !(total.is_finite() && total > 0.0) {
        return Err(Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::Weights,
        });
    }
    let mf = m as f64;
    match scheme {
        Resampling::Systematic => {
            let u = rng.uniform();
            inverse_cdf(weights, total, ancestors, |j| (j as f64 + u) / mf);
        }
        Resampling::Stratified => {
            inverse_cdf(weights, total, ancestors, |j| {
                (j as f64 + rng.uniform()) / mf
            });
        }
        Resampling::Multinomial => {
            scratch.clear();
            sorted_uniforms(m, rng, scratch);
            inverse_cdf(weights, total, ancestors, |j| scratch[j]);
        }
        Resampling::Residual => {
            let mut filled = 0;
            scratch.clear();
            for (i, &w) in weights.iter().enumerate() {
                let expected = mf * w / total;
                let copies = (expected.floor() as usize).min(m - filled);
                ancestors[filled..filled + copies].fill(i);
                filled += copies;
                scratch.push(expected - copies as f64);
            }
            let rest = m - filled;
            if rest > 0 {
                let n = weights.len();
                sorted_uniforms(rest, rng, scratch);
                let (residuals, uniforms) = scratch.split_at(n);
                let total = residuals.iter().sum();
                inverse_cdf(residuals, total, &mut ancestors[filled..], |j| uniforms[j]);
            }
        }
    }
    Ok(())
}

/// Appends m sorted uniforms to `out`: uⱼ = Sⱼ/Sₘ with Sⱼ = E₀ + … + Eⱼ, Eⱼ ~ Exp(1) i.i.d.
/// (the order statistics of m uniforms).
fn sorted_uniforms(m: usize, rng: &mut ParticleRng, out: &mut Vec<f64>) {
    let start = out.len();
    let mut sum = 0.0;
    for _ in 0..m {
        sum += -rng.uniform().ln();
        out.push(sum);
    }
    sum += -rng.uniform().ln();
    for u in &mut out[start..] {
        *u /= sum;
    }
}

/// aⱼ = min{i : Σₖ₍ᵢ Wₖ ≥ uⱼ · Σ W} for nondecreasing uⱼ in (0, 1), `total` = Σ W.
#[inline]
fn inverse_cdf(
    weights: &[f64],
    total: f64,
    ancestors: &mut [usize],
    mut u: impl FnMut(usize) -> f64,
) {
    let last = weights.len() - 1;
    let (mut i, mut cumulative) = (0, weights[0]);
    for (j, a) in ancestors.iter_mut().enumerate() {
        let target = u(j) * total;
        while target > cumulative && i < last {
            i += 1;
            cumulative += weights[i];
        }
        *a = i;
    }
}

/// log Σᵢ exp(vᵢ), computed as m + log Σ exp(vᵢ − m) with m = max vᵢ (no overflow or
/// underflow). −∞ for an empty slice or all −∞; NaN if any vᵢ is NaN.
///
/// ```
/// use estim_filters::particle::log_sum_exp;
///
/// let v = [-1000.0, -1000.0];
/// assert!((log_sum_exp(&v) - (-1000.0 + 2f64.ln())).abs() < 1e-12);
/// assert_eq!(log_sum_exp(&[f64::NEG_INFINITY; 3]), f64::NEG_INFINITY);
/// ```
pub fn log_sum_exp<T: estim_core::Real>(values: &[T]) -> T {
    let mut max = -T::one() / T::zero();
    for &v in values {
        #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
        if v != v {
            return v;
        }
        if v > max {
            max = v;
        }
    }
    if !max.is_finite() {
        // All −∞ (or empty): the sum is 0. A +∞ entry: the sum is +∞.
        return max;
    }
    let sum = values.iter().fold(T::zero(), |s, &v| s + (v - max).exp());
    max + sum.ln()
}

/// A `Real` as `f64` (exact for f32 and f64).
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn to_f64<T: estim_core::Real>(x: T) -> f64 {
    estim_core::nalgebra::try_convert::<T, f64>(x).unwrap_or(f64::NAN)
}

/// The effective sample size 1 / Σ Wᵢ² of normalised weights (Σ Wᵢ = 1).
pub(crate) fn ess_of_weights(weights: &[f64]) -> f64 {
    1.0 / weights.iter().map(|w| w * w).sum::<f64>()
}

/// The effective sample size 1 / Σ Wᵢ² of normalised log-weights (log Σ Wᵢ = 0), for the
/// filters that keep log-weights only.
pub(crate) fn effective_sample_size<T: estim_core::Real>(log_weights: &[T]) -> f64 {
    let sum_sq: f64 = log_weights
        .iter()
        .map(|&lw| {
            let w = to_f64(lw).exp();
            w * w
        })
        .sum();
    1.0 / sum_sq
}

/// log Σᵢ exp(vᵢ) of unnormalised log-weights, in one serial pass ([`log_sum_exp`]), or the
/// typed error of a degenerate weight set: every weight zero (no particle explains the
/// measurement, [`Quantity::Weights`]), or a NaN or +∞ (a bug in the model,
/// [`Quantity::FunctionValue`]).
pub(crate) fn normaliser<T: estim_core::Real>(log_w: &[T]) -> Result<T> {
    let total = log_sum_exp(log_w);
    if total.is_finite() {
        Ok(total)
    } else {
        let quantity = if total == -T::one() / T::zero() {
            Quantity::Weights
        } else {
            Quantity::FunctionValue
        };
        Err(Error::NonFinite {
            stage: Stage::Update,
            quantity,
        })
    }
}
