//! Allocation-free runtime sizes: the one opt-in trait [`InPlace`]. The calls the filters and
//! propagators make through it (in place when the model or function opts in, else its owned
//! method) stand beside the traits they serve: [`function::eval_into`](crate::function::eval_into),
//! [`jacobian_into`](crate::function::jacobian_into) and
//! [`hessian_into`](crate::function::hessian_into);
//! [`model::transition_into`](crate::model::transition_into),
//! [`process_noise_into`](crate::model::process_noise_into),
//! [`measure_into`](crate::model::measure_into) and
//! [`measurement_noise_into`](crate::model::measurement_noise_into).
//!
//! The model traits return owned values. With static sizes (`SVector`, `SMatrix`) that costs
//! nothing; with runtime sizes (`DVector`, `DMatrix`) every value, noise matrix and Jacobian a
//! step asks for is a heap allocation. A model meant for large runtime-sized states implements
//! [`InPlace`] (its outputs written into the filter's buffers, which already have the right
//! shape) and returns `Some(self)` from
//! [`ProcessModel::in_place`](crate::ProcessModel::in_place) or
//! [`MeasurementModel::in_place`](crate::MeasurementModel::in_place); after the filter's
//! workspace is sized (its `prepare_predict` / `prepare_update`, or the first step) a step then
//! allocates nothing. [`LinearProcess`](crate::LinearProcess) and
//! [`LinearMeasurement`](crate::LinearMeasurement) do this already, and so do the adapters of
//! the library ([`NoInput`](crate::NoInput), [`Offset`](crate::Offset)) when the model they
//! wrap does.
//!
//! What a model writes is shape-checked by the caller: a wrong size is a
//! [`DimensionMismatch`](crate::Error::DimensionMismatch), never a wrong answer. A model that
//! does not opt in runs exactly as before, through its owned methods.
//!
//! Differences of outputs are not part of it: like ⊞, the residual
//! ([`MeasurementModel::residual_into`](crate::MeasurementModel::residual_into)) and a
//! function's ⊖ ([`VectorFunction::difference_into`](crate::VectorFunction::difference_into))
//! are written in place by every model, through the one method.
//!
//! ```
//! use estim_core::in_place::InPlace;
//! use estim_core::model::transition_into;
//! use estim_core::nalgebra::{DMatrix, DVector, Dyn};
//! use estim_core::ProcessModel;
//!
//! /// xᵢ⁺ = xᵢ + Δt sin xᵢ, with Q = 0.01 Δt I, written in place.
//! struct Drift;
//! impl ProcessModel<f64, Dyn> for Drift {
//!     type Input = ();
//!     fn transition(&self, x: &DVector<f64>, u: &(), dt: f64) -> DVector<f64> {
//!         let mut out = x.clone();
//!         self.value_into(x, u, dt, &mut out);
//!         out
//!     }
//!     fn process_noise(&self, x: &DVector<f64>, _: &(), dt: f64) -> DMatrix<f64> {
//!         DMatrix::identity(x.nrows(), x.nrows()) * (0.01 * dt)
//!     }
//!     fn in_place(&self) -> Option<&dyn InPlace<f64, Dyn, Dyn, ()>> {
//!         Some(self)
//!     }
//! }
//! impl InPlace<f64, Dyn, Dyn, ()> for Drift {
//!     fn value_into(&self, x: &DVector<f64>, _: &(), dt: f64, out: &mut DVector<f64>) {
//!         out.zip_apply(x, |o, xi| *o = xi + dt * xi.sin());
//!     }
//!     fn noise_into(&self, _: &DVector<f64>, _: &(), dt: f64, out: &mut DMatrix<f64>) {
//!         out.fill_with_identity();
//!         *out *= 0.01 * dt;
//!     }
//!     // No Jacobian or Hessian traits: never asked for these.
//!     fn jacobian_into(&self, _: &DVector<f64>, _: &(), _: f64, _: &mut DMatrix<f64>) {}
//!     fn hessian_into<'o>(
//!         &self, _: &DVector<f64>, _: &(), _: f64, _: usize, _: &'o mut DMatrix<f64>,
//!     ) -> Option<&'o mut DMatrix<f64>> {
//!         None
//!     }
//! }
//! let x = DVector::from_vec(vec![0.5, -1.0]);
//! let mut out = DVector::zeros(2);
//! transition_into(&Drift, &x, &(), 0.1, &mut out);
//! assert_eq!(out, Drift.transition(&x, &(), 0.1));
//! ```

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::scalar::Real;

/// Opt-in: a model (or function) whose outputs are written into buffers the caller owns, so
/// that filter steps on runtime sizes allocate nothing (see the [module docs](self)).
///
/// One trait for every kind: for a process model `U` is its input and `dt` the step; a
/// measurement model or a plain function implements `InPlace<T, N, M>` (`U = ()`) and ignores
/// `u` and `dt`. Each method writes what the owned method of the same capability returns, at
/// the same point; `out` arrives with the right shape. A method whose capability the model
/// does not implement (a Hessian of a model without
/// [`ProcessHessian`](crate::ProcessHessian), the noise of a plain function) is never called
/// and may write nothing.
pub trait InPlace<T: Real, N: Dim, M: Dim, U: ?Sized = ()>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The value f(x, u, Δt), h(x) or g(x) into `out`.
    fn value_into(&self, x: &OVector<T, N>, u: &U, dt: T, out: &mut OVector<T, M>);

    /// The additive noise covariance Q(x, u, Δt) or R(x) into `out`.
    fn noise_into(&self, x: &OVector<T, N>, u: &U, dt: T, out: &mut OMatrix<T, M, M>);

    /// The Jacobian ∂/∂x (m × n) into `out`.
    fn jacobian_into(&self, x: &OVector<T, N>, u: &U, dt: T, out: &mut OMatrix<T, M, N>);

    /// The Hessian of output component `k` into `out`, returned; `None` (and `out` untouched)
    /// when that component is affine, as the owned Hessian's `None`.
    fn hessian_into<'o>(
        &self,
        x: &OVector<T, N>,
        u: &U,
        dt: T,
        k: usize,
        out: &'o mut OMatrix<T, N, N>,
    ) -> Option<&'o mut OMatrix<T, N, N>>;
}
