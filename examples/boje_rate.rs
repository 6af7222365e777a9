//! Boje section 3: the rate accuracy of the accelerometer pair (eq 17–19) at R = 0.1 m,
//! Δt = 0.01 s, σ = 1.4 mg, ω = 80 °/s — eq 18's closed form, eq 17 iterated to steady state,
//! the printed eq 19 (erratum), and a Monte Carlo of the scalar EKF (estim's `Ekf` on a 1-state
//! model) at constant rate on simulated accelerometer samples.
//!
//! `cargo run --release --example boje_rate [-- --json] [-- --quick]`
//!
//! Its Monte Carlo runs also in shards (`--shard I/N --out FILE`, then `--merge FILE...`,
//! optionally `--stats FILE`; see `estim_reproductions::sharding`), merged bit for bit.

use estim_reproductions::boje_rate;
use estim_reproductions::common;
use estim_reproductions::sharding::{self, Session};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = common::quick_requested();
    let session = Session::from_args("boje_rate", sharding::settings(quick))?;
    let output = boje_rate::run_in(quick, &session)?;
    session.finish()?;
    if let Some(output) = output
        && common::json_requested()
    {
        println!("{}", output.json);
    }
    Ok(())
}
