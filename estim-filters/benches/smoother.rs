//! The Rauch–Tung–Striebel backward pass against the forward filter it smooths: one
//! predict + update per step (`forward`) and the backward pass over the same 64 steps
//! (`backward`, `Rts::smooth` on the recorded pass; `backward_cross`,
//! `Rts::smooth_with_cross_covariances`, which adds the lag-one cross-covariances Pˢₖ₊₁ Gₖᵀ),
//! a linear Kalman filter on a stable n-state system with m = n/2 measured components: static
//! n = 6, runtime n = 50 and 200.
//!
//! Run: `cargo bench -p estim-filters-benches --bench smoother`; the figure is the ratio of the two
//! medians of each size (BENCHMARKS.md, "Smoother").

use std::hint::black_box;
use std::time::Duration;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use estim_core::nalgebra::{Const, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::smoother::Rts;
use estim_filters::{KalmanFilter, Predict, Update, UpdateReport};

const STEPS: usize = 64;

/// x⁺ = F x + b u + w with F = 0.98 I plus a small coupling to the next state, Q = 0.01 I;
/// z = the first m states + v, R = 0.1 I.
fn system<N: Dim, M: Dim>(n: N, m: M) -> (LinearProcess<f64, N, U1>, LinearMeasurement<f64, N, M>)
where
    DefaultAllocator: Alloc<N, M>,
{
    let process = LinearProcess::<f64, N, U1> {
        transition: OMatrix::from_fn_generic(n, n, |i, j| {
            if i == j {
                0.98
            } else if j == i + 1 {
                0.05
            } else {
                0.0
            }
        }),
        input: OMatrix::<f64, N, U1>::from_fn_generic(n, U1, |i, _| 0.1 / (1.0 + i as f64)),
        noise: OMatrix::identity_generic(n, n) * 0.01,
    };
    let sensor = LinearMeasurement {
        observation: OMatrix::from_fn_generic(m, n, |i, j| f64::from(i == j)),
        noise: OMatrix::identity_generic(m, m) * 0.1,
    };
    (process, sensor)
}

fn case<N: Dim, M: Dim>(c: &mut Criterion, name: &str, n: N, m: M)
where
    DefaultAllocator: Alloc<N, M>,
{
    let (process, sensor) = system(n, m);
    let prior = Gaussian::new(
        OVector::zeros_generic(n, U1),
        OMatrix::identity_generic(n, n),
    )
    .expect("valid prior");
    let inputs: Vec<OVector<f64, U1>> = (0..STEPS)
        .map(|k| OVector::<f64, U1>::new((k as f64 * 0.3).sin()))
        .collect();
    let zs: Vec<OVector<f64, M>> = (0..STEPS)
        .map(|k| OVector::from_fn_generic(m, U1, |i, _| ((k + i) as f64 * 0.7).cos()))
        .collect();
    let mut filter = KalmanFilter::new(prior);
    filter
        .prepare_predict(&process, &inputs[0], 1.0)
        .expect("sizes");
    let mut report = UpdateReport::zeros(m);
    filter.prepare_update(&sensor, &mut report).expect("sizes");

    // The recorded pass the backward benchmark smooths.
    let mut recorded = filter.clone();
    let mut rts = Rts::new();
    for k in 0..STEPS {
        rts.predict(&mut recorded, &process, &inputs[k], 1.0)
            .expect("predicts");
        recorded.update(&sensor, &zs[k]).expect("updates");
    }

    let mut group = c.benchmark_group(format!("smoother_{name}"));
    group.measurement_time(Duration::from_secs(3));
    group.bench_function("forward", |b| {
        b.iter_batched(
            || filter.clone(),
            |mut f| {
                for k in 0..STEPS {
                    f.predict(black_box(&process), &inputs[k], 1.0)
                        .expect("predicts");
                    black_box(f.update(black_box(&sensor), &zs[k]).expect("updates"));
                }
                f
            },
            BatchSize::SmallInput,
        )
    });
    group.bench_function("backward", |b| {
        b.iter(|| rts.smooth(black_box(&recorded)).expect("smooths"))
    });
    group.bench_function("backward_cross", |b| {
        b.iter(|| {
            rts.smooth_with_cross_covariances(black_box(&recorded))
                .expect("smooths")
        })
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    case(c, "n6_static", Const::<6>, Const::<3>);
    case(c, "n50", Dyn(50), Dyn(25));
    case(c, "n200", Dyn(200), Dyn(100));
}

criterion_group!(smoother, benches);
criterion_main!(smoother);
