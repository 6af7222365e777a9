//! Reusable buffers for the moment propagators.

use nalgebra::{DefaultAllocator, Dim, OMatrix, U1};

use crate::alloc::Alloc;
use crate::kernel::CholeskyScratch;
use crate::scalar::Real;

/// Scratch space for propagating through a map from an `N`- to an `M`-dimensional space.
///
/// Each built-in propagator takes the buffers it needs on first use and reuses them on every
/// later call, so a caller that keeps one `Workspace` per (n, m) makes dynamic-size propagation
/// allocation-free after the first call (a filter keeps its own). For static sizes the buffers
/// live inline, wherever the workspace lives. Its contents between calls are unspecified.
/// Custom propagators may ignore it.
pub struct Workspace<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) n: N,
    pub(crate) m: M,
    pub(crate) jacobian: Option<OMatrix<T, M, N>>,
    pub(crate) jacobian_covariance: Option<OMatrix<T, M, N>>,
    pub(crate) factor: Option<OMatrix<T, N, N>>,
    pub(crate) point: Option<OMatrix<T, N, U1>>,
    pub(crate) value: Option<OMatrix<T, M, U1>>,
    pub(crate) deviation: Option<OMatrix<T, M, U1>>,
    pub(crate) mean_deviation: Option<OMatrix<T, M, U1>>,
    pub(crate) plus: Option<OMatrix<T, M, N>>,
    pub(crate) minus: Option<OMatrix<T, M, N>>,
    pub(crate) hessian: Option<OMatrix<T, N, N>>,
    pub(crate) other_hessian: Option<OMatrix<T, N, N>>,
    pub(crate) product: Option<OMatrix<T, N, N>>,
    pub(crate) sandwich: Option<OMatrix<T, N, N>>,
    pub(crate) cholesky: CholeskyScratch,
}

impl<T: Real, N: Dim, M: Dim> Workspace<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// An empty workspace for maps from `n` to `m` dimensions (nothing is allocated until a
    /// propagator asks for a buffer).
    pub fn new(n: N, m: M) -> Self {
        Self {
            n,
            m,
            jacobian: None,
            jacobian_covariance: None,
            factor: None,
            point: None,
            value: None,
            deviation: None,
            mean_deviation: None,
            plus: None,
            minus: None,
            hessian: None,
            other_hessian: None,
            product: None,
            sandwich: None,
            cholesky: CholeskyScratch::default(),
        }
    }

    /// The input dimension n.
    pub fn input_dimension(&self) -> usize {
        self.n.value()
    }

    /// The output dimension m.
    pub fn output_dimension(&self) -> usize {
        self.m.value()
    }
}

impl<T: Real, N: Dim, M: Dim> core::fmt::Debug for Workspace<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Workspace")
            .field("n", &self.n.value())
            .field("m", &self.m.value())
            .finish_non_exhaustive()
    }
}

/// The buffer in `slot`, created (zeroed) if absent or of another shape. A model's default
/// `_into` method may have replaced a buffer by one of the wrong shape (and the caller then
/// reported it); this puts the right one back.
#[inline(always)]
pub(crate) fn buffer<T: Real, R: Dim, C: Dim>(
    slot: &mut Option<OMatrix<T, R, C>>,
    r: R,
    c: C,
) -> &mut OMatrix<T, R, C>
where
    DefaultAllocator: nalgebra::allocator::Allocator<R, C>,
{
    if slot
        .as_ref()
        .is_some_and(|b| b.shape() != (r.value(), c.value()))
    {
        *slot = None;
    }
    slot.get_or_insert_with(|| OMatrix::zeros_generic(r, c))
}
