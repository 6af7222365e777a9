//! Lu (UCLA MAE 271A report, 2017): accelerometer bias calibration from GPS, a 3-state
//! error-state Kalman filter (δp, δv, b) at 200 Hz with 5 Hz GPS position+velocity fixes, and
//! its Monte Carlo validation (§3.2) on estim's Monte Carlo runner
//! (`estim::filters::monte_carlo`).
//!
//! Runs 5000 realizations over 30 s (500 with `--quick`) with the consistent filter and with
//! each of the paper's printed variants, prints the four checks of the paper with the runner's
//! verdict tables, the gains and the headlines, writes figures to `target/figures/`, and with
//! `--json` prints one JSON line last (keys `t`, `filter_p_diag`, `ensemble_var_diag`,
//! `ensemble_mean_error`, `residual_corr_20_30`, `wall_s`, and `smoothed`: one realization
//! smoothed over the whole run, the bias estimate and σ of filter and smoother). `--sequential` runs the
//! realizations on the calling thread; by default they run on rayon's pool
//! (`RAYON_NUM_THREADS` sets its size), with bit-identical results.
//!
//! `--bench` runs only the consistent filter's Monte Carlo (5000 × 6000 steps, or 500 with
//! `--quick`) and prints its wall time (for BENCHMARKS.md).
//!
//! `--shard I/N --out FILE` runs shard I of N of its Monte Carlos and writes it to FILE;
//! `--merge FILE...` merges the N files and prints what one process prints (wall time aside),
//! bit for bit (`estim_reproductions::sharding`; the Slurm recipe is in
//! `estim::filters::monte_carlo`). Not with `--bench`.
//!
//! `cargo run --release --example lu_calibration [-- --json] [-- --quick] [-- --sequential] [-- --bench] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

use estim_reproductions::common;
use estim_reproductions::lu_calibration;
use estim_reproductions::sharding::{self, Mode, Session};

use lu_calibration::{Execution, MonteCarloConfig, run_monte_carlo};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let execution = if std::env::args().any(|a| a == "--sequential") {
        Execution::Sequential
    } else {
        Execution::Default
    };
    let quick = common::quick_requested();
    let session = Session::from_args("lu_calibration", sharding::settings(quick))?;
    if std::env::args().any(|a| a == "--bench") {
        if *session.mode() != Mode::Whole {
            return Err("--bench times one whole run: it does not shard".into());
        }
        let config = if common::quick_requested() {
            MonteCarloConfig::quick()
        } else {
            MonteCarloConfig::full()
        };
        let r = run_monte_carlo(&config.with_execution(execution))?;
        println!(
            "lu Monte Carlo: {} runs x {} steps, {:?} execution, wall_s {:.3}, consistent {}",
            r.config.runs,
            r.config.scenario.steps,
            execution,
            r.wall_s,
            r.verdict.consistent()
        );
        return Ok(());
    }
    let output = lu_calibration::run_in(quick, execution, &session)?;
    session.finish()?;
    if let Some(output) = output
        && common::json_requested()
    {
        println!("{}", output.json);
    }
    Ok(())
}
