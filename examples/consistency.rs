//! The consistency toolkit on each paper's filter: the Boje circle EKF (linear and nonlinear
//! process), the Lu calibration filter, and the Lee & Huang CKF and CKF+OTE, each a seeded Monte
//! Carlo on estim's runner; prints each verdict table and a summary line per filter.
//!
//! `cargo run --release --example consistency [-- --json] [-- --quick]`

use estim_reproductions::common;
use estim_reproductions::consistency;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = consistency::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
