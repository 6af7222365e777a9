//! The `lu_calibration` example's reproduction (`examples/reproductions/lu_calibration.rs`,
//! moved from estim-models' `lu_monte_carlo` tests with it; assertions unchanged).
//!
//! Lu §3.2 in a fast form (200 realizations instead of 5000) on the framework's Monte Carlo
//! runner: the consistent filter passes every check; each printed variant of the paper is
//! flagged by the verdict (errata E2, E3, E4, E5); the ensemble statistics agree with the exact
//! values of the covariance analysis.
//!
//! All checks are at 99 % per check (Simes over the check's single tests). For a consistent
//! filter the runner guarantees a false-alarm rate ≤ 1 % per check under the positive
//! dependence of neighbouring slots. The seed below is fixed, so the tests are deterministic;
//! every test of this file was also run with master seeds 1–40 (all passed).

use crate::lu_calibration::{MonteCarloConfig, MonteCarloResult, run_monte_carlo};
use estim_filters::consistency::Check;
use estim_models::lu::{FilterSettings, Scenario};

const RUNS: usize = 200;
const SEED: u64 = 271;

fn run(config: MonteCarloConfig) -> MonteCarloResult {
    run_monte_carlo(&config.with_runs(RUNS).with_seed(SEED)).unwrap()
}

/// The ensemble variance at every fix lies in the χ²_{N−1}/(N−1) band around the exact
/// variance of the covariance analysis (for the consistent filter that is P itself). Each band
/// is at 1 − 10⁻⁵ (the runner's exact χ² quantiles), so the 453 tests together false-alarm
/// with probability < 0.5 % (Bonferroni); at N = 200 the band is about [0.62, 1.50].
fn assert_ensemble_matches_analysis(r: &MonteCarloResult) {
    for k in 1..r.time.len() {
        let exact = r.analysis.error_covariance[k].diagonal();
        let stats = r.stats.slots[k].estimate.as_ref().unwrap();
        let (lo, hi) = stats.covariance_ratio_band(1.0 - 1e-5).unwrap();
        for i in 0..3 {
            let ratio = r.ensemble_variance[k][i] / exact[i];
            assert!(
                lo < ratio && ratio < hi,
                "{}: slot {k} component {i}: ensemble/exact = {ratio} not in [{lo}, {hi}]",
                r.config.label
            );
        }
    }
}

/// The consistent filter passes all six checks of the runner; and the paper's four checks in
/// its own terms, each bounded for its number of tests by Bonferroni at about 1 %: mean error
/// within 4.5 √(P/N) (453 t-tests: 4.3 is the 1 % Bonferroni bound; over master seeds 1–20 the
/// largest was 4.07), normalised orthogonality within 4.5/√N (1350 tests: 4.5 at 1 %; largest
/// 3.3 over seeds 1–20), residual products within 3.5 standard errors (4 tests: 0.2 %).
#[test]
fn consistent_filter_passes_every_check() {
    let r = run(MonteCarloConfig::full());
    assert!(r.verdict.consistent(), "{}", r.verdict);
    let s = r.summary();
    assert!(s.max_mean_error_sigmas.max() < 4.5, "{:?}", s);
    assert!(s.max_orthogonality_sigmas < 4.5, "{:?}", s);
    assert!(s.max_residual_z < 3.5, "{:?}", s);
    let z = r
        .residual_correlation
        .component_div(&r.residual_standard_error);
    assert!(z.abs().max() < 3.5, "{z}");
    assert_ensemble_matches_analysis(&r);
    // The filter's P is the same in every run and equals the information-form recursion.
    let p30 = r.filter_variance[r.slot_at(30.0)];
    assert!((p30[0].sqrt() - 0.0976).abs() < 2e-4, "{p30}");
    assert_eq!(r.residual_times, (20.0, 30.0));
}

/// E3: the listing's W = 0.0016 makes the filter pessimistic in δv and b: the covariance and
/// NEES checks fail (P^ave/P for b ≈ 0.49 at 30 s, far below the 200-run band [0.77, 1.27]).
#[test]
fn printed_noise_variance_fails_the_covariance_check() {
    let r = run(MonteCarloConfig::full().printed_noise());
    assert!(r.failed(Check::ErrorCovariance), "{}", r.verdict);
    assert!(r.failed(Check::Nees), "{}", r.verdict);
    let end = r.summary().covariance_ratio_end;
    assert!(end[2] < 0.65 && end[1] < 0.95, "{end}");
    assert_ensemble_matches_analysis(&r);
}

/// E2: the listing's M₀ = diag(1, 100, 0.01) (position and velocity variances swapped): the
/// δp error is 50× the filter's variance at the first fix; covariance, NEES, NIS and
/// orthogonality checks all fail.
#[test]
fn printed_prior_ordering_fails_the_checks() {
    let r = run(MonteCarloConfig::full().printed_prior());
    for check in [
        Check::ErrorCovariance,
        Check::Nees,
        Check::Nis,
        Check::Orthogonality,
    ] {
        assert!(r.failed(check), "{check}: {}", r.verdict);
    }
    assert!(r.summary().covariance_ratio_max[0] > 30.0);
    assert_ensemble_matches_analysis(&r);
}

/// E4: the printed Φ₁₃ = +Δt²/2 correlates the δp error with b̂. At the paper's bias prior
/// (σ_b = 0.1 m/s²) the exact correlation is only 0.068, which needs N ≈ 4000 runs to show
/// (the example's 5000-run Monte Carlo flags it); it scales with σ_b, so with σ_b = 1 m/s² it
/// is 0.56 and 200 runs flag it, while the derived sign passes the same scenario.
#[test]
fn printed_phi13_sign_fails_orthogonality() {
    let mut scenario = Scenario::paper();
    scenario.bias_variance = 1.0;
    let consistent = MonteCarloConfig {
        scenario,
        filter: FilterSettings::consistent(&scenario),
        ..MonteCarloConfig::full()
    };
    let printed = consistent.clone().printed_coupling();
    let r = run(printed);
    assert!(r.failed(Check::Orthogonality), "{}", r.verdict);
    let s = r.summary();
    assert!(s.exact_max_orthogonality > 0.5, "{:?}", s);
    // 200 runs: the sample correlation of 0.56 has SE ≈ (1 − ρ²)/√N ≈ 0.05.
    assert!(
        (s.max_orthogonality - s.exact_max_orthogonality).abs() < 0.2,
        "{:?}",
        s
    );
    let ok = run(consistent);
    assert!(ok.verdict.consistent(), "{}", ok.verdict);

    // At the paper's parameters the 200-run verdict cannot see it (exact 0.068 ≈ 1/√200).
    let paper = run(MonteCarloConfig::full().printed_coupling());
    let ps = paper.summary();
    assert!(
        (0.06..0.075).contains(&ps.exact_max_orthogonality),
        "{:?}",
        ps
    );
}

/// E5: with the closed-form truth of §2.1 and the Euler mechanisation, the quadrature error
/// biases δv by up to 0.03 m/s: the mean-error check fails (by tens of √(P/N)), covariances
/// are unaffected.
#[test]
fn closed_form_truth_fails_the_mean_check() {
    let r = run(MonteCarloConfig::full().exact_truth());
    assert!(r.failed(Check::MeanError), "{}", r.verdict);
    assert!(!r.failed(Check::ErrorCovariance), "{}", r.verdict);
    let s = r.summary();
    assert!(s.max_mean_error_sigmas[1] > 20.0, "{:?}", s);
    // The ensemble mean follows the exact mean of the analysis within 4.5 √(P/N).
    let n = r.config.runs as f64;
    for k in 1..r.time.len() {
        for i in 0..3 {
            let sd = (r.filter_variance[k][i] / n).sqrt();
            let d = r.mean_error[k][i] - r.analysis.mean_error[k][i];
            assert!(d.abs() < 4.5 * sd, "slot {k} [{i}]: {d} vs σ/√N {sd}");
        }
    }
}

// ---- from estim-models' `lu_models` tests (it runs the example's Monte Carlo too)

/// Invalid scenarios and settings are typed errors from every entry point, not panics.
#[test]
fn invalid_configurations_are_errors() {
    use estim_models::lu::{LuFilter, covariance_analysis, covariance_history};
    let good = Scenario::paper();
    let settings = FilterSettings::consistent(&good);
    let mut cases = Vec::new();
    let mut s = good;
    s.gps_every = 0;
    cases.push(s);
    let mut s = good;
    s.dt = 0.0;
    cases.push(s);
    let mut s = good;
    s.gps_velocity_variance = 0.0;
    cases.push(s);
    let mut s = good;
    s.bias_variance = -1.0;
    cases.push(s);
    let mut s = good;
    s.amplitude = f64::NAN;
    cases.push(s);
    for s in cases {
        assert!(s.validate().is_err());
        assert!(LuFilter::new(&s, &settings).is_err());
        assert!(covariance_history(&s, &settings, 100).is_err());
        assert!(covariance_analysis(&s, &settings).is_err());
        let mc = MonteCarloConfig {
            scenario: s,
            ..MonteCarloConfig::full().with_runs(2)
        };
        assert!(run_monte_carlo(&mc).is_err());
    }
    let mut bad = settings;
    bad.accel_noise_variance = -1.0;
    assert!(LuFilter::new(&good, &bad).is_err());
    let mut bad = settings;
    bad.initial_covariance[(0, 0)] = -1.0;
    assert!(LuFilter::new(&good, &bad).is_err());
    assert!(covariance_analysis(&good, &bad).is_err());
}

/// The smoothed calibration (one realization of the paper's 30 s run, every one of its 6000
/// accelerometer steps recorded): the bias is a random constant (the bias row of Φ is
/// (0, 0, 1) and Γ has no bias entry), so its smoothed estimate and σ are the end-of-run
/// filtered ones at every time (to rounding: 1e-12 absolute on b ≈ 0.08 and on σ ≈ 5e-4,
/// against 6000 steps of round-off of ~1e-16 each); the smoothed σ never exceeds the filtered
/// one (Pᶠ − Pˢ = G (P⁻ − Pˢ₊) Gᵀ ⪰ 0; slack 1e-12 relative for rounding); the smoother's
/// bias error stays within 4σˢ (a 6e-5 two-sided event for a consistent smoother; the seed
/// is fixed); and over the run its RMS errors are below the filter's in every component.
#[test]
fn smoothing_carries_the_final_bias_back_over_the_whole_run() {
    use crate::lu_calibration::run_smoothed_realization;
    let scenario = Scenario::paper();
    let settings = FilterSettings::consistent(&scenario);
    let z = run_smoothed_realization(&scenario, &settings, 2017).unwrap();
    let end = z.time.len() - 1;
    assert_eq!(end, scenario.steps);
    assert_eq!(z.smoothed[end], z.filtered[end]);
    let (b_end, sigma_end) = (z.filtered[end][2], z.filtered_sigma[end][2]);
    for k in 0..=end {
        assert!((z.smoothed[k][2] - b_end).abs() < 1e-12, "b at {k}");
        assert!(
            (z.smoothed_sigma[k][2] - sigma_end).abs() < 1e-12,
            "σ_b at {k}"
        );
        for i in 0..3 {
            assert!(
                z.smoothed_sigma[k][i] <= z.filtered_sigma[k][i] * (1.0 + 1e-12),
                "σ {i} at {k}: smoothed {} > filtered {}",
                z.smoothed_sigma[k][i],
                z.filtered_sigma[k][i]
            );
        }
        let normalised = (z.truth[k][2] - z.smoothed[k][2]) / z.smoothed_sigma[k][2];
        assert!(normalised.abs() < 4.0, "b error at {k}: {normalised} σ");
    }
    // The prior σ_b is 0.1 m/s²; the whole run brings it below 1e-3 at t = 0 as well.
    assert!(z.filtered_sigma[0][2] > 0.09 && z.smoothed_sigma[0][2] < 1e-3);
    let s = z.summary();
    assert!(s.bias_rms_smoothed < s.bias_rms_filtered);
    assert!(s.position_rms.1 < s.position_rms.0);
    assert!(s.velocity_rms.1 < s.velocity_rms.0);
}
