//! The models in filters: a bias state estimated through augmentation, and kept out of the
//! correction as a consider state.

use estim_core::nalgebra::{Matrix1, Matrix3, U3, Vector1, Vector3};
use estim_core::{Gaussian, ProcessModel};
use estim_filters::consider::schmidt_update;
use estim_filters::{Ekf, Estimator, Predict, Update};
use estim_models::augment::{Augmented, Biased};
use estim_models::motion::{ConstantVelocity, Noise, RandomWalk};
use estim_models::sensors::Position;

type Tracked = Augmented<ConstantVelocity<f64, 1>, RandomWalk<f64, 1>, 2, 1>;

/// The model, the biased and the unbiased sensors, the prior.
type Setup = (
    Tracked,
    Biased<Position<f64, 1>, f64, 2, 1, 1>,
    Position<f64, 1>,
    Gaussian<f64, U3>,
);

fn setup() -> Setup {
    let model: Tracked = Augmented {
        model: ConstantVelocity::new(Noise::Continuous(1e-4)),
        augment: RandomWalk {
            psd: Vector1::new(1e-8),
        },
    };
    // A biased 10 Hz position sensor, and an unbiased 1 Hz one.
    let biased = Biased {
        model: Position {
            noise: Matrix1::new(0.01),
        },
        coupling: Matrix1::new(1.0),
    };
    let reference = Position {
        noise: Matrix1::new(0.04),
    };
    let prior = Gaussian::new(
        Vector3::zeros(),
        Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 1.0)),
    )
    .unwrap();
    (model, biased, reference, prior)
}

/// Noise-free readings of a target at 2 m/s with a 0.7 m sensor bias: the augmented EKF
/// recovers the bias. The filter is consistent and the readings are one realisation (the
/// zero-noise one), so the error must sit well inside the posterior's 3σ; and σ must be small
/// (the unbiased sensor separates the bias), ≤ 0.05 m after 30 s.
#[test]
fn an_augmented_bias_is_estimated() {
    let (model, biased, reference, prior) = setup();
    let mut ekf = Ekf::new(prior);
    let mut truth = Vector3::new(0.0, 2.0, 0.7);
    for k in 1..=300 {
        truth = model.transition(&truth, &(), 0.1);
        ekf.predict(&model, &(), 0.1).unwrap();
        ekf.update(&biased, &Vector1::new(truth[0] + truth[2]))
            .unwrap();
        if k % 10 == 0 {
            ekf.update(&reference, &Vector1::new(truth[0])).unwrap();
        }
    }
    let sigma = ekf.covariance()[(2, 2)].sqrt();
    assert!(sigma <= 0.05, "σ_b = {sigma}");
    assert!(
        (ekf.state()[2] - 0.7).abs() <= 3.0 * sigma,
        "b̂ = {}",
        ekf.state()[2]
    );
}

/// The same bias as a consider state: never corrected (its mean stays at the prior's 0 and
/// its variance only grows by the random walk's q Δt per step), while the position absorbs
/// the bias' uncertainty through the cross-covariance: its variance is larger than with the
/// bias estimated.
#[test]
fn a_considered_bias_is_carried_not_corrected() {
    let (model, biased, _, prior) = setup();
    let mut consider = Ekf::new(prior.clone());
    let mut estimate = Ekf::new(prior);
    for k in 1..=50 {
        consider.predict(&model, &(), 0.1).unwrap();
        estimate.predict(&model, &(), 0.1).unwrap();
        let z = Vector1::new(0.2 * k as f64 + 0.7);
        schmidt_update(&mut consider, &biased, &z, &[2]).unwrap();
        estimate.update(&biased, &z).unwrap();
        assert_eq!(consider.state()[2], 0.0);
        // P_bb: 1 + k q Δt, accumulated step by step (rounding only).
        let expected = 1.0 + k as f64 * 1e-9;
        assert!((consider.covariance()[(2, 2)] - expected).abs() <= 1e-15 * k as f64);
    }
    assert!(consider.covariance()[(0, 0)] > estimate.covariance()[(0, 0)]);
}
