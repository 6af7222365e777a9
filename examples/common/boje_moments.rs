//! Boje section 2.2: Papoulis' second-order moments (eq 7, 9) on the paper's worked examples
//! (eq 8, 10, 11) — cos θ, sin θ, x cos θ, x sin θ for independent Gaussian x and θ — computed
//! by estim's generic `SecondOrder` propagator, beside the exact Gaussian expectation and a
//! seeded Monte Carlo.
//!
//! `cargo run --release --example boje_moments [-- --json] [-- --quick]`

use super::{Output, Series, line_plot};
use estim::models::boje::TrigProducts;
use estim::models::boje::{MomentsConfig, moments::exact_trig_moments, moments_experiment};
use estim::nalgebra::{Matrix2, Vector2};
use estim::prelude::*;

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
