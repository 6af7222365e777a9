//! Buffers the propagators size on first use.

use nalgebra::{DefaultAllocator, Dim, OMatrix};

use crate::scalar::Real;

/// The buffer in `slot`, created (zeroed) if absent or of another shape. A model's default
/// `_into` method may have replaced a buffer by one of the wrong shape (and the caller then
/// reported it); this puts the right one back.
#[cfg_attr(not(debug_assertions), inline(always))]
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
