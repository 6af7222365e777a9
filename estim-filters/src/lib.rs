//! # estim-filters
//!
//! Interchangeable recursive estimators over the models of [`estim_core`]:
//!
//! | filter | propagation | needs from the process model | from the measurement model |
//! |---|---|---|---|
//! | [`KalmanFilter`] | exact (affine) | [`LinearProcessModel`](estim_core::LinearProcessModel) | [`LinearMeasurementModel`](estim_core::LinearMeasurementModel) |
//! | [`Ekf`] | linearised | [`ProcessJacobian`](estim_core::ProcessJacobian) | [`MeasurementJacobian`](estim_core::MeasurementJacobian) |
//! | [`SecondOrderEkf`] | second order (Papoulis) | [`ProcessHessian`](estim_core::ProcessHessian) | [`MeasurementHessian`](estim_core::MeasurementHessian) |
//! | [`GaussianSecondOrderEkf`] | second order + Gaussian 4th-moment terms | Hessians | Hessians |
//! | [`Ukf`] | unscented | [`ProcessModel`](estim_core::ProcessModel) | [`MeasurementModel`](estim_core::MeasurementModel) |
//! | [`Iekf`] | linearised, update iterated (Gauss–Newton) | [`ProcessJacobian`](estim_core::ProcessJacobian) | [`MeasurementJacobian`](estim_core::MeasurementJacobian) |
//! | [`FadingMemoryRls`] | — (update only) | — | [`MeasurementJacobian`](estim_core::MeasurementJacobian) |
//! | [`SrKalmanFilter`], [`SrEkf`], [`SrUkf`] | as KF, EKF, UKF, on the Cholesky factor ([`square_root`]) | as KF, EKF, UKF | as KF, EKF, UKF |
//! | [`ParticleFilter`](particle::ParticleFilter) | sampled (bootstrap SIR, auxiliary, guided [`Proposal`](particle::Proposal)) | [`ProcessModel`](estim_core::ProcessModel), or a [`ProcessSampler`](particle::ProcessSampler) | [`MeasurementModel`](estim_core::MeasurementModel), or a [`MeasurementLikelihood`](particle::MeasurementLikelihood) |
//! | [`RaoBlackwellised`](particle::RaoBlackwellised) | sampled xn, a [`KalmanFilter`] per particle for xl | [`ConditionallyLinearProcess`](particle::ConditionallyLinearProcess) | [`ConditionallyLinearMeasurement`](particle::ConditionallyLinearMeasurement) |
//!
//! The Kalman-family filters are one type, [`GaussianFilter`], parameterised by the
//! [`MomentPropagator`](estim_core::MomentPropagator); they differ only in how the predicted
//! moments are computed. The gain, the Cholesky solve, the covariance update, gating and the
//! update report are written once ([`update`]). Changing filter is changing one constructor:
//!
//! ```
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess, nalgebra::{Matrix1, Matrix2, Matrix1x2, Vector1, Vector2, Matrix2x1}};
//! use estim_filters::{Ekf, Estimator, Predict, Ukf, Update};
//!
//! let process = LinearProcess { transition: Matrix2::new(1.0, 0.1, 0.0, 1.0), input: Matrix2x1::new(0.005, 0.1), noise: Matrix2::identity() * 1e-4 };
//! let position = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
//!
//! let mut filter = Ekf::new(prior.clone());          // or: Ukf::new(prior.clone());
//! filter.predict(&process, &Vector1::new(1.0), 0.1)?;
//! let report = filter.update(&position, &Vector1::new(0.02))?;
//! assert!(report.nis >= 0.0);
//! assert!(filter.covariance()[(0, 0)] < 1.0);
//! # let mut ukf = Ukf::new(prior); ukf.predict(&process, &Vector1::new(1.0), 0.1)?; ukf.update(&position, &Vector1::new(0.02))?;
//! # Ok::<(), estim_core::Error>(())
//! ```
//!
//! Models are passed to each call, never stored, so one filter serves several sensors at
//! several rates. [`Estimator`] is object safe: `Box<dyn Estimator<f64, U6>>` holds any of them.
//!
//! ## Outliers and consider states
//!
//! Beside the gate ([`Gate`]: reject), [`robust`] down-weights an outlier (Huber or Student-t
//! weights, the step bounded in prior standard deviations, the filter's own update when the
//! innovation is inside the threshold), and [`consider`] carries states without correcting
//! them (the Schmidt-Kalman update).
//!
//! ## Multiple models
//!
//! [`imm`]: the interacting multiple model estimator over any of these filters as modes (a
//! tuple of filters of their own types, or a `Vec`), with a Markov mode chain, mixing by moment
//! matching, and mode probabilities updated in logs; [`imm::ImmSmoother`] smooths a recorded
//! IMM run.
//!
//! ## Learning the noise
//!
//! [`noise_id`]: Q and R (and x₀, P₀, F, H) from recorded data by expectation–maximisation for
//! linear models, by maximum likelihood with standard errors for any filter (feature
//! `likelihood`), and online by innovation-based covariance matching.
//!
//! ## Verifying a filter
//!
//! - [`consistency`]: NEES, NIS, averaged NEES/NIS with χ² bands, innovation whiteness,
//!   log-likelihood, and the [`Verdict`] of a set of checks.
//! - [`monte_carlo`]: the Monte Carlo runner ([`MonteCarlo`]) giving per-time ensemble
//!   statistics — Lu's four checks (mean error, ensemble vs filter covariance, orthogonality,
//!   residual cross-correlation) and the NEES/NIS bands — for any model and filter; parallel
//!   with feature `parallel`, bit-identical to the sequential run.
//! - `proptest_support` (feature `proptest-support`): strategies for SPD matrices, Gaussians
//!   and stable linear systems, and derivative-check assertions for proptests.
//!
//! ## Without std
//!
//! With the default feature `std` off the crate is `#![no_std]` and allocates nothing: every
//! Gaussian filter, [`FadingMemoryRls`], [`Decorrelated`] and the shared [`update`] on static
//! sizes, in `f32` or `f64` (a microcontroller build: `docs/embedded.md`). The verification
//! tooling, noise identification, smoothers and the fusion driver need `std`.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

// Inlining: `#[cfg_attr(not(debug_assertions), inline(always))]` throughout, as in estim-core
// (the reason and the measurement are in its crate root).

mod bounds;
#[cfg(feature = "serde")]
pub mod checkpoint;
#[cfg(feature = "std")]
mod chi_square;
pub mod consider;
#[cfg(feature = "std")]
pub mod consistency;
mod correlated;
#[cfg(feature = "std")]
pub mod fusion;
mod gaussian_filter;
#[cfg(feature = "std")]
pub mod imm;
mod iterated;
#[cfg(feature = "std")]
pub mod monte_carlo;
#[cfg(feature = "std")]
pub mod noise_id;
#[cfg(feature = "std")]
pub mod particle;
#[cfg(feature = "proptest-support")]
pub mod proptest_support;
mod report;
mod rls;
pub mod robust;
mod scratch;
#[cfg(feature = "std")]
pub mod smoother;
mod snapshot;
pub mod square_root;
mod traits;
pub mod update;
#[cfg(feature = "std")]
pub mod validation;

pub use bounds::{FilterOver, Smoothable};
#[cfg(feature = "std")]
pub use consistency::Verdict;
pub use correlated::Decorrelated;
pub use gaussian_filter::{
    Ekf, GaussianFilter, GaussianSecondOrderEkf, KalmanFilter, SecondOrderEkf, Ukf,
};
pub use iterated::Iekf;
#[cfg(feature = "std")]
pub use monte_carlo::{EnsembleStats, MonteCarlo, MonteCarloError, Progress, Recorder, Shard};
pub use report::{Iterations, UpdateOutcome, UpdateReport};
pub use rls::FadingMemoryRls;
#[cfg(feature = "std")]
pub use smoother::{Rts, Sequence, SmootherError, filter_sequence, smooth_sequence};
#[cfg(feature = "std")]
pub use smoother::{Smoothed, smooth_sequence_with_cross_covariances};
pub use snapshot::{EstimateSnapshot, FactorSnapshot};
pub use square_root::{SquareRootFilter, SrEkf, SrKalmanFilter, SrUkf};
pub use traits::{
    Estimator, OnStateSpace, Predict, PredictCorrelated, PredictCross, ProcessInput, Rollback,
    Update,
};
pub use update::{CovarianceUpdate, Gate};
#[cfg(feature = "std")]
pub use validation::ValidationError;

#[doc = include_str!("../README.md")]
#[cfg(doctest)]
struct ReadmeDoctests;
