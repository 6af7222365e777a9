//! The consistency toolkit on each paper's filter: the Boje circle EKF (linear and nonlinear
//! process), the Lu calibration filter, and the Lee & Huang CKF and CKF+OTE, each a seeded Monte
//! Carlo on estim's runner; prints each verdict table and a summary line per filter.
//!
//! `--shard I/N --out FILE` runs shard I of N of its Monte Carlos and writes it to FILE;
//! `--merge FILE...` merges the N files and prints what one process prints (wall times
//! aside), bit for bit (`estim_reproductions::sharding`; the Slurm recipe is in
//! `estim::filters::monte_carlo`).
//!
//! `cargo run --release --example consistency [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

use estim_reproductions::common;
use estim_reproductions::consistency;
use estim_reproductions::sharding::{self, Session};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = common::quick_requested();
    let session = Session::from_args("consistency", sharding::settings(quick))?;
    let output = consistency::run_in(quick, &session)?;
    session.finish()?;
    if let Some(output) = output
        && common::json_requested()
    {
        println!("{}", output.json);
    }
    Ok(())
}
