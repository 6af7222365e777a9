//! The decorrelated process used when process and measurement noise are correlated.

use estim_core::linalg::{ensure_finite, ensure_shape, psd_factor, symmetrize};
use estim_core::nalgebra::{Cholesky, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{
    Alloc, Differentiable, Error, MeasurementHessian, MeasurementJacobian, MeasurementModel,
    ProcessHessian, ProcessJacobian, ProcessModel, Quantity, Real, Stage, TwiceDifferentiable,
    VectorFunction, error::Result,
};

/// The map x ↦ f(x, u, Δt) + D (z ⊖ h(x)) with D = S R⁻¹: the process rewritten so its noise
/// w* = w − D v is uncorrelated with the measurement noise v (see
/// [`PredictCorrelated`](crate::PredictCorrelated)). Its Jacobian is F − D H and the Hessian of
/// component k is ∂²fₖ − Σⱼ Dₖⱼ ∂²hⱼ, so it has every capability its two models have.
#[derive(Debug)]
pub struct Decorrelated<'a, P, U, H, T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    process: &'a P,
    input: &'a U,
    dt: T,
    measurement: &'a H,
    z: &'a OVector<T, M>,
    gain: OMatrix<T, N, M>,
}

impl<'a, P, H, T, N, M> Decorrelated<'a, P, P::Input, H, T, N, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessModel<T, N>,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    /// Builds the decorrelated process at the estimate `x` and returns it with its noise
    /// Q* = Q − S R⁻¹ Sᵀ (Q and R evaluated at `x`).
    ///
    /// Errors: R not positive definite, Q* not positive semi-definite, shapes or non-finite
    /// values.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        process: &'a P,
        input: &'a P::Input,
        dt: T,
        measurement: &'a H,
        z: &'a OVector<T, M>,
        cross: &OMatrix<T, N, M>,
        x: &OVector<T, N>,
    ) -> Result<(Self, OMatrix<T, N, N>)> {
        let stage = Stage::Prediction;
        let (n, m) = (x.nrows(), z.nrows());
        ensure_shape(cross, n, m, stage, Quantity::NoiseCrossCovariance)?;
        ensure_finite(cross, stage, Quantity::NoiseCrossCovariance)?;
        ensure_finite(z, stage, Quantity::Measurement)?;
        let r = measurement.measurement_noise(x);
        ensure_shape(&r, m, m, stage, Quantity::MeasurementNoise)?;
        ensure_finite(&r, stage, Quantity::MeasurementNoise)?;
        let q = process.process_noise(x, input, dt);
        ensure_shape(&q, n, n, stage, Quantity::ProcessNoise)?;
        ensure_finite(&q, stage, Quantity::ProcessNoise)?;
        let chol = Cholesky::new(r).ok_or(Error::NotPositiveDefinite {
            stage,
            quantity: Quantity::MeasurementNoise,
        })?;
        // D = S R⁻¹, solved as R Dᵀ = Sᵀ.
        let gain = chol.solve(&cross.transpose()).transpose();
        let mut q_star = q - &gain * cross.transpose();
        symmetrize(&mut q_star);
        psd_factor(&q_star, stage).map_err(|_| Error::NotPositiveSemiDefinite {
            stage,
            quantity: Quantity::NoiseCrossCovariance,
        })?;
        let map = Self {
            process,
            input,
            dt,
            measurement,
            z,
            gain,
        };
        Ok((map, q_star))
    }
}

impl<P, H, T, N, M> VectorFunction<T, N, N> for Decorrelated<'_, P, P::Input, H, T, N, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessModel<T, N>,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, N> {
        let mut fx = self.process.transition(x, self.input, self.dt);
        let residual = self
            .measurement
            .residual(self.z, &self.measurement.measure(x));
        fx.gemv(T::one(), &self.gain, &residual, T::one());
        fx
    }
}

impl<P, H, T, N, M> Differentiable<T, N, N> for Decorrelated<'_, P, P::Input, H, T, N, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessJacobian<T, N>,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, N, N> {
        let mut jac = self.process.transition_jacobian(x, self.input, self.dt);
        let h = self.measurement.measurement_jacobian(x);
        jac.gemm(-T::one(), &self.gain, &h, T::one());
        jac
    }
}

impl<P, H, T, N, M> TwiceDifferentiable<T, N, N> for Decorrelated<'_, P, P::Input, H, T, N, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessHessian<T, N>,
    H: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        let mut total = self.process.transition_hessian(x, self.input, self.dt, k);
        for j in 0..self.gain.ncols() {
            let d = self.gain[(k, j)];
            if d == T::zero() {
                continue;
            }
            if let Some(hj) = self.measurement.measurement_hessian(x, j) {
                match &mut total {
                    Some(t) => *t -= hj * d,
                    None => total = Some(hj * (-d)),
                }
            }
        }
        total
    }
}
