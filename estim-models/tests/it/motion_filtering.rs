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

/// A target turning at 0.1 rad/s seen by a range-bearing radar (σ_r = 1 m, σ_β = 1 mrad),
/// simulated from the models with seeded noise; the turn rate is estimated by every filter
/// of the family, the second-order ones using the turn's and the sensor's Hessians. Each
/// filter's final rate error must sit inside 4σ of its own posterior (a consistent filter
/// exceeds 4σ with probability 6·10⁻⁵), and σ_ω must have shrunk below 0.01 rad/s from the
/// prior's 0.1.
#[test]
fn every_filter_tracks_a_turn_with_the_rate_estimated() {
    use estim_core::MeasurementModel;
    use estim_core::nalgebra::{Matrix5, Vector2, Vector5};
    use estim_core::rand::SeedableRng;
    use estim_core::rand::rngs::StdRng;
    use estim_core::rand_distr::{Distribution, StandardNormal};
    use estim_filters::{GaussianSecondOrderEkf, SecondOrderEkf, Ukf};
    use estim_models::motion::CoordinatedTurnRate;
    use estim_models::sensors::RangeBearing;

    let ct = CoordinatedTurnRate {
        accel_psd: 0.01,
        rate_psd: 1e-6,
    };
    let radar = RangeBearing {
        origin: Vector2::zeros(),
        range_variance: 1.0,
        bearing_variance: 1e-6,
    };
    let mut rng = StdRng::seed_from_u64(0x7a7);
    let mut n = || -> f64 { StandardNormal.sample(&mut rng) };
    let dt = 0.5;
    let mut truth = Vector5::new(100.0, 0.0, 0.0, 10.0, 0.1);
    let mut readings = Vec::new();
    for _ in 0..120 {
        let q = ct.process_noise(&truth, &(), dt).cholesky().unwrap().l();
        truth = ct.transition(&truth, &(), dt) + q * Vector5::from_fn(|_, _| n());
        let z = radar.measure(&truth) + Vector2::new(n(), 1e-3 * n());
        readings.push(z);
    }
    let prior = Gaussian::new(
        Vector5::new(100.0, 0.0, 0.0, 10.0, 0.0),
        Matrix5::from_diagonal(&Vector5::new(4.0, 4.0, 1.0, 1.0, 0.01)),
    )
    .unwrap();
    let check = |name: &str, state: &Vector5<f64>, cov: &Matrix5<f64>| {
        let sigma = cov[(4, 4)].sqrt();
        assert!(sigma < 0.01, "{name}: σ_ω = {sigma}");
        assert!(
            (state[4] - truth[4]).abs() <= 4.0 * sigma,
            "{name}: ω̂ = {} vs {}",
            state[4],
            truth[4]
        );
    };
    macro_rules! run {
        ($filter:expr, $name:literal) => {{
            let mut f = $filter;
            for z in &readings {
                f.predict(&ct, &(), dt).unwrap();
                f.update(&radar, z).unwrap();
            }
            check($name, f.state(), f.covariance());
        }};
    }
    run!(Ekf::new(prior.clone()), "EKF");
    run!(Ukf::new(prior.clone()), "UKF");
    run!(SecondOrderEkf::new(prior.clone()), "second-order EKF");
    run!(
        GaussianSecondOrderEkf::new(prior.clone()),
        "Gaussian second-order EKF"
    );
}
