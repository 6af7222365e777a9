//! Lu: derivative checks of the error-state process and the GPS measurement, the error
//! dynamics of the simulated truth (errata E4, E5, E13), the GPS schedule (E1) and the
//! simulator's noise statistics. (The invalid-configuration test, which also runs the
//! `lu_calibration` example's Monte Carlo, is in the estim package's
//! `tests/it/lu_calibration_example.rs`.)

use estim_core::derivative::{check_measurement_model, check_process_model};
use estim_core::{MeasurementModel, ProcessModel};
use estim_models::lu::{
    BiasCoupling, ErrorStateProcess, GpsMeasurement, Mechanisation, Scenario, Simulator,
    TruthIntegration, noise_input, quadrature_drive, simulate, transition_matrix,
};
use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;

// The checker's mixed error |analytic − numeric| / max(1, |numeric|): 1e-6 is its documented
// bound for correct f64 derivatives of smooth, well-scaled functions. The models are linear, so
// central differences are exact up to round-off (≈ 1e-10 relative at these magnitudes).
const TOL: f64 = 1e-6;

fn state() -> impl Strategy<Value = Vector3<f64>> {
    (-1e3f64..1e3, -100f64..100.0, -1f64..1.0).prop_map(|(a, b, c)| Vector3::new(a, b, c))
}

proptest! {
    /// Jacobian Φ and (zero) Hessians of the error-state process, both signs of Φ₁₃, any Δt.
    #[test]
    fn process_model_derivatives_pass_the_checker(
        x in state(), dt in 1e-4f64..1.0, printed: bool, w in 1e-6f64..1.0,
    ) {
        let model = ErrorStateProcess {
            accel_noise_variance: w,
            coupling: if printed { BiasCoupling::Printed } else { BiasCoupling::Derived },
        };
        let report = check_process_model(&model, &x, &(), dt).unwrap();
        prop_assert!(report.is_accurate(TOL), "{report}");
        // Q = Γ W Γᵀ exactly.
        let g = noise_input(dt);
        let q = model.process_noise(&x, &(), dt);
        prop_assert!((q - g * g.transpose() * w).abs().max() <= 1e-15 * (1.0 + q.abs().max()));
    }

    /// Jacobian H and (zero) Hessians of the GPS measurement.
    #[test]
    fn gps_measurement_derivatives_pass_the_checker(x in state(), vp in 1e-3f64..10.0, vv in 1e-5f64..1.0) {
        let gps = GpsMeasurement { position_variance: vp, velocity_variance: vv };
        let report = check_measurement_model(&gps, &x).unwrap();
        prop_assert!(report.is_accurate(TOL), "{report}");
        let r = gps.measurement_noise(&x);
        prop_assert_eq!((r[(0, 0)], r[(1, 1)], r[(0, 1)], r[(1, 0)]), (vp, vv, 0.0, 0.0));
    }
}

/// Replays one realization: the true error state δx_j against the mechanisation, the noise w_j
/// (recovered as a_c − a(t_j) − b) and the one-step residual of δx_{j+1} = Φ δx_j − Γ w_j.
fn error_dynamics_residuals(scenario: &Scenario, coupling: BiasCoupling) -> Vec<Vector3<f64>> {
    let record = simulate(scenario, 42).unwrap();
    let phi = transition_matrix(scenario.dt, coupling);
    let gamma = noise_input(scenario.dt);
    let mut mech = Mechanisation::new(scenario.position_mean, scenario.velocity_mean);
    let mut out = Vec::new();
    for (j, &a_c) in record.accelerometer.iter().enumerate() {
        let before = record.truth[j].error_state(&mech);
        let w = a_c - scenario.acceleration(j as f64 * scenario.dt) - record.truth[j].bias;
        mech.step(a_c, scenario.dt);
        let after = record.truth[j + 1].error_state(&mech);
        out.push(after - (phi * before - gamma * w));
    }
    out
}

/// E4, E13: with the truth integrated like the mechanisation (§2.4), the simulated error state
/// obeys δx_{j+1} = Φ δx_j − Γ w_j with Φ₁₃ = −Δt²/2, to round-off, at every step.
#[test]
fn euler_truth_follows_the_derived_error_dynamics() {
    let scenario = Scenario::paper();
    let worst = error_dynamics_residuals(&scenario, BiasCoupling::Derived)
        .iter()
        .map(|r| r.abs().max())
        .fold(0.0, f64::max);
    // δp reaches ~30 m and p ~3000 m: round-off of the differences p − p_c is ≈ 1e-12 m.
    assert!(worst < 1e-9, "largest one-step residual {worst:e}");
}

/// E4: the printed Φ₁₃ = +Δt²/2 leaves a residual of exactly −Δt² b in δp at every step.
#[test]
fn printed_phi13_sign_does_not_follow_the_error_dynamics() {
    let scenario = Scenario::paper();
    let b = simulate(&scenario, 42).unwrap().truth[0].bias;
    let dt2 = scenario.dt * scenario.dt;
    for r in error_dynamics_residuals(&scenario, BiasCoupling::Printed) {
        // δx_{j+1} − (Φ_printed δx_j − Γ w) = (−Δt²/2 − Δt²/2) b in the δp row.
        assert!((r[0] + dt2 * b).abs() < 1e-9, "{r}");
        assert!(r[1].abs() < 1e-9 && r[2] == 0.0, "{r}");
    }
    assert!(
        b.abs() > 1e-3,
        "seed 42 should draw a visible bias, got {b}"
    );
}

/// E5: with the closed-form truth of §2.1, the error state obeys the model plus the
/// deterministic quadrature drive d_j (exact p, v increments minus one Euler step), which is
/// what biases the filter. Its accumulated effect on δv, with no filter, is of order
/// A Δt / 2 ≈ 0.025 m/s.
#[test]
fn closed_form_truth_adds_a_quadrature_drive() {
    let scenario = Scenario::paper().with_truth(TruthIntegration::Exact);
    let residuals = error_dynamics_residuals(&scenario, BiasCoupling::Derived);
    let mut largest_drive = 0.0f64;
    let mut accumulated = Vector3::zeros();
    let mut largest_accumulated = 0.0f64;
    for (j, r) in residuals.iter().enumerate() {
        let d = quadrature_drive(&scenario, j);
        // p reaches ~3000 m: the closed-form evaluation rounds at ≈ 1e-12 m.
        assert!(
            (r - d).abs().max() < 1e-9,
            "step {j}: residual {r}, drive {d}"
        );
        largest_drive = largest_drive.max(d.abs().max());
        accumulated += d;
        largest_accumulated = largest_accumulated.max(accumulated[1].abs());
    }
    // Per step: v error A 2πf Δt²/2 cos ≤ 7.9e-6 m/s.
    let w = 2.0 * std::f64::consts::PI * scenario.frequency;
    assert!(largest_drive <= scenario.amplitude * w * scenario.dt.powi(2) / 2.0 * 1.001);
    // Summed drive on δv: the Euler sum of a sin minus its integral, ≤ A Δt (and ≈ A Δt / 2).
    assert!(
        largest_accumulated > 0.2 * scenario.amplitude * scenario.dt
            && largest_accumulated <= scenario.amplitude * scenario.dt,
        "{largest_accumulated}"
    );
}

/// E1: GPS fixes every 40 Δt = 0.2 s (5 Hz): 150 fixes in 30 s, the first at 0.2 s.
#[test]
fn gps_fixes_every_0_2_s() {
    let scenario = Scenario::paper();
    assert_eq!(scenario.gps_every as f64 * scenario.dt, 0.2);
    let record = simulate(&scenario, 1).unwrap();
    assert_eq!(record.gps.len(), 150);
    assert_eq!(scenario.updates(), 150);
    for (i, (step, _)) in record.gps.iter().enumerate() {
        assert_eq!(*step, 40 * (i + 1));
    }
    assert!((scenario.update_time(1) - 0.2).abs() < 1e-12);
    assert!((scenario.update_time(150) - 30.0).abs() < 1e-9);
    assert_eq!(scenario.update_index(20.0), 100);
}

/// The simulator's noises and priors have the paper's statistics (sample moments over runs).
#[test]
fn simulator_noise_statistics() {
    let scenario = Scenario::paper().with_duration(2.0);
    let runs = 2000;
    let (mut p0, mut v0, mut b) = (Vec::new(), Vec::new(), Vec::new());
    let (mut w, mut ep, mut ev) = (Vec::new(), Vec::new(), Vec::new());
    for seed in 0..runs {
        let mut sim = Simulator::new(&scenario, seed);
        let t0 = sim.truth();
        p0.push(t0.position);
        v0.push(t0.velocity);
        b.push(t0.bias);
        for j in 0..scenario.steps {
            let a_c = sim.accelerometer();
            w.push(a_c - scenario.acceleration(j as f64 * scenario.dt) - t0.bias);
            if sim.gps_due() {
                let z = sim.gps();
                let t = sim.truth();
                ep.push(z[0] - t.position);
                ev.push(z[1] - t.velocity);
            }
        }
    }
    let moments = |x: &[f64]| {
        let n = x.len() as f64;
        let m = x.iter().sum::<f64>() / n;
        (
            m,
            x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0),
            n,
        )
    };
    // Each sample variance s² of n Gaussians has relative SE √(2/n); the tolerance is 5 SE
    // (n = 2000: 16 %; n = 800 000: 0.8 %), the mean |m| < 5 σ/√n.
    for (x, mean, var) in [
        (&p0, 0.0, 100.0),
        (&v0, 100.0, 1.0),
        (&b, 0.0, 0.01),
        (&w, 0.0, 0.0004),
        (&ep, 0.0, 1.0),
        (&ev, 0.0, 0.0016),
    ] {
        let (m, s2, n) = moments(x);
        assert!(
            (m - mean).abs() < 5.0 * (var / n).sqrt(),
            "mean {m} vs {mean}"
        );
        assert!(
            (s2 / var - 1.0).abs() < 5.0 * (2.0 / n).sqrt(),
            "variance {s2} vs {var} (n = {n})"
        );
    }
    // The bias is constant within a run.
    let mut sim = Simulator::new(&scenario, 3);
    let b0 = sim.truth().bias;
    for _ in 0..100 {
        sim.accelerometer();
    }
    assert_eq!(sim.truth().bias, b0);
}

/// The stored simulation draws the same numbers as the step-by-step simulator, and the truth
/// matches the closed form to the Euler quadrature error.
#[test]
fn stored_simulation_matches_the_step_by_step_simulator() {
    let scenario = Scenario::paper();
    let record = simulate(&scenario, 7).unwrap();
    let mut sim = Simulator::new(&scenario, 7);
    let mut fixes = record.gps.iter();
    for j in 0..scenario.steps {
        assert_eq!(sim.accelerometer(), record.accelerometer[j]);
        assert_eq!(sim.truth(), record.truth[j + 1]);
        if sim.gps_due() {
            assert_eq!(Some(&(sim.step_index(), sim.gps())), fixes.next());
        }
    }
    let t0 = record.truth[0];
    let last = record.truth[scenario.steps];
    let (p, v) = scenario.exact_position_velocity(t0.position, t0.velocity, 30.0);
    // Euler (with the Δt²/2 term) vs exact: velocity error ≤ A Δt, position ≤ A Δt · 30 s.
    assert!((last.velocity - v).abs() <= scenario.amplitude * scenario.dt);
    assert!((last.position - p).abs() <= scenario.amplitude * scenario.dt * 30.0);
    // Φ at the paper's Δt, for the record.
    let phi = transition_matrix(0.005, BiasCoupling::Derived);
    let expected = Matrix3::new(1.0, 0.005, -1.25e-5, 0.0, 1.0, -0.005, 0.0, 0.0, 1.0);
    assert!((phi - expected).abs().max() < 1e-18);
}
