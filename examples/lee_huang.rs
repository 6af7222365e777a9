//! Lee & Huang (IEEE T-AES 2002): all-accelerometer planar INS, CKF alone vs CKF + own-ship
//! trajectory estimator (OTE), section IV (30° pitch, 2 g along body x, 10 mg bias).
//!
//! Runs the CKF (the paper's Ψ Jacobian, in the linear Kalman filter) and the CKF followed by
//! the OTE (fading-memory RLS, γ = 0.95, S_p = 0.01 I, P_p(0) = I) on the same simulated
//! sensor data over several seeds, plus estim's radial-consistent second scenario and a table of
//! variant readings. Prints tables and headlines, writes figures to `target/figures/`, and with
//! `--json` prints one JSON line last. `--quick` uses 5 seeds instead of 20.
//!
//! `cargo run --release --example lee_huang [-- --json] [-- --quick]`

use estim_reproductions::common;
use estim_reproductions::lee_huang;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = lee_huang::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
