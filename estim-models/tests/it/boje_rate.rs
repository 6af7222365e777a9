//! Boje section 3 (eq 17–19): the closed forms against the Riccati recursion iterated. The
//! paper's numbers and the scalar EKF run on simulated accelerometer samples are tested with
//! the `boje_rate` example, in the estim package's tests (`tests/it/boje_examples.rs`).

use estim_models::boje::rate::{
    iterate_riccati, riccati_step, steady_state_eq18, steady_state_eq19,
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
            let (p, _, _) = iterate_riccati(p0, q, r, c, 0.0, 0.0, 20_000).unwrap();
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

/// Settings that would never stop the iteration (a NaN tolerance, an unbounded count on an
/// unobservable channel) are refused before any step: before, the trajectory grew until the
/// allocator aborted.
#[test]
fn unbounded_iteration_settings_are_refused() {
    use estim_core::{Error, Parameter};
    let refused = |result: Result<(f64, usize, Vec<f64>), Error>, expected: Parameter| {
        assert!(
            matches!(result, Err(Error::InvalidParameter { parameter, .. }) if parameter == expected),
            "{result:?}"
        );
    };
    refused(
        iterate_riccati(1.0, 1.0, 1.0, 1.0, 0.0, f64::NAN, 10),
        Parameter::Tolerance,
    );
    refused(
        iterate_riccati(1.0, 1.0, 1.0, 1.0, 0.0, -1.0, 10),
        Parameter::Tolerance,
    );
    refused(
        iterate_riccati(1.0, 1.0, 1.0, 1.0, 0.0, f64::INFINITY, 10),
        Parameter::Tolerance,
    );
    refused(
        iterate_riccati(1.0, 1.0, 1.0, 0.0, 0.0, 1e-13, usize::MAX),
        Parameter::StepCount,
    );
    // An accepted count runs to its end when nothing converges (c = 0): every step is taken.
    let (_, iterations, trace) = iterate_riccati(1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1000).unwrap();
    assert_eq!((iterations, trace.len()), (1000, 1001));
}
