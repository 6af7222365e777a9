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
//! **Allocation-free dynamic sizes.** The provided `_into` methods write into a buffer the
//! filter owns (already of the right shape). The defaults store the owned result, which for
//! `Dyn` sizes allocates; a model meant for large runtime-sized states overrides the `_into`
//! methods (as [`LinearProcess`](crate::LinearProcess) and
//! [`LinearMeasurement`](crate::LinearMeasurement) do), and then a filter step allocates
//! nothing. What a model writes is shape-checked: a wrong size is a
//! [`DimensionMismatch`](crate::Error::DimensionMismatch), never a wrong answer.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::error::Result;
use crate::function::{
    AffineFunction, Differentiable, SigmaScratch, TwiceDifferentiable, VectorFunction,
    sigma_points_one_by_one, sigma_points_through, store_hessian,
};
use crate::manifold::{Euclidean, StateSpace, add_into};
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

    /// Q(x, u, Δt): covariance of the additive process noise over the step. The filters
    /// evaluate it once per prediction, at the filtered mean x̂ the step starts from.
    fn process_noise(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OMatrix<T, N, N>;

    /// [`transition`](Self::transition) into `out`.
    #[inline(always)]
    fn transition_into(&self, x: &OVector<T, N>, u: &Self::Input, dt: T, out: &mut OVector<T, N>) {
        *out = self.transition(x, u, dt);
    }

    /// [`process_noise`](Self::process_noise) into `out`.
    #[inline(always)]
    fn process_noise_into(
        &self,
        x: &OVector<T, N>,
        u: &Self::Input,
        dt: T,
        out: &mut OMatrix<T, N, N>,
    ) {
        *out = self.process_noise(x, u, dt);
    }

    /// f(·, u, Δt) at the 2n sigma points μ ± Lⱼ into the columns of `plus` and `minus`:
    /// see [`VectorFunction::eval_sigma_points_into`]. The default maps them one at a time
    /// through [`transition_into`](Self::transition_into); a model that maps them with one
    /// matrix product saves most of the unscented prediction's cost.
    #[inline(always)]
    fn transition_sigma_points_into(
        &self,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        u: &Self::Input,
        dt: T,
        plus: &mut OMatrix<T, N, N>,
        minus: &mut OMatrix<T, N, N>,
        scratch: &mut SigmaScratch<T, N, N>,
    ) -> Result<()> {
        sigma_points_one_by_one(mean, offsets, plus, minus, scratch, add_into, |x, y| {
            self.transition_into(x, u, dt, y)
        })
    }
}

/// A [`ProcessModel`] with an analytic Jacobian.
pub trait ProcessJacobian<T: Real, N: Dim>: ProcessModel<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// F = ∂f/∂x at (x, u, Δt).
    fn transition_jacobian(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OMatrix<T, N, N>;

    /// [`transition_jacobian`](Self::transition_jacobian) into `out`.
    #[inline(always)]
    fn transition_jacobian_into(
        &self,
        x: &OVector<T, N>,
        u: &Self::Input,
        dt: T,
        out: &mut OMatrix<T, N, N>,
    ) {
        *out = self.transition_jacobian(x, u, dt);
    }
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

    /// [`transition_hessian`](Self::transition_hessian) into `out`: `true` if written,
    /// `false` if fₖ is affine.
    #[inline(always)]
    fn transition_hessian_into(
        &self,
        x: &OVector<T, N>,
        u: &Self::Input,
        dt: T,
        k: usize,
        out: &mut OMatrix<T, N, N>,
    ) -> bool {
        store_hessian(self.transition_hessian(x, u, dt, k), out)
    }
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
pub trait LinearProcessModel<T: Real, N: Dim>: ProcessJacobian<T, N>
where
    DefaultAllocator: Alloc<N>,
{
}

/// A measurement model z = h(x) + v, v ~ N(0, R(x)), with `M` components.
pub trait MeasurementModel<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// h(x): the predicted measurement.
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M>;

    /// R(x): covariance of the additive measurement noise. The filters evaluate it once per
    /// update, at the predicted state x̂⁻ (the mean before the update), for every propagator.
    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M>;

    /// The residual a ⊖ b between two measurements (innovations, deviations). Defaults to
    /// a − b; override for components that wrap, such as headings.
    fn residual(&self, a: &OVector<T, M>, b: &OVector<T, M>) -> OVector<T, M> {
        a - b
    }

    /// [`measure`](Self::measure) into `out`.
    #[inline(always)]
    fn measure_into(&self, x: &OVector<T, N>, out: &mut OVector<T, M>) {
        *out = self.measure(x);
    }

    /// [`measurement_noise`](Self::measurement_noise) into `out`.
    #[inline(always)]
    fn measurement_noise_into(&self, x: &OVector<T, N>, out: &mut OMatrix<T, M, M>) {
        *out = self.measurement_noise(x);
    }

    /// [`residual`](Self::residual) into `out`. The default stores `residual(a, b)`; a model
    /// that keeps the default subtraction can make it allocation-free for `Dyn` sizes with
    /// `out.copy_from(a); *out -= b;`.
    #[inline(always)]
    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        *out = self.residual(a, b);
    }

    /// h at the 2n sigma points μ ± Lⱼ into the columns of `plus` and `minus` (m × n): see
    /// [`VectorFunction::eval_sigma_points_into`]. The default maps them one at a time through
    /// [`measure_into`](Self::measure_into).
    #[inline(always)]
    fn measure_sigma_points_into(
        &self,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        plus: &mut OMatrix<T, M, N>,
        minus: &mut OMatrix<T, M, N>,
        scratch: &mut SigmaScratch<T, N, M>,
    ) -> Result<()> {
        sigma_points_one_by_one(mean, offsets, plus, minus, scratch, add_into, |x, y| {
            self.measure_into(x, y)
        })
    }
}

/// A [`MeasurementModel`] with an analytic Jacobian.
pub trait MeasurementJacobian<T: Real, N: Dim, M: Dim>: MeasurementModel<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// H = ∂h/∂x at x.
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N>;

    /// [`measurement_jacobian`](Self::measurement_jacobian) into `out`.
    #[inline(always)]
    fn measurement_jacobian_into(&self, x: &OVector<T, N>, out: &mut OMatrix<T, M, N>) {
        *out = self.measurement_jacobian(x);
    }
}

/// A [`MeasurementJacobian`] with analytic Hessians.
pub trait MeasurementHessian<T: Real, N: Dim, M: Dim>: MeasurementJacobian<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// ∂²hₖ/∂x² of measurement component `k`, or `None` when hₖ is affine in x.
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>>;

    /// [`measurement_hessian`](Self::measurement_hessian) into `out`: `true` if written,
    /// `false` if hₖ is affine.
    #[inline(always)]
    fn measurement_hessian_into(
        &self,
        x: &OVector<T, N>,
        k: usize,
        out: &mut OMatrix<T, N, N>,
    ) -> bool {
        store_hessian(self.measurement_hessian(x, k), out)
    }
}

/// Marker: h is affine in x, h(x) = H x + c, with H the
/// [`measurement_jacobian`](MeasurementJacobian::measurement_jacobian). The linear Kalman filter
/// accepts only such models. For the second-order filters, implement [`MeasurementHessian`]
/// with `None` for every component (see [`LinearProcessModel`] for why that is not derived).
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

impl<P, U, T, N, S> VectorFunction<T, N, N> for Transition<'_, P, U, T, S>
where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N, Input = U>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N>,
{
    const VECTOR_SPACES: bool = S::VECTOR;

    fn eval(&self, x: &OVector<T, N>) -> OVector<T, N> {
        self.model.transition(x, self.input, self.dt)
    }

    #[inline(always)]
    fn eval_into(&self, x: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.model.transition_into(x, self.input, self.dt, out);
    }

    #[inline(always)]
    fn input_plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.plus_into(x, delta, out);
    }

    #[inline(always)]
    fn output_plus_into(&self, y: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.plus_into(y, delta, out);
    }

    /// The model's batch hook on a vector space; otherwise the points one at a time through
    /// ⊞ (a batch hook forms μ ± Lⱼ with + and would bypass it).
    #[inline(always)]
    fn eval_sigma_points_into(
        &self,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        plus: &mut OMatrix<T, N, N>,
        minus: &mut OMatrix<T, N, N>,
        scratch: &mut SigmaScratch<T, N, N>,
    ) -> Result<()> {
        if S::VECTOR {
            self.model.transition_sigma_points_into(
                mean, offsets, self.input, self.dt, plus, minus, scratch,
            )
        } else {
            sigma_points_through(self, mean, offsets, plus, minus, scratch)
        }
    }

    fn difference(&self, a: &OVector<T, N>, b: &OVector<T, N>) -> OVector<T, N> {
        let mut out = a.clone();
        self.space.minus_into(a, b, &mut out);
        out
    }

    #[inline(always)]
    fn difference_into(&self, a: &OVector<T, N>, b: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.minus_into(a, b, out);
    }
}

impl<P, U, T, N, S> Differentiable<T, N, N> for Transition<'_, P, U, T, S>
where
    T: Real,
    N: Dim,
    P: ProcessJacobian<T, N, Input = U>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, N, N> {
        self.model.transition_jacobian(x, self.input, self.dt)
    }

    #[inline(always)]
    fn jacobian_into(&self, x: &OVector<T, N>, out: &mut OMatrix<T, N, N>) {
        self.model
            .transition_jacobian_into(x, self.input, self.dt, out);
    }
}

impl<P, U, T, N, S> TwiceDifferentiable<T, N, N> for Transition<'_, P, U, T, S>
where
    T: Real,
    N: Dim,
    P: ProcessHessian<T, N, Input = U>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N>,
{
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.transition_hessian(x, self.input, self.dt, k)
    }

    #[inline(always)]
    fn hessian_into(&self, x: &OVector<T, N>, k: usize, out: &mut OMatrix<T, N, N>) -> bool {
        self.model
            .transition_hessian_into(x, self.input, self.dt, k, out)
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
pub struct Observation<'a, H, S = Euclidean> {
    // By reference, as in `Transition`.
    space: &'a S,
    model: &'a H,
}

impl<'a, H> Observation<'a, H> {
    /// The map x ↦ h(x) on ℝⁿ.
    pub fn new(model: &'a H) -> Self {
        Self::on(&Euclidean, model)
    }
}

impl<'a, H, S> Observation<'a, H, S> {
    /// The map x ↦ h(x) on the state space `space`.
    pub fn on(space: &'a S, model: &'a H) -> Self {
        Self { space, model }
    }
}

impl<H, T, N, M, S> VectorFunction<T, N, M> for Observation<'_, H, S>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N, M>,
{
    // The output ⊞ stays +: the state space decides.
    const VECTOR_SPACES: bool = S::VECTOR;

    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.model.measure(x)
    }

    fn difference(&self, a: &OVector<T, M>, b: &OVector<T, M>) -> OVector<T, M> {
        self.model.residual(a, b)
    }

    #[inline(always)]
    fn eval_into(&self, x: &OVector<T, N>, out: &mut OVector<T, M>) {
        self.model.measure_into(x, out);
    }

    #[inline(always)]
    fn input_plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        self.space.plus_into(x, delta, out);
    }

    /// The model's batch hook on a vector space; otherwise the points one at a time through
    /// ⊞.
    #[inline(always)]
    fn eval_sigma_points_into(
        &self,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        plus: &mut OMatrix<T, M, N>,
        minus: &mut OMatrix<T, M, N>,
        scratch: &mut SigmaScratch<T, N, M>,
    ) -> Result<()> {
        if S::VECTOR {
            self.model
                .measure_sigma_points_into(mean, offsets, plus, minus, scratch)
        } else {
            sigma_points_through(self, mean, offsets, plus, minus, scratch)
        }
    }

    #[inline(always)]
    fn difference_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.residual_into(a, b, out);
    }
}

impl<H, T, N, M, S> Differentiable<T, N, M> for Observation<'_, H, S>
where
    T: Real,
    N: Dim,
    M: Dim,
    S: StateSpace<T, N>,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.model.measurement_jacobian(x)
    }

    #[inline(always)]
    fn jacobian_into(&self, x: &OVector<T, N>, out: &mut OMatrix<T, M, N>) {
        self.model.measurement_jacobian_into(x, out);
    }
}

impl<H, T, N, M, S> TwiceDifferentiable<T, N, M> for Observation<'_, H, S>
where
    T: Real,
    N: Dim,
    M: Dim,
    S: StateSpace<T, N>,
    H: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.measurement_hessian(x, k)
    }

    #[inline(always)]
    fn hessian_into(&self, x: &OVector<T, N>, k: usize, out: &mut OMatrix<T, N, N>) -> bool {
        self.model.measurement_hessian_into(x, k, out)
    }
}

impl<P, U, T, N, S> AffineFunction<T, N, N> for Transition<'_, P, U, T, S>
where
    T: Real,
    N: Dim,
    P: LinearProcessModel<T, N, Input = U>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N>,
{
}

impl<H, T, N, M, S> AffineFunction<T, N, M> for Observation<'_, H, S>
where
    T: Real,
    N: Dim,
    M: Dim,
    S: StateSpace<T, N>,
    H: LinearMeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
}
