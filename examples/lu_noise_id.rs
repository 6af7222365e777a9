//! Lu's accelerometer noise W from data (issue 22): realizations simulated with W = 0.0004,
//! W and the GPS noises recovered by EM and by maximum likelihood with standard errors, and the
//! likelihood ratio against the listing's W = 0.0016. 8 realizations of 600 s (1 with `--quick`);
//! `--json` prints one JSON line last.
//!
//! `cargo run --release --example lu_noise_id [-- --json] [-- --quick]`

use estim_reproductions::common;
use estim_reproductions::lu_noise_id;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let output = lu_noise_id::run(common::quick_requested())?;
    if common::json_requested() {
        println!("{}", output.json);
    }
    Ok(())
}
