//! The `large_state` example in its quick form (10 steps): the 200-state Kalman filter and
//! UKF are consistent and agree to round-off.

use crate::large_state::{
    MEASUREMENT_SIGMA, NODES, QUICK_STEPS, cov_diff_bound, run, state_diff_bound,
};
use estim::filters::consistency::ChiSquareBand;

fn get(v: &serde_json::Value, path: &[&str]) -> f64 {
    let mut v = v;
    for key in path {
        v = &v[*key];
    }
    v.as_f64()
        .unwrap_or_else(|| panic!("{path:?} missing or not a number"))
}

#[test]
fn large_state_quick_run_is_consistent_and_kf_matches_ukf() {
    let j = &run(true).unwrap();
    assert_eq!(get(j, &["steps"]) as usize, QUICK_STEPS);
    assert_eq!(get(j, &["nodes"]) as usize, NODES);

    // NEES. The truth starts from a draw of the prior and is driven by the model's own noises,
    // so for the Kalman filter the error after each update is exactly N(0, Pₖ) and its NEES
    // exactly χ²₂₀₀ (the UKF's P equals the KF's to ~10⁻¹¹, below). Successive NEES are
    // correlated, so no band for their average is tighter than for one value; instead a union
    // bound: with each of the 10 values inside the two-sided χ²₂₀₀ band of confidence
    // 1 − p/10, all are inside with probability ≥ 1 − p, and so is their mean. p = 10⁻³: a
    // correct filter fails this for at most 1 seed in 1000 (the seed is fixed; it passes).
    let p = 1e-3;
    let band = ChiSquareBand::two_sided(NODES, 1, 1.0 - p / QUICK_STEPS as f64).unwrap();
    for filter in ["kf", "ukf"] {
        for stat in ["nees_min", "nees_mean", "nees_max"] {
            let v = get(j, &[filter, stat]);
            assert!(
                band.contains(v),
                "{filter} {stat} = {v} outside [{}, {}]",
                band.lower,
                band.upper
            );
        }
        // The posterior std at a measured node is below σ_r = 0.1 K (that measurement alone
        // would give σ_r), and each unmeasured node lies between two measured ones on a field
        // smoothed by diffusion; the quick run's RMS is ≈ 0.04 K. Reaching σ_r would mean the
        // measurements were not used (the prior's std is 1 K).
        let rms = get(j, &[filter, "rms_error_k"]);
        assert!(
            rms.is_finite() && rms < MEASUREMENT_SIGMA,
            "{filter} RMS {rms}"
        );
        for t in ["step_ms_median", "step_ms_mean"] {
            let ms = get(j, &[filter, t]);
            assert!(ms.is_finite() && ms > 0.0, "{filter} {t} = {ms}");
        }
    }

    // KF vs UKF: exact on a linear model, so they differ by round-off, bounded by the
    // derivation of `state_diff_bound` / `cov_diff_bound` (the sigma-point rounding amplified
    // by 1/α² in the mean and 1/α in the covariance, plus both filters' kernel rounding
    // ≤ 10 n ε κ(S)), recomputed here from the run's own scales.
    let scales = (
        get(j, &["max_abs_state_k"]),
        get(j, &["max_gain_row_sum"]),
        get(j, &["max_cond_s"]),
        get(j, &["min_sigma_k"]),
    );
    let dx_bound = state_diff_bound(QUICK_STEPS, scales.0, scales.1, scales.2);
    let dp_bound = cov_diff_bound(QUICK_STEPS, scales.0, scales.1, scales.2, scales.3);
    let dx = get(j, &["max_state_diff_k"]);
    let dp = get(j, &["max_cov_rel_diff"]);
    assert!(dx <= dx_bound, "KF vs UKF state {dx:e} K > {dx_bound:e} K");
    assert!(dp <= dp_bound, "KF vs UKF covariance {dp:e} > {dp_bound:e}");
    // The RMS errors then differ by at most the largest state difference (RMS is 1-Lipschitz
    // in the max norm).
    let (rms_kf, rms_ukf) = (
        get(j, &["kf", "rms_error_k"]),
        get(j, &["ukf", "rms_error_k"]),
    );
    assert!((rms_kf - rms_ukf).abs() <= dx_bound);
}
