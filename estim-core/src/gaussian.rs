//! A Gaussian (normal) distribution N(μ, C) over an N-dimensional space.

#[cfg(feature = "std")]
use nalgebra::{DMatrix, DVector, Dyn, U1};
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
#[cfg(feature = "std")]
use rand::Rng;
#[cfg(feature = "std")]
use rand_distr::{Distribution, StandardNormal};

use crate::alloc::Alloc;
use crate::checks::{ensure_finite, ensure_psd, ensure_shape, ensure_symmetric};
use crate::error::{Quantity, Result, Stage};
#[cfg(feature = "std")]
use crate::linalg::psd_factor;
use crate::scalar::Real;

/// A mean μ and covariance C, checked at construction.
///
/// ```
/// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
/// let g = Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::new(2.0, 0.5, 0.5, 1.0))?;
/// assert_eq!(g.mean()[1], 2.0);
/// assert!(Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::new(1.0, 2.0, 2.0, 1.0)).is_err());
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Gaussian<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    mean: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim> Gaussian<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// N(mean, covariance), after checking, in this order, that the shapes agree, every entry
    /// is finite, the covariance is symmetric (within √ε relative to its largest entry) and
    /// positive semi-definite (no pivot below −16 n ε max Cᵢᵢ). The error names the failed check.
    pub fn new(mean: OVector<T, N>, covariance: OMatrix<T, N, N>) -> Result<Self> {
        let n = mean.nrows();
        let stage = Stage::Construction;
        ensure_shape(&covariance, n, n, stage, Quantity::Covariance)?;
        ensure_finite(&mean, stage, Quantity::Mean)?;
        ensure_finite(&covariance, stage, Quantity::Covariance)?;
        ensure_symmetric(&covariance, stage, Quantity::Covariance)?;
        ensure_psd(&covariance, stage, Quantity::Covariance)?;
        Ok(Self { mean, covariance })
    }

    /// N(mean, covariance) without checks. The caller guarantees what [`Gaussian::new`]
    /// would check; algorithms given a bad covariance return errors later, not panics.
    pub fn new_unchecked(mean: OVector<T, N>, covariance: OMatrix<T, N, N>) -> Self {
        Self { mean, covariance }
    }

    /// The mean μ.
    pub fn mean(&self) -> &OVector<T, N> {
        &self.mean
    }

    /// The covariance C.
    pub fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.covariance
    }

    /// The dimension n.
    pub fn dim(&self) -> usize {
        self.mean.nrows()
    }

    /// (μ, C), consuming the Gaussian.
    pub fn into_parts(self) -> (OVector<T, N>, OMatrix<T, N, N>) {
        (self.mean, self.covariance)
    }

    /// The same Gaussian on runtime sizes (`DVector`/`DMatrix`), e.g. to hand a static-size
    /// prior to a filter whose size comes from configuration.
    ///
    /// ```
    /// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
    /// let g = Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::identity())?.into_dyn();
    /// assert_eq!((g.dim(), g.covariance().ncols()), (2, 2));
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    #[cfg(feature = "std")]
    pub fn into_dyn(self) -> Gaussian<T, Dyn> {
        let n = self.dim();
        // `_generic` with the types spelled out: inside this impl's `Alloc<N>` bound rustc
        // would otherwise resolve the allocator for N, not Dyn.
        let mean = DVector::<T>::from_column_slice_generic(Dyn(n), U1, self.mean.as_slice());
        let covariance =
            DMatrix::<T>::from_column_slice_generic(Dyn(n), Dyn(n), self.covariance.as_slice());
        Gaussian::<T, Dyn> { mean, covariance }
    }

    /// A sampler of this Gaussian: x = μ + S z with S Sᵀ = C ([`psd_factor`], so a
    /// semi-definite C works) and z standard normal. The factor is computed once here, so
    /// draw many samples from one sampler.
    ///
    /// Errors: a covariance that is not positive semi-definite (possible only for a Gaussian
    /// built with [`new_unchecked`](Self::new_unchecked)).
    ///
    /// ```
    /// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
    /// use rand::SeedableRng;
    /// use rand_distr::Distribution;
    ///
    /// let g = Gaussian::new(Vector2::new(1.0, -1.0), Matrix2::new(4.0, 1.0, 1.0, 1.0))?;
    /// let sampler = g.sampler()?;
    /// let mut rng = estim_core::rand::rngs::StdRng::seed_from_u64(7);
    /// let n = 20_000;
    /// let mean = (0..n).map(|_| sampler.sample(&mut rng)).sum::<Vector2<f64>>() / n as f64;
    /// // The sample mean is within 5 standard errors (√(4/n) = 0.014) of μ.
    /// assert!((mean - g.mean()).abs().max() < 0.07);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    #[cfg(feature = "std")]
    pub fn sampler(&self) -> Result<GaussianSampler<T, N>> {
        Ok(GaussianSampler {
            mean: self.mean.clone(),
            factor: psd_factor(&self.covariance, Stage::Construction)?,
        })
    }

    /// One draw x ~ N(μ, C). Factorises C on every call: for many draws use
    /// [`sampler`](Self::sampler).
    ///
    /// ```
    /// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
    /// use rand::SeedableRng;
    ///
    /// let g = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 1e-300)?;
    /// let x = g.sample(&mut estim_core::rand::rngs::StdRng::seed_from_u64(1))?;
    /// assert!(x.norm() < 1e-140);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    #[cfg(feature = "std")]
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Result<OVector<T, N>> {
        Ok(self.sampler()?.sample(rng))
    }
}

/// Draws from a [`Gaussian`] (from [`Gaussian::sampler`]): x = μ + S z, z ~ N(0, I), with the
/// factor S computed once. Implements [`rand_distr::Distribution`].
#[cfg(feature = "std")]
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianSampler<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    mean: OVector<T, N>,
    factor: OMatrix<T, N, N>,
}

#[cfg(feature = "std")]
impl<T: Real, N: Dim> Distribution<OVector<T, N>> for GaussianSampler<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> OVector<T, N> {
        let (n, _) = self.mean.shape_generic();
        // Drawn in f64 and rounded, so f32 and f64 samplers see the same normal stream.
        let z = OVector::<T, N>::from_fn_generic(n, U1, |_, _| {
            nalgebra::convert::<f64, T>(StandardNormal.sample(rng))
        });
        &self.mean + &self.factor * z
    }
}
