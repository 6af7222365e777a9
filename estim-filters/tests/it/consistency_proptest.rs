//! The `proptest-support` strategies and assertions.
#![cfg(feature = "proptest-support")]

use crate::consistency_common;

use consistency_common::*;
use estim_core::nalgebra::{Dyn, U1, U2, U3, Vector1};
use estim_core::{Gaussian, ProcessModel};
use estim_filters::consistency::ChiSquareBand;
use estim_filters::monte_carlo::MonteCarlo;
use estim_filters::proptest_support::{
    assert_process_jacobian, gaussian, spd_matrix, stable_linear_system, vector,
};
use estim_filters::{Estimator, KalmanFilter, Predict, Update};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestError, TestRunner};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

proptest! {
    #![proptest_config(Config { cases: 64, ..Config::default() })]

    /// Exactly symmetric, eigenvalues in [1, κ] (up to rounding of 1e-9 relative), accepted
    /// by `Gaussian::new`; static and runtime sizes.
    #[test]
    fn spd_matrices_have_bounded_condition(
        a in spd_matrix::<f64, _>(U3, 1e4),
        b in spd_matrix::<f64, _>(Dyn(6), 50.0),
    ) {
        for (m, kappa) in [(a.resize(3, 3, 0.0), 1e4), (b.clone(), 50.0)] {
            prop_assert_eq!(&m, &m.transpose());
            let eig = m.clone().symmetric_eigenvalues();
            prop_assert!(eig.min() >= 1.0 - 1e-9 && eig.max() <= kappa * (1.0 + 1e-9), "{}", eig);
        }
        let n = b.nrows();
        prop_assert!(Gaussian::new(estim_core::nalgebra::DVector::zeros(n), b).is_ok());
    }

    #[test]
    fn gaussians_are_valid(g in gaussian::<f64, _>(U3), h in gaussian::<f32, _>(Dyn(4))) {
        prop_assert!(Gaussian::new(*g.mean(), *g.covariance()).is_ok());
        prop_assert!(g.mean().amax() <= 10.0);
        prop_assert!(Gaussian::new(h.mean().clone(), h.covariance().clone()).is_ok());
    }

    /// ‖F‖₂ < 1, hence every eigenvalue of F inside the unit circle.
    #[test]
    fn linear_systems_are_stable(sys in stable_linear_system(U3, U2), dynamic in stable_linear_system(Dyn(5), Dyn(2))) {
        prop_assert!(sys.spectral_norm < 0.99);
        let radius = sys.process.transition.complex_eigenvalues().iter().map(|e| e.norm()).fold(0.0, f64::max);
        prop_assert!(radius <= sys.spectral_norm + 1e-12);
        let radius = dynamic.process.transition.clone().complex_eigenvalues().iter().map(|e| e.norm()).fold(0.0, f64::max);
        prop_assert!(radius < 1.0);
        prop_assert_eq!(dynamic.measurement.observation.shape(), (2, 5));
    }

    /// The right hand-written Jacobian passes `assert_process_jacobian` at random points.
    #[test]
    fn right_jacobian_passes(x in vector::<f64, _>(U3, 100.0), u in vector::<f64, _>(U1, 5.0)) {
        let model = HandWritten { inner: Lu::new().process, forget_bias_coupling: false };
        assert_process_jacobian(&model, &x, &u, DT, 1e-6)?;
    }
}

/// The wrong Jacobian fails the property, and proptest reports it as a failure (not a panic).
#[test]
fn wrong_jacobian_fails_the_property() {
    let model = HandWritten {
        inner: Lu::new().process,
        forget_bias_coupling: true,
    };
    let mut runner = TestRunner::new(Config {
        cases: 16,
        failure_persistence: None,
        ..Config::default()
    });
    let result = runner.run(&vector::<f64, _>(U3, 100.0), |x| {
        assert_process_jacobian(&model, &x, &Vector1::new(0.1), DT, 1e-6)
    });
    match result {
        Err(TestError::Fail(reason, _)) => {
            assert!(reason.message().contains("process Jacobian"), "{reason}")
        }
        other => panic!("expected a failure, got {other:?}"),
    }
}

/// The Kalman filter on random stable systems: the average NEES over 200 runs after 30 steps
/// lies in its χ²_{200·3}/200 band at confidence 1 − 10⁻⁶, so a consistent filter fails a case
/// with probability 10⁻⁶ (no flakiness over 12 cases), while any real inconsistency of
/// the filter code or of the generated systems' noise would show.
#[test]
fn kalman_filter_is_consistent_on_random_stable_systems() {
    let mut runner = TestRunner::new(Config {
        cases: 12,
        failure_persistence: None,
        ..Config::default()
    });
    runner
        .run(&stable_linear_system(U3, U2), |sys| {
            let steps = 30;
            let chol = |m: &estim_core::nalgebra::Matrix3<f64>| m.cholesky().unwrap().l();
            let (lq, lp) = (chol(&sys.process.noise), chol(sys.prior.covariance()));
            let lr = sys.measurement.noise.cholesky().unwrap().l();
            let stats = MonteCarlo::new(200, 1)
                .unwrap()
                .run(|_, seed, rec| {
                    let mut rng = StdRng::seed_from_u64(seed);
                    let mut n = |k: usize| {
                        estim_core::nalgebra::DVector::<f64>::from_fn(k, |_, _| {
                            rng.sample(StandardNormal)
                        })
                    };
                    let mut x = sys.prior.mean() + lp * n(3).fixed_rows::<3>(0);
                    let mut kf = KalmanFilter::new(sys.prior.clone());
                    for k in 0..steps {
                        let u = Vector1::new((k as f64).cos());
                        x = sys.process.transition(&x, &u, 1.0) + lq * n(3).fixed_rows::<3>(0);
                        let z = sys.measurement.observation * x + lr * n(2).fixed_rows::<2>(0);
                        kf.predict(&sys.process, &u, 1.0)?;
                        kf.update(&sys.measurement, &z)?;
                    }
                    rec.record_estimate(0, &x, kf.state(), kf.covariance())
                })
                .unwrap();
            let e = stats.slots[0].estimate.as_ref().unwrap();
            let band = ChiSquareBand::two_sided(3, 200, 1.0 - 1e-6).unwrap();
            prop_assert!(
                band.contains(e.mean_nees),
                "NEES {} outside {:?}",
                e.mean_nees,
                band
            );
            Ok(())
        })
        .unwrap();
}
