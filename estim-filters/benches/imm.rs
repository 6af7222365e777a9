//! The IMM step against the sum of its modes' steps: one IMM predict + update (mixing, m mode
//! predictions and updates, Bayes' rule for μ, the combined estimate) against the same m
//! Kalman filters each predicting and updating alone with the same models and measurement.
//! Modes are constant-velocity models differing in their process noise (a `Vec` of
//! `KalmanFilter`s); static sizes n = 4 (planar position and velocity, position measured,
//! m = 2) and n = 6 (3-D, m = 3); 2 and 3 modes.
//!
//! Run: `cargo bench -p estim-filters-benches --bench imm`; the figure is the ratio of the
//! two medians of each group (issue 37's target: ≤ 1.3). Counted mode (see
//! `benches/common/mod.rs`): `IMM_BENCH_STEPS=<group>/<name>=<count>`, for
//! `valgrind --tool=callgrind --toggle-collect='*run_counted*' <binary> --bench`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use estim_core::nalgebra::{Const, DMatrix, DVector, DimName, OMatrix, OVector, U1};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::imm::Imm;
use estim_filters::{KalmanFilter, Predict, Update};

mod common;
use common::Steps;

/// Steps of the recorded trajectory (the harness resets the state after them).
const STEPS: usize = 64;
const DT: f64 = 0.1;

/// Constant velocity in `D` dimensions (state: D positions, then D velocities) with white
/// acceleration of intensity `q`; no input.
fn cv<const N: usize, const D: usize>(q: f64) -> LinearProcess<f64, Const<N>, U1> {
    LinearProcess {
        transition: OMatrix::from_fn_generic(Const::<N>, Const::<N>, |i, j| {
            f64::from(i == j) + if j == i + D { DT } else { 0.0 }
        }),
        input: OMatrix::zeros_generic(Const::<N>, U1),
        noise: OMatrix::from_fn_generic(Const::<N>, Const::<N>, |i, j| {
            let (a, b) = (i % D, j % D);
            if a != b {
                return 0.0;
            }
            q * match (i < D, j < D) {
                (true, true) => DT.powi(3) / 3.0,
                (false, false) => DT,
                _ => DT * DT / 2.0,
            }
        }),
    }
}

fn position<const N: usize, const D: usize>() -> LinearMeasurement<f64, Const<N>, Const<D>> {
    LinearMeasurement {
        observation: OMatrix::from_fn_generic(Const::<D>, Const::<N>, |i, j| f64::from(i == j)),
        noise: OMatrix::identity_generic(Const::<D>, Const::<D>) * 0.25,
    }
}

/// A target circling (deterministic), measured in position: STEPS measurements.
fn measurements<const D: usize>() -> Vec<OVector<f64, Const<D>>> {
    (0..STEPS)
        .map(|k| {
            let t = k as f64 * DT;
            OVector::from_fn_generic(Const::<D>, U1, |i, _| match i % 2 {
                0 => 10.0 * (0.3 * t + i as f64).sin(),
                _ => 10.0 * (0.3 * t + i as f64).cos(),
            })
        })
        .collect()
}

/// Π with `stay` on the diagonal and the rest spread evenly.
fn transition(m: usize, stay: f64) -> DMatrix<f64> {
    DMatrix::from_fn(m, m, |i, j| {
        if i == j {
            stay
        } else {
            (1.0 - stay) / (m - 1) as f64
        }
    })
}

fn case<const N: usize, const D: usize>(c: &mut Criterion, modes: usize)
where
    Const<N>: DimName,
{
    let name = format!("imm_{modes}modes_{N}state");
    let models: Vec<_> = [0.01, 1.0, 10.0][..modes]
        .iter()
        .map(|&q| cv::<N, D>(q))
        .collect();
    let sensor = position::<N, D>();
    let zs = measurements::<D>();
    let p0 = OMatrix::<f64, Const<N>, Const<N>>::identity() * 10.0;
    let prior = Gaussian::new(OVector::<f64, Const<N>>::zeros(), p0).expect("valid prior");
    let bank = vec![KalmanFilter::new(prior); modes];
    let u = OVector::<f64, U1>::zeros();
    let mut steps: Steps<'_, STEPS> =
        Steps::new(c.benchmark_group(&name), &name, "IMM_BENCH_STEPS");
    let imm = Imm::new(
        bank.clone(),
        transition(modes, 0.95),
        DVector::from_element(modes, 1.0 / modes as f64),
    )
    .expect("valid IMM");
    steps.bench("imm", &imm, |imm, k| {
        imm.predict_modes(&models, &u, DT).unwrap();
        imm.update_modes(&sensor, &zs[k]).unwrap().nis
    });
    steps.bench("modes", &bank, |bank, k| {
        let mut nis = 0.0;
        for (f, model) in bank.iter_mut().zip(&models) {
            f.predict(model, &u, DT).unwrap();
            nis += f.update(&sensor, &zs[k]).unwrap().nis;
        }
        black_box(nis)
    });
    steps.finish();
}

fn imm(c: &mut Criterion) {
    case::<4, 2>(c, 2);
    case::<4, 2>(c, 3);
    case::<6, 3>(c, 2);
    case::<6, 3>(c, 3);
}

criterion_group!(benches, imm);
criterion_main!(benches);
