//! Linear-Gaussian models with constant matrices.
//!
//! [`LinearProcess`]: x⁺ = F x + B u + w, w ~ N(0, Q). [`LinearMeasurement`]: z = H x + v,
//! v ~ N(0, R). Both implement every model capability (their Hessians are zero), so they work
//! with every filter, including the linear Kalman filter. Their matrices are per step: Δt is
//! accepted (filters pass it) and ignored. For matrices that depend on Δt, implement the model
//! traits on your own type. A process without input: [`LinearProcess::without_input`] (called
//! with `&()`); a measurement with a constant offset: [`LinearMeasurement::with_offset`].
//!
//! To check Q and R once, when the model is built (symmetric, positive semi-definite), build
//! it with [`LinearProcess::try_new`] / [`LinearMeasurement::try_new`] ([`crate::checked`]).
//!
//! Both implement [`InPlace`] (their matrices copied or multiplied into the filter's buffers),
//! so with `Dyn` sizes a filter step over them allocates nothing. Matrices whose shapes disagree with the state are reported by the filter as a
//! [`DimensionMismatch`](crate::Error::DimensionMismatch) (or, for an inner dimension nalgebra
//! cannot multiply, by nalgebra's panic).

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::in_place::InPlace;
use crate::kernel::{self, Accum};
use crate::model::{
    LinearMeasurementModel, LinearProcessModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel,
};
use crate::scalar::Real;

/// x⁺ = F x + B u + w, w ~ N(0, Q), with `U` inputs, for one step: Δt is ignored (module
/// docs). Without input: [`LinearProcess::without_input`].
#[derive(Clone, Debug, PartialEq)]
pub struct LinearProcess<T: Real, N: Dim, U: Dim>
where
    DefaultAllocator: Alloc<N, U>,
{
    /// Transition matrix F (n × n).
    pub transition: OMatrix<T, N, N>,
    /// Input matrix B (n × p).
    pub input: OMatrix<T, N, U>,
    /// Process noise covariance Q (n × n).
    pub noise: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim, U: Dim> ProcessModel<T, N> for LinearProcess<T, N, U>
where
    DefaultAllocator: Alloc<N, U>,
{
    type Input = OVector<T, U>;

    fn transition(&self, x: &OVector<T, N>, u: &OVector<T, U>, _dt: T) -> OVector<T, N> {
        &self.transition * x + &self.input * u
    }

    fn process_noise(&self, _: &OVector<T, N>, _: &OVector<T, U>, _dt: T) -> OMatrix<T, N, N> {
        self.noise.clone()
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, N, OVector<T, U>>> {
        Some(self)
    }
}

/// F x + B u, Q, F and no Hessians, written into the caller's buffers.
impl<T: Real, N: Dim, U: Dim> InPlace<T, N, N, OVector<T, U>> for LinearProcess<T, N, U>
where
    DefaultAllocator: Alloc<N, U>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn value_into(&self, x: &OVector<T, N>, u: &OVector<T, U>, _dt: T, out: &mut OVector<T, N>) {
        let (f, b) = (&self.transition, &self.input);
        let fits = f.shape() == (out.nrows(), x.nrows()) && b.shape() == (out.nrows(), u.nrows());
        if fits {
            // kernel::mul, not nalgebra's gemv: for runtime sizes (and static ones above
            // kernel::STATIC_NALGEBRA_MAX) its matrix–vector kernel is compiled for the CPU's
            // vector width (chosen at run time), where nalgebra's gemv is compiled for the
            // baseline target and its fixed-size product is not blocked; small static sizes
            // get the operator form, which unrolls (the same bits as `f * x + b * u`).
            kernel::mul(out, Accum::Replace, T::one(), f, x);
            kernel::mul(out, Accum::Add, T::one(), b, u);
        } else {
            *out = f * x + b * u;
        }
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn noise_into(&self, _: &OVector<T, N>, _: &OVector<T, U>, _dt: T, out: &mut OMatrix<T, N, N>) {
        assign(out, &self.noise);
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn jacobian_into(
        &self,
        _: &OVector<T, N>,
        _: &OVector<T, U>,
        _dt: T,
        out: &mut OMatrix<T, N, N>,
    ) {
        assign(out, &self.transition);
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn hessian_into<'o>(
        &self,
        _: &OVector<T, N>,
        _: &OVector<T, U>,
        _dt: T,
        _: usize,
        _: &'o mut OMatrix<T, N, N>,
    ) -> Option<&'o mut OMatrix<T, N, N>> {
        None
    }
}

/// `out` ← `value`, copying in place when the shapes agree.
#[cfg_attr(not(debug_assertions), inline(always))]
fn assign<T: Real, R: Dim, C: Dim>(out: &mut OMatrix<T, R, C>, value: &OMatrix<T, R, C>)
where
    DefaultAllocator: nalgebra::allocator::Allocator<R, C>,
{
    if out.shape() == value.shape() {
        crate::kernel::copy(out, value);
    } else {
        *out = value.clone();
    }
}

impl<T: Real, N: Dim, U: Dim> ProcessJacobian<T, N> for LinearProcess<T, N, U>
where
    DefaultAllocator: Alloc<N, U>,
{
    fn transition_jacobian(
        &self,
        _: &OVector<T, N>,
        _: &OVector<T, U>,
        _dt: T,
    ) -> OMatrix<T, N, N> {
        self.transition.clone()
    }
}

impl<T: Real, N: Dim, U: Dim> ProcessHessian<T, N> for LinearProcess<T, N, U>
where
    DefaultAllocator: Alloc<N, U>,
{
    /// `None`: every component is affine.
    fn transition_hessian(
        &self,
        _: &OVector<T, N>,
        _: &OVector<T, U>,
        _dt: T,
        _: usize,
    ) -> Option<OMatrix<T, N, N>> {
        None
    }
}

impl<T: Real, N: Dim, U: Dim> LinearProcessModel<T, N> for LinearProcess<T, N, U> where
    DefaultAllocator: Alloc<N, U>
{
}

/// z = H x + v, v ~ N(0, R).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearMeasurement<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Measurement matrix H (m × n).
    pub observation: OMatrix<T, M, N>,
    /// Measurement noise covariance R (m × m).
    pub noise: OMatrix<T, M, M>,
}

impl<T: Real, N: Dim, M: Dim> MeasurementModel<T, N, M> for LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        &self.observation * x
    }

    fn measurement_noise(&self, _: &OVector<T, N>) -> OMatrix<T, M, M> {
        self.noise.clone()
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, M>> {
        Some(self)
    }
}

/// H x, R, H and no Hessians, written into the caller's buffers.
impl<T: Real, N: Dim, M: Dim> InPlace<T, N, M> for LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn value_into(&self, x: &OVector<T, N>, _: &(), _: T, out: &mut OVector<T, M>) {
        let h = &self.observation;
        if h.shape() == (out.nrows(), x.nrows()) {
            kernel::mul(out, Accum::Replace, T::one(), h, x);
        } else {
            *out = h * x;
        }
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn noise_into(&self, _: &OVector<T, N>, _: &(), _: T, out: &mut OMatrix<T, M, M>) {
        assign(out, &self.noise);
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn jacobian_into(&self, _: &OVector<T, N>, _: &(), _: T, out: &mut OMatrix<T, M, N>) {
        assign(out, &self.observation);
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn hessian_into<'o>(
        &self,
        _: &OVector<T, N>,
        _: &(),
        _: T,
        _: usize,
        _: &'o mut OMatrix<T, N, N>,
    ) -> Option<&'o mut OMatrix<T, N, N>> {
        None
    }
}

impl<T: Real, N: Dim, M: Dim> MeasurementJacobian<T, N, M> for LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, _: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.observation.clone()
    }
}

impl<T: Real, N: Dim, M: Dim> MeasurementHessian<T, N, M> for LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// `None`: every component is affine.
    fn measurement_hessian(&self, _: &OVector<T, N>, _: usize) -> Option<OMatrix<T, N, N>> {
        None
    }
}

impl<T: Real, N: Dim, M: Dim> LinearMeasurementModel<T, N, M> for LinearMeasurement<T, N, M> where
    DefaultAllocator: Alloc<N, M>
{
}
