//! The buffers a square-root step works in, and where the filter keeps them between steps.
//!
//! A step computes its new estimate (x̂, S, P = S Sᵀ) aside, in a [`FactorScratch`], and the
//! filter swaps it in only when every check has passed, so a failed step changes nothing. For
//! static sizes the scratch is a local on the stack; for runtime sizes (n and m both `Dyn`) the
//! first step with each shape (or `prepare_*`) creates it in the filter's [`FactorCache`], and
//! every later step of that shape allocates nothing (with models that opt in through
//! [`InPlace`](estim_core::InPlace)).

#[cfg(feature = "std")]
use core::marker::PhantomData;

#[cfg(feature = "std")]
use estim_core::alloc::{DimAlloc, SizeFamily};
#[cfg(feature = "std")]
use estim_core::kernel::is_static;
#[cfg(feature = "std")]
use estim_core::nalgebra::Dyn;
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::propagate::SigmaDeviations;
use estim_core::{Alloc, Real};

/// The buffers of one square-root step over `N` states with `M` outputs (a prediction has
/// M = N; an update M measurement components). Opaque: a filter makes and keeps them; the
/// [`FactorPredict`](super::FactorPredict) and [`FactorUpdate`](super::FactorUpdate) steps
/// write their result into `state` and `factor`, which the filter then commits with
/// P = S Sᵀ formed in `covariance`.
///
/// Which step uses what (KF/EKF; SR-UKF where it differs):
///
/// | buffer | prediction | update |
/// |---|---|---|
/// | `noise`, `root` | Q, S_Q (SR-UKF: then S⁻) | R, S_R, then L (S_zz = L Lᵀ) |
/// | `left`, `right` | F, F S (SR-UKF: D₊, D₋) | H, H S (SR-UKF: D₊ then the even part, D₋ then the odd part) |
/// | `value`, `mean` | f(x̂) (SR-UKF: and d̄) | h(x̂) (SR-UKF: g(x̂) and d̄) |
/// | `factor` | F S, then S⁻ (SR-UKF: the offsets γS) | S, then S⁺ (SR-UKF: γS first) |
/// | `covariance` | P⁻ at the commit | P⁺ at the commit (SR-UKF: S below the odd part first) |
/// | `gain`, `whitened`, `step` | unused | K̄, L⁻¹ν, K̄ L⁻¹ν or the centre column's fill-in |
pub struct FactorScratch<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(super) state: OVector<T, N>,
    pub(super) factor: OMatrix<T, N, N>,
    pub(super) covariance: OMatrix<T, N, N>,
    pub(super) noise: OMatrix<T, M, M>,
    pub(super) root: OMatrix<T, M, M>,
    pub(super) value: OVector<T, M>,
    pub(super) mean: OVector<T, M>,
    pub(super) left: OMatrix<T, M, N>,
    pub(super) right: OMatrix<T, M, N>,
    pub(super) gain: OMatrix<T, N, M>,
    pub(super) whitened: OVector<T, M>,
    pub(super) step: OVector<T, N>,
    /// The SR-UKF's sigma-point buffers (empty until it first runs).
    pub(super) sigma: SigmaDeviations<T, N, M>,
}

impl<T: Real, N: Dim, M: Dim> FactorScratch<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Zeroed buffers for `n` states and `m` outputs.
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(super) fn new(n: N, m: M) -> Self {
        Self {
            state: OVector::zeros_generic(n, U1),
            factor: OMatrix::zeros_generic(n, n),
            covariance: OMatrix::zeros_generic(n, n),
            noise: OMatrix::zeros_generic(m, m),
            root: OMatrix::zeros_generic(m, m),
            value: OVector::zeros_generic(m, U1),
            mean: OVector::zeros_generic(m, U1),
            left: OMatrix::zeros_generic(m, n),
            right: OMatrix::zeros_generic(m, n),
            gain: OMatrix::zeros_generic(n, m),
            whitened: OVector::zeros_generic(m, U1),
            step: OVector::zeros_generic(n, U1),
            sigma: SigmaDeviations::default(),
        }
    }

    /// (n, m) the buffers were made for.
    #[cfg(feature = "std")]
    fn dimensions(&self) -> (usize, usize) {
        (self.state.nrows(), self.value.nrows())
    }
}

impl<T: Real, N: Dim, M: Dim> core::fmt::Debug for FactorScratch<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("FactorScratch")
            .field("states", &self.state.nrows())
            .field("outputs", &self.value.nrows())
            .finish_non_exhaustive()
    }
}

/// [`FactorScratch`] with `Dyn` outputs, as a function of the state dimension.
#[cfg(feature = "std")]
struct OfStates<T>(PhantomData<T>);

#[cfg(feature = "std")]
impl<T: Real> SizeFamily<Dyn> for OfStates<T> {
    type Of<Z: Dim>
        = FactorScratch<T, Z, Dyn>
    where
        DefaultAllocator: Alloc<Z, Dyn>;
}

/// [`FactorScratch`] with N states, as a function of the output dimension.
#[cfg(feature = "std")]
struct OfOutputs<T, N>(PhantomData<(T, N)>);

#[cfg(feature = "std")]
impl<T: Real, N: Dim> SizeFamily<N> for OfOutputs<T, N> {
    type Of<Z: Dim>
        = FactorScratch<T, N, Z>
    where
        DefaultAllocator: Alloc<Z, N>;
}

/// What a square-root filter keeps between steps for runtime sizes: the scratch of its
/// prediction and one per measurement length, created on first use. Only fully dynamic
/// scratch (n and m both `Dyn`) is kept; static and mixed shapes use a local per step. It is
/// scratch, not state: a cloned filter starts with an empty one, and it takes no part in
/// equality.
#[cfg(feature = "std")]
pub(crate) struct FactorCache<T: Real> {
    predict: Option<FactorScratch<T, Dyn, Dyn>>,
    update: Vec<FactorScratch<T, Dyn, Dyn>>,
}

#[cfg(feature = "std")]
impl<T: Real> Default for FactorCache<T> {
    fn default() -> Self {
        Self {
            predict: None,
            update: Vec::new(),
        }
    }
}

#[cfg(feature = "std")]
impl<T: Real> core::fmt::Debug for FactorCache<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("FactorCache")
            .field("predict", &self.predict.is_some())
            .field("update", &self.update.len())
            .finish()
    }
}

/// A cached scratch and its slot in the cache (0 for the prediction's).
pub(crate) type Cached<'a, T, N, M> = (&'a mut FactorScratch<T, N, M>, usize);

#[cfg(feature = "std")]
impl<T: Real> FactorCache<T> {
    /// The cached prediction scratch for `n` states if `N` is `Dyn` (made on first use, or
    /// remade for another n), `None` for a static size (the caller then uses a local).
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn predict<N: Dim>(&mut self, n: N) -> Option<Cached<'_, T, N, N>>
    where
        DefaultAllocator: Alloc<N>,
    {
        if is_static::<N>() {
            return None;
        }
        let size = n.value();
        if (self.predict.as_ref()).is_some_and(|s| s.dimensions() != (size, size)) {
            self.predict = None;
        }
        let cached = (self.predict)
            .get_or_insert_with(|| FactorScratch::<T, Dyn, Dyn>::new(Dyn(size), Dyn(size)));
        let by_states =
            <DefaultAllocator as DimAlloc<N>>::runtime_sized::<Dyn, OfStates<T>>(cached)?;
        <DefaultAllocator as DimAlloc<N>>::runtime_sized::<N, OfOutputs<T, N>>(by_states)
            .map(|scratch| (scratch, 0))
    }

    /// The cached update scratch for `n` states and `m` measurement components and its slot,
    /// if both are `Dyn` (made on first use); `None` otherwise (the caller uses a local).
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn update<N: Dim, M: Dim>(&mut self, n: N, m: M) -> Option<Cached<'_, T, N, M>>
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
                (self.update).push(FactorScratch::<T, Dyn, Dyn>::new(Dyn(dims.0), Dyn(dims.1)));
                self.update.len() - 1
            }
        };
        let cached = &mut self.update[index];
        let by_states =
            <DefaultAllocator as DimAlloc<N>>::runtime_sized::<Dyn, OfStates<T>>(cached)?;
        <DefaultAllocator as DimAlloc<M>>::runtime_sized::<N, OfOutputs<T, N>>(by_states)
            .map(|scratch| (scratch, index))
    }

    /// Drops the cached prediction scratch, after a failed step: a model without
    /// [`InPlace`](estim_core::InPlace) returns owned values, which may have reshaped a buffer.
    pub(crate) fn discard_predict(&mut self) {
        self.predict = None;
    }

    /// Drops the cached update scratch in `slot`, after a failed step.
    pub(crate) fn discard_update(&mut self, slot: usize) {
        self.update.swap_remove(slot);
    }
}

/// Without std only static sizes exist, and their scratch is always a local.
#[cfg(not(feature = "std"))]
pub(crate) struct FactorCache<T: Real>(core::marker::PhantomData<T>);

#[cfg(not(feature = "std"))]
impl<T: Real> Default for FactorCache<T> {
    fn default() -> Self {
        Self(core::marker::PhantomData)
    }
}

#[cfg(not(feature = "std"))]
impl<T: Real> core::fmt::Debug for FactorCache<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("FactorCache")
    }
}

#[cfg(not(feature = "std"))]
impl<T: Real> FactorCache<T> {
    /// Always `None`: the caller uses a local.
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn predict<N: Dim>(&mut self, _: N) -> Option<Cached<'_, T, N, N>>
    where
        DefaultAllocator: Alloc<N>,
    {
        None
    }

    /// Always `None`: the caller uses a local.
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn update<N: Dim, M: Dim>(&mut self, _: N, _: M) -> Option<Cached<'_, T, N, M>>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        None
    }

    /// Nothing to drop.
    pub(crate) fn discard_predict(&mut self) {}

    /// Nothing to drop.
    pub(crate) fn discard_update(&mut self, _slot: usize) {}
}
