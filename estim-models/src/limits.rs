//! Settings checks shared by every simulator and experiment runner: durations, step counts,
//! periods and run counts are finite, positive where they must be, and bounded, so that no
//! setting can make a run panic, abort on allocation or never return.
//!
//! The bound is [`MAX_STEPS`] = 10⁷ steps per run. The largest stored record per step is
//! Lee–Huang's simulation (a 6-state truth and one sensor sample, 120 bytes), so a stored run
//! stays under 1.2 GB; the step-by-step runners store nothing per step and take seconds at
//! most per million steps. Runs are bounded by [`MAX_RUNS`] = 10⁶.

use estim_core::{Error, Parameter};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// The largest number of steps (or iterations) a simulator, runner or recursion accepts.
pub const MAX_STEPS: usize = 10_000_000;

/// The largest number of Monte Carlo runs a runner accepts.
pub const MAX_RUNS: usize = 1_000_000;

fn invalid(parameter: Parameter, value: f64) -> Error {
    Error::InvalidParameter { parameter, value }
}

/// Checks a step (or iteration) count: `steps` ≤ [`MAX_STEPS`].
///
/// Errors: [`Error::InvalidParameter`] with [`Parameter::StepCount`] otherwise.
///
/// ```
/// use estim_models::limits::{MAX_STEPS, check_steps};
/// assert_eq!(check_steps(6000), Ok(6000));
/// assert!(check_steps(MAX_STEPS + 1).is_err());
/// ```
pub fn check_steps(steps: usize) -> Result<usize, Error> {
    if steps <= MAX_STEPS {
        Ok(steps)
    } else {
        Err(invalid(Parameter::StepCount, steps as f64))
    }
}

/// Checks a run count: 1 ≤ `runs` ≤ [`MAX_RUNS`].
///
/// Errors: [`Error::InvalidParameter`] with [`Parameter::RunCount`] otherwise.
///
/// ```
/// use estim_models::limits::check_runs;
/// assert_eq!(check_runs(50), Ok(50));
/// assert!(check_runs(0).is_err());
/// ```
pub fn check_runs(runs: usize) -> Result<usize, Error> {
    if (1..=MAX_RUNS).contains(&runs) {
        Ok(runs)
    } else {
        Err(invalid(Parameter::RunCount, runs as f64))
    }
}

/// Checks a period (a sample step Δt or a fix period) in seconds: finite and > 0.
///
/// Errors: [`Error::InvalidParameter`] with `parameter` (e.g. [`Parameter::StepSize`] for a
/// sample step, [`Parameter::Period`] for a fix period) otherwise.
///
/// ```
/// use estim_models::limits::check_period;
/// use estim_core::Parameter;
/// assert_eq!(check_period(0.01, Parameter::StepSize), Ok(0.01));
/// assert!(check_period(f64::NAN, Parameter::Period).is_err());
/// ```
pub fn check_period(period: f64, parameter: Parameter) -> Result<f64, Error> {
    if period > 0.0 && period.is_finite() {
        Ok(period)
    } else {
        Err(invalid(parameter, period))
    }
}

/// The number of steps of length `dt` in `duration` seconds, round(duration / dt), checked:
/// Δt finite and > 0 ([`Parameter::StepSize`]), the duration finite and ≥ 0
/// ([`Parameter::Duration`]), and the count ≤ [`MAX_STEPS`] ([`Parameter::Duration`]: the
/// duration is what is too long). The division is done in `f64` before any conversion, so
/// no duration can overflow the count.
///
/// ```
/// use estim_models::limits::steps_for_duration;
/// assert_eq!(steps_for_duration(30.0, 0.005), Ok(6000));
/// assert!(steps_for_duration(f64::INFINITY, 0.005).is_err());
/// assert!(steps_for_duration(1e12, 0.005).is_err());
/// ```
pub fn steps_for_duration(duration: f64, dt: f64) -> Result<usize, Error> {
    check_period(dt, Parameter::StepSize)?;
    if !(duration >= 0.0 && duration.is_finite()) {
        return Err(invalid(Parameter::Duration, duration));
    }
    let steps = (duration / dt).round();
    if steps <= MAX_STEPS as f64 {
        Ok(steps as usize)
    } else {
        Err(invalid(Parameter::Duration, duration))
    }
}
