//! Adapters that change how a model is called without touching its math: [`NoInput`] (a
//! process without input takes `&()`) and [`Offset`] (a measurement z = h(x) + d).
//!
//! Each passes every capability of the model through (values, Jacobians, Hessians, the
//! linear markers and the [`InPlace`] opt-in), so the adapted model runs in every filter the
//! original did, at the original's speed.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U0};

use crate::alloc::Alloc;
use crate::in_place::InPlace;
use crate::linear::{LinearMeasurement, LinearProcess};
use crate::model::{
    LinearMeasurementModel, LinearProcessModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel,
};
use crate::scalar::Real;

/// A process whose input is a zero-length vector, called with `&()` instead. Made by
/// [`LinearProcess::without_input`], or wrap your own model.
///
/// ```
/// use estim_core::{LinearProcess, ProcessModel};
/// use estim_core::nalgebra::{Matrix2, Vector2};
///
/// // x⁺ = F x + w: no input matrix, no input vector.
/// let process = LinearProcess::without_input(
///     Matrix2::new(1.0, 0.1, 0.0, 1.0),
///     Matrix2::identity() * 1e-3,
/// );
/// let x = process.transition(&Vector2::new(1.0, 2.0), &(), 0.1);
/// assert_eq!(x, Vector2::new(1.2, 2.0));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct NoInput<P>(pub P);

/// The zero-length input vector of the wrapped model.
type Empty<T> = OVector<T, U0>;

/// The zero-length input the wrapped model is called with.
#[cfg_attr(not(debug_assertions), inline(always))]
fn none<T: Real>() -> Empty<T> {
    Empty::zeros()
}

impl<T: Real, N: Dim, P: ProcessModel<T, N, Input = Empty<T>>> ProcessModel<T, N> for NoInput<P>
where
    DefaultAllocator: Alloc<N>,
{
    type Input = ();

    fn transition(&self, x: &OVector<T, N>, _: &(), dt: T) -> OVector<T, N> {
        self.0.transition(x, &none(), dt)
    }

    fn process_noise(&self, x: &OVector<T, N>, _: &(), dt: T) -> OMatrix<T, N, N> {
        self.0.process_noise(x, &none(), dt)
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, N, ()>> {
        self.0.in_place().map(|_| self as &dyn InPlace<T, N, N, ()>)
    }
}

/// The model's [`InPlace`] with the zero-length input (reached only when it has one).
impl<T: Real, N: Dim, P: ProcessModel<T, N, Input = Empty<T>>> InPlace<T, N, N, ()> for NoInput<P>
where
    DefaultAllocator: Alloc<N>,
{
    fn value_into(&self, x: &OVector<T, N>, _: &(), dt: T, out: &mut OVector<T, N>) {
        crate::model::transition_into(&self.0, x, &none(), dt, out);
    }

    fn noise_into(&self, x: &OVector<T, N>, _: &(), dt: T, out: &mut OMatrix<T, N, N>) {
        crate::model::process_noise_into(&self.0, x, &none(), dt, out);
    }

    fn jacobian_into(&self, x: &OVector<T, N>, _: &(), dt: T, out: &mut OMatrix<T, N, N>) {
        if let Some(m) = self.0.in_place() {
            m.jacobian_into(x, &none(), dt, out);
        }
    }

    fn hessian_into<'o>(
        &self,
        x: &OVector<T, N>,
        _: &(),
        dt: T,
        k: usize,
        out: &'o mut OMatrix<T, N, N>,
    ) -> Option<&'o mut OMatrix<T, N, N>> {
        self.0.in_place()?.hessian_into(x, &none(), dt, k, out)
    }
}

impl<T: Real, N: Dim, P: ProcessJacobian<T, N, Input = Empty<T>>> ProcessJacobian<T, N>
    for NoInput<P>
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_jacobian(&self, x: &OVector<T, N>, _: &(), dt: T) -> OMatrix<T, N, N> {
        self.0.transition_jacobian(x, &none(), dt)
    }
}

impl<T: Real, N: Dim, P: ProcessHessian<T, N, Input = Empty<T>>> ProcessHessian<T, N> for NoInput<P>
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_hessian(
        &self,
        x: &OVector<T, N>,
        _: &(),
        dt: T,
        k: usize,
    ) -> Option<OMatrix<T, N, N>> {
        self.0.transition_hessian(x, &none(), dt, k)
    }
}

impl<T: Real, N: Dim, P> LinearProcessModel<T, N> for NoInput<P>
where
    DefaultAllocator: Alloc<N>,
    P: LinearProcessModel<T, N> + ProcessJacobian<T, N, Input = Empty<T>>,
{
}

impl<T: Real, N: Dim> LinearProcess<T, N, U0>
where
    DefaultAllocator: Alloc<N, U0>,
{
    /// x⁺ = F x + w, w ~ N(0, Q), called with `&()` for the input (see [`NoInput`]).
    pub fn without_input(
        transition: OMatrix<T, N, N>,
        noise: OMatrix<T, N, N>,
    ) -> NoInput<LinearProcess<T, N, U0>> {
        let input = OMatrix::zeros_generic(transition.shape_generic().0, U0);
        NoInput(LinearProcess {
            transition,
            input,
            noise,
        })
    }
}

/// The measurement z = h(x) + d + v of a model h with a constant offset d (a sensor bias
/// known from calibration, pykalman's `observation_offsets`). R, the residual and the
/// derivatives are the model's.
///
/// ```
/// use estim_core::{LinearMeasurement, MeasurementModel};
/// use estim_core::adapter::Offset;
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Vector1, Vector2};
///
/// let sensor = Offset {
///     model: LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.1) },
///     offset: Vector1::new(0.5),
/// };
/// assert_eq!(sensor.measure(&Vector2::new(2.0, 7.0)), Vector1::new(2.5));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Offset<H, T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    /// The model h.
    pub model: H,
    /// The offset d (m components).
    pub offset: OVector<T, M>,
}

impl<T: Real, N: Dim, M: Dim> LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// z = H x + d + v (see [`Offset`]).
    ///
    /// ```
    /// use estim_core::{LinearMeasurement, MeasurementModel};
    /// use estim_core::nalgebra::{Matrix1, Matrix1x2, Vector1, Vector2};
    ///
    /// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.1) }
    ///     .with_offset(Vector1::new(-0.25));
    /// assert_eq!(sensor.measure(&Vector2::new(1.0, 3.0)), Vector1::new(0.75));
    /// ```
    pub fn with_offset(self, offset: OVector<T, M>) -> Offset<Self, T, M> {
        Offset {
            model: self,
            offset,
        }
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>> MeasurementModel<T, N, M>
    for Offset<H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.model.measure(x) + &self.offset
    }

    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M> {
        self.model.measurement_noise(x)
    }

    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.residual_into(a, b, out);
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, M>> {
        self.model.in_place().map(|_| self as &dyn InPlace<T, N, M>)
    }
}

/// The model's [`InPlace`] with the value shifted by d (reached only when it has one).
impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>> InPlace<T, N, M> for Offset<H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn value_into(&self, x: &OVector<T, N>, _: &(), _: T, out: &mut OVector<T, M>) {
        crate::model::measure_into(&self.model, x, out);
        *out += &self.offset;
    }

    fn noise_into(&self, x: &OVector<T, N>, _: &(), _: T, out: &mut OMatrix<T, M, M>) {
        crate::model::measurement_noise_into(&self.model, x, out);
    }

    fn jacobian_into(&self, x: &OVector<T, N>, u: &(), dt: T, out: &mut OMatrix<T, M, N>) {
        if let Some(m) = self.model.in_place() {
            m.jacobian_into(x, u, dt, out);
        }
    }

    fn hessian_into<'o>(
        &self,
        x: &OVector<T, N>,
        u: &(),
        dt: T,
        k: usize,
        out: &'o mut OMatrix<T, N, N>,
    ) -> Option<&'o mut OMatrix<T, N, N>> {
        self.model.in_place()?.hessian_into(x, u, dt, k, out)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementJacobian<T, N, M>> MeasurementJacobian<T, N, M>
    for Offset<H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.model.measurement_jacobian(x)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementHessian<T, N, M>> MeasurementHessian<T, N, M>
    for Offset<H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.measurement_hessian(x, k)
    }
}

impl<T: Real, N: Dim, M: Dim, H: LinearMeasurementModel<T, N, M>> LinearMeasurementModel<T, N, M>
    for Offset<H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
}
