//! Boje section 3: the rate accuracy of the accelerometer pair (eq 17–19) at R = 0.1 m,
//! Δt = 0.01 s, σ = 1.4 mg, ω = 80 °/s — eq 18's closed form, eq 17 iterated to steady state,
//! the printed eq 19 (erratum), and a Monte Carlo of the scalar EKF (estim's `Ekf` on a 1-state
//! model) at constant rate on simulated accelerometer samples.
//!
//! `cargo run --release --example boje_rate [-- --json] [-- --quick]`

use super::{Output, Series, line_plot};
use estim::models::boje::{RateConfig, rate_experiment};

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let config = if quick {
        RateConfig::quick()
    } else {
        RateConfig::paper()
    };
    let r = rate_experiment(&config)?;
    println!(
        "Boje section 3: R = {} m, Δt = {} s, σ = {} mg = {:.6} m/s², ω₀ = {} °/s",
        config.half_separation,
        config.dt,
        config.sigma_mg,
        config.sigma(),
        config.rate_deg_s
    );
    println!(
        "q = λ33 Δt² = {:.5e} (rad/s)², r = λ44 = {:.5e} (rad/s)⁴, c = 2ω₀ = {:.6} rad/s",
        r.q, r.r, r.c
    );
    println!("{:<52} {:>14} {:>10}", "route", "p (rad/s)²", "std °/s");
    let rows = [
        ("eq 18 closed form (predicted)", r.p_eq18),
        ("eq 17 iterated to steady state (predicted)", r.p_riccati),
        ("eq 17 steady state − q (filtered)", r.p_riccati - r.q),
        ("eq 19 corrected (1 + √(1 + 4/(cΔt)²))", r.p_eq19),
        ("eq 19 as printed (1 + √(1 + 1/(cΔt)²))", r.p_eq19_printed),
    ];
    for (name, p) in rows {
        println!("{:<52} {:>14.6e} {:>10.4}", name, p, p.sqrt().to_degrees());
    }
    println!(
        "eq 17 converged in {} iterations from p₀ = ({} °/s)²",
        r.riccati_iterations, config.initial_std_deg_s
    );
    println!(
        "scalar EKF Monte Carlo, {} runs × {} steps (first {} dropped): rms predicted {:.4} °/s, rms filtered {:.4} °/s, mean √P {:.4} °/s",
        config.runs,
        config.steps,
        config.burn_in,
        r.rate_rms_simulated_deg_s,
        r.rate_rms_filtered_simulated_deg_s,
        r.rate_sqrt_p_simulated_deg_s
    );
    println!();
    println!("{:<46} | {:<12} | estim", "headline", "paper");
    for h in r.headlines() {
        println!("{:<46} | {:<12} | {}", h.quantity, h.paper, h.estim);
        if !h.note.is_empty() {
            println!("{:<46}   note: {}", "", h.note);
        }
    }

    let eq18 = r.rate_std_eq18_deg_s;
    let printed = r.rate_std_eq19_printed_deg_s;
    let iters = r.riccati_trace.len().min(400);
    let trace: Vec<(f64, f64)> = r.riccati_trace[..iters]
        .iter()
        .enumerate()
        .map(|(i, p)| (i as f64, p.sqrt().to_degrees()))
        .collect();
    let flat = |v: f64| vec![(0.0, v), ((iters - 1) as f64, v)];
    match line_plot(
        "boje_rate_riccati.svg",
        "Boje eq 17 iterated vs eq 18 and the printed eq 19",
        "iteration (Δt steps)",
        "rate std (°/s)",
        &[
            Series {
                label: "√p, eq 17",
                points: trace,
            },
            Series {
                label: "eq 18",
                points: flat(eq18),
            },
            Series {
                label: "eq 19 as printed",
                points: flat(printed),
            },
        ],
    ) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
    let n = r.rms_over_time_deg_s.len().min(3000);
    let t = |i: usize| i as f64 * config.dt;
    match line_plot(
        "boje_rate_monte_carlo.svg",
        "Boje section 3: scalar EKF at 80 °/s, Monte Carlo",
        "t (s)",
        "rate error (°/s)",
        &[
            Series {
                label: "RMS predicted error over runs",
                points: (0..n).map(|i| (t(i), r.rms_over_time_deg_s[i])).collect(),
            },
            Series {
                label: "filter √P (run 1)",
                points: (0..n)
                    .map(|i| (t(i), r.sqrt_p_over_time_deg_s[i]))
                    .collect(),
            },
            Series {
                label: "eq 18",
                points: vec![(0.0, eq18), (t(n - 1), eq18)],
            },
            Series {
                label: "eq 19 as printed",
                points: vec![(0.0, printed), (t(n - 1), printed)],
            },
        ],
    ) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
    let json = {
        serde_json::json!({
            "rate_std_eq18_deg_s": r.rate_std_eq18_deg_s,
            "rate_std_riccati_deg_s": r.rate_std_riccati_deg_s,
            "rate_rms_simulated_deg_s": r.rate_rms_simulated_deg_s,
        })
    };
    let headlines = r.headlines();
    Ok(Output { json, headlines })
}
