//! A Gaussian (normal) distribution N(μ, C) over an N-dimensional space.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::error::{Quantity, Result, Stage};
use crate::linalg::{ensure_finite, ensure_psd, ensure_shape, ensure_symmetric};
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
}
