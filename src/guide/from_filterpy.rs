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
//! | `residual_z` | `MeasurementModel::residual_into` (angles: `wrap_angle`) |
//! | `residual_x`, `x_mean_fn` | a [`StateSpace`](crate::core::StateSpace) (⊞/⊟) given to `with_state_space` |
//! | Joseph form update (`update` default in FilterPy) | `CovarianceUpdate::Joseph` (the default) |
//! | `batch_filter(zs)`, `rts_smoother(Xs, Ps)` | `filter_sequence`, `smooth_sequence` (missing `z` as `None`), `Rts` |
//! | a log with irregular times and several sensors (a loop calling `predict(dt)`, `update(z, R, H)` per row) | `filter_readings`, `smooth_readings` over `(time, reading)` with a `SensorSet`; the results carry their times |
//! | pykalman `KalmanFilter.smooth`, `loglikelihood` | `smooth_sequence(..)?.estimates`, `.log_likelihood` |
//! | `filterpy.stats.NEES` | `estim::filters::consistency::nees`, and the Monte Carlo runner |
//! | `Saver` | keep what you need in your loop (reports are values) |
//!
//! ## Models and discretisation
//!
//! The models FilterPy users write by hand (or take from `filterpy.common`) are in
//! [`estim::models::motion`](crate::models::motion) and
//! [`estim::models::sensors`](crate::models::sensors) (default feature `models`), static-size
//! and generic over `f32`/`f64`, with analytic Jacobians (and Hessians for the second-order
//! filters). One difference: the state is ordered **by block**, position first,
//! (x, y, vₓ, v_y), not FilterPy's per-axis (x, vₓ, y, v_y), so that every sensor reads the
//! position from the first components.
//!
//! | FilterPy | estim |
//! |---|---|
//! | `Q_continuous_white_noise(dim, dt, spectral_density)` | `motion::continuous_white_noise::<f64, DIM>(dt, q)?` (any DIM ≥ 1) |
//! | `Q_discrete_white_noise(dim, dt, var)` (dim 2, 3, 4) | `motion::discrete_white_noise::<f64, DIM>(dt, var)?` |
//! | `van_loan_discretization(F, G, dt)` (unit white noise) | `motion::van_loan(&f, &g, &q_c, dt)?` → (Φ, Q), any Q_c |
//! | `F = [[1, dt], [0, 1]]`, `Q = Q_discrete_white_noise(2, dt, var)`, per axis | `ConstantVelocity::<f64, D>::new(Noise::Discrete(var))` (D = 1, 2, 3), or `Noise::Continuous(q)`: exact for irregular Δt |
//! | the same with `dim=3` | `ConstantAcceleration::<f64, D>` |
//! | a hand-written coordinated turn `fx(x, dt)` for the UKF | `CoordinatedTurn { rate, .. }` (known ω, linear, exact Q) or `CoordinatedTurnRate` (ω in the state, exact at ω = 0) |
//! | the robot `move(x, dt, u)` of the EKF chapter | `Unicycle` (input (v, ω), the exact arc) |
//! | a bias state with `Q = q·dt` / a Gauss-Markov `exp(-dt/tau)` | `RandomWalk<f64, N>`, `GaussMarkov<f64, N>` |
//! | `H_of`, `Hx` of a range / bearing / radar sensor | `sensors::Range`, `sensors::Bearing`, `sensors::RangeBearing` (residual wrapped), `sensors::Position` |
//! | a state vector extended by hand with bias states | `augment::Augmented` (process) and `augment::Biased` (sensor) |
//! | (no equivalent) consider / Schmidt states | [`filters::consider::schmidt_update`](crate::filters::consider::schmidt_update) |
//! | (no equivalent) outlier-robust update | [`filters::robust::robust_update`](crate::filters::robust::robust_update) (Huber, Student-t), beside gating |
//!
//! ```
//! # #[cfg(feature = "models")]
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use estim::prelude::*;
//! use estim::models::motion::CoordinatedTurnRate;
//! use estim::models::sensors::RangeBearing;
//! use estim::nalgebra::{Matrix5, Vector2, Vector5};
//!
//! // A radar at the origin tracks a target turning at 0.1 rad/s; the filter estimates the rate.
//! let ct = CoordinatedTurnRate { accel_psd: 0.01, rate_psd: 1e-4 };
//! let radar = RangeBearing { origin: Vector2::zeros(), range_variance: 1.0, bearing_variance: 1e-6 };
//! let mut truth = Vector5::new(100.0, 0.0, 0.0, 10.0, 0.1);
//! let prior = Vector5::new(100.0, 0.0, 0.0, 10.0, 0.0);
//! let mut ekf = Ekf::new(Gaussian::new(prior, Matrix5::from_diagonal(&Vector5::new(1.0, 1.0, 1.0, 1.0, 0.01)))?);
//! for _ in 0..100 {
//!     truth = ct.transition(&truth, &(), 0.5);
//!     ekf.predict(&ct, &(), 0.5)?;
//!     ekf.update(&radar, &radar.measure(&truth))?; // noise-free readings, for the check
//! }
//! let rate: f64 = ekf.state()[4];
//! assert!((rate - 0.1).abs() < 1e-3);
//! # Ok(())
//! # }
//! # #[cfg(not(feature = "models"))]
//! # fn main() {}
//! ```
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
