//! What `plaza_range` prints, draws and returns as JSON.

use std::path::PathBuf;

use serde_json::{Value, json};

use super::{Config, Estimate, Pass, PlazaResult, Score, run_config, truth_at};
use crate::common::{self, Band, Output, Series};

fn score_json(s: &Score) -> Value {
    json!({ "rmse_m": s.rmse, "coverage_3sigma": s.coverage, "mean_nees": s.mean_nees })
}

/// The JSON object of a result (the `--json` line). `gated_fraction` and `mean_nis` are the
/// EKF's (the smoother's forward pass); the other filters' are under `by_filter`.
pub fn json(r: &PlazaResult) -> Value {
    let pass = |p: &Option<Pass>| p.as_ref().map(|p| p.score.rmse);
    let cover = |p: &Option<Pass>| p.as_ref().and_then(|p| p.score.coverage);
    let smoothed = r.ekf.smoothed.as_ref().map(|s| s.1);
    let updates = |p: &Option<Pass>| {
        p.as_ref().and_then(|p| p.updates).map(|u| {
            json!({ "gated_fraction": u.gated_fraction(), "mean_nis": u.mean_nis, "applied": u.applied, "gated": u.gated })
        })
    };
    let ekf_updates = r.ekf.updates.unwrap_or_default();
    let n = &r.config.noise;
    json!({
        "rmse_m": {
            "dead_reckoning": r.dead_reckoning.1.rmse,
            "ekf": r.ekf.score.rmse,
            "ukf": pass(&r.ukf),
            "iekf": pass(&r.iekf),
            "particle": pass(&r.particle),
            "smoother": smoothed.map(|s| s.rmse),
        },
        "gated_fraction": ekf_updates.gated_fraction(),
        "mean_nis": ekf_updates.mean_nis,
        "coverage_3sigma": {
            "ekf": r.ekf.score.coverage,
            "ukf": cover(&r.ukf),
            "iekf": cover(&r.iekf),
            "particle": cover(&r.particle),
            "smoother": smoothed.and_then(|s| s.coverage),
        },
        "mean_nees": {
            "ekf": r.ekf.score.mean_nees,
            "smoother": smoothed.and_then(|s| s.mean_nees),
        },
        "by_filter": {
            "ekf": updates(&Some(r.ekf.clone())),
            "ukf": updates(&r.ukf),
            "iekf": updates(&r.iekf),
        },
        "white_noise_ranges": r.white_noise.iter().map(|w| json!({
            "range_sd_m": w.range_sd,
            "ekf": score_json(&w.ekf),
            "smoother": score_json(&w.smoother),
            "mean_nis": w.updates.mean_nis,
            "gated_fraction": w.updates.gated_fraction(),
        })).collect::<Vec<_>>(),
        "final_biases_m": {
            "common": r.ekf.biases.first(),
            "per_beacon": r.beacons.iter().zip(r.ekf.biases.iter().skip(1))
                .map(|(b, g)| json!({ "id": b.id, "bias": g })).collect::<Vec<_>>(),
        },
        "start": {
            "x": r.start.mean[0], "y": r.start.mean[1], "heading_rad": r.start.mean[2],
            "common_bias_m": r.start.mean[3],
            "sd": ([0, 1, 2, 3].map(|i| r.start.covariance[(i, i)].sqrt())),
            "window_end_s": r.start.window_end - r.window.0,
            "readings": r.start.readings, "inflation": r.start.inflation,
            "position_error_m": r.start_error.0, "heading_error_deg": r.start_error.1,
        },
        "window_s": [r.window.0, r.window.1],
        "ranges": r.ranges,
        "ranges_reordered": r.reordered_ranges,
        "particles": r.particle.as_ref().map(|_| r.config.particles),
        "seconds_per_filter": {
            "ekf_and_smoother": r.ekf.seconds,
            "ukf": r.ukf.as_ref().map(|p| p.seconds),
            "iekf": r.iekf.as_ref().map(|p| p.seconds),
            "particle": r.particle.as_ref().map(|p| p.seconds),
        },
        "settings": {
            "distance_m_per_sqrt_m": n.distance_per_sqrt_m,
            "heading_rad_per_sqrt_m": n.heading_per_sqrt_m,
            "heading_drift_rad2_s": n.heading_drift,
            "range_sd_m": n.range_sd,
            "beacon_bias_sd_m": n.beacon_bias_sd,
            "beacon_bias_tau_s": n.beacon_bias_tau,
            "common_bias_sd_m": n.common_bias_sd,
            "common_bias_drift_m2_s": n.common_bias_drift,
            "outlier_probability": n.outlier_probability,
            "gate_probability": r.config.gate,
            "fit_distance_m": r.config.fit_distance,
        },
        "run_s": r.run_s,
    })
}

/// An error curve over time and its 3σ band.
type ErrorCurve = (Vec<(f64, f64)>, Vec<(f64, f64, f64)>);

/// A small diamond around (x, y): a beacon's marker drawn as a closed line.
fn diamond(x: f64, y: f64, s: f64) -> Vec<(f64, f64)> {
    vec![(x - s, y), (x, y + s), (x + s, y), (x, y - s), (x - s, y)]
}

fn figures(r: &PlazaResult) -> Result<Vec<PathBuf>, Box<dyn std::error::Error>> {
    let (t0, t1) = r.window;
    let xy = |track: &[Estimate]| -> Vec<(f64, f64)> {
        track.iter().step_by(2).map(|e| (e.p.x, e.p.y)).collect()
    };
    let mut series = vec![
        Series {
            label: "ground truth (GPS)",
            points: r
                .truth
                .iter()
                .filter(|g| g.t >= t0 && g.t <= t1)
                .step_by(2)
                .map(|g| (g.x, g.y))
                .collect(),
        },
        Series {
            label: "EKF + RTS smoother",
            points: r.ekf.smoothed.as_ref().map_or(Vec::new(), |s| xy(&s.0)),
        },
        Series {
            label: "dead reckoning (true start)",
            points: xy(&r.dead_reckoning.0),
        },
    ];
    let labels: Vec<String> = r
        .beacons
        .iter()
        .map(|b| format!("beacon {}", b.id))
        .collect();
    for (b, label) in r.beacons.iter().zip(&labels) {
        series.push(Series {
            label,
            points: diamond(b.x, b.y, 1.5),
        });
    }
    let trajectory = common::line_plot(
        "plaza_range_trajectory.svg",
        "plaza_range: trajectory against the ground truth, with the beacons",
        "x [m]",
        "y [m]",
        &series,
    )?;
    // Position error over time with the estimate's own 3σ (3 √tr P_pp, the 2-D error's RMS
    // bound), for the smoother and the EKF.
    let error = |track: &[Estimate]| -> ErrorCurve {
        track
            .iter()
            .step_by(5)
            .filter_map(|e| {
                let g = truth_at(&r.truth, e.t)?;
                let t = e.t - t0;
                Some((
                    (t, (e.p - g).norm()),
                    (
                        t,
                        0.0,
                        3.0 * (e.cov[(0, 0)] + e.cov[(1, 1)]).max(0.0).sqrt(),
                    ),
                ))
            })
            .unzip()
    };
    let (smoothed_error, smoothed_band) = r
        .ekf
        .smoothed
        .as_ref()
        .map_or((Vec::new(), Vec::new()), |s| error(&s.0));
    let (ekf_error, ekf_band) = error(&r.ekf.track);
    let errors = common::band_plot(
        "plaza_range_error.svg",
        "plaza_range: position error against the ground truth, with each estimate's 3 sigma",
        "time since start [s]",
        "position error [m]",
        &[
            Series {
                label: "EKF + RTS smoother",
                points: smoothed_error,
            },
            Series {
                label: "EKF",
                points: ekf_error,
            },
        ],
        &[
            Band {
                label: "smoother 3 sigma (3 sqrt tr P)",
                points: smoothed_band,
            },
            Band {
                label: "EKF 3 sigma",
                points: ekf_band,
            },
        ],
    )?;
    Ok(vec![trajectory, errors])
}

fn line(name: &str, s: &Score, extra: &str) -> String {
    let cov = s
        .coverage
        .map_or("-".to_owned(), |c| format!("{:.1} %", 100.0 * c));
    let nees = s.mean_nees.map_or("-".to_owned(), |c| format!("{c:.2}"));
    format!(
        "{name:<34} {:>7.3} {:>10} {:>9}   {extra}",
        s.rmse, cov, nees
    )
}

/// The example: runs, prints the table, writes the figures, returns the JSON.
pub fn run(config: &Config) -> Result<Output, Box<dyn std::error::Error>> {
    let r = run_config(config)?;
    println!(
        "plaza_range (estim's own extension): {} beacons, {} ranges over {:.0} s",
        r.beacons.len(),
        r.ranges,
        r.window.1 - r.window.0
    );
    println!(
        "start from the ranges (first {:.0} m driven, {:.0} s, {} readings): ({:.2}, {:.2}) m, heading {:.1} deg, common bias {:.2} m; off the ground truth by {:.2} m and {:.1} deg\n",
        r.start.fit_distance,
        r.start.window_end - r.window.0,
        r.start.readings,
        r.start.mean[0],
        r.start.mean[1],
        r.start.mean[2].to_degrees(),
        r.start.mean[3],
        r.start_error.0,
        r.start_error.1
    );
    println!(
        "{:<34} {:>7} {:>10} {:>9}   updates",
        "position vs ground truth", "RMSE m", "3σ cover", "mean NEES"
    );
    println!(
        "{}",
        line("dead reckoning (true start)", &r.dead_reckoning.1, "")
    );
    let updates = |p: &Pass| {
        p.updates.map_or(String::new(), |u| {
            format!(
                "mean NIS {:.2}, gated {:.1} %",
                u.mean_nis,
                100.0 * u.gated_fraction()
            )
        })
    };
    println!("{}", line("EKF", &r.ekf.score, &updates(&r.ekf)));
    for (name, p) in [("UKF", &r.ukf), ("iterated EKF", &r.iekf)] {
        if let Some(p) = p {
            println!("{}", line(name, &p.score, &updates(p)));
        }
    }
    if let Some(p) = &r.particle {
        println!(
            "{}",
            line(
                &format!("particle filter ({})", config.particles),
                &p.score,
                "outlier-tolerant likelihood"
            )
        );
    }
    if let Some((_, s)) = &r.ekf.smoothed {
        println!("{}", line("EKF + RTS smoother", s, ""));
    }
    for w in &r.white_noise {
        println!(
            "{}",
            line(
                &format!("white ranges σ {:.2} m: EKF", w.range_sd),
                &w.ekf,
                &format!(
                    "mean NIS {:.2}, gated {:.1} %",
                    w.updates.mean_nis,
                    100.0 * w.updates.gated_fraction()
                )
            )
        );
        println!(
            "{}",
            line(
                &format!("white ranges σ {:.2} m: smoother", w.range_sd),
                &w.smoother,
                ""
            )
        );
    }
    println!(
        "\nfinal range biases (EKF): common {:.2} m; per beacon {}",
        r.ekf.biases.first().copied().unwrap_or(0.0),
        r.beacons
            .iter()
            .zip(r.ekf.biases.iter().skip(1))
            .map(|(b, g)| format!("{}: {g:+.2}", b.id))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!("run {:.2} s", r.run_s);
    if config.figures {
        match figures(&r) {
            Ok(paths) => paths
                .iter()
                .for_each(|p| println!("figure: {}", p.display())),
            Err(e) => eprintln!("figures not written: {e}"),
        }
    }
    Ok(Output {
        json: json(&r),
        headlines: Vec::new(),
    })
}
