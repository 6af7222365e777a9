//! First-order (linearised) propagation, as in the extended Kalman filter.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use super::{MomentPropagator, Moments, finish};
use crate::alloc::Alloc;
use crate::error::{Quantity, Result, Stage};
use crate::function::Differentiable;
use crate::linalg::ensure_shape;
use crate::scalar::Real;

/// Linearisation at the mean: ȳ = g(μ), cov(y) = J C Jᵀ, cov(x, y) = C Jᵀ, with J = ∂g/∂x(μ).
///
/// Exact for affine g. Requirements on g: [`Differentiable`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Linearized;

/// g(μ), J(μ), J C Jᵀ and C Jᵀ: the part every derivative-based propagator shares.
#[inline(always)]
pub(super) fn linear_moments<T, N, M, G>(
    mean: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    g: &G,
) -> Result<Moments<T, N, M>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let n = mean.nrows();
    ensure_shape(covariance, n, n, Stage::Propagation, Quantity::Covariance)?;
    let y = g.eval(mean);
    let j = g.jacobian(mean);
    ensure_shape(&j, y.nrows(), n, Stage::Propagation, Quantity::Jacobian)?;
    let jc = &j * covariance;
    let cov_y = &jc * j.transpose();
    Ok(Moments {
        mean: y,
        covariance: cov_y,
        // C Jᵀ = (J C)ᵀ because C is symmetric.
        cross_covariance: jc.transpose(),
    })
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Linearized
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    #[inline(always)]
    fn propagate(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<Moments<T, N, M>> {
        finish(linear_moments(mean, covariance, g)?)
    }
}
