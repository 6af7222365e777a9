//! Allocation-free runtime sizes: the one opt-in trait [`InPlace`], and the calls the filters
//! and propagators make through it.
//!
//! The model traits return owned values. With static sizes (`SVector`, `SMatrix`) that costs
//! nothing; with runtime sizes (`DVector`, `DMatrix`) every value, noise matrix and Jacobian a
//! step asks for is a heap allocation. A model meant for large runtime-sized states implements
//! [`InPlace`] (its outputs written into the filter's buffers, which already have the right
//! shape) and returns `Some(self)` from [`ProcessModel::in_place`] or
//! [`MeasurementModel::in_place`]; after the filter's workspace is sized (its
//! `prepare_predict` / `prepare_update`, or the first step) a step then allocates nothing.
//! [`LinearProcess`](crate::LinearProcess) and [`LinearMeasurement`](crate::LinearMeasurement)
//! do this already, and so do the adapters of the library ([`NoInput`](crate::NoInput),
//! [`Offset`](crate::Offset)) when the model they wrap does.
//!
//! What a model writes is shape-checked by the caller: a wrong size is a
//! [`DimensionMismatch`](crate::Error::DimensionMismatch), never a wrong answer. A model that
//! does not opt in runs exactly as before, through its owned methods.
//!
//! Differences of outputs are not part of it: like ⊞, the residual
//! ([`MeasurementModel::residual_into`]) and a function's ⊖
//! ([`VectorFunction::difference_into`]) are written in place by every model, through the one
//! method.
//!
//! ```
//! use estim_core::in_place::{InPlace, transition_into};
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
use crate::function::{Differentiable, TwiceDifferentiable, VectorFunction};
use crate::model::{MeasurementModel, Observation, ProcessModel};
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

/// g(x) into `out`: in place for an [`InPlace`] function, else the owned value.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn eval_into<T, N, M, G>(g: &G, x: &OVector<T, N>, out: &mut OVector<T, M>)
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    match g.in_place() {
        Some(g) => g.value_into(x, &(), T::zero(), out),
        None => *out = g.eval(x),
    }
}

/// J(x) into `out`.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn jacobian_into<T, N, M, G>(g: &G, x: &OVector<T, N>, out: &mut OMatrix<T, M, N>)
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    match g.in_place() {
        Some(g) => g.jacobian_into(x, &(), T::zero(), out),
        None => *out = g.jacobian(x),
    }
}

/// Hₖ(x) into `out`, returned; `None` when gₖ is affine.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn hessian_into<'o, T, N, M, G>(
    g: &G,
    x: &OVector<T, N>,
    k: usize,
    out: &'o mut OMatrix<T, N, N>,
) -> Option<&'o mut OMatrix<T, N, N>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    match g.in_place() {
        Some(g) => g.hessian_into(x, &(), T::zero(), k, out),
        None => {
            *out = g.hessian(x, k)?;
            Some(out)
        }
    }
}

/// f(x, u, Δt) into `out`.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn transition_into<T, N, P>(
    model: &P,
    x: &OVector<T, N>,
    u: &P::Input,
    dt: T,
    out: &mut OVector<T, N>,
) where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N> + ?Sized,
    DefaultAllocator: Alloc<N>,
{
    match model.in_place() {
        Some(m) => m.value_into(x, u, dt, out),
        None => *out = model.transition(x, u, dt),
    }
}

/// Q(x, u, Δt) into `out`.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn process_noise_into<T, N, P>(
    model: &P,
    x: &OVector<T, N>,
    u: &P::Input,
    dt: T,
    out: &mut OMatrix<T, N, N>,
) where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N> + ?Sized,
    DefaultAllocator: Alloc<N>,
{
    match model.in_place() {
        Some(m) => m.noise_into(x, u, dt, out),
        None => *out = model.process_noise(x, u, dt),
    }
}

/// h(x) into `out`: [`eval_into`] of the model's [`Observation`].
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn measure_into<T, N, M, H>(model: &H, x: &OVector<T, N>, out: &mut OVector<T, M>)
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    eval_into(&Observation::new(model), x, out);
}

/// R(x) into `out`.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn measurement_noise_into<T, N, M, H>(model: &H, x: &OVector<T, N>, out: &mut OMatrix<T, M, M>)
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    match model.in_place() {
        Some(m) => m.noise_into(x, &(), T::zero(), out),
        None => *out = model.measurement_noise(x),
    }
}
