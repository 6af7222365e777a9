//! Exact propagation through affine functions (the linear Kalman filter's).

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use super::{Linearized, MomentPropagator, Workspace, impl_propagator_via_moments_into};
use crate::alloc::Alloc;
use crate::error::Result;
use crate::function::AffineFunction;
use crate::scalar::Real;

/// ȳ = g(μ), cov(y) = J C Jᵀ, cov(x, y) = C Jᵀ for an affine g: the same arithmetic as
/// [`Linearized`], but only accepted for functions marked
/// [`AffineFunction`], where it is exact. This is what makes the linear Kalman filter refuse
/// a nonlinear model at compile time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Affine;

impl Affine {
    #[inline(always)]
    fn moments_into<T, N, M, G>(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        out_mean: &mut OVector<T, M>,
        out_covariance: &mut OMatrix<T, M, M>,
        cross: Option<&mut OMatrix<T, N, M>>,
        noise: Option<&OMatrix<T, M, M>>,
        workspace: &mut Workspace<T, N, M>,
    ) -> Result<()>
    where
        T: Real,
        N: Dim,
        M: Dim,
        G: AffineFunction<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        // Linearisation is exact here: the same arithmetic, restricted to affine g.
        Linearized.moments_into(
            mean,
            covariance,
            g,
            out_mean,
            out_covariance,
            cross,
            noise,
            workspace,
        )
    }
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Affine
where
    T: Real,
    N: Dim,
    M: Dim,
    G: AffineFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    impl_propagator_via_moments_into!();
}
