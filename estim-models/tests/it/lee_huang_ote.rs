//! The OTE (eq 44–48) on the framework's FadingMemoryRls: steady state, least-squares
//! equivalence, and its coupling to the CKF. Its equivalence with batch least squares on the
//! section IV pseudo-measurements uses the `lee_huang` example's configuration and is tested
//! with it, in the estim package's tests (`tests/it/lee_huang_example.rs`).

use estim_core::{Gaussian, LinearMeasurement};
use estim_filters::{Estimator, FadingMemoryRls, KalmanFilter, Update};
use estim_models::lee_huang::{OteSettings, OwnShipTrajectoryEstimator, ote_steady_state};
use nalgebra::{Matrix2, Matrix6, U2, Vector2, Vector6};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

fn inv(m: &Matrix2<f64>) -> Matrix2<f64> {
    m.try_inverse().expect("invertible in these tests")
}

/// K_p → (1 − γ) I and P_p → (1 − γ) S_p, for the issue's settings (γ = 0.95, S_p = 0.01 I,
/// P_p(0) = I) and for a non-diagonal S_p. The approach is geometric with ratio γ
/// (P_p⁻¹ = γᵏ P_p(0)⁻¹ + …): after 2000 cycles γᵏ < 1e-44, so only round-off (1e-12) remains.
#[test]
fn ote_steady_state_gain_and_covariance() {
    let issue = ote_steady_state(&OteSettings::issue(), 2000).unwrap();
    assert!(
        (issue.gain - Matrix2::identity() * 0.05).amax() < 1e-12,
        "{}",
        issue.gain
    );
    assert!(
        (issue.covariance - Matrix2::identity() * 5e-4).amax() < 1e-15,
        "{}",
        issue.covariance
    );
    assert!((issue.gain - issue.gain_closed_form).amax() < 1e-12);
    assert!((issue.covariance - issue.covariance_closed_form).amax() < 1e-15);

    let settings = OteSettings {
        forgetting: 0.9,
        weight: Matrix2::new(0.02, 0.005, 0.005, 0.01),
        initial_covariance: Matrix2::new(2.0, -0.3, -0.3, 0.5),
        ..OteSettings::issue()
    };
    let s = ote_steady_state(&settings, 2000).unwrap();
    assert!(
        (s.gain - Matrix2::identity() * 0.1).amax() < 1e-12,
        "{}",
        s.gain
    );
    assert!(
        (s.covariance - settings.weight * 0.1).amax() < 1e-14,
        "{}",
        s.covariance
    );
}

/// Independent route for every cycle: the information form
/// P_p(k)⁻¹ = γᵏ P_p(0)⁻¹ + S_p⁻¹ (1 − γᵏ)/(1 − γ), and K_p(k) = P_p(k) S_p⁻¹, entry by entry
/// (relative 1e-10: a 2 × 2 inverse of matrices with condition number < 1e3).
#[test]
fn ote_covariance_matches_information_form_at_every_step() {
    let settings = OteSettings {
        forgetting: 0.95,
        weight: Matrix2::new(0.01, 0.004, 0.004, 0.03),
        initial_covariance: Matrix2::identity(),
        ..OteSettings::issue()
    };
    let mut ote = OwnShipTrajectoryEstimator::new(&settings).unwrap();
    let (g, s_inv, p0_inv) = (
        settings.forgetting,
        inv(&settings.weight),
        inv(&settings.initial_covariance),
    );
    for k in 1..=300 {
        let step = ote.update(&Vector2::zeros(), &Vector2::zeros()).unwrap();
        let gk = g.powi(k);
        let p = inv(&(p0_inv * gk + s_inv * ((1.0 - gk) / (1.0 - g))));
        assert!((step.covariance - p).amax() < 1e-10 * p.amax(), "k = {k}");
        let k_info = p * s_inv;
        assert!((step.gain - k_info).amax() < 1e-10, "k = {k}");
    }
}

/// γ = 1: the gain diminishes like 1/k ("reduces to the usual sequential form", K_p → 0):
/// with P_p(0) = I, S_p = 0.01 I, K_p(k) = 1/(k + 0.01) exactly.
#[test]
fn unit_forgetting_gain_diminishes_like_one_over_k() {
    let settings = OteSettings {
        forgetting: 1.0,
        ..OteSettings::issue()
    };
    let mut ote = OwnShipTrajectoryEstimator::new(&settings).unwrap();
    for k in 1..=1000 {
        let step = ote.update(&Vector2::zeros(), &Vector2::zeros()).unwrap();
        let expected = 1.0 / (k as f64 + 0.01);
        assert!(
            (step.gain[(0, 0)] - expected).abs() < 1e-12 * expected.max(1.0),
            "k = {k}"
        );
    }
}

/// Erratum E9: P_p is not the error covariance of r̂_e. Smoothing white noise of covariance
/// S_p (constant true value, no reset) gives the steady error covariance
/// Σⱼ (1−γ)² γ²ʲ S_p = S_p (1 − γ)/(1 + γ) = 0.0256 S_p at γ = 0.95, while P_p → 0.05 S_p.
/// 200 000 samples of an AR(1) with coefficient γ estimate the variance to ≈ 1.4 % (1σ);
/// tolerance 6 %.
#[test]
fn ote_covariance_is_not_the_error_covariance() {
    let settings = OteSettings::issue();
    let gamma = settings.forgetting;
    let truth = Vector2::new(1.0, -2.0);
    let measurement = LinearMeasurement::<f64, U2, U2> {
        observation: Matrix2::identity(),
        noise: settings.weight,
    };
    let mut rls = FadingMemoryRls::new(
        Gaussian::new(truth, settings.initial_covariance).unwrap(),
        gamma,
    )
    .unwrap();
    let mut rng = StdRng::seed_from_u64(9);
    let sigma = settings.weight[(0, 0)].sqrt();
    let (burn, n) = (500, 200_000);
    let mut sum2 = 0.0;
    for k in 0..burn + n {
        let noise: Vector2<f64> = Vector2::new(
            StandardNormal.sample(&mut rng),
            StandardNormal.sample(&mut rng),
        ) * sigma;
        rls.update(&measurement, &(truth + noise)).unwrap();
        if k >= burn {
            sum2 += (rls.state() - truth).norm_squared() / 2.0;
        }
    }
    let measured = sum2 / n as f64;
    let formula = settings.weight[(0, 0)] * (1.0 - gamma) / (1.0 + gamma);
    let p_p = rls.covariance()[(0, 0)];
    assert!(
        (measured / formula - 1.0).abs() < 0.06,
        "{measured} vs {formula}"
    );
    assert!(
        p_p / measured > 1.8,
        "P_p = {p_p} is about twice the error variance {measured}"
    );
}

/// `correct` writes r̂_e = v̂ + K_p (g(D̂) − v̂) into the CKF velocity and touches nothing else
/// (position, θ, ω and the CKF covariance unchanged). First cycle of the issue's settings:
/// M = I/0.95, K_p = M (M + 0.01 I)⁻¹ = 0.990588… I.
#[test]
fn ote_correct_writes_velocity_back_and_keeps_covariance() {
    let x = Vector6::new(300.0, 120.0, 40.0, 25.0, 0.5, 0.01);
    let p = Matrix6::from_diagonal(&Vector6::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0));
    let mut ckf = KalmanFilter::new(Gaussian::new(x, p).unwrap());
    let mut ote = OwnShipTrajectoryEstimator::new(&OteSettings::issue()).unwrap();
    let step = ote.correct(&mut ckf).unwrap();
    let k = (1.0 / 0.95) / (1.0 / 0.95 + 0.01);
    assert!((step.gain - Matrix2::identity() * k).amax() < 1e-14);
    let z = estim_models::lee_huang::VelocityLikelihood;
    let g = estim_core::VectorFunction::eval(&z, &x);
    let v = Vector2::new(x[2], x[3]);
    let expected = v + (g - v) * k;
    let after = ckf.state();
    assert!((Vector2::new(after[2], after[3]) - expected).amax() < 1e-12);
    for i in [0, 1, 4, 5] {
        assert_eq!(after[i], x[i]);
    }
    assert_eq!(*ckf.covariance(), p);
}

/// Erratum E3: taken literally (eq 43 = eq 45), Z_p equals the prior r̂_e and the OTE leaves
/// the velocity unchanged whatever the gain.
#[test]
fn literal_eq43_45_make_the_ote_a_no_op() {
    let mut ote = OwnShipTrajectoryEstimator::new(&OteSettings::issue()).unwrap();
    for v in [Vector2::new(2.0, 2.0), Vector2::new(-30.0, 7.5)] {
        let step = ote.update(&v, &v).unwrap();
        assert!((step.velocity - v).amax() < 1e-14);
    }
}

/// g(D) is undefined at the origin: `correct` returns an error and leaves the filter as it was.
#[test]
fn correct_rejects_a_state_at_the_origin() {
    let x = Vector6::new(0.0, 0.0, 1.0, 1.0, 0.0, 0.0);
    let mut ckf = KalmanFilter::new(Gaussian::new(x, Matrix6::identity()).unwrap());
    let mut ote = OwnShipTrajectoryEstimator::new(&OteSettings::issue()).unwrap();
    assert!(ote.correct(&mut ckf).is_err());
    assert_eq!(*ckf.state(), x);
}

/// A cycle that fails (a non-finite prior velocity or pseudo-measurement) leaves the OTE as it
/// was: before, the RLS had already been reset to the prior when the update failed.
#[test]
fn a_failed_cycle_changes_nothing() {
    let mut ote = OwnShipTrajectoryEstimator::new(&OteSettings::issue()).unwrap();
    ote.update(&Vector2::new(1.0, 1.0), &Vector2::new(1.1, 0.9))
        .unwrap();
    let before = ote.clone();
    for (prior, z) in [
        (Vector2::new(5.0, 5.0), Vector2::new(f64::NAN, 0.0)),
        (Vector2::new(f64::NAN, 5.0), Vector2::new(1.0, 1.0)),
        (Vector2::new(5.0, f64::INFINITY), Vector2::new(1.0, 1.0)),
    ] {
        assert!(ote.update(&prior, &z).is_err(), "{prior:?} {z:?}");
        assert_eq!(ote, before, "{prior:?} {z:?}");
    }
    // And the next good cycle is the one the clone gives.
    let mut clone = before.clone();
    let step = ote.update(&Vector2::new(1.0, 1.0), &Vector2::new(1.2, 0.8));
    assert_eq!(
        step,
        clone.update(&Vector2::new(1.0, 1.0), &Vector2::new(1.2, 0.8))
    );
}
