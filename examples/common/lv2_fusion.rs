//! LV2 note: best estimates of x and y from redundant x, y and q = (x + y)/√2 accelerometer axes.
//!
//! Fuses the reading x̃ = 1.00, ỹ = 0.50, q̃ = 1.07 m/s² (σx = 0.010, σy = 0.012, σq = 0.008
//! m/s²) by the note's closed forms (eq 2–6), by weighted least squares and by the framework's
//! Kalman filter; tests consistency (eq 7) with a χ² threshold; fuses without each axis; then
//! runs the χ² Monte Carlo (fault-free and with a biased axis) and the saturation scenario.
//!
//! `cargo run --release --example lv2_fusion [-- --quick] [-- --json]`
//!
//! Figures: `target/figures/lv2_error_ellipses.svg` (1σ ellipses of (x̂, ŷ) with and without
//! each axis), `target/figures/lv2_chi2_cdf.svg` (Monte Carlo χ² CDF against χ²₁, fault-free
//! and with a biased x axis).

use super::{Output, Series, line_plot};
use estim::models::lv2::experiments::{self, Lv2Config, error_ellipse};
use estim::models::lv2::xyq::XyqEstimate;
use estim::nalgebra::Matrix2;

fn sd_rho(p: &Matrix2<f64>) -> (f64, f64, f64) {
    let (sx, sy) = (p[(0, 0)].sqrt(), p[(1, 1)].sqrt());
    (sx, sy, p[(0, 1)] / (sx * sy))
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let cfg = if quick {
        Lv2Config::quick()
    } else {
        Lv2Config::full()
    };
    let res = experiments::run(&cfg)?;
    let ex = &res.example;
    let r = ex.reading;
    let s = ex.sigmas;

    println!("LV2 redundant-axis fusion (all values in m/s²)");
    println!(
        "reading x̃ = {:.3}, ỹ = {:.3}, q̃ = {:.3};  σx = {:.3}, σy = {:.3}, σq = {:.3}",
        r.x, r.y, r.q, s.x, s.y, s.q
    );
    let c = ex.coefficients;
    println!(
        "eq 6 coefficients: s₁ = {:.4e}, f₁ = {:.6}, f₂ = {:.6}  (ŷ: g₁ = {:.6}, g₂ = {:.6})",
        c.s1, c.f1, c.f2, c.g1, c.g2
    );

    println!("\n{:<44} {:>12} {:>12}", "route", "x̂", "ŷ");
    println!(
        "{:<44} {:>12.7} {:>12}",
        "x̂₁ = x̃ (eq 2)", ex.x_hat_1_2.0, ""
    );
    println!(
        "{:<44} {:>12.7} {:>12}",
        "x̂₂ = √2 q̃ − ỹ (eq 2)", ex.x_hat_1_2.1, ""
    );
    println!(
        "{:<44} {:>12.7} {:>12}",
        "eq 3 (x̂₁, x̂₂ weighted by σx², σ²x2 of eq 4)", ex.eq3.0, ""
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "eq 5 as printed (and mirror for ŷ)", ex.eq5[0], ex.eq5[1]
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "eq 6 precomputed coefficients", ex.fused.estimate[0], ex.fused.estimate[1]
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "weighted least squares (HᵀR⁻¹H)⁻¹HᵀR⁻¹z", ex.wls.estimate[0], ex.wls.estimate[1]
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "Kalman filter: exact prior (x, y), update q", ex.filter.estimate[0], ex.filter.estimate[1]
    );
    let d = ex.route_difference;
    println!(
        "largest route difference: estimate {:.1e}, covariance {:.1e}, χ² {:.1e}",
        d.estimate, d.covariance, d.chi2
    );

    println!(
        "\n{:<22} {:>10} {:>10} {:>10} {:>10} {:>9}",
        "axes used", "x̂", "ŷ", "σx̂", "σŷ", "ρ(x̂,ŷ)"
    );
    let rows: [(&str, &XyqEstimate); 4] = [
        ("x, y, q", &ex.fused),
        ("y, q (x lost)", &ex.without_x),
        ("x, q (y lost)", &ex.without_y),
        ("x, y (q lost)", &ex.without_q),
    ];
    for (name, e) in rows {
        let (sx, sy, rho) = sd_rho(&e.covariance);
        println!(
            "{name:<22} {:>10.6} {:>10.6} {:>10.6} {:>10.6} {:>9.3}",
            e.estimate[0], e.estimate[1], sx, sy, rho
        );
    }
    let p = ex.fused.covariance;
    println!(
        "P (x, y, q) = [[{:.4e}, {:.4e}], [{:.4e}, {:.4e}]]",
        p[(0, 0)],
        p[(0, 1)],
        p[(1, 0)],
        p[(1, 1)]
    );

    println!("\nConsistency (eq 7)");
    println!(
        "parity r = x̂₁ − x̂₂ = x̃ + ỹ − √2 q̃ = {:.6};  χ² = r²/s₁ = {:.4} (dof 1), p = {:.3}",
        ex.fused.parity.unwrap_or(f64::NAN),
        ex.fused.chi2,
        ex.p_value
    );
    println!(
        "threshold at α = {:.0e}: {:.3} → {}",
        cfg.false_alarm,
        ex.threshold,
        if ex.consistent { "consistent" } else { "FAULT" }
    );

    let mc = &res.monte_carlo;
    println!("\nMonte Carlo, {} seeded readings", mc.runs);
    println!(
        "fault-free χ²: mean {:.4} (χ²₁: 1), variance {:.4} (2), false alarms {:.2e} (α = {:.0e})",
        mc.chi2_mean, mc.chi2_variance, mc.false_alarm_rate, mc.false_alarm
    );
    let (e, q) = (mc.empirical_covariance, mc.predicted_covariance);
    println!(
        "cov(x̂ − x, ŷ − y): Monte Carlo [[{:.4e}, {:.4e}], [·, {:.4e}]]  closed form [[{:.4e}, {:.4e}], [·, {:.4e}]]",
        e[(0, 0)],
        e[(0, 1)],
        e[(1, 1)],
        q[(0, 0)],
        q[(0, 1)],
        q[(1, 1)]
    );
    println!(
        "\n{:<12} {:>10} {:>14} {:>12} {:>12} {:>20} {:>20}",
        "biased axis",
        "bias",
        "parity shift",
        "detected",
        "predicted",
        "mean error (x, y)",
        "predicted"
    );
    for f in &mc.faults {
        println!(
            "{:<12} {:>10.3} {:>13.3}σ {:>12.4} {:>12.4} {:>9.5}, {:>8.5} {:>9.5}, {:>8.5}",
            f.axis,
            f.bias,
            f.parity_shift,
            f.detection_rate,
            f.predicted_rate,
            f.mean_error[0],
            f.mean_error[1],
            f.predicted_mean_error[0],
            f.predicted_mean_error[1]
        );
    }

    let sat = &res.saturation;
    let sc = &cfg.saturation;
    println!(
        "\nSaturation: {:.1} m/s² turning at {} Hz, range ±{} m/s², {} Hz for {} s ({} samples), {:.0} % drop-outs",
        sc.magnitude,
        sc.frequency_hz,
        sc.full_scale,
        sc.sample_rate_hz,
        sc.duration_s,
        sat.samples,
        100.0 * sc.dropout
    );
    println!(
        "at the rail: x {}, y {}, q {};  missing: x {}, y {}, q {}",
        sat.saturated[0],
        sat.saturated[1],
        sat.saturated[2],
        sat.missing[0],
        sat.missing[1],
        sat.missing[2]
    );
    println!(
        "{:<34} {:>10} {:>12} {:>12} {:>12} {:>12} {:>8}",
        "fusion", "estimated", "RMS x", "RMS y", "claimed x", "claimed y", "χ² flags"
    );
    for (name, e) in [
        ("drop saturated (the note)", &sat.screened),
        ("use clipped readings", &sat.naive),
    ] {
        println!(
            "{name:<34} {:>10} {:>12.5} {:>12.5} {:>12.5} {:>12.5} {:>8}",
            e.estimated,
            e.rms_error[0],
            e.rms_error[1],
            e.predicted_rms[0],
            e.predicted_rms[1],
            e.flagged
        );
    }
    println!(
        "samples with a clipped reading in use (naive): {}; the χ² test flags {} of the naive fusions",
        sat.clipped_samples, sat.naive.flagged
    );
    println!(
        "samples without an estimate (fewer than 2 axes): {} with q; {} with x and y alone",
        sat.screened.no_estimate, sat.xy_only_no_estimate
    );

    println!("\n{:<22} | {:<58} | estim", "claim", "note");
    for h in experiments::headlines(&res) {
        println!("{:<22} | {:<58} | {}", h.quantity, h.paper, h.estim);
        if !h.note.is_empty() {
            println!("{:<22} | {:<58} |   ({})", "", "", h.note);
        }
    }

    // Figures.
    let ellipses: Vec<(String, Vec<(f64, f64)>)> = rows
        .iter()
        .map(|(name, e)| {
            (
                name.to_string(),
                error_ellipse(&e.estimate, &e.covariance, 1.0, 120),
            )
        })
        .collect();
    let series: Vec<Series<'_>> = ellipses
        .iter()
        .map(|(label, points)| Series {
            label,
            points: points.clone(),
        })
        .collect();
    match line_plot(
        "lv2_error_ellipses.svg",
        "1σ error ellipses of (x̂, ŷ), LV2 example",
        "x [m/s²]",
        "y [m/s²]",
        &series,
    ) {
        Ok(path) => println!("\nfigure: {}", path.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
    let cdf = |f: fn(&experiments::CdfPoint) -> f64| {
        mc.cdf.iter().map(|c| (c.chi2, f(c))).collect::<Vec<_>>()
    };
    let thr = vec![(mc.threshold, 0.0), (mc.threshold, 1.0)];
    let series = [
        Series {
            label: "Monte Carlo, fault-free",
            points: cdf(|c| c.empirical),
        },
        Series {
            label: "χ²₁",
            points: cdf(|c| c.theory),
        },
        Series {
            label: "Monte Carlo, x biased",
            points: cdf(|c| c.empirical_biased),
        },
        Series {
            label: "noncentral χ²₁",
            points: cdf(|c| c.theory_biased),
        },
        Series {
            label: "threshold (α = 1e-3)",
            points: thr,
        },
    ];
    match line_plot(
        "lv2_chi2_cdf.svg",
        "CDF of the parity χ²",
        "χ²",
        "P(χ² ≤ value)",
        &series,
    ) {
        Ok(path) => println!("figure: {}", path.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }

    let json = {
        let json = serde_json::json!({
            "x_hat": ex.fused.estimate[0],
            "y_hat": ex.fused.estimate[1],
            "cov": [[p[(0, 0)], p[(0, 1)]], [p[(1, 0)], p[(1, 1)]]],
            "chi2": ex.fused.chi2,
            "x_hat_without_x": ex.without_x.estimate[0],
            "y_hat_without_y": ex.without_y.estimate[1],
        });
        json
    };
    let headlines = experiments::headlines(&res);
    Ok(Output { json, headlines })
}
