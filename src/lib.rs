//! # estim
//!
//! State estimation for Rust: write a model once (values, and where you have them analytic
//! Jacobians and Hessians), then run it through any filter of the Kalman family — linear KF,
//! EKF, second-order EKF, unscented KF — or the fading-memory RLS, by changing one constructor.
//!
//! This facade re-exports the three crates:
//!
//! - [`core`] (`estim-core`): [`Gaussian`](core::Gaussian), the model capability traits, the
//!   moment propagators (linearised, second order after Papoulis/Boje, Gaussian second order,
//!   unscented, sampled) and the derivative checker.
//! - [`filters`] (`estim-filters`): the filters and their step traits.
//! - `models` (`estim-models`, default feature `models`): the paper models, and the common
//!   motion and sensor models with the exact discretisation of continuous noise. A program that
//!   needs only the filters depends on `estim` with `default-features = false` and never
//!   compiles them.
//!
//! `use estim::prelude::*;` brings in what a typical program needs; the [`guide`] shows how to
//! do the common things (choosing a filter, runtime sizes, verifying, smoothing, `f32`,
//! coming from FilterPy).
//!
//! ```
//! use estim::prelude::*;
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//!
//! // A constant-acceleration-input cart observed in position.
//! let dt = 0.1;
//! let process = LinearProcess {
//!     transition: Matrix2::new(1.0, dt, 0.0, 1.0),
//!     input: Matrix2x1::new(0.5 * dt * dt, dt),
//!     noise: Matrix2::identity() * 1e-4,
//! };
//! let gps = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?;
//!
//! let mut filter = Ukf::new(prior); // or KalmanFilter::new, Ekf::new, SecondOrderEkf::new
//! for k in 0..50 {
//!     filter.predict(&process, &Vector1::new(1.0), dt)?;
//!     let t = (k + 1) as f64 * dt;
//!     let report = filter.update(&gps, &Vector1::new(0.5 * t * t))?;
//!     assert!(report.nis.is_finite());
//! }
//! assert!((filter.state()[1] - 5.0).abs() < 0.5);
//! # Ok::<(), estim::core::Error>(())
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod guide;

pub use estim_core as core;
pub use estim_filters as filters;
#[cfg(feature = "models")]
pub use estim_models as models;

/// The nalgebra estim uses, re-exported so users get the same version.
pub use estim_core::nalgebra;
/// The rand (and rand_distr) estim samples with, re-exported so users seed the same versions.
pub use estim_core::{rand, rand_distr};

/// The types and traits a typical estimation program needs.
pub mod prelude {
    pub use estim_core::derivative::{
        check_derivatives, check_jacobian, check_measurement_jacobian, check_measurement_model,
        check_process_jacobian, check_process_model,
    };
    pub use estim_core::propagate::{
        Affine, Linearized, Sampled, SecondOrder, SecondOrderGaussian, Unscented,
    };
    pub use estim_core::{
        AffineFunction, Alloc, Differentiable, Error, Euclidean, Gaussian, LinearMeasurement,
        LinearMeasurementModel, LinearProcess, LinearProcessModel, MeasurementHessian,
        MeasurementJacobian, MeasurementModel, MomentPropagator, NoInput, Offset, ProcessHessian,
        ProcessJacobian, ProcessModel, Real, StateSpace, TwiceDifferentiable, VectorFunction,
        wrap_angle,
    };
    pub use estim_filters::fusion::{
        FusionDriver, FusionSettings, Innovation, SensorSet, SensorSettings,
    };
    pub use estim_filters::{
        CovarianceUpdate, Ekf, EnsembleStats, Estimator, FadingMemoryRls, Gate, GaussianFilter,
        GaussianSecondOrderEkf, KalmanFilter, MonteCarlo, OnStateSpace, Predict, PredictCorrelated,
        PredictCross, ProcessInput, Recorder, Rollback, SecondOrderEkf, Ukf, Update, UpdateOutcome,
        UpdateReport, Verdict,
    };
    pub use estim_filters::{Iekf, SquareRootFilter, SrEkf, SrKalmanFilter, SrUkf};
}

#[doc = include_str!("../README.md")]
#[cfg(doctest)]
struct ReadmeDoctests;
