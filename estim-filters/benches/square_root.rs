//! One predict + update step of the square-root filters against the Joseph-form filters of
//! the same name, on a linear stable system (so KF, EKF and UKF run the same model): 6 states /
//! 4 measurements with static sizes, and 20 / 10 and 50 / 20 with runtime sizes.
//!
//! Each filter keeps its state across iterations and takes the input and measurement of step
//! i of a recorded 64-step trajectory; after step 64 it is reset to the prior (the harness of
//! [`common`]). For profilers and instruction counts, set
//! `SQUARE_ROOT_BENCH_STEPS=<group>/<name>=<count>` to run one variant for `count` steps
//! outside criterion (`square_root_counted.sh` drives it under callgrind).
//!
//! Run with `cargo bench -p estim-filters-benches --bench square_root`.

mod common;

use common::Steps;
use criterion::{Criterion, criterion_group, criterion_main};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1, U4, U6};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::{Ekf, KalmanFilter, Predict, SrEkf, SrKalmanFilter, SrUkf, Ukf, Update};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const STEPS: usize = 64;

struct Problem<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U1>,
{
    process: LinearProcess<f64, N, U1>,
    sensor: LinearMeasurement<f64, N, M>,
    prior: Gaussian<f64, N>,
    inputs: Vec<OVector<f64, U1>>,
    measurements: Vec<OVector<f64, M>>,
}

fn matrix<R: Dim, C: Dim>(rng: &mut StdRng, r: R, c: C, scale: f64) -> OMatrix<f64, R, C>
where
    DefaultAllocator: estim_core::nalgebra::allocator::Allocator<R, C>,
{
    OMatrix::from_fn_generic(r, c, |_, _| scale * (rng.random::<f64>() - 0.5))
}

fn problem<N: Dim, M: Dim>(n: N, m: M) -> Problem<N, M>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U1>,
{
    let mut rng = StdRng::seed_from_u64(6);
    // F = 0.9 I + small coupling: stable.
    let transition =
        OMatrix::<f64, N, N>::identity_generic(n, n) * 0.9 + matrix(&mut rng, n, n, 0.1);
    let a = matrix(&mut rng, n, n, 0.3);
    let noise = &a * a.transpose() + OMatrix::identity_generic(n, n) * 0.01;
    let observation = matrix(&mut rng, m, n, 2.0);
    let b = matrix(&mut rng, m, m, 0.5);
    let r = &b * b.transpose() + OMatrix::identity_generic(m, m) * 0.05;
    let process = LinearProcess {
        transition,
        input: matrix(&mut rng, n, U1, 1.0),
        noise,
    };
    let sensor = LinearMeasurement {
        observation,
        noise: r,
    };
    let prior = Gaussian::new(
        OVector::zeros_generic(n, U1),
        OMatrix::identity_generic(n, n),
    )
    .unwrap();
    let mut x: OVector<f64, N> = OVector::zeros_generic(n, U1);
    let (mut inputs, mut measurements) = (Vec::new(), Vec::new());
    for _ in 0..STEPS {
        let u = matrix(&mut rng, U1, U1, 1.0);
        x = &process.transition * &x + &process.input * u + matrix(&mut rng, n, U1, 0.2);
        measurements.push(&sensor.observation * &x + matrix(&mut rng, m, U1, 0.2));
        inputs.push(u);
    }
    Problem {
        process,
        sensor,
        prior,
        inputs,
        measurements,
    }
}

fn bench_filter<N: Dim, M: Dim, F>(
    group: &mut Steps<'_, STEPS>,
    name: &str,
    p: &Problem<N, M>,
    make: impl Fn(Gaussian<f64, N>) -> F,
) where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U1>,
    F: Clone
        + Predict<f64, N, LinearProcess<f64, N, U1>>
        + Update<f64, N, M, LinearMeasurement<f64, N, M>>,
{
    group.bench(name, &make(p.prior.clone()), |filter, i| {
        filter.predict(&p.process, &p.inputs[i], 1.0).unwrap();
        filter.update(&p.sensor, &p.measurements[i]).unwrap().nis
    });
}

fn all<N: Dim, M: Dim>(c: &mut Criterion, name: &'static str, p: &Problem<N, M>)
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U1>,
{
    let mut group = Steps::new(c.benchmark_group(name), name, "SQUARE_ROOT_BENCH_STEPS");
    bench_filter(&mut group, "kf_joseph", p, KalmanFilter::new);
    bench_filter(&mut group, "kf_sqrt", p, SrKalmanFilter::new);
    bench_filter(&mut group, "ekf_joseph", p, Ekf::new);
    bench_filter(&mut group, "ekf_sqrt", p, SrEkf::new);
    bench_filter(&mut group, "ukf_joseph", p, Ukf::new);
    bench_filter(&mut group, "ukf_sqrt", p, SrUkf::new);
    group.finish();
}

fn benches(c: &mut Criterion) {
    use estim_core::nalgebra::Dyn;
    all(c, "static_6x4", &problem(U6, U4));
    all(c, "dyn_20x10", &problem(Dyn(20), Dyn(10)));
    all(c, "dyn_50x20", &problem(Dyn(50), Dyn(20)));
}

criterion_group! {
    name = square_root;
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(2));
    targets = benches
}
criterion_main!(square_root);
