//! Boje section 4: the circle example (Table 1) with the 6-state filter of eq 14–16 —
//! Monte Carlo with correct initial conditions (Fig 3), a run with wrong initial conditions
//! (Fig 2), and (beyond the paper) the same data through a process with θ inside f, run by the
//! EKF, the second-order EKF and the UKF.
//!
//! Reading of the scenario (see `estim::models::boje` docs): rigid arm, CG on a 10 m circle,
//! heading tangent, ω = sgn(t − t_end/2)·0.1·t rad/s, t_end = 20 s. "Settled" = t ∈ [2, 20] s.
//!
//! `cargo run --release --example boje_circle [-- --json] [-- --quick]`

use super::{Output, Series, line_plot};
use estim::models::boje::filter::{HEADING, VX, X, Y};
use estim::models::boje::{CircleConfig, FilterTrace, circle_experiment, circle_variants};

const NAMES: [&str; 6] = ["vx m/s", "vy m/s", "rate rad/s", "x m", "y m", "theta rad"];

fn plot_band(
    file: &str,
    title: &str,
    unit: &str,
    trace: &FilterTrace,
    rms: Option<&[f64]>,
    comps: &[(usize, &str)],
) {
    let t = &trace.times;
    let mut series = Vec::new();
    let mut labels = Vec::new();
    for (_, name) in comps {
        labels.push(format!("error {name}"));
        labels.push(format!("+√P {name}"));
        labels.push(format!("−√P {name}"));
    }
    for (k, (j, _)) in comps.iter().enumerate() {
        series.push(Series {
            label: &labels[3 * k],
            points: t
                .iter()
                .zip(&trace.errors)
                .map(|(t, e)| (*t, e[*j]))
                .collect(),
        });
        series.push(Series {
            label: &labels[3 * k + 1],
            points: t
                .iter()
                .zip(&trace.sqrt_p)
                .map(|(t, s)| (*t, s[*j]))
                .collect(),
        });
        series.push(Series {
            label: &labels[3 * k + 2],
            points: t
                .iter()
                .zip(&trace.sqrt_p)
                .map(|(t, s)| (*t, -s[*j]))
                .collect(),
        });
    }
    if let Some(rms) = rms {
        series.push(Series {
            label: "Monte Carlo RMS",
            points: t.iter().copied().zip(rms.iter().copied()).collect(),
        });
    }
    match line_plot(file, title, "t (s)", unit, &series) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let config = if quick {
        CircleConfig::quick()
    } else {
        CircleConfig::paper()
    };
    let r = circle_experiment(&config)?;
    let mc = &r.monte_carlo;
    println!(
        "Boje section 4: R = {} m, circle {} m, t_end = {} s, h = {} s, σ_a = {} m/s², σ_xy = {} m, σ_θ = {} rad, fixes every {} s",
        config.half_separation,
        config.circle_radius,
        config.t_end,
        config.dt,
        config.sigma_accel,
        config.sigma_xy,
        config.sigma_theta,
        config.fix_period
    );
    println!(
        "{} Monte Carlo runs, {:?} filter, {:?} process, correct ICs (x̂₀ − x₀ ~ N(0, P₀)); settled part t ∈ [{}, {}] s",
        mc.runs, mc.filter, mc.process, config.settle_time, config.t_end
    );
    println!(
        "{:<12} {:>12} {:>12} {:>8} {:>14}",
        "state", "mean √P", "RMS error", "ratio", "ratio 2nd half"
    );
    let (ratio, ratio2) = (mc.settled.ratio(), mc.second_half.ratio());
    for j in 0..6 {
        println!(
            "{:<12} {:>12.5} {:>12.5} {:>8.3} {:>14.3}",
            NAMES[j], mc.settled.sqrt_p[j], mc.settled.rms[j], ratio[j], ratio2[j]
        );
    }
    println!(
        "mean NIS: θ̇² {:.3} (1 expected), GPS/compass {:.3} (3 expected); truth stays within {:.3} m of the circle",
        mc.mean_rate_nis, mc.mean_fix_nis, r.truth_circle_deviation_m
    );
    println!();
    println!("{:<26} | {:<14} | estim", "headline", "paper");
    for h in r.headlines() {
        println!("{:<26} | {:<14} | {}", h.quantity, h.paper, h.estim);
        if !h.note.is_empty() {
            println!("{:<26}   note: {}", "", h.note);
        }
    }
    let w = &r.wrong_ic_run;
    println!();
    println!(
        "wrong ICs (Fig 2), x̂₀ = x₀ + (1, −1, 0.5, 5, −5, 0.5), P₀ = diag(1, 1, 1, 25, 25, 1):"
    );
    println!(
        "{:>6} {:>12} {:>10} {:>12} {:>10}",
        "t s", "|pos err| m", "√P_xx m", "θ err rad", "√P_θθ rad"
    );
    for t in [0.0, 0.99, 1.01, 2.0, 5.0, 10.0, 20.0] {
        if let Some(i) = w.times.iter().position(|s| (s - t).abs() < 1e-9) {
            let e = &w.errors[i];
            println!(
                "{:>6.2} {:>12.4} {:>10.4} {:>12.5} {:>10.5}",
                t,
                e[X].hypot(e[Y]),
                w.sqrt_p[i][X],
                e[HEADING],
                w.sqrt_p[i][HEADING]
            );
        }
    }

    // Stretch: θ inside f.
    let variants = circle_variants(&config)?;
    println!();
    println!(
        "same data, {} runs each: settled rms/√P (velocity ratios ≈ 1 mean consistent)",
        config.runs
    );
    println!(
        "{:<10} {:<15} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>10} {:>10} {:>10}",
        "process", "filter", "vx", "vy", "rate", "x", "y", "theta", "√P pos", "√P θ", "√P vel"
    );
    for s in &variants {
        let q = s.settled.ratio();
        println!(
            "{:<10} {:<15} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>10.4} {:>10.5} {:>10.4}",
            format!("{:?}", s.process),
            format!("{:?}", s.filter),
            q[0],
            q[1],
            q[2],
            q[3],
            q[4],
            q[5],
            s.settled.position_sqrt_p(),
            s.settled.sqrt_p[HEADING],
            s.settled.velocity_sqrt_p()
        );
    }

    let col = |v: &[estim::nalgebra::Vector6<f64>], j: usize| {
        v.iter().map(|x| x[j]).collect::<Vec<f64>>()
    };
    let ex = &r.example_run;
    plot_band(
        "boje_circle_position.svg",
        "Boje Fig 3: position error, run 1, ±√P, Monte Carlo RMS (x)",
        "m",
        ex,
        Some(&col(&mc.rms_over_time, X)),
        &[(X, "x"), (Y, "y")],
    );
    plot_band(
        "boje_circle_heading.svg",
        "Boje Fig 3: heading error, run 1, ±√P, Monte Carlo RMS",
        "rad",
        ex,
        Some(&col(&mc.rms_over_time, HEADING)),
        &[(HEADING, "θ")],
    );
    plot_band(
        "boje_circle_velocity.svg",
        "Boje Fig 3: velocity error (ẋ), run 1, ±√P, Monte Carlo RMS",
        "m/s",
        ex,
        Some(&col(&mc.rms_over_time, VX)),
        &[(VX, "ẋ")],
    );
    plot_band(
        "boje_circle_wrong_ic_position.svg",
        "Boje Fig 2: wrong ICs, position error ±√P",
        "m",
        w,
        None,
        &[(X, "x"), (Y, "y")],
    );
    plot_band(
        "boje_circle_wrong_ic_heading.svg",
        "Boje Fig 2: wrong ICs, heading error ±√P",
        "rad",
        w,
        None,
        &[(HEADING, "θ")],
    );
    plot_band(
        "boje_circle_wrong_ic_velocity.svg",
        "Boje Fig 2: wrong ICs, velocity error ±√P",
        "m/s",
        w,
        None,
        &[(VX, "ẋ")],
    );
    if let (Some(lin), Some(non)) = (variants.first(), variants.get(2)) {
        let t = &r.example_run.times;
        let pts = |v: &[estim::nalgebra::Vector6<f64>]| {
            t.iter()
                .copied()
                .zip(v.iter().map(|x| x[VX]))
                .collect::<Vec<_>>()
        };
        match line_plot(
            "boje_circle_velocity_models.svg",
            "ẋ: Monte Carlo RMS vs mean √P, paper's process vs θ inside f (EKF)",
            "t (s)",
            "m/s",
            &[
                Series {
                    label: "RMS, paper process",
                    points: pts(&lin.rms_over_time),
                },
                Series {
                    label: "√P, paper process",
                    points: pts(&lin.sqrt_p_over_time),
                },
                Series {
                    label: "RMS, θ in f",
                    points: pts(&non.rms_over_time),
                },
                Series {
                    label: "√P, θ in f",
                    points: pts(&non.sqrt_p_over_time),
                },
            ],
        ) {
            Ok(p) => println!("figure: {}", p.display()),
            Err(e) => eprintln!("figure failed: {e}"),
        }
    }
    let json = {
        serde_json::json!({
            "pos_sqrt_p_m": r.pos_sqrt_p_m,
            "pos_rms_m": r.pos_rms_m,
            "heading_sqrt_p_rad": r.heading_sqrt_p_rad,
            "heading_rms_rad": r.heading_rms_rad,
            "vel_sqrt_p_m_s": r.vel_sqrt_p_m_s,
            "vel_rms_m_s": r.vel_rms_m_s,
        })
    };
    let headlines = r.headlines();
    Ok(Output { json, headlines })
}
