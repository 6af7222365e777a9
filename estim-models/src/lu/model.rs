//! The scenario (truth and sensor parameters), the error-state process, the GPS measurement
//! and the accelerometer mechanisation.
//!
//! Error state δx = (δp, δv, b) = (p − p_c, v − v_c, b), one accelerometer step Δt:
//!
//! ```text
//! δx_{j+1} = Φ δx_j − Γ w_j,   Φ = [[1, Δt, −Δt²/2], [0, 1, −Δt], [0, 0, 1]],   Γ = (Δt²/2, Δt, 0)
//! Q = Γ W Γᵀ,   δz = (z_p − p_c, z_v − v_c) = H δx + η,   H = [[1, 0, 0], [0, 1, 0]],   R = V
//! ```

use crate::limits::{check_steps, steps_for_duration};
use estim_core::{
    Error, LinearMeasurementModel, LinearProcessModel, MeasurementJacobian, MeasurementModel,
    Parameter, ProcessJacobian, ProcessModel, Quantity, Stage,
};
use nalgebra::{Matrix2, Matrix2x3, Matrix3, U2, U3, Vector2, Vector3};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// Accelerometer sample period Δt = 0.005 s (200 Hz).
pub const ACCEL_DT: f64 = 0.005;
/// GPS fixes come every 40 accelerometer steps: 40 Δt = 0.2 s, 5 Hz (erratum E1).
pub const GPS_EVERY: usize = 40;
/// Accelerometer white-noise variance W = 0.0004 (m/s²)², σ = 0.02 m/s² (erratum E3).
pub const ACCEL_NOISE_VARIANCE: f64 = 0.0004;
/// The variance the paper's filter listing prints for W (erratum E3): 0.0016.
pub const PRINTED_FILTER_ACCEL_NOISE_VARIANCE: f64 = 0.0016;

/// How the true position and velocity are generated from the true acceleration (erratum E5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TruthIntegration {
    /// The paper's §2.4 assumption, which the error model needs: the truth is integrated from
    /// a(t_j) by the same recursion as the mechanisation (p_E, v_E), so the error state obeys
    /// Φ exactly. estim's default.
    #[default]
    Euler,
    /// The closed forms of §2.1 (p(t), v(t) exact). The Euler mechanisation then differs from
    /// the truth by a deterministic quadrature error that the filter does not model.
    Exact,
}

/// The sign of Φ₁₃, the bias → position coupling of the error-state transition (erratum E4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BiasCoupling {
    /// Φ₁₃ = −Δt²/2: the bias enters like the noise, −(Δt²/2)(b + w) (the derivation).
    #[default]
    Derived,
    /// Φ₁₃ = +Δt²/2 as printed in §2.4 and §2.6.
    Printed,
}

/// Truth and sensors of the paper's experiment (§2.1–2.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scenario {
    /// Amplitude A of the true acceleration a(t) = A sin(2π f t) \[m/s²\].
    pub amplitude: f64,
    /// Its frequency f \[Hz\] (the paper's "ω = 0.1 rad/s", erratum E6).
    pub frequency: f64,
    /// Mean of p(0) \[m\] (also the mechanisation's p_c(0)).
    pub position_mean: f64,
    /// Variance of p(0) \[m²\].
    pub position_variance: f64,
    /// Mean of v(0) \[m/s\] (also the mechanisation's v_c(0)).
    pub velocity_mean: f64,
    /// Variance of v(0) \[(m/s)²\].
    pub velocity_variance: f64,
    /// Variance of the constant accelerometer bias b (mean 0) \[(m/s²)²\].
    pub bias_variance: f64,
    /// Accelerometer white-noise variance W \[(m/s²)²\].
    pub accel_noise_variance: f64,
    /// GPS position noise variance \[m²\].
    pub gps_position_variance: f64,
    /// GPS velocity noise variance \[(m/s)²\].
    pub gps_velocity_variance: f64,
    /// Accelerometer period Δt \[s\].
    pub dt: f64,
    /// A GPS fix every this many accelerometer steps.
    pub gps_every: usize,
    /// Number of accelerometer steps (6000 for 30 s).
    pub steps: usize,
    /// How the truth is integrated.
    pub truth: TruthIntegration,
}

impl Scenario {
    /// The paper's experiment as estim reads it: A = 10 m/s², f = 0.1 Hz, p(0) ~ N(0, 100 m²),
    /// v(0) ~ N(100 m/s, 1 (m/s)²), b ~ N(0, 0.01 (m/s²)²), W = 0.0004 (m/s²)², GPS
    /// V = diag(1 m², 0.0016 (m/s)²) every 0.2 s, Δt = 0.005 s, 30 s, Euler-consistent truth.
    pub fn paper() -> Self {
        Self {
            amplitude: 10.0,
            frequency: 0.1,
            position_mean: 0.0,
            position_variance: 100.0,
            velocity_mean: 100.0,
            velocity_variance: 1.0,
            bias_variance: 0.01,
            accel_noise_variance: ACCEL_NOISE_VARIANCE,
            gps_position_variance: 1.0,
            gps_velocity_variance: 0.0016,
            dt: ACCEL_DT,
            gps_every: GPS_EVERY,
            steps: 6000,
            truth: TruthIntegration::Euler,
        }
    }

    /// The same scenario over `seconds` (rounded to whole accelerometer steps). A duration
    /// that is NaN, negative, infinite or longer than [`MAX_STEPS`](crate::limits::MAX_STEPS) steps gives the step count
    /// `usize::MAX`, which [`validate`](Self::validate) (and so every simulator and runner)
    /// rejects with [`Parameter::StepCount`].
    ///
    /// ```
    /// use estim_models::lu::Scenario;
    /// assert_eq!(Scenario::paper().with_duration(10.0).steps, 2000);
    /// assert!(Scenario::paper().with_duration(f64::INFINITY).validate().is_err());
    /// ```
    pub fn with_duration(mut self, seconds: f64) -> Self {
        self.steps = steps_for_duration(seconds, self.dt).unwrap_or(usize::MAX);
        self
    }

    /// The same scenario with the truth integrated by `truth`.
    pub fn with_truth(mut self, truth: TruthIntegration) -> Self {
        self.truth = truth;
        self
    }

    /// Checks the parameters: Δt finite and > 0, a GPS fix every ≥ 1 steps, at most
    /// [`MAX_STEPS`](crate::limits::MAX_STEPS) steps, finite trajectory, prior and noise variances ≥ 0, GPS variances > 0.
    pub fn validate(&self) -> Result<(), Error> {
        check_steps(self.steps)?;
        if !(self.dt > 0.0 && self.dt.is_finite()) {
            return Err(Error::InvalidParameter {
                parameter: Parameter::StepSize,
                value: self.dt,
            });
        }
        if self.gps_every == 0 {
            return Err(Error::InvalidParameter {
                parameter: Parameter::SampleCount,
                value: 0.0,
            });
        }
        let finite = [
            self.amplitude,
            self.frequency,
            self.position_mean,
            self.velocity_mean,
        ];
        if !finite.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: Stage::Construction,
                quantity: Quantity::Mean,
            });
        }
        let semi_definite = |v: f64, quantity| {
            if v >= 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(Error::NotPositiveSemiDefinite {
                    stage: Stage::Construction,
                    quantity,
                })
            }
        };
        semi_definite(self.position_variance, Quantity::Covariance)?;
        semi_definite(self.velocity_variance, Quantity::Covariance)?;
        semi_definite(self.bias_variance, Quantity::Covariance)?;
        semi_definite(self.accel_noise_variance, Quantity::ProcessNoise)?;
        for v in [self.gps_position_variance, self.gps_velocity_variance] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(Error::NotPositiveDefinite {
                    stage: Stage::Construction,
                    quantity: Quantity::MeasurementNoise,
                });
            }
        }
        Ok(())
    }

    /// Run length \[s\].
    pub fn duration(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    /// Number of GPS updates (at steps gps_every, 2 gps_every, …, none at t = 0).
    pub fn updates(&self) -> usize {
        self.steps.checked_div(self.gps_every).unwrap_or(0)
    }

    /// The time of GPS update `k` ≥ 1: k · gps_every · Δt \[s\].
    pub fn update_time(&self, k: usize) -> f64 {
        // In f64: the integer product k · gps_every could overflow.
        k as f64 * self.gps_every as f64 * self.dt
    }

    /// The GPS update index nearest to time `t` (0 = the prior at t = 0).
    pub fn update_index(&self, t: f64) -> usize {
        let interval = self.gps_every as f64 * self.dt;
        ((t / interval).round().max(0.0) as usize).min(self.updates())
    }

    /// The true acceleration a(t) = A sin(2π f t) \[m/s²\].
    pub fn acceleration(&self, t: f64) -> f64 {
        self.amplitude * (2.0 * core::f64::consts::PI * self.frequency * t).sin()
    }

    /// The closed-form truth (p(t), v(t)) of §2.1 for initial values p₀, v₀.
    pub fn exact_position_velocity(&self, p0: f64, v0: f64, t: f64) -> (f64, f64) {
        let w = 2.0 * core::f64::consts::PI * self.frequency;
        let a = self.amplitude;
        let (s, c) = (w * t).sin_cos();
        let v = v0 + a / w - a / w * c;
        let p = p0 + (v0 + a / w) * t - a / (w * w) * s;
        (p, v)
    }

    /// The prior of the error state, diag(p variance, v variance, b variance) = M₀ in the state
    /// order (δp, δv, b) (erratum E2).
    pub fn error_prior_covariance(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::new(
            self.position_variance,
            self.velocity_variance,
            self.bias_variance,
        ))
    }

    /// The GPS measurement model with this scenario's noise.
    pub fn gps(&self) -> GpsMeasurement {
        GpsMeasurement {
            position_variance: self.gps_position_variance,
            velocity_variance: self.gps_velocity_variance,
        }
    }
}

impl Default for Scenario {
    fn default() -> Self {
        Self::paper()
    }
}

/// Φ(Δt) of the error state for the given sign of Φ₁₃.
pub fn transition_matrix(dt: f64, coupling: BiasCoupling) -> Matrix3<f64> {
    let half = 0.5 * dt * dt;
    let phi13 = match coupling {
        BiasCoupling::Derived => -half,
        BiasCoupling::Printed => half,
    };
    Matrix3::new(1.0, dt, phi13, 0.0, 1.0, -dt, 0.0, 0.0, 1.0)
}

/// Γ(Δt) = (Δt²/2, Δt, 0): how one accelerometer noise sample enters (δx_{j+1} = Φ δx_j − Γ w_j).
pub fn noise_input(dt: f64) -> Vector3<f64> {
    Vector3::new(0.5 * dt * dt, dt, 0.0)
}

/// The error-state process δx⁺ = Φ δx + w, w ~ N(0, Γ W Γᵀ) over one accelerometer step.
/// Linear: Jacobian Φ, Hessians zero. No input (the accelerometer drives the mechanisation,
/// not the error state).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorStateProcess {
    /// The accelerometer noise variance W the filter assumes \[(m/s²)²\].
    pub accel_noise_variance: f64,
    /// The sign of Φ₁₃.
    pub coupling: BiasCoupling,
}

impl ErrorStateProcess {
    /// The derived model with noise variance `w`.
    pub fn new(accel_noise_variance: f64) -> Self {
        Self {
            accel_noise_variance,
            coupling: BiasCoupling::Derived,
        }
    }

    /// Q(Δt) = Γ W Γᵀ.
    pub fn noise_covariance(&self, dt: f64) -> Matrix3<f64> {
        let g = noise_input(dt);
        g * g.transpose() * self.accel_noise_variance
    }
}

impl ProcessModel<f64, U3> for ErrorStateProcess {
    type Input = ();

    fn transition(&self, x: &Vector3<f64>, _: &(), dt: f64) -> Vector3<f64> {
        transition_matrix(dt, self.coupling) * x
    }

    fn process_noise(&self, _: &Vector3<f64>, _: &(), dt: f64) -> Matrix3<f64> {
        self.noise_covariance(dt)
    }
}

impl ProcessJacobian<f64, U3> for ErrorStateProcess {
    fn transition_jacobian(&self, _: &Vector3<f64>, _: &(), dt: f64) -> Matrix3<f64> {
        transition_matrix(dt, self.coupling)
    }
}

impl LinearProcessModel<f64, U3> for ErrorStateProcess {}

/// Affine: every Hessian is zero (the second-order filters and the derivative checker ask).
impl estim_core::ProcessHessian<f64, estim_core::nalgebra::U3> for ErrorStateProcess {
    fn transition_hessian(
        &self,
        _: &estim_core::nalgebra::OVector<f64, estim_core::nalgebra::U3>,
        _: &(),
        _: f64,
        _: usize,
    ) -> Option<
        estim_core::nalgebra::OMatrix<f64, estim_core::nalgebra::U3, estim_core::nalgebra::U3>,
    > {
        None
    }
}

/// The GPS fix as an error-state measurement: δz = (z_p − p_c, z_v − v_c) = H δx + η,
/// H = \[\[1, 0, 0\], \[0, 1, 0\]\], η ~ N(0, diag(position, velocity variance)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsMeasurement {
    /// Position noise variance \[m²\].
    pub position_variance: f64,
    /// Velocity noise variance \[(m/s)²\].
    pub velocity_variance: f64,
}

impl GpsMeasurement {
    /// H.
    pub fn observation() -> Matrix2x3<f64> {
        Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    }

    /// V = R.
    pub fn noise_covariance(&self) -> Matrix2<f64> {
        Matrix2::new(self.position_variance, 0.0, 0.0, self.velocity_variance)
    }
}

impl MeasurementModel<f64, U3, U2> for GpsMeasurement {
    fn measure(&self, x: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(x[0], x[1])
    }

    fn measurement_noise(&self, _: &Vector3<f64>) -> Matrix2<f64> {
        self.noise_covariance()
    }
}

impl MeasurementJacobian<f64, U3, U2> for GpsMeasurement {
    fn measurement_jacobian(&self, _: &Vector3<f64>) -> Matrix2x3<f64> {
        Self::observation()
    }
}

impl LinearMeasurementModel<f64, U3, U2> for GpsMeasurement {}

/// Affine: every Hessian is zero (the second-order filters and the derivative checker ask).
impl estim_core::MeasurementHessian<f64, estim_core::nalgebra::U3, estim_core::nalgebra::U2>
    for GpsMeasurement
{
    fn measurement_hessian(
        &self,
        _: &estim_core::nalgebra::OVector<f64, estim_core::nalgebra::U3>,
        _: usize,
    ) -> Option<
        estim_core::nalgebra::OMatrix<f64, estim_core::nalgebra::U3, estim_core::nalgebra::U3>,
    > {
        None
    }
}

/// The accelerometer mechanisation (§2.2), open loop, never reset:
///
/// ```text
/// v_c(j+1) = v_c(j) + a_c(j) Δt,   p_c(j+1) = p_c(j) + v_c(j) Δt + a_c(j) Δt²/2
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mechanisation {
    /// p_c \[m\].
    pub position: f64,
    /// v_c \[m/s\].
    pub velocity: f64,
}

impl Mechanisation {
    /// Starts at (p_c(0), v_c(0)).
    pub fn new(position: f64, velocity: f64) -> Self {
        Self { position, velocity }
    }

    /// One step with the accelerometer reading `acceleration` over `dt`.
    #[inline]
    pub fn step(&mut self, acceleration: f64, dt: f64) {
        self.position += self.velocity * dt + 0.5 * acceleration * dt * dt;
        self.velocity += acceleration * dt;
    }
}
