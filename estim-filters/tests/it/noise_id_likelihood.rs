//! Maximum likelihood ([`MaximumLikelihood`]): the Hessian standard errors against the
//! Monte Carlo spread of the estimates over seeds, a nonlinear model through the UKF and the
//! EKF, a flat direction, and bad input.

use estim_core::nalgebra::{Matrix1, Vector1};
use estim_core::nalgebra::{OMatrix, OVector, U1};
use estim_core::{
    Gaussian, LinearMeasurement, LinearProcess, MeasurementJacobian, MeasurementModel,
};
use estim_filters::noise_id::likelihood::sequence_log_likelihood;
use estim_filters::noise_id::{MaximumLikelihood, NoiseIdError, Setting, Unidentifiable};
use estim_filters::{Ekf, KalmanFilter, Ukf};

use crate::common::{normal, rng};

/// A random walk with Q = `q` seen through noise R = `r`: `steps` + 1 measurements.
pub fn random_walk_data(seed: u64, steps: usize, q: f64, r: f64) -> Vec<Option<Vector1<f64>>> {
    let (mut rng, mut x) = (rng(seed), 0.0);
    (0..=steps)
        .map(|k| {
            if k > 0 {
                x += q.sqrt() * normal(&mut rng);
            }
            Some(Vector1::new(x + r.sqrt() * normal(&mut rng)))
        })
        .collect()
}

/// The random-walk model with θ = (ln Q, ln R).
pub fn walk_model(theta: &[f64]) -> (LinearProcess<f64, U1, U1>, LinearMeasurement<f64, U1, U1>) {
    (
        LinearProcess {
            transition: Matrix1::new(1.0),
            input: Matrix1::zeros(),
            noise: Matrix1::new(theta[0].exp()),
        },
        LinearMeasurement {
            observation: Matrix1::new(1.0),
            noise: Matrix1::new(theta[1].exp()),
        },
    )
}

/// The prior of every random-walk test.
pub fn walk_prior() -> Gaussian<f64, U1> {
    Gaussian::new(Vector1::new(0.0), Matrix1::new(10.0)).unwrap()
}

/// ℓ(θ) of one random-walk record through the Kalman filter (θ₀ = ln Q, θ₁ = ln R; further
/// entries are ignored).
pub fn walk_log_likelihood(
    theta: &[f64],
    zs: &[Option<Vector1<f64>>],
) -> Result<f64, NoiseIdError> {
    let (process, sensor) = walk_model(theta);
    let kf = KalmanFilter::new(walk_prior());
    let inputs = vec![Vector1::zeros(); zs.len() - 1];
    sequence_log_likelihood(&kf, &process, &inputs, 1.0, &sensor, zs)
}

#[test]
fn standard_errors_match_the_spread_over_seeds() {
    let (q, r, steps, seeds) = (0.04f64, 0.25f64, 300, 16);
    let mut estimates = Vec::new();
    let mut errors = Vec::new();
    for seed in 0..seeds {
        let zs = random_walk_data(1000 + seed, steps, q, r);
        let fit = MaximumLikelihood::new()
            .maximize(|theta| walk_log_likelihood(theta, &zs), &[0.0, 0.0])
            .unwrap();
        estimates.push(fit.parameters.clone());
        errors.push(fit.standard_errors().unwrap());
    }
    let n = seeds as f64;
    for i in 0..2 {
        let mean = estimates.iter().map(|e| e[i]).sum::<f64>() / n;
        let sd = (estimates.iter().map(|e| (e[i] - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let se = errors.iter().map(|e| e[i]).sum::<f64>() / n;
        // Sample sd of 16 draws within [0.5, 1.6] of the true σ with probability > 0.99
        // (χ²₁₅ quantiles); the Hessian se estimates σ.
        assert!(
            (0.5..1.6).contains(&(sd / se)),
            "parameter {i}: sd {sd}, se {se}"
        );
        // The truth within 4 standard errors of the mean of 16 estimates (ML bias at 300
        // steps is far smaller than se).
        let truth = [q.ln(), r.ln()][i];
        assert!(
            (mean - truth).abs() < 4.0 * se / n.sqrt(),
            "parameter {i}: mean {mean}, truth {truth}"
        );
    }
}

/// z = atan(x) + v: a nonlinear sensor for the EKF and the UKF.
struct Bearing {
    r: f64,
}

impl MeasurementModel<f64, U1, U1> for Bearing {
    fn measure(&self, x: &OVector<f64, U1>) -> OVector<f64, U1> {
        Vector1::new(x[0].atan())
    }
    fn measurement_noise(&self, _: &OVector<f64, U1>) -> OMatrix<f64, U1, U1> {
        Matrix1::new(self.r)
    }
}

impl MeasurementJacobian<f64, U1, U1> for Bearing {
    fn measurement_jacobian(&self, x: &OVector<f64, U1>) -> OMatrix<f64, U1, U1> {
        Matrix1::new(1.0 / (1.0 + x[0] * x[0]))
    }
}

#[test]
fn a_nonlinear_sensor_through_the_ekf_and_the_ukf() {
    // x a slow random walk near 0 (Q = 0.01), z = atan x + v, R = 0.0025.
    let (q, r, steps) = (0.01f64, 0.0025f64, 400);
    let (mut rng, mut x) = (rng(77), 0.0);
    let zs: Vec<_> = (0..=steps)
        .map(|k| {
            if k > 0 {
                x += q.sqrt() * normal(&mut rng);
            }
            Some(Vector1::new(f64::atan(x) + r.sqrt() * normal(&mut rng)))
        })
        .collect();
    let inputs = vec![Vector1::zeros(); steps];
    let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(0.1)).unwrap();
    let ll = |theta: &[f64], ukf: bool| {
        let (process, _) = walk_model(theta);
        let sensor = Bearing { r: theta[1].exp() };
        if ukf {
            sequence_log_likelihood(
                &Ukf::new(prior.clone()),
                &process,
                &inputs,
                1.0,
                &sensor,
                &zs,
            )
        } else {
            sequence_log_likelihood(
                &Ekf::new(prior.clone()),
                &process,
                &inputs,
                1.0,
                &sensor,
                &zs,
            )
        }
    };
    let ekf = MaximumLikelihood::new()
        .maximize(|t| ll(t, false), &[0.0, 0.0])
        .unwrap();
    let ukf = MaximumLikelihood::new()
        .maximize(|t| ll(t, true), &[0.0, 0.0])
        .unwrap();
    for fit in [&ekf, &ukf] {
        let se = fit.standard_errors().unwrap();
        for (i, truth) in [q.ln(), r.ln()].into_iter().enumerate() {
            // 4 se: one realization, 99.99 % if the estimate is unbiased and Gaussian.
            assert!(
                (fit.parameters[i] - truth).abs() < 4.0 * se[i],
                "{:?} ± {se:?}",
                fit.parameters
            );
        }
    }
    // The two filters approximate the same likelihood: their optima differ by much less than
    // a standard error (the nonlinearity over the state spread is small).
    let se = ekf.standard_errors().unwrap();
    for i in 0..2 {
        assert!((ekf.parameters[i] - ukf.parameters[i]).abs() < 0.5 * se[i]);
    }
}

#[test]
fn a_parameter_the_data_ignore_is_reported_flat() {
    let zs = random_walk_data(3, 200, 0.04, 0.25);
    let fit = MaximumLikelihood::new()
        .maximize(
            // θ₂ does not enter the model.
            |theta| walk_log_likelihood(theta, &zs),
            &[0.0, 0.0, 0.5],
        )
        .unwrap();
    assert_eq!(
        fit.standard_errors(),
        Err(NoiseIdError::Unidentifiable(
            Unidentifiable::FlatLikelihood { index: 2 }
        ))
    );
}

#[test]
fn bad_input_is_a_typed_error() {
    let ml = MaximumLikelihood::new();
    assert!(matches!(
        ml.with_max_iterations(0),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::MaxIterations,
            ..
        })
    ));
    assert!(matches!(
        ml.with_tolerance(f64::NAN),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::Tolerance,
            ..
        })
    ));
    assert!(matches!(
        ml.with_memory(0),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::Memory,
            ..
        })
    ));
    let never = |_: &[f64]| -> Result<f64, NoiseIdError> { unreachable!() };
    assert!(matches!(
        ml.maximize(never, &[]),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::InitialParameter,
            ..
        })
    ));
    assert!(matches!(
        ml.maximize(never, &[f64::NAN]),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::InitialParameter,
            ..
        })
    ));
    // Data: non-finite, all missing.
    let (process, sensor) = walk_model(&[0.0, 0.0]);
    let kf = KalmanFilter::new(walk_prior());
    let mut zs = random_walk_data(1, 10, 0.04, 0.25);
    zs[4] = Some(Vector1::new(f64::INFINITY));
    let inputs = vec![Vector1::zeros(); 10];
    assert_eq!(
        sequence_log_likelihood(&kf, &process, &inputs, 1.0, &sensor, &zs),
        Err(NoiseIdError::NonFiniteData {
            sequence: 0,
            step: 4,
            quantity: estim_core::Quantity::Measurement
        })
    );
    let missing = vec![None; 11];
    assert_eq!(
        sequence_log_likelihood(&kf, &process, &inputs, 1.0, &sensor, &missing),
        Err(NoiseIdError::AllMissing)
    );
    // The objective's own error comes back.
    let failing = |_: &[f64]| Err(NoiseIdError::AllMissing);
    assert_eq!(ml.maximize(failing, &[0.0]), Err(NoiseIdError::AllMissing));
}

#[test]
fn agrees_with_em_at_the_optimum() {
    use estim_filters::noise_id::em::estimate;
    use estim_filters::noise_id::{CovarianceStructure, EmSettings, LinearGaussian, Record};
    // Two sequences, some measurements missing: both routes maximise the same ℓ.
    let steps = 300;
    let mut runs: Vec<_> = (0..2)
        .map(|s| random_walk_data(40 + s, steps, 0.04, 0.25))
        .collect();
    for k in (3..steps).step_by(7) {
        runs[0][k] = None;
    }
    let inputs = vec![Vector1::zeros(); steps];
    let (process, measurement) = walk_model(&[0.0, 0.0]);
    let start = LinearGaussian {
        process,
        measurement,
        prior: walk_prior(),
    };
    let settings = EmSettings::new()
        .with_process_noise(CovarianceStructure::Full)
        .with_measurement_noise(CovarianceStructure::Full)
        .with_iterations(5000, 1e-14)
        .unwrap();
    let records: Vec<_> = runs
        .iter()
        .map(|zs| Record {
            inputs: &inputs,
            measurements: zs,
        })
        .collect();
    let em = estimate(&start, &settings, &records).unwrap();
    assert!(em.converged);
    let ml = MaximumLikelihood::new()
        .maximize(
            |theta| runs.iter().map(|zs| walk_log_likelihood(theta, zs)).sum(),
            &[0.0, 0.0],
        )
        .unwrap();
    let se = ml.standard_errors().unwrap();
    let em_theta = [
        em.model.process.noise[(0, 0)].ln(),
        em.model.measurement.noise[(0, 0)].ln(),
    ];
    for i in 0..2 {
        // Both at the same maximum: a difference of 1 % of a standard error changes ℓ by
        // 0.5·10⁻⁴, far above where either stops (EM: ℓ gains < 10⁻¹⁴ (1 + |ℓ|) per
        // iteration; L-BFGS + Newton: gradient ~10⁻⁹).
        assert!(
            (em_theta[i] - ml.parameters[i]).abs() < 0.01 * se[i],
            "parameter {i}: EM {} ML {} se {}",
            em_theta[i],
            ml.parameters[i],
            se[i]
        );
    }
    assert!((em.log_likelihood - ml.log_likelihood).abs() < 1e-6 * ml.log_likelihood.abs());
}
