//! Section 2.2: Papoulis' second-order moments of functions of a random vector, on Boje's worked
//! examples (eq 8, 10, 11): cos θ, sin θ, x cos θ, x sin θ for independent x and θ.
//!
//! [`moments_experiment`] computes each quantity three ways: the generic [`SecondOrder`]
//! propagator on [`TrigProducts`], the exact Gaussian expectation ([`exact_trig_moments`]), and
//! the seeded [`Sampled`] propagator; it also evaluates the paper's printed closed forms
//! ([`paper_trig_moments`]), which the tests compare with the generic propagator.

use estim_core::error::Result;
use estim_core::nalgebra::{Matrix2, Matrix4x2, U2, U4, Vector2, Vector4};
use estim_core::{
    Differentiable, MomentPropagator, Moments, Sampled, SecondOrder, SecondOrderGaussian,
    TwiceDifferentiable, VectorFunction,
};

use super::Headline;

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

/// The seven quantities of the example, in the order of [`MomentsConfig::NAMES`].
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
    /// The values in the order of [`MomentsConfig::NAMES`].
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

    fn from_moments(m: &Moments<f64, U2, U4>) -> Self {
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

/// Settings of the moments example.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MomentsConfig {
    /// θ̄, rad.
    pub theta_mean: f64,
    /// σ_θ, rad.
    pub theta_std: f64,
    /// x̄.
    pub x_mean: f64,
    /// σ_x.
    pub x_std: f64,
    /// Monte Carlo samples for the sampled reference.
    pub samples: usize,
    /// Seed of the sampled reference.
    pub seed: u64,
}

impl MomentsConfig {
    /// The names of the seven quantities (the example's JSON keys).
    pub const NAMES: [&'static str; 7] = [
        "e_cos",
        "e_sin",
        "var_cos",
        "var_sin",
        "e_x_cos",
        "var_x_cos",
        "var_x_sin",
    ];

    /// The example's values: θ̄ = 0.7, σ_θ = 0.1, x̄ = 2, σ_x = 0.3, 10⁶ samples.
    pub fn paper() -> Self {
        Self {
            theta_mean: 0.7,
            theta_std: 0.1,
            x_mean: 2.0,
            x_std: 0.3,
            samples: 1_000_000,
            seed: 2026,
        }
    }

    /// As [`paper`](Self::paper) with 2·10⁵ samples.
    pub fn quick() -> Self {
        Self {
            samples: 200_000,
            ..Self::paper()
        }
    }
}

/// What [`moments_experiment`] returns.
#[derive(Clone, Debug, PartialEq)]
pub struct MomentsResult {
    /// The settings used.
    pub config: MomentsConfig,
    /// Generic [`SecondOrder`] propagator on [`TrigProducts`] (Papoulis, Boje eq 7 and 9).
    pub second_order: TrigMoments,
    /// Generic [`SecondOrderGaussian`] propagator (adds ½ tr(Hₖ C Hₗ C) to the covariance).
    pub second_order_gaussian: TrigMoments,
    /// Exact Gaussian expectations.
    pub exact: TrigMoments,
    /// Seeded Monte Carlo ([`Sampled`]).
    pub sampled: TrigMoments,
    /// Standard error of each sampled value: √(var/N) for means; for variances the Gaussian
    /// approximation var·√(2/(N−1)) (a guide: the outputs are not Gaussian).
    pub sampled_std_error: TrigMoments,
    /// The paper's printed closed forms (eq 8, 10, 11).
    pub paper: TrigMoments,
}

/// Runs the moments example.
///
/// Errors: invalid covariance (negative variance) or sample count < 2.
pub fn moments_experiment(config: &MomentsConfig) -> Result<MomentsResult> {
    let mean = Vector2::new(config.x_mean, config.theta_mean);
    let cov = Matrix2::new(
        config.x_std * config.x_std,
        0.0,
        0.0,
        config.theta_std * config.theta_std,
    );
    let g = TrigProducts;
    let second = SecondOrder.propagate(&mean, &cov, &g)?;
    let gaussian = SecondOrderGaussian.propagate(&mean, &cov, &g)?;
    let sampled = Sampled::new(config.samples, config.seed)?.propagate(&mean, &cov, &g)?;
    let sampled = TrigMoments::from_moments(&sampled);
    let n = config.samples as f64;
    let se_var = |v: f64| v * (2.0 / (n - 1.0)).sqrt();
    let sampled_std_error = TrigMoments {
        e_cos: (sampled.var_cos / n).sqrt(),
        e_sin: (sampled.var_sin / n).sqrt(),
        var_cos: se_var(sampled.var_cos),
        var_sin: se_var(sampled.var_sin),
        e_x_cos: (sampled.var_x_cos / n).sqrt(),
        var_x_cos: se_var(sampled.var_x_cos),
        var_x_sin: se_var(sampled.var_x_sin),
    };
    Ok(MomentsResult {
        config: *config,
        second_order: TrigMoments::from_moments(&second),
        second_order_gaussian: TrigMoments::from_moments(&gaussian),
        exact: exact_trig_moments(
            config.x_mean,
            config.x_std,
            config.theta_mean,
            config.theta_std,
        ),
        sampled,
        sampled_std_error,
        paper: paper_trig_moments(
            config.x_mean,
            config.x_std,
            config.theta_mean,
            config.theta_std,
        ),
    })
}

impl MomentsResult {
    /// Paper vs estim for each quantity: the paper's closed form against the exact Gaussian
    /// value (the second-order approximation's error).
    pub fn headlines(&self) -> Vec<Headline> {
        let paper = self.paper.to_array();
        let second = self.second_order.to_array();
        let exact = self.exact.to_array();
        MomentsConfig::NAMES
            .iter()
            .enumerate()
            .map(|(i, name)| Headline {
                quantity: format!("{name} (eq 8/10/11)"),
                paper: format!("{:.6e} (closed form)", paper[i]),
                estim: format!(
                    "{:.6e} (generic SecondOrder); exact {:.6e}",
                    second[i], exact[i]
                ),
                note: format!(
                    "second-order error vs exact Gaussian: {:.1e} relative",
                    (second[i] - exact[i]) / exact[i]
                ),
            })
            .collect()
    }
}
