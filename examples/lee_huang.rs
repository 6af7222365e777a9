//! Lee & Huang (IEEE T-AES 2002): all-accelerometer planar INS, CKF alone vs CKF + own-ship
//! trajectory estimator (OTE), section IV (30° pitch, 2 g along body x, 10 mg bias).
//!
//! Runs the CKF (the paper's Ψ Jacobian, in the linear Kalman filter) and the CKF followed by
//! the OTE (fading-memory RLS, γ = 0.95, S_p = 0.01 I, P_p(0) = I) on the same simulated
//! sensor data over several seeds, plus estim's radial-consistent second scenario and a table of
//! variant readings. Prints tables and headlines, writes figures to `target/figures/`, and with
//! `--json` prints one JSON line last. `--quick` uses 5 seeds instead of 20.
//!
//! `--shard I/N --out FILE` runs shard I of N of every configuration's seeds and writes their
//! records to FILE; `--merge FILE...` merges the N files and prints what one process prints,
//! bit for bit; `--stats FILE` writes the RMS and √P histories exactly
//! (`estim_reproductions::sharding`).
//!
//! `cargo run --release --example lee_huang [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

use estim_reproductions::common;
use estim_reproductions::lee_huang;
use estim_reproductions::sharding::{self, Session};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = common::quick_requested();
    let session = Session::from_args("lee_huang", sharding::settings(quick))?;
    let output = lee_huang::run_in(quick, &session)?;
    session.finish()?;
    if let Some(output) = output
        && common::json_requested()
    {
        println!("{}", output.json);
    }
    Ok(())
}
