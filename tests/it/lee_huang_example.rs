//! The `lee_huang` example's reproduction (`examples/reproductions/lee_huang.rs`): section IV
//! in a fast form, assertions on what the honest run shows (moved from estim-models'
//! `lee_huang_section_iv` tests), and the OTE's least-squares equivalence on the section IV
//! pseudo-measurements (moved from `lee_huang_ote`). Assertions unchanged.
//!
//! Statistics are RMS over 20 seeds (a 20 s run with two filters costs ≈ 0.1 s). Each tolerance
//! says where it sits against the values observed over 10 disjoint 20-seed sets (seeds 2002 to
//! 2201; 5-seed tests: 10 disjoint 5-seed sets), so a change of seeds does not flip it.

use crate::lee_huang::{
    CkfJacobian, LeeHuangConfig, SectionIvConfig, SectionIvResult, headlines,
    position_growth_exponent, run_experiment as run, run_section_iv,
};
use estim_core::{Gaussian, LinearMeasurement};
use estim_filters::{Estimator, FadingMemoryRls, KalmanFilter, Predict, Update};
use estim_models::lee_huang::{
    AttitudeMeasurement, CkfInput, Discretization, FourAccelerometers, InsProcess, LikelihoodForm,
    OwnShipTrajectoryEstimator, Plane, SensorConfig, simulate,
};
use nalgebra::{Matrix2, Matrix3, U2, Vector1, Vector2, Vector3};

fn axes() -> (Vector2<f64>, Vector2<f64>) {
    let (s, c) = 30f64.to_radians().sin_cos();
    (Vector2::new(c, s), Vector2::new(-s, c))
}

fn last(r: &SectionIvResult) -> usize {
    r.ckf.time.len() - 1
}

/// Without noise, the CKF position error is exactly the dead-reckoned bias: ½ R(θ) b t² at
/// every recorded time (θ is estimated exactly, and x, y, v are unobservable, so nothing
/// corrects them). σ_ε = 1e-12 rad rather than 0 keeps the innovation covariance positive
/// (with R = 0 two updates make P_θθ = P_ωω = 0); its effect on position, 2 g · 1e-12 · t²/2,
/// is < 1e-8 m. Tolerance 1e-6 m on errors of up to 28 m: round-off of 2000 steps.
#[test]
fn bias_alone_gives_half_b_t_squared() {
    let mut config = SectionIvConfig::paper().with_seeds(1);
    config.input_noise_std = Vector3::zeros();
    config.attitude_std = 1e-12;
    let r = run_section_iv(&config).unwrap();
    for (i, drift) in r.bias_drift.iter().enumerate() {
        let err = r.ckf.position_mean[i];
        assert!(
            (err - drift).norm() < 1e-6,
            "t = {}: {err} vs {drift}",
            r.ckf.time[i]
        );
    }
    let end = r.bias_drift[last(&r)].norm();
    // ½ · √2 · 0.0980665 · 20² = 27.74 m
    assert!((end - 27.74).abs() < 0.01, "{end}");
}

/// The paper's CKF diverges (Figs 5–6 reproduced): position error grows without bound, faster
/// than linearly, and far outside the filter's own √P (the CKF does not know the bias and drops
/// the θ → v coupling). Observed: final RMS 83–121 m, growth exponent over 10–20 s 2.2–2.8
/// (between t² for a constant error source and t³; the attitude-error part grows faster than
/// the bias part), RMS/σ ≥ 9.
#[test]
fn ckf_position_error_is_unbounded_and_inconsistent() {
    let r = run_section_iv(&SectionIvConfig::paper()).unwrap();
    let h = &r.ckf;
    let end = last(&r);
    assert!(h.position_rms[end] > 40.0, "{}", h.position_rms[end]);
    let k = position_growth_exponent(h, 20.0);
    assert!((1.3..3.2).contains(&k), "growth exponent {k}");
    for t in [5.0, 10.0, 15.0] {
        assert!(h.position_rms[h.index_at(t)] < h.position_rms[h.index_at(t + 5.0)]);
    }
    assert!(h.position_rms[end] > 3.0 * h.position_sigma[end]);
}

/// With an accurate attitude sensor the bias dominates and the CKF error follows the
/// unobservability analysis: ∝ t² (exponent 2 ± 0.1; observed 1.99–2.02), with a mean equal to
/// ½ R(θ) b t² (along-track within 2 %, observed 0.1 %; cross-track, which also carries the
/// attitude-noise part, within 10 %, observed 3.2 %).
#[test]
fn ckf_error_grows_as_t_squared_when_bias_dominates() {
    let r = run_section_iv(&SectionIvConfig::radial()).unwrap();
    let k = position_growth_exponent(&r.ckf, 20.0);
    assert!((k - 2.0).abs() < 0.1, "{k}");
    let (u, n) = axes();
    let end = last(&r);
    let half_bt2 = 0.5 * 0.0980665 * 400.0;
    let mean = r.ckf.position_mean[end];
    assert!(
        (mean.dot(&u) / half_bt2 - 1.0).abs() < 0.02,
        "along {}",
        mean.dot(&u)
    );
    assert!(
        (mean.dot(&n) / half_bt2 - 1.0).abs() < 0.10,
        "cross {}",
        mean.dot(&n)
    );
}

/// θ and ω are estimated within their √P bands (Figs 9–10, "satisfactory"), and identically
/// with and without the OTE (with Ψ the (θ, ω) block never sees the velocity). The mean of
/// (RMS/σ)² over 5–20 s must lie in [0.5, 1.5]: the CKF starts at the true state, so errors sit
/// somewhat inside √P (observed 0.77–1.15 for θ, 0.73–0.99 for ω).
#[test]
fn attitude_and_rate_within_sqrt_p_bands() {
    let r = run_section_iv(&SectionIvConfig::paper()).unwrap();
    let h = &r.ckf;
    let (i0, i1) = (h.index_at(5.0), h.index_at(20.0));
    let ratio = |rms: &[f64], sigma: &[f64]| {
        (i0..=i1).map(|i| (rms[i] / sigma[i]).powi(2)).sum::<f64>() / (i1 - i0 + 1) as f64
    };
    let th = ratio(&h.attitude_rms, &h.attitude_sigma);
    let w = ratio(&h.rate_rms, &h.rate_sigma);
    assert!((0.5..1.5).contains(&th), "theta {th}");
    assert!((0.5..1.5).contains(&w), "omega {w}");
    for i in 0..h.time.len() {
        assert!((h.attitude_rms[i] - r.ckf_ote.attitude_rms[i]).abs() < 1e-12);
        assert!((h.rate_rms[i] - r.ckf_ote.rate_rms[i]).abs() < 1e-12);
    }
    // ≈ 2-3 deg and ≈ 0.2-0.6 deg/s: "satisfactory" only relative to σ_ε = 57 deg.
    assert!(h.attitude_rms[i1].to_degrees() < 5.0);
}

/// Erratum E10: with the paper's initial conditions the OTE does not converge within 5 s; it
/// makes the position error larger (observed ratio 2.0–2.9 at 20 s; > 1.5 asserted), already at
/// 5 s (7.7–13 m vs 2.3–3.1 m), and for γ = 0.99 as well (1.7–2.4; > 1.3 asserted). With only
/// 5 seeds the ratio scatters more (1.35 for seeds 2002–2006), hence 20 here.
#[test]
fn ote_makes_position_worse_with_paper_initial_conditions() {
    let r = run_section_iv(&SectionIvConfig::paper()).unwrap();
    let end = last(&r);
    assert!(r.ckf_ote.position_rms[end] > 1.5 * r.ckf.position_rms[end]);
    let i5 = r.ckf.index_at(5.0);
    assert!(r.ckf_ote.position_rms[i5] > r.ckf.position_rms[i5]);
    assert!(r.ckf_ote.velocity_rms[end] > r.ckf.velocity_rms[end]);

    let mut c = SectionIvConfig::paper();
    c.ote.forgetting = 0.99;
    c.ote.initial_covariance = c.ote.weight;
    let r99 = run_section_iv(&c).unwrap();
    assert!(r99.ckf_ote.position_rms[end] > 1.3 * r99.ckf.position_rms[end]);
    // In steady state the OTE gain is (1 − γ) I; the approach is geometric with ratio γ, so
    // after 2000 cycles the residual is ≈ γ²⁰⁰⁰: 3e-45 for 0.95, 2e-9 for 0.99.
    assert!((r.ote_final_gain[(0, 0)] - 0.05).abs() < 1e-12);
    assert!((r99.ote_final_gain[(0, 0)] - 0.01).abs() < 1e-8);
}

/// estim's second scenario (radial ICs, σ_ε = 0.01 rad — not the paper's): the OTE removes
/// most of the mean cross-track drift (|cross| < 0.5 · ½ b t²; observed −0.09 to 0.35) but not
/// the along-track ½ b t² (within 5 %, observed −1.2 to −1.9 %), so the final position error
/// drops (observed ratio 0.78–0.87; < 0.95 asserted); meanwhile its velocity error exceeds the
/// CKF's because d·ω̂ scales rate noise by the range (observed ×1.5–2.1; > 1.2 asserted).
#[test]
fn ote_removes_cross_track_drift_in_radial_scenario() {
    let r = run_section_iv(&SectionIvConfig::radial()).unwrap();
    let end = last(&r);
    let (u, n) = axes();
    let half_bt2 = 0.5 * 0.0980665 * 400.0;
    let mean = r.ckf_ote.position_mean[end];
    assert!(
        mean.dot(&n).abs() < 0.5 * half_bt2,
        "cross {}",
        mean.dot(&n)
    );
    assert!(
        (mean.dot(&u) / half_bt2 - 1.0).abs() < 0.05,
        "along {}",
        mean.dot(&u)
    );
    assert!(r.ckf_ote.position_rms[end] < 0.95 * r.ckf.position_rms[end]);
    assert!(r.ckf_ote.velocity_rms[end] > 1.2 * r.ckf.velocity_rms[end]);
}

/// Erratum E4: gravity, modelled in truth and filter alike, is a known input and cancels in the
/// error dynamics: the CKF errors are the same in the horizontal and the vertical plane (to
/// round-off; 1e-6 relative). Only the OTE differs: in the vertical plane the flight is level
/// while the body is pitched 30°, and the radial-flight pseudo-measurement is far off
/// (observed ×5.7–11 the horizontal OTE error; > 3 asserted).
#[test]
fn gravity_does_not_change_ckf_errors() {
    let horizontal = run_section_iv(&SectionIvConfig::paper().with_seeds(5)).unwrap();
    let mut c = SectionIvConfig::paper().with_seeds(5);
    c.scenario.plane = Plane::Vertical;
    let vertical = run_section_iv(&c).unwrap();
    for i in 0..horizontal.ckf.time.len() {
        let (a, b) = (horizontal.ckf.position_rms[i], vertical.ckf.position_rms[i]);
        assert!(
            (a - b).abs() <= 1e-6 * (1.0 + a),
            "t = {}",
            horizontal.ckf.time[i]
        );
        assert!((horizontal.ckf.velocity_rms[i] - vertical.ckf.velocity_rms[i]).abs() < 1e-6);
    }
    let end = last(&horizontal);
    assert!(vertical.ckf_ote.position_rms[end] > 3.0 * horizontal.ckf_ote.position_rms[end]);
}

/// Erratum E2 in the run: the OTE fed by eq 38/39 as printed drives the position error to
/// kilometres (observed 1.89–1.96 km at 20 s, ×6.2–12.8 the eq 27/28 OTE; > 5 × asserted).
#[test]
fn printed_eq38_39_likelihood_diverges() {
    let consistent = run_section_iv(&SectionIvConfig::paper().with_seeds(5)).unwrap();
    let mut c = SectionIvConfig::paper().with_seeds(5);
    c.ote.likelihood = LikelihoodForm::AsPrinted;
    let printed = run_section_iv(&c).unwrap();
    let end = last(&consistent);
    assert!(printed.ckf_ote.position_rms[end] > 5.0 * consistent.ckf_ote.position_rms[end]);
    assert!(printed.ckf_ote.position_rms[end] > 500.0);
}

/// Keeping the θ → velocity coupling (the EKF over the full model) lets the attitude
/// measurement correct part of the velocity error that attitude errors cause: the position
/// error drops (observed ratio 0.52–0.78; < 0.9 asserted).
#[test]
fn full_jacobian_ekf_reduces_attitude_induced_drift() {
    let paper = run_section_iv(&SectionIvConfig::paper()).unwrap();
    let mut c = SectionIvConfig::paper();
    c.jacobian = CkfJacobian::Full;
    let full = run_section_iv(&c).unwrap();
    let end = last(&paper);
    assert!(full.ckf.position_rms[end] < 0.9 * paper.ckf.position_rms[end]);
}

/// The example's computation in its quick form: every configuration runs, the steady state is
/// the closed form, and every headline carries both the paper's claim and a finite estim value.
#[test]
fn quick_experiment_runs_and_headlines_are_complete() {
    let r = run(&LeeHuangConfig::quick()).unwrap();
    assert_eq!(r.variants.len(), 2 + LeeHuangConfig::quick().variants.len());
    assert!((r.steady_state.gain[(0, 0)] - 0.05).abs() < 1e-12);
    assert!((r.steady_state.covariance[(0, 0)] - 5e-4).abs() < 1e-15);
    let h = headlines(&r);
    assert_eq!(h.len(), 7);
    for line in &h {
        assert!(!line.quantity.is_empty() && !line.paper.is_empty() && !line.estim.is_empty());
        assert!(!line.estim.contains("NaN"), "{line:?}");
    }
    for v in &r.variants {
        assert!(v.ckf_final_position_rms.is_finite() && v.ckf_ote_final_position_rms.is_finite());
    }
}

// ---- the OTE on section IV pseudo-measurements (from estim-models' `lee_huang_ote` tests)

fn inv(m: &Matrix2<f64>) -> Matrix2<f64> {
    m.try_inverse().expect("invertible in these tests")
}

/// The pseudo-measurements Z_p = g(D̂) of a section IV CKF+OTE run (first seed, 5 s).
fn section_iv_pseudo_measurements() -> Vec<Vector2<f64>> {
    let config = SectionIvConfig::paper();
    let steps = 500;
    let sim = simulate(
        &config.scenario,
        &SensorConfig {
            dt: config.dt,
            steps,
            accelerometers: FourAccelerometers::default(),
            input_bias: config.input_bias,
            input_noise_std: config.input_noise_std,
            attitude_std: config.attitude_std,
        },
        config.first_seed,
    )
    .unwrap();
    let var = config
        .input_noise_std
        .component_mul(&config.input_noise_std);
    let process = InsProcess {
        input_noise: Matrix3::from_diagonal(&var),
        discretization: Discretization::ZeroOrderHold,
        plane: Plane::Horizontal,
    }
    .ckf();
    let measurement = AttitudeMeasurement {
        variance: config.attitude_std.powi(2),
    };
    let mut ckf = KalmanFilter::new(
        Gaussian::new(config.scenario.initial_state, config.initial_covariance).unwrap(),
    );
    let mut ote = OwnShipTrajectoryEstimator::new(&config.ote).unwrap();
    let mut z = Vec::new();
    for k in 1..=steps {
        let input = CkfInput {
            signals: sim.samples[k - 1].inputs,
            attitude: ckf.state()[4],
        };
        ckf.predict(&process, &input, config.dt).unwrap();
        ckf.update(&measurement, &Vector1::new(sim.samples[k].attitude))
            .unwrap();
        z.push(ote.correct(&mut ckf).unwrap().pseudo_measurement);
    }
    z
}

/// The framework RLS, fed the section IV pseudo-measurements without the CKF reset, equals the
/// batch (exponentially) weighted least-squares solution with the prior as regulariser,
///
/// r̂_k = argmin γᵏ |r − r₀|²_{P₀⁻¹} + Σⱼ γᵏ⁻ʲ |Z_j − r|²_{S⁻¹}
///     = (γᵏ P₀⁻¹ + Σ γᵏ⁻ʲ S⁻¹)⁻¹ (γᵏ P₀⁻¹ r₀ + Σ γᵏ⁻ʲ S⁻¹ Z_j),
///
/// at every k, for γ = 1 (ordinary RLS = batch least squares) and γ = 0.95. Tolerance 1e-9
/// relative: 500 sequential Joseph updates against one solve.
#[test]
fn rls_with_unit_forgetting_equals_batch_least_squares_on_pseudo_measurements() {
    let z = section_iv_pseudo_measurements();
    let s = Matrix2::new(0.01, 0.002, 0.002, 0.02);
    let p0 = Matrix2::identity();
    let r0 = Vector2::new(2.0, 2.0);
    let measurement = LinearMeasurement::<f64, U2, U2> {
        observation: Matrix2::identity(),
        noise: s,
    };
    for gamma in [1.0, 0.95] {
        let mut rls = FadingMemoryRls::new(Gaussian::new(r0, p0).unwrap(), gamma).unwrap();
        let s_inv = inv(&s);
        for k in 1..=z.len() {
            rls.update(&measurement, &z[k - 1]).unwrap();
            let w0 = gamma.powi(k as i32);
            let mut info = inv(&p0) * w0;
            let mut vec = inv(&p0) * r0 * w0;
            for (j, zj) in z[..k].iter().enumerate() {
                let w = gamma.powi((k - 1 - j) as i32);
                info += s_inv * w;
                vec += s_inv * zj * w;
            }
            let batch = inv(&info) * vec;
            let err = (rls.state() - batch).amax();
            assert!(
                err < 1e-9 * (1.0 + batch.amax()),
                "gamma {gamma}, k {k}: {err}"
            );
            assert!((rls.covariance() - inv(&info)).amax() < 1e-9 * inv(&info).amax());
        }
    }
}

/// Issue 18: an endless or huge section IV run is refused before anything is allocated
/// (formerly a hang collecting `usize::MAX` record slots).
#[test]
fn section_iv_rejects_endless_durations_and_run_counts() {
    use estim::core::{Error, Parameter};
    for duration in [f64::INFINITY, f64::NAN, 1e12] {
        let config = SectionIvConfig {
            duration,
            ..SectionIvConfig::paper()
        };
        assert!(matches!(
            run_section_iv(&config),
            Err(Error::InvalidParameter {
                parameter: Parameter::Duration,
                ..
            })
        ));
    }
    let config = SectionIvConfig {
        seeds: usize::MAX,
        ..SectionIvConfig::paper()
    };
    assert!(matches!(
        run_section_iv(&config),
        Err(Error::InvalidParameter {
            parameter: Parameter::RunCount,
            ..
        })
    ));
}
