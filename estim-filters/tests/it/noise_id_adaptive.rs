//! Covariance matching of R ([`MeasurementNoiseMatching`]): convergence on a stationary
//! problem with the spread its docs predict (measured over seeds), tracking of a step change,
//! the indefinite case, and bad input.

use estim_core::nalgebra::{Matrix1, Matrix2, Vector1, Vector2};
use estim_core::{Error, Gaussian, LinearMeasurement, LinearProcess, Quantity};
use estim_filters::noise_id::{MeasurementNoiseMatching, NoiseIdError, Setting};
use estim_filters::{KalmanFilter, Predict, Ukf, Update, UpdateOutcome, UpdateReport};

use crate::common::{normal, rng};

type Walk = LinearProcess<f64, estim_core::nalgebra::U1, estim_core::nalgebra::U1>;

/// A scalar random walk with Q = `q`.
fn walk(q: f64) -> Walk {
    LinearProcess {
        transition: Matrix1::new(1.0),
        input: Matrix1::zeros(),
        noise: Matrix1::new(q),
    }
}

/// Runs a Kalman filter with adaptive R over `steps` steps of a random walk (Q = 0.01) whose
/// measurement noise variance at step k is `r_true(k)`; returns R̂ after every step.
fn run(seed: u64, steps: usize, window: f64, r_true: impl Fn(usize) -> f64) -> Vec<f64> {
    let process = walk(0.01);
    let sensor = LinearMeasurement {
        observation: Matrix1::new(1.0),
        noise: Matrix1::new(2.0),
    };
    let mut adaptive = MeasurementNoiseMatching::new(sensor.noise, window, 1e-6).unwrap();
    let mut kf = KalmanFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap());
    let (mut rng, mut x) = (rng(seed), 0.0);
    let mut history = Vec::with_capacity(steps);
    for k in 0..steps {
        x += 0.1 * normal(&mut rng);
        kf.predict(&process, &Vector1::zeros(), 1.0).unwrap();
        let z = x + r_true(k).sqrt() * normal(&mut rng);
        let report = kf
            .update(&adaptive.model(&sensor), &Vector1::new(z))
            .unwrap();
        assert!(adaptive.observe(&report).unwrap());
        history.push(adaptive.noise()[(0, 0)]);
    }
    history
}

/// The steady-state innovation variance S of the random walk (Q = 0.01) with noise R: the
/// Riccati fixed point P⁻ = P⁻R/(P⁻ + R) + Q, S = P⁻ + R.
fn steady_innovation_variance(r: f64) -> f64 {
    let q = 0.01;
    let p = 0.5 * (q + (q * q + 4.0 * q * r).sqrt());
    p + r
}

#[test]
fn converges_to_the_true_r_with_the_predicted_spread() {
    let (window, r) = (200.0, 0.5);
    let finals: Vec<f64> = (0..16)
        .map(|seed| *run(100 + seed, 3000, window, |_| r).last().unwrap())
        .collect();
    let n = finals.len() as f64;
    let mean = finals.iter().sum::<f64>() / n;
    let sd = (finals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    // The docs' spread: Var d = 2 S² for a scalar, EWMA variance Var d / (2L − 1).
    let s = steady_innovation_variance(r);
    let predicted = (2.0 * s * s / (2.0 * window - 1.0)).sqrt();
    // The mean of 16 finals is within 4 standard errors of R (bias would show here).
    assert!(
        (mean - r).abs() < 4.0 * predicted / n.sqrt(),
        "mean {mean}, predicted sd {predicted}"
    );
    // The sample sd of 16 draws is within [0.5, 1.6] of σ with probability > 0.99
    // (χ²₁₅ quantiles 4.6 and 37.7 → √(4.6/15) = 0.55, √(37.7/15) = 1.59).
    assert!(
        (0.5..1.6).contains(&(sd / predicted)),
        "sd {sd}, predicted {predicted}"
    );
}

#[test]
fn tracks_a_step_change() {
    let window = 100.0;
    let (before, after, change) = (0.5, 2.0, 2000);
    let history = run(7, 4000, window, |k| if k < change { before } else { after });
    // Per-time sd of R̂ (the docs' formula), 4σ bands.
    let sigma = |r: f64| {
        let s = steady_innovation_variance(r);
        (2.0 * s * s / (2.0 * window - 1.0)).sqrt()
    };
    let at_change = history[change - 1];
    assert!(
        (at_change - before).abs() < 4.0 * sigma(before),
        "{at_change}"
    );
    // Time constant L: after 10 L the start is forgotten to e^-10.
    let settled = history[change + 1000 - 1];
    assert!((settled - after).abs() < 4.0 * sigma(after), "{settled}");
    // And after one window it has moved well off the old value (1 − e⁻¹ of the way, less noise).
    let one_window = history[change + window as usize];
    assert!(one_window > before + 0.3 * (after - before), "{one_window}");
}

#[test]
fn an_indefinite_statistic_is_clipped_to_the_floor() {
    // A filter far too pessimistic (Q = 10 assumed, 0.01 true) with a precise sensor: the
    // predicted output covariance H P⁻ Hᵀ ≈ 10 exceeds every innovation covariance estimate,
    // so C = mean(ν²) − H P⁻ Hᵀ < 0.
    let process = walk(10.0);
    let sensor = LinearMeasurement {
        observation: Matrix1::new(1.0),
        noise: Matrix1::new(0.1),
    };
    let floor = 1e-3;
    let mut adaptive = MeasurementNoiseMatching::new(sensor.noise, 20.0, floor).unwrap();
    let mut kf = KalmanFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap());
    let (mut rng, mut x) = (rng(11), 0.0);
    for _ in 0..200 {
        x += 0.1 * normal(&mut rng);
        kf.predict(&process, &Vector1::zeros(), 1.0).unwrap();
        let z = x + 0.01 * normal(&mut rng);
        let report = kf
            .update(&adaptive.model(&sensor), &Vector1::new(z))
            .unwrap();
        adaptive.observe(&report).unwrap();
    }
    assert!(adaptive.statistic()[(0, 0)] < 0.0);
    assert_eq!(adaptive.clipped(), 1);
    assert_eq!(adaptive.noise()[(0, 0)], floor);
}

#[test]
fn works_with_the_ukf_on_two_components() {
    // A 2-D random walk seen directly; true R = diag(0.3, 1.2) with correlation 0.2.
    let process = LinearProcess {
        transition: Matrix2::identity(),
        input: Matrix2::zeros(),
        noise: Matrix2::identity() * 0.01,
    };
    let sensor = LinearMeasurement {
        observation: Matrix2::identity(),
        noise: Matrix2::identity(),
    };
    let r_true = Matrix2::new(0.3, 0.2, 0.2, 1.2);
    let l = r_true.cholesky().unwrap().unpack();
    let mut adaptive = MeasurementNoiseMatching::new(sensor.noise, 2000.0, 1e-6).unwrap();
    let mut ukf = Ukf::new(Gaussian::new(Vector2::zeros(), Matrix2::identity()).unwrap());
    let (mut rng, mut x) = (rng(5), Vector2::zeros());
    for _ in 0..8000 {
        x += Vector2::new(normal(&mut rng), normal(&mut rng)) * 0.1;
        ukf.predict(&process, &Vector2::zeros(), 1.0).unwrap();
        let z = x + l * Vector2::new(normal(&mut rng), normal(&mut rng));
        let report = ukf.update(&adaptive.model(&sensor), &z).unwrap();
        adaptive.observe(&report).unwrap();
    }
    // σ of an entry ≈ √((SᵢᵢSⱼⱼ + Sᵢⱼ²) / (2L − 1)) ≤ √(2 · 1.3² / 3999) ≈ 0.03: 4σ = 0.12.
    let error = (adaptive.noise() - r_true).abs().max();
    assert!(error < 0.12, "{}", adaptive.noise());
}

#[test]
fn bad_settings_and_reports_are_typed_errors_that_change_nothing() {
    let r = Matrix1::new(1.0);
    for (window, floor, setting) in [
        (0.5, 1e-6, Setting::Window),
        (f64::NAN, 1e-6, Setting::Window),
        (f64::INFINITY, 1e-6, Setting::Window),
        (10.0, 0.0, Setting::Floor),
        (10.0, f64::NAN, Setting::Floor),
    ] {
        match MeasurementNoiseMatching::new(r, window, floor) {
            Err(NoiseIdError::InvalidSetting { setting: s, .. }) => assert_eq!(s, setting),
            other => panic!("{other:?}"),
        }
    }
    assert!(matches!(
        MeasurementNoiseMatching::new(Matrix1::new(f64::NAN), 10.0, 1e-6),
        Err(NoiseIdError::Model(Error::NonFinite { .. }))
    ));
    // A runtime-sized R that is not square (it panicked, in the symmetry check or in the
    // symmetric part).
    for (rows, cols) in [(2, 3), (3, 2)] {
        assert!(matches!(
            MeasurementNoiseMatching::new(
                estim_core::nalgebra::DMatrix::<f64>::identity(rows, cols),
                10.0,
                1e-6
            ),
            Err(NoiseIdError::Model(Error::DimensionMismatch {
                quantity: Quantity::MeasurementNoise,
                ..
            }))
        ));
    }
    let mut adaptive = MeasurementNoiseMatching::new(r, 10.0, 1e-6).unwrap();
    let before = adaptive.clone();
    let bad = UpdateReport {
        innovation: Vector1::new(f64::NAN),
        innovation_covariance: Matrix1::new(2.0),
        nis: f64::NAN,
        log_likelihood: f64::NAN,
        outcome: UpdateOutcome::Applied,
        iterations: None,
    };
    assert!(matches!(
        adaptive.observe(&bad),
        Err(NoiseIdError::Model(Error::NonFinite {
            quantity: Quantity::Innovation,
            ..
        }))
    ));
    assert_eq!(adaptive, before);
    // A gated update is not used.
    let gated = UpdateReport {
        outcome: UpdateOutcome::Gated,
        innovation: Vector1::new(100.0),
        ..bad
    };
    assert!(!adaptive.observe(&gated).unwrap());
    assert_eq!(adaptive, before);
}

/// Issue 41, defect 3: finite input whose R̂ overflows was accepted. `new` with entries
/// ±f64::MAX gave R̂ = ±∞ (C's eigenvalues 2·MAX = ∞ and 0, raised to the floor, recomposed),
/// and from 10³⁰⁰ I one report with ν = (10¹⁵⁴, −10¹⁵⁴), S = I gave `Ok(true)` and −∞
/// off-diagonals, after which every `observe` failed. Both are typed errors now, the
/// estimator unchanged.
#[test]
fn input_whose_estimate_would_overflow_is_refused() {
    let overflow = |e: Result<(), &NoiseIdError>| {
        matches!(
            e,
            Err(NoiseIdError::Model(Error::NonFinite {
                quantity: Quantity::MeasurementNoise,
                ..
            }))
        )
    };
    let max = f64::MAX;
    let huge = MeasurementNoiseMatching::new(Matrix2::new(max, -max, -max, max), 10.0, 1e-6);
    assert!(overflow(huge.as_ref().map(|_| ())), "{huge:?}");
    let mut adaptive =
        MeasurementNoiseMatching::new(Matrix2::identity() * 1e300, 10.0, 1e-6).unwrap();
    let before = adaptive.clone();
    let report = UpdateReport {
        innovation: Vector2::new(1e154, -1e154),
        innovation_covariance: Matrix2::identity(),
        nis: 0.0,
        log_likelihood: 0.0,
        outcome: UpdateOutcome::Applied,
        iterations: None,
    };
    let result = adaptive.observe(&report);
    assert!(overflow(result.as_ref().map(|_| ())), "{result:?}");
    assert_eq!(adaptive, before);
    // Still usable: an ordinary report is taken.
    let ordinary = UpdateReport {
        innovation: Vector2::new(1.0, -1.0),
        ..report
    };
    assert!(adaptive.observe(&ordinary).unwrap());
    assert!(adaptive.noise().iter().all(|v: &f64| v.is_finite()));
}

/// Issue 41, defect 3: R̂ is exactly symmetric, as documented, also when the initial R is
/// symmetric only within `new`'s tolerance (√ε relative), and after clipped updates with
/// reports whose S is not exactly symmetric (seeded random 3 × 3 reports).
#[test]
fn the_estimate_is_exactly_symmetric() {
    use estim_core::nalgebra::{Matrix3, Vector3};
    let exactly_symmetric =
        |r: &Matrix3<f64>| (0..3).all(|i| (0..3).all(|j| r[(i, j)] == r[(j, i)]));
    let mut initial = Matrix3::new(2.0, 0.5, 0.1, 0.5, 1.0, 0.2, 0.1, 0.2, 3.0);
    initial[(1, 0)] += 1e-12; // within √ε · 3 ≈ 4.5·10⁻⁸
    let mut adaptive = MeasurementNoiseMatching::new(initial, 5.0, 1e-3).unwrap();
    assert!(exactly_symmetric(adaptive.noise()), "{}", adaptive.noise());
    let mut r = rng(41);
    let mut clipped_steps = 0;
    for _ in 0..200 {
        let nu = Vector3::from_fn(|_, _| normal(&mut r));
        let a = Matrix3::from_fn(|_, _| normal(&mut r));
        let mut s = a * a.transpose() * 4.0;
        s[(2, 0)] *= 1.0 + 1e-14;
        let report = UpdateReport {
            innovation: nu,
            innovation_covariance: s,
            nis: 0.0,
            log_likelihood: 0.0,
            outcome: UpdateOutcome::Applied,
            iterations: None,
        };
        adaptive.observe(&report).unwrap();
        assert!(exactly_symmetric(adaptive.noise()), "{}", adaptive.noise());
        assert!(exactly_symmetric(adaptive.statistic()));
        clipped_steps += usize::from(adaptive.clipped() > 0);
    }
    // S ≫ ν νᵀ makes the statistic indefinite: the recomposed (clipped) R̂ is exercised.
    assert!(clipped_steps > 0);
}
