//! Section 3: how well the accelerometer pair measures the rate (eq 17–19).
//!
//! Scalar sub-model: ωᵢ₊₁ = ωᵢ + Δt θ̈ᵢ (θ̈ from eq 5, variance λ33), output y = θ̇² (variance
//! λ44), linearised at ω₀: c = 2ω₀, q = λ33 Δt², r = λ44, s = λ34 = 0.
//!
//! - eq 17 (Riccati, one-step predictor): pᵢ₊₁ = pᵢ − (pᵢ c + s)²/(r + pᵢ c²) + q
//!   ([`riccati_step`], iterated by [`iterate_riccati`]);
//! - eq 18 (its fixed point for s = 0): p = q/2 + √(q²/4 + q r/c²) ([`steady_state_eq18`]);
//! - eq 19 with equal channels σ²: q = Δt² σ²/(2R²), r = σ²/(2R²), so
//!   p = Δt² σ²/(4R²) (1 + √(1 + 4/(cΔt)²)) ([`steady_state_eq19`]); the paper prints
//!   1/(cΔt)² inside the root ([`steady_state_eq19_printed`], erratum E6).
//!
//! [`ScalarRateProcess`] and [`ScalarRateSquared`] are the scalar sub-model as estim models;
//! the `boje_rate` example (`examples/reproductions/boje_rate.rs`) evaluates the closed forms
//! and runs a Monte Carlo of the scalar EKF on them at constant rate on simulated accelerometer
//! samples (eq 4 plus white noise).

use estim_core::nalgebra::{Matrix1, U1, Vector1};
#[cfg(feature = "std")]
use estim_core::{Error, Parameter};
use estim_core::{
    LinearProcessModel, MeasurementHessian, MeasurementJacobian, MeasurementModel, ProcessJacobian,
    ProcessModel,
};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// Scalar rate process ω⁺ = ω + Δt u, u = θ̈ from the accelerometers, Q = λ33 Δt².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScalarRateProcess {
    /// λ33, the variance of the accelerometer θ̈, (rad/s²)².
    pub angular_accel_variance: f64,
}

impl ProcessModel<f64, U1> for ScalarRateProcess {
    type Input = f64;

    fn transition(&self, x: &Vector1<f64>, u: &f64, dt: f64) -> Vector1<f64> {
        Vector1::new(x[0] + dt * u)
    }

    fn process_noise(&self, _: &Vector1<f64>, _: &f64, dt: f64) -> Matrix1<f64> {
        Matrix1::new(self.angular_accel_variance * dt * dt)
    }
}

impl ProcessJacobian<f64, U1> for ScalarRateProcess {
    fn transition_jacobian(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        Matrix1::new(1.0)
    }
}

impl LinearProcessModel<f64, U1> for ScalarRateProcess {}

/// Affine: every Hessian is zero (the second-order filters and the derivative checker ask).
impl estim_core::ProcessHessian<f64, estim_core::nalgebra::U1> for ScalarRateProcess {
    fn transition_hessian(
        &self,
        _: &estim_core::nalgebra::OVector<f64, estim_core::nalgebra::U1>,
        _: &f64,
        _: f64,
        _: usize,
    ) -> Option<
        estim_core::nalgebra::OMatrix<f64, estim_core::nalgebra::U1, estim_core::nalgebra::U1>,
    > {
        None
    }
}

/// Scalar θ̇² measurement y = ω², R = λ44.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScalarRateSquared {
    /// λ44, (rad²/s²)².
    pub noise: f64,
}

impl MeasurementModel<f64, U1, U1> for ScalarRateSquared {
    fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(x[0] * x[0])
    }

    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(self.noise)
    }
}

impl MeasurementJacobian<f64, U1, U1> for ScalarRateSquared {
    fn measurement_jacobian(&self, x: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(2.0 * x[0])
    }
}

impl MeasurementHessian<f64, U1, U1> for ScalarRateSquared {
    fn measurement_hessian(&self, _: &Vector1<f64>, _: usize) -> Option<Matrix1<f64>> {
        Some(Matrix1::new(2.0))
    }
}

/// Eq 17: one step of the scalar Riccati recursion (one-step predicted variance).
pub fn riccati_step(p: f64, q: f64, r: f64, c: f64, s: f64) -> f64 {
    p - (p * c + s).powi(2) / (r + p * c * c) + q
}

/// Eq 17 iterated from `p0` until |pᵢ₊₁ − pᵢ| ≤ `rel_tol`·pᵢ₊₁ or `max_iterations`: returns
/// (p, iterations, the trajectory p₀, p₁, …). Needs the `std` feature (the trajectory is a
/// `Vec`).
///
/// Errors: [`Error::InvalidParameter`] with [`Parameter::StepCount`] for `max_iterations`
/// above [`MAX_STEPS`](crate::limits::MAX_STEPS), with [`Parameter::Tolerance`] for a
/// `rel_tol` that is negative or not finite (a NaN tolerance would never stop the iteration).
///
/// ```
/// use estim_models::boje::rate::{iterate_riccati, steady_state_eq18};
/// let (q, r, c) = (1e-4, 1.0, 10.0);
/// let (p, iterations, trace) = iterate_riccati(0.0, q, r, c, 0.0, 1e-13, 10_000)?;
/// assert!((p - steady_state_eq18(q, r, c)).abs() <= 1e-10 * p);
/// assert_eq!(trace.len(), iterations + 1);
/// assert!(iterate_riccati(0.0, q, r, c, 0.0, f64::NAN, 10).is_err());
/// # Ok::<(), estim_core::Error>(())
/// ```
#[cfg(feature = "std")]
pub fn iterate_riccati(
    p0: f64,
    q: f64,
    r: f64,
    c: f64,
    s: f64,
    rel_tol: f64,
    max_iterations: usize,
) -> Result<(f64, usize, Vec<f64>), Error> {
    crate::limits::check_steps(max_iterations)?;
    if !(rel_tol.is_finite() && rel_tol >= 0.0) {
        return Err(Error::InvalidParameter {
            parameter: Parameter::Tolerance,
            value: rel_tol,
        });
    }
    let mut p = p0;
    let mut trace = vec![p];
    for i in 1..=max_iterations {
        let next = riccati_step(p, q, r, c, s);
        trace.push(next);
        let done = (next - p).abs() <= rel_tol * next.abs();
        p = next;
        if done {
            return Ok((p, i, trace));
        }
    }
    Ok((p, max_iterations, trace))
}

/// Eq 18: the steady state of eq 17 for s = 0, p = q/2 + √(q²/4 + q r/c²) (predicted).
pub fn steady_state_eq18(q: f64, r: f64, c: f64) -> f64 {
    q / 2.0 + (q * q / 4.0 + q * r / (c * c)).sqrt()
}

/// Eq 19, corrected: p = Δt² σ²/(4R²) (1 + √(1 + 4/(cΔt)²)) for equal channel std `sigma`.
pub fn steady_state_eq19(dt: f64, sigma: f64, half_separation: f64, c: f64) -> f64 {
    let k = dt * dt * sigma * sigma / (4.0 * half_separation * half_separation);
    k * (1.0 + (1.0 + 4.0 / (c * dt).powi(2)).sqrt())
}

/// Eq 19 as printed: 1/(cΔt)² inside the root (erratum E6; equals eq 18 with c = 4ω₀).
pub fn steady_state_eq19_printed(dt: f64, sigma: f64, half_separation: f64, c: f64) -> f64 {
    let k = dt * dt * sigma * sigma / (4.0 * half_separation * half_separation);
    k * (1.0 + (1.0 + 1.0 / (c * dt).powi(2)).sqrt())
}
