//! What the Gaussian filters' [`Rollback`](crate::Rollback) snapshots hold.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Real};

/// A full-covariance filter's snapshot: the estimate x̂ and P exactly as the filter holds
/// them. Taken by [`GaussianFilter`](crate::GaussianFilter) and the filters built on it
/// ([`Iekf`](crate::Iekf), [`FadingMemoryRls`](crate::FadingMemoryRls)).
#[derive(Clone, Debug, PartialEq)]
pub struct EstimateSnapshot<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) state: OVector<T, N>,
    pub(crate) covariance: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim> EstimateSnapshot<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The state estimate x̂ saved.
    pub fn state(&self) -> &OVector<T, N> {
        &self.state
    }

    /// The covariance P saved.
    pub fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.covariance
    }

    /// Overwrites this snapshot with (x̂, P), reusing its buffers when the sizes agree.
    pub(crate) fn copy_from(&mut self, state: &OVector<T, N>, covariance: &OMatrix<T, N, N>) {
        self.state.clone_from(state);
        self.covariance.clone_from(covariance);
    }
}

/// A square-root filter's snapshot: x̂, the factor S, and P = S Sᵀ as the filter formed it,
/// so that a restore needs no refactorisation and loses no bit. Taken by
/// [`SquareRootFilter`](crate::SquareRootFilter).
#[derive(Clone, Debug, PartialEq)]
pub struct FactorSnapshot<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) estimate: EstimateSnapshot<T, N>,
    pub(crate) factor: OMatrix<T, N, N>,
    pub(crate) factored: bool,
}

impl<T: Real, N: Dim> FactorSnapshot<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The state estimate x̂ saved.
    pub fn state(&self) -> &OVector<T, N> {
        &self.estimate.state
    }

    /// The covariance P = S Sᵀ saved.
    pub fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.estimate.covariance
    }

    /// The lower-triangular factor S saved.
    pub fn factor(&self) -> &OMatrix<T, N, N> {
        &self.factor
    }
}
