//! Lu (UCLA MAE 271A report, 2017): accelerometer bias calibration from GPS, a 3-state
//! error-state Kalman filter (δp, δv, b) at 200 Hz with 5 Hz GPS position+velocity fixes, and
//! its Monte Carlo validation (§3.2) on estim's Monte Carlo runner.
//!
//! Runs 5000 realizations over 30 s (500 with `--quick`) with the consistent filter and prints
//! the four checks of the paper (ensemble mean error, ensemble covariance vs P, orthogonality,
//! residual correlation between 20 s and 30 s) with the runner's verdict table; then the same
//! Monte Carlo for each of the paper's printed variants (W = 0.0016, M₀ = diag(1, 100, 0.01),
//! Φ₁₃ = +Δt²/2, closed-form truth) and their verdicts; the gains; headlines. Writes figures to
//! `target/figures/`, and with `--json` prints one JSON line last. `--sequential` runs the
//! realizations on one thread (the default uses rayon; `RAYON_NUM_THREADS` sets the threads).
//!
//! `cargo run --release --example lu_calibration [-- --json] [-- --quick] [-- --sequential]`

use super::{Output, Series, line_plot};
use estim::models::lu::{
    Execution, LuConfig, LuResult, MonteCarloConfig, MonteCarloResult, headlines, verdict_line,
};

/// The example body, quick (500 runs) or full (5000), on the default execution.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    run_with(quick, Execution::Default)
}

fn table(r: &MonteCarloResult) {
    let n = r.config.runs as f64;
    println!(
        "  {:>5} | {:>26} | {:>26} | {:>30}",
        "t [s]",
        "filter sqrt P (dp, dv, b)",
        "ensemble std (dp, dv, b)",
        "e_ave / sqrt(P/N) (dp, dv, b)"
    );
    for t in [0.2, 1.0, 5.0, 10.0, 20.0, 30.0] {
        let k = r.slot_at(t);
        let p = r.filter_variance[k];
        let sd = r.ensemble_variance[k].map(f64::sqrt);
        let m = r.mean_error[k];
        println!(
            "  {:>5.1} | {:>8.4} {:>7.5} {:>9.2e} | {:>8.4} {:>7.5} {:>9.2e} | {:>9.2} {:>9.2} {:>9.2}",
            r.time[k],
            p[0].sqrt(),
            p[1].sqrt(),
            p[2].sqrt(),
            sd[0],
            sd[1],
            sd[2],
            m[0] / (p[0] / n).sqrt(),
            m[1] / (p[1] / n).sqrt(),
            m[2] / (p[2] / n).sqrt(),
        );
    }
}

fn figures(r: &LuResult) -> Vec<String> {
    let mc = &r.monte_carlo;
    let n = mc.config.runs;
    let mut out = Vec::new();
    let mut plot = |file: &str, title: String, y: &str, s: &[Series<'_>]| match line_plot(
        file, &title, "t [s]", y, s,
    ) {
        Ok(path) => out.push(path.display().to_string()),
        Err(e) => eprintln!("figure {file} failed: {e}"),
    };
    let series = |label: &'static str, f: &dyn Fn(usize) -> f64| Series {
        label,
        points: (1..mc.time.len()).map(|k| (mc.time[k], f(k))).collect(),
    };
    let names = [
        ("position", "dp [m]"),
        ("velocity", "dv [m/s]"),
        ("bias", "b [m/s^2]"),
    ];
    for (i, (name, unit)) in names.iter().enumerate() {
        plot(
            &format!("lu_sigma_{name}.svg"),
            format!("Lu: filter sqrt P vs ensemble std of the {name} error, N = {n}"),
            unit,
            &[
                series("filter sqrt P", &|k| mc.filter_variance[k][i].sqrt()),
                series("ensemble std (Monte Carlo)", &|k| {
                    mc.ensemble_variance[k][i].sqrt()
                }),
            ],
        );
    }
    plot(
        "lu_covariance_ratio.svg",
        format!("Lu: ensemble variance / filter P, N = {n} (1 = consistent)"),
        "P_ave / P",
        &[
            series("dp", &|k| {
                mc.ensemble_variance[k][0] / mc.filter_variance[k][0]
            }),
            series("dv", &|k| {
                mc.ensemble_variance[k][1] / mc.filter_variance[k][1]
            }),
            series("b", &|k| {
                mc.ensemble_variance[k][2] / mc.filter_variance[k][2]
            }),
        ],
    );
    let nf = n as f64;
    plot(
        "lu_mean_error.svg",
        format!("Lu: ensemble mean error in units of sqrt(P/N), N = {n}"),
        "e_ave / sqrt(P/N)",
        &[
            series("dp", &|k| {
                mc.mean_error[k][0] / (mc.filter_variance[k][0] / nf).sqrt()
            }),
            series("dv", &|k| {
                mc.mean_error[k][1] / (mc.filter_variance[k][1] / nf).sqrt()
            }),
            series("b", &|k| {
                mc.mean_error[k][2] / (mc.filter_variance[k][2] / nf).sqrt()
            }),
        ],
    );
    let mut orth = vec![series("consistent filter", &|k| mc.orthogonality[k])];
    for v in &r.variants {
        if v.config.label == estim::models::lu::labels::PRINTED_COUPLING {
            orth.push(Series {
                label: "printed Phi13 = +dt^2/2",
                points: (1..v.time.len())
                    .map(|k| (v.time[k], v.orthogonality[k]))
                    .collect(),
            });
        }
    }
    plot(
        "lu_orthogonality.svg",
        format!("Lu: max |corr(e, x_hat)| over the 9 entries, N = {n}"),
        "max |corr|",
        &orth,
    );
    let z = &r.realization;
    let one = |f: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
        (1..z.time.len()).map(|k| (z.time[k], f(k))).collect()
    };
    for (i, (name, unit)) in names.iter().enumerate() {
        plot(
            &format!("lu_realization_{name}.svg"),
            format!("Lu: one realization, {name} error with the filter's +-sigma"),
            unit,
            &[
                Series {
                    label: "error",
                    points: one(&|k| z.error[k][i]),
                },
                Series {
                    label: "+sigma",
                    points: one(&|k| z.sigma[k][i]),
                },
                Series {
                    label: "-sigma",
                    points: one(&|k| -z.sigma[k][i]),
                },
            ],
        );
    }
    let c = &r.covariance;
    let gain = |label: &'static str, i: usize, j: usize| Series {
        label,
        points: (1..c.time.len())
            .map(|k| (c.time[k], c.gain[k][(i, j)]))
            .collect(),
    };
    plot(
        "lu_gains.svg",
        "Lu: Kalman gains K (rows dp, dv, b; columns p fix, v fix)".into(),
        "K",
        &[
            gain("K11", 0, 0),
            gain("K12", 0, 1),
            gain("K21", 1, 0),
            gain("K22", 1, 1),
            gain("K31", 2, 0),
            gain("K32", 2, 1),
        ],
    );
    out
}

/// The example body with the given execution of the Monte Carlo runs.
pub fn run_with(quick: bool, execution: Execution) -> Result<Output, Box<dyn std::error::Error>> {
    let mc = if quick {
        MonteCarloConfig::quick()
    } else {
        MonteCarloConfig::full()
    }
    .with_execution(execution);
    let config = LuConfig::with_monte_carlo(mc);
    let r = estim::models::lu::run(&config)?;
    let m = &r.monte_carlo;
    let sc = &m.config.scenario;
    let n = m.config.runs;

    println!(
        "Lu 2017: accelerometer calibration with GPS. dt = {} s, GPS every {} steps ({} s), {} s, N = {n} realizations ({:?} execution)",
        sc.dt,
        sc.gps_every,
        sc.gps_every as f64 * sc.dt,
        sc.duration(),
        execution
    );
    println!(
        "Monte Carlo (consistent filter): wall {:.2} s for {n} x {} steps\n",
        m.wall_s, sc.steps
    );
    table(m);
    let s = m.summary();
    println!(
        "\n  max over fixes: |e_ave|/sqrt(P/N) = ({:.2}, {:.2}, {:.2}); P_ave/P in [{:.3}, {:.3}] / [{:.3}, {:.3}] / [{:.3}, {:.3}]; max |corr(e, x_hat)| = {:.4} ({:.2}/sqrt N)",
        s.max_mean_error_sigmas[0],
        s.max_mean_error_sigmas[1],
        s.max_mean_error_sigmas[2],
        s.covariance_ratio_min[0],
        s.covariance_ratio_max[0],
        s.covariance_ratio_min[1],
        s.covariance_ratio_max[1],
        s.covariance_ratio_min[2],
        s.covariance_ratio_max[2],
        s.max_orthogonality,
        s.max_orthogonality_sigmas
    );
    let (t1, t2) = m.residual_times;
    let c = &m.residual_correlation;
    let se = &m.residual_standard_error;
    println!(
        "  (1/N) sum r({t1}) r({t2})^T = [[{:.4}, {:.5}], [{:.5}, {:.2e}]]  (standard errors [[{:.4}, {:.5}], [{:.5}, {:.2e}]]; paper: [[0.0486, -0.0023], [0.0002, 0.0002]])\n",
        c[(0, 0)],
        c[(0, 1)],
        c[(1, 0)],
        c[(1, 1)],
        se[(0, 0)],
        se[(0, 1)],
        se[(1, 0)],
        se[(1, 1)]
    );
    println!("{}", m.verdict);

    println!("The paper's printed variants (same N, same seeds):");
    println!(
        "  {:<46} | {:>22} | {:>9} | {:>13} | verdict",
        "variant", "P_ave/P at 30 s", "max corr", "max dv mean"
    );
    for v in &r.variants {
        let vs = v.summary();
        println!(
            "  {:<46} | {:>6.3} {:>6.3} {:>6.3}  | {:>9.4} | {:>9.4} m/s | {}",
            v.config.label,
            vs.covariance_ratio_end[0],
            vs.covariance_ratio_end[1],
            vs.covariance_ratio_end[2],
            vs.max_orthogonality,
            vs.max_mean_error[1],
            verdict_line(&v.verdict)
        );
    }
    for v in &r.variants {
        println!("\n{}:\n{}", v.config.label, v.verdict);
    }

    println!("\nHeadlines (paper vs estim):");
    let headlines = headlines(&r);
    for h in &headlines {
        println!(
            "- {}\n    paper: {}\n    estim: {}\n    note:  {}",
            h.quantity, h.paper, h.estim, h.note
        );
    }

    println!("\nFigures:");
    for f in figures(&r) {
        println!("  {f}");
    }

    let times = [10.0, 20.0, 30.0];
    let rows = |f: &dyn Fn(usize) -> [f64; 3]| -> Vec<[f64; 3]> {
        times.iter().map(|&t| f(m.slot_at(t))).collect()
    };
    let json = serde_json::json!({
        "t": times,
        "filter_p_diag": rows(&|k| m.filter_variance[k].into()),
        "ensemble_var_diag": rows(&|k| m.ensemble_variance[k].into()),
        "ensemble_mean_error": rows(&|k| m.mean_error[k].into()),
        "residual_corr_20_30": [[c[(0, 0)], c[(0, 1)]], [c[(1, 0)], c[(1, 1)]]],
        "wall_s": m.wall_s,
    });
    Ok(Output { json, headlines })
}
