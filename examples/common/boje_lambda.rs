//! Boje eq 12–13: the mean and covariance Λ of (ẍ, ÿ, θ̈, θ̇²) from one accelerometer sample
//! (closed forms, eq 13 corrected), checked against estim's generic propagators on eq 5 and a
//! Monte Carlo; the printed eq 13 is shown beside (λ33/λ44 swapped).
//!
//! `cargo run --release --example boje_lambda [-- --json] [-- --quick]`

use super::{Output, Series, line_plot};
use estim::models::boje::{LambdaConfig, lambda_experiment};

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
