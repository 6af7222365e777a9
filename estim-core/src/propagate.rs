//! Moment propagation: the mean and covariance of y = g(x) for x ~ N(μ, C).
//!
//! Every Gaussian filter is the same algorithm around one question: given x ~ N(μ, C) and
//! y = g(x), what are E\[y\], cov(y) and cov(x, y)? The answer is a [`MomentPropagator`]:
//!
//! | propagator | needs | mean | covariance |
//! |---|---|---|---|
//! | [`Affine`] | J, g affine | g(μ) (exact) | J C Jᵀ (exact) |
//! | [`Linearized`] | J | g(μ) | J C Jᵀ |
//! | [`SecondOrder`] (Papoulis; Boje eq 7, 9) | J, Hₖ | g(μ) + ½ Σᵢⱼ (Hₖ ∘ C)ᵢⱼ | J C Jᵀ |
//! | [`SecondOrderGaussian`] | J, Hₖ | as above | J C Jᵀ + ½ [tr(Hₖ C Hₗ C)]ₖₗ |
//! | [`Unscented`] | values | sigma-point mean | sigma-point covariance |
//! | [`Sampled`] | values | Monte Carlo mean | Monte Carlo covariance |
//!
//! The cross-covariance cov(x, y) is C Jᵀ for the derivative-based propagators (exact for
//! the second-order ones too when x is Gaussian, because odd central moments vanish).
//!
//! `SecondOrder` is density-free, as Papoulis and Boje present it: it uses only the first two
//! moments of x. `SecondOrderGaussian` adds the term that the fourth Gaussian moments give, and
//! is exact for quadratic g when x is Gaussian.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::error::{Quantity, Result, Stage};
use crate::gaussian::Gaussian;
use crate::linalg::{ensure_finite, symmetrize};
use crate::scalar::Real;

mod affine;
mod linearized;
mod sampled;
mod second_order;
mod unscented;

pub use affine::Affine;
pub use linearized::Linearized;
pub use sampled::Sampled;
pub use second_order::{SecondOrder, SecondOrderGaussian};
pub use unscented::Unscented;

/// E\[y\] and cov(y), as returned by
/// [`MomentPropagator::propagate_mean_covariance`].
pub type MeanCovariance<T, M> = (OVector<T, M>, OMatrix<T, M, M>);

/// The first two moments of y = g(x) and its covariance with x.
#[derive(Clone, Debug, PartialEq)]
pub struct Moments<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// E\[y\] (m).
    pub mean: OVector<T, M>,
    /// cov(y) = E\[(y − ȳ)(y − ȳ)ᵀ\] (m × m).
    pub covariance: OMatrix<T, M, M>,
    /// cov(x, y) = E\[(x − μ)(y − ȳ)ᵀ\] (n × m).
    pub cross_covariance: OMatrix<T, N, M>,
}

/// Computes the [`Moments`] of y = g(x), x ~ N(μ, C).
///
/// Generic over the function type `G`, so each propagator bounds only the capability it
/// needs: `Linearized` implements this for every `G: Differentiable`, `Unscented` for every
/// `G: VectorFunction`.
pub trait MomentPropagator<T: Real, N: Dim, M: Dim, G: ?Sized>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The moments of g(x) for x with mean `mean` and covariance `covariance` (symmetric
    /// positive semi-definite; a propagator that factorises it reports when it is not).
    ///
    /// Errors: a non-finite result, a runtime shape mismatch between g and x, or a
    /// covariance that cannot be factorised.
    fn propagate(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<Moments<T, N, M>>;

    /// [`propagate`](Self::propagate) for a [`Gaussian`].
    fn propagate_gaussian(&self, x: &Gaussian<T, N>, g: &G) -> Result<Moments<T, N, M>> {
        self.propagate(x.mean(), x.covariance(), g)
    }

    /// E\[y\] and cov(y) only, for callers that do not need cov(x, y) (a filter's prediction).
    /// The default is [`propagate`](Self::propagate) without the cross-covariance; propagators
    /// that would accumulate it separately (the unscented one) skip that work.
    #[inline(always)]
    fn propagate_mean_covariance(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<MeanCovariance<T, M>> {
        self.propagate(mean, covariance, g)
            .map(|m| (m.mean, m.covariance))
    }
}

/// Symmetrises the covariance and checks the result is finite.
#[inline(always)]
fn finish<T: Real, N: Dim, M: Dim>(mut m: Moments<T, N, M>) -> Result<Moments<T, N, M>>
where
    DefaultAllocator: Alloc<N, M>,
{
    symmetrize(&mut m.covariance);
    let stage = Stage::Propagation;
    ensure_finite(&m.mean, stage, Quantity::Mean)?;
    ensure_finite(&m.covariance, stage, Quantity::Covariance)?;
    ensure_finite(&m.cross_covariance, stage, Quantity::CrossCovariance)?;
    Ok(m)
}
