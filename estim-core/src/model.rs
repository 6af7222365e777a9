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
//!
//! Each capability has one required method (the value traits also require their noise).
//!
//! **Allocation-free dynamic sizes.** The methods return owned values, which for `Dyn` sizes
//! allocate. A model meant for large runtime-sized states implements the one opt-in trait
//! [`InPlace`] and returns `Some(self)` from its [`ProcessModel::in_place`] /
//! [`MeasurementModel::in_place`] (as [`LinearProcess`](crate::LinearProcess) and
//! [`LinearMeasurement`](crate::LinearMeasurement) do); then a filter step allocates nothing
//! ([`crate::in_place`]). The filters reach a model through [`transition_into`],
//! [`process_noise_into`], [`measure_into`] and [`measurement_noise_into`]: in place when it
//! opts in, else its owned methods.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::function::{
    AffineFunction, Differentiable, TwiceDifferentiable, VectorFunction, VectorSpaces, eval_into,
};
use crate::in_place::InPlace;
use crate::manifold::{Euclidean, StateSpace, subtract_into};
use crate::scalar::Real;

/// A discrete-time process model x⁺ = f(x, u, Δt) + w, w ~ N(0, Q(x, u, Δt)).
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a process model of a {N}-dimensional state: implement `ProcessModel<{T}, {N}>` for it (x⁺ = f(x, u, Δt) + w)",
    label = "not a `ProcessModel<{T}, {N}>`"
)]
pub trait ProcessModel<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The input (control, or sensor signals used as inputs); `()` for none.
    type Input;

    /// f(x, u, Δt): the state after one step.
    fn transition(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OVector<T, N>;

    /// Q(x, u, Δt): covariance of the additive process noise over the step. The filters
    /// evaluate it once per prediction, at the filtered mean x̂ the step starts from.
    fn process_noise(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OMatrix<T, N, N>;

    /// Opt-in for allocation-free runtime sizes: `Some(self)` from a model that implements
    /// [`InPlace`]; the default, `None`, evaluates through the owned methods.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, N, Self::Input>> {
        None
    }
}

/// A [`ProcessModel`] with an analytic Jacobian.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no process Jacobian: implement `ProcessJacobian<{T}, {N}>` for it (F = ∂f/∂x), or use a filter that needs none (`Ukf`)",
    label = "this filter linearises the process model: it needs `ProcessJacobian<{T}, {N}>`"
)]
pub trait ProcessJacobian<T: Real, N: Dim>: ProcessModel<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// F = ∂f/∂x at (x, u, Δt).
    fn transition_jacobian(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OMatrix<T, N, N>;
}

/// A [`ProcessJacobian`] with analytic Hessians.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no process Hessians: implement `ProcessHessian<{T}, {N}>` for it (∂²fₖ/∂x², `None` where fₖ is affine), or use a first-order filter (`Ekf`, `Ukf`)",
    label = "this second-order filter needs `ProcessHessian<{T}, {N}>`"
)]
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
/// [`transition_jacobian`](ProcessJacobian::transition_jacobian). The linear Kalman filter
/// accepts only such models. Implement it only when it holds (the derivative checker can
/// confirm).
///
/// A linear model needs no Hessian for the Kalman filter, the EKF or the UKF. For the
/// second-order filters it implements [`ProcessHessian`] with `None` for every component (one
/// line, and the second-order propagators then cost nothing extra). That impl is written, not
/// derived from this marker: a blanket impl would make the Hessian traits impossible to
/// implement for models generic over their scalar (overlapping impls), and would let a
/// nonlinear model that forgot its Hessians pass with zeros.
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not marked linear: implement `LinearProcessModel<{T}, {N}>` for it if f is affine in x (the `KalmanFilter` takes only such models), or use `Ekf`",
    label = "the linear Kalman filter needs `LinearProcessModel<{T}, {N}>`"
)]
pub trait LinearProcessModel<T: Real, N: Dim>: ProcessJacobian<T, N>
where
    DefaultAllocator: Alloc<N>,
{
}

/// A measurement model z = h(x) + v, v ~ N(0, R(x)), with `M` components.
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a measurement model of {M} components of a {N}-dimensional state: implement `MeasurementModel<{T}, {N}, {M}>` for it (z = h(x) + v)",
    label = "not a `MeasurementModel<{T}, {N}, {M}>`"
)]
pub trait MeasurementModel<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// h(x): the predicted measurement.
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M>;

    /// R(x): covariance of the additive measurement noise. The filters evaluate it once per
    /// update, at the predicted state x̂⁻ (the mean before the update), for every propagator.
    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M>;

    /// The residual a ⊖ b between two measurements (innovations, deviations) into `out`.
    /// Defaults to a − b; override for components that wrap, such as headings. In place for
    /// every model, like the state space's ⊟: `out` arrives with the measurements' shape
    /// (on runtime sizes, `out.copy_from(a); *out -= b;` then wrapping keeps a step
    /// allocation-free, where `*out = a - b` allocates).
    ///
    /// # Panics
    ///
    /// The default, if `a` and `b` differ in length (the filters check before they call).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        subtract_into(a, b, out);
    }

    /// Opt-in for allocation-free runtime sizes: `Some(self)` from a model that implements
    /// [`InPlace`]; the default, `None`, evaluates through the owned methods.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, M>> {
        None
    }
}

/// A [`MeasurementModel`] with an analytic Jacobian.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no measurement Jacobian: implement `MeasurementJacobian<{T}, {N}, {M}>` for it (H = ∂h/∂x), or use a filter that needs none (`Ukf`)",
    label = "this filter linearises the measurement model: it needs `MeasurementJacobian<{T}, {N}, {M}>`"
)]
pub trait MeasurementJacobian<T: Real, N: Dim, M: Dim>: MeasurementModel<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// H = ∂h/∂x at x.
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N>;
}

/// A [`MeasurementJacobian`] with analytic Hessians.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no measurement Hessians: implement `MeasurementHessian<{T}, {N}, {M}>` for it (∂²hₖ/∂x², `None` where hₖ is affine), or use a first-order filter (`Ekf`, `Ukf`)",
    label = "this second-order filter needs `MeasurementHessian<{T}, {N}, {M}>`"
)]
pub trait MeasurementHessian<T: Real, N: Dim, M: Dim>: MeasurementJacobian<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// ∂²hₖ/∂x² of measurement component `k`, or `None` when hₖ is affine in x.
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>>;
}

/// Marker: h is affine in x, h(x) = H x + c, with H the
/// [`measurement_jacobian`](MeasurementJacobian::measurement_jacobian). The linear Kalman filter
/// accepts only such models. For the second-order filters, implement [`MeasurementHessian`]
/// with `None` for every component (see [`LinearProcessModel`] for why that is not derived).
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not marked linear: implement `LinearMeasurementModel<{T}, {N}, {M}>` for it if h is affine in x (the `KalmanFilter` takes only such models), or use `Ekf`",
    label = "the linear Kalman filter needs `LinearMeasurementModel<{T}, {N}, {M}>`"
)]
pub trait LinearMeasurementModel<T: Real, N: Dim, M: Dim>: MeasurementJacobian<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
}

/// The map x ↦ f(x, u, Δt) of a process model at a fixed input and step, on the state space
/// `S` (the ⊞ of its sigma points and the ⊟ of its deviations; [`Euclidean`] by default).
///
/// ```
/// use estim_core::{Euclidean, LinearProcess, Transition, VectorFunction};
/// use estim_core::nalgebra::{Matrix1, Vector1};
///
/// let model = LinearProcess {
///     transition: Matrix1::new(2.0),
///     input: Matrix1::new(1.0),
///     noise: Matrix1::new(0.1),
/// };
/// let u = Vector1::new(0.5);
/// let f = Transition::new(&model, &u, 1.0);
/// assert_eq!(f.eval(&Vector1::new(1.0)), Vector1::new(2.5));
/// // The same map with the state space named.
/// let f = Transition::on(&Euclidean, &model, &u, 1.0);
/// assert_eq!(f.eval(&Vector1::new(1.0)), Vector1::new(2.5));
/// ```
#[derive(Debug)]
pub struct Transition<'a, P, U, T, S = Euclidean> {
    // A reference, not a value: the filter owns its state space and lends it per step, so a
    // space holding data (say, which components are angles) is never cloned.
    space: &'a S,
    model: &'a P,
    input: &'a U,
    dt: T,
}

impl<'a, P, U, T: Copy> Transition<'a, P, U, T> {
    /// The map x ↦ f(x, u, Δt) on ℝⁿ.
    pub fn new(model: &'a P, input: &'a U, dt: T) -> Self {
        Self::on(&Euclidean, model, input, dt)
    }
}

impl<'a, P, U, T: Copy, S> Transition<'a, P, U, T, S> {
    /// The map x ↦ f(x, u, Δt) on the state space `space`.
    pub fn on(space: &'a S, model: &'a P, input: &'a U, dt: T) -> Self {
        Self {
            space,
            model,
            input,
            dt,
        }
    }
}

/// The map x ↦ h(x) of a measurement model on the state space `S` ([`Euclidean`] by
/// default): sigma points are formed with the state's ⊞, differences of measurements go
/// through the model's residual, and a mean correction is added with + (a predicted
/// measurement off by 2π is harmless: innovations go through the residual).
///
/// ```
/// use estim_core::{Euclidean, LinearMeasurement, Observation, VectorFunction};
/// use estim_core::nalgebra::{Matrix1x2, Matrix1, Vector1, Vector2};
///
/// let sensor = LinearMeasurement {
///     observation: Matrix1x2::new(1.0, 1.0),
///     noise: Matrix1::new(0.1),
/// };
/// let h = Observation::new(&sensor);
/// assert_eq!(h.eval(&Vector2::new(1.0, 2.0)), Vector1::new(3.0));
/// let h = Observation::on(&Euclidean, &sensor);
/// assert_eq!(h.eval(&Vector2::new(1.0, 2.0)), Vector1::new(3.0));
/// ```
#[derive(Debug)]
pub struct Observation<'a, H: ?Sized, S = Euclidean> {
    // By reference, as in `Transition`.
    space: &'a S,
    model: &'a H,
}

impl<'a, H: ?Sized> Observation<'a, H> {
    /// The map x ↦ h(x) on ℝⁿ.
    pub fn new(model: &'a H) -> Self {
        Self::on(&Euclidean, model)
    }
}

impl<'a, H: ?Sized, S> Observation<'a, H, S> {
    /// The map x ↦ h(x) on the state space `space`.
    pub fn on(space: &'a S, model: &'a H) -> Self {
        Self { space, model }
    }
}

// Both bridges are force-inlined (without debug assertions) only where callgrind showed it
// pays: the `in_place()` hooks (the `dyn InPlace` they return is then devirtualised; without:
// KF 3/2 +3.9 %, UKF 3/2 +5.2 % instructions per step) and `TwiceDifferentiable::hessian`
// (second-order EKF 6/4 +6.3 %). The rest, the `InPlace` impl included, is the compiler's.
impl<T: Real, N: Dim, P: ProcessModel<T, N, Input = U>, U, S: StateSpace<T, N>>
    VectorFunction<T, N, N> for Transition<'_, P, U, T, S>
where
    DefaultAllocator: Alloc<N>,
{
    const VECTOR_SPACES: VectorSpaces = VectorSpaces::of_space(S::VECTOR);

    fn eval(&self, x: &OVector<T, N>) -> OVector<T, N> {
        self.model.transition(x, self.input, self.dt)
    }

    fn difference_into(&self, a: &OVector<T, N>, b: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.minus_into(a, b, out);
    }

    fn input_plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.plus_into(x, delta, out);
    }

    fn output_plus_into(&self, y: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.plus_into(y, delta, out);
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, N>> {
        self.model.in_place().map(|_| self as &dyn InPlace<T, N, N>)
    }
}

/// The model's [`InPlace`] at this step's input and Δt (reached only when the model has one).
impl<T: Real, N: Dim, P: ProcessModel<T, N, Input = U>, U, S: StateSpace<T, N>> InPlace<T, N, N>
    for Transition<'_, P, U, T, S>
where
    DefaultAllocator: Alloc<N>,
{
    fn value_into(&self, x: &OVector<T, N>, _: &(), _: T, out: &mut OVector<T, N>) {
        transition_into(self.model, x, self.input, self.dt, out);
    }

    fn noise_into(&self, x: &OVector<T, N>, _: &(), _: T, out: &mut OMatrix<T, N, N>) {
        process_noise_into(self.model, x, self.input, self.dt, out);
    }

    fn jacobian_into(&self, x: &OVector<T, N>, _: &(), _: T, out: &mut OMatrix<T, N, N>) {
        if let Some(m) = self.model.in_place() {
            m.jacobian_into(x, self.input, self.dt, out);
        }
    }

    fn hessian_into<'o>(
        &self,
        x: &OVector<T, N>,
        _: &(),
        _: T,
        k: usize,
        out: &'o mut OMatrix<T, N, N>,
    ) -> Option<&'o mut OMatrix<T, N, N>> {
        self.model
            .in_place()?
            .hessian_into(x, self.input, self.dt, k, out)
    }
}

impl<T: Real, N: Dim, P: ProcessJacobian<T, N, Input = U>, U, S: StateSpace<T, N>>
    Differentiable<T, N, N> for Transition<'_, P, U, T, S>
where
    DefaultAllocator: Alloc<N>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, N, N> {
        self.model.transition_jacobian(x, self.input, self.dt)
    }
}

impl<T: Real, N: Dim, P: ProcessHessian<T, N, Input = U>, U, S: StateSpace<T, N>>
    TwiceDifferentiable<T, N, N> for Transition<'_, P, U, T, S>
where
    DefaultAllocator: Alloc<N>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.transition_hessian(x, self.input, self.dt, k)
    }
}

impl<T: Real, N: Dim, P: LinearProcessModel<T, N, Input = U>, U, S: StateSpace<T, N>>
    AffineFunction<T, N, N> for Transition<'_, P, U, T, S>
where
    DefaultAllocator: Alloc<N>,
{
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M> + ?Sized, S: StateSpace<T, N>>
    VectorFunction<T, N, M> for Observation<'_, H, S>
where
    DefaultAllocator: Alloc<N, M>,
{
    // The output ⊞ stays +: the state space decides.
    const VECTOR_SPACES: VectorSpaces = VectorSpaces::of_space(S::VECTOR);

    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.model.measure(x)
    }

    fn difference_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.residual_into(a, b, out);
    }

    fn input_plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.plus_into(x, delta, out);
    }

    /// The model's own: its value, noise and derivatives in place.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, M>> {
        self.model.in_place()
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementJacobian<T, N, M>, S: StateSpace<T, N>>
    Differentiable<T, N, M> for Observation<'_, H, S>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.model.measurement_jacobian(x)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementHessian<T, N, M>, S: StateSpace<T, N>>
    TwiceDifferentiable<T, N, M> for Observation<'_, H, S>
where
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.measurement_hessian(x, k)
    }
}

impl<T: Real, N: Dim, M: Dim, H: LinearMeasurementModel<T, N, M>, S: StateSpace<T, N>>
    AffineFunction<T, N, M> for Observation<'_, H, S>
where
    DefaultAllocator: Alloc<N, M>,
{
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
