//! Settings that used to panic, abort on allocation or never return (issue 18, item 4) now
//! return a typed error, checked before anything is allocated: every call here returns at
//! once, none allocates more than a default scenario does.

use estim_core::{Error, Parameter};
use estim_models::boje::{CircleConfig, simulate_circle};
use estim_models::lee_huang::{
    self, FourAccelerometers, OteSettings, SensorConfig, ote_steady_state,
};
use estim_models::limits::{MAX_RUNS, MAX_STEPS, check_runs, steps_for_duration};
use estim_models::lu::{
    FilterSettings, Scenario, covariance_analysis, covariance_history, run_realization, simulate,
};
use nalgebra::Vector3;

fn rejects(result: Result<impl Sized, Error>, parameter: Parameter) {
    match result {
        Err(Error::InvalidParameter { parameter: p, .. }) => assert_eq!(p, parameter),
        Err(e) => panic!("expected InvalidParameter({parameter:?}), got {e:?}"),
        Ok(_) => panic!("expected InvalidParameter({parameter:?}), got Ok"),
    }
}

#[test]
fn lu_simulate_rejects_endless_and_huge_durations() {
    // Formerly "capacity overflow" (∞) and an allocation abort (1e12 s = 2e14 steps).
    for seconds in [f64::INFINITY, 1e12, f64::NAN, -1.0] {
        let scenario = Scenario::paper().with_duration(seconds);
        rejects(simulate(&scenario, 0), Parameter::StepCount);
    }
    // The boundary itself is accepted by the check (not simulated: 10⁷ steps is too slow here).
    let longest = Scenario::paper().with_duration(MAX_STEPS as f64 * 0.005);
    assert_eq!(longest.steps, MAX_STEPS);
    assert!(longest.validate().is_ok());
    rejects(
        Scenario {
            steps: MAX_STEPS + 1,
            ..Scenario::paper()
        }
        .validate(),
        Parameter::StepCount,
    );
}

#[test]
fn lu_runners_reject_endless_runs() {
    let endless = Scenario::paper().with_duration(f64::INFINITY);
    let settings = FilterSettings::consistent(&Scenario::paper());
    // Formerly a hang (usize::MAX filter steps).
    rejects(
        run_realization(&endless, &settings, 0),
        Parameter::StepCount,
    );
    rejects(
        covariance_analysis(&endless, &settings),
        Parameter::StepCount,
    );
    // Formerly a loop of usize::MAX covariance steps.
    rejects(
        covariance_history(&Scenario::paper(), &settings, usize::MAX),
        Parameter::StepCount,
    );
    rejects(
        covariance_history(&Scenario::paper(), &settings, MAX_STEPS + 1),
        Parameter::StepCount,
    );
}

fn lee_huang_config(steps: usize, dt: f64) -> SensorConfig {
    SensorConfig {
        dt,
        steps,
        accelerometers: FourAccelerometers::default(),
        input_bias: Vector3::zeros(),
        input_noise_std: Vector3::repeat(0.01),
        attitude_std: 0.01,
    }
}

#[test]
fn lee_huang_simulate_rejects_endless_runs_and_bad_periods() {
    let scenario = lee_huang::Scenario::section_iv();
    // Formerly an overflow panic in `steps + 1` (debug) or an unbounded allocation (release).
    for steps in [usize::MAX, MAX_STEPS + 1] {
        rejects(
            lee_huang::simulate(&scenario, &lee_huang_config(steps, 0.01), 1),
            Parameter::StepCount,
        );
    }
    for dt in [0.0, -0.01, f64::NAN, f64::INFINITY] {
        rejects(
            lee_huang::simulate(&scenario, &lee_huang_config(10, dt), 1),
            Parameter::StepSize,
        );
    }
    let sim = lee_huang::simulate(&scenario, &lee_huang_config(10, 0.01), 1).unwrap();
    assert_eq!(sim.samples.len(), 11);
}

#[test]
fn ote_steady_state_rejects_endless_iterations() {
    rejects(
        ote_steady_state(&OteSettings::issue(), usize::MAX),
        Parameter::StepCount,
    );
}

#[test]
fn boje_circle_rejects_endless_runs_and_bad_fix_periods() {
    let paper = CircleConfig::paper();
    // Formerly an allocation of 4e18 steps.
    let long = CircleConfig {
        t_end: paper.dt * 4e18,
        ..paper
    };
    rejects(simulate_circle(&long, 0), Parameter::Duration);
    for t_end in [f64::INFINITY, f64::NAN] {
        rejects(
            simulate_circle(&CircleConfig { t_end, ..paper }, 0),
            Parameter::Duration,
        );
    }
    // Formerly read as "a fix every step".
    for fix_period in [f64::NAN, f64::INFINITY, 0.0, -1.0] {
        rejects(
            simulate_circle(
                &CircleConfig {
                    fix_period,
                    ..paper
                },
                0,
            ),
            Parameter::Period,
        );
    }
    for runs in [0, MAX_RUNS + 1] {
        rejects(
            CircleConfig { runs, ..paper }.validate(),
            Parameter::RunCount,
        );
    }
    for dt in [f64::NAN, 0.0, -0.01] {
        rejects(
            simulate_circle(&CircleConfig { dt, ..paper }, 0),
            Parameter::StepSize,
        );
    }
}

#[test]
fn limits_agree_with_their_documented_bounds() {
    assert_eq!(steps_for_duration(30.0, 0.005), Ok(6000));
    assert_eq!(steps_for_duration(MAX_STEPS as f64, 1.0), Ok(MAX_STEPS));
    rejects(
        steps_for_duration(MAX_STEPS as f64 + 1.0, 1.0),
        Parameter::Duration,
    );
    assert_eq!(check_runs(MAX_RUNS), Ok(MAX_RUNS));
}
