//! Coordinated turn in the plane: constant speed on a circle of turn rate ω, known
//! ([`CoordinatedTurn`]) or estimated as a state ([`CoordinatedTurnRate`]).
//!
//! State (x, y, vₓ, v_y) [, ω], position first as in the constant-velocity model. Over a step Δt,
//! with θ = ωΔt, c = cos θ, s = sin θ:
//!
//! ```text
//! p⁺ = p + [A −B; B A] v,    v⁺ = [c −s; s c] v,    ω⁺ = ω
//! A = sin(ωΔt)/ω = Δt·sinc θ,    B = (1 − cos ωΔt)/ω = Δt·θ·(1 − cos θ)/θ²
//! ```
//!
//! The θ-functions are evaluated by their Taylor series for |θ| < 1 and in closed form above,
//! so ω → 0 is exact (the constant-velocity model at ω = 0, with no 0/0) and so are their
//! derivatives in ω.
//!
//! **Noise.** Continuous white acceleration of power spectral density q on each axis, and for
//! [`CoordinatedTurnRate`] a random walk on ω of density q_ω. For a known ω the model is linear
//! and the noise is discretised exactly (Q = ∫₀^Δt e^{Fs} G q Gᵀ e^{Fᵀs} ds, G = [0; I]):
//!
//! ```text
//! Q_pp = 2Δt³ (θ − sin θ)/θ³ · q I,   Q_vv = Δt q I,
//! Q_pv = Δt² q [ (1−cos θ)/θ²    (θ − sin θ)/θ² ]
//!              [ −(θ − sin θ)/θ²  (1−cos θ)/θ²  ]
//! ```
//!
//! (→ the constant-velocity Q at ω = 0). [`CoordinatedTurnRate`] uses the same block at the
//! estimated ω plus q_ω Δt for ω (the cross-terms through the ω noise are neglected: they are
//! O(q_ω Δt³ |v|²) against Q_vv = O(qΔt)).

use estim_core::nalgebra::{Matrix4, Matrix5, U4, U5, Vector4, Vector5};
use estim_core::scalar::real;
use estim_core::{LinearProcessModel, ProcessHessian, ProcessJacobian, ProcessModel, Real};

use super::trig::{cosc, d2cosc1_over_theta, d2sinc, dcosc1, dsinc_over_theta, sinc, sinc3};

/// Coordinated turn at a known rate ω (rad/s, counter-clockwise positive): state (x, y, vₓ,
/// v_y); linear. With θ = ωΔt, c = cos θ, s = sin θ:
///
/// ```text
/// p⁺ = p + [A −B; B A] v,   v⁺ = [c −s; s c] v,   A = Δt·sin θ/θ,   B = Δt·(1 − cos θ)/θ
/// ```
///
/// (θ-functions by their series for |θ| < 1: exact at ω = 0, where it is the
/// constant-velocity model). The noise, continuous white acceleration of density q on each
/// axis, is discretised exactly (Q = ∫₀^Δt e^{Fs} G q Gᵀ e^{Fᵀs} ds, G = [0; I]):
///
/// ```text
/// Q_pp = 2Δt³ (θ − sin θ)/θ³ · q I,   Q_vv = Δt q I,
/// Q_pv = Δt² q [ (1−cos θ)/θ²    (θ − sin θ)/θ² ]
///              [ −(θ − sin θ)/θ²  (1−cos θ)/θ²  ]
/// ```
///
/// ```
/// use estim_core::nalgebra::Vector4;
/// use estim_core::ProcessModel;
/// use estim_models::motion::CoordinatedTurn;
///
/// // A quarter circle of radius 1 at unit speed: from (1, 0) heading north to (0, 1) heading west.
/// let ct = CoordinatedTurn { rate: 1.0, accel_psd: 0.0 };
/// let x = ct.transition(&Vector4::new(1.0, 0.0, 0.0, 1.0), &(), std::f64::consts::FRAC_PI_2);
/// assert!((x - Vector4::new(0.0, 1.0, -1.0, 0.0)).amax() < 1e-15);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoordinatedTurn<T> {
    /// The turn rate ω, rad/s.
    pub rate: T,
    /// q, the power spectral density of the white acceleration on each axis, m²/s³.
    pub accel_psd: T,
}

/// A, B, c, s at θ = ωΔt.
fn turn_coefficients<T: Real>(rate: T, dt: T) -> (T, T, T, T) {
    let theta = rate * dt;
    let (s, c) = theta.sin_cos();
    (dt * sinc(theta), dt * theta * cosc(theta), c, s)
}

/// The exact Q of a coordinated turn at rate ω (module docs).
fn turn_noise<T: Real>(rate: T, accel_psd: T, dt: T) -> Matrix4<T> {
    let theta = rate * dt;
    let dt2 = dt * dt;
    let pp = real::<T>(2.0) * dt2 * dt * sinc3(theta) * accel_psd;
    let pv_diag = dt2 * cosc(theta) * accel_psd;
    let pv_off = dt2 * theta * sinc3(theta) * accel_psd;
    let vv = dt * accel_psd;
    let z = T::zero();
    Matrix4::new(
        pp, z, pv_diag, pv_off, //
        z, pp, -pv_off, pv_diag, //
        pv_diag, -pv_off, vv, z, //
        pv_off, pv_diag, z, vv,
    )
}

fn turn_matrix<T: Real>(rate: T, dt: T) -> Matrix4<T> {
    let (a, b, c, s) = turn_coefficients(rate, dt);
    let (o, z) = (T::one(), T::zero());
    Matrix4::new(
        o, z, a, -b, //
        z, o, b, a, //
        z, z, c, -s, //
        z, z, s, c,
    )
}

impl<T: Real> ProcessModel<T, U4> for CoordinatedTurn<T> {
    type Input = ();

    fn transition(&self, x: &Vector4<T>, _: &(), dt: T) -> Vector4<T> {
        turn_matrix(self.rate, dt) * x
    }

    fn process_noise(&self, _: &Vector4<T>, _: &(), dt: T) -> Matrix4<T> {
        turn_noise(self.rate, self.accel_psd, dt)
    }
}

impl<T: Real> ProcessJacobian<T, U4> for CoordinatedTurn<T> {
    fn transition_jacobian(&self, _: &Vector4<T>, _: &(), dt: T) -> Matrix4<T> {
        turn_matrix(self.rate, dt)
    }
}

impl<T: Real> ProcessHessian<T, U4> for CoordinatedTurn<T> {
    fn transition_hessian(&self, _: &Vector4<T>, _: &(), _: T, _: usize) -> Option<Matrix4<T>> {
        None
    }
}

impl<T: Real> LinearProcessModel<T, U4> for CoordinatedTurn<T> {}

/// Coordinated turn with the rate estimated: state (x, y, vₓ, v_y, ω), ω a random walk of
/// density q_ω. The motion is [`CoordinatedTurn`]'s at the state's ω; Q is its Q at the
/// estimated ω plus q_ω Δt for ω (the cross-terms through the ω noise, O(q_ω Δt³ |v|²), are
/// neglected). Nonlinear (the rotation depends on ω), with analytic Jacobian and Hessians; exact at ω = 0.
///
/// With A′ = ∂A/∂ω = Δt² sinc′(θ), B′ = ∂B/∂ω = Δt² b′(θ), b(θ) = (1 − cos θ)/θ:
///
/// ```text
/// ∂x⁺/∂ω = A′vₓ − B′v_y,   ∂y⁺/∂ω = B′vₓ + A′v_y,
/// ∂vₓ⁺/∂ω = −Δt(s vₓ + c v_y),   ∂v_y⁺/∂ω = Δt(c vₓ − s v_y)
/// ```
///
/// and the Hessians have entries only in the ω row and column (∂²/∂v∂ω and ∂²/∂ω²).
///
/// ```
/// use estim_core::nalgebra::Vector5;
/// use estim_core::{ProcessJacobian, ProcessModel};
/// use estim_models::motion::CoordinatedTurnRate;
///
/// let ct = CoordinatedTurnRate { accel_psd: 0.1, rate_psd: 0.01 };
/// // At ω = 0 it moves straight, and turning left (ω > 0) would move it left: ∂y⁺/∂ω = Δt²vₓ/2.
/// let x = Vector5::new(0.0, 0.0, 2.0, 0.0, 0.0);
/// assert_eq!(ct.transition(&x, &(), 1.0), Vector5::new(2.0, 0.0, 2.0, 0.0, 0.0));
/// assert!((ct.transition_jacobian(&x, &(), 1.0)[(1, 4)] - 1.0f64).abs() < 1e-15);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoordinatedTurnRate<T> {
    /// q, the power spectral density of the white acceleration on each axis, m²/s³.
    pub accel_psd: T,
    /// q_ω, the power spectral density of the turn rate's random walk, rad²/s³.
    pub rate_psd: T,
}

/// A′, B′ (first ω-derivatives) and A″, B″ (second) at θ = ωΔt.
fn turn_rate_derivatives<T: Real>(rate: T, dt: T) -> (T, T, T, T) {
    let theta = rate * dt;
    let dt2 = dt * dt;
    (
        dt2 * theta * dsinc_over_theta(theta),
        dt2 * dcosc1(theta),
        dt2 * dt * d2sinc(theta),
        dt2 * dt * theta * d2cosc1_over_theta(theta),
    )
}

impl<T: Real> ProcessModel<T, U5> for CoordinatedTurnRate<T> {
    type Input = ();

    fn transition(&self, x: &Vector5<T>, _: &(), dt: T) -> Vector5<T> {
        let (a, b, c, s) = turn_coefficients(x[4], dt);
        let (vx, vy) = (x[2], x[3]);
        Vector5::new(
            x[0] + a * vx - b * vy,
            x[1] + b * vx + a * vy,
            c * vx - s * vy,
            s * vx + c * vy,
            x[4],
        )
    }

    fn process_noise(&self, x: &Vector5<T>, _: &(), dt: T) -> Matrix5<T> {
        let mut q = Matrix5::zeros();
        q.fixed_view_mut::<4, 4>(0, 0)
            .copy_from(&turn_noise(x[4], self.accel_psd, dt));
        q[(4, 4)] = self.rate_psd * dt;
        q
    }
}

impl<T: Real> ProcessJacobian<T, U5> for CoordinatedTurnRate<T> {
    fn transition_jacobian(&self, x: &Vector5<T>, _: &(), dt: T) -> Matrix5<T> {
        let mut f = Matrix5::identity();
        f.fixed_view_mut::<4, 4>(0, 0)
            .copy_from(&turn_matrix(x[4], dt));
        let (_, _, c, s) = turn_coefficients(x[4], dt);
        let (da, db, _, _) = turn_rate_derivatives(x[4], dt);
        let (vx, vy) = (x[2], x[3]);
        f[(0, 4)] = da * vx - db * vy;
        f[(1, 4)] = db * vx + da * vy;
        f[(2, 4)] = -dt * (s * vx + c * vy);
        f[(3, 4)] = dt * (c * vx - s * vy);
        f
    }
}

impl<T: Real> ProcessHessian<T, U5> for CoordinatedTurnRate<T> {
    fn transition_hessian(&self, x: &Vector5<T>, _: &(), dt: T, k: usize) -> Option<Matrix5<T>> {
        let (_, _, c, s) = turn_coefficients(x[4], dt);
        let (da, db, dda, ddb) = turn_rate_derivatives(x[4], dt);
        let (vx, vy) = (x[2], x[3]);
        let dt2 = dt * dt;
        // (∂²/∂vₓ∂ω, ∂²/∂v_y∂ω, ∂²/∂ω²) of component k.
        let (hx, hy, hw) = match k {
            0 => (da, -db, dda * vx - ddb * vy),
            1 => (db, da, ddb * vx + dda * vy),
            2 => (-dt * s, -dt * c, -dt2 * (c * vx - s * vy)),
            3 => (dt * c, -dt * s, -dt2 * (s * vx + c * vy)),
            _ => return None,
        };
        let mut h = Matrix5::zeros();
        h[(2, 4)] = hx;
        h[(4, 2)] = hx;
        h[(3, 4)] = hy;
        h[(4, 3)] = hy;
        h[(4, 4)] = hw;
        Some(h)
    }
}
