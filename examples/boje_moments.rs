//! Boje section 2.2: Papoulis' second-order moments (eq 7, 9) on the paper's worked examples
//! (eq 8, 10, 11) — cos θ, sin θ, x cos θ, x sin θ for independent Gaussian x and θ — computed
//! by estim's generic `SecondOrder` propagator, beside the exact Gaussian expectation and a
//! seeded Monte Carlo.
//!
//! `cargo run --release --example boje_moments [-- --json] [-- --quick]`

use estim_reproductions::boje_moments;
use estim_reproductions::common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = boje_moments::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
