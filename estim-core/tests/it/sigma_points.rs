//! Evaluating all sigma points at once (`VectorFunction::eval_sigma_points_into`,
//! `ProcessModel::transition_sigma_points_into`, `MeasurementModel::measure_sigma_points_into`):
//!
//! - the unscented transform gives the same bits whether a function maps its points together or
//!   one by one, when both routes compute each point the same way;
//! - the linear models' one-product versions, c ± A Lⱼ, agree with their per-point values
//!   A (μ ± Lⱼ) (+ B u) within the round-off of the two routes (Higham: |fl(Σ aᵢbᵢ) − Σ aᵢbᵢ|
//!   ≤ γₖ Σ |aᵢbᵢ|, per side; the point μ ± Lⱼ itself rounds once more);
//! - a batch written in the wrong shape is a typed error, not a wrong answer.

use crate::common;

use common::*;
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1, U2, U3,
};
use estim_core::{
    Alloc, Error, LinearMeasurement, LinearProcess, MeasurementModel, MomentPropagator, Moments,
    Observation, ProcessModel, Quantity, SigmaScratch, Stage, Transition, Unscented,
    VectorFunction,
};

/// g(x) = A x + ε sin x (componentwise on the first m components), either evaluated one
/// point at a time by the trait's default `eval_sigma_points_into` (`together = false`) or in
/// its own `eval_sigma_points_into` by the same per-point code on the same points μ ± Lⱼ.
struct SineMap<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    a: OMatrix<f64, M, N>,
    together: bool,
}

impl<N: Dim, M: Dim> VectorFunction<f64, N, M> for SineMap<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<f64, N>) -> OVector<f64, M> {
        let mut y = &self.a * x;
        for (i, yi) in y.iter_mut().enumerate() {
            *yi += 0.1 * x[i].sin();
        }
        y
    }

    fn eval_sigma_points_into(
        &self,
        mean: &OVector<f64, N>,
        offsets: &OMatrix<f64, N, N>,
        plus: &mut OMatrix<f64, M, N>,
        minus: &mut OMatrix<f64, M, N>,
        scratch: &mut SigmaScratch<f64, N, M>,
    ) -> estim_core::error::Result<()> {
        if !self.together {
            return OneByOne(self).eval_sigma_points_into(mean, offsets, plus, minus, scratch);
        }
        for j in 0..offsets.ncols() {
            for (sign, out) in [(1.0, &mut *plus), (-1.0, &mut *minus)] {
                let point = mean.zip_map(&offsets.column(j), |mi, li| mi + sign * li);
                out.set_column(j, &self.eval(&point));
            }
        }
        Ok(())
    }
}

/// A function's values with the trait's default (one point at a time) sigma-point route.
struct OneByOne<'a, F>(&'a F);

impl<N: Dim, M: Dim, F: VectorFunction<f64, N, M>> VectorFunction<f64, N, M> for OneByOne<'_, F>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<f64, N>) -> OVector<f64, M> {
        self.0.eval(x)
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
    for ut in unscented_sets() {
        let one_by_one = SineMap::<N, M> {
            a: a.clone(),
            together: false,
        };
        let together = SineMap::<N, M> {
            a: a.clone(),
            together: true,
        };
        let (p, q) = (
            ut.propagate(&mu, &c, &one_by_one).expect("propagates"),
            ut.propagate(&mu, &c, &together).expect("propagates"),
        );
        assert_same_bits(&p, &q);
        assert!(p.mean.iter().all(|v| v.is_finite()), "{nv} → {mv}");
    }
}

#[test]
fn unscented_transform_is_the_same_one_by_one_or_together() {
    // (At static sizes the transform goes one by one either way: this checks that implementing
    // the method changes nothing there.)
    same_bits_both_routes(U3, U2);
    same_bits_both_routes(Dyn(9), Dyn(4));
    same_bits_both_routes(Dyn(1), Dyn(1));
}

/// Column j of `together` against `single(j)`, within `bound[:, j]` elementwise.
fn assert_columns_within(
    together: &DMatrix<f64>,
    single: impl Fn(usize) -> DVector<f64>,
    bound: &DMatrix<f64>,
) {
    for j in 0..together.ncols() {
        let y = single(j);
        for i in 0..together.nrows() {
            let gap = (together[(i, j)] - y[i]).abs();
            assert!(
                gap <= bound[(i, j)],
                "({i}, {j}): {gap:e} > {:e}",
                bound[(i, j)]
            );
        }
    }
}

#[test]
fn linear_models_map_sigma_points_as_they_map_points() {
    let (n, p, m) = (11, 3, 5);
    let f = DMatrix::from_fn(n, n, |i, j| ((i * 13 + j * 7) as f64 * 0.37).sin());
    let b = DMatrix::from_fn(n, p, |i, j| ((i + 3 * j) as f64).cos());
    let h = DMatrix::from_fn(m, n, |i, j| ((i * 5 + j) as f64 * 0.21).cos());
    let process = LinearProcess {
        transition: f.clone(),
        input: b.clone(),
        noise: DMatrix::identity(n, n),
    };
    let sensor = LinearMeasurement {
        observation: h.clone(),
        noise: DMatrix::identity(m, m),
    };
    let u = DVector::from_fn(p, |i, _| 1.5 - i as f64);
    let mu = DVector::from_fn(n, |i, _| (i as f64 * 0.7).cos() * 3.0);
    let l = DMatrix::from_fn(n, n, |i, j| ((i * 3 + j * 11) as f64 * 0.13).sin() * 0.5);
    let point = |j: usize, sign: f64| mu.zip_map(&l.column(j), |mi, li| mi + sign * li);
    let ones = DMatrix::from_element(1, n, 1.0);
    // |A| (|μ| 1ᵀ + |L|) (+ |B| |u| 1ᵀ): the magnitude every element's sums run over.
    let magnitude =
        |a: &DMatrix<f64>, extra: DMatrix<f64>| abs(a) * (abs(&mu) * &ones + abs(&l)) + extra;
    let bu = abs(&b) * abs(&u) * &ones;
    // Per side: γ_{n+p+1} for a sum of n + p products of rounded points, and the centre's
    // extra addition; both sides round.
    let bound = |scale: DMatrix<f64>, k: usize| scale * (2.0 * gamma(k + 2));

    let (mut plus, mut minus) = (DMatrix::zeros(n, n), DMatrix::zeros(n, n));
    let mut scratch = SigmaScratch::new(Dyn(n), Dyn(n));
    let batch =
        process.transition_sigma_points_into(&mu, &l, &u, 0.1, &mut plus, &mut minus, &mut scratch);
    assert!(batch.is_ok());
    let (process_ref, u_ref, point_ref) = (&process, &u, &point);
    let single = move |sign: f64| {
        move |j: usize| {
            let mut y = DVector::zeros(n);
            process_ref.transition_into(&point_ref(j, sign), u_ref, 0.1, &mut y);
            y
        }
    };
    let x_bound = bound(magnitude(&f, bu.clone()), n + p);
    assert_columns_within(&plus, single(1.0), &x_bound);
    assert_columns_within(&minus, single(-1.0), &x_bound);
    // Through the adapter the unscented transform uses: the same values.
    let map = Transition::new(&process, &u, 0.1);
    let (mut plus2, mut minus2) = (DMatrix::zeros(n, n), DMatrix::zeros(n, n));
    assert!(
        map.eval_sigma_points_into(&mu, &l, &mut plus2, &mut minus2, &mut scratch)
            .is_ok()
    );
    assert_eq!((&plus2, &minus2), (&plus, &minus));
    // No inputs.
    let no_input = LinearProcess {
        transition: f.clone(),
        input: DMatrix::zeros(n, 0),
        noise: DMatrix::identity(n, n),
    };
    let none = DVector::zeros(0);
    let batch = no_input.transition_sigma_points_into(
        &mu,
        &l,
        &none,
        0.1,
        &mut plus,
        &mut minus,
        &mut scratch,
    );
    assert!(batch.is_ok());
    let f_bound = bound(magnitude(&f, DMatrix::zeros(n, n)), n);
    assert_columns_within(&plus, |j| &f * point(j, 1.0), &f_bound);
    assert_columns_within(&minus, |j| &f * point(j, -1.0), &f_bound);

    let (mut plus, mut minus) = (DMatrix::zeros(m, n), DMatrix::zeros(m, n));
    let mut scratch = SigmaScratch::new(Dyn(n), Dyn(m));
    assert!(
        sensor
            .measure_sigma_points_into(&mu, &l, &mut plus, &mut minus, &mut scratch)
            .is_ok()
    );
    let h_bound = bound(magnitude(&h, DMatrix::zeros(m, n)), n);
    assert_columns_within(&plus, |j| &h * point(j, 1.0), &h_bound);
    assert_columns_within(&minus, |j| &h * point(j, -1.0), &h_bound);
    let observation = Observation::new(&sensor);
    let (mut plus2, mut minus2) = (DMatrix::zeros(m, n), DMatrix::zeros(m, n));
    assert!(
        observation
            .eval_sigma_points_into(&mu, &l, &mut plus2, &mut minus2, &mut scratch)
            .is_ok()
    );
    assert_eq!((&plus2, &minus2), (&plus, &minus));

    // Shapes that do not fit: left to the per-point route, which reports them.
    let mut wrong = DMatrix::zeros(m + 1, n);
    let e = sensor.measure_sigma_points_into(&mu, &l, &mut wrong, &mut minus, &mut scratch);
    assert!(matches!(e, Err(Error::DimensionMismatch { .. })));
}

/// Claims to have mapped the points but leaves its outputs a row short.
struct ShortBatch;

impl VectorFunction<f64, Dyn, Dyn> for ShortBatch {
    fn eval(&self, x: &DVector<f64>) -> DVector<f64> {
        x.rows(0, 2).into_owned()
    }

    fn eval_sigma_points_into(
        &self,
        _: &DVector<f64>,
        offsets: &DMatrix<f64>,
        plus: &mut DMatrix<f64>,
        minus: &mut DMatrix<f64>,
        _: &mut SigmaScratch<f64, Dyn, Dyn>,
    ) -> estim_core::error::Result<()> {
        *plus = DMatrix::zeros(1, offsets.ncols());
        *minus = DMatrix::zeros(1, offsets.ncols());
        Ok(())
    }
}

#[test]
fn a_batch_of_the_wrong_shape_is_an_error() {
    let mu = DVector::from_vec(vec![0.1, 0.2, 0.3]);
    let c = DMatrix::identity(3, 3);
    let e = Unscented::default()
        .propagate(&mu, &c, &ShortBatch)
        .map(|_: Moments<f64, Dyn, Dyn>| ())
        .expect_err("the short batch is reported");
    assert_eq!(
        e,
        Error::DimensionMismatch {
            stage: Stage::Propagation,
            quantity: Quantity::FunctionValue,
            expected_rows: 2,
            expected_cols: 3,
            found_rows: 1,
            found_cols: 3,
        }
    );
    // And the workspace recovers: the same propagator with a well-behaved function works.
    let fine = SineMap::<Dyn, Dyn> {
        a: DMatrix::identity(2, 3),
        together: true,
    };
    assert!(Unscented::default().propagate(&mu, &c, &fine).is_ok());
}
