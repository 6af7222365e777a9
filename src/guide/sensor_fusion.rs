//! # Sensors that arrive late, or wrong
//!
//! A navigation filter's sensors come at different rates, late, and sometimes wrong. Fusing a
//! GPS fix taken 150 ms ago as if it were current puts a 100 m/s vehicle 15 m off and makes the
//! filter report an error far smaller than it has. The fusion driver
//! ([`estim::filters::fusion`](crate::filters::fusion)) sits above any filter of the family:
//!
//! 1. **Register the sensors** as one type implementing
//!    [`SensorSet`](crate::filters::fusion::SensorSet): a reading enum (one variant per sensor),
//!    which sensor a reading is from, its dimension, and the update with the filters' usual
//!    `filter.update(&model, &z)`.
//! 2. **Fuse with timestamps**: [`fuse(time, reading)`](crate::filters::fusion::FusionDriver::fuse)
//!    predicts to the time the measurement was *taken*; a late one is inserted in the history
//!    and everything after it re-run (bit-identical to an in-order delivery). Older than the
//!    horizon: [`FusionError::TooOld`](crate::filters::fusion::FusionError::TooOld), never fused
//!    as current. [`advance_to(now)`](crate::filters::fusion::FusionDriver::advance_to) gives the
//!    real-time estimate.
//! 3. **Read the decision**: [`Outcome`](crate::filters::fusion::Outcome) says accepted,
//!    rejected (with NIS / gate and the normalised innovation per component), reset, or excluded
//!    (the sensor's windowed NIS χ² monitor found it faulty); `health(sensor)` has the counters.
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::fusion::{MonitorSettings, Outcome};
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, U1, U2, Vector1, Vector2};
//!
//! /// The constant-velocity cart, exactly discretised (so any sub-step gives the same moments).
//! struct Cart;
//! impl ProcessModel<f64, U2> for Cart {
//!     type Input = ();
//!     fn transition(&self, x: &Vector2<f64>, _: &(), dt: f64) -> Vector2<f64> { Vector2::new(x[0] + dt * x[1], x[1]) }
//!     fn process_noise(&self, _: &Vector2<f64>, _: &(), dt: f64) -> Matrix2<f64> {
//!         Matrix2::new(dt * dt * dt / 3.0, dt * dt / 2.0, dt * dt / 2.0, dt) * 0.01
//!     }
//! }
//! impl ProcessJacobian<f64, U2> for Cart {
//!     fn transition_jacobian(&self, _: &Vector2<f64>, _: &(), dt: f64) -> Matrix2<f64> { Matrix2::new(1.0, dt, 0.0, 1.0) }
//! }
//! impl LinearProcessModel<f64, U2> for Cart {}
//!
//! /// One GPS position sensor (sensor 0), its fixes as 1-vectors.
//! struct Gps(LinearMeasurement<f64, U2, U1>);
//! impl<F: Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>> SensorSet<f64, U2, F> for Gps {
//!     type Reading = Vector1<f64>;
//!     fn count(&self) -> usize { 1 }
//!     fn sensor(&self, _: &Vector1<f64>) -> usize { 0 }
//!     fn dimension(&self, _: usize) -> usize { 1 }
//!     fn update(&self, f: &mut F, z: &Vector1<f64>) -> estim::core::error::Result<Innovation<f64>> {
//!         f.update(&self.0, z).map(|r| Innovation::of(&r))
//!     }
//! }
//!
//! let gps = Gps(LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) });
//! let filter = KalmanFilter::new(Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::identity())?);
//! // Fixes up to 0.5 s late; predictions in steps of at most 10 ms.
//! let settings = FusionSettings { horizon: 0.5, max_step: 0.01, ..FusionSettings::default() };
//! // Gate at 0.9999; a windowed NIS monitor (W = 20, 10⁻³ false alarms per test).
//! let judged = SensorSettings::gated(0.9999).with_monitor(MonitorSettings::default());
//! let mut driver = FusionDriver::new(filter, Cart, (), gps, 0.0, settings, judged)?;
//!
//! for k in 1..=20 {
//!     let taken = 0.1 * k as f64;
//!     driver.fuse(taken, Vector1::new(taken))?; // the cart moves at 1 m/s
//! }
//! // A fix taken at 1.95 s arrives now, after the 2.0 s one: fused at 1.95 s, 2.0 s re-run.
//! assert_eq!(driver.fuse(1.95, Vector1::new(1.95))?.replayed, 1);
//! // A 100 σ outlier: rejected, and why.
//! if let Outcome::Rejected { test_ratio, innovation } = driver.fuse(2.1, Vector1::new(12.1))?.outcome {
//!     assert!(test_ratio > 1.0 && innovation.normalized()[0] > 50.0);
//! } else {
//!     panic!("a 100 σ outlier must be rejected");
//! }
//! driver.advance_to(2.15)?; // the real-time estimate
//! assert!((driver.filter().state()[0] - 2.15).abs() < 0.05);
//! assert_eq!(driver.health(0).rejected, 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Choosing the settings
//!
//! | setting | rule of thumb |
//! |---|---|
//! | `horizon` | the largest latency you accept (a fix older than that is refused, with its time) |
//! | `capacity` | events per second × horizon + 2 (each fix, input change and `advance_to` is one record) |
//! | `max_step` | default ∞: one prediction per gap (the models take Δt); set it to the sample period your discretised Q is written for (Lu's error state: 5 ms) |
//! | `duplicates` | default `FuseBoth`: two readings of one sensor at one time are two measurements; `KeepFirst` when the log repeats the same line; `Refuse` for the old error |
//! | gate | 0.999–0.9999: rejections cascade (a rejected fix was informative), so gate loosely |
//! | monitor | W fixes a channel may take to be declared faulty once its NIS exceeds the clip c: at most ⌈q/c⌉ (7 for m = 1, W = 20, α = 10⁻³) |
//! | reset | only for sensors the filter may be re-initialised from; it fires when no *other* sensor was accepted during the run of rejections, so a healthy second sensor protects you from resetting to a stuck one |
//!
//! A gate cannot refuse an outlier that lies inside the prior's spread (at the first fixes, a
//! 4 m/s velocity outlier against a 1 m/s prior σ): start with a prior you trust, or keep the
//! monitor to exclude the channel that the filter then disagrees with.
//!
//! ## Smoothing a run, and its likelihood
//!
//! `driver.smooth()` returns the run's Rauch–Tung–Striebel estimates over the history kept
//! (size `capacity` to the log), in time order with each late reading where it was taken, as
//! a `Track` (times and estimates); it equals `smooth_readings` on the same log sorted by
//! time. `driver.log_likelihood()` is the sum of the accepted updates' ln N(ν; 0, S), the
//! same as `filter_readings(..)?.log_likelihood`, so maximum-likelihood noise identification
//! runs over a driver run. Both batch functions take a log of `(time, reading)` with
//! irregular times and the driver's `SensorSet`, so one sensor definition serves both.
//!
//! The `lu_delays` example (`cargo run --release --example lu_delays`) runs Lu's GPS/accelerometer
//! problem with 0–300 ms latency, 100 σ outliers and a stuck channel three ways: fused as
//! current (ANEES ≈ 27 000), at the time taken (3.2, consistent), and with gating and fault
//! exclusion (3.2 with the faults; the stuck channel excluded within 1.9 s).
