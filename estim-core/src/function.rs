//! Vector functions y = g(x), ℝⁿ → ℝᵐ, one capability per trait.
//!
//! - [`VectorFunction`]: values g(x) (enough for the unscented and sampled propagators).
//! - [`Differentiable`]: adds the Jacobian J = ∂g/∂x (m × n) (linearised propagation).
//! - [`TwiceDifferentiable`]: adds the Hessian Hₖ = ∂²gₖ/∂x² (n × n) of each output
//!   component k (second-order propagation), where a component may be declared affine.
//!
//! A propagator states in its bounds which level it needs, so a function without Hessians
//! fails at compile time when given to a second-order propagator.
//!
//! Every method also has an `_into` form that writes into a buffer the caller owns (already of
//! the right shape). By default it stores the owned result there, which for runtime (`Dyn`)
//! sizes allocates; implement the `_into` forms to make dynamic-size propagation, and the
//! filter steps built on it, allocation-free. Whatever they write is shape-checked by the
//! caller, so a wrong size is a typed error, not a wrong answer.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::alloc::Alloc;
use crate::scalar::Real;

/// y = g(x) from an `N`-dimensional to an `M`-dimensional space.
pub trait VectorFunction<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// g(x).
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M>;

    /// The difference a ⊖ b of two outputs, used wherever outputs are subtracted (deviations
    /// from a mean, innovations). Defaults to a − b; override it for outputs that wrap, such
    /// as angles, e.g. to return the difference wrapped into (−π, π].
    fn difference(&self, a: &OVector<T, M>, b: &OVector<T, M>) -> OVector<T, M> {
        a - b
    }

    /// [`eval`](Self::eval) into `out`.
    #[inline(always)]
    fn eval_into(&self, x: &OVector<T, N>, out: &mut OVector<T, M>) {
        *out = self.eval(x);
    }

    /// [`difference`](Self::difference) into `out`.
    #[inline(always)]
    fn difference_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        *out = self.difference(a, b);
    }

    /// g at the 2n points μ ± Lⱼ (Lⱼ the columns of the n × n `offsets`), all at once: g(μ + Lⱼ)
    /// into column j of `plus` and g(μ − Lⱼ) into column j of `minus` (both m × n). `true` if
    /// done; `false` (the default, nothing written) has the caller evaluate the points one by
    /// one through [`eval_into`](Self::eval_into). The unscented transform asks for its sigma
    /// points this way (offsets √c L) when the state size is a runtime one (`Dyn`; at static
    /// sizes it goes point by point, which measured faster there). Implement it when the points
    /// map together more cheaply: e.g. for g(x) = A x, A μ 1ᵀ ± A L with one matrix product A L
    /// for all 2n points ([`LinearProcess`](crate::LinearProcess) does this).
    #[inline(always)]
    fn eval_sigma_points_into(
        &self,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        plus: &mut OMatrix<T, M, N>,
        minus: &mut OMatrix<T, M, N>,
    ) -> bool {
        let _ = (mean, offsets, plus, minus);
        false
    }
}

/// A [`VectorFunction`] with an analytic Jacobian.
pub trait Differentiable<T: Real, N: Dim, M: Dim>: VectorFunction<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// J(x) = ∂g/∂x, an m × n matrix: row k is the gradient of gₖ.
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N>;

    /// [`jacobian`](Self::jacobian) into `out`.
    #[inline(always)]
    fn jacobian_into(&self, x: &OVector<T, N>, out: &mut OMatrix<T, M, N>) {
        *out = self.jacobian(x);
    }
}

/// A [`Differentiable`] function with analytic Hessians.
pub trait TwiceDifferentiable<T: Real, N: Dim, M: Dim>: Differentiable<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Hₖ(x) = ∂²gₖ/∂x², the symmetric n × n Hessian of output component `k` (0-based), or
    /// `None` when gₖ is affine in x (its Hessian is zero), so no work is spent on it.
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>>;

    /// [`hessian`](Self::hessian) into `out`: `true` if it wrote Hₖ, `false` if gₖ is affine
    /// (then `out` is unspecified).
    #[inline(always)]
    fn hessian_into(&self, x: &OVector<T, N>, k: usize, out: &mut OMatrix<T, N, N>) -> bool {
        match self.hessian(x, k) {
            Some(h) => {
                *out = h;
                true
            }
            None => false,
        }
    }
}

/// Marker: g is affine, g(x) = J x + c with a constant Jacobian J, so every propagator is exact
/// for it and its Hessians are zero. Implement it only when that holds; it lets linear-only
/// algorithms (the Kalman filter) refuse nonlinear functions at compile time.
pub trait AffineFunction<T: Real, N: Dim, M: Dim>: TwiceDifferentiable<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
}
