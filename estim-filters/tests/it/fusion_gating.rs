//! The driver's decisions: the gate (a 100 σ outlier rejected with its test ratio, the clean
//! false-rejection rate equal to the gate's χ² tail), the fault monitor (a stuck channel
//! excluded within the derived bound, readmitted when it recovers) and the reset (it restores
//! consistency after the filter lost the truth).

use estim_core::Gaussian;
use estim_core::nalgebra::{Matrix2, Vector1, Vector2};
use estim_filters::consistency::{ChiSquareBand, nees};
use estim_filters::fusion::{
    ExclusionReason, MonitorSettings, Outcome, ResetReason, ResetSettings, SensorSettings,
    SensorStatus,
};
use estim_filters::{Estimator, KalmanFilter};

use crate::common::{normal, rng};
use crate::fusion_support::{
    GRID, POSITION_SIGMA, Q, Reading, driver, kf_driver, measurements, noise, prior, read,
};

#[test]
fn a_100_sigma_outlier_is_rejected_with_its_test_ratio() {
    let (truth, taken) = measurements(7, 200);
    let mut d = kf_driver(SensorSettings::gated(0.9999));
    let mut twin = kf_driver(SensorSettings::gated(0.9999));
    for m in &taken {
        d.fuse(m.time(), m.reading).unwrap();
        twin.fuse(m.time(), m.reading).unwrap();
    }
    let (x, p) = (*d.filter().state(), *d.filter().covariance());
    let t = d.time() + 0.05;
    let step = (t / GRID).round() as usize;
    let z = truth[step.min(truth.len() - 1)][0] + 100.0 * POSITION_SIGMA;
    let fused = d.fuse(t, Reading::Position(Vector1::new(z))).unwrap();
    // The independent route: one exact-discretisation step over the whole gap.
    let dt = t - twin.time();
    let f = Matrix2::new(1.0, dt, 0.0, 1.0);
    let (xp, pp) = (f * x, f * p * f.transpose() + noise(Q, dt));
    let s = pp[(0, 0)] + POSITION_SIGMA * POSITION_SIGMA;
    let nu = z - xp[0];
    let gate = d.gate(0).unwrap();
    // χ²₁ quantile at 0.9999 (tables: 15.137).
    assert!((gate - 15.137).abs() < 1e-3, "{gate}");
    let Outcome::Rejected {
        innovation,
        test_ratio,
    } = fused.outcome
    else {
        panic!("{:?}", fused.outcome)
    };
    // The driver predicts in 5 sub-steps; the exact discretisation makes that one step up to
    // rounding (≈ 1e-15 relative); 1e-9 leaves room for the Joseph-form updates before.
    assert!((innovation.nis - nu * nu / s).abs() < 1e-9 * innovation.nis);
    assert!((test_ratio - innovation.nis / gate).abs() < 1e-12 * test_ratio);
    assert!(test_ratio > 100.0 * 100.0 * POSITION_SIGMA.powi(2) / s / gate * 0.9);
    assert!((innovation.normalized()[0] - nu / s.sqrt()).abs() < 1e-9 * innovation.largest);
    assert_eq!(d.health(0).rejected, 1);
    // The estimate is the prediction to t, exactly: as a driver that only advanced to t.
    twin.advance_to(t).unwrap();
    assert_eq!(d.filter().state(), twin.filter().state());
    assert_eq!(d.filter().covariance(), twin.filter().covariance());
}

/// The NIS of one measurement of a consistent filter is χ²₁, so the gate at 0.99 rejects it with
/// probability 0.01. Each run tests one gated velocity fix after ungated position fixes: a
/// rejection changes the next NIS's distribution (a rejected fix was informative), so only the
/// first gated fix of a run is exactly χ².
#[test]
fn false_rejection_rate_on_clean_data_is_the_gates_tail_probability() {
    let probability = 0.99;
    let runs = 4000u64;
    let mut rejected = 0u64;
    for seed in 0..runs {
        let (_, taken) = measurements(1000 + seed, 60);
        let mut d = kf_driver(SensorSettings::default())
            .with_sensor_settings(1, SensorSettings::gated(probability))
            .unwrap();
        let mut velocity_fixes = 0;
        for m in &taken {
            if let Reading::Velocity(_) = m.reading {
                if m.step < 56 {
                    continue;
                }
                velocity_fixes += 1;
            }
            d.fuse(m.time(), m.reading).unwrap();
        }
        assert_eq!(velocity_fixes, 1);
        let h = d.health(1);
        assert_eq!(h.rejected + h.accepted, 1);
        rejected += h.rejected;
    }
    // Binomial(4000, 0.01): ±4.5 standard deviations (two-sided tail ≈ 7e-6).
    let n = runs as f64;
    let (mean, sd) = (
        n * (1.0 - probability),
        (n * probability * (1.0 - probability)).sqrt(),
    );
    assert!(
        (rejected as f64 - mean).abs() < 4.5 * sd,
        "{rejected} rejections of {runs}, expected {mean} ± {sd}"
    );
}

#[test]
fn a_stuck_position_channel_is_excluded_within_the_derived_bound_and_readmitted() {
    let window = 20;
    let monitor = MonitorSettings {
        window,
        false_alarm: 1e-3,
        clip_probability: 0.99,
    };
    let settings = SensorSettings::gated(0.9999)
        .with_monitor(monitor)
        .with_reset(ResetSettings {
            after_rejections: 3,
            states: vec![0, 1],
            variance: 1e4,
            blow_up_variance: None,
        });
    let mut r = rng(11);
    // A cart at 2 m/s; position fixes every 0.1 s, velocity fixes every 0.07 s.
    let mut x = Vector2::new(0.0, 2.0);
    let lq = noise(Q, GRID).cholesky().unwrap().l();
    let prior = Gaussian::new(x, Matrix2::new(0.01, 0.0, 0.0, 0.01)).unwrap();
    let mut d = driver(KalmanFilter::new(prior), settings);
    let (q, c) = d.monitor_thresholds(0).unwrap();
    // q = χ²₂₀(0.999) = 45.31, c = χ²₁(0.99) = 6.635: a channel whose every NIS exceeds c is
    // detected within ⌈q / c⌉ = 7 deliveries (the window then holds ≥ 7 c > q, whatever else).
    let bound = (q / c).ceil() as usize;
    assert_eq!(bound, 7);
    let (stuck_from, stuck_until, steps) = (100, 600, 1200);
    let mut stuck_value = 0.0;
    let mut position = Vec::new(); // (step, outcome) of position deliveries while stuck and after
    for step in 1..=steps {
        x = Vector2::new(x[0] + GRID * x[1], x[1])
            + lq * Vector2::new(normal(&mut r), normal(&mut r));
        let t = step as f64 * GRID;
        if step % 10 == 0 {
            let mut reading = read(&mut r, 0, &x);
            if (stuck_from..stuck_until).contains(&step) {
                if let (true, Reading::Position(z)) = (step == stuck_from, reading) {
                    stuck_value = z[0];
                }
                reading = Reading::Position(Vector1::new(stuck_value));
            }
            let fused = d.fuse(t, reading).unwrap();
            if step >= stuck_from {
                position.push((step, fused.outcome));
            }
        }
        if step % 7 == 0 {
            let fused = d.fuse(t, read(&mut r, 1, &x)).unwrap();
            // The velocity sensor stays good throughout: never blamed, never reset.
            assert!(
                matches!(
                    fused.outcome,
                    Outcome::Accepted { .. } | Outcome::Rejected { .. }
                ),
                "{:?}",
                fused.outcome
            );
        }
    }
    let detected = position
        .iter()
        .position(|(_, o)| {
            matches!(
                o,
                Outcome::Excluded {
                    reason: ExclusionReason::FaultDetected { .. },
                    ..
                }
            )
        })
        .expect("the stuck channel must be detected");
    let first_over = position
        .iter()
        .position(|(_, o)| o.innovation().nis > c)
        .unwrap();
    // The bound's premise: from the first NIS over c to the detection, every NIS is over c.
    assert!(
        position[first_over..=detected]
            .iter()
            .all(|(_, o)| o.innovation().nis > c)
    );
    assert!(
        detected - first_over < bound,
        "detected {} deliveries after the first NIS over c",
        detected - first_over + 1
    );
    // No reset: the velocity sensor was accepted during the run of rejections.
    assert_eq!(d.health(0).resets, 0);
    // Excluded while stuck, readmitted within a window of the recovery (a clean window passes
    // with probability 1 − α = 0.999), accepted again after.
    let recovered = position
        .iter()
        .position(|(s, _)| *s >= stuck_until)
        .unwrap();
    assert!(
        position[detected..recovered]
            .iter()
            .all(|(_, o)| matches!(o, Outcome::Excluded { .. }))
    );
    let readmitted = position
        .iter()
        .position(|(_, o)| {
            matches!(
                o,
                Outcome::Excluded {
                    reason: ExclusionReason::Readmitted { .. },
                    ..
                }
            )
        })
        .expect("readmitted after the recovery");
    // The window still holds k stuck values (each counting c) until k < q / c, so at least
    // W − (⌈q/c⌉ − 1) = 14 clean deliveries are needed; after W clean ones the window passes
    // with probability 0.999 (5 more allowed).
    let clean = readmitted + 1 - recovered;
    assert!(
        clean > window - bound && clean <= window + 5,
        "readmitted after {clean} clean deliveries"
    );
    let h = d.health(0);
    assert_eq!(
        (h.status, h.faults, h.readmissions),
        (SensorStatus::Admitted, 1, 1)
    );
    assert!(matches!(
        position.last().unwrap().1,
        Outcome::Accepted { .. }
    ));
}

/// A filter that lost the truth (its mean 50 σ off) with one position sensor: gated only, it
/// rejects every fix for ever; with a reset after three rejections it is consistent again.
#[test]
fn reset_restores_consistency() {
    let runs = 200;
    let band = ChiSquareBand::two_sided(2, runs, 0.99).unwrap();
    for with_reset in [true, false] {
        let mut settings = SensorSettings::gated(0.9999);
        if with_reset {
            settings = settings.with_reset(ResetSettings {
                after_rejections: 3,
                states: vec![0, 1],
                variance: 1e6,
                blow_up_variance: None,
            });
        }
        let mut total = 0.0;
        for run in 0..runs as u64 {
            let (truth, taken) = measurements(5000 + run, 300);
            let p0 = prior();
            let lost =
                Gaussian::new(p0.mean() + Vector2::new(50.0, 0.0), *p0.covariance()).unwrap();
            let mut d = driver(KalmanFilter::new(lost), settings.clone());
            for m in taken
                .iter()
                .filter(|m| matches!(m.reading, Reading::Position(_)))
            {
                let fused = d.fuse(m.time(), m.reading).unwrap();
                if let Outcome::Reset { reason, .. } = fused.outcome {
                    assert_eq!(reason, ResetReason::RejectionRun { rejections: 3 });
                }
            }
            d.advance_to(300.0 * GRID).unwrap();
            assert_eq!(d.health(0).resets, u64::from(with_reset));
            total += nees(&(truth[300] - d.filter().state()), d.filter().covariance()).unwrap();
        }
        let anees = total / runs as f64;
        if with_reset {
            assert!(
                band.contains(anees),
                "after reset: ANEES {anees} outside {band:?}"
            );
        } else {
            assert!(anees > 100.0 * band.upper, "without reset: ANEES {anees}");
        }
    }
}

#[test]
fn a_covariance_blow_up_resets_the_observed_states() {
    let settings = SensorSettings::gated(0.9999).with_reset(ResetSettings {
        after_rejections: 5,
        states: vec![0],
        variance: 1e4,
        blow_up_variance: Some(2.0),
    });
    let mut d = kf_driver(settings);
    // No fix for 3 s: the position variance grows past 2 m² (1 + 0.25 · 3² ≈ 3.3).
    let fused = d.fuse(3.0, Reading::Position(Vector1::new(3.0))).unwrap();
    let Outcome::Reset {
        reason: ResetReason::CovarianceBlowUp { state, variance },
        ..
    } = fused.outcome
    else {
        panic!("{:?}", fused.outcome)
    };
    assert_eq!(state, 0);
    assert!(variance > 2.0);
    // Re-initialised from the fix: the position is the fix up to R / (R + 10⁴), uncorrelated.
    let (x, p) = (d.filter().state(), d.filter().covariance());
    assert!((x[0] - 3.0).abs() < 1e-5 && (p[(0, 0)] - 0.01).abs() < 1e-7 && p[(0, 1)] == 0.0);
}
