//! Lu (UCLA MAE 271A report, 2017): accelerometer bias calibration from GPS, a 3-state
//! error-state Kalman filter (δp, δv, b) at 200 Hz with 5 Hz GPS position+velocity fixes, and
//! its Monte Carlo validation (§3.2) on estim's Monte Carlo runner
//! (`estim::filters::monte_carlo`).
//!
//! Runs 5000 realizations over 30 s (500 with `--quick`) with the consistent filter and with
//! each of the paper's printed variants, prints the four checks of the paper with the runner's
//! verdict tables, the gains and the headlines, writes figures to `target/figures/`, and with
//! `--json` prints one JSON line last (keys `t`, `filter_p_diag`, `ensemble_var_diag`,
//! `ensemble_mean_error`, `residual_corr_20_30`, `wall_s`). `--sequential` runs the
//! realizations on the calling thread; by default they run on rayon's pool
//! (`RAYON_NUM_THREADS` sets its size), with bit-identical results.
//!
//! `cargo run --release --example lu_calibration [-- --json] [-- --quick] [-- --sequential]`

mod common;

use estim::models::lu::Execution;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let execution = if std::env::args().any(|a| a == "--sequential") {
        Execution::Sequential
    } else {
        Execution::Default
    };
    let output = common::lu_calibration::run_with(common::quick_requested(), execution)?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
