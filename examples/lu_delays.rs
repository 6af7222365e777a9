//! **estim's extension of Lu's problem, not in the paper**: GPS fixes 0–300 ms late, 100 σ
//! outliers and a stuck position channel, fused three ways by estim's time-aware driver
//! (latency ignored; at the time taken; delayed + gating + fault exclusion) over a Monte Carlo.
//! Prints the table (ANEES, RMS error, detection delay), writes figures to `target/figures/`,
//! and with `--json` prints one JSON line last.
//!
//! `cargo run --release --example lu_delays [-- --json] [-- --quick]`

use estim_reproductions::common;
use estim_reproductions::lu_delays;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = lu_delays::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
