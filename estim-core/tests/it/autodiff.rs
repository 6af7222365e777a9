//! The automatic-derivative adapter against analytic derivatives: the shared polynomial
//! ([`Quadratic`]) and trigonometric ([`TrigSum`]) test functions, written a second time
//! generically over the scalar, give the same Jacobians and Hessians in f64 and f32, static and
//! runtime sizes; the Hessian cache follows the input (also when it is changed in place) and
//! the model; the second-order propagator gives the same moments from either; a value of the
//! wrong length is a typed error.
//!
//! Tolerance (f64): AD and the hand-written formulas evaluate the same expressions in a
//! different order, so each entry differs by rounding only: at most γₖ times the sum of the
//! magnitudes of its terms, k ≲ 30 operations. With |x|, |coefficients| ≤ 2 and n ≤ 5 that sum
//! is ≲ 10³, so 30 ε · 10³ ≈ 7·10⁻¹² absolute: `1e-11 · max(1, |entry|)` (the relative
//! ~1e-12 of the issue for entries of order 10). A wrong derivative (a missing term) is O(1)
//! off. f32: the same bound with ε₃₂: 30 · 1.2·10⁻⁷ · 10³ ≈ 4·10⁻³ absolute, so
//! `5e-3 · max(1, |entry|)`.

use crate::common::*;
use estim_core::autodiff::{
    AdReal, AdScalar, AutoDiff, AutoDiffFunction, AutoDiffMeasurement, AutoDiffProcess,
};
use estim_core::nalgebra::{
    DefaultAllocator, Dim, Dyn, Matrix2, OMatrix, OVector, U1, U2, U3, Vector1, Vector2,
};
use estim_core::{
    Alloc, Differentiable, Error, MeasurementHessian, MeasurementJacobian, MeasurementModel,
    MomentPropagator, ProcessHessian, ProcessJacobian, ProcessModel, Quantity, SecondOrderGaussian,
    TwiceDifferentiable, VectorFunction,
};
use proptest::prelude::*;

/// f64 tolerance (see the module docs).
const TOL: f64 = 1e-11;
/// f32 tolerance (see the module docs).
const TOL_F32: f64 = 5e-3;

/// [`Quadratic`] again, generically: gₖ = xᵀQₖx + aₖᵀx + cₖ.
struct GenericQuadratic<T: AdReal, N: Dim, M: Dim>(Quadratic<T, N, M>)
where
    DefaultAllocator: Alloc<N, M>;

impl<T: AdReal, N: Dim, M: Dim> AutoDiffFunction<T, N, M> for GenericQuadratic<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, M> {
        let mut y: OVector<D, M> = self.0.c.map(D::from);
        y += self.0.a.map(D::from) * x;
        for (k, q) in self.0.q.iter().enumerate() {
            y[k] += x.dot(&(q.map(D::from) * x));
        }
        y
    }
}

/// [`TrigSum`] again, generically: gₖ = Σ (c₀ + bᵀx) cos(aᵀx + φ).
struct GenericTrig<T: AdReal, N: Dim, M: Dim>(TrigSum<T, N, M>)
where
    DefaultAllocator: Alloc<N, M>;

impl<T: AdReal, N: Dim, M: Dim> AutoDiffFunction<T, N, M> for GenericTrig<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval<D: AdScalar<T>>(&self, x: &OVector<D, N>) -> OVector<D, M> {
        OVector::from_fn_generic(self.0.m, U1, |k, _| {
            self.0.outputs[k].iter().fold(D::zero(), |s, t| {
                let u = x.dot(&t.b.map(D::from)) + t.c0;
                let psi = x.dot(&t.a.map(D::from)) + t.phase;
                s + u * psi.cos()
            })
        })
    }
}

/// Asserts |got − want| ≤ tol · max(1, |want|) entrywise.
fn assert_close<T: AdReal>(got: &[T], want: &[T], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let (g, w) = (g.widen(), w.widen());
        assert!(
            (g - w).abs() <= tol * w.abs().max(1.0),
            "{what}: entry {i}: AD {g} vs analytic {w}"
        );
    }
}

/// AD and analytic Jacobian and every Hessian of `analytic` at x agree; affine components
/// are `None` on both sides.
fn assert_same_derivatives<T, N, M, G, A>(
    ad: &AutoDiff<G>,
    analytic: &A,
    x: &OVector<T, N>,
    tol: f64,
) where
    T: AdReal,
    N: Dim,
    M: Dim,
    G: AutoDiffFunction<T, N, M>,
    A: TwiceDifferentiable<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    assert_close(
        (ad.eval(x)).as_slice(),
        (analytic.eval(x)).as_slice(),
        tol,
        "value",
    );
    assert_close(
        (ad.jacobian(x)).as_slice(),
        (analytic.jacobian(x)).as_slice(),
        tol,
        "jacobian",
    );
    let m = analytic.eval(x).nrows();
    for k in 0..m {
        match (ad.hessian(x, k), analytic.hessian(x, k)) {
            (Some(h), Some(want)) => {
                assert_close(h.as_slice(), want.as_slice(), tol, &format!("hessian {k}"))
            }
            (None, None) => {}
            (Some(h), None) => panic!("hessian {k}: AD {h} but analytic affine"),
            // A nonlinear component can have a zero Hessian at one point; AD then says None.
            (None, Some(want)) => assert_close(
                &vec![T::zero(); want.len()],
                want.as_slice(),
                tol,
                &format!("hessian {k} (AD: zero)"),
            ),
        }
    }
}

fn params(len: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-2.0..2.0f64, len)
}

proptest! {
    #![proptest_config(config(64, 0xad01))]

    #[test]
    fn quadratic_static_and_dynamic(p in params(3 * 3 * 2 + 2 * 3 + 2 + 3)) {
        let q = |k: usize| {
            let b = mat(U3, U3, &p[9 * k..9 * k + 9]);
            (b + b.transpose()) * 0.5
        };
        let f = Quadratic { q: vec![q(0), q(1)], a: mat(U2, U3, &p[18..24]), c: vector(U2, &p[24..26]) };
        let x = vector(U3, &p[26..29]);
        assert_same_derivatives(&AutoDiff::new(GenericQuadratic(f.clone())), &f, &x, TOL);
        // The same function on runtime sizes.
        let d = Quadratic {
            q: f.q.iter().map(|q| mat(Dyn(3), Dyn(3), q.as_slice())).collect(),
            a: mat(Dyn(2), Dyn(3), f.a.as_slice()),
            c: vector(Dyn(2), f.c.as_slice()),
        };
        let xd = vector(Dyn(3), x.as_slice());
        assert_same_derivatives(&AutoDiff::new(GenericQuadratic(d.clone())), &d, &xd, TOL);
        // f32.
        let f32 = f.to_f32();
        assert_same_derivatives(&AutoDiff::new(GenericQuadratic(f32.clone())), &f32, &to32(&x), TOL_F32);
    }

    #[test]
    fn trigonometric_static_and_dynamic(p in params(TrigSum::<f64, U3, U2>::random_len(3, 2) + 3)) {
        let len = TrigSum::<f64, U3, U2>::random_len(3, 2);
        let f = TrigSum::random(U3, U2, &p[..len]);
        let x = vector(U3, &p[len..]);
        assert_same_derivatives(&AutoDiff::new(GenericTrig(f.clone())), &f, &x, TOL);
        let d = TrigSum::random(Dyn(3), Dyn(2), &p[..len]);
        let xd = vector(Dyn(3), x.as_slice());
        assert_same_derivatives(&AutoDiff::new(GenericTrig(d.clone())), &d, &xd, TOL);
        let f32 = f.to_f32();
        assert_same_derivatives(&AutoDiff::new(GenericTrig(f32.clone())), &f32, &to32(&x), TOL_F32);
    }
}

#[test]
fn boje_products_function() {
    // x₀ cos x₁, sin x₀ cos x₁, x₂ sin x₁ + ½ x₀ (Boje's worked example), at a few points.
    let f = TrigSum::products(U3, U3);
    let ad = AutoDiff::new(GenericTrig(f.clone()));
    for x in [[0.3, -1.2, 2.0], [0.0, 0.0, 0.0], [-2.5, 3.0, -0.7]] {
        assert_same_derivatives(&ad, &f, &vector(U3, &x), TOL);
    }
}

/// x⁺ = (x₀ + u x₁² Δt, x₁): the Hessian of component 0 is 2 u Δt e₁e₁ᵀ, so it follows u.
struct InputScaled;

impl AutoDiffProcess<f64, U2> for InputScaled {
    type Input = f64;
    fn transition<D: AdScalar<f64>>(&self, x: &Vector2<D>, u: &f64, dt: f64) -> Vector2<D> {
        Vector2::new(x[0] + x[1] * x[1] * (*u * dt), x[1])
    }
    fn process_noise(&self, _: &Vector2<f64>, _: &f64, _: f64) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

#[test]
fn hessian_cache_follows_the_input_and_the_model() {
    let model = AutoDiff::new(InputScaled);
    let x = Vector2::new(0.0, 0.0);
    let mut u = 1.0;
    let h = |model: &AutoDiff<InputScaled>, u: &f64, dt: f64| {
        model.transition_hessian(&x, u, dt, 0).map(|h| h[(1, 1)])
    };
    assert_eq!(h(&model, &u, 0.5), Some(1.0));
    // The same variable changed in place, same state and step: the key sees the new value.
    u = 3.0;
    assert_eq!(h(&model, &u, 0.5), Some(3.0));
    assert_eq!(h(&model, &u, 0.25), Some(1.5));
    // Component 1 is affine; component 0 again is served from the cache, unchanged.
    assert!(model.transition_hessian(&x, &u, 0.25, 1).is_none());
    assert_eq!(h(&model, &u, 0.25), Some(1.5));
    // u = 0 makes component 0 affine at every point.
    assert_eq!(h(&model, &0.0, 0.25), None);
    // Jacobian: ∂f₀/∂x₁ = 2 u x₁ Δt.
    let j = model.transition_jacobian(&Vector2::new(1.0, 2.0), &u, 0.25);
    assert_eq!(j, Matrix2::new(1.0, 3.0, 0.0, 1.0));
}

/// h(x) = scale · x₀ x₁: a model whose parameter changes through `model_mut`.
#[derive(Clone, Debug)]
struct Scaled(f64);

impl AutoDiffMeasurement<f64, U2, U1> for Scaled {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector2<D>) -> Vector1<D> {
        Vector1::new(x[0] * x[1] * self.0)
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> OMatrix<f64, U1, U1> {
        OMatrix::<f64, U1, U1>::identity()
    }
}

/// h(x) = x₀, a heading: its residual wraps into (−π, π].
struct Heading;

impl AutoDiffMeasurement<f64, U2, U1> for Heading {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector2<D>) -> Vector1<D> {
        Vector1::new(x[0])
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> OMatrix<f64, U1, U1> {
        OMatrix::<f64, U1, U1>::identity()
    }
    fn residual_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
        *out = Vector1::new(estim_core::wrap_angle(a[0] - b[0]));
    }
}

/// g(x) = x₀ as a function whose outputs are angles.
struct Angle;

impl AutoDiffFunction<f64, U2, U1> for Angle {
    fn eval<D: AdScalar<f64>>(&self, x: &Vector2<D>) -> Vector1<D> {
        Vector1::new(x[0])
    }
    fn difference_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
        *out = Vector1::new(estim_core::wrap_angle(a[0] - b[0]));
    }
}

/// The adapter forwards the written-once model's residual and the function's ⊖, so angles
/// wrap through it.
#[test]
fn the_residual_and_the_difference_are_the_models() {
    let (a, b) = (Vector1::new(-3.1), Vector1::new(3.1));
    let wrapped = 2.0 * std::f64::consts::PI - 6.2;
    let mut r = Vector1::zeros();
    MeasurementModel::residual_into(&AutoDiff::new(Heading), &a, &b, &mut r);
    assert_eq!(r[0], estim_core::wrap_angle(-6.2));
    assert!((r[0] - wrapped).abs() < 1e-15);
    let mut d = Vector1::zeros();
    VectorFunction::difference_into(&AutoDiff::new(Angle), &a, &b, &mut d);
    assert_eq!(d, r);
}

#[test]
fn model_mut_clears_the_cache() {
    let mut model = AutoDiff::new(Scaled(2.0));
    let x = Vector2::new(1.0, -1.0);
    assert_eq!(model.measurement_hessian(&x, 0).unwrap()[(0, 1)], 2.0);
    model.model_mut().0 = 5.0;
    assert_eq!(model.measurement_hessian(&x, 0).unwrap()[(0, 1)], 5.0);
    let copy = model.clone();
    assert_eq!(copy.measurement_hessian(&x, 0).unwrap()[(1, 0)], 5.0);
    assert_eq!(
        model.measurement_jacobian(&x),
        OMatrix::<f64, U1, U2>::new(-5.0, 5.0)
    );
    assert!(model.measurement_hessian(&x, 1).is_none(), "no component 1");
}

#[test]
fn second_order_moments_agree_with_analytic() {
    // The Gaussian second-order propagator asks for Hessians in the order 0, 1, 0, 2, 0, 1, …:
    // every request served from the cache must be the right component.
    let p: Vec<f64> = (0..64)
        .map(|i| ((i * 37 % 23) as f64 / 11.5) - 1.0)
        .collect();
    let f = TrigSum::random(U3, U3, &p[..TrigSum::<f64, U3, U3>::random_len(3, 3)]);
    let ad = AutoDiff::new(GenericTrig(f.clone()));
    let mu = vector(U3, &[0.2, -0.4, 0.9]);
    let c = spd(U3, &p[..9], 0.3);
    let want = SecondOrderGaussian.propagate(&mu, &c, &f).unwrap();
    let got = SecondOrderGaussian.propagate(&mu, &c, &ad).unwrap();
    assert_close(got.mean.as_slice(), want.mean.as_slice(), TOL, "mean");
    assert_close(
        got.covariance.as_slice(),
        want.covariance.as_slice(),
        TOL,
        "covariance",
    );
    assert_close(
        got.cross_covariance.as_slice(),
        want.cross_covariance.as_slice(),
        TOL,
        "cross",
    );
}

/// A runtime-sized function that returns one component too many.
struct WrongLength;

impl AutoDiffFunction<f64, Dyn, Dyn> for WrongLength {
    fn eval<D: AdScalar<f64>>(&self, x: &OVector<D, Dyn>) -> OVector<D, Dyn> {
        OVector::<D, Dyn>::from_fn_generic(Dyn(x.nrows() + 1), U1, |i, _| x[i % x.nrows()] * x[0])
    }
}

#[test]
fn wrong_length_is_a_typed_error() {
    let g = AutoDiff::new(WrongLength);
    let mu = vector(Dyn(2), &[1.0, 2.0]);
    let c = OMatrix::<f64, Dyn, Dyn>::identity(2, 2);
    // The propagator is told m = 2 by the caller's buffers; the function returns 3.
    let mut out = estim_core::Moments::zeros(Dyn(2), Dyn(2));
    let mut ws = Default::default();
    let err = MomentPropagator::propagate_into(
        &SecondOrderGaussian,
        &mu,
        &c,
        &g,
        estim_core::Outputs::moments(&mut out),
        &mut ws,
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            Error::DimensionMismatch {
                quantity: Quantity::FunctionValue | Quantity::Jacobian,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn process_values_are_the_function_on_t() {
    let model = AutoDiff::new(InputScaled);
    let x = Vector2::new(1.0, 2.0);
    assert_eq!(model.transition(&x, &2.0, 0.5), Vector2::new(5.0, 2.0));
    assert_eq!(model.process_noise(&x, &2.0, 0.5), Matrix2::identity());
}

#[test]
fn derivative_checker_with_an_automatic_reference() {
    use estim_core::derivative::{Entry, compare_derivatives};
    let p: Vec<f64> = (0..40)
        .map(|i| ((i * 29 % 17) as f64 / 8.5) - 1.0)
        .collect();
    let len = TrigSum::<f64, U3, U2>::random_len(3, 2);
    let f = TrigSum::random(U3, U2, &p[..len]);
    let x = vector(U3, &[0.4, -0.3, 1.1]);
    let ad = AutoDiff::new(GenericTrig(f.clone()));
    // Correct analytic derivatives agree to rounding (see TOL).
    let report = compare_derivatives(&f, &ad, &x).unwrap();
    assert!(report.is_accurate(TOL), "{report}");
    // One coefficient of one term changed by 10⁻⁶: the reference now differs from the
    // analytic model, far above rounding, and the report names a Hessian or value entry of
    // component 1.
    let mut other = f.clone();
    other.outputs[1][0].a[2] += 1e-6;
    let report = compare_derivatives(&f, &AutoDiff::new(GenericTrig(other)), &x).unwrap();
    assert!(!report.is_accurate(1e-9), "{report}");
    let worst = report.worst_mixed.unwrap().entry;
    assert!(
        matches!(
            worst,
            Entry::Value { row: 1 }
                | Entry::Jacobian { row: 1, .. }
                | Entry::Hessian { component: 1, .. }
        ),
        "{worst:?}"
    );
}
