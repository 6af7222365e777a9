//! Automatic derivatives: write a model once, generic over its scalar, and get its Jacobian and
//! Hessians exactly (to rounding) from dual numbers ([`num_dual`]).
//!
//! | you implement | [`AutoDiff`] then provides |
//! |---|---|
//! | [`AutoDiffProcess`]: f(x, u, Δt) for any [`AdScalar`], and Q | [`ProcessModel`], [`ProcessJacobian`], [`ProcessHessian`] |
//! | [`AutoDiffMeasurement`]: h(x) for any [`AdScalar`], and R | [`MeasurementModel`], [`MeasurementJacobian`], [`MeasurementHessian`] |
//! | [`AutoDiffFunction`]: g(x) for any [`AdScalar`] | [`VectorFunction`], [`Differentiable`], [`TwiceDifferentiable`] |
//!
//! so the same model runs in every filter, the second-order ones included; a filter never knows
//! whether a derivative was written or derived.
//!
//! **How.** Values run the function on `T` itself. The Jacobian J = ∂g/∂x takes n passes on
//! first-order duals a + b ε (ε² = 0): with xⱼ ← xⱼ + ε, g(x) = g + (∂g/∂xⱼ) ε, column j.
//! The Hessians take n(n+1)/2 passes on hyper-duals a + b ε₁ + c ε₂ + d ε₁ε₂: with
//! xᵢ ← xᵢ + ε₁ and xⱼ ← xⱼ + ε₂, the ε₁ε₂ part of gₖ is ∂²gₖ/∂xᵢ∂xⱼ, for every k at once.
//! The filters ask for Hₖ one component at a time, so the adapter computes all m Hessians on
//! the first request at a point and serves the others from a cache keyed by the point (the
//! state, and for a process the step and the input's [`InputKey`]). No finite difference
//! and no step size: the results are exact up to the rounding of the function's own arithmetic.
//!
//! Static (`Const`) and runtime (`Dyn`) sizes go through the same code; `T` is `f64` or `f32`.
//! A Hessian that is exactly zero at the point is reported as affine (`None`), which the
//! second-order propagators skip; a zero Hessian contributes nothing either way.
//!
//! **Writing the function.** Arithmetic with `D` and with `T` constants (`x[0] * dt`), the
//! elementary functions as methods of [`num_dual::DualNum`] (`x[0].sin()`, `.sqrt()`,
//! `.atan2(b)`, `.powi(2)`), `D::from(c)` for a `T` constant. Branches on values are allowed
//! (`x[0].re() > 0.0`); the derivative is that of the branch taken.
//!
//! ```
//! use estim_core::autodiff::{AdScalar, AutoDiff, AutoDiffProcess};
//! use estim_core::nalgebra::{Matrix2, Vector2};
//! use estim_core::{ProcessHessian, ProcessJacobian, ProcessModel};
//!
//! /// A pendulum: angle and rate, x⁺ = (θ + ω Δt, ω − g/l sin θ Δt).
//! struct Pendulum;
//! impl AutoDiffProcess<f64, estim_core::nalgebra::U2> for Pendulum {
//!     type Input = ();
//!     fn transition<D: AdScalar<f64>>(&self, x: &Vector2<D>, _: &(), dt: f64) -> Vector2<D> {
//!         Vector2::new(x[0] + x[1] * dt, x[1] - x[0].sin() * (9.81 * dt))
//!     }
//!     fn process_noise(&self, _: &Vector2<f64>, _: &(), dt: f64) -> Matrix2<f64> {
//!         Matrix2::identity() * (1e-4 * dt)
//!     }
//! }
//! let model = AutoDiff::new(Pendulum);
//! let (x, dt) = (Vector2::new(0.3, -0.1), 0.01);
//! let f = model.transition_jacobian(&x, &(), dt);
//! assert_eq!(f[(1, 0)], -(0.3f64).cos() * 9.81 * dt);
//! let h = model.transition_hessian(&x, &(), dt, 1).expect("sin θ is not affine");
//! assert_eq!(h[(0, 0)], (0.3f64).sin() * 9.81 * dt);
//! assert!(model.transition_hessian(&x, &(), dt, 0).is_none()); // θ + ω Δt is affine
//! ```

mod cache;
mod rotation;

use core::fmt;

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use num_dual::{Dual, DualNum, DualNumFloat, HyperDual};

use crate::alloc::Alloc;
use crate::function::{Differentiable, TwiceDifferentiable, VectorFunction};
use crate::model::{
    MeasurementHessian, MeasurementJacobian, MeasurementModel, ProcessHessian, ProcessJacobian,
    ProcessModel,
};
use crate::scalar::Real;

pub use cache::InputKey;
use cache::{HessianCache, Kind};
pub use rotation::{
    quaternion_conjugate, quaternion_lift, quaternion_product, quaternion_rotate, rotation_exp,
    rotation_matrix, so3_exp, so3_log,
};

/// The dual-number crate the adapter is built on, re-exported so users name the same version.
pub use num_dual;

/// A floating-point type the adapter differentiates in: `f64` or `f32`.
pub trait AdReal: Real + DualNumFloat + DualNum<Primitive = Self> {
    /// The value as an `f64`, exactly (the cache keys compare bits).
    fn widen(self) -> f64;
    /// Back from [`widen`](Self::widen), exactly.
    fn narrow(x: f64) -> Self;
}

impl AdReal for f64 {
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn widen(self) -> f64 {
        self
    }
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn narrow(x: f64) -> Self {
        x
    }
}

impl AdReal for f32 {
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn widen(self) -> f64 {
        f64::from(self)
    }
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn narrow(x: f64) -> Self {
        // Only values that came from `widen` come back: exact.
        x as f32
    }
}

/// The scalar a generic model function runs on: `T` itself (values), or a dual number over `T`
/// (derivatives). Every [`DualNum`] over `T` that is `Copy` qualifies.
pub trait AdScalar<T: AdReal>: DualNum<Primitive = T> + Copy {}

impl<T: AdReal, D: DualNum<Primitive = T> + Copy> AdScalar<T> for D {}

/// A process model written once, generic over the scalar: x⁺ = f(x, u, Δt) + w,
/// w ~ N(0, Q(x, u, Δt)). Wrap it in [`AutoDiff`] to use it in a filter.
pub trait AutoDiffProcess<T: AdReal, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The input (`()` for none). The second-order filters also need it to be an
    /// [`InputKey`] (implemented for `()`, scalars and nalgebra vectors/matrices).
    type Input;

    /// f(x, u, Δt), for any scalar `D` (values on `T`, derivatives on duals).
    fn transition<D: AdScalar<T>>(
        &self,
        x: &OVector<D, N>,
        u: &Self::Input,
        dt: T,
    ) -> OVector<D, N>;

    /// Q(x, u, Δt), written plainly.
    fn process_noise(&self, x: &OVector<T, N>, u: &Self::Input, dt: T) -> OMatrix<T, N, N>;
}

/// A measurement model written once, generic over the scalar: z = h(x) + v, v ~ N(0, R(x)).
/// Wrap it in [`AutoDiff`] to use it in a filter.
pub trait AutoDiffMeasurement<T: AdReal, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// h(x), for any scalar `D`.
    fn measure<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, M>;

    /// R(x), written plainly.
    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M>;

    /// The residual a ⊖ b into `out` (defaults to a − b; override for wrapping components),
    /// as in [`MeasurementModel::residual_into`] (whose default panics, as this one does, on
    /// `a` and `b` of different lengths).
    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        crate::manifold::subtract_into(a, b, out);
    }
}

/// A vector function g: ℝⁿ → ℝᵐ written once, generic over the scalar. Wrap it in
/// [`AutoDiff`] for a [`TwiceDifferentiable`] function (propagators, derivative checks).
pub trait AutoDiffFunction<T: AdReal, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// g(x), for any scalar `D`.
    fn eval<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, M>;

    /// The difference a ⊖ b of two outputs into `out` (defaults to a − b; override for
    /// outputs that wrap), as in [`VectorFunction::difference_into`] (whose default panics, as
    /// this one does, on `a` and `b` of different lengths).
    fn difference_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        crate::manifold::subtract_into(a, b, out);
    }
}

/// The adapter: implements the value, Jacobian and Hessian capabilities of a model written
/// once over [`AdScalar`] (see the `autodiff` module docs: what to implement, and how).
///
/// It owns the model (reach it with [`model`](Self::model); [`model_mut`](Self::model_mut)
/// clears the Hessian cache) and is `Send + Sync` when the model is.
pub struct AutoDiff<G> {
    model: G,
    cache: HessianCache,
}

impl<G> AutoDiff<G> {
    /// Wraps `model`.
    pub fn new(model: G) -> Self {
        Self {
            model,
            cache: HessianCache::default(),
        }
    }

    /// The wrapped model.
    pub fn model(&self) -> &G {
        &self.model
    }

    /// The wrapped model, mutably; clears the cached Hessians, which may depend on it.
    pub fn model_mut(&mut self) -> &mut G {
        self.cache.clear();
        &mut self.model
    }

    /// The wrapped model back.
    pub fn into_inner(self) -> G {
        self.model
    }
}

impl<G: Clone> Clone for AutoDiff<G> {
    /// A copy of the model with an empty cache.
    fn clone(&self) -> Self {
        Self::new(self.model.clone())
    }
}

impl<G: fmt::Debug> fmt::Debug for AutoDiff<G> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("AutoDiff")
            .field("model", &self.model)
            .finish_non_exhaustive()
    }
}

/// A function generic over the scalar, whichever of the three traits it came from.
trait GenericMap<T: AdReal, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn apply<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, M>;
}

/// f(·, u, Δt) of a process at a fixed input and step.
struct ProcessAt<'a, P, U, T>(&'a P, &'a U, T);

impl<T: AdReal, N: Dim, P: AutoDiffProcess<T, N>> GenericMap<T, N, N>
    for ProcessAt<'_, P, P::Input, T>
where
    DefaultAllocator: Alloc<N>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn apply<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, N> {
        self.0.transition(x, self.1, self.2)
    }
}

struct MeasurementAt<'a, H>(&'a H);

impl<T: AdReal, N: Dim, M: Dim, H: AutoDiffMeasurement<T, N, M>> GenericMap<T, N, M>
    for MeasurementAt<'_, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn apply<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, M> {
        self.0.measure(x)
    }
}

struct FunctionAt<'a, G>(&'a G);

impl<T: AdReal, N: Dim, M: Dim, G: AutoDiffFunction<T, N, M>> GenericMap<T, N, M>
    for FunctionAt<'_, G>
where
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn apply<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, M> {
        self.0.eval(x)
    }
}

/// J = ∂g/∂x into `out`, one first-order dual pass per column. A value of another length than
/// `out`'s rows leaves `out` with the value's length, for the caller's shape check.
fn jacobian_into<T, N, M, G>(g: &G, x: &OVector<T, N>, out: &mut OMatrix<T, M, N>)
where
    T: AdReal,
    N: Dim,
    M: Dim,
    G: GenericMap<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let mut xd: OVector<Dual<T>, N> = x.map(Dual::from_re);
    for j in 0..x.nrows() {
        xd[j].eps = T::one();
        let y = g.apply(&xd);
        xd[j].eps = T::zero();
        if y.nrows() != out.nrows() {
            *out = OMatrix::zeros_generic(y.shape_generic().0, x.shape_generic().0);
        }
        for (o, yi) in out.column_mut(j).iter_mut().zip(y.iter()) {
            *o = yi.eps;
        }
    }
}

/// The owned Jacobian (m × n, m the value's length).
fn jacobian<T, N, M, G>(g: &G, x: &OVector<T, N>) -> OMatrix<T, M, N>
where
    T: AdReal,
    N: Dim,
    M: Dim,
    G: GenericMap<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let y = g.apply(x);
    let mut out = OMatrix::zeros_generic(y.shape_generic().0, x.shape_generic().0);
    jacobian_into(g, x, &mut out);
    out
}

/// Every ∂²gₖ/∂xᵢ∂xⱼ (i ≤ j, mirrored) by hyper-dual passes, written straight into `values`
/// (Hₖ column-major at `k * n * n`, as `f64`). Returns m, the value's length; `values` holds
/// exactly m n² numbers.
fn all_hessians<T, N, M, G>(g: &G, x: &OVector<T, N>, values: &mut Vec<f64>) -> usize
where
    T: AdReal,
    N: Dim,
    M: Dim,
    G: GenericMap<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let n = x.nrows();
    let nn = n * n;
    if n == 0 {
        values.clear();
        return g.apply(x).nrows();
    }
    let mut xd: OVector<HyperDual<T>, N> = x.map(HyperDual::from_re);
    let mut m = 0;
    for i in 0..n {
        xd[i].eps1 = T::one();
        for j in i..n {
            xd[j].eps2 = T::one();
            let y = g.apply(&xd);
            xd[j].eps2 = T::zero();
            // One length check per pass, not per entry (a value whose length changes between
            // passes keeps the last pass's, as the shape check downstream expects). The buffer
            // is not cleared: the passes i ≤ j, mirrored, overwrite every entry.
            m = y.nrows();
            if values.len() < m * nn {
                values.resize(m * nn, 0.0);
            }
            for (h, yk) in values.chunks_exact_mut(nn).zip(y.iter()) {
                let v = yk.eps1eps2.widen();
                (h[j * n + i], h[i * n + j]) = (v, v);
            }
        }
        xd[i].eps1 = T::zero();
    }
    values.truncate(m * nn);
    m
}

impl<G> AutoDiff<G> {
    /// Hₖ at `x` (`None` when it is exactly zero) from the cache, computing all m Hessians at
    /// `x` when the key differs.
    fn cached_hessian<T, N, M, F>(
        &self,
        f: &F,
        kind: Kind,
        key: impl FnOnce(&mut Vec<f64>),
        x: &OVector<T, N>,
        k: usize,
    ) -> Option<OMatrix<T, N, N>>
    where
        T: AdReal,
        N: Dim,
        M: Dim,
        F: GenericMap<T, N, M>,
        DefaultAllocator: Alloc<N, M>,
    {
        let n = x.shape_generic().0;
        let mut out = OMatrix::zeros_generic(n, n);
        let fill_key = |buf: &mut Vec<f64>| {
            buf.extend(x.iter().map(|v| v.widen()));
            key(buf);
        };
        let all = |values: &mut Vec<f64>| all_hessians(f, x, values);
        // Slices, not nalgebra's strided iterator: this copy runs once per request.
        let write = |values: &[f64]| {
            for (o, v) in out.as_mut_slice().iter_mut().zip(values) {
                *o = T::narrow(*v);
            }
        };
        let written = self
            .cache
            .hessian_into(kind, fill_key, x.nrows(), all, k, write);
        written.then_some(out)
    }
}

impl<T: AdReal, N: Dim, P: AutoDiffProcess<T, N>> ProcessModel<T, N> for AutoDiff<P>
where
    DefaultAllocator: Alloc<N>,
{
    type Input = P::Input;

    fn transition(&self, x: &OVector<T, N>, u: &P::Input, dt: T) -> OVector<T, N> {
        self.model.transition(x, u, dt)
    }

    fn process_noise(&self, x: &OVector<T, N>, u: &P::Input, dt: T) -> OMatrix<T, N, N> {
        self.model.process_noise(x, u, dt)
    }
}

impl<T: AdReal, N: Dim, P: AutoDiffProcess<T, N>> ProcessJacobian<T, N> for AutoDiff<P>
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_jacobian(&self, x: &OVector<T, N>, u: &P::Input, dt: T) -> OMatrix<T, N, N> {
        jacobian(&ProcessAt(&self.model, u, dt), x)
    }
}

impl<T: AdReal, N: Dim, P: AutoDiffProcess<T, N, Input: InputKey>> ProcessHessian<T, N>
    for AutoDiff<P>
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_hessian(
        &self,
        x: &OVector<T, N>,
        u: &P::Input,
        dt: T,
        k: usize,
    ) -> Option<OMatrix<T, N, N>> {
        let key = |buf: &mut Vec<f64>| {
            buf.push(dt.widen());
            u.push_key(buf);
        };
        self.cached_hessian(&ProcessAt(&self.model, u, dt), Kind::Process, key, x, k)
    }
}

impl<T: AdReal, N: Dim, M: Dim, H: AutoDiffMeasurement<T, N, M>> MeasurementModel<T, N, M>
    for AutoDiff<H>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.model.measure(x)
    }

    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M> {
        self.model.measurement_noise(x)
    }

    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.residual_into(a, b, out);
    }
}

impl<T: AdReal, N: Dim, M: Dim, H: AutoDiffMeasurement<T, N, M>> MeasurementJacobian<T, N, M>
    for AutoDiff<H>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        jacobian(&MeasurementAt(&self.model), x)
    }
}

impl<T: AdReal, N: Dim, M: Dim, H: AutoDiffMeasurement<T, N, M>> MeasurementHessian<T, N, M>
    for AutoDiff<H>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        let h = MeasurementAt(&self.model);
        self.cached_hessian(&h, Kind::Measurement, |_| {}, x, k)
    }
}

impl<T: AdReal, N: Dim, M: Dim, G: AutoDiffFunction<T, N, M>> VectorFunction<T, N, M>
    for AutoDiff<G>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.model.eval(x)
    }

    fn difference_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.difference_into(a, b, out);
    }
}

impl<T: AdReal, N: Dim, M: Dim, G: AutoDiffFunction<T, N, M>> Differentiable<T, N, M>
    for AutoDiff<G>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        jacobian(&FunctionAt(&self.model), x)
    }
}

impl<T: AdReal, N: Dim, M: Dim, G: AutoDiffFunction<T, N, M>> TwiceDifferentiable<T, N, M>
    for AutoDiff<G>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.cached_hessian(&FunctionAt(&self.model), Kind::Function, |_| {}, x, k)
    }
}
