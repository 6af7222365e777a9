//! Sensor geometry (eq 1–4), its inversion (eq 5) and the moments of the inversion (eq 12–13).
//!
//! The inversion is a [`VectorFunction`] of z = (θ, a_u1, a_v1, a_u2, a_v2) with analytic
//! Jacobian and Hessians ([`AccelerometerInversion`]), so the generic moment propagators can be
//! run on it; [`inertial_mean`] and [`lambda`] are Boje's closed forms (eq 12 and the corrected
//! eq 13), which the tests compare with those propagators entry by entry.

use estim_core::checks::ensure_finite;
use estim_core::error::Result;
use estim_core::nalgebra::{Matrix4, Matrix4x5, Matrix5, U4, U5, Vector4, Vector5};
use estim_core::{Differentiable, Error, Quantity, Stage, TwiceDifferentiable, VectorFunction};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// Standard gravity, m/s² (converts the paper's mg figures).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// Per-channel white-noise **variances** of the four accelerometer channels, (m/s²)².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelVariances {
    /// σ²_u1 (sensor 1, body u axis).
    pub u1: f64,
    /// σ²_v1 (sensor 1, body v axis).
    pub v1: f64,
    /// σ²_u2 (sensor 2, body u axis).
    pub u2: f64,
    /// σ²_v2 (sensor 2, body v axis).
    pub v2: f64,
}

impl ChannelVariances {
    /// The same variance `sigma²` in all four channels (`sigma` is a standard deviation).
    pub fn equal(sigma: f64) -> Self {
        let v = sigma * sigma;
        Self {
            u1: v,
            v1: v,
            u2: v,
            v2: v,
        }
    }

    /// From the four channel standard deviations (σ_u1, σ_v1, σ_u2, σ_v2).
    pub fn from_std(u1: f64, v1: f64, u2: f64, v2: f64) -> Self {
        Self {
            u1: u1 * u1,
            v1: v1 * v1,
            u2: u2 * u2,
            v2: v2 * v2,
        }
    }

    /// The variances in channel order (u1, v1, u2, v2).
    pub fn as_vector(&self) -> Vector4<f64> {
        Vector4::new(self.u1, self.v1, self.u2, self.v2)
    }

    fn validate(&self) -> Result<()> {
        let v = self.as_vector();
        ensure_finite(&v, Stage::Propagation, Quantity::Covariance)?;
        if v.iter().any(|x| *x < 0.0) {
            return Err(Error::NotPositiveSemiDefinite {
                stage: Stage::Propagation,
                quantity: Quantity::Covariance,
            });
        }
        Ok(())
    }
}

/// The eq 4 matrix M(θ): accelerometer signals (a_u1, a_v1, a_u2, a_v2) =
/// M(θ) (ẍ, ÿ, θ̈, θ̇²), for sensors at ±R along the body u axis.
pub fn sensor_matrix(theta: f64, half_separation: f64) -> Matrix4<f64> {
    let (s, c) = theta.sin_cos();
    let r = half_separation;
    Matrix4::new(
        c, s, 0.0, -r, //
        -s, c, r, 0.0, //
        c, s, 0.0, r, //
        -s, c, -r, 0.0,
    )
}

/// Noise-free accelerometer signals (eq 4) for inertial accelerations (ẍ, ÿ), angular
/// acceleration θ̈ and squared rate θ̇² at heading θ.
pub fn sensor_signals(theta: f64, inertial: &Vector4<f64>, half_separation: f64) -> Vector4<f64> {
    sensor_matrix(theta, half_separation) * inertial
}

/// Eq 5: (ẍ, ÿ, θ̈, θ̇²) from the heading θ and the accelerometer signals
/// a = (a_u1, a_v1, a_u2, a_v2), R = `half_separation`.
pub fn invert(theta: f64, accel: &Vector4<f64>, half_separation: f64) -> Vector4<f64> {
    let (s, c) = theta.sin_cos();
    let su = accel[0] + accel[2];
    let sv = accel[1] + accel[3];
    let two_r = 2.0 * half_separation;
    Vector4::new(
        0.5 * (c * su - s * sv),
        0.5 * (s * su + c * sv),
        (accel[1] - accel[3]) / two_r,
        (accel[2] - accel[0]) / two_r,
    )
}

/// θ̇² from the accelerometers (fourth row of eq 5): (a_u2 − a_u1)/(2R). Independent of θ.
pub fn rate_squared(accel: &Vector4<f64>, half_separation: f64) -> f64 {
    (accel[2] - accel[0]) / (2.0 * half_separation)
}

/// Eq 5 as a function of z = (θ, a_u1, a_v1, a_u2, a_v2) ↦ (ẍ, ÿ, θ̈, θ̇²), with analytic
/// Jacobian and Hessians, for the generic moment propagators (θ random, the a's random).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccelerometerInversion {
    /// R, half the sensor separation, m.
    pub half_separation: f64,
}

impl VectorFunction<f64, U5, U4> for AccelerometerInversion {
    fn eval(&self, z: &Vector5<f64>) -> Vector4<f64> {
        invert(
            z[0],
            &Vector4::new(z[1], z[2], z[3], z[4]),
            self.half_separation,
        )
    }
}

impl Differentiable<f64, U5, U4> for AccelerometerInversion {
    fn jacobian(&self, z: &Vector5<f64>) -> Matrix4x5<f64> {
        let (s, c) = z[0].sin_cos();
        let su = z[1] + z[3];
        let sv = z[2] + z[4];
        let k = 1.0 / (2.0 * self.half_separation);
        Matrix4x5::new(
            0.5 * (-s * su - c * sv),
            0.5 * c,
            -0.5 * s,
            0.5 * c,
            -0.5 * s, //
            0.5 * (c * su - s * sv),
            0.5 * s,
            0.5 * c,
            0.5 * s,
            0.5 * c, //
            0.0,
            0.0,
            k,
            0.0,
            -k, //
            0.0,
            -k,
            0.0,
            k,
            0.0,
        )
    }
}

impl TwiceDifferentiable<f64, U5, U4> for AccelerometerInversion {
    fn hessian(&self, z: &Vector5<f64>, k: usize) -> Option<Matrix5<f64>> {
        let (s, c) = z[0].sin_cos();
        let su = z[1] + z[3];
        let sv = z[2] + z[4];
        // Only the θ row/column is nonzero: ∂²g/∂θ² = −g and ∂²g/∂θ∂a = ∂/∂θ (∂g/∂a).
        let (tt, du, dv) = match k {
            0 => (0.5 * (-c * su + s * sv), -0.5 * s, -0.5 * c),
            1 => (0.5 * (-s * su - c * sv), 0.5 * c, -0.5 * s),
            _ => return None,
        };
        let mut h = Matrix5::zeros();
        h[(0, 0)] = tt;
        for (j, d) in [(1, du), (2, dv), (3, du), (4, dv)] {
            h[(0, j)] = d;
            h[(j, 0)] = d;
        }
        Some(h)
    }
}

/// The input of eq 12–13: heading mean θ̄ and variance σ²_θ, the accelerometer sample, the
/// channel variances and R.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InversionInput {
    /// θ̄, rad.
    pub theta: f64,
    /// σ²_θ, rad².
    pub theta_variance: f64,
    /// The measured (a_u1, a_v1, a_u2, a_v2), m/s².
    pub accel: Vector4<f64>,
    /// The channel variances.
    pub variances: ChannelVariances,
    /// R, half the sensor separation, m.
    pub half_separation: f64,
}

impl InversionInput {
    /// z̄ = (θ̄, a_u1, a_v1, a_u2, a_v2), the mean of the inversion's argument.
    pub fn mean(&self) -> Vector5<f64> {
        Vector5::new(
            self.theta,
            self.accel[0],
            self.accel[1],
            self.accel[2],
            self.accel[3],
        )
    }

    /// C_z = diag(σ²_θ, σ²_u1, σ²_v1, σ²_u2, σ²_v2).
    pub fn covariance(&self) -> Matrix5<f64> {
        let v = &self.variances;
        Matrix5::from_diagonal(&Vector5::new(self.theta_variance, v.u1, v.v1, v.u2, v.v2))
    }

    /// The inversion function with this R.
    pub fn function(&self) -> AccelerometerInversion {
        AccelerometerInversion {
            half_separation: self.half_separation,
        }
    }

    fn validate(&self) -> Result<()> {
        let stage = Stage::Propagation;
        ensure_finite(&self.mean(), stage, Quantity::Mean)?;
        self.variances.validate()?;
        if !(self.theta_variance >= 0.0) {
            return Err(Error::NotPositiveSemiDefinite {
                stage,
                quantity: Quantity::Covariance,
            });
        }
        if !(self.half_separation > 0.0 && self.half_separation.is_finite()) {
            return Err(Error::NonFinite {
                stage,
                quantity: Quantity::FunctionValue,
            });
        }
        Ok(())
    }
}

/// Eq 12 (with eq 8's E{cos θ} ≈ cos θ̄ (1 − σ²_θ/2)): the approximate mean of
/// (ẍ, ÿ, θ̈, θ̇²).
///
/// Errors: non-finite inputs, negative variances, R ≤ 0.
pub fn inertial_mean(input: &InversionInput) -> Result<Vector4<f64>> {
    input.validate()?;
    let g = invert(input.theta, &input.accel, input.half_separation);
    let shrink = 1.0 - 0.5 * input.theta_variance;
    Ok(Vector4::new(g[0] * shrink, g[1] * shrink, g[2], g[3]))
}

/// Eq 13, **corrected** (λ33 and λ44 swapped with respect to the paper, erratum E1): the
/// covariance Λ of (ẍ, ÿ, θ̈, θ̇²), order as eq 5.
///
/// Errors: non-finite inputs, negative variances, R ≤ 0.
pub fn lambda(input: &InversionInput) -> Result<Matrix4<f64>> {
    input.validate()?;
    let mut l = lambda_common(input);
    let v = &input.variances;
    let r2 = 4.0 * input.half_separation * input.half_separation;
    l[(2, 2)] = (v.v1 + v.v2) / r2;
    l[(3, 3)] = (v.u1 + v.u2) / r2;
    Ok(l)
}

/// Eq 13 **as printed** (λ33 = (σ²_u1 + σ²_u2)/(4R²), λ44 = (σ²_v1 + σ²_v2)/(4R²)): kept only to
/// show the erratum; use [`lambda`].
///
/// Errors: as [`lambda`].
pub fn lambda_as_printed(input: &InversionInput) -> Result<Matrix4<f64>> {
    input.validate()?;
    let mut l = lambda_common(input);
    let v = &input.variances;
    let r2 = 4.0 * input.half_separation * input.half_separation;
    l[(2, 2)] = (v.u1 + v.u2) / r2;
    l[(3, 3)] = (v.v1 + v.v2) / r2;
    Ok(l)
}

/// Every λ of eq 13 but λ33 and λ44 (which the two variants set).
fn lambda_common(input: &InversionInput) -> Matrix4<f64> {
    let (s, c) = input.theta.sin_cos();
    let a = &input.accel;
    let su = a[0] + a[2];
    let sv = a[1] + a[3];
    let v = &input.variances;
    let st2 = input.theta_variance;
    let r = input.half_separation;
    let (vu, vv) = (v.u1 + v.u2, v.v1 + v.v2);
    let l11 = (st2 * (su * s + sv * c).powi(2) + vu * c * c + vv * s * s) / 4.0;
    let l12 = (st2 * (-su * s - sv * c) * (su * c - sv * s) + (vu - vv) * s * c) / 4.0;
    let l22 = (st2 * (su * c - sv * s).powi(2) + vu * s * s + vv * c * c) / 4.0;
    let l13 = (v.v2 - v.v1) * s / (4.0 * r);
    let l23 = (v.v1 - v.v2) * c / (4.0 * r);
    let l14 = (v.u2 - v.u1) * c / (4.0 * r);
    let l24 = (v.u2 - v.u1) * s / (4.0 * r);
    Matrix4::new(
        l11, l12, l13, l14, //
        l12, l22, l23, l24, //
        l13, l23, 0.0, 0.0, //
        l14, l24, 0.0, 0.0,
    )
}

/// Eq 12 and the corrected eq 13 together.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InertialMoments {
    /// E{(ẍ, ÿ, θ̈, θ̇²)} (eq 12).
    pub mean: Vector4<f64>,
    /// Λ = cov(ẍ, ÿ, θ̈, θ̇²) (eq 13 corrected).
    pub lambda: Matrix4<f64>,
}

/// [`inertial_mean`] and [`lambda`] at once.
///
/// Errors: as [`lambda`].
pub fn inertial_moments(input: &InversionInput) -> Result<InertialMoments> {
    Ok(InertialMoments {
        mean: inertial_mean(input)?,
        lambda: lambda(input)?,
    })
}
