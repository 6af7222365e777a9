//! Boje section 2.2: Papoulis' second-order moments (eq 7, 9) on the paper's worked examples
//! (eq 8, 10, 11) — cos θ, sin θ, x cos θ, x sin θ for independent Gaussian x and θ — computed
//! by estim's generic `SecondOrder` propagator, beside the exact Gaussian expectation and a
//! seeded Monte Carlo.
//!
//! `cargo run --release --example boje_moments [-- --json] [-- --quick]`

use crate::common::{Headline, Output, Series, line_plot};
use estim::core::error::Result;
use estim::core::{MomentPropagator, Sampled, SecondOrder, SecondOrderGaussian};
use estim::models::boje::TrigProducts;
use estim::models::boje::moments::{TrigMoments, exact_trig_moments, paper_trig_moments};
use estim::nalgebra::{Matrix2, Vector2};
use estim::prelude::*;

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

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let config = if quick {
        MomentsConfig::quick()
    } else {
        MomentsConfig::paper()
    };
    let r = moments_experiment(&config)?;
    println!(
        "Boje eq 8, 10, 11: θ ~ N({}, {}²), x ~ N({}, {}²), independent; sampled: {} draws",
        config.theta_mean, config.theta_std, config.x_mean, config.x_std, config.samples
    );
    println!(
        "{:<10} {:>14} {:>14} {:>14} {:>10} {:>14} {:>10}",
        "quantity", "second order", "exact", "sampled", "±1 s.e.", "paper formula", "SO rel err"
    );
    let (so, ex, sa, se, pa) = (
        r.second_order.to_array(),
        r.exact.to_array(),
        r.sampled.to_array(),
        r.sampled_std_error.to_array(),
        r.paper.to_array(),
    );
    for (i, name) in MomentsConfig::NAMES.iter().enumerate() {
        println!(
            "{:<10} {:>14.8} {:>14.8} {:>14.8} {:>10.1e} {:>14.8} {:>10.2e}",
            name,
            so[i],
            ex[i],
            sa[i],
            se[i],
            pa[i],
            (so[i] - ex[i]) / ex[i]
        );
    }
    println!(
        "(SecondOrderGaussian adds ½ tr(HₖCHₗC): var(cos θ) {:.8}, var(x cos θ) {:.8})",
        r.second_order_gaussian.var_cos, r.second_order_gaussian.var_x_cos
    );

    // Figure: relative error of the second-order mean and variance of cos θ against σ_θ.
    let mut mean_err = Vec::new();
    let mut var_err = Vec::new();
    for k in 1..=40 {
        let st = 0.02 * k as f64;
        let prior = Gaussian::new(
            Vector2::new(config.x_mean, config.theta_mean),
            Matrix2::new(config.x_std.powi(2), 0.0, 0.0, st * st),
        )?;
        let m = SecondOrder.propagate_gaussian(&prior, &TrigProducts)?;
        let e = exact_trig_moments(config.x_mean, config.x_std, config.theta_mean, st);
        mean_err.push((st, ((m.mean[0] - e.e_cos) / e.e_cos).abs().log10()));
        var_err.push((
            st,
            ((m.covariance[(2, 2)] - e.var_x_cos) / e.var_x_cos)
                .abs()
                .log10(),
        ));
    }
    match line_plot(
        "boje_moments_error.svg",
        "Boje eq 8/11: second-order relative error vs σθ",
        "σθ (rad)",
        "log10 |relative error|",
        &[
            Series {
                label: "E{cos θ}",
                points: mean_err,
            },
            Series {
                label: "var(x cos θ)",
                points: var_err,
            },
        ],
    ) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }

    let json = {
        let mut obj = serde_json::Map::new();
        for (i, name) in MomentsConfig::NAMES.iter().enumerate() {
            obj.insert(
                (*name).to_string(),
                serde_json::json!({"second_order": so[i], "exact": ex[i], "sampled": sa[i]}),
            );
        }
        serde_json::Value::Object(obj)
    };
    let headlines = r.headlines();
    Ok(Output { json, headlines })
}
