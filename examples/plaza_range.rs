//! **estim's own extension (issue 38)**: range-only localisation of a ground robot over CMU's
//! Plaza run (wheel odometry and UWB ranges to four surveyed beacons, vendored in
//! `examples/data/plaza1`), with an EKF, a UKF, an iterated EKF and a particle filter, range
//! biases as Gauss-Markov states, gating of outliers and the RTS smoother, scored against the
//! GPS ground truth. Prints the table, writes figures to `target/figures/`, and with `--json`
//! prints one JSON line last.
//!
//! `cargo run --release --example plaza_range [-- --data DIR] [-- --seconds S] [-- --particles N]
//! [-- --seed N] [-- --json]`
//!
//! `--data DIR`: a folder holding `GT`, `DR`, `TD` and `TL` as `.csv` or `.csv.gz` (named as in
//! the data set); `--seconds S`: only the first S seconds; `--particles N`: the particle
//! filter's count (default 1000); `--seed N`: its random seed (default 38).

use estim_reproductions::common;
use estim_reproductions::plaza_range::{self, Config};

fn main() {
    // The error's message (naming the file and line of bad data), not its debug form.
    if let Err(e) = run() {
        eprintln!("plaza_range: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
    };
    let data = value("--data").map_or_else(plaza_range::vendored, Into::into);
    let mut config = Config::full(data);
    if let Some(s) = value("--seconds") {
        config.seconds = Some(s.parse()?);
    }
    if let Some(n) = value("--particles") {
        config.particles = n.parse()?;
    }
    if let Some(n) = value("--seed") {
        config.seed = n.parse()?;
    }
    let output = plaza_range::run(&config)?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
