//! LV2 note: best estimates of x and y from redundant x, y and q = (x + y)/√2 accelerometer axes.
//!
//! Fuses the reading x̃ = 1.00, ỹ = 0.50, q̃ = 1.07 m/s² (σx = 0.010, σy = 0.012, σq = 0.008
//! m/s²) by the note's closed forms (eq 2–6), by weighted least squares and by the framework's
//! Kalman filter; tests consistency (eq 7) with a χ² threshold; fuses without each axis; then
//! runs the χ² Monte Carlo (fault-free and with a biased axis) and the saturation scenario.
//!
//! `cargo run --release --example lv2_fusion [-- --quick] [-- --json]`
//!
//! Its χ² Monte Carlo runs also in shards (`--shard I/N --out FILE`, then `--merge FILE...`,
//! optionally `--stats FILE`; see `estim_reproductions::sharding`), merged bit for bit.
//!
//! Figures: `target/figures/lv2_error_ellipses.svg` (1σ ellipses of (x̂, ŷ) with and without
//! each axis), `target/figures/lv2_chi2_cdf.svg` (Monte Carlo χ² CDF against χ²₁, fault-free
//! and with a biased x axis).

use estim_reproductions::common;
use estim_reproductions::lv2_fusion;
use estim_reproductions::sharding::{self, Session};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = common::quick_requested();
    let session = Session::from_args("lv2_fusion", sharding::settings(quick))?;
    let output = lv2_fusion::run_in(quick, &session)?;
    session.finish()?;
    if let Some(output) = output
        && common::json_requested()
    {
        println!("{}", output.json);
    }
    Ok(())
}
