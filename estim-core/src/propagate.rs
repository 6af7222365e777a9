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
use crate::checks::{ensure_finite, ensure_shape, finite_or_error};
use crate::error::{Quantity, Result, Stage};
use crate::function::VectorFunction;
use crate::gaussian::Gaussian;
use crate::linalg::{mirror_lower_checked, symmetric_map};
use crate::scalar::Real;

mod affine;
mod linearized;
#[cfg(feature = "std")]
mod sampled;
mod second_order;
mod unscented;
mod workspace;

pub use affine::Affine;
pub use linearized::{Linearized, LinearizedWorkspace};
#[cfg(feature = "std")]
pub use sampled::Sampled;
pub use second_order::{SecondOrder, SecondOrderGaussian, SecondOrderWorkspace};
pub use unscented::{SigmaDeviations, Unscented, UnscentedWorkspace};

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
    /// [`Outputs::moments`].
    pub fn zeros(n: N, m: M) -> Self {
        Self {
            mean: OVector::zeros_generic(m, nalgebra::U1),
            covariance: OMatrix::zeros_generic(m, m),
            cross_covariance: OMatrix::zeros_generic(n, m),
        }
    }
}

/// Where a propagation writes its results, and the independent noise it adds to cov(y).
///
/// The length of `mean` is the output dimension m; the other buffers are reshaped to agree
/// if they do not. On error the buffers' contents (and shapes) are unspecified.
///
/// Repeated propagation into the same buffers, with the propagator's workspace kept between
/// calls (what a filter does; for runtime sizes nothing is allocated after the first call):
///
/// ```
/// use estim_core::{LinearMeasurement, MomentPropagator, Moments, Observation, Outputs, Unscented};
/// use estim_core::nalgebra::{DMatrix, DVector, Dyn};
///
/// let sensor = LinearMeasurement {
///     observation: DMatrix::from_row_slice(1, 2, &[1.0, 1.0]),
///     noise: DMatrix::identity(1, 1),
/// };
/// let (mean, covariance) = (DVector::from_vec(vec![1.0, 2.0]), DMatrix::identity(2, 2));
/// let ukf = Unscented::default();
/// let mut moments: Moments<f64, Dyn, Dyn> = Moments::zeros(Dyn(2), Dyn(1));
/// let mut workspace = Default::default();
/// for _ in 0..3 {
///     let out = Outputs::moments(&mut moments);
///     ukf.propagate_into(&mean, &covariance, &Observation::new(&sensor), out, &mut workspace)?;
/// }
/// // h(x) = x₀ + x₁ is linear: E[h] = 3, var h = 2, cov(x, h) = (1, 1).
/// assert!((moments.mean[0] - 3.0).abs() < 1e-9 && (moments.covariance[(0, 0)] - 2.0).abs() < 1e-9);
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Debug)]
pub struct Outputs<'a, T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// E\[y\] (m).
    pub mean: &'a mut OVector<T, M>,
    /// cov(y) (m × m), plus `noise` if given, symmetric.
    pub covariance: &'a mut OMatrix<T, M, M>,
    /// cov(x, y) (n × m), computed only if asked for.
    pub cross_covariance: Option<&'a mut OMatrix<T, N, M>>,
    /// The covariance of a noise w independent of x, for y = g(x) + w (a filter's process
    /// noise Q); must be m × m.
    pub noise: Option<&'a OMatrix<T, M, M>>,
}

impl<'a, T: Real, N: Dim, M: Dim> Outputs<'a, T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// All three moments, into `moments`.
    pub fn moments(moments: &'a mut Moments<T, N, M>) -> Self {
        Self {
            mean: &mut moments.mean,
            covariance: &mut moments.covariance,
            cross_covariance: Some(&mut moments.cross_covariance),
            noise: None,
        }
    }

    /// E\[y\] and cov(y) only (a filter's prediction needs no cross-covariance).
    pub fn mean_covariance(
        mean: &'a mut OVector<T, M>,
        covariance: &'a mut OMatrix<T, M, M>,
    ) -> Self {
        Self {
            mean,
            covariance,
            cross_covariance: None,
            noise: None,
        }
    }

    /// The same outputs for y = g(x) + w, w ~ N(0, `noise`) independent of x: cov(y) gets
    /// `noise` added (P⁻ = cov f + Q in a prediction).
    pub fn with_noise(mut self, noise: &'a OMatrix<T, M, M>) -> Self {
        self.noise = Some(noise);
        self
    }
}

/// Names the buffers a moment propagator keeps between calls, for each pair of dimensions
/// (n, m). A filter keeps one per shape it sees, so repeated runtime-size propagation
/// allocates nothing after the first call; for static sizes the buffers live inline.
///
/// Every [`MomentPropagator`] implements it; a propagator that needs no buffers says
/// `type Workspace<N: Dim, M: Dim> = () where DefaultAllocator: Alloc<N, M>;`.
pub trait PropagatorWorkspace<T: Real> {
    /// The buffers for maps from N to M dimensions. `Default` is empty: a propagator sizes
    /// its buffers on first use. Contents between calls are unspecified.
    type Workspace<N: Dim, M: Dim>: Default
    where
        DefaultAllocator: Alloc<N, M>;
}

/// Computes the [`Moments`] of y = g(x), x ~ N(μ, C).
///
/// Generic over the function type `G`, so each propagator bounds only the capability it
/// needs: `Linearized` implements this for every `G: Differentiable`, `Unscented` for every
/// `G: VectorFunction`. One method is required,
/// [`propagate_into`](Self::propagate_into); the others wrap it for one-off use.
///
/// ```
/// use estim_core::{MomentPropagator, Unscented, VectorFunction};
/// use estim_core::nalgebra::{Const, Matrix1, Vector1};
///
/// struct Square;
/// impl VectorFunction<f64, Const<1>, Const<1>> for Square {
///     fn eval(&self, x: &Vector1<f64>) -> Vector1<f64> {
///         x.map(|v| v * v)
///     }
/// }
/// // x ~ N(1, 0.5): E[x²] = 1.5 (the unscented transform is exact for a quadratic).
/// let y = Unscented::default()
///     .propagate(&Vector1::new(1.0), &Matrix1::new(0.5), &Square)
///     .unwrap();
/// assert!((y.mean[0] - 1.5).abs() < 1e-9);
/// ```
pub trait MomentPropagator<T: Real, N: Dim, M: Dim, G: VectorFunction<T, N, M> + ?Sized>:
    PropagatorWorkspace<T>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The moments of g(x) for x with mean `mean` and covariance `covariance` (symmetric
    /// positive semi-definite; a propagator that factorises it reports when it is not), into
    /// `out` (which also says whether the cross-covariance is wanted and what noise to add),
    /// with scratch in `workspace`.
    ///
    /// Errors: a non-finite result, a shape mismatch between g, x and the outputs, or a
    /// covariance that cannot be factorised. On error `out` is unspecified.
    fn propagate_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        out: Outputs<'_, T, N, M>,
        workspace: &mut Self::Workspace<N, M>,
    ) -> Result<()>;

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
        let mut workspace = Default::default();
        self.propagate_into(
            mean,
            covariance,
            g,
            Outputs::moments(&mut out),
            &mut workspace,
        )?;
        Ok(out)
    }

    /// [`propagate`](Self::propagate) for a [`Gaussian`].
    fn propagate_gaussian(&self, x: &Gaussian<T, N>, g: &G) -> Result<Moments<T, N, M>> {
        self.propagate(x.mean(), x.covariance(), g)
    }

    /// E\[y\] and cov(y) only, for callers that do not need cov(x, y).
    fn propagate_mean_covariance(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<MeanCovariance<T, M>> {
        let (_, m) = dimensions(mean, g);
        let mut out_mean = OVector::zeros_generic(m, nalgebra::U1);
        let mut out_covariance = OMatrix::zeros_generic(m, m);
        let mut workspace = Default::default();
        self.propagate_into(
            mean,
            covariance,
            g,
            Outputs::mean_covariance(&mut out_mean, &mut out_covariance),
            &mut workspace,
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

/// Checks that C is n × n for the n of x, and reshapes output buffers that disagree with the
/// mean buffer's m (left by an earlier failure), so the kernels only ever see agreeing shapes.
/// Returns (n, m).
#[cfg_attr(not(debug_assertions), inline(always))]
fn check_inputs<T: Real, N: Dim, M: Dim>(
    mean: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    out: &mut Outputs<'_, T, N, M>,
) -> Result<(N, M)>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = mean.shape_generic().0;
    let m = out.mean.shape_generic().0;
    ensure_shape(
        covariance,
        n.value(),
        n.value(),
        Stage::Propagation,
        Quantity::Covariance,
    )?;
    if out.covariance.shape() != (m.value(), m.value()) {
        *out.covariance = OMatrix::zeros_generic(m, m);
    }
    if let Some(cross) = out.cross_covariance.as_deref_mut()
        && cross.shape() != (n.value(), m.value())
    {
        *cross = OMatrix::zeros_generic(n, m);
    }
    Ok((n, m))
}

impl<T: Real, N: Dim, M: Dim> Outputs<'_, T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The last step of every propagation, for custom propagators too: once `mean`, the lower
    /// triangle of `covariance` and (if asked for) `cross_covariance` are written, makes the
    /// covariance symmetric from its lower triangle, adds `noise` if given, and checks that
    /// every result is finite ([`Error::NonFinite`](crate::Error::NonFinite), stage
    /// `Propagation`; a noise of the wrong shape is a dimension error naming `ProcessNoise`).
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub fn finish(self) -> Result<()> {
        finish(self)
    }
}

/// [`Outputs::finish`].
#[cfg_attr(not(debug_assertions), inline(always))]
fn finish<T: Real, N: Dim, M: Dim>(out: Outputs<'_, T, N, M>) -> Result<()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Propagation;
    ensure_finite(&*out.mean, stage, Quantity::Mean)?;
    let covariance = out.covariance;
    let finite = match out.noise {
        None => mirror_lower_checked(covariance),
        Some(noise) => {
            // cov + noise, symmetrised, from cov's lower triangle: the arithmetic of
            // mirroring it, adding the noise and averaging the triangles, in one pass.
            let m = out.mean.nrows();
            ensure_shape(noise, m, m, stage, Quantity::ProcessNoise)?;
            let half = crate::scalar::real::<T>(0.5);
            symmetric_map(
                m,
                covariance.as_mut_slice(),
                [noise.as_slice()],
                |c_ij, [q_ij], _, [q_ji]| ((c_ij + q_ij) + (c_ij + q_ji)) * half,
            )
        }
    };
    finite_or_error(finite, stage, Quantity::Covariance)?;
    if let Some(cross) = out.cross_covariance {
        ensure_finite(&*cross, stage, Quantity::CrossCovariance)?;
    }
    Ok(())
}
