//! Unscented parameter sets anywhere in the accepted region (α from 10⁻³ to 10³, κ from near
//! −n to 10⁶, β from its lower bound −α²κ/n upwards, the boundary itself included) never give
//! an indefinite covariance: every step on a random nonlinear problem either fails with a
//! typed error (never a parameter error, the set being accepted) or returns a P that is
//! symmetric and positive semi-definite within the library's round-off tolerance
//! (16 n ε max Pᵢᵢ, the one `psd_factor` uses).

use estim_core::checks::ensure_psd;
use estim_core::nalgebra::{Matrix2, Matrix3, U2, U3, Vector2, Vector3};
use estim_core::{Error, Gaussian, MeasurementModel, ProcessModel, Quantity, Stage, Unscented};
use estim_filters::{Estimator, GaussianFilter, Predict, Update};
use proptest::prelude::*;

/// A mildly nonlinear 3-state process.
struct Process;
impl ProcessModel<f64, U3> for Process {
    type Input = ();
    fn transition(&self, x: &Vector3<f64>, _: &(), _: f64) -> Vector3<f64> {
        Vector3::new(
            x[0] + 0.1 * x[1].sin(),
            x[1] + 0.05 * x[2] * x[2],
            0.9 * x[2] + 0.2 * x[0].cos(),
        )
    }
    fn process_noise(&self, _: &Vector3<f64>, _: &(), _: f64) -> Matrix3<f64> {
        Matrix3::identity() * 1e-2
    }
}

/// A quadratic and a periodic measurement.
struct Sensor;
impl MeasurementModel<f64, U3, U2> for Sensor {
    fn measure(&self, x: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(x[0] * x[0] + x[1], x[2].sin())
    }
    fn measurement_noise(&self, _: &Vector3<f64>) -> Matrix2<f64> {
        Matrix2::identity() * 0.05
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    #[test]
    fn accepted_unscented_sets_keep_the_covariance_psd(
        log_alpha in -3.0..3.0f64,
        kappa_choice in 0..3u8,
        kappa_unit in 0.0..1.0f64,
        slack in prop_oneof![Just(0.0), 0.0..3.0f64],
        z in proptest::array::uniform2(-2.0..2.0f64),
        x0 in proptest::array::uniform3(-1.0..1.0f64),
    ) {
        let n = 3.0;
        let alpha = 10f64.powf(log_alpha);
        // κ near −n (just above), moderate, or up to 10⁶.
        let kappa = match kappa_choice {
            0 => -n + 0.01 + 2.0 * kappa_unit,
            1 => 10.0 * kappa_unit,
            _ => 1e6 * kappa_unit,
        };
        // β on the boundary (slack 0) or inside.
        let beta = -alpha * alpha * kappa / n + slack;
        let rule = Unscented::new(alpha, beta, kappa).unwrap();
        if rule.check_dimension(3).is_err() {
            // The boundary value rounded to just outside: refused, which is the contract.
            return Ok(());
        }
        let prior = Gaussian::new(Vector3::from(x0), Matrix3::identity() * 0.5).unwrap();
        let mut ukf = GaussianFilter::with_propagator(prior, rule);
        for _ in 0..3 {
            let steps = [
                ukf.predict(&Process, &(), 1.0).err(),
                ukf.update(&Sensor, &Vector2::from(z)).err(),
            ];
            for e in steps.into_iter().flatten() {
                prop_assert!(!matches!(e, Error::InvalidParameter { .. }), "{e:?}");
            }
            let p = ukf.covariance();
            prop_assert!((p - p.transpose()).abs().max() <= 1e-12 * p.abs().max());
            prop_assert_eq!(
                ensure_psd(p, Stage::Update, Quantity::Covariance),
                Ok(()),
                "(α, β, κ) = ({}, {}, {}): P = {}", alpha, beta, kappa, p
            );
        }
    }
}
