//! Particle-filter throughput: particle-steps per second (one step = predict + update of
//! every particle) at N = 10², 10³, 10⁴, 10⁵, for
//!
//! - `growth`: the univariate nonstationary growth model (Gordon, Salmond & Smith 1993),
//!   x⁺ = x/2 + 25 x/(1 + x²) + 8 cos(1.2 k) + w, Q = 10; z = x²/20 + v, R = 1;
//! - `tracker`: a 2-D constant-velocity target (4 states) read in range and bearing.
//!
//! Variants per model and N: `library_1t` and `library_2t` (the [`ParticleFilter`]'s
//! `predict` + `update` in a rayon pool of 1 or 2 threads; the pool matters only with the
//! `parallel` feature and N ≥ [`PARALLEL_MIN`]), and `hand` — a hand-written loop of the same
//! algorithm on one thread: the same counter-based streams, resampling every step by the same
//! systematic scheme, the same log-domain weights (one `exp` per particle, as the library) and weighted moments, specialised to the model
//! (no trait calls, no error checks, Q's factor and R's inverse computed once). The library
//! resamples every step too (`ResampleWhen::Always`), so both do the same work.
//!
//! Run: `cargo bench -p estim-filters-benches --features parallel --bench particle`
//! (add a filter such as `-- growth` to run one model). Throughput is reported per particle
//! (criterion's "elem/s" = particle-steps per second).

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use estim_core::nalgebra::{Cholesky, Matrix1, Matrix2, Matrix4, U1, U2, U4, Vector1};
use estim_core::nalgebra::{Vector2, Vector4};
use estim_core::rand::Rng;
use estim_core::{Gaussian, MeasurementModel, ProcessModel};
use estim_filters::particle::{
    PARALLEL_MIN, ParticleFilter, ParticleRng, Proposal, RESAMPLE, ResampleWhen, Resampling,
    resample,
};
use estim_filters::{Estimator, Predict, Update};
use rand_distr::{Distribution, StandardNormal};

const COUNTS: [usize; 4] = [100, 1_000, 10_000, 100_000];
const SEED: u64 = 11;
/// The readings cycle through this many simulated steps.
const STEPS: usize = 64;

/// The growth model's transition, with the step k as the input.
struct Growth;

impl ProcessModel<f64, U1> for Growth {
    type Input = f64;
    fn transition(&self, x: &Vector1<f64>, k: &f64, _: f64) -> Vector1<f64> {
        Vector1::new(growth(x[0], *k))
    }
    fn process_noise(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        Matrix1::new(10.0)
    }
}

#[inline(always)]
fn growth(x: f64, k: f64) -> f64 {
    x / 2.0 + 25.0 * x / (1.0 + x * x) + 8.0 * (1.2 * k).cos()
}

/// z = x²/20 + v, R = 1.
struct Square;

impl MeasurementModel<f64, U1, U1> for Square {
    fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(x[0] * x[0] / 20.0)
    }
    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(1.0)
    }
}

const DT: f64 = 1.0;

/// Constant velocity in 2-D, white acceleration of intensity 0.1.
struct ConstantVelocity;

fn cv_noise() -> Matrix4<f64> {
    let (d2, d3) = (DT * DT / 2.0, DT * DT * DT / 3.0);
    Matrix4::new(
        d3, 0.0, d2, 0.0, //
        0.0, d3, 0.0, d2, //
        d2, 0.0, DT, 0.0, //
        0.0, d2, 0.0, DT,
    ) * 0.1
}

impl ProcessModel<f64, U4> for ConstantVelocity {
    type Input = ();
    fn transition(&self, x: &Vector4<f64>, _: &(), dt: f64) -> Vector4<f64> {
        Vector4::new(x[0] + dt * x[2], x[1] + dt * x[3], x[2], x[3])
    }
    fn process_noise(&self, _: &Vector4<f64>, _: &(), _: f64) -> Matrix4<f64> {
        cv_noise()
    }
}

/// Range and bearing from the origin (σ = 0.5, 0.05 rad), the bearing residual wrapped.
struct RangeBearing;

const R_DIAG: [f64; 2] = [0.25, 0.0025];

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

impl MeasurementModel<f64, U4, U2> for RangeBearing {
    fn measure(&self, x: &Vector4<f64>) -> Vector2<f64> {
        Vector2::new(x[0].hypot(x[1]), x[1].atan2(x[0]))
    }
    fn measurement_noise(&self, _: &Vector4<f64>) -> Matrix2<f64> {
        Matrix2::new(R_DIAG[0], 0.0, 0.0, R_DIAG[1])
    }
    fn residual_into(&self, a: &Vector2<f64>, b: &Vector2<f64>, out: &mut Vector2<f64>) {
        *out = Vector2::new(a[0] - b[0], wrap(a[1] - b[1]));
    }
}

/// Growth readings (seeded): the model simulated from x₀ = 0.1.
fn growth_readings() -> Vec<f64> {
    let mut rng = ParticleRng::stream(99, 0, 0);
    let mut x: f64 = 0.1;
    (1..=STEPS)
        .map(|k| {
            let w: f64 = StandardNormal.sample(&mut rng);
            let v: f64 = StandardNormal.sample(&mut rng);
            x = growth(x, k as f64) + 10f64.sqrt() * w;
            x * x / 20.0 + v
        })
        .collect()
}

/// Tracker readings: a target from (10, 5) at (1, 0.1) per step, readings noise-free (the
/// throughput does not depend on the noise).
fn tracker_readings() -> Vec<Vector2<f64>> {
    (1..=STEPS)
        .map(|k| {
            let (x, y) = (10.0 + k as f64, 5.0 + 0.1 * k as f64);
            Vector2::new(x.hypot(y), y.atan2(x))
        })
        .collect()
}

/// The hand-written bootstrap filter: particles `x` (n × N column-major), normalised
/// log-weights and weights, the step counter; `propagate(x, k, normals, out)` and
/// `log_density(x, z)` are the model, specialised.
struct Hand<const D: usize> {
    x: Vec<f64>,
    next: Vec<f64>,
    log_w: Vec<f64>,
    w: Vec<f64>,
    ancestors: Vec<usize>,
    step: u64,
    mean: [f64; D],
    cov: [[f64; D]; D],
}

impl<const D: usize> Hand<D> {
    /// The library's initial cloud (streams (seed, 0, i), x = μ + S ε).
    fn new(count: usize, mean: [f64; D], factor: [[f64; D]; D]) -> Self {
        let mut x = vec![0.0; D * count];
        for i in 0..count {
            let mut rng = ParticleRng::stream(SEED, 0, i as u64);
            let e: [f64; D] = std::array::from_fn(|_| StandardNormal.sample(&mut rng));
            for r in 0..D {
                x[i * D + r] = mean[r] + (0..D).map(|c| factor[r][c] * e[c]).sum::<f64>();
            }
        }
        let lw = -(count as f64).ln();
        Self {
            next: x.clone(),
            x,
            log_w: vec![lw; count],
            w: vec![lw.exp(); count],
            ancestors: vec![0; count],
            step: 1,
            mean: [0.0; D],
            cov: [[0.0; D]; D],
        }
    }

    /// Resample (systematic, every step), propagate, weigh, normalise, moments.
    #[inline(always)]
    fn step(
        &mut self,
        propagate: impl Fn(&[f64], &[f64; D], &mut [f64]),
        log_density: impl Fn(&[f64]) -> f64,
    ) {
        let count = self.w.len();
        let mut rng = ParticleRng::stream(SEED, self.step, RESAMPLE);
        resample(
            Resampling::Systematic,
            &self.w,
            &mut rng,
            &mut self.ancestors,
        )
        .expect("normalised weights");
        for (j, &a) in self.ancestors.iter().enumerate() {
            let mut rng = ParticleRng::stream(SEED, self.step, j as u64);
            let e: [f64; D] = std::array::from_fn(|_| StandardNormal.sample(&mut rng));
            propagate(
                &self.x[a * D..a * D + D],
                &e,
                &mut self.next[j * D..j * D + D],
            );
        }
        std::mem::swap(&mut self.x, &mut self.next);
        self.step += 1;
        let uniform = -(count as f64).ln();
        let mut max = f64::NEG_INFINITY;
        for (i, lw) in self.log_w.iter_mut().enumerate() {
            *lw = uniform + log_density(&self.x[i * D..i * D + D]);
            max = max.max(*lw);
        }
        // One exp per particle: eᵢ = exp(ℓᵢ − max) kept, Wᵢ = eᵢ exp(max − total).
        let mut sum = 0.0;
        for (&lw, w) in self.log_w.iter().zip(&mut self.w) {
            *w = (lw - max).exp();
            sum += *w;
        }
        let total = max + sum.ln();
        let scale = (max - total).exp();
        for (lw, w) in self.log_w.iter_mut().zip(&mut self.w) {
            *lw -= total;
            *w *= scale;
        }
        self.mean = [0.0; D];
        for (i, &w) in self.w.iter().enumerate() {
            for r in 0..D {
                self.mean[r] += w * self.x[i * D + r];
            }
        }
        self.cov = [[0.0; D]; D];
        for (i, &w) in self.w.iter().enumerate() {
            let d: [f64; D] = std::array::from_fn(|r| self.x[i * D + r] - self.mean[r]);
            for c in 0..D {
                for r in 0..D {
                    self.cov[r][c] += w * d[r] * d[c];
                }
            }
        }
    }
}

fn pools() -> [(&'static str, rayon::ThreadPool); 2] {
    let pool = |k| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .expect("a rayon pool")
    };
    [("library_1t", pool(1)), ("library_2t", pool(2))]
}

fn bench_growth(c: &mut Criterion) {
    let zs = growth_readings();
    let mut group = c.benchmark_group("particle_growth");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(2));
    let prior = Gaussian::new(Vector1::new(0.1), Matrix1::new(2.0)).unwrap();
    for count in COUNTS {
        group.throughput(Throughput::Elements(count as u64));
        for (name, pool) in pools() {
            let mut pf = ParticleFilter::new(prior.clone(), count, SEED)
                .unwrap()
                .with_trigger(ResampleWhen::Always)
                .unwrap();
            let mut k = 0usize;
            group.bench_function(BenchmarkId::new(name, count), |b| {
                pool.install(|| {
                    b.iter(|| {
                        k += 1;
                        pf.predict(&Growth, &(k as f64), 1.0).unwrap();
                        pf.update(&Square, &Vector1::new(zs[k % STEPS])).unwrap();
                        black_box(pf.state()[0])
                    })
                })
            });
        }
        let mut hand = Hand::<1>::new(count, [0.1], [[2f64.sqrt()]]);
        let sq = 10f64.sqrt();
        let half_log_2pi = 0.5 * std::f64::consts::TAU.ln();
        let mut k = 0usize;
        group.bench_function(BenchmarkId::new("hand", count), |b| {
            b.iter(|| {
                k += 1;
                let (kf, z) = (k as f64, zs[k % STEPS]);
                hand.step(
                    |x, e, out| out[0] = growth(x[0], kf) + sq * e[0],
                    |x| {
                        let r = z - x[0] * x[0] / 20.0;
                        -0.5 * r * r - half_log_2pi
                    },
                );
                black_box(hand.mean[0])
            })
        });
    }
    group.finish();
}

fn bench_tracker(c: &mut Criterion) {
    let zs = tracker_readings();
    let mut group = c.benchmark_group("particle_tracker");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(2));
    let mean = Vector4::new(10.0, 5.0, 1.0, 0.0);
    let p0: Matrix4<f64> = Matrix4::from_diagonal(&Vector4::new(4.0, 4.0, 1.0, 1.0));
    let prior = Gaussian::new(mean, p0).unwrap();
    let lq = Cholesky::new(cv_noise()).unwrap().l();
    let lq: [[f64; 4]; 4] = std::array::from_fn(|r| std::array::from_fn(|c| lq[(r, c)]));
    let l0: [[f64; 4]; 4] = std::array::from_fn(|r| {
        std::array::from_fn(|c| if r == c { p0[(r, r)].sqrt() } else { 0.0 })
    });
    let half_log_det = std::f64::consts::TAU.ln() + 0.5 * (R_DIAG[0] * R_DIAG[1]).ln();
    for count in COUNTS {
        group.throughput(Throughput::Elements(count as u64));
        for (name, pool) in pools() {
            let mut pf = ParticleFilter::new(prior.clone(), count, SEED)
                .unwrap()
                .with_trigger(ResampleWhen::Always)
                .unwrap();
            let mut k = 0usize;
            group.bench_function(BenchmarkId::new(name, count), |b| {
                pool.install(|| {
                    b.iter(|| {
                        k += 1;
                        pf.predict(&ConstantVelocity, &(), DT).unwrap();
                        pf.update(&RangeBearing, &zs[k % STEPS]).unwrap();
                        black_box(pf.state()[0])
                    })
                })
            });
        }
        let mut hand = Hand::<4>::new(count, [10.0, 5.0, 1.0, 0.0], l0);
        let mut k = 0usize;
        group.bench_function(BenchmarkId::new("hand", count), |b| {
            b.iter(|| {
                k += 1;
                let z = zs[k % STEPS];
                hand.step(
                    |x, e, out| {
                        let f = [x[0] + DT * x[2], x[1] + DT * x[3], x[2], x[3]];
                        for r in 0..4 {
                            out[r] = f[r] + (0..=r).map(|c| lq[r][c] * e[c]).sum::<f64>();
                        }
                    },
                    |x| {
                        let r0 = z[0] - x[0].hypot(x[1]);
                        let r1 = wrap(z[1] - x[1].atan2(x[0]));
                        -0.5 * (r0 * r0 / R_DIAG[0] + r1 * r1 / R_DIAG[1]) - half_log_det
                    },
                );
                black_box(hand.mean[0])
            })
        });
    }
    group.finish();
}

/// The library and the hand-written loop compute the same filter: after 20 steps at N = 1000
/// their means agree to round-off (the same streams, resampling and arithmetic up to the
/// order of sums, so equal to ~1e-9 of the state scale), checked once before timing.
fn check_same_algorithm() {
    let zs = growth_readings();
    let prior = Gaussian::new(Vector1::new(0.1), Matrix1::new(2.0)).unwrap();
    let mut pf = ParticleFilter::new(prior, 1000, SEED)
        .unwrap()
        .with_trigger(ResampleWhen::Always)
        .unwrap();
    let mut hand = Hand::<1>::new(1000, [0.1], [[2f64.sqrt()]]);
    let sq = 10f64.sqrt();
    let half_log_2pi = 0.5 * std::f64::consts::TAU.ln();
    for k in 1..=20 {
        let (kf, z) = (k as f64, zs[k % STEPS]);
        pf.predict(&Growth, &kf, 1.0).unwrap();
        pf.update(&Square, &Vector1::new(z)).unwrap();
        hand.step(
            |x, e, out| out[0] = growth(x[0], kf) + sq * e[0],
            |x| {
                let r = z - x[0] * x[0] / 20.0;
                -0.5 * r * r - half_log_2pi
            },
        );
    }
    let scale = hand.cov[0][0].sqrt().max(1.0);
    assert!(
        (pf.state()[0] - hand.mean[0]).abs() <= 1e-9 * scale,
        "library {} vs hand-written {}",
        pf.state()[0],
        hand.mean[0]
    );
    let _ = PARALLEL_MIN;
}

/// q = p for the growth model: x⁺ = f(x, k) + √10 e drawn from the particle's stream, with
/// its log-density (the guided step with it is the bootstrap filter).
struct GrowthPrior;

impl Proposal<f64, U1, U1> for GrowthPrior {
    type Input = f64;
    fn propose<R: Rng + ?Sized>(
        &self,
        x: &Vector1<f64>,
        k: &f64,
        _: f64,
        _: &Vector1<f64>,
        rng: &mut R,
    ) -> (Vector1<f64>, f64) {
        let e: f64 = StandardNormal.sample(rng);
        let log_q = -0.5 * e * e - 0.5 * (std::f64::consts::TAU * 10.0).ln();
        (Vector1::new(growth(x[0], *k) + 10f64.sqrt() * e), log_q)
    }
}

/// Counted mode for callgrind: `PARTICLE_BENCH_STEPS=<variant>=<steps>[,<count>]` with
/// variant `library` (predict and update), `auxiliary` (the auxiliary step), `guided` (the
/// guided step with q = p) or `hand` runs that many growth-model steps at N = `count`
/// (default 1000) in [`run_counted`] and exits, e.g. `PARTICLE_BENCH_STEPS=library=50
/// valgrind --tool=callgrind --toggle-collect='*run_counted*' <binary> --bench`. The
/// difference of two step counts is the per-step cost without the setup.
fn counted() -> bool {
    let Ok(spec) = std::env::var("PARTICLE_BENCH_STEPS") else {
        return false;
    };
    let (variant, rest) = spec.split_once('=').expect("<variant>=<steps>[,<count>]");
    let (steps, count) = rest.split_once(',').unwrap_or((rest, "1000"));
    run_counted(
        variant,
        steps.parse().expect("a step count"),
        count.parse().expect("a particle count"),
    );
    true
}

#[inline(never)]
fn run_counted(variant: &str, steps: usize, count: usize) {
    let zs = growth_readings();
    let prior = Gaussian::new(Vector1::new(0.1), Matrix1::new(2.0)).unwrap();
    let mut pf = ParticleFilter::new(prior, count, SEED)
        .unwrap()
        .with_trigger(ResampleWhen::Always)
        .unwrap();
    let mut hand = Hand::<1>::new(count, [0.1], [[2f64.sqrt()]]);
    let sq = 10f64.sqrt();
    let half_log_2pi = 0.5 * std::f64::consts::TAU.ln();
    for k in 1..=steps {
        let (kf, z) = (k as f64, zs[k % STEPS]);
        let zv = Vector1::new(z);
        if variant == "library" {
            pf.predict(&Growth, &kf, 1.0).unwrap();
            pf.update(&Square, &zv).unwrap();
        } else if variant == "auxiliary" {
            pf.auxiliary_step(&Growth, &kf, 1.0, &Square, &zv).unwrap();
        } else if variant == "guided" {
            pf.guided_step(&Growth, &GrowthPrior, &kf, 1.0, &Square, &zv)
                .unwrap();
        } else {
            hand.step(
                |x, e, out| out[0] = growth(x[0], kf) + sq * e[0],
                |x| {
                    let r = z - x[0] * x[0] / 20.0;
                    -0.5 * r * r - half_log_2pi
                },
            );
        }
    }
    black_box((pf.state()[0], hand.mean[0]));
}

fn benches(c: &mut Criterion) {
    if counted() {
        return;
    }
    check_same_algorithm();
    bench_growth(c);
    bench_tracker(c);
}

criterion_group!(particle, benches);
criterion_main!(particle);
