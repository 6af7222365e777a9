//! The opt-in buffer-writing route ([`InPlace`]):
//!
//! - the unscented and linearised transforms give the same bits whether a function writes its
//!   values in place or returns them, when both compute each value the same way;
//! - the linear models' in-place values, kernel products A x (+ B u), agree with the owned
//!   operator values within the round-off of the two summation orders (Higham:
//!   |fl(Σ aᵢbᵢ) − Σ aᵢbᵢ| ≤ γₖ Σ |aᵢbᵢ|, per side), and the bridges the propagators use
//!   (`Transition`, `Observation`) write exactly what the model writes;
//! - a value written in the wrong shape is a typed error, not a wrong answer.

use crate::common;

use common::*;
use estim_core::in_place::InPlace;
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1, U2, U3,
};
use estim_core::{
    Alloc, Differentiable, Error, LinearMeasurement, LinearProcess, Linearized, MeasurementModel,
    MomentPropagator, Moments, Observation, ProcessModel, Quantity, Stage, Transition, Unscented,
    VectorFunction,
};
use estim_core::{function, model};

/// g(x) = A x + ε sin x (componentwise on the first m components), returned by `eval` and,
/// when `in_place` is set, also written in place by the same code.
struct SineMap<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    a: OMatrix<f64, M, N>,
    in_place: bool,
}

impl<N: Dim, M: Dim> SineMap<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn write(&self, x: &OVector<f64, N>, y: &mut OVector<f64, M>) {
        y.copy_from(&(&self.a * x));
        for (i, yi) in y.iter_mut().enumerate() {
            *yi += 0.1 * x[i].sin();
        }
    }
}

impl<N: Dim, M: Dim> VectorFunction<f64, N, M> for SineMap<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<f64, N>) -> OVector<f64, M> {
        let mut y = OVector::zeros_generic(self.a.shape_generic().0, U1);
        self.write(x, &mut y);
        y
    }

    fn in_place(&self) -> Option<&dyn InPlace<f64, N, M>> {
        self.in_place.then_some(self as &dyn InPlace<f64, N, M>)
    }
}

impl<N: Dim, M: Dim> Differentiable<f64, N, M> for SineMap<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<f64, N>) -> OMatrix<f64, M, N> {
        let mut j = self.a.clone();
        for i in 0..j.nrows() {
            j[(i, i)] += 0.1 * x[i].cos();
        }
        j
    }
}

impl<N: Dim, M: Dim> InPlace<f64, N, M> for SineMap<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn value_into(&self, x: &OVector<f64, N>, _: &(), _: f64, out: &mut OVector<f64, M>) {
        self.write(x, out);
    }
    fn noise_into(&self, _: &OVector<f64, N>, _: &(), _: f64, _: &mut OMatrix<f64, M, M>) {}
    fn jacobian_into(&self, x: &OVector<f64, N>, _: &(), _: f64, out: &mut OMatrix<f64, M, N>) {
        out.copy_from(&self.jacobian(x));
    }
    fn hessian_into<'o>(
        &self,
        _: &OVector<f64, N>,
        _: &(),
        _: f64,
        _: usize,
        _: &'o mut OMatrix<f64, N, N>,
    ) -> Option<&'o mut OMatrix<f64, N, N>> {
        None
    }
}

fn unscented_sets() -> [Unscented<f64>; 3] {
    [
        Unscented::default(),
        Unscented::cubature(),
        Unscented::new(0.5, 2.0, 1.0).expect("valid parameters"),
    ]
}

fn assert_same_bits<N: Dim, M: Dim>(a: &Moments<f64, N, M>, b: &Moments<f64, N, M>)
where
    DefaultAllocator: Alloc<N, M>,
{
    let bits = |m: &Moments<f64, N, M>| -> Vec<u64> {
        m.mean
            .iter()
            .chain(m.covariance.iter())
            .chain(m.cross_covariance.iter())
            .map(|v| v.to_bits())
            .collect()
    };
    assert_eq!(bits(a), bits(b));
}

fn same_bits_both_routes<N: Dim, M: Dim>(n: N, m: M)
where
    DefaultAllocator: Alloc<N, M>,
{
    let (nv, mv) = (n.value(), m.value());
    let a = OMatrix::<f64, M, N>::from_fn_generic(m, n, |i, j| ((i * 7 + j * 3) as f64).sin());
    let mu = OVector::<f64, N>::from_fn_generic(n, U1, |i, _| 0.3 * i as f64 - 0.5);
    let entries: Vec<f64> = (0..nv * nv).map(|k| ((k * 5) as f64).cos()).collect();
    let c = spd(n, &entries, 0.2);
    let owned = SineMap::<N, M> {
        a: a.clone(),
        in_place: false,
    };
    let written = SineMap::<N, M> {
        a: a.clone(),
        in_place: true,
    };
    for ut in unscented_sets() {
        let (p, q) = (
            ut.propagate(&mu, &c, &owned).expect("propagates"),
            ut.propagate(&mu, &c, &written).expect("propagates"),
        );
        assert_same_bits(&p, &q);
        assert!(p.mean.iter().all(|v| v.is_finite()), "{nv} → {mv}");
    }
    let (p, q) = (
        Linearized.propagate(&mu, &c, &owned).expect("propagates"),
        Linearized.propagate(&mu, &c, &written).expect("propagates"),
    );
    assert_same_bits(&p, &q);
}

#[test]
fn transforms_are_the_same_in_place_or_owned() {
    same_bits_both_routes(U3, U2);
    same_bits_both_routes(Dyn(9), Dyn(4));
    same_bits_both_routes(Dyn(1), Dyn(1));
}

/// |a − b| ≤ bound elementwise.
fn assert_within(a: &DVector<f64>, b: &DVector<f64>, bound: &DVector<f64>) {
    for i in 0..a.nrows() {
        let gap = (a[i] - b[i]).abs();
        assert!(gap <= bound[i], "({i}): {gap:e} > {:e}", bound[i]);
    }
}

#[test]
fn linear_models_write_their_values_in_place() {
    let (n, p, m) = (11, 3, 5);
    let f = DMatrix::from_fn(n, n, |i, j| ((i * 13 + j * 7) as f64 * 0.37).sin());
    let b = DMatrix::from_fn(n, p, |i, j| ((i + 3 * j) as f64).cos());
    let h = DMatrix::from_fn(m, n, |i, j| ((i * 5 + j) as f64 * 0.21).cos());
    let process = LinearProcess {
        transition: f.clone(),
        input: b.clone(),
        noise: DMatrix::identity(n, n) * 0.5,
    };
    let sensor = LinearMeasurement {
        observation: h.clone(),
        noise: DMatrix::identity(m, m) * 0.25,
    };
    let u = DVector::from_fn(p, |i, _| 1.5 - i as f64);
    let x = DVector::from_fn(n, |i, _| (i as f64 * 0.7).cos() * 3.0);

    // F x + B u: two sums (n and p products, the second added to the first), each side;
    // |F| |x| + |B| |u| is the magnitude every element's sums run over.
    let mut y = DVector::zeros(n);
    model::transition_into(&process, &x, &u, 0.1, &mut y);
    let bound = (abs(&f) * abs(&x) + abs(&b) * abs(&u)) * (2.0 * gamma(n + p + 1));
    assert_within(&y, &process.transition(&x, &u, 0.1), &bound);
    // Through the bridge the propagators use: the same bits.
    let mut y2 = DVector::zeros(n);
    function::eval_into(&Transition::new(&process, &u, 0.1), &x, &mut y2);
    assert_eq!(y2, y);
    // Q and F are copied.
    let mut q = DMatrix::zeros(n, n);
    model::process_noise_into(&process, &x, &u, 0.1, &mut q);
    assert_eq!(q, process.noise);
    let mut j = DMatrix::zeros(n, n);
    function::jacobian_into(&Transition::new(&process, &u, 0.1), &x, &mut j);
    assert_eq!(j, f);

    // H x: n products, each side.
    let mut z = DVector::zeros(m);
    model::measure_into(&sensor, &x, &mut z);
    let bound = abs(&h) * abs(&x) * (2.0 * gamma(n));
    assert_within(&z, &sensor.measure(&x), &bound);
    let mut z2 = DVector::zeros(m);
    function::eval_into(&Observation::new(&sensor), &x, &mut z2);
    assert_eq!(z2, z);
    let mut r = DMatrix::zeros(m, m);
    model::measurement_noise_into(&sensor, &x, &mut r);
    assert_eq!(r, sensor.noise);
    let (mut d, half) = (DVector::zeros(m), z2.map(|v| v * 0.5));
    sensor.residual_into(&z, &half, &mut d);
    assert_eq!(d, &z - &half);
    // The offset adapter passes the route on.
    let offset = sensor.clone().with_offset(DVector::from_element(m, 0.5));
    let mut zo = DVector::zeros(m);
    model::measure_into(&offset, &x, &mut zo);
    assert_eq!(zo, z.add_scalar(0.5));
}

/// Writes its values a row short.
struct ShortValue;

impl VectorFunction<f64, Dyn, Dyn> for ShortValue {
    fn eval(&self, x: &DVector<f64>) -> DVector<f64> {
        x.rows(0, 2).into_owned()
    }

    fn in_place(&self) -> Option<&dyn InPlace<f64, Dyn, Dyn>> {
        Some(self)
    }
}

impl InPlace<f64, Dyn, Dyn> for ShortValue {
    fn value_into(&self, _: &DVector<f64>, _: &(), _: f64, out: &mut DVector<f64>) {
        *out = DVector::zeros(1);
    }
    fn noise_into(&self, _: &DVector<f64>, _: &(), _: f64, _: &mut DMatrix<f64>) {}
    fn jacobian_into(&self, _: &DVector<f64>, _: &(), _: f64, _: &mut DMatrix<f64>) {}
    fn hessian_into<'o>(
        &self,
        _: &DVector<f64>,
        _: &(),
        _: f64,
        _: usize,
        _: &'o mut DMatrix<f64>,
    ) -> Option<&'o mut DMatrix<f64>> {
        None
    }
}

#[test]
fn a_value_of_the_wrong_shape_is_an_error() {
    let mu = DVector::from_vec(vec![0.1, 0.2, 0.3]);
    let c = DMatrix::identity(3, 3);
    let e = Unscented::default()
        .propagate(&mu, &c, &ShortValue)
        .map(|_: Moments<f64, Dyn, Dyn>| ())
        .expect_err("the short value is reported");
    assert_eq!(
        e,
        Error::DimensionMismatch {
            stage: Stage::Propagation,
            quantity: Quantity::FunctionValue,
            expected_rows: 2,
            expected_cols: 1,
            found_rows: 1,
            found_cols: 1,
        }
    );
    // And the workspace recovers: the same propagator with a well-behaved function works.
    let fine = SineMap::<Dyn, Dyn> {
        a: DMatrix::identity(2, 3),
        in_place: true,
    };
    assert!(Unscented::default().propagate(&mu, &c, &fine).is_ok());
}
