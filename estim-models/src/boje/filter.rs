//! The 6-state planar filter of eq 14–16 (corrected), as estim models.
//!
//! State x = (ẋ, ẏ, θ̇, x, y, θ); accelerometer period Δt.
//!
//! - [`PlanarProcess`]: the paper's linear process x⁺ = A x + B u + B v, whose input
//!   [`PlanarInput`] carries u = (E{ẍ}, E{ÿ}, θ̈) (eq 12) and Λ (eq 13, corrected), computed from
//!   the accelerometer sample with θ̄ = x̂\[5\], σ²_θ = P\[5,5\] ([`planar_input`]);
//!   Q = B Λ_vv Bᵀ.
//! - [`NonlinearPlanarProcess`] (a variant beyond the paper): the input is the raw
//!   accelerometer sample and θ enters f through eq 5, so the filter carries the
//!   heading–velocity coupling in P instead of folding σ²_θ into Q.
//! - [`RateSquaredMeasurement`]: θ̇² = x\[2\]² from the accelerometers (every step), R = λ44.
//! - [`PositionHeadingMeasurement`]: (x, y, θ) from GPS and compass (1 Hz), the heading
//!   residual wrapped to (−π, π].
//!
//! [`filter_step`] runs one accelerometer step on any estim filter: update with θ̇², update
//! with the fix when there is one, then
//! [`predict_correlated`](estim_filters::PredictCorrelated::predict_correlated) with the θ̇²
//! model and S = B Λ_vw. For the linear process this reproduces eq 16's one-step predictor
//! (test `eq16_predictor_equals_update_then_decorrelated_predict`).

use estim_core::error::Result;
use estim_core::nalgebra::{
    Matrix1, Matrix1x6, Matrix3, Matrix3x6, Matrix4, Matrix6, Matrix6x1, Matrix6x3, U1, U3, U6,
    Vector1, Vector3, Vector4, Vector6,
};
use estim_core::{
    LinearMeasurementModel, MeasurementHessian, MeasurementJacobian, MeasurementModel,
    ProcessHessian, ProcessJacobian, ProcessModel, wrap_components,
};
use estim_filters::{Estimator, PredictCorrelated, Rollback, Update};

use super::geometry::{ChannelVariances, InversionInput, inertial_moments, invert, rate_squared};

/// Index of ẋ in the state.
pub const VX: usize = 0;
/// Index of ẏ in the state.
pub const VY: usize = 1;
/// Index of θ̇ in the state.
pub const RATE: usize = 2;
/// Index of x in the state.
pub const X: usize = 3;
/// Index of y in the state.
pub const Y: usize = 4;
/// Index of θ in the state.
pub const HEADING: usize = 5;

/// A = exp(A_c Δt) = `[[I₃, 0₃], [Δt I₃, I₃]]` with the corrected A_c = `[[0, 0], [I, 0]]`
/// (erratum E2).
pub fn transition_matrix(dt: f64) -> Matrix6<f64> {
    let mut a = Matrix6::identity();
    for i in 0..3 {
        a[(i + 3, i)] = dt;
    }
    a
}

/// B = ∫₀^Δt exp(A_c τ) dτ [I₃; 0₃] = [Δt I₃; (Δt²/2) I₃].
pub fn input_matrix(dt: f64) -> Matrix6x3<f64> {
    let mut b = Matrix6x3::zeros();
    for i in 0..3 {
        b[(i, i)] = dt;
        b[(i + 3, i)] = 0.5 * dt * dt;
    }
    b
}

/// Λ_vv = Λ\[0..3, 0..3\], the covariance of the input noise v.
pub fn lambda_vv(lambda: &Matrix4<f64>) -> Matrix3<f64> {
    lambda.fixed_view::<3, 3>(0, 0).into_owned()
}

/// Λ_vw = Λ\[0..3, 3\], the covariance of v with the θ̇² noise w.
pub fn lambda_vw(lambda: &Matrix4<f64>) -> Vector3<f64> {
    lambda.fixed_view::<3, 1>(0, 3).into_owned()
}

/// The input of [`PlanarProcess`] for one accelerometer step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarInput {
    /// u = (E{ẍ}, E{ÿ}, θ̈) from eq 12, m/s², m/s², rad/s².
    pub accel_mean: Vector3<f64>,
    /// Λ (eq 13 corrected) for (ẍ, ÿ, θ̈, θ̇²).
    pub lambda: Matrix4<f64>,
}

/// The input for the step from the accelerometer sample `accel` with the filter's heading
/// mean `theta` (= x̂\[5\]) and variance `theta_variance` (= P\[5,5\]) (erratum E10).
///
/// Errors: non-finite values, negative variances, R ≤ 0.
pub fn planar_input(
    accel: &Vector4<f64>,
    theta: f64,
    theta_variance: f64,
    half_separation: f64,
    variances: ChannelVariances,
) -> Result<PlanarInput> {
    let m = inertial_moments(&InversionInput {
        theta,
        theta_variance,
        accel: *accel,
        variances,
        half_separation,
    })?;
    Ok(PlanarInput {
        accel_mean: Vector3::new(m.mean[0], m.mean[1], m.mean[2]),
        lambda: m.lambda,
    })
}

/// The paper's process (eq 14, corrected): x⁺ = A x + B u, Q = B Λ_vv Bᵀ, both from the
/// [`PlanarInput`]. Linear in x.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarProcess {
    /// R, half the sensor separation, m.
    pub half_separation: f64,
    /// The accelerometer channel variances.
    pub variances: ChannelVariances,
}

impl ProcessModel<f64, U6> for PlanarProcess {
    type Input = PlanarInput;

    fn transition(&self, x: &Vector6<f64>, u: &PlanarInput, dt: f64) -> Vector6<f64> {
        transition_matrix(dt) * x + input_matrix(dt) * u.accel_mean
    }

    fn process_noise(&self, _: &Vector6<f64>, u: &PlanarInput, dt: f64) -> Matrix6<f64> {
        let b = input_matrix(dt);
        b * lambda_vv(&u.lambda) * b.transpose()
    }
}

impl ProcessJacobian<f64, U6> for PlanarProcess {
    fn transition_jacobian(&self, _: &Vector6<f64>, _: &PlanarInput, dt: f64) -> Matrix6<f64> {
        transition_matrix(dt)
    }
}

impl estim_core::LinearProcessModel<f64, U6> for PlanarProcess {}

/// Affine: no curvature, so the second-order filters run it as the EKF does.
impl estim_core::ProcessHessian<f64, U6> for PlanarProcess {
    fn transition_hessian(
        &self,
        _: &Vector6<f64>,
        _: &PlanarInput,
        _: f64,
        _: usize,
    ) -> Option<Matrix6<f64>> {
        None
    }
}

/// A process driven by the accelerometers, as [`filter_step`] needs it: how to build the
/// step's input from a sample and the current estimate, and the noise cross-covariance S with
/// the θ̇² measurement of the same sample.
pub trait AccelerometerProcess: ProcessModel<f64, U6> {
    /// The input for one step from the sample `accel`, at the predicted estimate (x̂, P).
    ///
    /// Errors: non-finite values, invalid variances.
    fn input(
        &self,
        accel: &Vector4<f64>,
        state: &Vector6<f64>,
        covariance: &Matrix6<f64>,
    ) -> Result<Self::Input>;

    /// S = E{(process noise)(θ̇² noise)} (6 × 1) for the step, evaluated at `state`.
    fn noise_cross_covariance(
        &self,
        input: &Self::Input,
        state: &Vector6<f64>,
        dt: f64,
    ) -> Matrix6x1<f64>;

    /// The θ̇² measurement from the same accelerometers (R = λ44).
    fn rate_measurement(&self) -> RateSquaredMeasurement {
        RateSquaredMeasurement {
            noise: rate_squared_variance(self.variances(), self.half_separation()),
        }
    }

    /// R, half the sensor separation, m.
    fn half_separation(&self) -> f64;

    /// The accelerometer channel variances.
    fn variances(&self) -> &ChannelVariances;
}

/// λ44 = (σ²_u1 + σ²_u2)/(4R²), the variance of the accelerometer θ̇².
pub fn rate_squared_variance(variances: &ChannelVariances, half_separation: f64) -> f64 {
    (variances.u1 + variances.u2) / (4.0 * half_separation * half_separation)
}

impl AccelerometerProcess for PlanarProcess {
    fn input(
        &self,
        accel: &Vector4<f64>,
        state: &Vector6<f64>,
        covariance: &Matrix6<f64>,
    ) -> Result<PlanarInput> {
        planar_input(
            accel,
            state[HEADING],
            covariance[(HEADING, HEADING)],
            self.half_separation,
            self.variances,
        )
    }

    fn noise_cross_covariance(
        &self,
        input: &PlanarInput,
        _: &Vector6<f64>,
        dt: f64,
    ) -> Matrix6x1<f64> {
        input_matrix(dt) * lambda_vw(&input.lambda)
    }

    fn half_separation(&self) -> f64 {
        self.half_separation
    }

    fn variances(&self) -> &ChannelVariances {
        &self.variances
    }
}

/// The variant with θ inside f (not in the paper): input = the raw sample
/// a = (a_u1, a_v1, a_u2, a_v2), and
///
/// ```text
/// f(x, a) = A x + B (g1(x[5], a), g2(x[5], a), g3(a))        (eq 5 rows 1–3)
/// ∂f/∂x  = A + B (−g2, g1, 0)ᵀ e5ᵀ
/// ∂²fₖ/∂x² = Bₖ· (−g1, −g2, 0) at [5,5] only
/// Q = B Λ_vv(σ²_θ = 0) Bᵀ,  S = B Λ_vw   (Λ at θ = x[5])
/// ```
///
/// The heading uncertainty then enters the velocities through F P Fᵀ, correlated with the
/// heading error, instead of as white noise in Q.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonlinearPlanarProcess {
    /// R, half the sensor separation, m.
    pub half_separation: f64,
    /// The accelerometer channel variances.
    pub variances: ChannelVariances,
}

impl NonlinearPlanarProcess {
    fn lambda_at(&self, accel: &Vector4<f64>, theta: f64) -> Matrix4<f64> {
        // The closed form only fails on non-finite input; then the noise is NaN and the
        // filter's finiteness checks report it.
        inertial_moments(&InversionInput {
            theta,
            theta_variance: 0.0,
            accel: *accel,
            variances: self.variances,
            half_separation: self.half_separation,
        })
        .map(|m| m.lambda)
        .unwrap_or_else(|_| Matrix4::from_element(f64::NAN))
    }
}

impl ProcessModel<f64, U6> for NonlinearPlanarProcess {
    type Input = Vector4<f64>;

    fn transition(&self, x: &Vector6<f64>, a: &Vector4<f64>, dt: f64) -> Vector6<f64> {
        let g = invert(x[HEADING], a, self.half_separation);
        transition_matrix(dt) * x + input_matrix(dt) * Vector3::new(g[0], g[1], g[2])
    }

    fn process_noise(&self, x: &Vector6<f64>, a: &Vector4<f64>, dt: f64) -> Matrix6<f64> {
        let b = input_matrix(dt);
        b * lambda_vv(&self.lambda_at(a, x[HEADING])) * b.transpose()
    }
}

impl ProcessJacobian<f64, U6> for NonlinearPlanarProcess {
    fn transition_jacobian(&self, x: &Vector6<f64>, a: &Vector4<f64>, dt: f64) -> Matrix6<f64> {
        let g = invert(x[HEADING], a, self.half_separation);
        let d = input_matrix(dt) * Vector3::new(-g[1], g[0], 0.0);
        let mut f = transition_matrix(dt);
        for i in 0..6 {
            f[(i, HEADING)] += d[i];
        }
        f
    }
}

impl ProcessHessian<f64, U6> for NonlinearPlanarProcess {
    fn transition_hessian(
        &self,
        x: &Vector6<f64>,
        a: &Vector4<f64>,
        dt: f64,
        k: usize,
    ) -> Option<Matrix6<f64>> {
        let g = invert(x[HEADING], a, self.half_separation);
        let d2 = input_matrix(dt) * Vector3::new(-g[0], -g[1], 0.0);
        match k {
            VX | VY | X | Y => {
                let mut h = Matrix6::zeros();
                h[(HEADING, HEADING)] = d2[k];
                Some(h)
            }
            _ => None,
        }
    }
}

impl AccelerometerProcess for NonlinearPlanarProcess {
    fn input(
        &self,
        accel: &Vector4<f64>,
        _: &Vector6<f64>,
        _: &Matrix6<f64>,
    ) -> Result<Vector4<f64>> {
        estim_core::checks::ensure_finite(
            accel,
            estim_core::Stage::Prediction,
            estim_core::Quantity::Measurement,
        )?;
        Ok(*accel)
    }

    fn noise_cross_covariance(
        &self,
        a: &Vector4<f64>,
        state: &Vector6<f64>,
        dt: f64,
    ) -> Matrix6x1<f64> {
        input_matrix(dt) * lambda_vw(&self.lambda_at(a, state[HEADING]))
    }

    fn half_separation(&self) -> f64 {
        self.half_separation
    }

    fn variances(&self) -> &ChannelVariances {
        &self.variances
    }
}

/// θ̇² measured by the accelerometers (eq 14's fourth output): h(x) = x\[2\]², R = λ44.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateSquaredMeasurement {
    /// R = λ44, (rad²/s²)².
    pub noise: f64,
}

impl MeasurementModel<f64, U6, U1> for RateSquaredMeasurement {
    fn measure(&self, x: &Vector6<f64>) -> Vector1<f64> {
        Vector1::new(x[RATE] * x[RATE])
    }

    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix1<f64> {
        Matrix1::new(self.noise)
    }
}

impl MeasurementJacobian<f64, U6, U1> for RateSquaredMeasurement {
    fn measurement_jacobian(&self, x: &Vector6<f64>) -> Matrix1x6<f64> {
        let mut h = Matrix1x6::zeros();
        h[RATE] = 2.0 * x[RATE];
        h
    }
}

impl MeasurementHessian<f64, U6, U1> for RateSquaredMeasurement {
    fn measurement_hessian(&self, _: &Vector6<f64>, _: usize) -> Option<Matrix6<f64>> {
        let mut h = Matrix6::zeros();
        h[(RATE, RATE)] = 2.0;
        Some(h)
    }
}

/// GPS position and compass heading: h(x) = (x\[3\], x\[4\], x\[5\]),
/// R = diag(σ²_xy, σ²_xy, σ²_yθ) (erratum E4); the heading residual is wrapped to (−π, π].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionHeadingMeasurement {
    /// σ_xy, m.
    pub sigma_xy: f64,
    /// σ_yθ, rad.
    pub sigma_theta: f64,
}

impl MeasurementModel<f64, U6, U3> for PositionHeadingMeasurement {
    fn measure(&self, x: &Vector6<f64>) -> Vector3<f64> {
        Vector3::new(x[X], x[Y], x[HEADING])
    }

    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix3<f64> {
        let (a, b) = (
            self.sigma_xy * self.sigma_xy,
            self.sigma_theta * self.sigma_theta,
        );
        Matrix3::from_diagonal(&Vector3::new(a, a, b))
    }

    fn residual_into(&self, a: &Vector3<f64>, b: &Vector3<f64>, out: &mut Vector3<f64>) {
        *out = a - b;
        wrap_components(out, &[2]); // z = (x, y, θ): the heading
    }
}

impl MeasurementJacobian<f64, U6, U3> for PositionHeadingMeasurement {
    fn measurement_jacobian(&self, _: &Vector6<f64>) -> Matrix3x6<f64> {
        let mut h = Matrix3x6::zeros();
        h[(0, X)] = 1.0;
        h[(1, Y)] = 1.0;
        h[(2, HEADING)] = 1.0;
        h
    }
}

impl LinearMeasurementModel<f64, U6, U3> for PositionHeadingMeasurement {}

/// Affine: no curvature.
impl estim_core::MeasurementHessian<f64, U6, U3> for PositionHeadingMeasurement {
    fn measurement_hessian(&self, _: &Vector6<f64>, _: usize) -> Option<Matrix6<f64>> {
        None
    }
}

/// What one [`filter_step`] reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// NIS of the θ̇² update.
    pub rate_nis: f64,
    /// NIS of the GPS/compass update, when there was one.
    pub fix_nis: Option<f64>,
}

/// A filter that can run [`filter_step`] with process `P` (and roll back a failed one).
pub trait PlanarFilter<P: ProcessModel<f64, U6>>:
    Estimator<f64, U6>
    + Rollback
    + Update<f64, U6, U1, RateSquaredMeasurement>
    + Update<f64, U6, U3, PositionHeadingMeasurement>
    + PredictCorrelated<f64, U6, U1, P, RateSquaredMeasurement>
{
}

impl<P, F> PlanarFilter<P> for F
where
    P: ProcessModel<f64, U6>,
    F: Estimator<f64, U6>
        + Rollback
        + Update<f64, U6, U1, RateSquaredMeasurement>
        + Update<f64, U6, U3, PositionHeadingMeasurement>
        + PredictCorrelated<f64, U6, U1, P, RateSquaredMeasurement>,
{
}

/// One accelerometer step: from the one-step prediction (x̂ᵢ, Pᵢ) at tᵢ to (x̂ᵢ₊₁, Pᵢ₊₁).
///
/// 1. the input from the sample aᵢ at (x̂ᵢ, Pᵢ) ([`AccelerometerProcess::input`]);
/// 2. update with θ̇²ᵢ = (a_u2 − a_u1)/(2R) — first, so it is linearised at x̂ᵢ as in eq 16;
/// 3. update with the GPS/compass `fix` (z, model), if any (linear, so the order with 2 does
///    not matter for it);
/// 4. `predict_correlated` with the θ̇² model, zᵢ and S (the process noise of this step is
///    correlated with the θ̇² noise of this sample).
///
/// On an error the filter is as it was before the call: steps 2–3 taken before a failing
/// step are rolled back ([`Rollback`]).
///
/// Errors: those of the input construction and of the filter steps (non-finite values,
/// innovation covariance not positive definite, Q − S R⁻¹ Sᵀ not PSD, a negative or
/// non-finite Δt).
pub fn filter_step<F, P>(
    filter: &mut F,
    process: &P,
    accel: &Vector4<f64>,
    fix: Option<(&PositionHeadingMeasurement, &Vector3<f64>)>,
    dt: f64,
) -> Result<StepReport>
where
    P: AccelerometerProcess,
    F: PlanarFilter<P>,
{
    let input = process.input(accel, filter.state(), filter.covariance())?;
    let before = filter.snapshot();
    let steps = |filter: &mut F| {
        let rate = process.rate_measurement();
        let z = Vector1::new(rate_squared(accel, process.half_separation()));
        let rate_report = Update::<f64, U6, U1, RateSquaredMeasurement>::update(filter, &rate, &z)?;
        let fix_nis = match fix {
            Some((model, y)) => Some(
                Update::<f64, U6, U3, PositionHeadingMeasurement>::update(filter, model, y)?.nis,
            ),
            None => None,
        };
        let s = process.noise_cross_covariance(&input, filter.state(), dt);
        filter.predict_correlated(process, &input, dt, &rate, &z, &s)?;
        Ok(StepReport {
            rate_nis: rate_report.nis,
            fix_nis,
        })
    };
    let result = steps(filter);
    if result.is_err() {
        filter.restore(&before);
    }
    result
}
