//! What `flight_ins` prints, draws and returns as JSON.

use std::path::PathBuf;

use serde_json::{Value, json};

use super::{Config, FlightResult, Point, Windows, run_config};
use crate::common::{self, Band, Output, Series};

fn row(name: &str, w: &Windows) -> String {
    let m = w.airborne.unwrap_or(w.whole);
    let cov = m.coverage.map_or(String::from("-"), |c| {
        format!(
            "{:.0}/{:.0}/{:.0} %",
            100.0 * c[0],
            100.0 * c[1],
            100.0 * c[2]
        )
    });
    format!(
        "{name:<32} {:>6.2} {:>6.2} {:>6.2} {:>8.2} {:>8.3}   {cov}",
        m.attitude_median, m.attitude_p95, m.attitude_max, m.ne_position_rms, m.ne_velocity_rms
    )
}

fn figures(result: &FlightResult) -> Result<Vec<PathBuf>, Box<dyn std::error::Error>> {
    let ekf = &result.ekf.track;
    let every = |k: usize| move |(i, _): &(usize, &Point)| i % k == 0;
    let trajectory = common::line_plot(
        "flight_ins_trajectory.svg",
        "flight_ins: NE trajectory, EKF against EKF3 core 0",
        "east [m]",
        "north [m]",
        &[
            Series {
                label: "estim EKF",
                points: ekf
                    .iter()
                    .enumerate()
                    .filter(every(5))
                    .map(|(_, e)| (e.p.y, e.p.x))
                    .collect(),
            },
            Series {
                label: "EKF3 core 0 (XKF1)",
                points: result
                    .reference_track
                    .iter()
                    .step_by(2)
                    .map(|(_, p)| (p.y, p.x))
                    .collect(),
            },
        ],
    )?;
    // The attitude error against XKQ core 0, with the filter's 3σ of the error angle
    // (3 √tr P_θθ, the 3-axis error's RMS bound).
    let rec_errors = result.ekf_attitude_errors.clone();
    let attitude = common::band_plot(
        "flight_ins_attitude.svg",
        "flight_ins: EKF attitude error against EKF3 core 0, with the filter's 3 sigma",
        "time since boot [s]",
        "error [deg]",
        &[Series {
            label: "attitude error",
            points: rec_errors,
        }],
        &[Band {
            label: "3 sigma (3 sqrt tr P)",
            points: ekf
                .iter()
                .enumerate()
                .filter(every(5))
                .map(|(_, e)| {
                    let s = e.sd.unwrap_or([0.0; 7]);
                    (
                        e.t,
                        0.0,
                        3.0 * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
                            .sqrt()
                            .to_degrees(),
                    )
                })
                .collect(),
        }],
    )?;
    Ok(vec![trajectory, attitude])
}

/// The JSON object of a result (the `--json` line).
pub fn json(result: &FlightResult) -> Value {
    let s = &result.settings;
    json!({
        "whole": result.ekf.windows.whole.json(),
        "airborne": result.ekf.windows.airborne.map(|m| m.json()),
        "reference_spread": result.reference_spread.json(),
        "latency_ignored": result.latency_ignored.as_ref().map(|r| r.windows.json()),
        "ukf": result.ukf.as_ref().map(|r| r.windows.json()),
        "us_per_imu_sample": {
            "ekf": result.ekf.us_per_sample,
            "ukf": result.ukf.as_ref().map(|r| r.us_per_sample),
            "ekf_latency_ignored": result.latency_ignored.as_ref().map(|r| r.us_per_sample),
        },
        "rejected": { "gps_position": result.ekf.rejected.0, "gps_velocity": result.ekf.rejected.1 },
        "window_s": [result.window.0, result.window.1],
        "airborne_s": result.airborne.map(|(a, b)| [a, b]),
        "imu_samples": result.imu_samples,
        "settings": {
            "gps_delay_s": s.gps_delay, "gps_delay_source": format!("{:?}", s.gps_delay_source),
            "gyro_noise": s.gyro_noise, "accel_noise": s.accel_noise,
            "gyro_bias_walk": s.gyro_bias_walk, "accel_bias_walk": s.accel_bias_walk,
            "gps_position_sd_m": [s.pos_sd.x, s.pos_sd.y, s.pos_sd.z],
            "gps_velocity_sd_m_s": [s.vel_sd.x, s.vel_sd.y, s.vel_sd.z],
            "declination_rad": s.declination, "imu_period_s": s.imu_period, "imu_lag_s": s.imu_lag,
            "ekf3_step_s": s.ekf_step, "imu_instance": result.instances.0,
            "mag_instance": result.instances.1, "scored_against_core": result.instances.2,
            "from_parm": s.from_log,
        },
        "run_s": result.run_s,
    })
}

/// The example: runs, prints the table, writes the figures, returns the JSON.
pub fn run(config: &Config) -> Result<Output, Box<dyn std::error::Error>> {
    let result = run_config(config)?;
    let s = &result.settings;
    println!(
        "flight_ins (estim's own extension): {} samples of IMU {} at {:.0} Hz (compass {}), {:.1}-{:.1} s, airborne {}",
        result.imu_samples,
        result.instances.0,
        1.0 / s.imu_period,
        result.instances.1,
        result.window.0,
        result.window.1,
        result
            .airborne
            .map_or("never".to_owned(), |(a, b)| format!("{a:.1}-{b:.1} s")),
    );
    println!(
        "GPS latency {:.3} s ({}); from PARM: {}\n",
        s.gps_delay,
        match s.gps_delay_source {
            super::DelaySource::Flag => "--gps-delay",
            super::DelaySource::Parameter => "PARM GPS_DELAY_MS",
            super::DelaySource::Likelihood => "maximum likelihood over 0-0.3 s",
        },
        if s.from_log.is_empty() {
            "nothing (ArduPilot defaults)".to_owned()
        } else {
            s.from_log.join(", ")
        }
    );
    println!(
        "{:<32} {:>6} {:>6} {:>6} {:>8} {:>8}   3-sigma coverage att/pos/vel",
        format!("airborne (else whole) vs EKF3 c{}", result.instances.2),
        "med°",
        "p95°",
        "max°",
        "pos m",
        "vel m/s"
    );
    println!("{}", row("EKF, GPS at time taken", &result.ekf.windows));
    if let Some(u) = &result.ukf {
        println!("{}", row("UKF, GPS at time taken", &u.windows));
    }
    if let Some(l) = &result.latency_ignored {
        println!("{}", row("EKF, GPS on arrival", &l.windows));
    }
    println!(
        "{}",
        row("EKF3 core 1 (reference spread)", &result.reference_spread)
    );
    println!(
        "\nEKF {:.2} us per IMU sample (replays of the late fixes included){}{}; rejected GPS position {}, velocity {}; run {:.2} s",
        result.ekf.us_per_sample,
        result
            .latency_ignored
            .as_ref()
            .map_or(String::new(), |l| format!(
                ", {:.2} with the fixes on arrival (no replay)",
                l.us_per_sample
            )),
        result
            .ukf
            .as_ref()
            .map_or(String::new(), |u| format!(", UKF {:.2}", u.us_per_sample)),
        result.ekf.rejected.0,
        result.ekf.rejected.1,
        result.run_s
    );
    if config.figures {
        match figures(&result) {
            Ok(paths) => paths
                .iter()
                .for_each(|p| println!("figure: {}", p.display())),
            Err(e) => eprintln!("figures not written: {e}"),
        }
    }
    Ok(Output {
        json: json(&result),
        headlines: Vec::new(),
    })
}
