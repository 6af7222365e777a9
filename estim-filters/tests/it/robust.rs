//! The robust (Huber / Student-t) update: the filter's own update, bit for bit, while every
//! innovation is inside the threshold; against the closed form x + wKν, P − wKSKᵀ otherwise;
//! and the step bounded by the derived bound for gross outliers.

use crate::common::{gaussian_matrix, normal, random_spd, rng};
use estim_core::nalgebra::{Matrix2x3, Matrix3, U2, U3, Vector2, Vector3};
use estim_core::{Error, Gaussian, LinearMeasurement, LinearProcess, Parameter};
use estim_filters::robust::{RobustWeight, robust_update};
use estim_filters::{Estimator, Gate, KalmanFilter, Predict, Update, UpdateOutcome};

/// A 3-state system with a 2-component sensor.
type System = (
    LinearProcess<f64, U3, U2>,
    LinearMeasurement<f64, U3, U2>,
    Gaussian<f64, U3>,
);

fn system(seed: u64) -> System {
    let mut g = rng(seed);
    let process = LinearProcess {
        transition: Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.1, 0.0, 0.0, 0.95),
        input: gaussian_matrix(&mut g, U3, U2),
        noise: random_spd(&mut g, U3, 0.01, 1e-3),
    };
    let sensor = LinearMeasurement {
        observation: gaussian_matrix(&mut g, U2, U3),
        noise: random_spd(&mut g, U2, 0.5, 0.1),
    };
    let prior = Gaussian::new(Vector3::zeros(), random_spd(&mut g, U3, 2.0, 0.1)).unwrap();
    (process, sensor, prior)
}

/// Readings simulated from the model itself, Huber threshold k = 5 on a 2-component NIS:
/// P(d > 5) = e^{−12.5} ≈ 4·10⁻⁶ per step for a consistent filter, so over 300 steps the seed's
/// run has none, and the robust filter must be the plain one bit for bit (the same update is
/// computed; no rounding differs).
#[test]
fn inside_the_threshold_it_is_the_kalman_filter_bit_for_bit() {
    let (process, sensor, prior) = system(0x70b);
    let mut g = rng(0x70c);
    let mut plain = KalmanFilter::new(prior.clone());
    let mut robust = KalmanFilter::new(prior.clone());
    let l = prior.covariance().cholesky().unwrap().l();
    let mut truth = l * Vector3::new(normal(&mut g), normal(&mut g), normal(&mut g));
    let lq = process.noise.cholesky().unwrap().l();
    let lr = sensor.noise.cholesky().unwrap().l();
    for _ in 0..300 {
        let u = Vector2::new(normal(&mut g), normal(&mut g));
        truth = process.transition * truth
            + process.input * u
            + lq * Vector3::new(normal(&mut g), normal(&mut g), normal(&mut g));
        let z = sensor.observation * truth + lr * Vector2::new(normal(&mut g), normal(&mut g));
        plain.predict(&process, &u, 0.1).unwrap();
        robust.predict(&process, &u, 0.1).unwrap();
        let expected = plain.update(&sensor, &z).unwrap();
        let r = robust_update(&mut robust, &sensor, &z, RobustWeight::Huber(5.0)).unwrap();
        assert_eq!(r.weight, 1.0);
        assert_eq!(r.report, expected);
        assert_eq!(robust.state(), plain.state());
        assert_eq!(robust.covariance(), plain.covariance());
    }
}

/// One reading z = H x + δ with δ of 10 to 10⁶ innovation standard deviations, against the
/// closed form (K = P Hᵀ S⁻¹ by LU; w from d² = νᵀS⁻¹ν): x⁺ = x + wKν, P⁺ = P − wKSKᵀ, and
/// the step's length in the prior metric ‖L⁻¹(x⁺ − x)‖ (P = LLᵀ) ≤ the weight's step bound.
///
/// Tolerances: x and P agree to 10⁻¹⁰ relative to their scale (the two routes differ by
/// rounding amplified by κ(S) ≲ 10³ here, and |ν| up to 10⁶ σ multiplies the mean's absolute
/// error); the bound holds to 10⁻⁹ relative (the step is w K ν, its length computed through a
/// triangular solve with κ(P) ≲ 10²).
#[test]
fn an_outlier_moves_the_estimate_by_at_most_the_bound() {
    let (_, sensor, prior) = system(0x0b7);
    let (x, p) = (*prior.mean(), *prior.covariance());
    let h: Matrix2x3<f64> = sensor.observation;
    let s = h * p * h.transpose() + sensor.noise;
    let k = (s.lu().solve(&(h * p)).unwrap()).transpose();
    let ls = s.cholesky().unwrap().l();
    let lp = p.cholesky().unwrap().l();
    for weight in [
        RobustWeight::Huber(2.0),
        RobustWeight::Huber(3.0),
        RobustWeight::StudentT(4.0),
    ] {
        for sigmas in [10.0, 1e3, 1e6] {
            // δ = L_S · (σs along a fixed direction): d = σs exactly.
            let direction = Vector2::new(0.6, -0.8);
            let z = h * x + ls * direction * sigmas;
            let mut kf = KalmanFilter::new(prior.clone());
            let r = robust_update(&mut kf, &sensor, &z, weight).unwrap();
            let nu = z - h * x;
            let d2 = (s.lu().solve(&nu).unwrap()).dot(&nu);
            let w = weight.weight(d2, 2);
            assert!(w < 1.0);
            assert!((r.weight - w).abs() <= 1e-12 * w, "{} vs {w}", r.weight);
            let x_expected = x + k * nu * w;
            let p_expected = p - k * s * k.transpose() * w;
            let scale = x_expected.amax().max(1.0);
            assert!(
                (kf.state() - x_expected).amax() <= 1e-10 * scale,
                "{weight:?} {sigmas}: x"
            );
            assert!(
                (kf.covariance() - p_expected).amax() <= 1e-10 * p.amax(),
                "{weight:?} {sigmas}: P"
            );
            let step = lp.solve_lower_triangular(&(kf.state() - x)).unwrap().norm();
            let bound = weight.step_bound(2);
            assert!(
                step <= bound * (1.0 + 1e-9),
                "{weight:?} {sigmas}: step {step} > {bound}"
            );
            // Huber: a gross outlier moves it by the full k·(Kν direction); Student-t
            // redescends: the step is ≤ w d = d(ν+m)/(ν+d²) < (ν+m)/d.
            if let RobustWeight::StudentT(dof) = weight {
                assert!(step <= (dof + 2.0) / sigmas * (1.0 + 1e-9));
            }
            // Not overconfident: P⁺ ≥ the Kalman posterior P − KSKᵀ.
            let gap = kf.covariance() - (p - k * s * k.transpose());
            assert!(gap.symmetric_eigenvalues().min() >= -1e-12 * p.amax());
        }
    }
}

#[test]
fn bad_weights_are_refused_and_a_gate_acts_first() {
    let (_, sensor, prior) = system(0xbad);
    let mut kf = KalmanFilter::new(prior.clone());
    for weight in [
        RobustWeight::Huber(0.0),
        RobustWeight::StudentT(f64::NAN),
        RobustWeight::Huber(-1.0),
    ] {
        assert!(matches!(
            robust_update(&mut kf, &sensor, &Vector2::new(1.0, 2.0), weight),
            Err(Error::InvalidParameter {
                parameter: Parameter::GateThreshold,
                ..
            })
        ));
        assert_eq!(kf.estimate(), prior);
    }
    let mut gated = KalmanFilter::new(prior.clone())
        .with_gate(Gate::Nis(9.0))
        .unwrap();
    let r = robust_update(
        &mut gated,
        &sensor,
        &Vector2::new(1e4, 0.0),
        RobustWeight::Huber(2.0),
    )
    .unwrap();
    assert_eq!(r.report.outcome, UpdateOutcome::Gated);
    assert_eq!(r.weight, 1.0);
    assert_eq!(gated.estimate(), prior);
}
