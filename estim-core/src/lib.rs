//! # estim-core
//!
//! The foundation of [estim](https://docs.rs/estim): everything a filter needs to know about a
//! model, and nothing about filters.
//!
//! - [`Real`]: the scalar (`f32` or `f64`).
//! - [`Gaussian`]: a mean and a checked covariance.
//! - [`function`]: vector functions y = g(x) with optional analytic Jacobian and Hessians,
//!   one capability per trait ([`VectorFunction`] ← [`Differentiable`] ← [`TwiceDifferentiable`]).
//! - [`model`]: process models x⁺ = f(x, u, Δt) and measurement models z = h(x) with their noise,
//!   again one capability per trait, and the adapters that turn them into vector functions.
//! - [`propagate`]: the moment propagators — given x ~ N(μ, C) and y = g(x), the mean and
//!   covariance of y and the cross-covariance of x and y — linearised, second order (Papoulis),
//!   Gaussian second order, unscented and sampled.
//! - [`linear`]: linear-Gaussian models with constant matrices.
//! - [`derivative`]: checks analytic Jacobians and Hessians against finite differences.
//! - [`psd_factor`]: the square root of a positive semi-definite covariance.
//! - [`Error`]: the one error type.
//!
//! Sizes are generic: the same code serves `SVector<f64, 6>` (stack only, no heap allocation)
//! and `DVector<f64>` (heavy kernels on faer; allocation-free once a propagator's
//! [workspace](PropagatorWorkspace) is sized, for models that implement the `_into` methods). The allocator bounds nalgebra needs are
//! gathered in [`Alloc`].
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod alloc;
pub mod angle;
pub mod derivative;
pub mod error;
pub mod function;
pub mod gaussian;
#[doc(hidden)]
pub mod kernel;
#[doc(hidden)]
pub mod linalg;
pub mod linear;
pub mod manifold;
pub mod model;
pub mod propagate;
pub mod scalar;

pub use alloc::Alloc;
pub use angle::{wrap_angle, wrap_components};
pub use error::{Error, Parameter, Quantity, Stage};
pub use function::{
    AffineFunction, Differentiable, SigmaScratch, TwiceDifferentiable, VectorFunction,
};
pub use gaussian::Gaussian;
pub use linalg::psd_factor;
pub use linear::{LinearMeasurement, LinearProcess};
pub use manifold::{Euclidean, StateSpace};
pub use model::{
    LinearMeasurementModel, LinearProcessModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, Observation, ProcessHessian, ProcessJacobian, ProcessModel, Transition,
};
pub use propagate::{
    Affine, Linearized, MomentPropagator, Moments, Outputs, PropagatorWorkspace, Sampled,
    SecondOrder, SecondOrderGaussian, Unscented,
};
pub use scalar::Real;

/// The nalgebra this crate is built on, re-exported so users get the same version.
pub use nalgebra;
