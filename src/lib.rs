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

// The three crates are modules here whose items are inlined (`#[doc(inline)]` globs), so that
// `cargo doc --no-deps -p estim` documents the whole API under the facade (`estim::filters::Rts`)
// and every intra-doc link has a page to point at. Not `#[doc(inline)] pub use estim_core as
// core`: rustdoc then renders each crate as a "crate" page whose "All Items" link is dead, and
// inlines the external crates estim-core re-exports (all of nalgebra, rand, num-dual) with it.
// A glob inlines them too, even beside a `no_inline` re-export of the same crate (rustdoc lets
// a glob inline whatever the module re-exports), so each is shadowed by a small module of the
// same name whose `no_inline` glob keeps the paths (`estim::core::nalgebra::Vector2`) and
// links to that crate's own docs.

/// The foundation (`estim-core`): [`Gaussian`](core::Gaussian), the model capability traits
/// ([`ProcessModel`](core::ProcessModel) x⁺ = f(x, u, Δt) + w, [`MeasurementModel`](core::MeasurementModel)
/// z = h(x) + v, their Jacobian and Hessian traits), the moment propagators ([`propagate`](core::propagate):
/// given x ~ N(μ, P) and y = g(x), the mean and covariance of y and the cross-covariance of x
/// and y), the derivative checker ([`derivative`](core::derivative)) and the one [`Error`](core::Error).
pub mod core {
    #[doc(inline)]
    pub use estim_core::*;

    /// The nalgebra estim-core is built on: the same as [`estim::nalgebra`](crate::nalgebra).
    pub mod nalgebra {
        #[doc(no_inline)]
        pub use estim_core::nalgebra::*;
    }
    /// The rand estim-core samples with: the same as [`estim::rand`](crate::rand).
    pub mod rand {
        #[doc(no_inline)]
        pub use estim_core::rand::*;
    }
    /// The rand_distr estim-core samples with: the same as [`estim::rand_distr`](crate::rand_distr).
    pub mod rand_distr {
        #[doc(no_inline)]
        pub use estim_core::rand_distr::*;
    }

    /// Automatic derivatives (feature `autodiff`): write a model once, generic over its scalar
    /// ([`AdScalar`](autodiff::AdScalar)), and [`AutoDiff`](autodiff::AutoDiff) derives its
    /// Jacobian J = ∂g/∂x and Hessians ∂²gₖ/∂xᵢ∂xⱼ exactly (to rounding) from dual numbers
    /// (num-dual): [`AutoDiffProcess`](autodiff::AutoDiffProcess) gives the process
    /// capabilities, [`AutoDiffMeasurement`](autodiff::AutoDiffMeasurement) the measurement
    /// ones, [`AutoDiffFunction`](autodiff::AutoDiffFunction) a vector function's. How to write
    /// the function: [`writing_a_model`](crate::guide::writing_a_model).
    #[cfg(feature = "autodiff")]
    pub mod autodiff {
        #[doc(inline)]
        pub use estim_core::autodiff::*;

        /// The num-dual the adapters are built on, so users name the same version.
        pub mod num_dual {
            #[doc(no_inline)]
            pub use estim_core::autodiff::num_dual::*;
        }
    }
}

/// The filters (`estim-filters`): the Kalman family as one [`GaussianFilter`](filters::GaussianFilter)
/// parameterised by its moment propagator (KF, EKF, IEKF, second-order EKF, UKF and their
/// square-root forms), the fading-memory RLS, particle filters ([`particle`](filters::particle)),
/// the IMM ([`imm`](filters::imm)), smoothers ([`Rts`](filters::Rts), [`smoother`](filters::smoother)),
/// the multi-sensor [`fusion`](filters::fusion) driver, noise identification
/// ([`noise_id`](filters::noise_id)) and Monte Carlo consistency checks
/// ([`MonteCarlo`](filters::MonteCarlo)). What each filter needs of the models:
/// [`choosing_a_filter`](crate::guide::choosing_a_filter).
pub mod filters {
    #[doc(inline)]
    pub use estim_filters::*;
}

/// The models (`estim-models`, default feature `models`): constant velocity and acceleration,
/// coordinated turn, unicycle, random walk and Gauss-Markov states with the exact
/// discretisation of continuous noise ([`motion`](models::motion)), position, range and bearing
/// sensors ([`sensors`](models::sensors)), bias augmentation ([`augment`](models::augment)), the
/// strapdown INS ([`nav`](models::nav)), and the four papers' models with their simulators.
#[cfg(feature = "models")]
pub mod models {
    #[doc(inline)]
    pub use estim_models::*;
}

/// The nalgebra estim uses, re-exported so users get the same version.
pub use estim_core::nalgebra;
/// The rand (and rand_distr) estim samples with, re-exported so users seed the same versions.
pub use estim_core::{rand, rand_distr};

/// The types and traits a typical estimation program needs.
///
/// Links to their pages under [`core`] and [`filters`] (`no_inline`: one page per item).
pub mod prelude {
    #[doc(no_inline)]
    pub use estim_core::derivative::{
        check_derivatives, check_jacobian, check_measurement_jacobian, check_measurement_model,
        check_process_jacobian, check_process_model,
    };
    #[doc(no_inline)]
    pub use estim_core::propagate::{
        Affine, Linearized, Sampled, SecondOrder, SecondOrderGaussian, Unscented,
    };
    #[doc(no_inline)]
    pub use estim_core::{
        AffineFunction, Alloc, Differentiable, Error, Euclidean, Gaussian, LinearMeasurement,
        LinearMeasurementModel, LinearProcess, LinearProcessModel, MeasurementHessian,
        MeasurementJacobian, MeasurementModel, MomentPropagator, NoInput, Offset, ProcessHessian,
        ProcessJacobian, ProcessModel, Real, StateSpace, TwiceDifferentiable, VectorFunction,
        wrap_angle,
    };
    #[doc(no_inline)]
    pub use estim_filters::fusion::{
        FusionDriver, FusionSettings, Innovation, SensorSet, SensorSettings,
    };
    #[doc(no_inline)]
    pub use estim_filters::{
        CovarianceUpdate, Ekf, EnsembleStats, Estimator, FadingMemoryRls, Gate, GaussianFilter,
        GaussianSecondOrderEkf, KalmanFilter, MonteCarlo, OnStateSpace, Predict, PredictCorrelated,
        PredictCross, ProcessInput, Recorder, Rollback, SecondOrderEkf, Ukf, Update, UpdateOutcome,
        UpdateReport, Verdict,
    };
    #[doc(no_inline)]
    pub use estim_filters::{Iekf, SquareRootFilter, SrEkf, SrKalmanFilter, SrUkf};
}

#[doc = include_str!("../README.md")]
#[cfg(doctest)]
struct ReadmeDoctests;
