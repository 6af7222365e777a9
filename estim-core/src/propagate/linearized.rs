//! First-order (linearised) propagation, as in the extended Kalman filter.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use super::workspace::buffer;
use super::{MomentPropagator, Workspace, check_inputs, finish, impl_propagator_via_moments_into};
use crate::alloc::Alloc;
use crate::error::{Quantity, Result, Stage};
use crate::function::Differentiable;
use crate::kernel::{Accum, mul, mul_lower, mul_tr, mul_tr_lower};
use crate::linalg::ensure_shape;
use crate::scalar::Real;

/// Linearisation at the mean: ȳ = g(μ), cov(y) = J C Jᵀ, cov(x, y) = C Jᵀ, with J = ∂g/∂x(μ).
///
/// Exact for affine g. Requirements on g: [`Differentiable`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Linearized;

/// g(μ), J(μ), J C Jᵀ and C Jᵀ (if `cross` is given): the part every derivative-based
/// propagator shares. Only the lower triangle of J C Jᵀ is written; not finished (mirrored,
/// checked) yet.
#[inline(always)]
pub(super) fn linear_moments_into<T, N, M, G>(
    mean: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    g: &G,
    out_mean: &mut OVector<T, M>,
    out_covariance: &mut OMatrix<T, M, M>,
    mut cross: Option<&mut OMatrix<T, N, M>>,
    workspace: &mut Workspace<T, N, M>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    check_inputs(
        mean,
        covariance,
        out_mean,
        out_covariance,
        cross.as_deref_mut(),
        workspace,
    )?;
    let (n, m) = (workspace.n, workspace.m);
    let stage = Stage::Propagation;
    g.eval_into(mean, out_mean);
    ensure_shape(out_mean, m.value(), 1, stage, Quantity::FunctionValue)?;
    let j = buffer(&mut workspace.jacobian, m, n);
    g.jacobian_into(mean, j);
    ensure_shape(j, m.value(), n.value(), stage, Quantity::Jacobian)?;
    // Only the lower triangle of the symmetric J C Jᵀ is computed ([`finish`] mirrors it).
    if let Some(cross) = cross {
        mul_tr(cross, Accum::Replace, T::one(), covariance, j);
        mul_lower(out_covariance, Accum::Replace, T::one(), j, cross);
    } else {
        let jc = buffer(&mut workspace.jacobian_covariance, m, n);
        mul(jc, Accum::Replace, T::one(), j, covariance);
        mul_tr_lower(out_covariance, Accum::Replace, T::one(), jc, j);
    }
    Ok(())
}

impl Linearized {
    #[inline(always)]
    pub(super) fn moments_into<T, N, M, G>(
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
        G: Differentiable<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        let mut cross = cross;
        linear_moments_into(
            mean,
            covariance,
            g,
            out_mean,
            out_covariance,
            cross.as_deref_mut(),
            workspace,
        )?;
        finish(out_mean, out_covariance, cross.as_deref(), noise)
    }
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Linearized
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    impl_propagator_via_moments_into!();
}
