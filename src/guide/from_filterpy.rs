//! # Coming from FilterPy or pykalman
//!
//! | FilterPy / pykalman | estim |
//! |---|---|
//! | `KalmanFilter(dim_x, dim_z)`, then `kf.x`, `kf.P` | `KalmanFilter::new(Gaussian::new(x, P)?)` |
//! | `kf.F`, `kf.B`, `kf.Q` | `LinearProcess { transition, input, noise }`, passed to each `predict` |
//! | `kf.H`, `kf.R` | `LinearMeasurement { observation, noise }`, passed to each `update` (one per sensor) |
//! | `kf.predict(u)` | `filter.predict(&process, &u, dt)?` |
//! | `kf.update(z)`; `kf.y`, `kf.S`, `kf.log_likelihood` | `let r = filter.update(&sensor, &z)?;` `r.innovation`, `r.innovation_covariance`, `r.log_likelihood`, `r.nis` |
//! | `ExtendedKalmanFilter`, `update(z, HJacobian, Hx)` | `Ekf::new(prior)`; your model implements `MeasurementJacobian` |
//! | `UnscentedKalmanFilter(..., points=MerweScaledSigmaPoints(n, α, β, κ))` | `Ukf::with_propagator(prior, Unscented::new(α, β, κ)?)` |
//! | `residual_z` | `MeasurementModel::residual` (angles: `wrap_angle`) |
//! | `residual_x`, `x_mean_fn` | a [`StateSpace`](crate::core::StateSpace) (⊞/⊟) given to `with_state_space` |
//! | Joseph form update (`update` default in FilterPy) | `CovarianceUpdate::Joseph` (the default) |
//! | `batch_filter(zs)`, `rts_smoother(Xs, Ps)` | `filter_sequence`, `smooth_sequence` (missing `z` as `None`), `Rts` |
//! | pykalman `KalmanFilter.smooth`, `loglikelihood` | `smooth_sequence(..)?.estimates`, `.log_likelihood` |
//! | `filterpy.stats.NEES` | `estim::filters::consistency::nees`, and the Monte Carlo runner |
//! | `Saver` | keep what you need in your loop (reports are values) |
//!
//! One difference in habit: models are not stored in the filter. Pass the model to each call,
//! so one filter takes several sensors at several rates:
//!
//! ```
//! use estim::prelude::*;
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//!
//! let process = LinearProcess {
//!     transition: Matrix2::new(1.0, 0.01, 0.0, 1.0),
//!     input: Matrix2x1::zeros(),
//!     noise: Matrix2::identity() * 1e-5,
//! };
//! let gps = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(4.0) };
//! let odometer = LinearMeasurement { observation: Matrix1x2::new(0.0, 1.0), noise: Matrix1::new(0.01) };
//! let mut ekf = Ekf::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
//! for k in 0..100 {
//!     ekf.predict(&process, &Vector1::zeros(), 0.01)?;
//!     ekf.update(&odometer, &Vector1::new(1.0))?; // 100 Hz
//!     if k % 20 == 19 {
//!         ekf.update(&gps, &Vector1::new(0.01 * (k + 1) as f64))?; // 5 Hz
//!     }
//! }
//! assert!((ekf.state()[1] - 1.0).abs() < 0.05);
//! # Ok::<(), estim::core::Error>(())
//! ```
