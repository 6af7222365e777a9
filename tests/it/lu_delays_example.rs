//! The `lu_delays` example (estim's extension of Lu's problem, not in the paper) in a small
//! form: late GPS fixes fused at the time taken are consistent, fused as current they are not;
//! with outliers and a stuck position channel, the gated, monitored driver stays consistent and
//! detects the stuck channel within the derived bound in every run.

use crate::lu_delays::{DelayConfig, DelayResult, Method, detection_bound, run_config};
use estim_filters::consistency::ChiSquareBand;

const RUNS: usize = 40;

fn small(config: DelayConfig, stuck_from: Option<f64>) -> DelayConfig {
    DelayConfig {
        scenario: config.scenario.with_duration(6.0),
        runs: RUNS,
        stuck_from: config.stuck_from.and(stuck_from),
        ..config
    }
}

fn run(config: DelayConfig) -> DelayResult {
    run_config(&config).unwrap()
}

/// Each slot's ANEES (3 states, 40 runs) in its band at 1 − 10⁻⁴: with 25 slots after 1 s the
/// family false-alarm rate is below 0.3 % (Bonferroni).
fn band() -> ChiSquareBand {
    ChiSquareBand::two_sided(3, RUNS, 1.0 - 1e-4).unwrap()
}

#[test]
fn late_fixes_at_their_time_are_consistent_and_as_current_are_not() {
    let band = band();
    let taken = run(small(DelayConfig::latency(true, Method::AtTimeTaken), None));
    for (t, a) in taken.anees() {
        assert!(
            band.contains(a),
            "at time taken: ANEES {a} at {t} s outside {band:?}"
        );
    }
    let ignored = run(small(
        DelayConfig::latency(true, Method::LatencyIgnored),
        None,
    ));
    for (t, a) in ignored.anees() {
        // A 0-300 ms latency at 100 m/s is a 0-30 m position error against a 1 m fix.
        assert!(a > 10.0 * band.upper, "latency ignored: ANEES {a} at {t} s");
    }
}

#[test]
fn gating_and_fault_exclusion_stay_consistent_and_detect_the_stuck_channel_in_time() {
    let band = band();
    let config = small(DelayConfig::faults(true, Method::Robust), Some(3.0));
    let bound = detection_bound(&config).unwrap();
    let robust = run(config);
    for (t, a) in robust.anees() {
        assert!(
            band.contains(a),
            "robust: ANEES {a} at {t} s outside {band:?}"
        );
    }
    assert_eq!(robust.detection_delay.len(), RUNS);
    for (run, d) in robust.detection_delay.iter().enumerate() {
        let d = d.unwrap_or_else(|| panic!("run {run}: the stuck channel was not detected"));
        assert!(
            d <= bound,
            "run {run}: detected after {d} s, bound {bound} s"
        );
    }
    // Without a gate the outliers and the stuck channel wreck the estimate.
    let plain = run(small(
        DelayConfig::faults(true, Method::AtTimeTaken),
        Some(3.0),
    ));
    assert!(plain.mean_rms(0) > 10.0 * robust.mean_rms(0));
}
