//! Boje eq 12–13: the mean and covariance Λ of (ẍ, ÿ, θ̈, θ̇²) from one accelerometer sample
//! (closed forms, eq 13 corrected), checked against estim's generic propagators on eq 5 and a
//! Monte Carlo; the printed eq 13 is shown beside (λ33/λ44 swapped).
//!
//! `cargo run --release --example boje_lambda [-- --json] [-- --quick]`

use estim_reproductions::boje_lambda;
use estim_reproductions::common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = boje_lambda::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
