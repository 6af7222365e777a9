//! The main job: reproduces the four papers in a faithful but quick form and writes a report.
//!
//! Runs every paper example (Boje: moments, λ, rate accuracy, circle; Lee & Huang; LV2; Lu),
//! and estim's own extension on two real recordings (flight_ins, plaza_range),
//! with its full configuration (about 10 s of CPU time in release for the papers, the Monte
//! Carlo runs on every core; the two recordings add about 6 s: plaza_range 4.0 s, most of it
//! its particle filter, and flight_ins 1.6 s), prints their tables, writes their figures to
//! `target/figures/`, and writes `target/figures/papers.md` (in the workspace's `target/`, or in
//! `$CARGO_TARGET_DIR` when set: `common::target_dir`): each paper's headline numbers
//! beside the paper's own claim, with the explanation wherever they differ, each example's
//! JSON, and links to the figures. Each example can also be run alone, in full:
//! `cargo run --release --example boje_circle`, etc.
//!
//! `cargo run --release --example papers [-- --json] [-- --quick]`
//!
//! `--quick` runs the smaller configurations (fewer Monte Carlo runs); `--json` prints one JSON
//! object, keyed by example name, as the last stdout line.
//!
//! Each paper example `X` is `examples/X.rs` (flags and `main`) and its reproduction (the
//! experiment, tables, figures, headlines and JSON) is `examples/reproductions/X.rs`, module `X`
//! of the `estim-reproductions` library that this file, `X.rs` and the tests share.

use estim_reproductions::boje_circle;
use estim_reproductions::boje_lambda;
use estim_reproductions::boje_moments;
use estim_reproductions::boje_rate;
use estim_reproductions::common;
use estim_reproductions::flight_ins;
use estim_reproductions::lee_huang;
use estim_reproductions::lu_calibration;
use estim_reproductions::lu_delays;
use estim_reproductions::lu_noise_id;
use estim_reproductions::lv2_fusion;
use estim_reproductions::plaza_range;

use std::fmt::Write as _;
use std::time::{Instant, SystemTime};

use common::Output;

/// An example's body: quick or full, returning its JSON and headlines.
type RunExample = fn(bool) -> Result<Output, Box<dyn std::error::Error>>;

/// A paper and the examples that reproduce it.
struct Paper {
    title: &'static str,
    citation: &'static str,
    module: &'static str,
    examples: &'static [(&'static str, RunExample)],
}

const PAPERS: &[Paper] = &[
    Paper {
        title: "Boje: planar state estimation with two two-axis accelerometers",
        citation: "E. Boje, Approximations for state estimation in a plane using two two-axis accelerometers.",
        module: "estim_models::boje",
        examples: &[
            ("boje_moments", boje_moments::run),
            ("boje_lambda", boje_lambda::run),
            ("boje_rate", boje_rate::run),
            ("boje_circle", boje_circle::run),
        ],
    },
    Paper {
        title: "Lee & Huang: all-accelerometer INS with an own-ship trajectory estimator",
        citation: "S.-C. Lee, Y.-C. Huang, Innovative estimation method with measurement likelihood for all-accelerometer type INS, IEEE T-AES 38(1), 2002.",
        module: "estim_models::lee_huang",
        examples: &[("lee_huang", lee_huang::run)],
    },
    Paper {
        title: "LV2: best estimates for X and Y given X, Y and Q",
        citation: "LV2 IMU note, Best estimates for X and Y given X, Y and Q, v1.00, 2004.",
        module: "estim_models::lv2",
        examples: &[("lv2_fusion", lv2_fusion::run)],
    },
    Paper {
        title: "Lu: calibration of an accelerometer using GPS measurements",
        citation: "J. Lu, Calibration of an accelerometer using GPS measurements (course report).",
        module: "estim_models::lu",
        examples: &[
            ("lu_calibration", lu_calibration::run),
            ("lu_noise_id", lu_noise_id::run),
            ("lu_delays", lu_delays::run), // estim's extension (latency, faults): not in the paper
        ],
    },
    Paper {
        title: "estim's own extension: two real recordings with independent references (issue 38)",
        citation: "An ArduPlane 4.3.2 aerobatic flight (the `flightdata` 0.3.10 test log p23, LGPL-3.0) against the autopilot's EKF3; CMU's Plaza range-only run (J. Djugash, S. Singh, G. Kantor, W. Zhang, ICRA 2006; as shipped with GTSAM, BSD) against its GPS ground truth. Not a paper: the targets are the issue's.",
        module: "estim_models::nav (flight_ins); estim_models::motion, augment, sensors (plaza_range)",
        examples: &[
            ("flight_ins", flight_ins_example),
            ("plaza_range", plaza_range_example),
        ],
    },
];

/// `flight_ins` for the report: the whole flight (quick: the first 30 s airborne, EKF only),
/// with the airborne targets as headlines.
fn flight_ins_example(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let mut config = flight_ins::Config::full(flight_ins::vendored());
    if quick {
        config.flight_seconds = Some(30.0);
        config.ukf = false;
    }
    let mut output = flight_ins::run(&config)?;
    let air = &output.json["airborne"];
    let number = |v: &serde_json::Value| v.as_f64().map_or("-".to_owned(), |x| format!("{x:.2}"));
    output.headlines = vec![
        common::Headline {
            quantity: "airborne attitude vs EKF3 core 0, median / p95 [deg]".into(),
            paper: "≤ 0.7 / ≤ 2.0 (issue 38's target; EKF3 core 1 vs core 0: 1.42 / 3.44)".into(),
            estim: format!(
                "{} / {}",
                number(&air["attitude_deg"]["median"]),
                number(&air["attitude_deg"]["p95"])
            ),
            note: "EKF, GPS fused at the time it was taken".into(),
        },
        common::Headline {
            quantity: "airborne NE position / velocity RMS vs EKF3 core 0".into(),
            paper: "≤ 0.8 m / ≤ 0.3 m/s (issue 38's target)".into(),
            estim: format!(
                "{} m / {} m/s",
                number(&air["ne_position_rms_m"]),
                number(&air["ne_velocity_rms_m_s"])
            ),
            note: "the same run with the GPS fused on arrival is in the JSON (`latency_ignored`)"
                .into(),
        },
    ];
    Ok(output)
}

/// `plaza_range` for the report: the whole run (quick: the first 600 s, 500 particles), with
/// the targets as headlines.
fn plaza_range_example(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let mut config = plaza_range::Config::full(plaza_range::vendored());
    if quick {
        config.seconds = Some(600.0);
        config.particles = 500;
    }
    let mut output = plaza_range::run(&config)?;
    let j = &output.json;
    let number = |v: &serde_json::Value| v.as_f64().map_or("-".to_owned(), |x| format!("{x:.2}"));
    output.headlines = vec![
        common::Headline {
            quantity: "position RMSE vs GPS: smoother; EKF / UKF / IEKF / particle; dead reckoning [m]".into(),
            paper: "smoother ≤ 1.1, below every filter (issue 38's target; a hand-built EKF + RTS: 1.25; filters 1.32; dead reckoning 1.94)".into(),
            estim: format!(
                "{}; {} / {} / {} / {}; {}",
                number(&j["rmse_m"]["smoother"]),
                number(&j["rmse_m"]["ekf"]),
                number(&j["rmse_m"]["ukf"]),
                number(&j["rmse_m"]["iekf"]),
                number(&j["rmse_m"]["particle"]),
                number(&j["rmse_m"]["dead_reckoning"])
            ),
            note: "the start from the ranges, not the ground truth; dead reckoning from the true start".into(),
        },
        common::Headline {
            quantity: "consistency: mean NIS of the ranges; 3σ coverage of the smoother".into(),
            paper: "the mean NIS explained; 3σ covering the error most of the time".into(),
            estim: format!(
                "{}; {}",
                number(&j["mean_nis"]),
                number(&j["coverage_3sigma"]["smoother"])
            ),
            note: "range errors are correlated in time: Gauss-Markov bias states per beacon; the white-noise models are in the JSON".into(),
        },
    ];
    Ok(output)
}

/// Escapes `|` so a cell stays one Markdown table cell.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let full = !common::quick_requested();
    let started = Instant::now();
    let since = SystemTime::now();
    let mut report = String::new();
    let mut all_json = serde_json::Map::new();
    writeln!(report, "# estim: the four papers, reproduced\n")?;
    writeln!(
        report,
        "Generated by `cargo run --release --example papers{}` ({} configurations). Each row sets a \
         paper's own claim beside what estim computes by *running* the model and filter; where \
         they differ, the note says why. The errata behind the notes are documented, with the \
         tests that show them, in each model module's docs (`cargo doc --open`).\n",
        if full { "" } else { " -- --quick" },
        if full { "full" } else { "quick" },
    )?;
    for paper in PAPERS {
        writeln!(
            report,
            "## {}\n\n{} Module: `{}`.\n",
            paper.title, paper.citation, paper.module
        )?;
        writeln!(
            report,
            "| example | quantity | paper | estim | note |\n|---|---|---|---|---|"
        )?;
        let mut json_lines = String::new();
        for (name, run) in paper.examples {
            println!("\n==================== {name} ====================");
            let t0 = Instant::now();
            let output = run(!full)?;
            println!("({name}: {:.1} s)", t0.elapsed().as_secs_f64());
            for h in &output.headlines {
                writeln!(
                    report,
                    "| `{name}` | {} | {} | {} | {} |",
                    cell(&h.quantity),
                    cell(&h.paper),
                    cell(&h.estim),
                    cell(&h.note)
                )?;
            }
            writeln!(json_lines, "- `{name}`: `{}`", output.json)?;
            all_json.insert((*name).to_string(), output.json);
        }
        writeln!(
            report,
            "\nJSON (as printed by each example with `--json`):\n\n{json_lines}"
        )?;
    }

    let dir = common::figure_dir();
    let mut figures: Vec<String> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok())
        .filter(|e| {
            e.path().extension().is_some_and(|x| x == "svg")
                && e.metadata()
                    .and_then(|m| m.modified())
                    .is_ok_and(|m| m >= since)
        })
        .filter_map(|e| e.file_name().into_string().ok())
        .collect();
    figures.sort();
    writeln!(report, "## Figures\n")?;
    for f in &figures {
        writeln!(report, "### {f}\n\n![{f}]({f})\n")?;
    }
    writeln!(
        report,
        "Total wall time: {:.1} s.",
        started.elapsed().as_secs_f64()
    )?;
    let path = dir.join("papers.md");
    std::fs::write(&path, report)?;
    println!(
        "\nWrote {} and {} figures in {:.1} s.",
        path.display(),
        figures.len(),
        started.elapsed().as_secs_f64()
    );
    if common::json_requested() {
        println!("{}", serde_json::Value::Object(all_json));
    }
    Ok(())
}
