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
//! - [`linear`]: linear-Gaussian models with constant matrices; [`checked`]: their
//!   constructors that check the noise once, when the model is built.
//! - [`derivative`]: checks analytic Jacobians and Hessians against finite differences, or
//!   against a reference model (such as its automatic derivatives).
//! - `autodiff` (feature `autodiff`): models written once over a dual-number scalar, with
//!   their Jacobians and Hessians derived automatically (num-dual).
//! - [`in_place`]: the one opt-in trait for allocation-free steps at runtime sizes.
//! - [`checks`]: the checks the filters run on what they are handed (finite, shape,
//!   symmetric, positive semi-definite), each with a typed [`Error`], for models to use too.
//! - [`psd_factor`]: the square root of a positive semi-definite covariance.
//! - [`manifold`]: the state's ⊞ and ⊟ ([`StateSpace`]; [`Euclidean`] by default,
//!   [`WrappedAngles`] for headings, a unit-quaternion attitude error block).
//! - [`Error`]: the one error type.
//!
//! **States with angles.** A heading near ±π is not a vector: x + δ can leave (−π, π] and a
//! difference of two headings can be off by 2π. Give the state a [`StateSpace`] whose ⊞ and ⊟
//! wrap (Hertzberg et al. 2013); [`Transition::on`] and [`Observation::on`] carry it into the
//! propagators, and a filter takes it with `GaussianFilter::with_state_space` (estim-filters).
//! The default, [`Euclidean`], is plain + and −, to the bit.
//!
//! ```
//! use core::f64::consts::PI;
//! use estim_core::nalgebra::{Const, Matrix1, Vector1};
//! use estim_core::{MomentPropagator, ProcessModel, StateSpace, Transition, Unscented, wrap_angle};
//!
//! /// A heading in (−π, π].
//! #[derive(Clone, Debug)]
//! struct Heading;
//! impl StateSpace<f64, Const<1>> for Heading {
//!     fn plus_into(&self, x: &Vector1<f64>, d: &Vector1<f64>, out: &mut Vector1<f64>) {
//!         out[0] = wrap_angle(x[0] + d[0]);
//!     }
//!     fn minus_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
//!         out[0] = wrap_angle(a[0] - b[0]);
//!     }
//! }
//! /// θ⁺ = wrap(θ + ω Δt).
//! struct Turn;
//! impl ProcessModel<f64, Const<1>> for Turn {
//!     type Input = f64;
//!     fn transition(&self, x: &Vector1<f64>, omega: &f64, dt: f64) -> Vector1<f64> {
//!         Vector1::new(wrap_angle(x[0] + omega * dt))
//!     }
//!     fn process_noise(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
//!         Matrix1::new(1e-4)
//!     }
//! }
//! let (mean, covariance) = (Vector1::new(PI - 0.05), Matrix1::new(0.01));
//! let cubature = Unscented::cubature();
//! let on_circle = Transition::on(&Heading, &Turn, &0.1, 1.0);
//! let (m, p) = cubature.propagate_mean_covariance(&mean, &covariance, &on_circle)?;
//! assert!(wrap_angle(m[0] - (-PI + 0.05)).abs() < 1e-12 && (p[(0, 0)] - 0.01).abs() < 1e-12);
//! // With + and −, one sigma point's deviation is ≈ 2π and the variance explodes.
//! let on_line = Transition::new(&Turn, &0.1, 1.0);
//! let (_, p) = cubature.propagate_mean_covariance(&mean, &covariance, &on_line)?;
//! assert!(p[(0, 0)] > 1.0);
//! # Ok::<(), estim_core::Error>(())
//! ```
//!
//! Sizes are generic: the same code serves `SVector<f64, 6>` (stack only, no heap allocation)
//! and `DVector<f64>` (heavy kernels on faer; allocation-free once a propagator's
//! [workspace](PropagatorWorkspace) is sized, for models that opt in through [`InPlace`]). The
//! allocator bounds nalgebra needs are gathered in [`Alloc`].
//!
//! **Without std** (default feature `std` off) the crate is `#![no_std]` and allocates nothing:
//! static sizes, `f32` and `f64`, every propagator but [`Sampled`], the angle and manifold
//! helpers, and [`Error`] with its `Display`. Runtime sizes, sampling (rand) and the
//! derivative checks need `std`; faer's kernels for runtime sizes need `dense` (on by default;
//! without it runtime sizes run plain loops, and faer is not compiled).
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

// Inlining, here and in estim-filters: the filter steps, propagators and kernels are
// `#[cfg_attr(not(debug_assertions), inline(always))]`, inlined whole into their callers in
// optimised builds (the steps' speed, BENCHMARKS.md, is measured so) and left to the compiler's
// judgement with debug assertions on (the test profile, where forcing it copies every step into
// each of the tests' calls: estim-filters' test binary took 262-264 s of CPU to build, 168-183 s
// without). A release build with debug assertions turned on therefore runs them as calls.

pub mod adapter;
pub mod alloc;
pub mod angle;
#[cfg(feature = "autodiff")]
pub mod autodiff;
pub mod checked;
pub mod checks;
mod dense;
#[cfg(feature = "std")]
pub mod derivative;
pub mod error;
pub mod function;
pub mod gaussian;
pub mod in_place;
#[doc(hidden)]
pub mod kernel;
#[doc(hidden)]
pub mod linalg;
pub mod linear;
pub mod manifold;
pub mod model;
pub mod propagate;
pub mod scalar;
#[cfg(feature = "serde")]
pub mod serialize;

pub use adapter::{NoInput, Offset};
pub use alloc::Alloc;
pub use angle::{wrap_angle, wrap_components};
pub use error::{Error, Parameter, Quantity, Stage};
pub use function::{AffineFunction, Differentiable, TwiceDifferentiable, VectorFunction};
pub use gaussian::Gaussian;
#[cfg(feature = "std")]
pub use gaussian::GaussianSampler;
pub use in_place::InPlace;
pub use linalg::psd_factor;
pub use linear::{LinearMeasurement, LinearProcess};
pub use manifold::{Euclidean, StateSpace, WrappedAngles};
pub use model::{
    LinearMeasurementModel, LinearProcessModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, Observation, ProcessHessian, ProcessJacobian, ProcessModel, Transition,
};
#[cfg(feature = "std")]
pub use propagate::Sampled;
pub use propagate::{
    Affine, Linearized, MomentPropagator, Moments, Outputs, PropagatorWorkspace, SecondOrder,
    SecondOrderGaussian, Unscented,
};
pub use scalar::Real;

/// The nalgebra this crate is built on, re-exported so users get the same version.
pub use nalgebra;

/// The rand and rand_distr that [`Gaussian::sampler`] and the sampled propagator use,
/// re-exported so users seed and draw with the same versions.
#[cfg(feature = "std")]
pub use rand;
#[cfg(feature = "std")]
pub use rand_distr;
