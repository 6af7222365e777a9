//! Gates by probability: the threshold is the χ²ₘ quantile for each measurement's dimension, and
//! on clean data a consistent filter rejects the fraction 1 − p.

use crate::common::{gaussian_matrix, random_spd, rng};
use estim_core::nalgebra::{DMatrix, DVector, Dyn, Matrix2, Vector2};
use estim_core::rand_distr::{Distribution, StandardNormal};
use estim_core::{Error, Gaussian, LinearMeasurement, Parameter};
use estim_filters::{Gate, KalmanFilter, Update, UpdateOutcome};

/// For m = 2 the χ² quantile has a closed form, χ²₂(p) = −2 ln(1 − p): the gate lets a
/// measurement through exactly up to it (an independent route to statrs' inverse CDF; the two
/// agree to a few ulp, so the probes sit 1e-9 relative either side).
#[test]
fn two_component_gate_sits_at_the_closed_form_quantile() {
    for p in [0.5, 0.9, 0.99, 0.9999] {
        let quantile = -2.0 * (1.0f64 - p).ln();
        let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity()).unwrap();
        let filter = KalmanFilter::new(prior)
            .with_gate(Gate::Probability(p))
            .unwrap();
        assert_eq!(filter.gate(), Some(Gate::Probability(p)));
        // S = P + R = 2 I, so a reading (a, 0) has NIS a²/2.
        let sensor = LinearMeasurement {
            observation: Matrix2::identity(),
            noise: Matrix2::identity(),
        };
        for (scale, expected) in [
            (1.0 - 1e-9, UpdateOutcome::Applied),
            (1.0 + 1e-9, UpdateOutcome::Gated),
        ] {
            let z = Vector2::new((2.0 * quantile * scale).sqrt(), 0.0);
            let report = filter.clone().update(&sensor, &z).unwrap();
            assert_eq!(report.outcome, expected, "p = {p}, NIS {}", report.nis);
        }
    }
}

/// The fraction of correct measurements a consistent filter rejects is 1 − p, for a
/// dimension in the precomputed table (m = 1, 3) and one beyond it (m = 20, whose quantile is
/// computed at each update). Each trial updates a fresh copy of the prior with z ~ N(H x, S)
/// drawn from the prior and R: its NIS is exactly χ²ₘ. With 4000 trials and p = 0.95 the
/// rejected count is Binomial(4000, 0.05): mean 200, σ = 13.8; the bound is 5σ (a false
/// failure once in 3·10⁶ runs; the seed is fixed anyway).
#[test]
fn clean_data_is_rejected_at_the_gate_probability() {
    const TRIALS: usize = 4000;
    let p = 0.95;
    let mut r = rng(7);
    for (n, m) in [(2, 1), (3, 3), (4, 20)] {
        let prior = Gaussian::new(DVector::zeros(n), random_spd(&mut r, Dyn(n), 1.0, 0.1)).unwrap();
        let sensor = LinearMeasurement {
            observation: gaussian_matrix(&mut r, Dyn(m), Dyn(n)),
            noise: random_spd(&mut r, Dyn(m), 1.0, 0.1),
        };
        let filter = KalmanFilter::new(prior.clone())
            .with_gate(Gate::Probability(p))
            .unwrap();
        let p_chol = prior.covariance().clone().cholesky().unwrap().l();
        let r_chol = sensor.noise.clone().cholesky().unwrap().l();
        let normal = |r: &mut _, k| DVector::from_fn(k, |_, _| StandardNormal.sample(r));
        let mut rejected = 0;
        for _ in 0..TRIALS {
            let x: DVector<f64> = &p_chol * normal(&mut r, n);
            let z = &sensor.observation * x + &r_chol * normal(&mut r, m);
            let report = filter.clone().update(&sensor, &z).unwrap();
            if report.outcome == UpdateOutcome::Gated {
                rejected += 1;
            }
        }
        let mean = TRIALS as f64 * (1.0 - p);
        let sigma = (mean * p).sqrt();
        assert!(
            (rejected as f64 - mean).abs() < 5.0 * sigma,
            "m = {m}: {rejected} of {TRIALS} rejected, expected {mean} ± {sigma:.1}"
        );
    }
}

#[test]
fn gate_probabilities_outside_zero_one_are_rejected() {
    let prior = Gaussian::new(DVector::<f64>::zeros(2), DMatrix::identity(2, 2)).unwrap();
    for p in [0.0, 1.0, -0.5, 1.5, f64::NAN, f64::INFINITY] {
        let err = KalmanFilter::new(prior.clone())
            .with_gate(Gate::Probability(p))
            .unwrap_err();
        assert!(
            matches!(
                err,
                Error::InvalidParameter { parameter: Parameter::GateProbability, value }
                    if value.to_bits() == p.to_bits()
            ),
            "{p}: {err:?}"
        );
    }
}
