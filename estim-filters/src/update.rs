//! The measurement update, written once for every filter.
//!
//! Given the predicted measurement moments (ẑ, cov(ẑ), Pₓᵤ = cov(x, ẑ)) from any moment
//! propagator, the noise R and the innovation ν = z ⊖ ẑ:
//!
//! ```text
//! S  = cov(ẑ) + R                       (factorised by Cholesky, S = L Lᵀ; never inverted)
//! K  = Pₓᵤ S⁻¹                          (solved: S Kᵀ = Pₓᵤᵀ)
//! x⁺ = x + K ν
//! P⁺ = P − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ     (Joseph)
//! NIS = νᵀ S⁻¹ ν,   ln p(z) = −½ (NIS + 2 Σ ln Lᵢᵢ + m ln 2π)
//! ```
//!
//! For a linear(ised) model, Pₓᵤ = P Hᵀ and S = H P Hᵀ + R, and the Joseph line expands to the
//! familiar (I − K H) P (I − K H)ᵀ + K R Kᵀ. Like it, it is insensitive to first-order errors
//! in K: with K = K* + δK it equals P − K* S K*ᵀ + δK S δKᵀ. But it needs no H, so it serves
//! the unscented filter too.

use estim_core::linalg::{all_finite, ensure_finite, ensure_shape, symmetrize};
use estim_core::nalgebra::{Cholesky, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::propagate::Moments;
use estim_core::scalar::real;
use estim_core::{Alloc, Error, Parameter, Quantity, Real, Stage, error::Result};

use crate::report::{UpdateOutcome, UpdateReport};

/// How the covariance is updated after a measurement.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
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

/// What every filter's measurement update is configured with: the covariance form and an
/// optional NIS gate. Shared by the Kalman family and the fading-memory RLS.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct UpdateSettings<T> {
    /// The covariance update form.
    pub(crate) form: CovarianceUpdate,
    /// The NIS gate threshold, if any.
    pub(crate) gate: Option<T>,
}

impl<T: Real> UpdateSettings<T> {
    /// Joseph form, no gate.
    pub(crate) fn new() -> Self {
        Self {
            form: CovarianceUpdate::default(),
            gate: None,
        }
    }

    /// Gates at `threshold`, which must be finite and > 0.
    pub(crate) fn with_gate(self, threshold: T) -> Result<Self> {
        if threshold.is_finite() && threshold > T::zero() {
            Ok(Self {
                gate: Some(threshold),
                ..self
            })
        } else {
            Err(Error::InvalidParameter {
                parameter: Parameter::GateThreshold,
                value: estim_core::nalgebra::try_convert::<T, f64>(threshold).unwrap_or(f64::NAN),
            })
        }
    }
}

/// A state estimate and its covariance, computed but not yet committed to a filter.
pub(crate) type Estimate<T, N> = (OVector<T, N>, OMatrix<T, N, N>);

/// The result of [`apply`]: the new estimate (`None` if gated) and the report.
pub(crate) type Posterior<T, N, M> = (Option<Estimate<T, N>>, UpdateReport<T, M>);

/// ln det S = 2 Σ ln Lᵢᵢ from the Cholesky factor: one logarithm of the product of the diagonal
/// when that product is comfortably normal (the common case), else the sum of logarithms (no
/// overflow or underflow for large or badly scaled S).
#[inline(always)]
fn log_det_from_cholesky<T: Real, M: Dim>(l: &OMatrix<T, M, M>) -> T
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
/// `innovation` is z ⊖ ẑ (the caller applies the model's residual). Nothing is written to the
/// filter here: the caller commits the returned estimate, so a failure leaves it untouched.
#[inline(always)]
pub(crate) fn apply<T: Real, N: Dim, M: Dim>(
    state: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    predicted: Moments<T, N, M>,
    noise: OMatrix<T, M, M>,
    innovation: OVector<T, M>,
    settings: UpdateSettings<T>,
) -> Result<Posterior<T, N, M>>
where
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let m = predicted.mean.nrows();
    ensure_shape(&noise, m, m, stage, Quantity::MeasurementNoise)?;
    ensure_shape(&innovation, m, 1, stage, Quantity::Measurement)?;
    // Inputs are not scanned up front: a non-finite z or R makes the factorisation, the NIS or
    // the committed results non-finite, and only then are they examined to name the culprit.
    let bad_input = |innovation: &OVector<T, M>| {
        if !all_finite(innovation) {
            Some(Error::NonFinite {
                stage,
                quantity: Quantity::Measurement,
            })
        } else if !all_finite(&noise) {
            Some(Error::NonFinite {
                stage,
                quantity: Quantity::MeasurementNoise,
            })
        } else {
            None
        }
    };

    let mut s = &predicted.covariance + &noise;
    symmetrize(&mut s);
    let Some(chol) = Cholesky::new(s.clone()) else {
        return Err(
            bad_input(&innovation).unwrap_or(Error::NotPositiveDefinite {
                stage,
                quantity: Quantity::InnovationCovariance,
            }),
        );
    };
    let nis = innovation.dot(&chol.solve(&innovation));
    if !nis.is_finite() {
        // A bad measurement is an error, never a gated outlier. (With finite inputs an
        // overflowing NIS is gated if a gate is set, else it fails below.)
        if let Some(e) = bad_input(&innovation) {
            return Err(e);
        }
    }
    let log_det = log_det_from_cholesky(chol.l_dirty());
    let log_likelihood = -real::<T>(0.5)
        * (nis + log_det + real::<T>(m as f64 * (2.0 * core::f64::consts::PI).ln()));
    let mut report = UpdateReport {
        innovation,
        innovation_covariance: s,
        nis,
        log_likelihood,
        outcome: UpdateOutcome::Applied,
    };
    if settings.gate.is_some_and(|g| !(nis <= g)) {
        report.outcome = UpdateOutcome::Gated;
        return Ok((None, report));
    }

    let cross = predicted.cross_covariance;
    let gain = chol.solve(&cross.transpose()).transpose();
    let new_state = state + &gain * &report.innovation;
    let k_cross_t = &gain * cross.transpose();
    let mut new_covariance = covariance - &k_cross_t;
    match settings.form {
        CovarianceUpdate::Joseph => {
            // P − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ
            new_covariance -= k_cross_t.transpose();
            let ks = &gain * &report.innovation_covariance;
            new_covariance += ks * gain.transpose();
            symmetrize(&mut new_covariance);
        }
        CovarianceUpdate::Standard => {}
        CovarianceUpdate::Symmetrized => symmetrize(&mut new_covariance),
    }
    // A non-finite gain shows up in both of these.
    ensure_finite(&new_state, stage, Quantity::Mean)
        .and_then(|()| ensure_finite(&new_covariance, stage, Quantity::Covariance))
        .map_err(|e| bad_input(&report.innovation).unwrap_or(e))?;
    Ok((Some((new_state, new_covariance)), report))
}
