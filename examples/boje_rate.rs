//! Boje section 3: the rate accuracy of the accelerometer pair (eq 17–19) at R = 0.1 m,
//! Δt = 0.01 s, σ = 1.4 mg, ω = 80 °/s — eq 18's closed form, eq 17 iterated to steady state,
//! the printed eq 19 (erratum), and a Monte Carlo of the scalar EKF (estim's `Ekf` on a 1-state
//! model) at constant rate on simulated accelerometer samples.
//!
//! `cargo run --release --example boje_rate [-- --json] [-- --quick]`

use estim_reproductions::boje_rate;
use estim_reproductions::common;
use estim_reproductions::sharding;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    sharding::refuse_flags(
        "boje_rate",
        "its runs share one random stream and it sums over every (run, step), so a shard cannot give the whole run's bits",
    )?;
    let output = boje_rate::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
