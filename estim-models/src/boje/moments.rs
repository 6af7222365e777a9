//! Section 2.2: Papoulis' second-order moments of functions of a random vector, on Boje's worked
//! examples (eq 8, 10, 11): cos θ, sin θ, x cos θ, x sin θ for independent x and θ.
//!
//! [`TrigProducts`] is the function with its analytic derivatives, so the generic propagators
//! run on it; [`exact_trig_moments`] gives the exact Gaussian expectations and
//! [`paper_trig_moments`] the paper's printed closed forms, which the tests compare with the
//! generic [`SecondOrder`](estim_core::SecondOrder) propagator. The `boje_moments` example
//! (`examples/reproductions/boje_moments.rs`) computes each quantity three ways (generic
//! second order, exact, seeded [`Sampled`](estim_core::Sampled)).

use estim_core::nalgebra::{Matrix2, Matrix4x2, U2, U4, Vector2, Vector4};
use estim_core::{Differentiable, Moments, TwiceDifferentiable, VectorFunction};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// g(x, θ) = (cos θ, sin θ, x cos θ, x sin θ), argument order (x, θ).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TrigProducts;

impl VectorFunction<f64, U2, U4> for TrigProducts {
    fn eval(&self, z: &Vector2<f64>) -> Vector4<f64> {
        let (x, th) = (z[0], z[1]);
        let (s, c) = th.sin_cos();
        Vector4::new(c, s, x * c, x * s)
    }
}

impl Differentiable<f64, U2, U4> for TrigProducts {
    fn jacobian(&self, z: &Vector2<f64>) -> Matrix4x2<f64> {
        let (x, th) = (z[0], z[1]);
        let (s, c) = th.sin_cos();
        Matrix4x2::new(
            0.0,
            -s, //
            0.0,
            c, //
            c,
            -x * s, //
            s,
            x * c,
        )
    }
}

impl TwiceDifferentiable<f64, U2, U4> for TrigProducts {
    fn hessian(&self, z: &Vector2<f64>, k: usize) -> Option<Matrix2<f64>> {
        let (x, th) = (z[0], z[1]);
        let (s, c) = th.sin_cos();
        Some(match k {
            0 => Matrix2::new(0.0, 0.0, 0.0, -c),
            1 => Matrix2::new(0.0, 0.0, 0.0, -s),
            2 => Matrix2::new(0.0, -s, -s, -x * c),
            _ => Matrix2::new(0.0, c, c, -x * s),
        })
    }
}

/// The seven quantities of the worked examples: E{cos θ}, E{sin θ}, var(cos θ), var(sin θ),
/// E{x cos θ}, var(x cos θ), var(x sin θ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrigMoments {
    /// E{cos θ}.
    pub e_cos: f64,
    /// E{sin θ}.
    pub e_sin: f64,
    /// var(cos θ).
    pub var_cos: f64,
    /// var(sin θ).
    pub var_sin: f64,
    /// E{x cos θ}.
    pub e_x_cos: f64,
    /// var(x cos θ).
    pub var_x_cos: f64,
    /// var(x sin θ).
    pub var_x_sin: f64,
}

impl TrigMoments {
    /// The values in field order (e_cos, e_sin, var_cos, var_sin, e_x_cos, var_x_cos, var_x_sin).
    pub fn to_array(&self) -> [f64; 7] {
        [
            self.e_cos,
            self.e_sin,
            self.var_cos,
            self.var_sin,
            self.e_x_cos,
            self.var_x_cos,
            self.var_x_sin,
        ]
    }

    /// The seven quantities read off the moments of [`TrigProducts`].
    pub fn from_moments(m: &Moments<f64, U2, U4>) -> Self {
        let c = &m.covariance;
        Self {
            e_cos: m.mean[0],
            e_sin: m.mean[1],
            var_cos: c[(0, 0)],
            var_sin: c[(1, 1)],
            e_x_cos: m.mean[2],
            var_x_cos: c[(2, 2)],
            var_x_sin: c[(3, 3)],
        }
    }
}

/// Exact Gaussian expectations for independent x ~ N(x̄, σ²_x), θ ~ N(θ̄, σ²_θ):
/// E{cos θ} = cos θ̄ e^{−σ²_θ/2}, E{cos² θ} = ½ (1 + e^{−2σ²_θ} cos 2θ̄), E{x²} = x̄² + σ²_x,
/// and var(x cos θ) = E{x²} E{cos² θ} − (x̄ E{cos θ})².
pub fn exact_trig_moments(x_mean: f64, x_std: f64, theta_mean: f64, theta_std: f64) -> TrigMoments {
    let v = theta_std * theta_std;
    let e1 = (-v / 2.0).exp();
    let e2 = (-2.0 * v).exp();
    let (s, c) = theta_mean.sin_cos();
    let (ec, es) = (c * e1, s * e1);
    let cos2 = (2.0 * theta_mean).cos();
    let (ec2, es2) = (0.5 * (1.0 + e2 * cos2), 0.5 * (1.0 - e2 * cos2));
    let ex2 = x_mean * x_mean + x_std * x_std;
    TrigMoments {
        e_cos: ec,
        e_sin: es,
        var_cos: ec2 - ec * ec,
        var_sin: es2 - es * es,
        e_x_cos: x_mean * ec,
        var_x_cos: ex2 * ec2 - (x_mean * ec).powi(2),
        var_x_sin: ex2 * es2 - (x_mean * es).powi(2),
    }
}

/// The paper's printed closed forms: eq 8 (means), eq 10 (variances of cos, sin), eq 11
/// (variances of x cos θ, x sin θ), and E{x cos θ} ≈ x̄ cos θ̄ (1 − σ²_θ/2) (eq 7 with the
/// eq 8 remark, x and θ uncorrelated).
pub fn paper_trig_moments(x_mean: f64, x_std: f64, theta_mean: f64, theta_std: f64) -> TrigMoments {
    let v = theta_std * theta_std;
    let vx = x_std * x_std;
    let (s, c) = theta_mean.sin_cos();
    TrigMoments {
        e_cos: c * (1.0 - v / 2.0),
        e_sin: s * (1.0 - v / 2.0),
        var_cos: v * s * s,
        var_sin: v * c * c,
        e_x_cos: x_mean * c * (1.0 - v / 2.0),
        var_x_cos: v * x_mean * x_mean * s * s + vx * c * c,
        var_x_sin: v * x_mean * x_mean * c * c + vx * s * s,
    }
}
