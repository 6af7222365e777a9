//! The buffers a filter step works in, and where a filter keeps them between steps.
//!
//! A step computes its new estimate aside (so a failure changes nothing) in a scratch of
//! nalgebra matrices. For static sizes the scratch is a local on the stack. For runtime sizes
//! it is created by `prepare_*` or the first step with each (n, m) and kept in the filter's [`ScratchCache`],
//! so every later step allocates nothing.

use core::marker::PhantomData;

#[cfg(feature = "std")]
use estim_core::alloc::{DimAlloc, SizeFamily};
#[cfg(feature = "std")]
use estim_core::kernel::is_static;
#[cfg(feature = "std")]
use estim_core::nalgebra::Dyn;
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::{Alloc, PropagatorWorkspace, Real};

/// Buffers of one prediction over an `N`-dimensional state with propagator `Pr`.
pub(crate) struct PredictScratch<T: Real, N: Dim, Pr: PropagatorWorkspace<T>>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) propagation: Pr::Workspace<N, N>,
    /// The predicted mean, then the committed state's old buffer.
    pub(crate) state: OVector<T, N>,
    /// The predicted covariance, then the committed covariance's old buffer.
    pub(crate) covariance: OMatrix<T, N, N>,
    pub(crate) noise: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>> PredictScratch<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn new(n: N) -> Self {
        Self {
            propagation: Default::default(),
            state: OVector::zeros_generic(n, U1),
            covariance: OMatrix::zeros_generic(n, n),
            noise: OMatrix::zeros_generic(n, n),
        }
    }
}

/// Buffers of one measurement update with `M` components and propagator `Pr`.
pub(crate) struct UpdateScratch<T: Real, N: Dim, M: Dim, Pr: PropagatorWorkspace<T>>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) propagation: Pr::Workspace<N, M>,
    pub(crate) predicted: estim_core::Moments<T, N, M>,
    pub(crate) noise: OMatrix<T, M, M>,
    /// The Cholesky factor L of S.
    pub(crate) factor: OMatrix<T, M, M>,
    /// L⁻¹ ν.
    pub(crate) whitened: OVector<T, M>,
    /// K (n × m): Pₓᵤ, then solved in place.
    pub(crate) gain: OMatrix<T, N, M>,
    /// K S (n × m), for the Joseph form.
    pub(crate) gain_s: OMatrix<T, N, M>,
    /// K S Kᵀ (n × n), for the Joseph form.
    pub(crate) gain_s_gain: OMatrix<T, N, N>,
    /// −K Pₓᵤᵀ (n × n), turned into the posterior covariance in place; after the commit, the
    /// committed covariance's old buffer.
    pub(crate) covariance: OMatrix<T, N, N>,
    /// The posterior state, then the committed state's old buffer.
    pub(crate) state: OVector<T, N>,
    /// K ν for a state space other than ℝⁿ (created on first use).
    pub(crate) step: Option<OVector<T, N>>,
    pub(crate) cholesky: estim_core::kernel::CholeskyScratch,
}

impl<T: Real, N: Dim, M: Dim, Pr: PropagatorWorkspace<T>> UpdateScratch<T, N, M, Pr>
where
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn new(n: N, m: M) -> Self {
        Self {
            propagation: Default::default(),
            predicted: estim_core::Moments::zeros(n, m),
            noise: OMatrix::zeros_generic(m, m),
            factor: OMatrix::zeros_generic(m, m),
            whitened: OVector::zeros_generic(m, U1),
            gain: OMatrix::zeros_generic(n, m),
            gain_s: OMatrix::zeros_generic(n, m),
            gain_s_gain: OMatrix::zeros_generic(n, n),
            covariance: OMatrix::zeros_generic(n, n),
            state: OVector::zeros_generic(n, U1),
            step: None,
            cholesky: Default::default(),
        }
    }

    #[cfg(feature = "std")]
    fn dimensions(&self) -> (usize, usize) {
        (self.state.nrows(), self.predicted.mean.nrows())
    }
}

/// [`PredictScratch`] as a function of the state dimension, for [`DimAlloc::runtime_sized`].
#[cfg(feature = "std")]
struct PredictFamily<T, Pr>(PhantomData<(T, Pr)>);

#[cfg(feature = "std")]
impl<T: Real, Pr: PropagatorWorkspace<T>> SizeFamily<Dyn> for PredictFamily<T, Pr> {
    type Of<Z: Dim>
        = PredictScratch<T, Z, Pr>
    where
        DefaultAllocator: Alloc<Z, Dyn>;
}

/// [`UpdateScratch`] with a runtime-size measurement, as a function of the state dimension.
#[cfg(feature = "std")]
struct UpdateOfStates<T, Pr>(PhantomData<(T, Pr)>);

#[cfg(feature = "std")]
impl<T: Real, Pr: PropagatorWorkspace<T>> SizeFamily<Dyn> for UpdateOfStates<T, Pr> {
    type Of<Z: Dim>
        = UpdateScratch<T, Z, Dyn, Pr>
    where
        DefaultAllocator: Alloc<Z, Dyn>;
}

/// [`UpdateScratch`] with N states, as a function of the measurement dimension.
#[cfg(feature = "std")]
struct UpdateOfMeasurements<T, N, Pr>(PhantomData<(T, N, Pr)>);

#[cfg(feature = "std")]
impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>> SizeFamily<N> for UpdateOfMeasurements<T, N, Pr> {
    type Of<Z: Dim>
        = UpdateScratch<T, N, Z, Pr>
    where
        DefaultAllocator: Alloc<Z, N>;
}

/// A cached update scratch and its slot in the cache.
pub(crate) type CachedUpdate<'a, T, N, M, Pr> = (&'a mut UpdateScratch<T, N, M, Pr>, usize);

/// What a filter keeps between steps for runtime sizes: the scratch of its prediction and one
/// per measurement length, created on first use. Only fully dynamic scratch (n and m both
/// `Dyn`) is kept; mixed static/dynamic shapes run the same code with a fresh scratch per step.
/// It is scratch, not state: a cloned filter starts with an empty one, and it takes no part in
/// equality.
#[cfg(feature = "std")]
pub(crate) struct ScratchCache<T: Real, Pr: PropagatorWorkspace<T>> {
    predict: Option<PredictScratch<T, Dyn, Pr>>,
    update: Vec<UpdateScratch<T, Dyn, Dyn, Pr>>,
}

#[cfg(feature = "std")]
impl<T: Real, Pr: PropagatorWorkspace<T>> Default for ScratchCache<T, Pr> {
    fn default() -> Self {
        Self {
            predict: None,
            update: Vec::new(),
        }
    }
}

#[cfg(feature = "std")]
impl<T: Real, Pr: PropagatorWorkspace<T>> core::fmt::Debug for ScratchCache<T, Pr> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ScratchCache")
            .field("predict", &self.predict.is_some())
            .field("update", &self.update.len())
            .finish()
    }
}

#[cfg(feature = "std")]
impl<T: Real, Pr: PropagatorWorkspace<T>> ScratchCache<T, Pr> {
    /// Drops every scratch (after the state dimension changed).
    pub(crate) fn clear(&mut self) {
        *self = Self::default();
    }

    /// The cached prediction scratch for `n` states if `N` is `Dyn` (made on first use), or
    /// `None` for a static size: then the caller uses a local, which the compiler keeps in
    /// registers. (Returning the choice rather than taking a closure keeps the whole static
    /// step in one function, where that optimisation can see it.)
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn predict<N: Dim>(&mut self, n: N) -> Option<&mut PredictScratch<T, N, Pr>>
    where
        DefaultAllocator: Alloc<N>,
    {
        if is_static::<N>() {
            return None;
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
            .get_or_insert_with(|| PredictScratch::<T, Dyn, Pr>::new(Dyn(n.value())));
        <DefaultAllocator as DimAlloc<N>>::runtime_sized::<Dyn, PredictFamily<T, Pr>>(cached)
    }

    /// Drops the cached prediction scratch, after a failed step: a model's owned value (the
    /// route of a model without [`InPlace`](estim_core::InPlace)) may have reshaped a buffer.
    pub(crate) fn discard_predict(&mut self) {
        self.predict = None;
    }

    /// The cached update scratch for `n` states and `m` measurement components and its slot,
    /// if both are `Dyn` (made on first use); `None` otherwise (the caller uses a local).
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn update<N: Dim, M: Dim>(
        &mut self,
        n: N,
        m: M,
    ) -> Option<CachedUpdate<'_, T, N, M, Pr>>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        if is_static::<N>() || is_static::<M>() {
            return None;
        }
        let dims = (n.value(), m.value());
        let index = match self.update.iter().position(|s| s.dimensions() == dims) {
            Some(index) => index,
            None => {
                self.update.push(UpdateScratch::<T, Dyn, Dyn, Pr>::new(
                    Dyn(dims.0),
                    Dyn(dims.1),
                ));
                self.update.len() - 1
            }
        };
        let cached = &mut self.update[index];
        // Both dimensions are runtime sizes here: the cached (Dyn, Dyn) scratch, seen as
        // (N, Dyn), then as (N, M).
        let by_states =
            <DefaultAllocator as DimAlloc<N>>::runtime_sized::<Dyn, UpdateOfStates<T, Pr>>(cached)?;
        <DefaultAllocator as DimAlloc<M>>::runtime_sized::<N, UpdateOfMeasurements<T, N, Pr>>(
            by_states,
        )
        .map(|scratch| (scratch, index))
    }

    /// Drops the cached update scratch in `slot`, after a failed step.
    pub(crate) fn discard_update(&mut self, slot: usize) {
        self.update.swap_remove(slot);
    }
}

/// Without std only static sizes exist, and their scratch is always a local: the cache holds
/// nothing and hands out nothing.
#[cfg(not(feature = "std"))]
pub(crate) struct ScratchCache<T: Real, Pr: PropagatorWorkspace<T>>(PhantomData<(T, Pr)>);

#[cfg(not(feature = "std"))]
impl<T: Real, Pr: PropagatorWorkspace<T>> Default for ScratchCache<T, Pr> {
    fn default() -> Self {
        Self(PhantomData)
    }
}

#[cfg(not(feature = "std"))]
impl<T: Real, Pr: PropagatorWorkspace<T>> core::fmt::Debug for ScratchCache<T, Pr> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("ScratchCache")
    }
}

#[cfg(not(feature = "std"))]
impl<T: Real, Pr: PropagatorWorkspace<T>> ScratchCache<T, Pr> {
    /// Nothing to drop.
    pub(crate) fn clear(&mut self) {}

    /// Always `None`: the caller uses a local.
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn predict<N: Dim>(&mut self, _: N) -> Option<&mut PredictScratch<T, N, Pr>>
    where
        DefaultAllocator: Alloc<N>,
    {
        None
    }

    /// Nothing to drop.
    pub(crate) fn discard_predict(&mut self) {}

    /// Always `None`: the caller uses a local.
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn update<N: Dim, M: Dim>(
        &mut self,
        _: N,
        _: M,
    ) -> Option<CachedUpdate<'_, T, N, M, Pr>>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        None
    }

    /// Nothing to drop.
    pub(crate) fn discard_update(&mut self, _slot: usize) {}
}
