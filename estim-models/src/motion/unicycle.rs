//! The unicycle (odometry) model: a planar pose driven by measured speed and yaw rate.

use estim_core::nalgebra::{Matrix2x3, Matrix3, Matrix3x2, U3, Vector2, Vector3};
use estim_core::scalar::real;
use estim_core::{ProcessHessian, ProcessJacobian, ProcessModel, Real};

use super::trig::{dsinc_over_theta, sinc};

/// Unicycle / odometry: state (x, y, ψ) (position and heading, rad), input u = (v, ω), the
/// speed (m/s) and yaw rate (rad/s) held over the step, as odometry reports them. The motion is
/// integrated exactly (an arc of a circle, a straight line at ω = 0):
///
/// ```text
/// φ = ωΔt/2,   L = vΔt · sinc φ          (the chord: 2v/ω · sin φ, exact at ω = 0)
/// x⁺ = x + L cos(ψ + φ),   y⁺ = y + L sin(ψ + φ),   ψ⁺ = ψ + ωΔt
/// ```
///
/// The heading is not wrapped (use a [`WrappedAngles`](estim_core::WrappedAngles) state space
/// in the filter if it must be). The noise is the input noise carried through the motion,
/// Q = J_u diag(σ_v², σ_ω²) J_uᵀ with J_u = ∂f/∂u, σ_v² and σ_ω² the variances of the step's
/// mean speed and yaw rate; it has rank ≤ 2 (the heading and the along-track position move
/// together).
///
/// ```
/// use estim_core::nalgebra::{Vector2, Vector3};
/// use estim_core::ProcessModel;
/// use estim_models::motion::Unicycle;
///
/// let odometry = Unicycle { speed_variance: 0.01, rate_variance: 0.001 };
/// // Half a circle of radius 1: speed 1, rate 1, for π seconds, from the origin heading east.
/// let u = Vector2::new(1.0, 1.0);
/// let x = odometry.transition(&Vector3::zeros(), &u, std::f64::consts::PI);
/// assert!((x - Vector3::new(0.0, 2.0, std::f64::consts::PI)).amax() < 1e-15);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unicycle<T> {
    /// σ_v², the variance of the speed input, (m/s)².
    pub speed_variance: T,
    /// σ_ω², the variance of the yaw-rate input, (rad/s)².
    pub rate_variance: T,
}

/// (φ, L, cos(ψ + φ), sin(ψ + φ)).
fn chord<T: Real>(psi: T, u: &Vector2<T>, dt: T) -> (T, T, T, T) {
    let phi = u[1] * dt * real::<T>(0.5);
    let (s, c) = (psi + phi).sin_cos();
    (phi, u[0] * dt * sinc(phi), c, s)
}

impl<T: Real> Unicycle<T> {
    /// J_u = ∂f/∂(v, ω) at (x, u, Δt).
    ///
    /// ```text
    /// ∂(x, y)⁺/∂v = Δt sinc φ (cos, sin)(ψ + φ)
    /// ∂(x, y)⁺/∂ω = vΔt²/2 · (sinc′φ (cos, sin) + sinc φ (−sin, cos))(ψ + φ),   ∂ψ⁺/∂ω = Δt
    /// ```
    ///
    /// ```
    /// use estim_core::nalgebra::{Vector2, Vector3};
    /// use estim_models::motion::Unicycle;
    ///
    /// let odometry = Unicycle { speed_variance: 0.01, rate_variance: 0.001 };
    /// let j = odometry.input_jacobian(&Vector3::zeros(), &Vector2::new(1.0, 0.0), 2.0);
    /// assert_eq!(j[(0, 0)], 2.0); // straight east: Δt per unit of speed
    /// assert_eq!(j[(1, 1)], 2.0); // turning left by δω moves it v Δt²/2 δω north
    /// assert_eq!(j[(2, 1)], 2.0);
    /// ```
    pub fn input_jacobian(&self, x: &Vector3<T>, u: &Vector2<T>, dt: T) -> Matrix3x2<T> {
        let (phi, _, c, s) = chord(x[2], u, dt);
        let sc = sinc(phi);
        let dsc = phi * dsinc_over_theta(phi);
        let k = u[0] * dt * dt * real::<T>(0.5);
        Matrix3x2::new(
            dt * sc * c,
            k * (dsc * c - sc * s),
            dt * sc * s,
            k * (dsc * s + sc * c),
            T::zero(),
            dt,
        )
    }
}

impl<T: Real> ProcessModel<T, U3> for Unicycle<T> {
    type Input = Vector2<T>;

    fn transition(&self, x: &Vector3<T>, u: &Vector2<T>, dt: T) -> Vector3<T> {
        let (_, l, c, s) = chord(x[2], u, dt);
        Vector3::new(x[0] + l * c, x[1] + l * s, x[2] + u[1] * dt)
    }

    fn process_noise(&self, x: &Vector3<T>, u: &Vector2<T>, dt: T) -> Matrix3<T> {
        let j = self.input_jacobian(x, u, dt);
        let sigma = Vector2::new(self.speed_variance, self.rate_variance);
        let js: Matrix3x2<T> = Matrix3x2::from_fn(|i, k| j[(i, k)] * sigma[k]);
        let jt: Matrix2x3<T> = j.transpose();
        js * jt
    }
}

impl<T: Real> ProcessJacobian<T, U3> for Unicycle<T> {
    fn transition_jacobian(&self, x: &Vector3<T>, u: &Vector2<T>, dt: T) -> Matrix3<T> {
        let (_, l, c, s) = chord(x[2], u, dt);
        let mut f = Matrix3::identity();
        f[(0, 2)] = -l * s;
        f[(1, 2)] = l * c;
        f
    }
}

impl<T: Real> ProcessHessian<T, U3> for Unicycle<T> {
    /// Only ∂²/∂ψ² is non-zero: −L (cos, sin)(ψ + φ) for x⁺, y⁺; ψ⁺ is affine.
    fn transition_hessian(
        &self,
        x: &Vector3<T>,
        u: &Vector2<T>,
        dt: T,
        k: usize,
    ) -> Option<Matrix3<T>> {
        let (_, l, c, s) = chord(x[2], u, dt);
        let value = match k {
            0 => -l * c,
            1 => -l * s,
            _ => return None,
        };
        let mut h = Matrix3::zeros();
        h[(2, 2)] = value;
        Some(h)
    }
}
