//! A real log through the driver: repeated readings (the duplicate policies), the default
//! step (no subdivision), and the log-likelihood of a run with late readings, which equals a
//! plain filter's over the same readings in time order.

use estim_core::nalgebra::{Matrix1, U1, U2, Vector1};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
use estim_filters::fusion::{
    DuplicatePolicy, FusionDriver, FusionError, FusionSettings, Innovation, SensorSet,
    SensorSettings,
};
use estim_filters::smoother::{ReadingsError, filter_readings, smooth_readings};
use estim_filters::{Estimator, KalmanFilter, Predict, Update};

use crate::fusion_support::{
    Cart, CartDriver, ConstantVelocity, Q, Reading, kf_driver, measurements, prior, settings,
    snapshot,
};

fn position(z: f64) -> Reading {
    Reading::Position(Vector1::new(z))
}

#[test]
fn duplicate_readings_follow_the_policy_and_refusing_changes_nothing() {
    let make = |duplicates| {
        FusionDriver::new(
            KalmanFilter::new(prior()),
            ConstantVelocity { q: Q },
            (),
            Cart::new(),
            0.0,
            // One prediction per gap, as the plain filter below.
            FusionSettings {
                duplicates,
                max_step: f64::INFINITY,
                ..settings()
            },
            SensorSettings::default(),
        )
        .unwrap()
    };
    // Default: both fused, as two readings with independent noise.
    assert_eq!(
        FusionSettings::default().duplicates,
        DuplicatePolicy::FuseBoth
    );
    let mut both = make(DuplicatePolicy::FuseBoth);
    both.fuse(0.1, position(0.2)).unwrap();
    let second = both.fuse(0.1, position(0.3)).unwrap();
    assert!(!second.ignored && second.outcome.applied());
    // The same as one plain filter updated twice at 0.1 s.
    let mut kf = KalmanFilter::new(prior());
    kf.predict(&ConstantVelocity { q: Q }, &(), 0.1).unwrap();
    let cart = Cart::new();
    kf.update(&cart.position, &Vector1::new(0.2)).unwrap();
    kf.update(&cart.position, &Vector1::new(0.3)).unwrap();
    assert_eq!(both.filter().estimate(), kf.estimate());

    // A late duplicate goes after the first one (arrival order) and replays what follows.
    both.fuse(0.2, position(0.5)).unwrap();
    let late = both.fuse(0.1, position(0.25)).unwrap();
    assert_eq!(late.replayed, 1);
    assert_eq!(both.decisions().filter(|d| d.0 == 0.1).count(), 3);

    // Keep first: the second is ignored and reported as such; nothing changes.
    let mut first = make(DuplicatePolicy::KeepFirst);
    let kept = first.fuse(0.1, position(0.2)).unwrap();
    let before = snapshot(&first);
    let ignored = first.fuse(0.1, position(9.0)).unwrap();
    assert!(ignored.ignored && ignored.outcome == kept.outcome);
    assert_eq!(snapshot(&first), before);

    // Refuse: the typed error names sensor and time; nothing changes.
    let mut refuse = make(DuplicatePolicy::Refuse);
    refuse.fuse(0.1, position(0.2)).unwrap();
    let before = snapshot(&refuse);
    let error = refuse.fuse(0.1, position(0.3)).unwrap_err();
    assert_eq!(
        error,
        FusionError::Duplicate {
            sensor: 0,
            time: 0.1
        }
    );
    assert!(error.to_string().contains("FusionSettings::duplicates"));
    assert_eq!(snapshot(&refuse), before);
}

/// One scalar sensor for a model whose Q is per call (a `LinearProcess` ignores Δt).
struct One(LinearMeasurement<f64, U1, U1>);

impl<F: Update<f64, U1, U1, LinearMeasurement<f64, U1, U1>>> SensorSet<f64, U1, F> for One {
    type Reading = Vector1<f64>;
    fn count(&self) -> usize {
        1
    }
    fn sensor(&self, _: &Vector1<f64>) -> usize {
        0
    }
    fn dimension(&self, _: usize) -> usize {
        1
    }
    fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> {
        f.update(&self.0, z).map(|r| Innovation::of(&r))
    }
}

#[test]
fn the_default_step_predicts_once_per_gap_and_errors_name_the_setting() {
    let walk = LinearProcess {
        transition: Matrix1::new(1.0),
        input: Matrix1::zeros(),
        noise: Matrix1::new(0.01),
    };
    let sensor = One(LinearMeasurement {
        observation: Matrix1::new(1.0),
        noise: Matrix1::new(0.1),
    });
    let start = Gaussian::new(Vector1::zeros(), Matrix1::new(1.0)).unwrap();
    let mut driver = FusionDriver::new(
        KalmanFilter::new(start.clone()),
        walk.clone(),
        Vector1::zeros(),
        sensor,
        0.0,
        FusionSettings::default(),
        SensorSettings::default(),
    )
    .unwrap();
    // A 0.2 s odometry interval: one prediction (Q added once), not 20.
    driver.advance_to(0.2).unwrap();
    let mut kf = KalmanFilter::new(start);
    kf.predict(&walk, &Vector1::zeros(), 0.2).unwrap();
    assert_eq!(driver.filter().estimate(), kf.estimate());
    // Asked for sub-steps, a gap beyond max_substeps names both settings to change.
    let message = FusionError::GapTooLong {
        gap: 10.0,
        max_step: 0.01,
    }
    .to_string();
    assert!(message.contains("FusionSettings::max_substeps") && message.contains("max_step"));
    let too_old = FusionError::TooOld {
        time: 0.0,
        oldest: 1.0,
    }
    .to_string();
    assert!(too_old.contains("FusionSettings::horizon"));
}

#[test]
fn the_log_likelihood_of_a_run_with_late_readings_is_the_time_ordered_one() {
    let (_, taken) = measurements(11, 120);
    // Delivered late: each reading 3 grid steps (30 ms, inside the 0.5 s horizon) after it
    // was taken, in arrival order.
    let mut arrivals: Vec<_> = taken.iter().map(|m| (m.step + 3, *m)).collect();
    arrivals.sort_by_key(|a| a.0);
    let mut driver = kf_driver(SensorSettings::default());
    for (arrival, m) in &arrivals {
        driver.advance_to(*arrival as f64 * 0.01 - 0.03).ok();
        driver.fuse(m.time(), m.reading).unwrap();
    }
    // A plain filter over the same readings in time order.
    let (cart, model) = (Cart::new(), ConstantVelocity { q: Q });
    let (mut kf, mut t, mut expected) = (KalmanFilter::new(prior()), 0.0, 0.0);
    for m in &taken {
        if m.time() > t {
            kf.predict(&model, &(), m.time() - t).unwrap();
            t = m.time();
        }
        let report = match m.reading {
            Reading::Position(z) => kf.update(&cart.position, &z),
            Reading::Velocity(z) => kf.update(&cart.velocity, &z),
            Reading::Unknown => unreachable!(),
        };
        expected += report.unwrap().log_likelihood;
    }
    // The driver predicts in sub-steps of the grid and the advance marks split gaps, so the
    // moments agree to round-off of ~10² steps (exact discretisation), not to the bit:
    // 1e-9 relative.
    let got = driver.log_likelihood();
    assert!(
        (got - expected).abs() <= 1e-9 * expected.abs(),
        "{got} vs {expected}"
    );
}

/// The cart's readings of `measurements(seed, 120)` as a log `(time, reading)` in time order
/// (sensor 0 before 1 at equal times, the driver's order), and the driver fed them 3 grid
/// steps late, in arrival order, with one prediction per gap.
type Log = Vec<(f64, Reading)>;

fn late_run(seed: u64, q: f64) -> (Log, CartDriver<KalmanFilter<f64, U2>>) {
    let (_, taken) = measurements(seed, 120);
    let log: Vec<_> = taken.iter().map(|m| (m.time(), m.reading)).collect();
    let mut arrivals: Vec<_> = taken.iter().map(|m| (m.step + 3, *m)).collect();
    arrivals.sort_by_key(|a| a.0);
    let mut driver = FusionDriver::new(
        KalmanFilter::new(prior()),
        ConstantVelocity { q },
        (),
        Cart::new(),
        0.0,
        FusionSettings {
            max_step: f64::INFINITY,
            ..settings()
        },
        SensorSettings::default(),
    )
    .unwrap();
    for (_, m) in &arrivals {
        driver.fuse(m.time(), m.reading).unwrap();
    }
    (log, driver)
}

/// The driver's run (late readings replayed) smoothed equals the batch RTS of the same log in
/// time order: the same times, and moments equal to round-off. The filtered estimates are
/// bit-identical (the replay is); the two backward passes then run the same arithmetic, so
/// 1e-12 relative is generous. Smoothing leaves the driver as it was.
#[test]
fn the_driver_run_smoothed_is_the_batch_smoother_of_the_sorted_log() {
    let (log, mut driver) = late_run(5, Q);
    let before = snapshot(&driver);
    let track = driver.smooth().unwrap();
    assert_eq!(snapshot(&driver), before);
    let batch = smooth_readings(
        &mut KalmanFilter::new(prior()),
        &ConstantVelocity { q: Q },
        |_| (),
        &Cart::new(),
        0.0,
        &log,
    )
    .unwrap();
    assert_eq!(track.times, batch.track.times);
    assert_eq!(track.estimates.len(), batch.track.estimates.len());
    for (a, b) in track.estimates.iter().zip(&batch.track.estimates) {
        let scale = 1.0 + b.mean().amax().max(b.covariance().amax());
        assert!((a.mean() - b.mean()).amax() <= 1e-12 * scale);
        assert!((a.covariance() - b.covariance()).amax() <= 1e-12 * scale);
    }
    // And its log-likelihood is the batch's (same filtered run: 1e-12 relative).
    let ll = driver.log_likelihood();
    assert!((ll - batch.log_likelihood).abs() <= 1e-12 * ll.abs());
}

/// Bad logs are typed errors naming the reading, and the filter is as it was.
#[test]
fn bad_logs_name_the_reading_and_leave_the_filter_unchanged() {
    let (log, _) = late_run(7, Q);
    let (model, cart) = (ConstantVelocity { q: Q }, Cart::new());
    let mut kf = KalmanFilter::new(prior());
    kf.update(&cart.position, &Vector1::new(0.1)).unwrap();
    let before = kf.estimate();
    let mut run = |log: &[(f64, Reading)]| {
        let error = filter_readings(&mut kf, &model, |_| (), &cart, 0.0, log).unwrap_err();
        let smoothed = smooth_readings(&mut kf, &model, |_| (), &cart, 0.0, log).unwrap_err();
        // Compared as text: a NaN time is not equal to itself.
        assert_eq!(error.to_string(), smoothed.to_string());
        error
    };
    let mut unsorted = log.clone();
    unsorted.swap(3, 4);
    assert!(matches!(
        run(&unsorted),
        ReadingsError::NotSorted { index: 4, .. }
    ));
    let mut unknown = log.clone();
    unknown[2].1 = Reading::Unknown;
    assert_eq!(
        run(&unknown),
        ReadingsError::UnknownSensor {
            index: 2,
            sensor: 5,
            count: 2
        }
    );
    let mut nan_time = log.clone();
    nan_time[6].0 = f64::NAN;
    assert!(matches!(
        run(&nan_time),
        ReadingsError::NonFiniteTime { index: Some(6), .. }
    ));
    // A NaN reading fails inside the filter, after the readings before it ran.
    let mut nan = log.clone();
    nan[9].1 = position(f64::NAN);
    let error = run(&nan);
    assert!(
        matches!(error, ReadingsError::Step { index: 9, .. }),
        "{error}"
    );
    assert!(error.to_string().contains("reading 9"));
    assert_eq!(kf.estimate(), before);
}

/// Maximum likelihood of the process noise over a driver run with late readings finds what it
/// finds over the batch log: the two log-likelihoods are the same function of q (to 1e-12
/// relative, previous test), so the optima agree to the optimiser's tolerance (1e-6 in ln q,
/// far below the standard error of ~0.3).
#[cfg(feature = "likelihood")]
#[test]
fn ml_over_a_driver_run_equals_ml_over_the_batch() {
    use estim_filters::noise_id::{MaximumLikelihood, NoiseIdError};
    let (log, _) = late_run(9, Q);
    let over_driver = |theta: &[f64]| -> Result<f64, NoiseIdError> {
        Ok(late_run(9, theta[0].exp()).1.log_likelihood())
    };
    let over_batch = |theta: &[f64]| -> Result<f64, NoiseIdError> {
        let model = ConstantVelocity { q: theta[0].exp() };
        let mut kf = KalmanFilter::new(prior());
        let run = filter_readings(&mut kf, &model, |_| (), &Cart::new(), 0.0, &log).unwrap();
        Ok(run.log_likelihood)
    };
    let ml = MaximumLikelihood::new();
    let a = ml.maximize(over_driver, &[0.0]).unwrap();
    let b = ml.maximize(over_batch, &[0.0]).unwrap();
    assert!((a.parameters[0] - b.parameters[0]).abs() < 1e-6);
    assert!((a.log_likelihood - b.log_likelihood).abs() <= 1e-9 * b.log_likelihood.abs());
}
