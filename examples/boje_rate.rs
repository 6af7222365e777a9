//! Boje section 3: the rate accuracy of the accelerometer pair (eq 17–19) at R = 0.1 m,
//! Δt = 0.01 s, σ = 1.4 mg, ω = 80 °/s — eq 18's closed form, eq 17 iterated to steady state,
//! the printed eq 19 (erratum), and a Monte Carlo of the scalar EKF (estim's `Ekf` on a 1-state
//! model) at constant rate on simulated accelerometer samples.
//!
//! `cargo run --release --example boje_rate [-- --json] [-- --quick]`

use estim_reproductions::boje_rate;
use estim_reproductions::common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = boje_rate::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
