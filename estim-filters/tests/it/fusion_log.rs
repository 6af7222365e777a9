//! A real log through the driver: repeated readings (the duplicate policies), the default
//! step (no subdivision), and the log-likelihood of a run with late readings, which equals a
//! plain filter's over the same readings in time order.

use estim_core::nalgebra::{Matrix1, U1, Vector1};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
use estim_filters::fusion::{
    DuplicatePolicy, FusionDriver, FusionError, FusionSettings, Innovation, SensorSet,
    SensorSettings,
};
use estim_filters::{Estimator, KalmanFilter, Predict, Update};

use crate::fusion_support::{
    Cart, ConstantVelocity, Q, Reading, kf_driver, measurements, prior, settings, snapshot,
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
