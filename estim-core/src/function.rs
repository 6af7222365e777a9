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
//! The provided `_into` methods write into a buffer the caller owns (already of the right
//! shape). By default they store the owned result there, which for runtime (`Dyn`) sizes
//! allocates; override them to make dynamic-size propagation, and the filter steps built on it,
//! allocation-free. Whatever they write is shape-checked by the caller, so a wrong size is a
//! typed error, not a wrong answer.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};

use crate::alloc::Alloc;
use crate::checks::ensure_shape;
use crate::error::{Quantity, Result, Stage};
use crate::manifold::add_into;
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
pub trait VectorFunction<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// g(x).
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M>;

    /// The difference a ⊖ b of two outputs, used wherever outputs are subtracted (deviations
    /// from a mean, innovations). Defaults to a − b; override it for outputs that wrap, such
    /// as angles (see [`wrap_angle`](crate::wrap_angle)).
    fn difference(&self, a: &OVector<T, M>, b: &OVector<T, M>) -> OVector<T, M> {
        a - b
    }

    /// `true` while [`input_plus_into`](Self::input_plus_into) and
    /// [`output_plus_into`](Self::output_plus_into) are their defaults, plain vector addition:
    /// the unscented propagator then forms μ ± Lⱼ and g(μ) + d̄ in one fused pass (a tenth of a
    /// static 3/2 UKF step). **Set it to `false` when you override either**; debug builds check
    /// that the fused pass agrees with [`input_plus_into`](Self::input_plus_into).
    const VECTOR_SPACES: bool = true;

    /// x ⊞ δ in the input space, into `out`: the point reached from x along the tangent δ
    /// (see [`StateSpace`](crate::StateSpace)). Sigma points are formed with it. Defaults to
    /// x + δ.
    #[inline(always)]
    fn input_plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        add_into(x, delta, out);
    }

    /// y ⊞ δ in the output space, into `out`: how a mean correction δ (the unscented mean of
    /// the deviations, a second-order bias) is applied to g(μ). Defaults to y + δ;
    /// [`difference`](Self::difference) is the matching ⊟.
    #[inline(always)]
    fn output_plus_into(&self, y: &OVector<T, M>, delta: &OVector<T, M>, out: &mut OVector<T, M>) {
        add_into(y, delta, out);
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

    /// g at the 2n sigma points μ ⊞ ±Lⱼ (Lⱼ the columns of the n × n `offsets`): g(μ ⊞ Lⱼ)
    /// into column j of `plus`, g(μ ⊞ (−Lⱼ)) into column j of `minus` (both m × n).
    ///
    /// The default forms the points with [`input_plus_into`](Self::input_plus_into) and maps
    /// them one at a time through [`eval_into`](Self::eval_into), using `scratch` for the
    /// tangent, the point and the value. Override it when the points map together
    /// more cheaply: for g(x) = A x, A μ 1ᵀ ± A L is one matrix product A L for all 2n points
    /// ([`LinearProcess`](crate::LinearProcess) does this). The unscented propagator calls it
    /// for runtime-sized states.
    ///
    /// Errors: a value whose length is not the number of rows of `plus`
    /// ([`DimensionMismatch`](crate::Error::DimensionMismatch), quantity `FunctionValue`).
    #[inline(always)]
    fn eval_sigma_points_into(
        &self,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        plus: &mut OMatrix<T, M, N>,
        minus: &mut OMatrix<T, M, N>,
        scratch: &mut SigmaScratch<T, N, M>,
    ) -> Result<()> {
        sigma_points_through(self, mean, offsets, plus, minus, scratch)
    }
}

/// The tangent, point and value buffers that [`VectorFunction::eval_sigma_points_into`]'s
/// default (one point at a time) works in. Created by the caller; an implementation that maps all
/// points at once ignores it.
///
/// ```
/// use estim_core::{SigmaScratch, VectorFunction};
/// use estim_core::nalgebra::{Const, Matrix2, Matrix1x2, Vector1, Vector2};
///
/// struct Sum;
/// impl VectorFunction<f64, Const<2>, Const<1>> for Sum {
///     fn eval(&self, x: &Vector2<f64>) -> Vector1<f64> {
///         Vector1::new(x.sum())
///     }
/// }
/// let (mut plus, mut minus) = (Matrix1x2::zeros(), Matrix1x2::zeros());
/// let mut scratch = SigmaScratch::new(Const::<2>, Const::<1>);
/// let offsets = Matrix2::identity();
/// Sum.eval_sigma_points_into(&Vector2::new(1.0, 2.0), &offsets, &mut plus, &mut minus, &mut scratch)?;
/// assert_eq!((plus, minus), (Matrix1x2::new(4.0, 4.0), Matrix1x2::new(2.0, 2.0)));
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct SigmaScratch<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    delta: OVector<T, N>,
    point: OVector<T, N>,
    value: OVector<T, M>,
}

impl<T: Real, N: Dim, M: Dim> SigmaScratch<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Buffers for a map from `n` to `m` dimensions.
    pub fn new(n: N, m: M) -> Self {
        Self {
            delta: OVector::zeros_generic(n, U1),
            point: OVector::zeros_generic(n, U1),
            value: OVector::zeros_generic(m, U1),
        }
    }
}

/// The 2n sigma points μ ⊞ ±Lⱼ, formed by `plus_into` (x, δ, out) and mapped one at a time by
/// `eval_into` into the columns of `plus` and `minus`: the default of every
/// `*_sigma_points_into` method. A value of the wrong length is a dimension error (quantity
/// `FunctionValue`, stage `Propagation`).
///
/// With x + δ for ⊞ this is the arithmetic of forming μ + Lⱼ and μ − Lⱼ directly: −Lⱼ is
/// exact, and μ + (−Lⱼ) is the IEEE result of μ − Lⱼ.
#[inline(always)]
pub(crate) fn sigma_points_one_by_one<T: Real, N: Dim, M: Dim>(
    mean: &OVector<T, N>,
    offsets: &OMatrix<T, N, N>,
    plus: &mut OMatrix<T, M, N>,
    minus: &mut OMatrix<T, M, N>,
    scratch: &mut SigmaScratch<T, N, M>,
    mut plus_into: impl FnMut(&OVector<T, N>, &OVector<T, N>, &mut OVector<T, N>),
    mut eval_into: impl FnMut(&OVector<T, N>, &mut OVector<T, M>),
) -> Result<()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = mean.nrows();
    let m = plus.nrows();
    if scratch.point.nrows() != n {
        scratch.point = mean.clone();
    }
    if scratch.delta.nrows() != n {
        scratch.delta = mean.clone();
    }
    for j in 0..n {
        let column = &offsets.as_slice()[j * n..(j + 1) * n];
        for (sign, values) in [(T::one(), &mut *plus), (-T::one(), &mut *minus)] {
            for (di, &li) in scratch.delta.as_mut_slice().iter_mut().zip(column) {
                *di = sign * li;
            }
            plus_into(mean, &scratch.delta, &mut scratch.point);
            eval_into(&scratch.point, &mut scratch.value);
            let stage = Stage::Propagation;
            ensure_shape(&scratch.value, m, 1, stage, Quantity::FunctionValue)?;
            values.as_mut_slice()[j * m..(j + 1) * m].copy_from_slice(scratch.value.as_slice());
        }
    }
    Ok(())
}

/// [`VectorFunction::eval_sigma_points_into`]'s default: g at μ ⊞ ±Lⱼ one point at a time,
/// through g's own ⊞ and value (also what a non-vector state space falls back to).
#[inline(always)]
pub(crate) fn sigma_points_through<T, N, M, G>(
    g: &G,
    mean: &OVector<T, N>,
    offsets: &OMatrix<T, N, N>,
    plus: &mut OMatrix<T, M, N>,
    minus: &mut OMatrix<T, M, N>,
    scratch: &mut SigmaScratch<T, N, M>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    sigma_points_one_by_one(
        mean,
        offsets,
        plus,
        minus,
        scratch,
        |x, delta, out| g.input_plus_into(x, delta, out),
        |x, y| g.eval_into(x, y),
    )
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
        store_hessian(self.hessian(x, k), out)
    }
}

/// Stores `Some(h)` into `out` (`true`); `None` leaves it (`false`).
#[inline(always)]
pub(crate) fn store_hessian<T: Real, N: Dim>(
    h: Option<OMatrix<T, N, N>>,
    out: &mut OMatrix<T, N, N>,
) -> bool
where
    DefaultAllocator: Alloc<N>,
{
    match h {
        Some(h) => {
            *out = h;
            true
        }
        None => false,
    }
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
