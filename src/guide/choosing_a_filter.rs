//! # Choosing a filter
//!
//! Every Gaussian filter is one type, [`GaussianFilter`](crate::filters::GaussianFilter),
//! parameterised by how it propagates a Gaussian through your model (its
//! [`MomentPropagator`](crate::core::MomentPropagator)). The aliases differ in that one choice
//! and in what they need from the model, which the compiler checks:
//!
//! | filter | propagation | your model implements | use when |
//! |---|---|---|---|
//! | `KalmanFilter` | exact | `LinearProcessModel`, `LinearMeasurementModel` | the model is linear |
//! | `Ekf` | first-order Taylor | `ProcessJacobian`, `MeasurementJacobian` | mild nonlinearity, cheap Jacobians |
//! | `SecondOrderEkf` | second order (Papoulis) | the `…Hessian` traits | curvature matters (Boje's accelerometers) |
//! | `GaussianSecondOrderEkf` | + Gaussian fourth moments | the `…Hessian` traits | exact for quadratic models |
//! | `Ukf` | unscented sigma points | values only | no derivatives at hand, or strong nonlinearity |
//! | `FadingMemoryRls` | update only, forgetting γ | `MeasurementJacobian` | parameter tracking (Lee & Huang's OTE) |
//!
//! Changing filter is changing the constructor; the loop stays:
//!
//! ```
//! use estim::prelude::*;
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//!
//! fn track<F>(mut filter: F) -> Result<f64, estim::core::Error>
//! where
//!     F: Predict<f64, estim::nalgebra::U2, LinearProcess<f64, estim::nalgebra::U2, estim::nalgebra::U1>>
//!         + Update<f64, estim::nalgebra::U2, estim::nalgebra::U1, LinearMeasurement<f64, estim::nalgebra::U2, estim::nalgebra::U1>>,
//! {
//!     let dt = 0.1;
//!     let process = LinearProcess {
//!         transition: Matrix2::new(1.0, dt, 0.0, 1.0),
//!         input: Matrix2x1::new(0.5 * dt * dt, dt),
//!         noise: Matrix2::identity() * 1e-4,
//!     };
//!     let gps = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
//!     for k in 1..=20 {
//!         filter.predict(&process, &Vector1::new(1.0), dt)?;
//!         let t = k as f64 * dt;
//!         filter.update(&gps, &Vector1::new(0.5 * t * t))?;
//!     }
//!     Ok(filter.state()[1])
//! }
//!
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?;
//! let kf = track(KalmanFilter::new(prior.clone()))?;
//! let ekf = track(Ekf::new(prior.clone()))?;
//! let ukf = track(Ukf::new(prior))?;
//! // On a linear model the three agree (the UKF to its sigma-point rounding).
//! assert!((kf - ekf).abs() < 1e-12 && (kf - ukf).abs() < 1e-6);
//! # Ok::<(), estim::core::Error>(())
//! ```
//!
//! Settings that every Gaussian filter takes: the covariance form
//! ([`CovarianceUpdate`](crate::filters::CovarianceUpdate): Joseph by default), an NIS gate
//! ([`with_gate`](crate::filters::GaussianFilter::with_gate)), and a state space for angles
//! ([`with_state_space`](crate::filters::GaussianFilter::with_state_space)). The unscented
//! spread is chosen with `Ukf::with_propagator(prior, Unscented::new(α, β, κ)?)`.
//!
//! # When one Gaussian is not enough
//!
//! Every filter above carries one Gaussian. Two estimators go beyond it through the same
//! step traits, so they take the same models and go into the fusion driver, the sequence
//! functions and checkpoints:
//!
//! - [`ParticleFilter`](crate::filters::particle::ParticleFilter) (bootstrap and auxiliary,
//!   four resampling schemes, an unbiased likelihood estimate) for multimodal posteriors: an
//!   ambiguous start, range-only localisation, the growth model. A model written for the
//!   Kalman filters runs in it by changing the constructor; non-Gaussian noise is opt-in
//!   ([`NonGaussianFilter`](crate::filters::particle::NonGaussianFilter)).
//! - [`Imm`](crate::filters::imm::Imm) (and GPB1, GPB2, the static bank) for a target that
//!   switches between models: each mode is any filter of this family with its own process
//!   model, mixed through a Markov transition matrix. Modes may have different state sizes
//!   (a constant-velocity mode inside a constant-acceleration state) through maps you give
//!   ([`EmbeddedModes`](crate::filters::imm::EmbeddedModes), see
//!   [`imm::embed`](crate::filters::imm::embed)). [`ImmSmoother`](crate::filters::imm::ImmSmoother)
//!   smooths a recorded IMM run (see [smoothing](super::smoothing)); the
//!   `manoeuvring_target` example compares a CV KF, a CT EKF and a CV/CT IMM on a target that
//!   turns (RMSE, NEES, mode probabilities against the true mode, the smoother's gain).
//!
//! What lets them share the tools is [`Rollback`](crate::filters::Rollback): every estimator
//! saves and restores exactly what its estimate depends on (a square-root factor, a particle
//! cloud, mode probabilities), which is how the fusion driver replays late readings and how a
//! failed sequence is undone. A generic function over "a filter that can be smoothed" bounds
//! its filter by [`PredictCross`](crate::filters::PredictCross).
