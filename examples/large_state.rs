//! A 200-state linear filter: the heat equation on a rod with 200 interior nodes, observed at
//! every other node, filtered with `KalmanFilter<f64, Dyn>` and `Ukf<f64, Dyn>` (401 sigma
//! points) from the same prior. Prints the wall time per step of each, the RMS error, the
//! NEES (≈ 200 when consistent) and the largest KF−UKF difference against its round-off bound.
//! With `--json` prints one JSON line last.
//!
//! `cargo run --release --example large_state [-- --json] [-- --quick]`

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = common::large_state::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
