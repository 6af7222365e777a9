//! First-order (linearised) propagation, as in the extended Kalman filter.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use super::workspace::buffer;
use super::{MomentPropagator, Outputs, PropagatorWorkspace, check_inputs};
use crate::alloc::Alloc;
use crate::checks::ensure_shape;
use crate::error::{Quantity, Result, Stage};
use crate::function::Differentiable;
use crate::function::{eval_into, jacobian_into};
use crate::kernel::{Accum, mul, mul_lower, mul_tr, mul_tr_lower};
use crate::scalar::Real;

/// Linearisation at the mean: ȳ = g(μ), cov(y) = J C Jᵀ, cov(x, y) = C Jᵀ, with J = ∂g/∂x(μ).
///
/// Exact for affine g. Requirements on g: [`Differentiable`]. On a state space with a ⊞
/// ([`StateSpace`](crate::StateSpace)) g(μ) needs none, and J is meant in the ⊞ sense,
/// J = ∂(g(μ ⊞ δ) ⊟ g(μ))/∂δ at δ = 0 (for + and −, the ordinary Jacobian).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Linearized;

/// [`Linearized`]'s buffers: the Jacobian J and, without a cross-covariance, J C.
#[derive(Debug)]
pub struct LinearizedWorkspace<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    jacobian: Option<OMatrix<T, M, N>>,
    jacobian_covariance: Option<OMatrix<T, M, N>>,
}

impl<T: Real, N: Dim, M: Dim> Default for LinearizedWorkspace<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn default() -> Self {
        Self {
            jacobian: None,
            jacobian_covariance: None,
        }
    }
}

/// g(μ), J(μ), J C Jᵀ and C Jᵀ (if asked for): the part every derivative-based propagator
/// shares. Only the lower triangle of J C Jᵀ is written; not finished (mirrored, checked) yet.
#[cfg_attr(not(debug_assertions), inline(always))]
pub(super) fn linear_moments_into<T, N, M, G>(
    mean: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    g: &G,
    out: &mut Outputs<'_, T, N, M>,
    workspace: &mut LinearizedWorkspace<T, N, M>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let (n, m) = check_inputs(mean, covariance, out)?;
    let stage = Stage::Propagation;
    eval_into(g, mean, out.mean);
    ensure_shape(&*out.mean, m.value(), 1, stage, Quantity::FunctionValue)?;
    let j = buffer(&mut workspace.jacobian, m, n);
    jacobian_into(g, mean, j);
    ensure_shape(j, m.value(), n.value(), stage, Quantity::Jacobian)?;
    // Only the lower triangle of the symmetric J C Jᵀ is computed (`finish` mirrors it).
    if let Some(cross) = out.cross_covariance.as_deref_mut() {
        mul_tr(cross, Accum::Replace, T::one(), covariance, j);
        mul_lower(out.covariance, Accum::Replace, T::one(), j, cross);
    } else {
        let jc = buffer(&mut workspace.jacobian_covariance, m, n);
        mul(jc, Accum::Replace, T::one(), j, covariance);
        mul_tr_lower(out.covariance, Accum::Replace, T::one(), jc, j);
    }
    Ok(())
}

impl<T: Real> PropagatorWorkspace<T> for Linearized {
    type Workspace<N: Dim, M: Dim>
        = LinearizedWorkspace<T, N, M>
    where
        DefaultAllocator: Alloc<N, M>;
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Linearized
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
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
