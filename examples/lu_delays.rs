//! **estim's extension of Lu's problem, not in the paper**: GPS fixes 0–300 ms late, 100 σ
//! outliers and a stuck position channel, fused three ways by estim's time-aware driver
//! (latency ignored; at the time taken; delayed + gating + fault exclusion) over a Monte Carlo.
//! Prints the table (ANEES, RMS error, detection delay), writes figures to `target/figures/`,
//! and with `--json` prints one JSON line last.
//!
//! `--shard I/N --out FILE` runs shard I of N of its Monte Carlos and writes it to FILE;
//! `--merge FILE...` merges the N files and prints what one process prints (wall time aside),
//! bit for bit (`estim_reproductions::sharding`; the Slurm recipe is in
//! `estim::filters::monte_carlo`).
//!
//! `cargo run --release --example lu_delays [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

use estim_reproductions::common;
use estim_reproductions::lu_delays;
use estim_reproductions::sharding::{self, Session};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = common::quick_requested();
    let session = Session::from_args("lu_delays", sharding::settings(quick))?;
    let output = lu_delays::run_in(quick, &session)?;
    session.finish()?;
    if let Some(output) = output
        && common::json_requested()
    {
        println!("{}", output.json);
    }
    Ok(())
}
