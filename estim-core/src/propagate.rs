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
use crate::function::VectorFunction;
use crate::gaussian::Gaussian;
use crate::linalg::{
    ensure_finite, ensure_shape, finite_or_error, mirror_lower_checked, symmetric_map,
    symmetrize_add_checked,
};
use crate::scalar::Real;

mod affine;
mod linearized;
mod sampled;
mod second_order;
mod unscented;
mod workspace;

pub use affine::Affine;
pub use linearized::Linearized;
pub use sampled::Sampled;
pub use second_order::{SecondOrder, SecondOrderGaussian};
pub use unscented::Unscented;
pub use workspace::Workspace;

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

impl<T: Real, N: Dim, M: Dim> Moments<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Zeros of the shapes for a map from `n` to `m` dimensions: a buffer for
    /// [`MomentPropagator::propagate_into`].
    pub fn zeros(n: N, m: M) -> Self {
        Self {
            mean: OVector::zeros_generic(m, nalgebra::U1),
            covariance: OMatrix::zeros_generic(m, m),
            cross_covariance: OMatrix::zeros_generic(n, m),
        }
    }
}

/// Computes the [`Moments`] of y = g(x), x ~ N(μ, C).
///
/// Generic over the function type `G`, so each propagator bounds only the capability it
/// needs: `Linearized` implements this for every `G: Differentiable`, `Unscented` for every
/// `G: VectorFunction`.
///
/// The `_into` methods are the primitives: they write into caller-owned buffers and keep their
/// scratch in a [`Workspace`], so repeated propagation with runtime sizes allocates nothing
/// after the first call (given a function that implements the `_into` forms of
/// [`VectorFunction`]). The owned methods wrap them for one-off use.
pub trait MomentPropagator<T: Real, N: Dim, M: Dim, G: VectorFunction<T, N, M> + ?Sized>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The moments of g(x) for x with mean `mean` and covariance `covariance` (symmetric
    /// positive semi-definite; a propagator that factorises it reports when it is not), written
    /// into `out`, for the dimensions n and m of `workspace`.
    ///
    /// Errors: a non-finite result, a shape mismatch between g, x and the workspace's
    /// dimensions, or a covariance that cannot be factorised. On error `out` is unspecified.
    fn propagate_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        out: &mut Moments<T, N, M>,
        workspace: &mut Workspace<T, N, M>,
    ) -> Result<()>;

    /// E\[y\] and cov(y) only, for callers that do not need cov(x, y) (a filter's
    /// prediction). The default calls [`propagate_into`](Self::propagate_into) with a fresh
    /// [`Moments`] buffer; the built-in propagators skip the cross-covariance instead.
    fn propagate_mean_covariance_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        out_mean: &mut OVector<T, M>,
        out_covariance: &mut OMatrix<T, M, M>,
        workspace: &mut Workspace<T, N, M>,
    ) -> Result<()> {
        let mut out = Moments::zeros(workspace.n, workspace.m);
        self.propagate_into(mean, covariance, g, &mut out, workspace)?;
        *out_mean = out.mean;
        *out_covariance = out.covariance;
        Ok(())
    }

    /// E\[y\] and cov(y) + `noise` for y = g(x) + w, w ~ N(0, `noise`) independent of x: what
    /// a filter's prediction needs (P⁻ = cov f + Q), symmetrised, in `out_covariance`. The
    /// default adds the noise after
    /// [`propagate_mean_covariance_into`](Self::propagate_mean_covariance_into); the built-in
    /// propagators add it in the pass that symmetrises their covariance (one sweep of the
    /// matrix fewer). `noise` must be m × m (else a dimension error naming it as
    /// `ProcessNoise`); a non-finite sum is an error
    /// ([`Error::NonFinite`](crate::Error::NonFinite), stage `Propagation`, quantity
    /// `Covariance`).
    fn propagate_with_noise_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        noise: &OMatrix<T, M, M>,
        out_mean: &mut OVector<T, M>,
        out_covariance: &mut OMatrix<T, M, M>,
        workspace: &mut Workspace<T, N, M>,
    ) -> Result<()> {
        self.propagate_mean_covariance_into(
            mean,
            covariance,
            g,
            out_mean,
            out_covariance,
            workspace,
        )?;
        let stage = Stage::Propagation;
        let m = out_mean.nrows();
        ensure_shape(noise, m, m, stage, Quantity::ProcessNoise)?;
        let finite = symmetrize_add_checked(out_covariance, noise);
        finite_or_error(finite, stage, Quantity::Covariance)
    }

    /// The moments of g(x) for x with mean `mean` and covariance `covariance`: see
    /// [`propagate_into`](Self::propagate_into).
    fn propagate(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<Moments<T, N, M>> {
        let (n, m) = dimensions(mean, g);
        let mut out = Moments::zeros(n, m);
        self.propagate_into(mean, covariance, g, &mut out, &mut Workspace::new(n, m))?;
        Ok(out)
    }

    /// [`propagate`](Self::propagate) for a [`Gaussian`].
    fn propagate_gaussian(&self, x: &Gaussian<T, N>, g: &G) -> Result<Moments<T, N, M>> {
        self.propagate(x.mean(), x.covariance(), g)
    }

    /// E\[y\] and cov(y) only: see
    /// [`propagate_mean_covariance_into`](Self::propagate_mean_covariance_into).
    fn propagate_mean_covariance(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<MeanCovariance<T, M>> {
        let (n, m) = dimensions(mean, g);
        let mut out_mean = OVector::zeros_generic(m, nalgebra::U1);
        let mut out_covariance = OMatrix::zeros_generic(m, m);
        self.propagate_mean_covariance_into(
            mean,
            covariance,
            g,
            &mut out_mean,
            &mut out_covariance,
            &mut Workspace::new(n, m),
        )?;
        Ok((out_mean, out_covariance))
    }
}

/// n from x, and m from the type or, for a runtime size, from g(x).
fn dimensions<T: Real, N: Dim, M: Dim, G: VectorFunction<T, N, M> + ?Sized>(
    x: &OVector<T, N>,
    g: &G,
) -> (N, M)
where
    DefaultAllocator: Alloc<N, M>,
{
    let m = M::try_to_usize().unwrap_or_else(|| g.eval(x).nrows());
    (x.shape_generic().0, M::from_usize(m))
}

/// Checks that x and C have the workspace's n, and resets output buffers of the wrong shape
/// (left by an earlier failure), so the kernels only ever see agreeing shapes.
#[inline(always)]
fn check_inputs<T: Real, N: Dim, M: Dim>(
    mean: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    out_mean: &mut OVector<T, M>,
    out_covariance: &mut OMatrix<T, M, M>,
    cross: Option<&mut OMatrix<T, N, M>>,
    workspace: &Workspace<T, N, M>,
) -> Result<()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (n, m) = (workspace.n, workspace.m);
    let stage = Stage::Propagation;
    ensure_shape(mean, n.value(), 1, stage, Quantity::Mean)?;
    ensure_shape(
        covariance,
        n.value(),
        n.value(),
        stage,
        Quantity::Covariance,
    )?;
    if out_covariance.shape() != (m.value(), m.value()) {
        *out_covariance = OMatrix::zeros_generic(m, m);
    }
    if out_mean.shape() != (m.value(), 1) {
        *out_mean = OVector::zeros_generic(m, nalgebra::U1);
    }
    if let Some(cross) = cross
        && cross.shape() != (n.value(), m.value())
    {
        *cross = OMatrix::zeros_generic(n, m);
    }
    Ok(())
}

/// Makes the covariance symmetric from its lower triangle (the propagators compute only that
/// triangle of their symmetric products: [`crate::kernel::mul_lower`]) and checks the results
/// are finite.
#[inline(always)]
fn finish<T: Real, N: Dim, M: Dim>(
    mean: &OVector<T, M>,
    covariance: &mut OMatrix<T, M, M>,
    cross: Option<&OMatrix<T, N, M>>,
    noise: Option<&OMatrix<T, M, M>>,
) -> Result<()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Propagation;
    ensure_finite(mean, stage, Quantity::Mean)?;
    let finite = match noise {
        None => mirror_lower_checked(covariance),
        Some(noise) => {
            // cov + noise, symmetrised, from cov's lower triangle: the arithmetic of
            // mirroring it, adding the noise and averaging the triangles, in one pass.
            ensure_shape(
                noise,
                mean.nrows(),
                mean.nrows(),
                stage,
                Quantity::ProcessNoise,
            )?;
            let half = crate::scalar::real::<T>(0.5);
            let n = covariance.nrows();
            symmetric_map(
                n,
                covariance.as_mut_slice(),
                [noise.as_slice()],
                |c_ij, [q_ij], _, [q_ji]| ((c_ij + q_ij) + (c_ij + q_ji)) * half,
            )
        }
    };
    finite_or_error(finite, stage, Quantity::Covariance)?;
    if let Some(cross) = cross {
        ensure_finite(cross, stage, Quantity::CrossCovariance)?;
    }
    Ok(())
}

/// Implements [`MomentPropagator`]'s three `_into` methods for a propagator with an inherent
/// `moments_into(mean, covariance, g, out_mean, out_covariance, cross: Option<..>,
/// noise: Option<..>, workspace)`.
macro_rules! impl_propagator_via_moments_into {
    () => {
        #[inline(always)]
        fn propagate_into(
            &self,
            mean: &OVector<T, N>,
            covariance: &OMatrix<T, N, N>,
            g: &G,
            out: &mut super::Moments<T, N, M>,
            workspace: &mut super::Workspace<T, N, M>,
        ) -> Result<()> {
            let super::Moments {
                mean: out_mean,
                covariance: out_covariance,
                cross_covariance,
            } = out;
            self.moments_into(
                mean,
                covariance,
                g,
                out_mean,
                out_covariance,
                Some(cross_covariance),
                None,
                workspace,
            )
        }

        #[inline(always)]
        fn propagate_mean_covariance_into(
            &self,
            mean: &OVector<T, N>,
            covariance: &OMatrix<T, N, N>,
            g: &G,
            out_mean: &mut OVector<T, M>,
            out_covariance: &mut OMatrix<T, M, M>,
            workspace: &mut super::Workspace<T, N, M>,
        ) -> Result<()> {
            self.moments_into(
                mean,
                covariance,
                g,
                out_mean,
                out_covariance,
                None,
                None,
                workspace,
            )
        }

        #[inline(always)]
        fn propagate_with_noise_into(
            &self,
            mean: &OVector<T, N>,
            covariance: &OMatrix<T, N, N>,
            g: &G,
            noise: &OMatrix<T, M, M>,
            out_mean: &mut OVector<T, M>,
            out_covariance: &mut OMatrix<T, M, M>,
            workspace: &mut super::Workspace<T, N, M>,
        ) -> Result<()> {
            self.moments_into(
                mean,
                covariance,
                g,
                out_mean,
                out_covariance,
                None,
                Some(noise),
                workspace,
            )
        }
    };
}
use impl_propagator_via_moments_into;
