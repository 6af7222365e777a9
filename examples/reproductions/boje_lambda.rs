//! Boje eq 12–13: the mean and covariance Λ of (ẍ, ÿ, θ̈, θ̇²) from one accelerometer sample
//! (closed forms, eq 13 corrected), checked against estim's generic propagators on eq 5 and a
//! Monte Carlo; the printed eq 13 is shown beside (λ33/λ44 swapped).
//!
//! `cargo run --release --example boje_lambda [-- --json] [-- --quick]`

use crate::common::{Headline, Output, Series, line_plot};
use estim::core::error::Result;
use estim::core::{Linearized, MomentPropagator, Sampled, SecondOrder};
use estim::models::boje::{ChannelVariances, InversionInput, inertial_moments, lambda_as_printed};
use estim::nalgebra::{Matrix4, Vector4};

/// Settings of the λ example.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LambdaConfig {
    /// The heading mean, variance, sample, channel variances and R.
    pub input: InversionInput,
    /// Monte Carlo samples for the sampled reference.
    pub samples: usize,
    /// Seed of the sampled reference.
    pub seed: u64,
}

impl LambdaConfig {
    /// a = (0.3, −0.2, 0.5, 0.1) m/s², θ̄ = 0.4 rad, σ_θ = 0.05 rad, R = 0.5 m,
    /// σ = (0.01, 0.012, 0.009, 0.011) m/s² (unequal, so λ13…λ24 ≠ 0 and λ33 ≠ λ44), 10⁶ samples.
    pub fn example() -> Self {
        Self {
            input: InversionInput {
                theta: 0.4,
                theta_variance: 0.05 * 0.05,
                accel: Vector4::new(0.3, -0.2, 0.5, 0.1),
                variances: ChannelVariances::from_std(0.01, 0.012, 0.009, 0.011),
                half_separation: 0.5,
            },
            samples: 1_000_000,
            seed: 13,
        }
    }

    /// As [`example`](Self::example) with 10⁵ samples.
    pub fn quick() -> Self {
        Self {
            samples: 100_000,
            ..Self::example()
        }
    }
}

/// What [`lambda_experiment`] returns. Order of every vector and matrix: (ẍ, ÿ, θ̈, θ̇²).
#[derive(Clone, Debug, PartialEq)]
pub struct LambdaResult {
    /// The settings used.
    pub config: LambdaConfig,
    /// Eq 12, closed form.
    pub mean: Vector4<f64>,
    /// Eq 13 corrected, closed form.
    pub lambda: Matrix4<f64>,
    /// Eq 13 as printed (λ33, λ44 swapped).
    pub lambda_printed: Matrix4<f64>,
    /// Generic [`SecondOrder`] mean of eq 5 with z ~ (z̄, C_z).
    pub generic_mean: Vector4<f64>,
    /// Generic [`Linearized`] covariance J C_z Jᵀ of eq 5.
    pub generic_lambda: Matrix4<f64>,
    /// Monte Carlo mean of eq 5 with Gaussian z.
    pub sampled_mean: Vector4<f64>,
    /// Monte Carlo covariance of eq 5 with Gaussian z.
    pub sampled_lambda: Matrix4<f64>,
}

/// Runs the λ example.
///
/// Errors: invalid input (non-finite, negative variances, R ≤ 0), sample count < 2.
pub fn lambda_experiment(config: &LambdaConfig) -> Result<LambdaResult> {
    let input = &config.input;
    let closed = inertial_moments(input)?;
    let (mean, cov, g) = (input.mean(), input.covariance(), input.function());
    let second = SecondOrder.propagate(&mean, &cov, &g)?;
    let linear = Linearized.propagate(&mean, &cov, &g)?;
    let sampled = Sampled::new(config.samples, config.seed)?.propagate(&mean, &cov, &g)?;
    Ok(LambdaResult {
        config: *config,
        mean: closed.mean,
        lambda: closed.lambda,
        lambda_printed: lambda_as_printed(input)?,
        generic_mean: second.mean,
        generic_lambda: linear.covariance,
        sampled_mean: sampled.mean,
        sampled_lambda: sampled.covariance,
    })
}

impl LambdaResult {
    /// Paper vs estim for λ33 and λ44 (the erratum) and the largest closed-form/generic gap.
    pub fn headlines(&self) -> Vec<Headline> {
        let gap = (self.lambda - self.generic_lambda).abs().max();
        let gap_mean = (self.mean - self.generic_mean).abs().max();
        vec![
            Headline {
                quantity: "λ33 = var(θ̈) (eq 13)".into(),
                paper: format!(
                    "(σ²u1+σ²u2)/(4R²) = {:.6e} (1/s²)²",
                    self.lambda_printed[(2, 2)]
                ),
                estim: format!(
                    "(σ²v1+σ²v2)/(4R²) = {:.6e}; J C Jᵀ {:.6e}; sampled {:.6e}",
                    self.lambda[(2, 2)],
                    self.generic_lambda[(2, 2)],
                    self.sampled_lambda[(2, 2)]
                ),
                note: "θ̈ = (a_v1 − a_v2)/(2R) uses the v channels: paper swapped λ33/λ44".into(),
            },
            Headline {
                quantity: "λ44 = var(θ̇²) (eq 13)".into(),
                paper: format!(
                    "(σ²v1+σ²v2)/(4R²) = {:.6e} (1/s²)²",
                    self.lambda_printed[(3, 3)]
                ),
                estim: format!(
                    "(σ²u1+σ²u2)/(4R²) = {:.6e}; J C Jᵀ {:.6e}; sampled {:.6e}",
                    self.lambda[(3, 3)],
                    self.generic_lambda[(3, 3)],
                    self.sampled_lambda[(3, 3)]
                ),
                note: "θ̇² = (a_u2 − a_u1)/(2R) uses the u channels".into(),
            },
            Headline {
                quantity: "other λ's and eq 12 mean".into(),
                paper: "closed forms eq 12, 13".into(),
                estim: format!(
                    "closed form − generic propagator: max |Δλ| = {gap:.1e}, max |Δmean| = {gap_mean:.1e}"
                ),
                note: "agree (round-off)".into(),
            },
        ]
    }
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let config = if quick {
        LambdaConfig::quick()
    } else {
        LambdaConfig::example()
    };
    let r = lambda_experiment(&config)?;
    let names = ["xdd", "ydd", "thdd", "thd^2"];
    let i = &config.input;
    println!(
        "Boje eq 12–13 at a = ({}, {}, {}, {}) m/s², θ̄ = {} rad, σθ = {:.3} rad, R = {} m",
        i.accel[0],
        i.accel[1],
        i.accel[2],
        i.accel[3],
        i.theta,
        i.theta_variance.sqrt(),
        i.half_separation
    );
    println!(
        "{:<5} {:>14} {:>14} {:>14}",
        "mean", "eq 12", "SecondOrder", "sampled"
    );
    for k in 0..4 {
        println!(
            "{:<6} {:>14.8} {:>14.8} {:>14.8}",
            names[k], r.mean[k], r.generic_mean[k], r.sampled_mean[k]
        );
    }
    println!("Λ (eq 13 corrected), entries (row, col), closed form | J C Jᵀ | sampled | printed");
    for a in 0..4 {
        for b in a..4 {
            println!(
                "λ{}{}  {:>13.6e} {:>13.6e} {:>13.6e} {:>13.6e}{}",
                a + 1,
                b + 1,
                r.lambda[(a, b)],
                r.generic_lambda[(a, b)],
                r.sampled_lambda[(a, b)],
                r.lambda_printed[(a, b)],
                if (r.lambda[(a, b)] - r.lambda_printed[(a, b)]).abs() > 0.0 {
                    "  <- erratum E1"
                } else {
                    ""
                }
            );
        }
    }
    // Figure: the four diagonal standard deviations of Λ as σθ grows.
    let mut series: Vec<Vec<(f64, f64)>> = vec![Vec::new(); 4];
    for k in 0..=50 {
        let st = 0.004 * k as f64;
        let mut input = config.input;
        input.theta_variance = st * st;
        let l = estim::models::boje::lambda(&input)?;
        for j in 0..4 {
            series[j].push((st, l[(j, j)].sqrt()));
        }
    }
    let labels = ["√λ11 (ẍ)", "√λ22 (ÿ)", "√λ33 (θ̈)", "√λ44 (θ̇²)"];
    let s: Vec<Series<'_>> = series
        .into_iter()
        .zip(labels)
        .map(|(points, label)| Series { label, points })
        .collect();
    match line_plot(
        "boje_lambda.svg",
        "Boje eq 13: std of the inertial signals vs σθ",
        "σθ (rad)",
        "std (SI)",
        &s,
    ) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
    let json = {
        let mean: Vec<f64> = r.mean.iter().copied().collect();
        let lambda: Vec<Vec<f64>> = (0..4)
            .map(|a| (0..4).map(|b| r.lambda[(a, b)]).collect())
            .collect();
        serde_json::json!({"mean": mean, "lambda": lambda})
    };
    let headlines = r.headlines();
    Ok(Output { json, headlines })
}
