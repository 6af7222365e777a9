//! Vector functions y = g(x), ℝⁿ → ℝᵐ, one capability per trait.
//!
//! - [`VectorFunction`]: values g(x) (enough for the unscented and sampled propagators).
//! - [`Differentiable`]: adds the Jacobian J = ∂g/∂x (m × n) (linearised propagation).
//! - [`TwiceDifferentiable`]: adds the Hessian Hₖ = ∂²gₖ/∂x² (n × n) of each output
//!   component k (second-order propagation), where a component may be declared affine.
//! - [`AffineFunction`]: a marker for g(x) = J x + c, which linear-only algorithms require.
//!
//! Each trait has one required method. A propagator states in its bounds which level it needs,
//! so a function without Hessians fails at compile time when given to a second-order
//! propagator.
//!
//! **Allocation-free runtime sizes.** The methods return owned values, which for `Dyn` sizes
//! allocate. A function that should not allocate implements the one opt-in trait
//! [`InPlace`] and returns `Some(self)` from [`VectorFunction::in_place`]; the propagators
//! then write its values and derivatives into their own buffers through [`eval_into`],
//! [`jacobian_into`] and [`hessian_into`] (differences are written in place by every function:
//! [`VectorFunction::difference_into`]). Whatever is
//! written is shape-checked by the caller, so a wrong size is a typed error, not a wrong answer.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
pub use crate::in_place::InPlace;
use crate::manifold::{add_into, subtract_into};
use crate::scalar::Real;

/// y = g(x) from an `N`-dimensional to an `M`-dimensional space.
///
/// ```
/// use estim_core::VectorFunction;
/// use estim_core::nalgebra::{Const, Vector1, Vector2};
///
/// struct Norm2;
/// impl VectorFunction<f64, Const<2>, Const<1>> for Norm2 {
///     fn eval(&self, x: &Vector2<f64>) -> Vector1<f64> {
///         Vector1::new(x.norm_squared())
///     }
/// }
/// assert_eq!(Norm2.eval(&Vector2::new(3.0, 4.0))[0], 25.0);
/// ```
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a vector function from {N} to {M} components: implement `VectorFunction<{T}, {N}, {M}>` for it (y = g(x))",
    label = "not a `VectorFunction<{T}, {N}, {M}>`"
)]
pub trait VectorFunction<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// g(x).
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M>;

    /// The difference a ⊖ b of two outputs into `out`, used wherever outputs are subtracted
    /// (deviations from a mean, innovations). Defaults to a − b; override it for outputs that
    /// wrap, such as angles (see [`wrap_angle`](crate::wrap_angle)). Like ⊞, in place for
    /// every function: `out` arrives with the outputs' shape.
    ///
    /// # Panics
    ///
    /// The default, if `a` and `b` differ in length (the propagators check before they call).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn difference_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        subtract_into(a, b, out);
    }

    /// Whether both ⊞ are plain vector addition: lets the unscented propagator form μ ± Lⱼ and
    /// g(μ) + d̄ in one fused pass (a tenth of a static 3/2 UKF step). Only the library can say
    /// yes ([`VectorSpaces::NO`] is the one value outside estim-core): the state-space bridges
    /// [`Transition`](crate::Transition) and [`Observation`](crate::Observation) take it from
    /// their space ([`StateSpace::VECTOR`](crate::StateSpace::VECTOR)). A function of your own
    /// keeps the default, which is correct whatever its ⊞ (the points go through
    /// [`input_plus_into`](Self::input_plus_into)).
    #[doc(hidden)]
    const VECTOR_SPACES: VectorSpaces = VectorSpaces::NO;

    /// x ⊞ δ in the input space, into `out`: the point reached from x along the tangent δ
    /// (see [`StateSpace`](crate::StateSpace)). Sigma points are formed with it. Defaults to
    /// x + δ.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn input_plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        add_into(x, delta, out);
    }

    /// y ⊞ δ in the output space, into `out`: how a mean correction δ (the unscented mean of
    /// the deviations, a second-order bias) is applied to g(μ). Defaults to y + δ;
    /// [`difference_into`](Self::difference_into) is the matching ⊟.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn output_plus_into(&self, y: &OVector<T, M>, delta: &OVector<T, M>, out: &mut OVector<T, M>) {
        add_into(y, delta, out);
    }

    /// The opt-in buffer-writing form of this function ([`InPlace`]), for allocation-free
    /// propagation at runtime sizes: `Some(self)` from a function that implements it. The
    /// default, `None`, evaluates through the owned methods.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn in_place(&self) -> Option<&dyn InPlace<T, N, M>> {
        None
    }
}

/// Whether a function's ⊞ are plain vector addition ([`VectorFunction::VECTOR_SPACES`]): a
/// token that only estim-core can make true, so a function cannot claim it by mistake.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VectorSpaces(bool);

impl VectorSpaces {
    /// Not (known to be) plain addition: the safe value, and the default.
    pub const NO: Self = Self(false);

    /// From a state space's [`VECTOR`](crate::StateSpace::VECTOR).
    pub(crate) const fn of_space(vector: bool) -> Self {
        Self(vector)
    }

    /// `true` for plain addition.
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub const fn get(self) -> bool {
        self.0
    }
}

/// A [`VectorFunction`] with an analytic Jacobian.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no Jacobian: implement `Differentiable<{T}, {N}, {M}>` for it (J = ∂g/∂x; for a model: `ProcessJacobian` or `MeasurementJacobian`), or use the unscented propagator",
    label = "the linearised propagator needs `Differentiable<{T}, {N}, {M}>`"
)]
pub trait Differentiable<T: Real, N: Dim, M: Dim>: VectorFunction<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// J(x) = ∂g/∂x, an m × n matrix: row k is the gradient of gₖ.
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N>;
}

/// A [`Differentiable`] function with analytic Hessians.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no Hessians: implement `TwiceDifferentiable<{T}, {N}, {M}>` for it (∂²gₖ/∂x²; for a model: `ProcessHessian` or `MeasurementHessian`), or use a first-order propagator",
    label = "the second-order propagators need `TwiceDifferentiable<{T}, {N}, {M}>`"
)]
pub trait TwiceDifferentiable<T: Real, N: Dim, M: Dim>: Differentiable<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Hₖ(x) = ∂²gₖ/∂x², the symmetric n × n Hessian of output component `k` (0-based), or
    /// `None` when gₖ is affine in x (its Hessian is zero), so no work is spent on it.
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>>;
}

/// Marker: g is affine, g(x) = J x + c with a constant Jacobian J, so linearisation is exact.
/// Implement it only when that holds; it lets linear-only algorithms (the Kalman filter)
/// refuse nonlinear functions at compile time. It implies nothing about Hessians: a
/// second-order propagator still asks for [`TwiceDifferentiable`], whose `hessian` an affine
/// function implements as `None`.
pub trait AffineFunction<T: Real, N: Dim, M: Dim>: Differentiable<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
}

/// g(x) into `out`: in place for an [`InPlace`] function, else the owned value.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn eval_into<T, N, M, G>(g: &G, x: &OVector<T, N>, out: &mut OVector<T, M>)
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    match g.in_place() {
        Some(g) => g.value_into(x, &(), T::zero(), out),
        None => *out = g.eval(x),
    }
}

/// J(x) into `out`.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn jacobian_into<T, N, M, G>(g: &G, x: &OVector<T, N>, out: &mut OMatrix<T, M, N>)
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    match g.in_place() {
        Some(g) => g.jacobian_into(x, &(), T::zero(), out),
        None => *out = g.jacobian(x),
    }
}

/// Hₖ(x) into `out`, returned; `None` when gₖ is affine.
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn hessian_into<'o, T, N, M, G>(
    g: &G,
    x: &OVector<T, N>,
    k: usize,
    out: &'o mut OMatrix<T, N, N>,
) -> Option<&'o mut OMatrix<T, N, N>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    match g.in_place() {
        Some(g) => g.hessian_into(x, &(), T::zero(), k, out),
        None => {
            *out = g.hessian(x, k)?;
            Some(out)
        }
    }
}
