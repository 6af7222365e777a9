//! Time, delays, gating outcomes and faults: a fusion driver above the filters.
//!
//! A navigation filter's sensors arrive at different rates, late, and sometimes wrong. The
//! [`FusionDriver`] holds a filter of the family, the process model and its input, and takes
//! timestamped measurements from several sensors:
//!
//! - it **predicts to each measurement's time**: by default in one prediction of Δt, or, if
//!   [`FusionSettings::max_step`] h is set, in equal sub-steps (n = ⌈Δt / h − 10⁻⁹⌉ steps of
//!   Δt / n, so that rounding in the timestamps never adds a sliver of a step); no prediction
//!   at all between equal times, where two readings of one sensor follow the
//!   [`DuplicatePolicy`] (fused both by default);
//! - it **fuses a late (out-of-sequence) measurement at the time it was taken**: a bounded
//!   history ([`FusionSettings::horizon`] seconds, at most [`FusionSettings::capacity`]
//!   records) keeps, after every event, the state, the covariance, the input in force and the
//!   per-sensor health; a late measurement is inserted in time order and every later event is
//!   re-run from the checkpoint before it. The replay runs the same operations in the same
//!   order as a time-ordered delivery would have, so the result is **bit-identical** (tested);
//!   a measurement older than the history is refused with [`FusionError::TooOld`], never fused
//!   as if it were current. Readings that arrive together (a GPS fix's position and velocity)
//!   go in one [`FusionDriver::fuse_all`] call: inserted together, one rollback and one replay,
//!   the same bits as fusing them one by one, and all or nothing if one is refused;
//! - it **decides per measurement** ([`Outcome`]): accepted, rejected by the NIS gate (with the
//!   test ratio NIS/gate and the per-component normalised innovations), used to reset the
//!   filter, or excluded because its sensor is faulty; it keeps counters and a health summary
//!   per sensor ([`SensorHealth`]);
//! - it **detects faults** with a windowed NIS χ² monitor per sensor and excludes a faulty
//!   sensor until it recovers ([`MonitorSettings`]);
//! - its run is **smoothable and has a likelihood**: [`FusionDriver::smooth`] is the
//!   Rauch–Tung–Striebel pass over the history, each late reading where it was taken, with
//!   the estimates' times; [`FusionDriver::log_likelihood`] sums the accepted updates'
//!   ln N(ν; 0, S), for maximum-likelihood noise identification over a run. Both equal the
//!   batch functions ([`smooth_readings`](crate::smoother::smooth_readings),
//!   [`filter_readings`](crate::smoother::filter_readings)) on the same log in time order.
//!
//! The driver never changes the filters: it calls [`Predict::predict`](crate::Predict) and the
//! sensors' updates, reads the estimate through [`Estimator`](crate::Estimator), and rolls the
//! filter back with its own snapshots ([`Rollback`](crate::Rollback)): the history keeps one
//! per event, and a rejected, excluded or replayed measurement puts one back bit for bit, a
//! square-root factor included (the filter's own gate is not needed; leave it unset). Only a
//! covariance reset ([`ResetSettings`]) re-initialises the filter from a new Gaussian, through
//! [`Estimator::reset`](crate::Estimator::reset) (a multiple-model estimator restarts every
//! mode from it and keeps its mode probabilities μ). Any estimator implementing [`Predict`],
//! the sensors' updates and [`Rollback`](crate::Rollback) goes in: a multiple-model estimator's "process" is
//! whatever its `Predict` takes (its set of per-mode models).
//!
//! [`Predict`]: crate::Predict
//!
//! Everything an estimate depends on must be in the filter for this to hold: a quantity kept
//! beside it (say an attitude reference that is recentred after each step) is not in the
//! snapshots and is not rolled back. Keep an attitude in the state as its rotation vector
//! under `estim_core::manifold::AttitudeError` (see the note in `estim_core::manifold::attitude`).
//!
//! # Registering sensors
//!
//! The sensors are one user type implementing [`SensorSet`]: a *reading* type (typically an
//! enum with one variant per sensor, each holding its static-size vector), which sensor a
//! reading comes from, the dimension of each sensor, and the update of a filter with a
//! reading, written with the filters' own per-call `update(&model, &z)`. Why this and not one
//! boxed model per sensor: the history must store readings of every sensor in memory fixed at
//! construction, and a user enum of static-size vectors is one `Clone` type of fixed size
//! (no allocation, no type erasure); the models keep their exact types, so the compiler checks
//! each sensor's dimension, and a filter lacking what a model needs is a compile error as
//! everywhere in estim.
//!
//! ```
//! use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, U1, U2, Vector1, Vector2};
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
//! use estim_filters::fusion::{FusionDriver, FusionSettings, Innovation, Outcome, SensorSet, SensorSettings};
//! use estim_filters::{KalmanFilter, Update};
//!
//! /// A position fix and a velocity fix, two sensors.
//! #[derive(Clone, Debug)]
//! enum Reading { Position(Vector1<f64>), Velocity(Vector1<f64>) }
//! struct Cart { position: LinearMeasurement<f64, U2, U1>, velocity: LinearMeasurement<f64, U2, U1> }
//! impl<F: Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>> SensorSet<f64, U2, F> for Cart {
//!     type Reading = Reading;
//!     fn count(&self) -> usize { 2 }
//!     fn sensor(&self, r: &Reading) -> usize { match r { Reading::Position(_) => 0, Reading::Velocity(_) => 1 } }
//!     fn dimension(&self, _: usize) -> usize { 1 }
//!     fn update(&self, filter: &mut F, r: &Reading) -> Result<Innovation<f64>> {
//!         match r {
//!             Reading::Position(z) => filter.update(&self.position, z).map(|r| Innovation::of(&r)),
//!             Reading::Velocity(z) => filter.update(&self.velocity, z).map(|r| Innovation::of(&r)),
//!         }
//!     }
//! }
//! let process = LinearProcess { transition: Matrix2::new(1.0, 0.01, 0.0, 1.0), input: Matrix2::zeros(), noise: Matrix2::identity() * 1e-6 };
//! let sensors = Cart {
//!     position: LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) },
//!     velocity: LinearMeasurement { observation: Matrix1x2::new(0.0, 1.0), noise: Matrix1::new(0.01) },
//! };
//! let filter = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
//! let settings = FusionSettings { horizon: 0.5, max_step: 0.01, ..FusionSettings::default() };
//! let mut driver = FusionDriver::new(filter, process, Vector2::zeros(), sensors, 0.0, settings,
//!     SensorSettings::gated(0.999))?;
//! driver.fuse(0.10, Reading::Position(Vector1::new(0.1)))?;
//! // A velocity fix taken at 0.05 s arrives after the 0.10 s position fix: fused at 0.05 s.
//! let late = driver.fuse(0.05, Reading::Velocity(Vector1::new(1.0)))?;
//! assert_eq!(late.replayed, 1);
//! assert!(matches!(late.outcome, Outcome::Accepted { .. }));
//! // A 100 σ outlier is rejected, with its test ratio NIS / gate.
//! let outlier = driver.fuse(0.2, Reading::Position(Vector1::new(10.0)))?;
//! assert!(matches!(outlier.outcome, Outcome::Rejected { test_ratio, .. } if test_ratio > 10.0));
//! assert_eq!(driver.health(0).rejected, 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Decisions, in order, for a measurement of sensor s
//!
//! 1. The filter is updated with it; its NIS ε and the normalised innovation νᵢ / √Sᵢᵢ of each
//!    component are read from the update report.
//! 2. **Monitor** (if configured): min(ε, c) is pushed into the sensor's window of the last W
//!    values, c = χ²ₘ quantile at [`MonitorSettings::clip_probability`]. The sensor is declared
//!    faulty when the window's sum exceeds q = χ²_{W·m} quantile at 1 − α
//!    ([`MonitorSettings::false_alarm`]). On a consistent sensor the sum of W values is
//!    χ²_{W·m}, so the false-alarm rate per test is at most α (clipping and partly filled windows
//!    only lower the sum). Clipping is what tells a *fault* from an *outlier*: one gross outlier
//!    adds at most c, while a channel whose every NIS exceeds c (stuck, or biased by more than
//!    √c σ) is detected within **⌈q / c⌉ deliveries**, whatever the size of its error. A faulty
//!    sensor is **excluded**: its measurements are not applied (their NIS still feeds the
//!    window, from empty); it is **readmitted** once W deliveries since the exclusion give a
//!    window sum ≤ q (the measurement that readmits is itself still excluded).
//! 3. **Reset** (if configured, [`ResetSettings`]): after `after_rejections` consecutive
//!    rejections of sensor s *during which no other sensor's measurement was accepted* (then the
//!    filter, not the sensor, is the likely culprit: with one sensor this is always so), or
//!    when the predicted variance of one of the reset states exceeds `blow_up_variance`: the
//!    reset states lose their correlations, get variance `variance` (a large prior), and the
//!    measurement is applied without gate. The window of s is cleared.
//! 4. **Gate** (if configured): ε > g = χ²ₘ quantile at [`SensorSettings::gate_probability`]
//!    rejects the measurement; the estimate is restored exactly.
//! 5. Otherwise the measurement is accepted.
//!
//! # Memory
//!
//! Everything is allocated at construction: the history's records (with static sizes their
//! vectors and matrices live inside the records), the per-sensor windows, and room for a
//! [`FusionDriver::fuse_all`] batch of one reading per sensor. After that, with static sizes,
//! no call allocates (tested with a counting allocator); a larger batch grows the spare
//! records and the result buffer once, to its size. With runtime sizes the
//! snapshots are copied into the records' buffers ([`Rollback::snapshot_into`]), a covariance
//! reset allocates one vector and one matrix, and a runtime-sized input is cloned into each
//! record it is held over.
//!
//! [`Rollback::snapshot_into`]: crate::Rollback::snapshot_into
//!
//! # Time
//!
//! Timestamps are `f64` seconds whatever the filter's scalar (an `f32` timestamp loses
//! milliseconds after a few hours). The process input is piecewise constant and recorded, so
//! that replays use the input that was in force. By default it is held from
//! [`FusionDriver::set_input`]'s time on; a sampled input that covers the interval *before*
//! its timestamp (an IMU sample) is [`InputConvention::Preceding`]
//! ([`FusionDriver::with_input_convention`]): no queue of samples is needed in front of the
//! driver. [`FusionDriver::advance_to`] predicts to a time with no measurement (the real-time
//! estimate); it is recorded too, so a replay splits the prediction at the same times.
//!
//! # Reference
//!
//! Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*
//! (2001): §5.4 (NIS tests), §11.5 (sliding-window χ² fault detection); Bar-Shalom, *Update
//! with out-of-sequence measurements in tracking: exact solution* (IEEE TAES 2002), whose exact
//! answer this driver obtains by re-filtering from a stored checkpoint (the PX4 EKF2 approach
//! of a delayed fusion horizon, generalised to any filter and any number of sensors).

mod driver;
mod error;
mod history;
mod monitor;
mod outcome;
mod sensors;
mod settings;

pub use driver::FusionDriver;
pub use error::{BatchError, FusionError, FusionSetting};
pub use monitor::{SensorHealth, SensorStatus};
pub use outcome::{
    ExclusionReason, Fused, Innovation, MAX_REPORTED_COMPONENTS, Outcome, ResetReason,
};
pub use sensors::SensorSet;
pub use settings::{
    DuplicatePolicy, FusionSettings, InputConvention, MonitorSettings, ResetSettings,
    SensorSettings,
};
