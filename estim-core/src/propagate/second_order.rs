//! Second-order propagation: Papoulis' approximation (as used by Boje) and its Gaussian
//! refinement.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};

use super::linearized::linear_moments_into;
use super::workspace::buffer;
use super::{LinearizedWorkspace, MomentPropagator, Outputs, PropagatorWorkspace};
use crate::alloc::Alloc;
use crate::checks::ensure_shape;
use crate::error::{Quantity, Result, Stage};
use crate::function::TwiceDifferentiable;
use crate::kernel::{self, Accum, mul};
use crate::scalar::{Real, real};

/// Papoulis' second-order approximation (Boje eq 7 and eq 9):
///
/// ```text
/// E[yₖ]   ≈ gₖ(μ) + ½ Σᵢⱼ (Hₖ ∘ C)ᵢⱼ        (Hₖ = ∂²gₖ/∂x² at μ, ∘ the Hadamard product)
/// cov(y)  ≈ J C Jᵀ
/// cov(x,y) ≈ C Jᵀ
/// ```
///
/// The correction is applied with the function's
/// [`output_plus_into`](crate::VectorFunction::output_plus_into): ȳ = g(μ) ⊞ δ, δₖ the
/// second-order term (by default +, to the bit the in-place sum). Density-free: only the mean
/// and covariance of x enter. The mean is exact for quadratic g
/// under any density; the covariance is first order. Requirements on g: [`TwiceDifferentiable`]
/// (components declared affine cost nothing).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SecondOrder;

/// The Gaussian second-order approximation: [`SecondOrder`]'s mean, and the covariance
///
/// ```text
/// cov(yₖ, yₗ) ≈ (J C Jᵀ)ₖₗ + ½ tr(Hₖ C Hₗ C)
/// ```
///
/// which adds the contribution of the fourth moments of a Gaussian x. Mean and covariance are
/// both exact for quadratic g when x is Gaussian. Cost on top of the Jacobian product: two
/// n × n products per nonlinear component and O(m² n²) inner products; to stay allocation-free
/// for static sizes, Hessians are re-evaluated per pair (m + m(m−1)/2 evaluations) rather than
/// stored. With runtime sizes the products run on faer in the caller's workspace.
/// Requirements on g:
/// [`TwiceDifferentiable`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SecondOrderGaussian;

/// Writes Hₖ into `h` (shape-checked): `Ok(true)`, or `Ok(false)` if gₖ is affine.
#[cfg_attr(not(debug_assertions), inline(always))]
fn hessian_into<T, N, M, G>(
    g: &G,
    mean: &OVector<T, N>,
    k: usize,
    h: &mut OMatrix<T, N, N>,
) -> Result<bool>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let n = mean.nrows();
    match crate::function::hessian_into(g, mean, k, h) {
        Some(h) => {
            ensure_shape(h, n, n, Stage::Propagation, Quantity::Hessian)?;
            Ok(true)
        }
        None => Ok(false),
    }
}

/// The mean-correction buffer δ, shaped like `mean` and filled with −0: x + (−0) = x for every
/// x (+0 would turn a −0 into +0), so components without a correction keep their bits under
/// the default ⊞.
#[cfg_attr(not(debug_assertions), inline(always))]
fn zero_correction<'w, T: Real, M: Dim>(
    slot: &'w mut Option<OMatrix<T, M, U1>>,
    mean: &OVector<T, M>,
) -> &'w mut OMatrix<T, M, U1>
where
    DefaultAllocator: nalgebra::allocator::Allocator<M>,
{
    let delta = buffer(slot, mean.shape_generic().0, U1);
    delta.fill(-T::zero());
    delta
}

/// ȳ ← g(μ) ⊞ δ, g(μ) taken from `mean` and moved aside into `centre`.
#[cfg_attr(not(debug_assertions), inline(always))]
fn correct_mean<T, N, M, G>(
    g: &G,
    mean: &mut OVector<T, M>,
    delta: &OVector<T, M>,
    centre: &mut Option<OMatrix<T, M, U1>>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let (m_dim, m) = (mean.shape_generic().0, mean.nrows());
    let y0 = buffer(centre, m_dim, U1);
    kernel::copy(y0, mean);
    g.output_plus_into(y0, delta, mean);
    ensure_shape(mean, m, 1, Stage::Propagation, Quantity::FunctionValue)
}

/// The buffers of [`SecondOrder`] and [`SecondOrderGaussian`]: the linearised part's, and
/// the Hessians and products of the second-order terms.
#[derive(Debug)]
pub struct SecondOrderWorkspace<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    linear: LinearizedWorkspace<T, N, M>,
    hessian: Option<OMatrix<T, N, N>>,
    other_hessian: Option<OMatrix<T, N, N>>,
    product: Option<OMatrix<T, N, N>>,
    sandwich: Option<OMatrix<T, N, N>>,
    correction: Option<OMatrix<T, M, U1>>,
    centre: Option<OMatrix<T, M, U1>>,
}

impl<T: Real, N: Dim, M: Dim> Default for SecondOrderWorkspace<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn default() -> Self {
        Self {
            linear: LinearizedWorkspace::default(),
            hessian: None,
            other_hessian: None,
            product: None,
            sandwich: None,
            correction: None,
            centre: None,
        }
    }
}

impl<T: Real> PropagatorWorkspace<T> for SecondOrder {
    type Workspace<N: Dim, M: Dim>
        = SecondOrderWorkspace<T, N, M>
    where
        DefaultAllocator: Alloc<N, M>;
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for SecondOrder
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    /// Linear moments plus the ½ Σᵢⱼ (Hₖ ∘ C)ᵢⱼ mean correction.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn propagate_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        mut out: Outputs<'_, T, N, M>,
        workspace: &mut SecondOrderWorkspace<T, N, M>,
    ) -> Result<()> {
        linear_moments_into(mean, covariance, g, &mut out, &mut workspace.linear)?;
        let half = real::<T>(0.5);
        let n = mean.shape_generic().0;
        let h = buffer(&mut workspace.hessian, n, n);
        let delta = zero_correction(&mut workspace.correction, out.mean);
        let mut nonlinear = false;
        for k in 0..out.mean.nrows() {
            if hessian_into(g, mean, k, h)? {
                // Σᵢⱼ (Hₖ ∘ C)ᵢⱼ is the Frobenius inner product ⟨Hₖ, C⟩.
                delta[k] = half * h.dot(covariance);
                nonlinear = true;
            }
        }
        if nonlinear {
            correct_mean(g, out.mean, delta, &mut workspace.centre)?;
        }
        out.finish()
    }
}

impl<T: Real> PropagatorWorkspace<T> for SecondOrderGaussian {
    type Workspace<N: Dim, M: Dim>
        = SecondOrderWorkspace<T, N, M>
    where
        DefaultAllocator: Alloc<N, M>;
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for SecondOrderGaussian
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn propagate_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        mut out: Outputs<'_, T, N, M>,
        workspace: &mut SecondOrderWorkspace<T, N, M>,
    ) -> Result<()> {
        linear_moments_into(mean, covariance, g, &mut out, &mut workspace.linear)?;
        let half = real::<T>(0.5);
        let n = mean.shape_generic().0;
        let hk = buffer(&mut workspace.hessian, n, n);
        let hl = buffer(&mut workspace.other_hessian, n, n);
        let product = buffer(&mut workspace.product, n, n);
        let bk = buffer(&mut workspace.sandwich, n, n);
        let delta = zero_correction(&mut workspace.correction, out.mean);
        let mut nonlinear = false;
        // tr(Hₖ C Hₗ C) = ⟨C Hₖ C, Hₗ⟩ (Frobenius, Hₗ symmetric): one O(n³) product pair per k,
        // O(n²) per pair. Hessians of earlier components are re-evaluated rather than stored
        // (m + m(m−1)/2 evaluations in all), so the workspace holds two n × n Hessians, not m.
        for k in 0..out.mean.nrows() {
            if !hessian_into(g, mean, k, hk)? {
                continue;
            }
            delta[k] = half * hk.dot(covariance);
            nonlinear = true;
            mul(product, Accum::Replace, T::one(), covariance, hk);
            mul(bk, Accum::Replace, T::one(), product, covariance);
            out.covariance[(k, k)] += half * bk.dot(hk);
            // The lower triangle only (k > l): `finish` mirrors it.
            for l in 0..k {
                if hessian_into(g, mean, l, hl)? {
                    out.covariance[(k, l)] += half * bk.dot(hl);
                }
            }
        }
        if nonlinear {
            correct_mean(g, out.mean, delta, &mut workspace.centre)?;
        }
        out.finish()
    }
}
