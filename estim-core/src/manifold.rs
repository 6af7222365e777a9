//! The state's ⊞ and ⊟ (Hertzberg et al. 2013): filters on states that are not plain vectors.
//!
//! A Gaussian filter moves its estimate along tangent vectors: sigma points χ = μ ⊞ δ, the
//! update x⁺ = x ⊞ K ν, deviations χ ⊟ μ. For ℝⁿ these are + and −
//! ([`Euclidean`], the default everywhere). A state with an angle (a heading near ±π) needs a
//! ⊞ that wraps, or the estimate leaves (−π, π] and the deviations jump by 2π. Give such a
//! state its [`StateSpace`] and hand it to the filter (`GaussianFilter::with_state_space` in
//! estim-filters); the models and the propagators are unchanged.
//!
//! The rules a ⊞/⊟ pair must satisfy (near enough to x): x ⊞ 0 = x, (x ⊞ δ) ⊟ x = δ and
//! x ⊞ (y ⊟ x) = y. The tangent has the state's dimension N.
//!
//! Ready-made spaces: [`Euclidean`] (the default), [`WrappedAngles`] (components on the
//! circle, such as headings) and [`AttitudeError`] (a 3-dimensional attitude error about a
//! reference unit quaternion, [`AttitudeReference`]: the multiplicative error state that
//! gives a unit quaternion its 3-dimensional tangent, see [`attitude`]).

mod angles;
pub mod attitude;

pub use angles::WrappedAngles;
pub use attitude::{AttitudeError, AttitudeReference, so3_exp, so3_log};

use nalgebra::{DefaultAllocator, Dim, OVector, allocator::Allocator};

use crate::alloc::Alloc;
use crate::scalar::Real;

/// The state's ⊞ / ⊟ (x ⊞ δ moves x along tangent δ; a ⊟ b is the δ with b ⊞ δ = a), same
/// dimension N for state and tangent.
///
/// ```
/// use core::f64::consts::PI;
/// use estim_core::{StateSpace, wrap_angle};
/// use estim_core::nalgebra::{Const, Vector1};
///
/// /// A heading in (−π, π].
/// #[derive(Clone, Debug)]
/// struct Heading;
/// impl StateSpace<f64, Const<1>> for Heading {
///     fn plus_into(&self, x: &Vector1<f64>, delta: &Vector1<f64>, out: &mut Vector1<f64>) {
///         out[0] = wrap_angle(x[0] + delta[0]);
///     }
///     fn minus_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
///         out[0] = wrap_angle(a[0] - b[0]);
///     }
/// }
/// let (x, mut out) = (Vector1::new(PI - 0.1), Vector1::zeros());
/// Heading.plus_into(&x, &Vector1::new(0.3), &mut out);
/// assert!((out[0] - (-PI + 0.2)).abs() < 1e-12);
/// let mut d = Vector1::zeros();
/// Heading.minus_into(&out, &x, &mut d);
/// assert!((d[0] - 0.3).abs() < 1e-12);
/// ```
pub trait StateSpace<T: Real, N: Dim>: Clone + core::fmt::Debug
where
    DefaultAllocator: Alloc<N>,
{
    /// `true` only for plain vector addition and subtraction (the library's [`Euclidean`]):
    /// lets fused fast paths run that would bypass ⊞ (the unscented propagator's μ ± Lⱼ, the
    /// update's x + K ν). The default, `false`, is right for every space, only slower.
    const VECTOR: bool = false;

    /// out ← x ⊞ δ.
    fn plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>);

    /// out ← a ⊟ b.
    fn minus_into(&self, a: &OVector<T, N>, b: &OVector<T, N>, out: &mut OVector<T, N>);
}

/// ℝⁿ: x ⊞ δ = x + δ, a ⊟ b = a − b. The default state space of every filter.
///
/// ```
/// use estim_core::{Euclidean, StateSpace};
/// use estim_core::nalgebra::{Const, Vector2};
///
/// let (x, delta) = (Vector2::new(1.0, 2.0), Vector2::new(0.5, -1.0));
/// let mut y = Vector2::zeros();
/// Euclidean.plus_into(&x, &delta, &mut y);
/// assert_eq!(y, x + delta);
/// let mut d = Vector2::zeros();
/// Euclidean.minus_into(&y, &x, &mut d);
/// assert_eq!(d, delta);
/// assert!(<Euclidean as StateSpace<f64, Const<2>>>::VECTOR);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Euclidean;

impl<T: Real, N: Dim> StateSpace<T, N> for Euclidean
where
    DefaultAllocator: Alloc<N>,
{
    const VECTOR: bool = true;

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        add_into(x, delta, out);
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn minus_into(&self, a: &OVector<T, N>, b: &OVector<T, N>, out: &mut OVector<T, N>) {
        subtract_into(a, b, out);
    }
}

/// out ← x + δ without allocating (`out` takes x's shape if it differs): a copy, then `+=`,
/// which gives the same bits as adding δ to x in place.
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn add_into<T: Real, D: Dim>(
    x: &OVector<T, D>,
    delta: &OVector<T, D>,
    out: &mut OVector<T, D>,
) where
    DefaultAllocator: Allocator<D>,
{
    if out.shape() == x.shape() {
        crate::kernel::copy(out, x);
    } else {
        *out = x.clone();
    }
    *out += delta;
}

/// out ← a − b without allocating (`out` takes a's shape if it differs).
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn subtract_into<T: Real, D: Dim>(
    a: &OVector<T, D>,
    b: &OVector<T, D>,
    out: &mut OVector<T, D>,
) where
    DefaultAllocator: Alloc<D>,
{
    if out.shape() == a.shape() {
        crate::kernel::copy(out, a);
    } else {
        *out = a.clone();
    }
    *out -= b;
}
