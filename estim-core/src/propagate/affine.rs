//! Exact propagation through affine functions (the linear Kalman filter's).

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use super::linearized::linear_moments_into;
use super::{LinearizedWorkspace, MomentPropagator, Outputs, PropagatorWorkspace};
use crate::alloc::Alloc;
use crate::error::Result;
use crate::function::AffineFunction;
use crate::scalar::Real;

/// ȳ = g(μ), cov(y) = J C Jᵀ, cov(x, y) = C Jᵀ for an affine g: the same arithmetic as
/// [`Linearized`](super::Linearized), but only accepted for functions marked
/// [`AffineFunction`], where it is exact. This is what makes the linear Kalman filter refuse
/// a nonlinear model at compile time. The Jacobian is meant in the ⊞ sense, as for
/// [`Linearized`](super::Linearized).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Affine;

impl<T: Real> PropagatorWorkspace<T> for Affine {
    type Workspace<N: Dim, M: Dim>
        = LinearizedWorkspace<T, N, M>
    where
        DefaultAllocator: Alloc<N, M>;
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Affine
where
    T: Real,
    N: Dim,
    M: Dim,
    G: AffineFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn propagate_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        mut out: Outputs<'_, T, N, M>,
        workspace: &mut LinearizedWorkspace<T, N, M>,
    ) -> Result<()> {
        linear_moments_into(mean, covariance, g, &mut out, workspace)?;
        out.finish()
    }
}
