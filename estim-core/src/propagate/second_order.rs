//! Second-order propagation: Papoulis' approximation (as used by Boje) and its Gaussian
//! refinement.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use super::linearized::linear_moments;
use super::{MomentPropagator, Moments, finish};
use crate::alloc::Alloc;
use crate::error::{Quantity, Result, Stage};
use crate::function::TwiceDifferentiable;
use crate::linalg::ensure_shape;
use crate::scalar::{Real, real};

/// Papoulis' second-order approximation (Boje eq 7 and eq 9):
///
/// ```text
/// E[yₖ]   ≈ gₖ(μ) + ½ Σᵢⱼ (Hₖ ∘ C)ᵢⱼ        (Hₖ = ∂²gₖ/∂x² at μ, ∘ the Hadamard product)
/// cov(y)  ≈ J C Jᵀ
/// cov(x,y) ≈ C Jᵀ
/// ```
///
/// Density-free: only the mean and covariance of x enter. The mean is exact for quadratic g
/// under any density; the covariance is first order. Requirements on g: [`TwiceDifferentiable`]
/// (components declared affine cost nothing).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
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
/// stored. Requirements on g:
/// [`TwiceDifferentiable`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SecondOrderGaussian;

/// The Hessian of component k, shape-checked.
#[inline(always)]
fn hessian<T, N, M, G>(g: &G, mean: &OVector<T, N>, k: usize) -> Result<Option<OMatrix<T, N, N>>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let n = mean.nrows();
    match g.hessian(mean, k) {
        Some(h) => {
            ensure_shape(&h, n, n, Stage::Propagation, Quantity::Hessian)?;
            Ok(Some(h))
        }
        None => Ok(None),
    }
}

/// Linear moments plus the ½ Σᵢⱼ (Hₖ ∘ C)ᵢⱼ mean correction.
#[inline(always)]
fn second_order_moments<T, N, M, G>(
    mean: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    g: &G,
) -> Result<Moments<T, N, M>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let mut m = linear_moments(mean, covariance, g)?;
    let half = real::<T>(0.5);
    for k in 0..m.mean.nrows() {
        if let Some(h) = hessian(g, mean, k)? {
            // Σᵢⱼ (Hₖ ∘ C)ᵢⱼ is the Frobenius inner product ⟨Hₖ, C⟩.
            m.mean[k] += half * h.dot(covariance);
        }
    }
    Ok(m)
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for SecondOrder
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    #[inline(always)]
    fn propagate(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<Moments<T, N, M>> {
        finish(second_order_moments(mean, covariance, g)?)
    }
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for SecondOrderGaussian
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    #[inline(always)]
    fn propagate(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<Moments<T, N, M>> {
        let mut m = linear_moments(mean, covariance, g)?;
        let half = real::<T>(0.5);
        // tr(Hₖ C Hₗ C) = ⟨C Hₖ C, Hₗ⟩ (Frobenius, Hₗ symmetric): one O(n³) product pair per k,
        // O(n²) per pair. Hessians of earlier components are re-evaluated rather than stored,
        // so static sizes stay off the heap: m + m(m−1)/2 Hessian evaluations in all.
        for k in 0..m.mean.nrows() {
            let Some(hk) = hessian(g, mean, k)? else {
                continue;
            };
            m.mean[k] += half * hk.dot(covariance);
            let bk = covariance * &hk * covariance;
            m.covariance[(k, k)] += half * bk.dot(&hk);
            for l in 0..k {
                if let Some(hl) = hessian(g, mean, l)? {
                    let t = half * bk.dot(&hl);
                    m.covariance[(k, l)] += t;
                    m.covariance[(l, k)] += t;
                }
            }
        }
        finish(m)
    }
}
