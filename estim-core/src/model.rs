//! Process and measurement models, one capability per trait.
//!
//! | trait | provides | needed by |
//! |---|---|---|
//! | [`ProcessModel`] | x⁺ = f(x, u, Δt), process noise Q(x, u, Δt) | unscented / sampled prediction |
//! | [`ProcessJacobian`] | F = ∂f/∂x | extended Kalman prediction |
//! | [`ProcessHessian`] | ∂²fᵢ/∂x² per component | second-order prediction |
//! | [`MeasurementModel`] | z = h(x), noise R(x), residual z ⊖ ẑ | unscented / sampled update |
//! | [`MeasurementJacobian`] | H = ∂h/∂x | extended Kalman update |
//! | [`MeasurementHessian`] | ∂²hᵢ/∂x² per component | second-order update |
//!
//! The noise is additive: x⁺ = f(x, u, Δt) + w with w ~ N(0, Q), z = h(x) + v with
//! v ~ N(0, R). Q may depend on the state and input (Boje's accelerometer-derived inputs make
//! it do so); it is evaluated at the estimate.
//!
//! [`Transition`] and [`Observation`] turn a model into a [`VectorFunction`] (with the same
//! derivative capabilities), which is what the moment propagators consume.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::function::{AffineFunction, Differentiable, TwiceDifferentiable, VectorFunction};
use crate::scalar::Real;

/// A discrete-time process model x⁺ = f(x, u, Δt) + w, w ~ N(0, Q(x, u, Δt)).
pub trait ProcessModel<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The input (control, or sensor signals used as inputs); `()` for none.
    type Input;

    /// f(x, u, Δt): the state after one step.
    fn transition(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OVector<T, N>;

    /// Q(x, u, Δt): covariance of the additive process noise over the step.
    fn process_noise(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OMatrix<T, N, N>;
}

/// A [`ProcessModel`] with an analytic Jacobian.
pub trait ProcessJacobian<T: Real, N: Dim>: ProcessModel<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// F = ∂f/∂x at (x, u, Δt).
    fn transition_jacobian(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OMatrix<T, N, N>;
}

/// A [`ProcessJacobian`] with analytic Hessians.
pub trait ProcessHessian<T: Real, N: Dim>: ProcessJacobian<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// ∂²fₖ/∂x² of state component `k`, or `None` when fₖ is affine in x.
    fn transition_hessian(
        &self,
        x: &OVector<T, N>,
        u: &Self::Input,
        dt: T,
        k: usize,
    ) -> Option<OMatrix<T, N, N>>;
}

/// Marker: f is affine in x, f(x, u, Δt) = F(u, Δt) x + b(u, Δt), with F the
/// [`transition_jacobian`](ProcessJacobian::transition_jacobian). Such a model gets zero
/// Hessians for free (so it also works with second-order filters) and is accepted by the linear
/// Kalman filter. Implement it only when it holds (the derivative checker can confirm).
pub trait LinearProcessModel<T: Real, N: Dim>: ProcessJacobian<T, N>
where
    DefaultAllocator: Alloc<N>,
{
}

impl<T: Real, N: Dim, P: LinearProcessModel<T, N>> ProcessHessian<T, N> for P
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_hessian(
        &self,
        _: &OVector<T, N>,
        _: &P::Input,
        _: T,
        _: usize,
    ) -> Option<OMatrix<T, N, N>> {
        None
    }
}

/// A measurement model z = h(x) + v, v ~ N(0, R(x)), with `M` components.
pub trait MeasurementModel<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// h(x): the predicted measurement.
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M>;

    /// R(x): covariance of the additive measurement noise.
    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M>;

    /// The residual a ⊖ b between two measurements (innovations, deviations). Defaults to
    /// a − b; override for components that wrap, such as headings.
    fn residual(&self, a: &OVector<T, M>, b: &OVector<T, M>) -> OVector<T, M> {
        a - b
    }
}

/// A [`MeasurementModel`] with an analytic Jacobian.
pub trait MeasurementJacobian<T: Real, N: Dim, M: Dim>: MeasurementModel<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// H = ∂h/∂x at x.
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N>;
}

/// A [`MeasurementJacobian`] with analytic Hessians.
pub trait MeasurementHessian<T: Real, N: Dim, M: Dim>: MeasurementJacobian<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// ∂²hₖ/∂x² of measurement component `k`, or `None` when hₖ is affine in x.
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>>;
}

/// Marker: h is affine in x, h(x) = H x + c, with H the
/// [`measurement_jacobian`](MeasurementJacobian::measurement_jacobian). Such a model gets zero
/// Hessians for free and is accepted by the linear Kalman filter.
pub trait LinearMeasurementModel<T: Real, N: Dim, M: Dim>: MeasurementJacobian<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
}

impl<T: Real, N: Dim, M: Dim, H: LinearMeasurementModel<T, N, M>> MeasurementHessian<T, N, M> for H
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_hessian(&self, _: &OVector<T, N>, _: usize) -> Option<OMatrix<T, N, N>> {
        None
    }
}

/// The map x ↦ f(x, u, Δt) of a process model at a fixed input and step.
#[derive(Debug)]
pub struct Transition<'a, P, U, T> {
    model: &'a P,
    input: &'a U,
    dt: T,
}

impl<'a, P, U, T: Copy> Transition<'a, P, U, T> {
    /// The map x ↦ f(x, u, Δt).
    pub fn new(model: &'a P, input: &'a U, dt: T) -> Self {
        Self { model, input, dt }
    }
}

impl<P, U, T, N> VectorFunction<T, N, N> for Transition<'_, P, U, T>
where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N, Input = U>,
    DefaultAllocator: Alloc<N>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, N> {
        self.model.transition(x, self.input, self.dt)
    }
}

impl<P, U, T, N> Differentiable<T, N, N> for Transition<'_, P, U, T>
where
    T: Real,
    N: Dim,
    P: ProcessJacobian<T, N, Input = U>,
    DefaultAllocator: Alloc<N>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, N, N> {
        self.model.transition_jacobian(x, self.input, self.dt)
    }
}

impl<P, U, T, N> TwiceDifferentiable<T, N, N> for Transition<'_, P, U, T>
where
    T: Real,
    N: Dim,
    P: ProcessHessian<T, N, Input = U>,
    DefaultAllocator: Alloc<N>,
{
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.transition_hessian(x, self.input, self.dt, k)
    }
}

/// The map x ↦ h(x) of a measurement model; differences go through its residual.
#[derive(Debug)]
pub struct Observation<'a, H> {
    model: &'a H,
}

impl<'a, H> Observation<'a, H> {
    /// The map x ↦ h(x).
    pub fn new(model: &'a H) -> Self {
        Self { model }
    }
}

impl<H, T, N, M> VectorFunction<T, N, M> for Observation<'_, H>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.model.measure(x)
    }

    fn difference(&self, a: &OVector<T, M>, b: &OVector<T, M>) -> OVector<T, M> {
        self.model.residual(a, b)
    }
}

impl<H, T, N, M> Differentiable<T, N, M> for Observation<'_, H>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.model.measurement_jacobian(x)
    }
}

impl<H, T, N, M> TwiceDifferentiable<T, N, M> for Observation<'_, H>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.measurement_hessian(x, k)
    }
}

impl<P, U, T, N> AffineFunction<T, N, N> for Transition<'_, P, U, T>
where
    T: Real,
    N: Dim,
    P: LinearProcessModel<T, N, Input = U>,
    DefaultAllocator: Alloc<N>,
{
}

impl<H, T, N, M> AffineFunction<T, N, M> for Observation<'_, H>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: LinearMeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
}
