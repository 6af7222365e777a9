//! Lee & Huang (IEEE T-AES 2002): all-accelerometer planar INS, CKF alone vs CKF + own-ship
//! trajectory estimator (OTE), section IV (30° pitch, 2 g along body x, 10 mg bias).
//!
//! Runs the CKF (the paper's Ψ Jacobian, in the linear Kalman filter) and the CKF followed by
//! the OTE (fading-memory RLS, γ = 0.95, S_p = 0.01 I, P_p(0) = I) on the same simulated
//! sensor data over several seeds, plus estim's radial-consistent second scenario and a table of
//! variant readings. Prints tables and headlines, writes figures to `target/figures/`, and with
//! `--json` prints one JSON line last. `--quick` uses 5 seeds instead of 20.
//!
//! `cargo run --release --example lee_huang [-- --json] [-- --quick]`

use super::{Output, Series, line_plot};
use estim::models::lee_huang::{ErrorHistory, LeeHuangConfig, SectionIvResult, headlines, labels};

fn history_table(r: &SectionIvResult) {
    println!(
        "  {:>5} | {:>9} {:>9} | {:>9} {:>9} | {:>15} | {:>17}",
        "t [s]",
        "CKF |p|",
        "CKF |v|",
        "+OTE |p|",
        "+OTE |v|",
        "theta deg (sqP)",
        "omega deg/s (sqP)"
    );
    for t in [1.0, 2.0, 5.0, 10.0, 15.0, 20.0] {
        let (c, o) = (&r.ckf, &r.ckf_ote);
        let i = c.index_at(t);
        if (c.time[i] - t).abs() > 1e-9 {
            continue;
        }
        println!(
            "  {:>5.1} | {:>8.2}m {:>6.2}m/s | {:>8.2}m {:>6.2}m/s | {:>6.2} ({:>5.2}) | {:>7.3} ({:>6.3})",
            t,
            c.position_rms[i],
            c.velocity_rms[i],
            o.position_rms[i],
            o.velocity_rms[i],
            c.attitude_rms[i].to_degrees(),
            c.attitude_sigma[i].to_degrees(),
            c.rate_rms[i].to_degrees(),
            c.rate_sigma[i].to_degrees(),
        );
    }
}

fn series<'a>(
    label: &'a str,
    h: &ErrorHistory,
    f: impl Fn(&ErrorHistory, usize) -> f64,
) -> Series<'a> {
    Series {
        label,
        points: (0..h.time.len()).map(|i| (h.time[i], f(h, i))).collect(),
    }
}

fn figures(r: &estim::models::lee_huang::LeeHuangResult) -> Vec<String> {
    let p = &r.paper;
    let n = p.config.seeds;
    let drift = Series {
        label: "1/2 |R b| t^2 (bias alone)",
        points: p
            .ckf
            .time
            .iter()
            .zip(&p.bias_drift)
            .map(|(t, b)| (*t, b.norm()))
            .collect(),
    };
    let mut out = Vec::new();
    let mut plot = |file: &str, title: String, y: &str, s: &[Series<'_>]| match line_plot(
        file, &title, "t [s]", y, s,
    ) {
        Ok(path) => out.push(path.display().to_string()),
        Err(e) => eprintln!("figure {file} failed: {e}"),
    };
    plot(
        "lee_huang_position_error.svg",
        format!("Section IV: position error, RMS over {n} seeds (paper ICs)"),
        "|p_hat - p| [m]",
        &[
            series("CKF", &p.ckf, |h, i| h.position_rms[i]),
            series("CKF + OTE (gamma 0.95)", &p.ckf_ote, |h, i| {
                h.position_rms[i]
            }),
            series("CKF own sqrt tr P_pp", &p.ckf, |h, i| h.position_sigma[i]),
            drift,
        ],
    );
    plot(
        "lee_huang_velocity_error.svg",
        format!("Section IV: velocity error, RMS over {n} seeds (paper ICs)"),
        "|v_hat - v| [m/s]",
        &[
            series("CKF", &p.ckf, |h, i| h.velocity_rms[i]),
            series("CKF + OTE (gamma 0.95)", &p.ckf_ote, |h, i| {
                h.velocity_rms[i]
            }),
        ],
    );
    plot(
        "lee_huang_attitude_error.svg",
        format!("Section IV: attitude error, RMS over {n} seeds (same with OTE)"),
        "[deg]",
        &[
            series("theta RMS error", &p.ckf, |h, i| {
                h.attitude_rms[i].to_degrees()
            }),
            series("sqrt P_theta", &p.ckf, |h, i| {
                h.attitude_sigma[i].to_degrees()
            }),
        ],
    );
    plot(
        "lee_huang_rate_error.svg",
        format!("Section IV: rate error, RMS over {n} seeds (same with OTE)"),
        "[deg/s]",
        &[
            series("omega RMS error", &p.ckf, |h, i| h.rate_rms[i].to_degrees()),
            series("sqrt P_omega", &p.ckf, |h, i| h.rate_sigma[i].to_degrees()),
        ],
    );
    let q = &r.radial;
    plot(
        "lee_huang_radial_position_error.svg",
        format!("estim's reading: radial ICs, sigma_eps = 0.01 rad, RMS over {n} seeds"),
        "|p_hat - p| [m]",
        &[
            series("CKF", &q.ckf, |h, i| h.position_rms[i]),
            series("CKF + OTE (gamma 0.95)", &q.ckf_ote, |h, i| {
                h.position_rms[i]
            }),
            Series {
                label: "1/2 |R b| t^2 (bias alone)",
                points: q
                    .ckf
                    .time
                    .iter()
                    .zip(&q.bias_drift)
                    .map(|(t, b)| (*t, b.norm()))
                    .collect(),
            },
        ],
    );
    out
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let config = if quick {
        LeeHuangConfig::quick()
    } else {
        LeeHuangConfig::full()
    };
    let r = estim::models::lee_huang::run(&config)?;
    let n = r.paper.config.seeds;
    let t_end = r.paper.config.duration;

    println!(
        "Lee & Huang 2002, section IV: T = {} s, {t_end} s, RMS over {n} seeds",
        r.paper.config.dt
    );
    println!("(errors are RMS over seeds of the error norm; sqP = the filter's own sqrt P)\n");
    println!(
        "{} (CKF = paper's Psi Jacobian; OTE gamma = 0.95, S_p = 0.01 I, P_p(0) = I):",
        labels::PAPER
    );
    history_table(&r.paper);
    println!(
        "\n{} -- estim's second scenario, NOT the paper's:",
        labels::RADIAL
    );
    history_table(&r.radial);

    println!("\nReadings and variants, at {t_end} s:");
    println!(
        "  {:<52} | {:>9} {:>10} | {:>9} {:>10}",
        "configuration", "CKF |p|", "+OTE |p|", "CKF |v|", "+OTE |v|"
    );
    for v in &r.variants {
        println!(
            "  {:<52} | {:>8.1}m {:>9.1}m | {:>6.2}m/s {:>7.2}m/s",
            v.label,
            v.ckf_final_position_rms,
            v.ckf_ote_final_position_rms,
            v.ckf_final_velocity_rms,
            v.ckf_ote_final_velocity_rms
        );
    }

    let ss = &r.steady_state;
    println!(
        "\nOTE steady state (gamma = {}, S_p = {} I, P_p(0) = {} I) after {} cycles of FadingMemoryRls:",
        ss.settings.forgetting,
        ss.settings.weight[(0, 0)],
        ss.settings.initial_covariance[(0, 0)],
        ss.steps
    );
    println!(
        "  K_p = {:.12} I  (closed form (1-gamma) I = {:.12} I)",
        ss.gain[(0, 0)],
        ss.gain_closed_form[(0, 0)]
    );
    println!(
        "  P_p = {:.12e} I  (closed form (1-gamma) S_p = {:.12e} I)",
        ss.covariance[(0, 0)],
        ss.covariance_closed_form[(0, 0)]
    );

    println!("\nHeadlines (paper vs estim):");
    for h in headlines(&r) {
        println!(
            "- {}\n    paper: {}\n    estim: {}\n    note:  {}",
            h.quantity, h.paper, h.estim, h.note
        );
    }

    println!("\nFigures:");
    for f in figures(&r) {
        println!("  {f}");
    }

    let json = {
        let json = serde_json::json!({
            "ote_steady_gain": ss.gain[(0, 0)],
            "ote_steady_p": ss.covariance[(0, 0)],
            "ckf_final_pos_err_m": r.paper.ckf.final_position_rms(),
            "ckf_ote_final_pos_err_m": r.paper.ckf_ote.final_position_rms(),
        });
        json
    };
    let headlines = headlines(&r);
    Ok(Output { json, headlines })
}
