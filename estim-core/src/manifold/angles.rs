//! Wrapped angle components: the ready-made state space for headings and bearings.

use nalgebra::{DefaultAllocator, Dim, OVector};

use super::{StateSpace, add_into, subtract_into};
use crate::alloc::Alloc;
use crate::angle::wrap_components;
use crate::scalar::Real;

/// ℝⁿ with the components at `indices` on the circle (−π, π]: x ⊞ δ = wrap(x + δ) and
/// a ⊟ b = wrap(a − b) on those components, + and − on the others.
///
/// Hand it to a filter with `with_state_space` (estim-filters) so that a heading near ±π
/// keeps its estimate, sigma points and deviations right. The models are unchanged; a
/// transition may return an unwrapped angle (the filter's ⊟ and ⊞ wrap it).
///
/// Indices beyond the state's length are ignored (as in [`wrap_components`]).
///
/// ```
/// use core::f64::consts::PI;
/// use estim_core::{StateSpace, WrappedAngles};
/// use estim_core::nalgebra::Vector3;
///
/// // (x, y, heading).
/// let space = WrappedAngles::new([2]);
/// let mut out = Vector3::zeros();
/// space.plus_into(&Vector3::new(1.0, 2.0, PI - 0.1), &Vector3::new(0.5, 0.5, 0.3), &mut out);
/// assert!((out - Vector3::new(1.5, 2.5, -PI + 0.2)).norm() < 1e-12);
/// let mut d = Vector3::zeros();
/// space.minus_into(&out, &Vector3::new(1.0, 2.0, PI - 0.1), &mut d);
/// assert!((d - Vector3::new(0.5, 0.5, 0.3)).norm() < 1e-12);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct WrappedAngles<const K: usize> {
    indices: [usize; K],
}

impl<const K: usize> WrappedAngles<K> {
    /// The state space whose components `indices` are angles.
    pub const fn new(indices: [usize; K]) -> Self {
        Self { indices }
    }

    /// The angle components.
    pub fn indices(&self) -> &[usize; K] {
        &self.indices
    }
}

impl<T: Real, N: Dim, const K: usize> StateSpace<T, N> for WrappedAngles<K>
where
    DefaultAllocator: Alloc<N>,
{
    #[inline]
    fn plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        add_into(x, delta, out);
        wrap_components(out, &self.indices);
    }

    #[inline]
    fn minus_into(&self, a: &OVector<T, N>, b: &OVector<T, N>, out: &mut OVector<T, N>) {
        subtract_into(a, b, out);
        wrap_components(out, &self.indices);
    }
}
