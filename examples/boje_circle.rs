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
//!
//! Its Monte Carlos run also in shards (`--shard I/N --out FILE`, then `--merge FILE...`,
//! optionally `--stats FILE`; see `estim_reproductions::sharding`), merged bit for bit.

use estim_reproductions::boje_circle;
use estim_reproductions::common;
use estim_reproductions::sharding::{self, Session};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = common::quick_requested();
    let session = Session::from_args("boje_circle", sharding::settings(quick))?;
    let output = boje_circle::run_in(quick, &session)?;
    session.finish()?;
    if let Some(output) = output
        && common::json_requested()
    {
        println!("{}", output.json);
    }
    Ok(())
}
