//! The measurement update, written once for every filter.
//!
//! Given the predicted measurement moments (ẑ, cov(ẑ), Pₓᵤ = cov(x, ẑ)) from any moment
//! propagator, the noise R and the innovation ν = z ⊖ ẑ:
//!
//! ```text
//! S  = cov(ẑ) + R                       (factorised by Cholesky, S = L Lᵀ; never inverted)
//! K  = Pₓᵤ S⁻¹                          (solved from the right: K = Pₓᵤ L⁻ᵀ L⁻¹)
//! x⁺ = x ⊞ K ν                         (x + K ν on ℝⁿ; see estim_core::StateSpace)
//! P⁺ = P − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ     (Joseph)
//! NIS = |L⁻¹ ν|²,   ln p(z) = −½ (NIS + 2 Σ ln Lᵢᵢ + m ln 2π)
//! ```
//!
//! For a linear(ised) model, Pₓᵤ = P Hᵀ and S = H P Hᵀ + R, and the Joseph line expands to the
//! familiar (I − K H) P (I − K H)ᵀ + K R Kᵀ. Like it, it is insensitive to first-order errors
//! in K: with K = K* + δK it equals P − K* S K*ᵀ + δK S δKᵀ. But it needs no H, so it serves
//! the unscented filter too.
//!
//! The products, the factorisation and the solves go through [`estim_core::kernel`]: nalgebra
//! on the stack for static sizes, faer in the filter's preallocated buffers for runtime sizes.
//!
//! # Optimised builds (erratum, rustc 1.95 / LLVM 22)
//!
//! Up to `df5c075`, an optimised build (opt-level 3, 16 codegen units: `--release` and
//! `cargo bench`) could compute a wrong Joseph-form covariance in a static-size update: the
//! analytic 6-state EKF of `benches/autodiff.rs` gave P⁺ off by 4·10⁻² (relative) from the
//! first update on, while the same code at opt-level 1 or 2, with one codegen unit, or with
//! `-C no-vectorize-slp` was right to rounding. The cause is LLVM's SLP vectoriser, not estim's
//! arithmetic: narrowed with `-C llvm-args=-debug-counter=slp-vectorized=0-N`, one vectorised
//! tree, rooted at the stores of the `Symmetrized` arm below and reaching back into the product
//! X = −K Pₓᵤᵀ that every arm shares, was enough; the Joseph arm, the one executed, then used
//! wrong values of X. The two non-default forms are now finished in a separate, never-inlined
//! function, so no vector tree can span the arms; the results are bit for bit those of
//! opt-level 1. The AD bench's lockstep check (analytic against automatic derivatives, to
//! 10⁻¹²) is the guard: it fails before timing anything if this recurs. The reproduction is
//! `benches/errata/slp_joseph_repro.rs` (a bench target of the bench package).

use estim_core::checks::{
    all_finite, ensure_finite, ensure_nonnegative_diagonal, ensure_semidefinite_noise,
    ensure_shape, finite_or_error,
};
use estim_core::kernel::{self, Accum};
use estim_core::linalg::{symmetric_map, symmetric_sum_into_checked, symmetrize_add_checked};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::scalar::real;
use estim_core::{Alloc, Error, Parameter, Quantity, Real, Stage, StateSpace, error::Result};

use crate::report::{UpdateOutcome, UpdateReport};
use crate::scratch::UpdateScratch;
use estim_core::PropagatorWorkspace;

/// How the covariance is updated after a measurement.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum CovarianceUpdate {
    /// P⁺ = P − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ, symmetrised: the Joseph form, robust to round-off
    /// in K (see the [module docs](self)).
    #[default]
    Joseph,
    /// P⁺ = P − K Pₓᵤᵀ (= P − K S Kᵀ), as computed; may drift from symmetry over many steps.
    Standard,
    /// The standard form followed by P⁺ ← (P⁺ + P⁺ᵀ)/2.
    Symmetrized,
}

/// Which measurements an update rejects (and reports as [`Gated`](crate::UpdateOutcome::Gated),
/// leaving the estimate unchanged).
///
/// ```
/// use estim_filters::{Estimator, Gate, KalmanFilter, Update, UpdateOutcome};
/// use estim_core::{Gaussian, LinearMeasurement};
/// use estim_core::nalgebra::{Matrix2, Vector2};
///
/// // Reject what a consistent filter would see with probability below 1 %, whatever the
/// // measurement's dimension (for 2 components the threshold is χ²₂(0.99) = 9.21).
/// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
/// let mut kf = KalmanFilter::new(prior).with_gate(Gate::Probability(0.99))?;
/// let sensor = LinearMeasurement { observation: Matrix2::identity(), noise: Matrix2::identity() };
/// // S = P + R = 2 I: NIS = (2² + 2²)/2 = 4 < 9.21, used.
/// assert_eq!(kf.update(&sensor, &Vector2::new(2.0, 2.0))?.outcome, UpdateOutcome::Applied);
/// // A 10σ outlier: rejected, the estimate unchanged.
/// let before = kf.state().clone();
/// assert_eq!(kf.update(&sensor, &Vector2::new(10.0, -10.0))?.outcome, UpdateOutcome::Gated);
/// assert_eq!(kf.state(), &before);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Gate<T> {
    /// Rejects a measurement whose NIS exceeds this threshold (finite, > 0), whatever its
    /// dimension.
    Nis(T),
    /// Rejects a measurement whose NIS exceeds the χ²ₘ quantile at this probability (in
    /// (0, 1)), m its dimension: a consistent filter then rejects the fraction 1 − p of correct
    /// measurements from every sensor. The quantiles for m ≤ 16 are computed once, when the
    /// gate is set; larger m compute theirs at each update (a few microseconds). The
    /// quantiles come from statrs: without the `std` feature this gate is rejected as an
    /// invalid [`GateProbability`](estim_core::Parameter::GateProbability); use [`Gate::Nis`].
    Probability(f64),
}

/// A bare threshold is a [`Gate::Nis`]: `with_gate(9.21)`.
impl<T: Real> From<T> for Gate<T> {
    fn from(threshold: T) -> Self {
        Gate::Nis(threshold)
    }
}

/// The quantiles a [`Gate::Probability`] keeps, for m = 1..=GATE_TABLE.
const GATE_TABLE: usize = 16;

/// What every filter's measurement update is configured with: the covariance form and an
/// optional gate. Shared by the Kalman family and the fading-memory RLS.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct UpdateSettings<T> {
    /// The covariance update form.
    pub(crate) form: CovarianceUpdate,
    /// The gate, if any.
    pub(crate) gate: Option<Gate<T>>,
    /// For a [`Gate::Probability`]: its χ²ₘ quantiles, m = 1..=GATE_TABLE.
    quantiles: [T; GATE_TABLE],
}

impl<T: Real> UpdateSettings<T> {
    /// Joseph form, no gate.
    pub(crate) fn new() -> Self {
        Self {
            form: CovarianceUpdate::default(),
            gate: None,
            quantiles: [T::zero(); GATE_TABLE],
        }
    }

    /// Gates with `gate`: a threshold must be finite and > 0, a probability in (0, 1).
    pub(crate) fn with_gate(self, gate: Gate<T>) -> Result<Self> {
        let mut quantiles = [T::zero(); GATE_TABLE];
        match gate {
            Gate::Nis(threshold) if !(threshold.is_finite() && threshold > T::zero()) => {
                return Err(Error::InvalidParameter {
                    parameter: Parameter::GateThreshold,
                    value: estim_core::nalgebra::try_convert::<T, f64>(threshold)
                        .unwrap_or(f64::NAN),
                });
            }
            Gate::Nis(_) => {}
            Gate::Probability(p) => {
                let invalid = Error::InvalidParameter {
                    parameter: Parameter::GateProbability,
                    value: p,
                };
                if !(p > 0.0 && p < 1.0) {
                    return Err(invalid);
                }
                for (m, q) in quantiles.iter_mut().enumerate() {
                    *q = real(chi2_quantile(m + 1, p).ok_or(invalid)?);
                }
            }
        }
        Ok(Self {
            gate: Some(gate),
            quantiles,
            ..self
        })
    }

    /// The NIS above which an m-component measurement is rejected, if any.
    pub(crate) fn threshold(&self, m: usize) -> Option<T> {
        match self.gate? {
            Gate::Nis(threshold) => Some(threshold),
            Gate::Probability(_) if m == 0 => None,
            Gate::Probability(_) if m <= GATE_TABLE => Some(self.quantiles[m - 1]),
            // Always representable: p was validated when the gate was set.
            Gate::Probability(p) => chi2_quantile(m, p).map(real),
        }
    }
}

/// The tail every update shares (full-covariance and square-root): from the Cholesky factor L
/// of S = L Lᵀ and NIS = |L⁻¹ν|², the report's NIS, its log-likelihood
/// ln p = −½ (NIS + 2 Σ ln Lᵢᵢ + m ln 2π) and its outcome: [`Gated`](UpdateOutcome::Gated)
/// if the NIS exceeds `threshold` (returns `false`: the update does not apply), else
/// [`Applied`](UpdateOutcome::Applied).
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn report_statistics<T: Real, M: Dim>(
    l: &OMatrix<T, M, M>,
    nis: T,
    threshold: Option<T>,
    report: &mut UpdateReport<T, M>,
) -> bool
where
    DefaultAllocator: Alloc<M>,
{
    let m = l.nrows();
    let log_det = log_det_from_cholesky(l);
    report.nis = nis;
    report.log_likelihood = -real::<T>(0.5) * (nis + log_det + real::<T>(m as f64 * LN_TWO_PI));
    if threshold.is_some_and(|g| !(nis <= g)) {
        report.outcome = UpdateOutcome::Gated;
        return false;
    }
    report.outcome = UpdateOutcome::Applied;
    true
}

/// ln 2π, the f64 nearest (`(2π).ln()` needs std's or libm's logarithm; a test checks the
/// two agree to the bit).
pub(crate) const LN_TWO_PI: f64 = 1.837_877_066_409_345_3;

/// χ²_dof's `p` quantile, if finite.
#[cfg(feature = "std")]
fn chi2_quantile(dof: usize, p: f64) -> Option<f64> {
    crate::chi_square::quantile(dof, p)
}

/// Without std (no statrs) there are no χ² quantiles: a probability gate is refused.
#[cfg(not(feature = "std"))]
fn chi2_quantile(_dof: usize, _p: f64) -> Option<f64> {
    None
}

/// ln det S = 2 Σ ln Lᵢᵢ from the Cholesky factor: one logarithm of the product of the diagonal
/// when that product is comfortably normal (the common case), else the sum of logarithms (no
/// overflow or underflow for large or badly scaled S).
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn log_det_from_cholesky<T: Real, M: Dim>(l: &OMatrix<T, M, M>) -> T
where
    DefaultAllocator: Alloc<M>,
{
    let n = l.nrows();
    let product = (0..n).fold(T::one(), |p, i| p * l[(i, i)]);
    let two = real::<T>(2.0);
    // 1e-30 keeps clear of subnormals in both f32 and f64.
    if product.is_finite() && product > real::<T>(1e-30) {
        two * product.ln()
    } else {
        two * (0..n).fold(T::zero(), |acc, i| acc + l[(i, i)].ln())
    }
}

/// The Kalman update shared by every filter: see the [module docs](self).
///
/// On entry `scratch.predicted` holds the predicted measurement moments, `scratch.noise` R, and
/// `report.innovation` ν = z ⊖ ẑ (the caller applies the model's residual). The posterior goes
/// to `scratch.state` and `scratch.covariance`; nothing is written to the filter here, so the
/// caller commits it (by swapping buffers) only on `Ok(true)`; `Ok(false)` means gated.
///
/// The gain is solved in place from the right, K = Pₓᵤ L⁻ᵀ L⁻¹ (two triangular solves).
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn apply<T: Real, N: Dim, M: Dim, Pr: PropagatorWorkspace<T>, S: StateSpace<T, N>>(
    space: &S,
    state: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    scratch: &mut UpdateScratch<T, N, M, Pr>,
    report: &mut UpdateReport<T, M>,
    settings: UpdateSettings<T>,
) -> Result<bool>
where
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let UpdateScratch {
        predicted,
        noise,
        factor,
        whitened,
        gain,
        gain_s,
        gain_s_gain,
        state: new_state,
        covariance: new_covariance,
        step: tangent,
        cholesky,
        ..
    } = scratch;
    // One-step filters report no iterations (the iterated EKF sets its own after this).
    report.iterations = None;
    let m = predicted.mean.nrows();
    ensure_shape(noise, m, m, stage, Quantity::MeasurementNoise)?;
    ensure_shape(&report.innovation, m, 1, stage, Quantity::Innovation)?;
    // An indefinite R (even with a positive diagonal) can leave S positive definite and give
    // a posterior with negative variances: R must be semi-definite. O(m²) when R is
    // diagonally dominant, else one factorisation in `factor` (free until S is formed).
    ensure_semidefinite_noise(noise, factor, stage, Quantity::MeasurementNoise)?;
    // Inputs are not scanned up front: a non-finite z or R makes the factorisation, the NIS or
    // the committed results non-finite, and only then are they examined to name the culprit.
    let bad_input = |innovation: &OVector<T, M>, noise: &OMatrix<T, M, M>| {
        if !all_finite(innovation) {
            Some(Error::NonFinite {
                stage,
                quantity: Quantity::Measurement,
            })
        } else if !all_finite(noise) {
            Some(Error::NonFinite {
                stage,
                quantity: Quantity::MeasurementNoise,
            })
        } else {
            None
        }
    };

    // S = sym(cov ẑ + R), one pass that also checks it; a non-finite S is not factorised.
    let s = &mut report.innovation_covariance;
    let finite_s = symmetric_sum_into_checked(s, &predicted.covariance, noise);
    kernel::copy(factor, s);
    if !finite_s || !kernel::cholesky_in_place(factor, cholesky) {
        return Err(
            bad_input(&report.innovation, noise).unwrap_or(Error::NotPositiveDefinite {
                stage,
                quantity: Quantity::InnovationCovariance,
            }),
        );
    }
    kernel::copy(whitened, &report.innovation);
    kernel::solve_lower_in_place(factor, whitened);
    let nis = whitened.norm_squared();
    if !nis.is_finite() {
        // A bad measurement is an error, never a gated outlier. With finite inputs an
        // overflowing NIS (‖L⁻¹ν‖² beyond the largest float) is gated if a gate is set;
        // without one the update applies if the new estimate is finite (reported NIS ∞,
        // log-likelihood −∞), and fails below if not.
        if let Some(e) = bad_input(&report.innovation, noise) {
            return Err(e);
        }
    }
    if !report_statistics(factor, nis, settings.threshold(m), report) {
        return Ok(false);
    }

    // K = Pₓᵤ L⁻ᵀ L⁻¹, solved from the right in K's own storage.
    let cross = &predicted.cross_covariance;
    kernel::copy(gain, cross);
    kernel::solve_right_lower_transpose_in_place(factor, gain);
    kernel::solve_right_lower_in_place(factor, gain);
    if S::VECTOR {
        // x⁺ = x + K ν, fused.
        kernel::copy(new_state, state);
        kernel::mul(new_state, Accum::Add, T::one(), gain, &report.innovation);
    } else {
        // x⁺ = x ⊞ δ, δ = K ν. Both products add the finished K ν to x, so with ⊞ = + this
        // gives the fused form's bits.
        let delta = tangent.get_or_insert_with(|| state.clone());
        if delta.shape() != state.shape() {
            *delta = state.clone();
        }
        kernel::mul(delta, Accum::Replace, T::one(), gain, &report.innovation);
        space.plus_into(state, delta, new_state);
        ensure_shape(new_state, state.nrows(), 1, stage, Quantity::Mean)?;
    }
    // X = −K Pₓᵤᵀ (n × n, in the posterior's buffer).
    kernel::mul_tr(new_covariance, Accum::Replace, -T::one(), gain, cross);
    let finite = match settings.form {
        CovarianceUpdate::Joseph => {
            // G = K S Kᵀ = (K S) Kᵀ, both triangles (see below).
            kernel::mul(
                gain_s,
                Accum::Replace,
                T::one(),
                gain,
                &report.innovation_covariance,
            );
            kernel::mul_tr(gain_s_gain, Accum::Replace, T::one(), gain_s, gain);
            // P⁺ = ((P + X) + Xᵀ) + G, in that order, then symmetrised by averaging the two
            // triangles, in one pass that also checks finiteness: when K ≈ Pₓᵤ S⁻¹ nearly
            // cancels P (a state measured almost exactly), P + X is a subtraction of nearby
            // numbers and exact, and the small posterior keeps its relative accuracy. Every
            // shortcut measured worse in Lee & Huang's noise-free run
            // (tests/it/lee_huang_example.rs, bias_alone_gives_half_b_t_squared,
            // worst position error 7.2e-10 m with this form): grouping as P + (X + Xᵀ), or the
            // cheaper P + A Kᵀ + K Aᵀ (A = ½ K S − Pₓᵤ), 3000× larger; taking the lower
            // triangle of each term instead of averaging both (which would let G be computed
            // on one triangle only, half its product), 2.2e-6 m; the upper triangle alone, a
            // non-positive-definite S a few steps later.
            let half = real::<T>(0.5);
            let sources = [covariance.as_slice(), gain_s_gain.as_slice()];
            symmetric_map(
                new_covariance.nrows(),
                new_covariance.as_mut_slice(),
                sources,
                |x_ij, [p_ij, g_ij], x_ji, [p_ji, g_ji]| {
                    let lower = ((p_ij + x_ij) + x_ji) + g_ij;
                    let upper = ((p_ji + x_ji) + x_ij) + g_ji;
                    (lower + upper) * half
                },
            )
        }
        form => add_prior(form, new_covariance, covariance),
    };
    // A non-finite gain shows up in both the state and the covariance.
    ensure_finite(new_state, stage, Quantity::Mean)
        .and_then(|()| finite_or_error(finite, stage, Quantity::Covariance))
        .map_err(|e| bad_input(&report.innovation, noise).unwrap_or(e))?;
    // An ill-conditioned update (P ≈ 10²⁰ nearly rank one, R = 10⁻³: cond ≫ 1/ε) returned a
    // posterior with variances of −10¹³ as `Ok` in every full-P form (found by the fuzz test,
    // tests/it/fuzz.rs); only a square-root form avoids it. The diagonal costs O(n) to check.
    ensure_nonnegative_diagonal(new_covariance, stage, Quantity::Covariance)?;
    Ok(true)
}

/// P⁺ = P + X (X = −K Pₓᵤᵀ in `x`) in the [`Standard`](CovarianceUpdate::Standard) form, or
/// (P⁺ + P⁺ᵀ)/2 in the [`Symmetrized`](CovarianceUpdate::Symmetrized) one; true if finite.
///
/// Out of line on purpose, at a small cost to the two non-default forms (one call per update:
/// +16 and +17 instructions on 5,344 and 5,414 per 6/4 EKF step, callgrind):
/// inlined into [`apply`] beside the Joseph arm, LLVM 22's SLP vectoriser (rustc 1.95) built
/// one vector tree from the symmetrisation's stores back into the product X that all three
/// arms share, and the Joseph arm, the one executed, then used wrong values of X: the analytic
/// EKF of `benches/autodiff.rs` gave P⁺ wrong by 4·10⁻² from the first update on, in
/// optimised builds with 16 codegen units (not at opt-level 1, not with
/// `-C no-vectorize-slp`). See the [module docs](self), "Optimised builds".
#[inline(never)]
fn add_prior<T: Real, N: Dim>(
    form: CovarianceUpdate,
    x: &mut OMatrix<T, N, N>,
    covariance: &OMatrix<T, N, N>,
) -> bool
where
    DefaultAllocator: Alloc<N>,
{
    if form == CovarianceUpdate::Symmetrized {
        symmetrize_add_checked(x, covariance)
    } else {
        // P⁺ = P − K Pₓᵤᵀ, as computed.
        *x += covariance;
        all_finite(x)
    }
}

#[cfg(test)]
mod tests {
    /// The constant is the logarithm std computes, bit for bit, so the log-likelihood of a std
    /// build is what it was before the constant replaced the call.
    #[test]
    fn ln_two_pi_is_the_logarithm() {
        assert_eq!(
            super::LN_TWO_PI.to_bits(),
            (2.0 * core::f64::consts::PI).ln().to_bits()
        );
    }
}
