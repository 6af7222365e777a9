//! Linear-Gaussian models with constant matrices.
//!
//! [`LinearProcess`]: x⁺ = F x + B u + w, w ~ N(0, Q). [`LinearMeasurement`]: z = H x + v,
//! v ~ N(0, R). Both implement every model capability (their Hessians are zero), so they work
//! with every filter, including the linear Kalman filter. For matrices that depend on Δt,
//! implement the model traits on your own type.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
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
}

impl<T: Real, N: Dim, M: Dim> MeasurementJacobian<T, N, M> for LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, _: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.observation.clone()
    }
}

impl<T: Real, N: Dim, M: Dim> LinearMeasurementModel<T, N, M> for LinearMeasurement<T, N, M> where
    DefaultAllocator: Alloc<N, M>
{
}
