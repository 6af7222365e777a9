//! The multi-rate error-state Kalman filter (§2.6): predicted at 200 Hz, updated by GPS at
//! 5 Hz, with the accelerometer mechanisation alongside; and the paper's covariance recursion
//! written out by hand (information form), the independent route the tests compare with.

use estim_core::{Error, Gaussian, Quantity, Stage};
use estim_filters::{Estimator, KalmanFilter, Predict, Update, UpdateReport};
use nalgebra::{Matrix2, Matrix3, Matrix3x2, U2, U3, Vector2, Vector3};

#[cfg(feature = "std")]
use super::model::transition_matrix;
use super::model::{
    BiasCoupling, ErrorStateProcess, GpsMeasurement, Mechanisation,
    PRINTED_FILTER_ACCEL_NOISE_VARIANCE, Scenario,
};
#[cfg(feature = "std")]
use super::simulation::Simulator;

/// What the filter assumes: noise variance, prior covariance M₀, and the sign of Φ₁₃. The
/// consistent settings match the scenario; the others are the paper's printed variants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterSettings {
    /// W assumed by the filter \[(m/s²)²\].
    pub accel_noise_variance: f64,
    /// M₀, the prior covariance of (δp, δv, b).
    pub initial_covariance: Matrix3<f64>,
    /// The sign of Φ₁₃.
    pub coupling: BiasCoupling,
}

impl FilterSettings {
    /// The filter matching `scenario`: W = the scenario's, M₀ = diag(M₀ᵖ, M₀ᵛ, M₀ᵇ), Φ₁₃ = −Δt²/2.
    pub fn consistent(scenario: &Scenario) -> Self {
        Self {
            accel_noise_variance: scenario.accel_noise_variance,
            initial_covariance: scenario.error_prior_covariance(),
            coupling: BiasCoupling::Derived,
        }
    }

    /// The listing's W = 0.0016 (erratum E3), otherwise consistent.
    pub fn printed_noise(scenario: &Scenario) -> Self {
        Self {
            accel_noise_variance: PRINTED_FILTER_ACCEL_NOISE_VARIANCE,
            ..Self::consistent(scenario)
        }
    }

    /// The listing's M₀ = diag(1, 100, 0.01) (erratum E2): the position and velocity prior
    /// variances swapped.
    pub fn printed_prior(scenario: &Scenario) -> Self {
        let m = scenario.error_prior_covariance();
        Self {
            initial_covariance: Matrix3::from_diagonal(&Vector3::new(
                m[(1, 1)],
                m[(0, 0)],
                m[(2, 2)],
            )),
            ..Self::consistent(scenario)
        }
    }

    /// The printed Φ₁₃ = +Δt²/2 (erratum E4), otherwise consistent.
    pub fn printed_coupling(scenario: &Scenario) -> Self {
        Self {
            coupling: BiasCoupling::Printed,
            ..Self::consistent(scenario)
        }
    }

    /// Checks W (finite, ≥ 0) and M₀ (finite, symmetric, positive semi-definite).
    pub fn validate(&self) -> Result<(), Error> {
        if !(self.accel_noise_variance >= 0.0 && self.accel_noise_variance.is_finite()) {
            return Err(Error::NotPositiveSemiDefinite {
                stage: Stage::Construction,
                quantity: Quantity::ProcessNoise,
            });
        }
        Gaussian::new(Vector3::zeros(), self.initial_covariance).map(|_| ())
    }

    /// The process model these settings give.
    pub fn process(&self) -> ErrorStateProcess {
        ErrorStateProcess {
            accel_noise_variance: self.accel_noise_variance,
            coupling: self.coupling,
        }
    }
}

/// The paper's filter: the accelerometer mechanisation (p_c, v_c) and a linear Kalman filter on
/// the error state δx = (δp, δv, b), prior N(0, M₀).
///
/// Per accelerometer sample: [`propagate`](Self::propagate) (mechanisation step and
/// δx̄ ← Φ δx̂, M ← Φ P Φᵀ + Γ W Γᵀ). Per GPS fix: [`update`](Self::update) with
/// δz = z − (p_c, v_c). The mechanisation is never reset (open loop, as in the paper); the
/// estimates are p̂ = p_c + δp̂, v̂ = v_c + δv̂, b̂.
#[derive(Clone, Debug, PartialEq)]
pub struct LuFilter {
    kalman: KalmanFilter<f64, U3>,
    mechanisation: Mechanisation,
    process: ErrorStateProcess,
    gps: GpsMeasurement,
    dt: f64,
}

impl LuFilter {
    /// The filter for `scenario` with `settings`; the mechanisation starts at the prior means.
    /// Errors if the scenario is invalid ([`Scenario::validate`]) or M₀ or W is not a valid
    /// covariance.
    pub fn new(scenario: &Scenario, settings: &FilterSettings) -> Result<Self, Error> {
        scenario.validate()?;
        settings.validate()?;
        let prior = Gaussian::new(Vector3::zeros(), settings.initial_covariance)?;
        Ok(Self {
            kalman: KalmanFilter::new(prior),
            mechanisation: Mechanisation::new(scenario.position_mean, scenario.velocity_mean),
            process: settings.process(),
            gps: scenario.gps(),
            dt: scenario.dt,
        })
    }

    /// One accelerometer sample a_c(t_j): mechanisation and error-state prediction to t_{j+1}.
    ///
    /// Errors (the filter unchanged): a non-finite sample ([`Error::NonFinite`], quantity
    /// [`Measurement`](Quantity::Measurement): the accelerometer's reading), and the
    /// prediction's errors.
    pub fn propagate(&mut self, acceleration: f64) -> Result<(), Error> {
        if !acceleration.is_finite() {
            // It would turn the mechanisation's position and velocity into NaN, and every
            // later update would blame the GPS fix.
            return Err(Error::NonFinite {
                stage: Stage::Prediction,
                quantity: Quantity::Measurement,
            });
        }
        self.kalman.predict(&self.process, &(), self.dt)?;
        self.mechanisation.step(acceleration, self.dt);
        Ok(())
    }

    /// A GPS fix z = (z_p, z_v) at the current time. The report's innovation is the paper's
    /// residual r = δz − H δx̄.
    pub fn update(&mut self, z: &Vector2<f64>) -> Result<UpdateReport<f64, U2>, Error> {
        let dz = Vector2::new(
            z[0] - self.mechanisation.position,
            z[1] - self.mechanisation.velocity,
        );
        self.kalman.update(&self.gps, &dz)
    }

    /// The Kalman filter on the error state.
    pub fn kalman(&self) -> &KalmanFilter<f64, U3> {
        &self.kalman
    }

    /// δx̂ = (δp̂, δv̂, b̂).
    pub fn error_estimate(&self) -> &Vector3<f64> {
        self.kalman.state()
    }

    /// P (or M between fixes).
    pub fn covariance(&self) -> &Matrix3<f64> {
        self.kalman.covariance()
    }

    /// The mechanisation (p_c, v_c).
    pub fn mechanisation(&self) -> &Mechanisation {
        &self.mechanisation
    }

    /// (p̂, v̂, b̂) = (p_c + δp̂, v_c + δv̂, b̂).
    pub fn estimate(&self) -> Vector3<f64> {
        let x = self.kalman.state();
        Vector3::new(
            self.mechanisation.position + x[0],
            self.mechanisation.velocity + x[1],
            x[2],
        )
    }

    /// The gain of the last update, K = P Hᵀ V⁻¹ (valid right after an update).
    pub fn gain(&self) -> Matrix3x2<f64> {
        gain(self.kalman.covariance(), &self.gps)
    }
}

/// K = P Hᵀ V⁻¹ from the posterior P (§2.6).
fn gain(p: &Matrix3<f64>, gps: &GpsMeasurement) -> Matrix3x2<f64> {
    let v_inv = Matrix2::new(
        1.0 / gps.position_variance,
        0.0,
        0.0,
        1.0 / gps.velocity_variance,
    );
    p * GpsMeasurement::observation().transpose() * v_inv
}

#[cfg(feature = "std")]
/// The deterministic covariances and gains at the GPS updates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CovarianceHistory {
    /// Update times \[s\]; entry 0 is t = 0 (the prior).
    pub time: Vec<f64>,
    /// A priori M(t_i) (entry 0: M₀).
    pub prior: Vec<Matrix3<f64>>,
    /// A posteriori P(t_i) (entry 0: M₀).
    pub posterior: Vec<Matrix3<f64>>,
    /// K(t_i) = P(t_i) Hᵀ V⁻¹ (entry 0: zero).
    pub gain: Vec<Matrix3x2<f64>>,
}

#[cfg(feature = "std")]
impl CovarianceHistory {
    /// The index of the entry nearest to time `t`.
    pub fn index_at(&self, t: f64) -> usize {
        nearest(&self.time, t)
    }

    /// √diag P at entry `i`: (σ_δp \[m\], σ_δv \[m/s\], σ_b \[m/s²\]).
    ///
    /// # Panics
    /// When `i` is not an entry (`i` ≥ the length of `time`), as indexing does.
    #[track_caller]
    pub fn sigma(&self, i: usize) -> Vector3<f64> {
        self.posterior[i].diagonal().map(f64::sqrt)
    }
}

#[cfg(feature = "std")]
pub(crate) fn nearest(times: &[f64], t: f64) -> usize {
    let mut best = 0;
    for (i, &ti) in times.iter().enumerate() {
        if (ti - t).abs() < (times[best] - t).abs() {
            best = i;
        }
    }
    best
}

#[cfg(feature = "std")]
/// The paper's covariance recursion (§2.6) written out, for `steps` accelerometer steps:
/// M ← Φ P Φᵀ + Γ W Γᵀ each step and, every `gps_every` steps, the information form
/// P = (M⁻¹ + Hᵀ V⁻¹ H)⁻¹, K = P Hᵀ V⁻¹. An independent route to the framework filter's
/// (Joseph-form) covariance. Errors if the scenario or settings are invalid, `steps` exceeds
/// [`MAX_STEPS`](crate::limits::MAX_STEPS) ([`Parameter::StepCount`](estim_core::Parameter)),
/// or M or the information matrix is not invertible.
pub fn covariance_history(
    scenario: &Scenario,
    settings: &FilterSettings,
    steps: usize,
) -> Result<CovarianceHistory, Error> {
    crate::limits::check_steps(steps)?;
    scenario.validate()?;
    settings.validate()?;
    let phi = transition_matrix(scenario.dt, settings.coupling);
    let q = settings.process().noise_covariance(scenario.dt);
    let gps = scenario.gps();
    let h = GpsMeasurement::observation();
    let v_inv = Matrix2::new(
        1.0 / gps.position_variance,
        0.0,
        0.0,
        1.0 / gps.velocity_variance,
    );
    let information = h.transpose() * v_inv * h;
    let singular = Error::NotPositiveDefinite {
        stage: Stage::Update,
        quantity: Quantity::Covariance,
    };
    let m0 = settings.initial_covariance;
    let mut history = CovarianceHistory {
        time: vec![0.0],
        prior: vec![m0],
        posterior: vec![m0],
        gain: vec![Matrix3x2::zeros()],
    };
    let mut p = m0;
    for j in 1..=steps {
        p = phi * p * phi.transpose() + q;
        if j % scenario.gps_every == 0 {
            let m = p;
            let m_inv = m.try_inverse().ok_or(singular)?;
            p = (m_inv + information).try_inverse().ok_or(singular)?;
            p = (p + p.transpose()) * 0.5;
            history.time.push(j as f64 * scenario.dt);
            history.prior.push(m);
            history.posterior.push(p);
            history.gain.push(gain(&p, &gps));
        }
    }
    Ok(history)
}

#[cfg(feature = "std")]
/// One realization filtered, recorded at t = 0 and at every GPS update.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Realization {
    /// Times \[s\] (0, then the update times).
    pub time: Vec<f64>,
    /// The true error state δx.
    pub truth: Vec<Vector3<f64>>,
    /// The estimate δx̂ (a posteriori).
    pub estimate: Vec<Vector3<f64>>,
    /// The estimation error e = δx − δx̂ = (p − p̂, v − v̂, b − b̂).
    pub error: Vec<Vector3<f64>>,
    /// The filter's √diag P.
    pub sigma: Vec<Vector3<f64>>,
    /// The residual r = δz − H δx̄ at each update (entry 0: zero).
    pub residual: Vec<Vector2<f64>>,
    /// The gain K at each update (entry 0: zero).
    pub gain: Vec<Matrix3x2<f64>>,
    /// The mechanisation error before filtering, (p − p_c, v − v_c) (= the first two of δx).
    pub mechanisation_error: Vec<Vector2<f64>>,
}

#[cfg(feature = "std")]
/// Runs the filter on one realization of `scenario` (seed `seed`) and records it.
///
/// Errors: an invalid scenario or settings ([`LuFilter::new`]; at most
/// [`MAX_STEPS`](crate::limits::MAX_STEPS) steps, so the run ends), or a filter failure.
pub fn run_realization(
    scenario: &Scenario,
    settings: &FilterSettings,
    seed: u64,
) -> Result<Realization, Error> {
    let mut filter = LuFilter::new(scenario, settings)?;
    let mut sim = Simulator::new(scenario, seed);
    let mut out = Realization::default();
    let mut record =
        |t: f64, sim: &Simulator, filter: &LuFilter, r: Vector2<f64>, k: Matrix3x2<f64>| {
            let dx = sim.truth().error_state(filter.mechanisation());
            let xh = *filter.error_estimate();
            out.time.push(t);
            out.truth.push(dx);
            out.estimate.push(xh);
            out.error.push(dx - xh);
            out.sigma
                .push(filter.covariance().diagonal().map(f64::sqrt));
            out.residual.push(r);
            out.gain.push(k);
            out.mechanisation_error.push(Vector2::new(dx[0], dx[1]));
        };
    record(0.0, &sim, &filter, Vector2::zeros(), Matrix3x2::zeros());
    for _ in 0..scenario.steps {
        let a = sim.accelerometer();
        filter.propagate(a)?;
        if sim.gps_due() {
            let z = sim.gps();
            let report = filter.update(&z)?;
            record(sim.time(), &sim, &filter, report.innovation, filter.gain());
        }
    }
    Ok(out)
}
