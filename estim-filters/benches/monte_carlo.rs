//! The Monte Carlo consistency runner on a 3-state linear system: 1000 runs × 1000 steps,
//! statistics recorded at every step (1000 slots: estimate, innovation), sequential and
//! parallel.
//!
//! The system is the Lu-style accelerometer/GPS calibration problem of the consistency tests:
//! x = (p, v, b), the accelerometer reading as input, GPS position and velocity measured every
//! step (Δt = 0.1 s), a linear Kalman filter. Each run draws x₀ from the prior and all noise
//! from `StdRng` seeded with the run's seed.
//!
//! Variants (group `monte_carlo_1000x1000`):
//!
//! - `baseline_no_recording`: the same 10⁶ simulation + KF steps in a plain sequential loop,
//!   nothing recorded — the cost of the work itself;
//! - `sequential`: [`MonteCarlo::run_sequential`], recording at every step;
//! - `parallel_1_thread`, `parallel_2_threads`: [`MonteCarlo::run_parallel`] in a rayon pool
//!   of that size (feature `parallel`; bit-identical to `sequential`).
//!
//! Run: `cargo bench -p estim-filters-benches --features parallel --bench monte_carlo`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use estim_core::nalgebra::{
    Matrix2, Matrix2x3, Matrix3, Matrix3x1, U1, U2, U3, Vector1, Vector2, Vector3,
};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::monte_carlo::{MonteCarlo, Recorder, run_seed};
use estim_filters::{Estimator, KalmanFilter, Predict, Update, ValidationError};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

const RUNS: usize = 1000;
const STEPS: usize = 1000;
const DT: f64 = 0.1;

struct System {
    process: LinearProcess<f64, U3, U1>,
    sensor: LinearMeasurement<f64, U3, U2>,
    prior: Gaussian<f64, U3>,
    lq: Matrix3<f64>,
    lr: Matrix2<f64>,
    lp: Matrix3<f64>,
}

fn system() -> System {
    let (sa, sb) = (0.05, 0.01);
    let q = Matrix3::new(
        DT.powi(3) / 3.0,
        DT * DT / 2.0,
        0.0,
        DT * DT / 2.0,
        DT,
        0.0,
        0.0,
        0.0,
        0.0,
    ) * (sa * sa)
        + Matrix3::from_diagonal(&Vector3::new(0.0, 0.0, sb * sb * DT));
    let r = Matrix2::from_diagonal(&Vector2::new(1.0, 0.01));
    let p0 = Matrix3::from_diagonal(&Vector3::new(100.0, 1.0, 0.01));
    let chol3 = |m: Matrix3<f64>| m.cholesky().expect("SPD").l();
    System {
        process: LinearProcess {
            transition: Matrix3::new(1.0, DT, -0.5 * DT * DT, 0.0, 1.0, -DT, 0.0, 0.0, 1.0),
            input: Matrix3x1::new(0.5 * DT * DT, DT, 0.0),
            noise: q,
        },
        sensor: LinearMeasurement {
            observation: Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
            noise: r,
        },
        prior: Gaussian::new(Vector3::zeros(), p0).expect("valid prior"),
        lq: chol3(q),
        lr: r.cholesky().expect("SPD").l(),
        lp: chol3(p0),
    }
}

/// One run; `on_step(k, truth, filter, report)` after each update.
fn simulate(
    sys: &System,
    seed: u64,
    mut on_step: impl FnMut(
        usize,
        &Vector3<f64>,
        &KalmanFilter<f64, U3>,
        &estim_filters::UpdateReport<f64, U2>,
    ) -> Result<(), ValidationError>,
) -> Result<(), ValidationError> {
    let mut rng = StdRng::seed_from_u64(seed);
    let n3 = |rng: &mut StdRng| Vector3::from_fn(|_, _| rng.sample(StandardNormal));
    let mut x = sys.prior.mean() + sys.lp * n3(&mut rng);
    let mut kf = KalmanFilter::new(sys.prior.clone());
    for k in 0..STEPS {
        let u = Vector1::new((0.05 * k as f64).sin());
        x = sys.process.transition * x + sys.process.input * u + sys.lq * n3(&mut rng);
        let v = Vector2::from_fn(|_, _| rng.sample(StandardNormal));
        let z = sys.sensor.observation * x + sys.lr * v;
        kf.predict(&sys.process, &u, DT)?;
        let report = kf.update(&sys.sensor, &z)?;
        on_step(k, &x, &kf, &report)?;
    }
    Ok(())
}

fn record(sys: &System, seed: u64, rec: &mut Recorder) -> Result<(), ValidationError> {
    simulate(sys, seed, |k, x, kf, report| {
        rec.record_innovation(k, report)?;
        rec.record_estimate(k, x, kf.state(), kf.covariance())
    })
}

fn bench(c: &mut Criterion) {
    let sys = system();
    let mc = MonteCarlo::new(RUNS, STEPS).expect("valid").with_seed(2026);
    let mut group = c.benchmark_group("monte_carlo_1000x1000");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(15));
    group.bench_function("baseline_no_recording", |b| {
        b.iter(|| {
            let mut sum = 0.0;
            for run in 0..RUNS {
                simulate(&sys, run_seed(2026, run), |_, x, kf, _| {
                    sum += x[0] - kf.state()[0];
                    Ok(())
                })
                .expect("run");
            }
            black_box(sum)
        })
    });
    group.bench_function("sequential", |b| {
        b.iter(|| {
            black_box(
                mc.run_sequential(|_, s, rec| record(&sys, s, rec))
                    .expect("runs"),
            )
        })
    });
    #[cfg(feature = "parallel")]
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let name = if threads == 1 {
            "parallel_1_thread".to_string()
        } else {
            format!("parallel_{threads}_threads")
        };
        group.bench_function(name, |b| {
            b.iter(|| {
                pool.install(|| {
                    black_box(
                        mc.run_parallel(|_, s, rec| record(&sys, s, rec))
                            .expect("runs"),
                    )
                })
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
