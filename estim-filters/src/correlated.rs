//! The decorrelated process used when process and measurement noise are correlated.

use estim_core::checks::{ensure_finite, ensure_shape, symmetrize};
use estim_core::kernel::is_static;
use estim_core::linalg::psd_factor;
use estim_core::nalgebra::{Cholesky, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::scalar::real;
use estim_core::{
    Alloc, Differentiable, Error, MeasurementHessian, MeasurementJacobian, MeasurementModel,
    ProcessHessian, ProcessJacobian, ProcessModel, Quantity, Real, Stage, TwiceDifferentiable,
    VectorFunction, error::Result,
};

/// The map x ↦ f(x, u, Δt) + D (z ⊖ h(x)) with D = S R⁻¹: the process rewritten so its noise
/// w* = w − D v is uncorrelated with the measurement noise v (see
/// [`PredictCorrelated`](crate::PredictCorrelated)). Its Jacobian is F − D H and the Hessian of
/// component k is ∂²fₖ − Σⱼ Dₖⱼ ∂²hⱼ, so it has every capability its two models have.
///
/// On runtime sizes [`new`](Self::new) checks the lengths of f(x), h(x) and z ⊖ h(x) at the
/// estimate (typed errors); at the other points the propagator evaluates, a wrong f(x) is a
/// [`Quantity::FunctionValue`] mismatch and a wrong h(x) or residual an [`Error::NonFinite`] mean
/// ([`eval`](VectorFunction::eval)). The Jacobian and Hessians are not evaluated there: a process
/// Jacobian or Hessian of the wrong shape reaches the propagator, which reports it as
/// [`Error::DimensionMismatch`]. So does a misshapen measurement derivative (never a silent product
/// over the agreeing part): a measurement Hessian that is not n × n is handed on as the map's
/// Hessian, and a measurement Jacobian that is not m × n makes the map's Jacobian a matrix of that
/// shape (n × 0 if it happens to be n × n) on a runtime-sized state, which the propagator reports
/// as a [`Quantity::Jacobian`] mismatch. On a static state only the rows of a runtime-sized m can
/// be wrong; the map's Jacobian is then NaN, reported as [`Error::NonFinite`] by the propagation.
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
    /// Errors: R not positive definite, Q* not positive semi-definite, shapes (on runtime
    /// sizes also of f(x), h(x) and z ⊖ h(x): a model whose h(x) has another length than z is
    /// reported as z's length, as by the update) or non-finite values.
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
        if !(is_static::<N>() && is_static::<M>()) {
            let fx = process.transition(x, input, dt);
            ensure_shape(&fx, n, 1, stage, Quantity::FunctionValue)?;
            let hx = measurement.measure(x);
            if hx.shape() != (m, 1) {
                return Err(Error::DimensionMismatch {
                    stage,
                    quantity: Quantity::Measurement,
                    expected_rows: hx.nrows(),
                    expected_cols: hx.ncols(),
                    found_rows: m,
                    found_cols: 1,
                });
            }
            let mut residual = hx.clone();
            measurement.residual_into(z, &hx, &mut residual);
            ensure_shape(&residual, m, 1, stage, Quantity::Innovation)?;
        }
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
    /// f(x) + D (z ⊖ h(x)). Runtime sizes, where [`new`](Self::new) checked the lengths at x̂
    /// only: an f(x) of the wrong length is returned as it is (the propagator reports the
    /// [`Quantity::FunctionValue`] mismatch), and NaN where h(x) or its residual has not z's
    /// length (reported by the propagation's finiteness check): errors, not a panic in the
    /// product.
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, N> {
        let mut fx = self.process.transition(x, self.input, self.dt);
        if fx.nrows() != self.gain.nrows() {
            return fx;
        }
        let hx = self.measurement.measure(x);
        let m = (self.z.nrows(), 1);
        // A misshapen h(x) stays in `residual` (its copy) and fails the length check below.
        let mut residual = hx.clone();
        if hx.shape() == m {
            self.measurement.residual_into(self.z, &hx, &mut residual);
        }
        if residual.shape() == m {
            fx.gemv(T::one(), &self.gain, &residual, T::one());
        } else {
            fx.fill(T::zero() / T::zero());
        }
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
    /// F − D H; a misshapen H gives the stand-in described at [`Decorrelated`].
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, N, N> {
        let mut jac = self.process.transition_jacobian(x, self.input, self.dt);
        let (n, m) = self.gain.shape();
        if jac.shape() != (n, n) {
            return jac; // the propagator reports its shape
        }
        let h = self.measurement.measurement_jacobian(x);
        if h.shape() != (m, n) {
            return misshapen_jacobian(h.shape(), n);
        }
        jac.gemm(-T::one(), &self.gain, &h, T::one());
        jac
    }
}

/// What the map's Jacobian is when the measurement Jacobian has shape `h` instead of m × n: on
/// a runtime-sized state a matrix of shape `h` (n × 0 if `h` is n × n), which the propagator's
/// shape check rejects naming H's shape; on a static one (only m can be wrong, so `h` has n
/// columns) an n × n NaN matrix, which the propagation reports as non-finite.
fn misshapen_jacobian<T: Real, N: Dim>(h: (usize, usize), n: usize) -> OMatrix<T, N, N>
where
    DefaultAllocator: Alloc<N>,
{
    if is_static::<N>() {
        OMatrix::from_element_generic(N::from_usize(n), N::from_usize(n), real(f64::NAN))
    } else {
        let (rows, cols) = if h == (n, n) { (n, 0) } else { h };
        OMatrix::zeros_generic(N::from_usize(rows), N::from_usize(cols))
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
    /// ∂²fₖ − Σⱼ Dₖⱼ ∂²hⱼ; a measurement Hessian that is not n × n is returned as it is, for
    /// the propagator to report (see [`Decorrelated`]).
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        let mut total = self.process.transition_hessian(x, self.input, self.dt, k);
        let n = self.gain.nrows();
        if total.as_ref().is_some_and(|t| t.shape() != (n, n)) {
            return total; // the propagator reports its shape
        }
        for j in 0..self.gain.ncols() {
            let d = self.gain[(k, j)];
            if d == T::zero() {
                continue;
            }
            if let Some(hj) = self.measurement.measurement_hessian(x, j) {
                if hj.shape() != (n, n) {
                    return Some(hj); // the propagator reports its shape
                }
                match &mut total {
                    Some(t) => *t -= hj * d,
                    None => total = Some(hj * (-d)),
                }
            }
        }
        total
    }
}
