//! The buffers a filter step works in, and where a filter keeps them between steps.
//!
//! A step computes its new estimate aside (so a failure changes nothing) in a scratch of
//! nalgebra matrices. For static sizes the scratch is a local on the stack. For runtime sizes
//! it is created on the first step with each (n, m) and kept in the filter's [`ScratchCache`],
//! so every later step allocates nothing.

use core::any::{Any, TypeId};

use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::{Alloc, Real, Workspace, error::Result};

/// Buffers of one prediction over an `N`-dimensional state.
pub(crate) struct PredictScratch<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) propagation: Workspace<T, N, N>,
    /// The predicted mean, then the committed state's old buffer.
    pub(crate) state: OVector<T, N>,
    /// The predicted covariance, then the committed covariance's old buffer.
    pub(crate) covariance: OMatrix<T, N, N>,
    pub(crate) noise: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim> PredictScratch<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    #[inline(always)]
    pub(crate) fn new(n: N) -> Self {
        Self {
            propagation: Workspace::new(n, n),
            state: OVector::zeros_generic(n, U1),
            covariance: OMatrix::zeros_generic(n, n),
            noise: OMatrix::zeros_generic(n, n),
        }
    }
}

/// Buffers of one measurement update with `M` components.
pub(crate) struct UpdateScratch<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) propagation: Workspace<T, N, M>,
    pub(crate) predicted: estim_core::Moments<T, N, M>,
    pub(crate) noise: OMatrix<T, M, M>,
    /// The Cholesky factor L of S.
    pub(crate) factor: OMatrix<T, M, M>,
    /// L⁻¹ ν.
    pub(crate) whitened: OVector<T, M>,
    /// Kᵀ (m × n): Pₓᵤᵀ, then solved in place.
    pub(crate) gain_t: OMatrix<T, M, N>,
    /// Aᵀ = ½ S Kᵀ − Pₓᵤᵀ (m × n) for the Joseph form (−Pₓᵤᵀ for the others).
    pub(crate) joseph_t: OMatrix<T, M, N>,
    /// A Kᵀ (n × n).
    pub(crate) product: OMatrix<T, N, N>,
    /// The posterior state, then the committed state's old buffer.
    pub(crate) state: OVector<T, N>,
    /// The posterior covariance, then the committed covariance's old buffer.
    pub(crate) covariance: OMatrix<T, N, N>,
    /// P/γ for the fading-memory filter (created on first use).
    pub(crate) inflated: Option<OMatrix<T, N, N>>,
    pub(crate) cholesky: estim_core::kernel::CholeskyScratch,
}

impl<T: Real, N: Dim, M: Dim> UpdateScratch<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    #[inline(always)]
    pub(crate) fn new(n: N, m: M) -> Self {
        Self {
            propagation: Workspace::new(n, m),
            predicted: estim_core::Moments::zeros(n, m),
            noise: OMatrix::zeros_generic(m, m),
            factor: OMatrix::zeros_generic(m, m),
            whitened: OVector::zeros_generic(m, U1),
            gain_t: OMatrix::zeros_generic(m, n),
            joseph_t: OMatrix::zeros_generic(m, n),
            product: OMatrix::zeros_generic(n, n),
            state: OVector::zeros_generic(n, U1),
            covariance: OMatrix::zeros_generic(n, n),
            inflated: None,
            cholesky: Default::default(),
        }
    }

    fn dimensions(&self) -> (usize, usize) {
        (self.state.nrows(), self.predicted.mean.nrows())
    }
}

/// What a filter keeps between steps for runtime sizes: the scratch of its prediction and one
/// per measurement length, created on first use. Only fully dynamic scratch (n and m both
/// `Dyn`) is kept; mixed static/dynamic shapes run the same code with a fresh scratch per step.
/// Cloning a filter does not clone it (it is scratch, not state), and it never takes part in
/// equality.
pub(crate) struct ScratchCache<T: Real> {
    predict: Option<PredictScratch<T, Dyn>>,
    update: Vec<UpdateScratch<T, Dyn, Dyn>>,
}

impl<T: Real> Default for ScratchCache<T> {
    fn default() -> Self {
        Self {
            predict: None,
            update: Vec::new(),
        }
    }
}

impl<T: Real> Clone for ScratchCache<T> {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl<T: Real> PartialEq for ScratchCache<T> {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl<T: Real> core::fmt::Debug for ScratchCache<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ScratchCache")
            .field("predict", &self.predict.is_some())
            .field("update", &self.update.len())
            .finish()
    }
}

/// `true` when `D` is `Dyn`.
#[inline(always)]
fn is_dyn<D: Dim>() -> bool {
    TypeId::of::<D>() == TypeId::of::<Dyn>()
}

impl<T: Real> ScratchCache<T> {
    /// Drops every scratch (after the state dimension changed).
    pub(crate) fn clear(&mut self) {
        *self = Self::default();
    }

    /// Runs a prediction step over `n` states in its scratch: a local for static sizes, the
    /// cached one for `Dyn`. A failed step drops the cached scratch, because a model's default
    /// `_into` method may have reshaped a buffer.
    #[inline(always)]
    pub(crate) fn predict<N: Dim, R>(
        &mut self,
        n: N,
        step: impl FnOnce(&mut PredictScratch<T, N>) -> Result<R>,
    ) -> Result<R>
    where
        DefaultAllocator: Alloc<N>,
    {
        if !is_dyn::<N>() {
            return step(&mut PredictScratch::new(n));
        }
        if self
            .predict
            .as_ref()
            .is_some_and(|s| s.state.nrows() != n.value())
        {
            self.predict = None;
        }
        let cached = self
            .predict
            .get_or_insert_with(|| PredictScratch::<T, Dyn>::new(Dyn(n.value())));
        let Some(scratch) = (cached as &mut dyn Any).downcast_mut::<PredictScratch<T, N>>() else {
            // Unreachable: N is Dyn.
            return step(&mut PredictScratch::new(n));
        };
        let result = step(scratch);
        if result.is_err() {
            self.predict = None;
        }
        result
    }

    /// Runs an update step over `n` states with `m` measurement components in its scratch: a
    /// local unless both are `Dyn`, else the cached one for (n, m), dropped if the step fails.
    #[inline(always)]
    pub(crate) fn update<N: Dim, M: Dim, R>(
        &mut self,
        n: N,
        m: M,
        step: impl FnOnce(&mut UpdateScratch<T, N, M>) -> Result<R>,
    ) -> Result<R>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        if !(is_dyn::<N>() && is_dyn::<M>()) {
            return step(&mut UpdateScratch::new(n, m));
        }
        let dims = (n.value(), m.value());
        let index = match self.update.iter().position(|s| s.dimensions() == dims) {
            Some(index) => index,
            None => {
                self.update
                    .push(UpdateScratch::<T, Dyn, Dyn>::new(Dyn(dims.0), Dyn(dims.1)));
                self.update.len() - 1
            }
        };
        let cached = &mut self.update[index];
        let Some(scratch) = (cached as &mut dyn Any).downcast_mut::<UpdateScratch<T, N, M>>()
        else {
            // Unreachable: N and M are Dyn.
            return step(&mut UpdateScratch::new(n, m));
        };
        let result = step(scratch);
        if result.is_err() {
            self.update.swap_remove(index);
        }
        result
    }
}
