//! Linear-Gaussian models with constant matrices.
//!
//! [`LinearProcess`]: x⁺ = F x + B u + w, w ~ N(0, Q). [`LinearMeasurement`]: z = H x + v,
//! v ~ N(0, R). Both implement every model capability (their Hessians are zero), so they work
//! with every filter, including the linear Kalman filter. For matrices that depend on Δt,
//! implement the model traits on your own type.
//!
//! Both implement the `_into` forms, so with `Dyn` sizes a filter step over them allocates
//! nothing. Matrices whose shapes disagree with the state are reported by the filter as a
//! [`DimensionMismatch`](crate::Error::DimensionMismatch) (or, for an inner dimension nalgebra
//! cannot multiply, by nalgebra's panic).

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::kernel::{self, Accum, is_static};
use crate::model::{
    LinearMeasurementModel, LinearProcessModel, MeasurementJacobian, MeasurementModel,
    ProcessJacobian, ProcessModel,
};
use crate::scalar::Real;

/// x⁺ = F x + B u + w, w ~ N(0, Q), with `U` inputs (use `U0`… or a zero-column B for none).
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

    #[inline(always)]
    fn transition_into(
        &self,
        x: &OVector<T, N>,
        u: &OVector<T, U>,
        _dt: T,
        out: &mut OVector<T, N>,
    ) {
        let (f, b) = (&self.transition, &self.input);
        let fits = f.shape() == (out.nrows(), x.nrows()) && b.shape() == (out.nrows(), u.nrows());
        // Static sizes: the operator form unrolls and allocates nothing anyway.
        let dynamic = !(is_static::<N>() && is_static::<U>());
        if dynamic && fits {
            // kernel::mul, not nalgebra's gemv: for runtime sizes its matrix–vector kernel is
            // compiled for the CPU's vector width (chosen at run time), where nalgebra's gemv
            // is compiled for the baseline target.
            kernel::mul(out, Accum::Replace, T::one(), f, x);
            kernel::mul(out, Accum::Add, T::one(), b, u);
        } else {
            *out = f * x + b * u;
        }
    }

    #[inline(always)]
    fn process_noise_into(
        &self,
        _: &OVector<T, N>,
        _: &OVector<T, U>,
        _dt: T,
        out: &mut OMatrix<T, N, N>,
    ) {
        assign(out, &self.noise);
    }

    /// F X + (B u) 1ᵀ: one matrix product for all the columns (an unscented prediction's
    /// sigma points) instead of one matrix–vector product each.
    #[inline(always)]
    fn transition_columns_into(
        &self,
        points: &OMatrix<T, N, N>,
        u: &OVector<T, U>,
        _dt: T,
        out: &mut OMatrix<T, N, N>,
    ) -> bool {
        let (f, b) = (&self.transition, &self.input);
        let n = points.nrows();
        if f.shape() != (n, n) || b.shape() != (n, u.nrows()) || out.shape() != (n, n) {
            return false; // per column (where wrong shapes are reported)
        }
        if n == 0 || u.nrows() == 0 {
            kernel::mul(out, Accum::Replace, T::one(), f, points);
            return true;
        }
        // B u into the first column, copied to the others, then + F X.
        let first = &mut out.as_mut_slice()[..n];
        first.fill(T::zero());
        for (column, &uk) in b.as_slice().chunks_exact(n).zip(u.as_slice()) {
            for (o, &v) in first.iter_mut().zip(column) {
                *o += v * uk;
            }
        }
        for j in 1..n {
            out.as_mut_slice().copy_within(..n, j * n);
        }
        kernel::mul(out, Accum::Add, T::one(), f, points);
        true
    }
}

/// `out` ← `value`, copying in place when the shapes agree.
#[inline(always)]
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

    #[inline(always)]
    fn transition_jacobian_into(
        &self,
        _: &OVector<T, N>,
        _: &OVector<T, U>,
        _dt: T,
        out: &mut OMatrix<T, N, N>,
    ) {
        assign(out, &self.transition);
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

    #[inline(always)]
    fn measure_into(&self, x: &OVector<T, N>, out: &mut OVector<T, M>) {
        let h = &self.observation;
        let dynamic = !(is_static::<N>() && is_static::<M>());
        if dynamic && h.shape() == (out.nrows(), x.nrows()) {
            kernel::mul(out, Accum::Replace, T::one(), h, x);
        } else {
            *out = h * x;
        }
    }

    #[inline(always)]
    fn measurement_noise_into(&self, _: &OVector<T, N>, out: &mut OMatrix<T, M, M>) {
        assign(out, &self.noise);
    }

    #[inline(always)]
    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        crate::model::subtract_into(a, b, out);
    }

    /// H X: one matrix product for all the columns.
    #[inline(always)]
    fn measure_columns_into(&self, points: &OMatrix<T, N, N>, out: &mut OMatrix<T, M, N>) -> bool {
        let h = &self.observation;
        if h.ncols() != points.nrows() || out.shape() != (h.nrows(), points.ncols()) {
            return false; // per column (where wrong shapes are reported)
        }
        kernel::mul(out, Accum::Replace, T::one(), h, points);
        true
    }
}

impl<T: Real, N: Dim, M: Dim> MeasurementJacobian<T, N, M> for LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, _: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.observation.clone()
    }

    #[inline(always)]
    fn measurement_jacobian_into(&self, _: &OVector<T, N>, out: &mut OMatrix<T, M, N>) {
        assign(out, &self.observation);
    }
}

impl<T: Real, N: Dim, M: Dim> LinearMeasurementModel<T, N, M> for LinearMeasurement<T, N, M> where
    DefaultAllocator: Alloc<N, M>
{
}
