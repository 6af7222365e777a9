//! Boje section 3 (eq 17–19): the closed forms against the Riccati recursion iterated and
//! against the scalar EKF run on simulated accelerometer samples.

use estim_models::boje::RateConfig;
use estim_models::boje::rate::{
    iterate_riccati, rate_experiment, riccati_step, steady_state_eq18, steady_state_eq19,
    steady_state_eq19_printed,
};

/// Eq 18 is the fixed point of eq 17: iterating eq 17 from several p₀ converges to it
/// (relative 1e-12: the recursion contracts by ≈ 1 − k ≈ 0.97 per step, so 10⁴ iterations
/// reach round-off), for several rates and noise levels.
#[test]
fn eq18_equals_iterated_eq17() {
    for &(q, r, c) in &[(9.4e-7, 9.4e-3, 2.79), (1e-6, 1e-2, 0.5), (1e-4, 1.0, 10.0)] {
        let p18 = steady_state_eq18(q, r, c);
        assert!((riccati_step(p18, q, r, c, 0.0) - p18).abs() <= 1e-14 * p18);
        for p0 in [0.0, 1e-8, 1.0] {
            let (p, _, _) = iterate_riccati(p0, q, r, c, 0.0, 0.0, 20_000);
            assert!(
                (p - p18).abs() <= 1e-12 * p18,
                "q={q} r={r} c={c} p0={p0}: {p} vs {p18}"
            );
        }
    }
}

/// Eq 19 (first line: q = Δt²σ²/(2R²), r = σ²/(2R²)) substituted into eq 18 gives
/// Δt²σ²/(4R²)(1 + √(1 + 4/(cΔt)²)) — the corrected second line — for any parameters.
#[test]
fn eq19_corrected_equals_eq18() {
    for &(dt, sigma, rr, c) in &[
        (0.01, 0.0137, 0.1, 2.79),
        (0.005, 0.1, 0.5, 0.3),
        (0.1, 1e-3, 1.0, 20.0),
    ] {
        let q = dt * dt * sigma * sigma / (2.0 * rr * rr);
        let r = sigma * sigma / (2.0 * rr * rr);
        let p18 = steady_state_eq18(q, r, c);
        assert!((steady_state_eq19(dt, sigma, rr, c) - p18).abs() <= 1e-13 * p18);
    }
}

/// Erratum E6/E7: the printed eq 19 (1/(cΔt)² inside the root) differs from eq 18 — at the
/// paper's numbers it gives 1.735e-5 (rad/s)² = 0.2387 °/s (the paper's "0.24 °/s") against the
/// consistent 3.4224e-5 = 0.3352 °/s — and it equals eq 18 with c doubled (c = 4ω₀).
#[test]
fn eq19_as_printed_differs_from_eq18() {
    let cfg = RateConfig::paper();
    let (dt, sigma, rr, c) = (cfg.dt, cfg.sigma(), cfg.half_separation, 2.0 * cfg.rate());
    let q = dt * dt * sigma * sigma / (2.0 * rr * rr);
    let r = sigma * sigma / (2.0 * rr * rr);
    let p18 = steady_state_eq18(q, r, c);
    let printed = steady_state_eq19_printed(dt, sigma, rr, c);
    assert!((p18 - 3.42242e-5).abs() < 1e-9);
    assert!((printed - 1.73527e-5).abs() < 1e-9);
    assert!((printed.sqrt().to_degrees() - 0.24).abs() < 0.005);
    assert!((p18.sqrt().to_degrees() - 0.3352).abs() < 5e-4);
    assert!((steady_state_eq18(q, r, 2.0 * c) - printed).abs() <= 1e-13 * printed);
}

/// The section 3 experiment (quick Monte Carlo of the scalar EKF built on estim's Ekf): the
/// simulated RMS of the predicted rate error matches eq 18. Tolerance: the errors are
/// correlated over ≈ 1/k ≈ 36 steps, so 40 runs × 17 000 post-burn-in steps hold ≈ 19 000
/// independent samples and the RMS has relative standard error ≈ 1/√(2·19 000) = 0.5 %; 3 % is
/// six standard errors. The filter's own √P must equal eq 18 to 0.1 % (it is the same
/// recursion, evaluated at ω̂ instead of ω₀: c differs by ≈ 0.3/80 relative).
#[test]
fn scalar_ekf_monte_carlo_matches_eq18() {
    let r = rate_experiment(&RateConfig::quick()).unwrap();
    assert!((r.rate_std_eq18_deg_s - r.rate_std_riccati_deg_s).abs() < 1e-9);
    assert!(
        (r.rate_rms_simulated_deg_s / r.rate_std_eq18_deg_s - 1.0).abs() < 0.03,
        "{}",
        r.rate_rms_simulated_deg_s
    );
    assert!((r.rate_sqrt_p_simulated_deg_s / r.rate_std_eq18_deg_s - 1.0).abs() < 1e-3);
    // Filtered (after the θ̇² update) std: p − q.
    assert!((r.rate_rms_filtered_simulated_deg_s / r.rate_std_filtered_deg_s - 1.0).abs() < 0.03);
    // Datasheet arithmetic of section 3.
    assert!((r.full_scale_rate_deg_s - 740.0).abs() < 1.0);
    assert!((r.accel_noise_mg - 1.4).abs() < 0.05);
    assert!((r.gyro_noise_deg_s - 0.63).abs() < 0.01);
    assert!((r.noise_to_full_scale_ratio - 10.0).abs() < 0.5);
}
