//! The own-ship trajectory estimator (OTE, eq 40–48) on the framework's
//! [`FadingMemoryRls`], and its steady state.
//!
//! Per CKF cycle k, after the CKF update (erratum E3 for the two definitions):
//!
//! ```text
//! Z_p     = g(D̂_{k|k})                       pseudo-measurement (eq 40, g of eq 27/28)
//! r̂_e     = (D̂_{k|k}[2], D̂_{k|k}[3])         CKF velocity (eq 45), the RLS prior
//! M       = P_p/γ,  K_p = M (M + S_p)⁻¹,  P_p ← (I − K_p) M         (eq 46/47, B = I)
//! r̂_e     ← r̂_e + K_p (Z_p − r̂_e)                                  (eq 48)
//! D̂_{k|k}[2..3] ← r̂_e                        fed back to the CKF ("input vector of the CKF
//!                                              in the next computational cycle")
//! ```
//!
//! The measurement is z = B r_e + n, B = I₂, n ~ N(0, S_p): a [`LinearMeasurement`] with
//! H = I₂, R = S_p. P_p is carried by the RLS from cycle to cycle; its state is reset to the
//! CKF velocity before each update. The CKF covariance is left unchanged by the feedback (the
//! paper is silent; the OTE's P_p is a fading-memory weight, not an error covariance of the
//! CKF's velocity, erratum E9).
//!
//! **Steady state** (B = I, 0 < γ < 1): the information form P_p⁻¹ ← γ P_p⁻¹ + S_p⁻¹ gives
//! P_p(k)⁻¹ = γᵏ P_p(0)⁻¹ + S_p⁻¹ (1 − γᵏ)/(1 − γ), so P_p → (1 − γ) S_p and
//! K_p = P_p S_p⁻¹ → (1 − γ) I for any SPD S_p. The OTE then is r̂ ← γ r̂ + (1 − γ) Z_p,
//! independent of S_p, with time constant T/(1 − γ).

use estim_core::{Error, Gaussian, LinearMeasurement, Quantity, Stage};
use estim_filters::{Estimator, FadingMemoryRls, Update};
use nalgebra::{Cholesky, Matrix2, U2, U6, Vector2};

use super::likelihood::LikelihoodForm;

/// Settings of the OTE.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OteSettings {
    /// Forgetting factor γ, 0 < γ ≤ 1.
    pub forgetting: f64,
    /// S_p: weight (nominal pseudo-measurement noise covariance) \[(m/s)²\].
    pub weight: Matrix2<f64>,
    /// P_p(0) \[(m/s)²\].
    pub initial_covariance: Matrix2<f64>,
    /// Which formula builds the pseudo-measurement.
    pub likelihood: LikelihoodForm,
}

impl OteSettings {
    /// The settings of the issue: γ = 0.95, S_p = 0.01 I, P_p(0) = I, eq 27/28.
    pub fn issue() -> Self {
        Self {
            forgetting: 0.95,
            weight: Matrix2::identity() * 0.01,
            initial_covariance: Matrix2::identity(),
            likelihood: LikelihoodForm::Consistent,
        }
    }

    /// The closed-form steady gain (1 − γ) I.
    pub fn steady_gain(&self) -> Matrix2<f64> {
        Matrix2::identity() * (1.0 - self.forgetting)
    }

    /// The closed-form steady P_p = (1 − γ) S_p.
    pub fn steady_covariance(&self) -> Matrix2<f64> {
        self.weight * (1.0 - self.forgetting)
    }
}

/// What one OTE cycle did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OteStep {
    /// The pseudo-measurement Z_p = g(D̂).
    pub pseudo_measurement: Vector2<f64>,
    /// The CKF velocity before the correction.
    pub prior_velocity: Vector2<f64>,
    /// The corrected velocity written back to the CKF.
    pub velocity: Vector2<f64>,
    /// K_p = (P_p/γ)(P_p/γ + S_p)⁻¹ of this cycle.
    pub gain: Matrix2<f64>,
    /// P_p after the update.
    pub covariance: Matrix2<f64>,
}

/// The own-ship trajectory estimator: a [`FadingMemoryRls`] over the velocity, fed by g(D̂).
#[derive(Clone, Debug, PartialEq)]
pub struct OwnShipTrajectoryEstimator {
    rls: FadingMemoryRls<f64, U2>,
    measurement: LinearMeasurement<f64, U2, U2>,
    likelihood: LikelihoodForm,
}

impl OwnShipTrajectoryEstimator {
    /// A new OTE. Errors if γ ∉ (0, 1] or P_p(0) is not a valid covariance.
    pub fn new(settings: &OteSettings) -> Result<Self, Error> {
        let prior = Gaussian::new(Vector2::zeros(), settings.initial_covariance)?;
        Ok(Self {
            rls: FadingMemoryRls::new(prior, settings.forgetting)?,
            measurement: LinearMeasurement {
                observation: Matrix2::identity(),
                noise: settings.weight,
            },
            likelihood: settings.likelihood,
        })
    }

    /// P_p.
    pub fn covariance(&self) -> &Matrix2<f64> {
        self.rls.covariance()
    }

    /// The underlying fading-memory RLS.
    pub fn rls(&self) -> &FadingMemoryRls<f64, U2> {
        &self.rls
    }

    /// One OTE cycle on the velocity `prior` with pseudo-measurement `z` (eq 46–48), without a
    /// CKF: returns the step record. On an error (a non-finite prior or reading, an innovation
    /// covariance that is not positive definite) the estimator is as it was.
    pub fn update(&mut self, prior: &Vector2<f64>, z: &Vector2<f64>) -> Result<OteStep, Error> {
        let p = *self.rls.covariance();
        // The cycle runs on a copy (two 2-vectors and a 2 × 2 matrix), committed at the end.
        let mut rls = self.rls.clone();
        rls.reset(Gaussian::new_unchecked(*prior, p));
        let report = rls.update(&self.measurement, z)?;
        // K_p = M (M + S_p)⁻¹ with M = P_p/γ; M + S_p is the report's innovation covariance.
        let s = Cholesky::new(report.innovation_covariance).ok_or(Error::NotPositiveDefinite {
            stage: Stage::Update,
            quantity: Quantity::InnovationCovariance,
        })?;
        let m = p / rls.forgetting_factor();
        let gain = s.solve(&m.transpose()).transpose();
        self.rls = rls;
        Ok(OteStep {
            pseudo_measurement: *z,
            prior_velocity: *prior,
            velocity: *self.rls.state(),
            gain,
            covariance: *self.rls.covariance(),
        })
    }

    /// One OTE cycle on a CKF: builds Z_p = g(D̂) from the filter's state, updates the RLS with
    /// the CKF velocity as prior, and writes the corrected velocity back into the filter
    /// (covariance unchanged). Errors (filter untouched) if g is not finite (D̂ at the origin).
    pub fn correct<F: Estimator<f64, U6>>(&mut self, filter: &mut F) -> Result<OteStep, Error> {
        let state = *filter.state();
        let z = self.likelihood.eval(&state);
        if !z.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Measurement,
            });
        }
        let step = self.update(&Vector2::new(state[2], state[3]), &z)?;
        let mut corrected = state;
        corrected[2] = step.velocity.x;
        corrected[3] = step.velocity.y;
        let covariance = *filter.covariance();
        filter.reset(Gaussian::new_unchecked(corrected, covariance));
        Ok(step)
    }
}

/// The OTE's gain and P_p after many cycles, from the framework RLS, with the closed forms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OteSteadyState {
    /// The settings.
    pub settings: OteSettings,
    /// Cycles iterated.
    pub steps: usize,
    /// K_p after `steps` cycles (from the RLS).
    pub gain: Matrix2<f64>,
    /// P_p after `steps` cycles (from the RLS).
    pub covariance: Matrix2<f64>,
    /// (1 − γ) I.
    pub gain_closed_form: Matrix2<f64>,
    /// (1 − γ) S_p.
    pub covariance_closed_form: Matrix2<f64>,
}

/// Iterates the OTE (B = I) `steps` times. P_p and K_p do not depend on the data, so zero
/// pseudo-measurements are used.
///
/// Errors: invalid settings, or `steps` above [`MAX_STEPS`](crate::limits::MAX_STEPS)
/// ([`Parameter::StepCount`](estim_core::Parameter), so the call returns in bounded time).
pub fn ote_steady_state(settings: &OteSettings, steps: usize) -> Result<OteSteadyState, Error> {
    crate::limits::check_steps(steps)?;
    let mut ote = OwnShipTrajectoryEstimator::new(settings)?;
    let mut gain = Matrix2::zeros();
    for _ in 0..steps {
        gain = ote.update(&Vector2::zeros(), &Vector2::zeros())?.gain;
    }
    Ok(OteSteadyState {
        settings: *settings,
        steps,
        gain,
        covariance: *ote.covariance(),
        gain_closed_form: settings.steady_gain(),
        covariance_closed_form: settings.steady_covariance(),
    })
}
