//! Boje section 4: the circle example (Table 1) with the 6-state filter of eq 14–16 —
//! Monte Carlo with correct initial conditions (Fig 3), a run with wrong initial conditions
//! (Fig 2), and (beyond the paper) the same data through a process with θ inside f, run by the
//! EKF, the second-order EKF and the UKF; and every Monte Carlo run smoothed (RTS), filtered
//! vs smoothed errors.
//!
//! Reading of the scenario (see `estim::models::boje` docs): rigid arm, CG on a 10 m circle,
//! heading tangent, ω = sgn(t − t_end/2)·0.1·t rad/s, t_end = 20 s. "Settled" = t ∈ [2, 20] s.
//!
//! `cargo run --release --example boje_circle [-- --json] [-- --quick]`

use estim_reproductions::boje_circle;
use estim_reproductions::common;
use estim_reproductions::sharding;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    sharding::refuse_flags(
        "boje_circle",
        "not ported yet (its per-step sums over runs would need shard files of ~200 MB to merge bit for bit)",
    )?;
    let output = boje_circle::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
