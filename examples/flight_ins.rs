//! **estim's own extension (issue 38)**: the strapdown INS of `estim_models::nav` over a real
//! ArduPilot flight (an aerobatic fixed-wing, vendored in `examples/data/ardupilot-p23`), EKF and
//! UKF, GPS fused at the time each fix was taken, compared with the autopilot's own EKF3. Prints
//! the table, writes figures to `target/figures/`, and with `--json` prints one JSON line last.
//!
//! `cargo run --release --example flight_ins [-- --data DIR] [-- --gps-delay S] [-- --imu N]
//! [-- --mag N] [-- --core C] [-- --json]`
//!
//! `--data DIR`: a folder holding the log's `IMU`, `GPS`, `MAG`, `XKQ`, `XKF1` (and optionally
//! `PARM`, `ORGN`) as `<TYPE>.csv.gz`, named as in the vendored folder; `--imu N`, `--mag N`:
//! the IMU and compass instances (`I` column, default 0); `--core C`: the EKF3 core the
//! filters are scored against (0 or 1, default 0; core c runs on IMU c).

use estim_reproductions::common;
use estim_reproductions::flight_ins::{self, Config};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
    };
    let data = value("--data").map_or_else(flight_ins::vendored, Into::into);
    let mut config = Config::full(data);
    if let Some(s) = value("--gps-delay") {
        config.gps_delay = Some(s.parse()?);
    }
    if let Some(n) = value("--imu") {
        config.imu = n.parse()?;
    }
    if let Some(n) = value("--mag") {
        config.mag = n.parse()?;
    }
    if let Some(c) = value("--core") {
        config.core = c.parse()?;
    }
    let output = flight_ins::run(&config)?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
