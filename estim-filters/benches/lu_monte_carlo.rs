//! Lu's Monte Carlo validation (§3.2; 5000 runs × 6000 steps, 151 slots) on estim's runner
//! against a hand-written Monte Carlo of the same filter and simulator.
//!
//! - `library`: what `examples/reproductions/lu_calibration.rs`'s `run_monte_carlo` runs: per
//!   run the seeded [`Simulator`] (with the shared [`AccelerationProfile`]) and [`LuFilter`]
//!   (estim's `KalmanFilter` on the error state), recording at t = 0 and at every GPS fix the
//!   estimate (error moments, mean P, NEES, orthogonality), the NIS and the residuals at 20 s
//!   and 30 s on a [`MonteCarlo`] runner (master seed 271);
//! - `hand`: the same simulator and seeds (identical inputs), a fixed-size nalgebra Kalman filter
//!   written out (Φ P Φᵀ + Q, gain through the 2 × 2 inverse, Joseph update) and the same
//!   statistics in fixed-size per-slot accumulators (Welford; Chan's merge between chunks);
//! - `runner`: the hand-written filter inside the library's runner, recording through the same
//!   [`Recorder`] calls as `library` (an `UpdateReport` filled by hand): `library` − `runner` is
//!   the cost of estim's filter step over the hand-written one, `runner` − `hand` that of the
//!   runner's recording;
//! - `check`: `library` and `hand` once (sequentially and on 2 threads), every statistic compared to round-off
//!   before any timing is quoted.
//!
//! `--threads 1` runs sequentially (`run_sequential`, a plain loop); `--threads T` ≥ 2 in a
//! rayon pool of T threads (`run_parallel`, 64 chunks on `par_iter`). `--runs N` (default
//! 5000). The process prints its wall time; CPU time comes from `perf stat` around it
//! (`estim-filters/benches/lu_monte_carlo_counted.sh`).
//!
//! `cargo build --release -p estim-filters-benches --features parallel --bench lu_monte_carlo`, then
//! `estim-filters/benches/lu_monte_carlo_counted.sh target/release/deps/lu_monte_carlo-<hash> 5`.

use std::time::Instant;

use estim::filters::monte_carlo::{EnsembleStats, MonteCarlo, Recorder, run_seed};
use estim::filters::{UpdateReport, ValidationError};
use estim::models::lu::{AccelerationProfile, FilterSettings, LuFilter, Scenario, Simulator};
use estim::nalgebra::{Matrix2, Matrix2x3, Matrix3, U2, Vector2, Vector3};
use rayon::prelude::*;

const SEED: u64 = 271;
const CHUNKS: usize = 64;

struct Setup {
    scenario: Scenario,
    settings: FilterSettings,
    profile: AccelerationProfile,
    runs: usize,
    slots: usize,
    pair: (usize, usize),
}

fn setup(runs: usize) -> Setup {
    let scenario = Scenario::paper();
    let settings = FilterSettings::consistent(&scenario);
    Setup {
        scenario,
        settings,
        profile: AccelerationProfile::new(&scenario).expect("valid scenario"),
        runs,
        slots: scenario.updates() + 1,
        pair: (scenario.update_index(20.0), scenario.update_index(30.0)),
    }
}

/// The library run: the realization of the example's `run_monte_carlo`, verbatim.
fn library(s: &Setup, threads: usize) -> EnsembleStats {
    let (scenario, settings) = (s.scenario, s.settings);
    let mc = MonteCarlo::new(s.runs, s.slots)
        .and_then(|m| m.with_seed(SEED).with_residual_pair(s.pair.0, s.pair.1))
        .expect("valid experiment");
    let profile = &s.profile;
    let realization = |_run: usize, seed: u64, rec: &mut Recorder| -> Result<(), ValidationError> {
        let mut sim = Simulator::with_profile(&scenario, seed, profile);
        let mut filter = LuFilter::new(&scenario, &settings)?;
        let truth = sim.truth().error_state(filter.mechanisation());
        rec.record_filter(0, &truth, filter.kalman())?;
        for _ in 0..scenario.steps {
            let acceleration = sim.accelerometer();
            filter.propagate(acceleration)?;
            if sim.gps_due() {
                let slot = sim.step_index() / scenario.gps_every;
                let z = sim.gps();
                let report = filter.update(&z)?;
                rec.record_innovation(slot, &report)?;
                rec.record_residual(slot, &report.innovation)?;
                let truth = sim.truth().error_state(filter.mechanisation());
                rec.record_filter(slot, &truth, filter.kalman())?;
            }
        }
        Ok(())
    };
    if threads <= 1 {
        mc.run_sequential(realization)
    } else {
        pool(threads).install(|| mc.run_parallel(realization))
    }
    .expect("consistent runs")
}

/// The hand-written filter of [`hand_chunk`] in the library's runner, with the recordings of
/// [`library`].
fn runner(s: &Setup, threads: usize) -> EnsembleStats {
    let sc = s.scenario;
    let mc = MonteCarlo::new(s.runs, s.slots)
        .and_then(|m| m.with_seed(SEED).with_residual_pair(s.pair.0, s.pair.1))
        .expect("valid experiment");
    let (phi, q, h, r) = matrices(s);
    let ln_2pi = (2.0 * std::f64::consts::PI).ln();
    let realization = |_run: usize, seed: u64, rec: &mut Recorder| -> Result<(), ValidationError> {
        let (phi, q, h, r) = (phi, q, h, r);
        let mut sim = Simulator::with_profile(&sc, seed, &s.profile);
        let (mut pc, mut vc) = (sc.position_mean, sc.velocity_mean);
        let mut x = Vector3::zeros();
        let mut p = s.settings.initial_covariance;
        let mut report = UpdateReport::zeros(U2);
        let truth = sim.truth();
        rec.record_estimate(
            0,
            &Vector3::new(truth.position - pc, truth.velocity - vc, truth.bias),
            &x,
            &p,
        )?;
        for _ in 0..sc.steps {
            let a = sim.accelerometer();
            x = phi * x;
            p = phi * p * phi.transpose() + q;
            pc += vc * sc.dt + 0.5 * a * sc.dt * sc.dt;
            vc += a * sc.dt;
            if sim.gps_due() {
                let slot = sim.step_index() / sc.gps_every;
                let z = sim.gps();
                let innovation = Vector2::new(z[0] - pc, z[1] - vc) - h * x;
                let cov = h * p * h.transpose() + r;
                let cov_inv = cov.try_inverse().expect("S invertible");
                let k = p * h.transpose() * cov_inv;
                x += k * innovation;
                let a_ = Matrix3::identity() - k * h;
                p = a_ * p * a_.transpose() + k * r * k.transpose();
                report.innovation = innovation;
                report.innovation_covariance = cov;
                report.nis = innovation.dot(&(cov_inv * innovation));
                report.log_likelihood = -0.5 * (report.nis + cov.determinant().ln() + 2.0 * ln_2pi);
                rec.record_innovation(slot, &report)?;
                rec.record_residual(slot, &report.innovation)?;
                let t = sim.truth();
                let truth = Vector3::new(t.position - pc, t.velocity - vc, t.bias);
                rec.record_estimate(slot, &truth, &x, &p)?;
            }
        }
        Ok(())
    };
    if threads <= 1 {
        mc.run_sequential(realization)
    } else {
        pool(threads).install(|| mc.run_parallel(realization))
    }
    .expect("consistent runs")
}

/// Φ, Q, H and R of the consistent filter.
fn matrices(s: &Setup) -> (Matrix3<f64>, Matrix3<f64>, Matrix2x3<f64>, Matrix2<f64>) {
    let sc = &s.scenario;
    let dt = sc.dt;
    let phi = Matrix3::new(1.0, dt, -0.5 * dt * dt, 0.0, 1.0, -dt, 0.0, 0.0, 1.0);
    let g = Vector3::new(0.5 * dt * dt, dt, 0.0);
    let q = g * g.transpose() * s.settings.accel_noise_variance;
    let h = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let r = Matrix2::new(sc.gps_position_variance, 0.0, 0.0, sc.gps_velocity_variance);
    (phi, q, h, r)
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
}

/// One slot's running moments, fixed size.
#[derive(Clone, Copy, Default)]
struct Slot {
    count: usize,
    mean_e: Vector3<f64>,
    mean_x: Vector3<f64>,
    c_ee: Matrix3<f64>,
    c_ex: Matrix3<f64>,
    m2_x: Vector3<f64>,
    sum_p: Matrix3<f64>,
    sum_nees: f64,
    nis_count: usize,
    sum_nis: f64,
    sum_ll: f64,
}

impl Slot {
    fn add(&mut self, e: &Vector3<f64>, x: &Vector3<f64>, p: &Matrix3<f64>, nees: f64) {
        self.count += 1;
        let k = self.count as f64;
        let (de, dx) = (e - self.mean_e, x - self.mean_x);
        self.mean_e += de / k;
        self.mean_x += dx / k;
        let f = (k - 1.0) / k;
        self.c_ee += de * de.transpose() * f;
        self.c_ex += de * dx.transpose() * f;
        self.m2_x += dx.component_mul(&dx) * f;
        self.sum_p += p;
        self.sum_nees += nees;
    }

    fn merge(&mut self, o: &Slot) {
        self.nis_count += o.nis_count;
        self.sum_nis += o.sum_nis;
        self.sum_ll += o.sum_ll;
        if o.count == 0 {
            return;
        }
        let (na, nb) = (self.count as f64, o.count as f64);
        self.count += o.count;
        let total = self.count as f64;
        let (de, dx) = (o.mean_e - self.mean_e, o.mean_x - self.mean_x);
        let f = na * nb / total;
        self.mean_e += de * (nb / total);
        self.mean_x += dx * (nb / total);
        self.c_ee += o.c_ee + de * de.transpose() * f;
        self.c_ex += o.c_ex + de * dx.transpose() * f;
        self.m2_x += o.m2_x + dx.component_mul(&dx) * f;
        self.sum_p += o.sum_p;
        self.sum_nees += o.sum_nees;
    }
}

/// Σ r(a) r(b)ᵀ and the squares.
#[derive(Clone, Copy, Default)]
struct Pair {
    count: usize,
    sum_ab: Matrix2<f64>,
    sum_a2: Vector2<f64>,
    sum_b2: Vector2<f64>,
}

struct Acc {
    slots: Vec<Slot>,
    pair: Pair,
}

/// The hand-written Monte Carlo of runs `range`, accumulated in run order.
fn hand_chunk(s: &Setup, range: std::ops::Range<usize>) -> Acc {
    let sc = &s.scenario;
    let dt = sc.dt;
    let (phi, q, h, r) = matrices(s);
    let ln_2pi = (2.0 * std::f64::consts::PI).ln();
    let mut acc = Acc {
        slots: vec![Slot::default(); s.slots],
        pair: Pair::default(),
    };
    let nees = |e: &Vector3<f64>, p: &Matrix3<f64>| {
        let l = p.cholesky().expect("P positive definite");
        e.dot(&l.solve(e))
    };
    for run in range {
        let mut sim = Simulator::with_profile(sc, run_seed(SEED, run), &s.profile);
        let (mut pc, mut vc) = (sc.position_mean, sc.velocity_mean);
        let mut x = Vector3::zeros();
        let mut p = s.settings.initial_covariance;
        let t = sim.truth();
        let e = Vector3::new(t.position - pc, t.velocity - vc, t.bias) - x;
        acc.slots[0].add(&e, &x, &p, nees(&e, &p));
        let mut ra = Vector2::zeros();
        for _ in 0..sc.steps {
            let a = sim.accelerometer();
            x = phi * x;
            p = phi * p * phi.transpose() + q;
            pc += vc * dt + 0.5 * a * dt * dt;
            vc += a * dt;
            if sim.gps_due() {
                let slot = sim.step_index() / sc.gps_every;
                let z = sim.gps();
                let innovation = Vector2::new(z[0] - pc, z[1] - vc) - h * x;
                let cov = h * p * h.transpose() + r;
                let cov_inv = cov.try_inverse().expect("S invertible");
                let k = p * h.transpose() * cov_inv;
                x += k * innovation;
                let a_ = Matrix3::identity() - k * h;
                p = a_ * p * a_.transpose() + k * r * k.transpose();
                let nis = innovation.dot(&(cov_inv * innovation));
                let sl = &mut acc.slots[slot];
                sl.nis_count += 1;
                sl.sum_nis += nis;
                sl.sum_ll += -0.5 * (nis + cov.determinant().ln() + 2.0 * ln_2pi);
                if slot == s.pair.0 {
                    ra = innovation;
                } else if slot == s.pair.1 {
                    let pr = &mut acc.pair;
                    pr.count += 1;
                    pr.sum_ab += ra * innovation.transpose();
                    pr.sum_a2 += ra.component_mul(&ra);
                    pr.sum_b2 += innovation.component_mul(&innovation);
                }
                let t = sim.truth();
                let e = Vector3::new(t.position - pc, t.velocity - vc, t.bias) - x;
                acc.slots[slot].add(&e, &x, &p, nees(&e, &p));
            }
        }
    }
    acc
}

fn merge(total: &mut Acc, chunk: &Acc) {
    for (a, b) in total.slots.iter_mut().zip(&chunk.slots) {
        a.merge(b);
    }
    let (a, b) = (&mut total.pair, &chunk.pair);
    a.count += b.count;
    a.sum_ab += b.sum_ab;
    a.sum_a2 += b.sum_a2;
    a.sum_b2 += b.sum_b2;
}

fn hand(s: &Setup, threads: usize) -> Acc {
    if threads <= 1 {
        return hand_chunk(s, 0..s.runs);
    }
    let k = CHUNKS.min(s.runs);
    let chunks: Vec<Acc> = pool(threads).install(|| {
        (0..k)
            .into_par_iter()
            .map(|c| hand_chunk(s, c * s.runs / k..(c + 1) * s.runs / k))
            .collect()
    });
    let mut total = Acc {
        slots: vec![Slot::default(); s.slots],
        pair: Pair::default(),
    };
    for c in &chunks {
        merge(&mut total, c);
    }
    total
}

/// The largest discrepancy between the two runs' statistics, each relative to the largest
/// magnitude of the statistic it belongs to (a matrix at one slot).
fn discrepancy(lib: &EnsembleStats, hand: &Acc) -> f64 {
    let mut worst: f64 = 0.0;
    let mut cmp = |a: &[f64], b: &[f64]| {
        assert_eq!(a.len(), b.len());
        let scale = a.iter().chain(b).fold(0.0f64, |m, v| m.max(v.abs()));
        for (x, y) in a.iter().zip(b) {
            let d = if scale > 0.0 {
                (x - y).abs() / scale
            } else {
                0.0
            };
            assert!(d.is_finite(), "non-finite statistic");
            worst = worst.max(d);
        }
    };
    for (stats, h) in lib.slots.iter().zip(&hand.slots) {
        let e = stats
            .estimate
            .as_ref()
            .expect("every slot records an estimate");
        let n = h.count as f64;
        assert_eq!(e.samples, h.count);
        cmp(e.mean_error.as_slice(), h.mean_e.as_slice());
        cmp(
            e.error_covariance.as_slice(),
            (h.c_ee / (n - 1.0)).as_slice(),
        );
        cmp(e.mean_covariance.as_slice(), (h.sum_p / n).as_slice());
        cmp(e.orthogonality.as_slice(), (h.c_ex / n).as_slice());
        cmp(
            e.estimate_variance.as_slice(),
            (h.m2_x / (n - 1.0)).as_slice(),
        );
        cmp(&[e.mean_nees], &[h.sum_nees / n]);
        match &stats.innovation {
            Some(i) => {
                assert_eq!(i.samples, h.nis_count);
                let m = h.nis_count as f64;
                cmp(&[i.mean_nis], &[h.sum_nis / m]);
                cmp(&[i.mean_log_likelihood], &[h.sum_ll / m]);
            }
            None => assert_eq!(h.nis_count, 0),
        }
    }
    let pair = &lib.residual_pairs[0];
    assert_eq!(pair.samples, hand.pair.count);
    cmp(
        pair.cross_correlation.as_slice(),
        (hand.pair.sum_ab / hand.pair.count as f64).as_slice(),
    );
    let normalized = Matrix2::from_fn(|i, j| {
        hand.pair.sum_ab[(i, j)] / (hand.pair.sum_a2[i] * hand.pair.sum_b2[j]).sqrt()
    });
    cmp(pair.normalized.as_slice(), normalized.as_slice());
    worst
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str, default: usize| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let (runs, threads) = (value("--runs", 5000), value("--threads", 1));
    let s = setup(runs);
    let mode = args
        .iter()
        .skip(1)
        .find(|a| ["library", "runner", "hand", "check"].contains(&a.as_str()))
        .map_or("check", String::as_str);
    let start = Instant::now();
    match mode {
        "library" => {
            let stats = library(&s, threads);
            std::hint::black_box(&stats);
        }
        "runner" => {
            let stats = runner(&s, threads);
            std::hint::black_box(&stats);
        }
        "hand" => {
            let acc = hand(&s, threads);
            std::hint::black_box(&acc.slots);
        }
        _ => {
            for t in [1, 2] {
                let h = hand(&s, t);
                for (name, stats) in [("library", library(&s, t)), ("runner", runner(&s, t))] {
                    let d = discrepancy(&stats, &h);
                    println!(
                        "check, {runs} runs, {t} thread(s): {name} against hand, largest relative difference {d:.1e}"
                    );
                    assert!(d < 1e-9, "{name} and hand-written statistics differ: {d:e}");
                }
            }
        }
    }
    println!(
        "{mode}: {runs} runs x {} steps, {threads} thread(s), wall_s {:.3}",
        s.scenario.steps,
        start.elapsed().as_secs_f64()
    );
}
