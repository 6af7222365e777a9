//! When a Gaussian is not enough: two problems with multimodal posteriors, run by the EKF,
//! the UKF and the particle filters on the same models.
//!
//! **1. The univariate nonstationary growth model** (Gordon, Salmond & Smith 1993; Kitagawa
//! 1996):
//!
//! ```text
//! xₖ = xₖ₋₁/2 + 25 xₖ₋₁/(1 + xₖ₋₁²) + 8 cos(1.2 k) + wₖ,   wₖ ~ N(0, 10)
//! zₖ = xₖ²/20 + vₖ,                                      vₖ ~ N(0, 1),   x₀ ~ N(0, 5)
//! ```
//!
//! z sees x², not its sign, so the posterior is bimodal whenever the dynamics do not settle the
//! sign. The EKF, the UKF, the bootstrap particle filter and the auxiliary particle filter
//! (1000 particles each) run on the same simulated readings; the RMSE of each filter's
//! posterior mean over every step of every run (200 runs × 50 steps, seeded; `--quick` 40 runs)
//! is the table. A figure shows, at the most bimodal step of run 0, the bootstrap filter's
//! weighted histogram beside the EKF's and UKF's Gaussians and the true state.
//!
//! **2. Range-only localisation from far away.** A robot drives with known odometry
//! (1 m/step in x, 0.2 m/step in y, process noise σ = 0.1 m) and measures its range to two
//! beacons at (0, 0) and (30, 0) (σ = 1 m). It starts at (5, 12); the filters are told
//! N((5, −12), 15² I): the mirror image across the beacons' line, 24 m away. The ranges cannot
//! tell the two sides apart at first; the odometry's y-motion (away from the line on the true
//! side, towards it on the mirror side) does, over a few steps. The EKF linearises at the
//! mirror and locks onto it. The particle filter (10 000 particles) keeps both hypotheses
//! until the motion kills the wrong one. The (cubature) UKF recovers too in this setting: its
//! sigma points at ±√2·15 m reach the true side. Reported: each filter's final position error
//! over 50 runs (`--quick` 10), 60 steps each.
//!
//! `--shard I/N --out FILE` runs shard I of N of both Monte Carlos' runs and writes their
//! records to FILE; `--merge FILE...` merges the N files and prints what one process prints,
//! bit for bit (the figure's single run is run by the merge); `--stats FILE` writes the sums
//! over runs and the final errors exactly (`estim_reproductions::sharding`).
//!
//! `cargo run --release --example particle_growth [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

use estim::filters::particle::ParticleFilter;
use estim::nalgebra::{Matrix1, Matrix2, Matrix2x1, U1, U2, Vector1, Vector2};
use estim::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use crate::sharding::{self, Session};

/// Process noise variance Q, measurement noise variance R and prior variance of the growth
/// model.
pub const Q: f64 = 10.0;
/// Measurement noise variance.
pub const R: f64 = 1.0;
/// Prior variance (mean 0).
pub const PRIOR_VARIANCE: f64 = 5.0;
/// Particles per filter in the growth model.
pub const PARTICLES: usize = 1000;

/// The growth model's transition; the input is the step k.
pub struct Growth;

fn growth(x: f64, k: f64) -> f64 {
    x / 2.0 + 25.0 * x / (1.0 + x * x) + 8.0 * (1.2 * k).cos()
}

impl ProcessModel<f64, U1> for Growth {
    type Input = f64;
    fn transition(&self, x: &Vector1<f64>, k: &f64, _: f64) -> Vector1<f64> {
        Vector1::new(growth(x[0], *k))
    }
    fn process_noise(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        Matrix1::new(Q)
    }
}

impl ProcessJacobian<f64, U1> for Growth {
    fn transition_jacobian(&self, x: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        let x2 = x[0] * x[0];
        Matrix1::new(0.5 + 25.0 * (1.0 - x2) / ((1.0 + x2) * (1.0 + x2)))
    }
}

/// z = x²/20 + v.
pub struct Square;

impl MeasurementModel<f64, U1, U1> for Square {
    fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(x[0] * x[0] / 20.0)
    }
    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(R)
    }
}

impl MeasurementJacobian<f64, U1, U1> for Square {
    fn measurement_jacobian(&self, x: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(x[0] / 10.0)
    }
}

fn normal(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

/// The four filters of the comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// The extended Kalman filter.
    Ekf,
    /// The cubature unscented Kalman filter (sigma points at ±√(nP)).
    Ukf,
    /// The bootstrap particle filter.
    Bootstrap,
    /// The auxiliary particle filter.
    Auxiliary,
}

/// Every method, in table order.
pub const METHODS: [Method; 4] = [
    Method::Ekf,
    Method::Ukf,
    Method::Bootstrap,
    Method::Auxiliary,
];

/// One filter's estimates over a run: means, variances, and (particle filters) the weighted
/// cloud after each step.
#[derive(Default)]
pub struct Track {
    /// The posterior mean after each step.
    pub means: Vec<f64>,
    /// The posterior variance after each step.
    pub variances: Vec<f64>,
    /// The particles and their weights after each step (particle filters, if asked).
    pub clouds: Vec<(Vec<f64>, Vec<f64>)>,
    /// Steps whose update the filter refused (a typed error; the filter kept its prediction).
    pub refused: usize,
}

/// A simulated run: truth x₁..x_T and readings z₁..z_T.
pub fn simulate(steps: usize, rng: &mut StdRng) -> (Vec<f64>, Vec<f64>) {
    let mut x = PRIOR_VARIANCE.sqrt() * normal(rng);
    let (mut truth, mut zs) = (Vec::new(), Vec::new());
    for k in 1..=steps {
        x = growth(x, k as f64) + Q.sqrt() * normal(rng);
        truth.push(x);
        zs.push(x * x / 20.0 + R.sqrt() * normal(rng));
    }
    (truth, zs)
}

/// Runs `method` over the readings; `keep_clouds` records the particle clouds.
pub fn track(method: Method, zs: &[f64], seed: u64, keep_clouds: bool) -> Result<Track, Error> {
    let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(PRIOR_VARIANCE))?;
    let mut out = Track::default();
    let record = |f: &dyn Estimator<f64, U1>, out: &mut Track| {
        out.means.push(f.state()[0]);
        out.variances.push(f.covariance()[(0, 0)]);
    };
    match method {
        Method::Ekf | Method::Ukf => {
            let mut ekf = Ekf::new(prior.clone());
            let mut ukf = Ukf::with_propagator(prior, Unscented::cubature());
            for (k, &z) in zs.iter().enumerate() {
                let kf = (k + 1) as f64;
                let z = Vector1::new(z);
                let refused = if method == Method::Ekf {
                    ekf.predict(&Growth, &kf, 1.0)?;
                    ekf.update(&Square, &z).is_err()
                } else {
                    ukf.predict(&Growth, &kf, 1.0)?;
                    ukf.update(&Square, &z).is_err()
                };
                out.refused += usize::from(refused);
                if method == Method::Ekf {
                    record(&ekf, &mut out);
                } else {
                    record(&ukf, &mut out);
                }
            }
        }
        Method::Bootstrap | Method::Auxiliary => {
            let mut pf = ParticleFilter::new(prior, PARTICLES, seed)?;
            for (k, &z) in zs.iter().enumerate() {
                let kf = (k + 1) as f64;
                let z = Vector1::new(z);
                if method == Method::Bootstrap {
                    pf.predict(&Growth, &kf, 1.0)?;
                    pf.update(&Square, &z)?;
                } else {
                    pf.auxiliary_step(&Growth, &kf, 1.0, &Square, &z)?;
                }
                record(&pf, &mut out);
                if keep_clouds {
                    let mut w = Vec::new();
                    pf.weights_into(&mut w);
                    out.clouds
                        .push((pf.particles().iter().copied().collect(), w));
                }
            }
        }
    }
    Ok(out)
}

/// The growth-model comparison: RMSE per method over `runs` runs of `steps` steps, and the
/// number of refused updates.
pub struct GrowthSummary {
    /// RMSE of each method's posterior mean, in [`METHODS`] order.
    pub rmse: [f64; 4],
    /// Updates each method refused (typed errors), in [`METHODS`] order.
    pub refused: [usize; 4],
}

/// The growth-model Monte Carlo (runs seeded `seed + run`).
pub fn growth_comparison(
    runs: usize,
    steps: usize,
    seed: u64,
) -> Result<GrowthSummary, Box<dyn std::error::Error>> {
    Ok(sharding::whole(growth_comparison_in(
        runs,
        steps,
        seed,
        &Session::whole(),
    )?)?)
}

/// Run `run` of the growth-model Monte Carlo: per method (in [`METHODS`] order) the sum over
/// the steps of the squared error, then per method the refused updates.
fn growth_run(run: usize, steps: usize, seed: u64) -> Result<Vec<f64>, Error> {
    let mut rng = StdRng::seed_from_u64(seed.wrapping_add(run as u64));
    let (truth, zs) = simulate(steps, &mut rng);
    let mut record = vec![0.0; 2 * METHODS.len()];
    for (m, &method) in METHODS.iter().enumerate() {
        let t = track(method, &zs, seed ^ (run as u64) << 20, false)?;
        record[m] = t
            .means
            .iter()
            .zip(&truth)
            .map(|(e, x)| (e - x) * (e - x))
            .sum::<f64>();
        record[METHODS.len() + m] = t.refused as f64;
    }
    Ok(record)
}

/// [`growth_comparison`] in a sharding session (`--shard`/`--merge`): the runs' records
/// summed in run order, `None` in a shard.
pub fn growth_comparison_in(
    runs: usize,
    steps: usize,
    seed: u64,
    session: &Session,
) -> Result<Option<GrowthSummary>, Box<dyn std::error::Error>> {
    let Some(records) = session.records("growth", runs, |run| Ok(growth_run(run, steps, seed)?))?
    else {
        return Ok(None);
    };
    let mut sq = [0.0; 4];
    let mut refused = [0; 4];
    for record in &records {
        for m in 0..METHODS.len() {
            sq[m] += record[m];
            refused[m] += record[METHODS.len() + m] as usize;
        }
    }
    let mut flat = sq.to_vec();
    flat.extend(refused.map(|r| r as f64));
    session.summary("growth", &flat);
    let n = (runs * steps) as f64;
    Ok(Some(GrowthSummary {
        rmse: sq.map(|s| (s / n).sqrt()),
        refused,
    }))
}

/// The weight of the cloud on each side of zero: min(P(x < 0), P(x > 0)), 0.5 when the two
/// modes are equal.
pub fn bimodality(cloud: &(Vec<f64>, Vec<f64>)) -> f64 {
    let negative: f64 = cloud
        .0
        .iter()
        .zip(&cloud.1)
        .filter(|(x, _)| **x < 0.0)
        .map(|(_, w)| w)
        .sum();
    negative.min(1.0 - negative)
}

/// Range-only localisation: state (x, y), known odometry input (dx, dy) per step.
pub struct Odometry;

/// Process noise standard deviation per step, m.
pub const ODOMETRY_SIGMA: f64 = 0.1;
/// Range noise standard deviation, m.
pub const RANGE_SIGMA: f64 = 1.0;
/// The beacons.
pub const BEACONS: [[f64; 2]; 2] = [[0.0, 0.0], [30.0, 0.0]];
/// Particles of the localisation filter.
pub const LOCALISATION_PARTICLES: usize = 10_000;
/// The odometry per step.
pub const MOTION: [f64; 2] = [1.0, 0.2];

impl ProcessModel<f64, U2> for Odometry {
    type Input = Vector2<f64>;
    fn transition(&self, x: &Vector2<f64>, u: &Vector2<f64>, _: f64) -> Vector2<f64> {
        x + u
    }
    fn process_noise(&self, _: &Vector2<f64>, _: &Vector2<f64>, _: f64) -> Matrix2<f64> {
        Matrix2::identity() * (ODOMETRY_SIGMA * ODOMETRY_SIGMA)
    }
}

impl ProcessJacobian<f64, U2> for Odometry {
    fn transition_jacobian(&self, _: &Vector2<f64>, _: &Vector2<f64>, _: f64) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

/// The range to one beacon.
pub struct Range(pub [f64; 2]);

impl MeasurementModel<f64, U2, U1> for Range {
    fn measure(&self, x: &Vector2<f64>) -> Vector1<f64> {
        Vector1::new((x[0] - self.0[0]).hypot(x[1] - self.0[1]))
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> {
        Matrix1::new(RANGE_SIGMA * RANGE_SIGMA)
    }
}

impl MeasurementJacobian<f64, U2, U1> for Range {
    fn measurement_jacobian(&self, x: &Vector2<f64>) -> estim::nalgebra::Matrix1x2<f64> {
        let (dx, dy) = (x[0] - self.0[0], x[1] - self.0[1]);
        let r = dx.hypot(dy).max(1e-9);
        Matrix2x1::new(dx / r, dy / r).transpose()
    }
}

/// The final position errors of the EKF, the UKF and the bootstrap particle filter over
/// `runs` runs of `steps` steps.
pub fn localisation(
    runs: usize,
    steps: usize,
    seed: u64,
) -> Result<[Vec<f64>; 3], Box<dyn std::error::Error>> {
    Ok(sharding::whole(localisation_in(
        runs,
        steps,
        seed,
        &Session::whole(),
    )?)?)
}

/// Run `run` of the localisation: the final position errors of the EKF, the UKF and the
/// bootstrap particle filter.
fn localisation_run(run: usize, steps: usize, seed: u64) -> Result<Vec<f64>, Error> {
    let start = Vector2::new(5.0, 12.0);
    let told = Gaussian::new(Vector2::new(5.0, -12.0), Matrix2::identity() * 225.0)?;
    let u = Vector2::from(MOTION);
    let beacons = BEACONS.map(Range);
    let mut rng = StdRng::seed_from_u64(seed.wrapping_add(run as u64));
    let mut ekf = Ekf::new(told.clone());
    let mut ukf = Ukf::with_propagator(told.clone(), Unscented::cubature());
    let mut pf = ParticleFilter::new(
        told.clone(),
        LOCALISATION_PARTICLES,
        seed ^ (run as u64) << 20,
    )?;
    let mut x = start;
    for _ in 0..steps {
        x += u + Vector2::new(normal(&mut rng), normal(&mut rng)) * ODOMETRY_SIGMA;
        ekf.predict(&Odometry, &u, 1.0)?;
        ukf.predict(&Odometry, &u, 1.0)?;
        pf.predict(&Odometry, &u, 1.0)?;
        for b in &beacons {
            let z = b.measure(&x) + Vector1::new(RANGE_SIGMA * normal(&mut rng));
            // A refused update (typed error) leaves the filter as it was.
            let _ = ekf.update(b, &z);
            let _ = ukf.update(b, &z);
            pf.update(b, &z)?;
        }
    }
    Ok([ekf.state(), ukf.state(), pf.state()]
        .iter()
        .map(|f| (*f - x).norm())
        .collect())
}

/// [`localisation`] in a sharding session (`--shard`/`--merge`): the runs' errors in run
/// order, `None` in a shard.
pub fn localisation_in(
    runs: usize,
    steps: usize,
    seed: u64,
    session: &Session,
) -> Result<Option<[Vec<f64>; 3]>, Box<dyn std::error::Error>> {
    let records = session.records("localisation", runs, |run| {
        Ok(localisation_run(run, steps, seed)?)
    })?;
    let Some(records) = records else {
        return Ok(None);
    };
    let mut errors = [Vec::new(), Vec::new(), Vec::new()];
    for record in &records {
        for (e, d) in errors.iter_mut().zip(record) {
            e.push(*d);
        }
    }
    session.summary("localisation", &errors.concat());
    Ok(Some(errors))
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The figure: at the most bimodal step of run 0, the bootstrap filter's weighted histogram,
/// the EKF's and UKF's Gaussian densities and the truth.
fn figure(seed: u64, steps: usize) -> Result<(usize, f64), Box<dyn std::error::Error>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let (truth, zs) = simulate(steps, &mut rng);
    let pf = track(Method::Bootstrap, &zs, seed << 20, true)?;
    let ekf = track(Method::Ekf, &zs, 0, false)?;
    let ukf = track(Method::Ukf, &zs, 0, false)?;
    let (k, score) = pf
        .clouds
        .iter()
        .map(bimodality)
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 0.0));
    let (lo, hi, bins) = (-30.0, 30.0, 60);
    let width = (hi - lo) / bins as f64;
    let mut density = vec![0.0; bins];
    for (x, w) in pf.clouds[k].0.iter().zip(&pf.clouds[k].1) {
        let b = ((x - lo) / width).floor();
        if (0.0..bins as f64).contains(&b) {
            density[b as usize] += w / width;
        }
    }
    // The histogram as a step line.
    let mut hist = Vec::new();
    for (b, d) in density.iter().enumerate() {
        let left = lo + b as f64 * width;
        hist.push((left, *d));
        hist.push((left + width, *d));
    }
    let gaussian = |m: f64, v: f64| -> Vec<(f64, f64)> {
        (0..=600)
            .map(|i| {
                let x = lo + (hi - lo) * i as f64 / 600.0;
                (
                    x,
                    (-(x - m) * (x - m) / (2.0 * v)).exp() / (std::f64::consts::TAU * v).sqrt(),
                )
            })
            .collect()
    };
    let top = density.iter().copied().fold(0.0, f64::max);
    let series = [
        crate::common::Series {
            label: "bootstrap PF: weighted histogram",
            points: hist,
        },
        crate::common::Series {
            label: "EKF: N(x̂, P)",
            points: gaussian(ekf.means[k], ekf.variances[k]),
        },
        crate::common::Series {
            label: "UKF: N(x̂, P)",
            points: gaussian(ukf.means[k], ukf.variances[k]),
        },
        crate::common::Series {
            label: "true state",
            points: vec![(truth[k], 0.0), (truth[k], top)],
        },
    ];
    let path = crate::common::line_plot(
        "particle_growth_posterior.svg",
        &format!("Growth model, step {}: the posterior is bimodal", k + 1),
        "x",
        "density",
        &series,
    )?;
    println!("figure: {}", path.display());
    Ok((k + 1, score))
}

/// The example's `main` (`examples/particle_growth.rs`): its flags, the run and its output.
pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = crate::common::quick_requested();
    let (runs, steps) = if quick { (40, 50) } else { (200, 50) };
    let seed = 0x1993;
    let session = Session::from_args("particle_growth", sharding::settings(quick))?;
    let (lruns, lsteps) = if quick { (10, 60) } else { (50, 60) };
    let g = growth_comparison_in(runs, steps, seed, &session)?;
    let errors = localisation_in(lruns, lsteps, seed, &session)?;
    session.finish()?;
    let (Some(g), Some(errors)) = (g, errors) else {
        return Ok(());
    };
    println!("Growth model, {runs} runs × {steps} steps, {PARTICLES} particles:");
    println!("{:<28} {:>8} {:>16}", "filter", "RMSE", "refused updates");
    let mut json = serde_json::Map::new();
    for (m, method) in METHODS.iter().enumerate() {
        println!(
            "{:<28} {:>8.2} {:>16}",
            format!("{method:?}"),
            g.rmse[m],
            g.refused[m]
        );
        json.insert(
            format!("growth_rmse_{method:?}"),
            serde_json::json!(g.rmse[m]),
        );
    }
    let (step, score) = figure(seed, steps)?;
    println!("most bimodal step of run 0: {step} (mass on the smaller side {score:.2})");
    println!(
        "Range-only localisation, started at the mirror image 24 m away, {lruns} runs × {lsteps} steps:"
    );
    println!(
        "{:<28} {:>18} {:>18}",
        "filter", "median final error", "runs within 2 m"
    );
    for (name, e) in ["EKF", "UKF", "bootstrap PF"].iter().zip(&errors) {
        let within = e.iter().filter(|&&d| d < 2.0).count();
        println!("{name:<28} {:>16.2} m {:>12}/{lruns}", median(e), within);
        json.insert(
            format!("localisation_median_error_{}", name.replace(' ', "_")),
            serde_json::json!(median(e)),
        );
    }
    if crate::common::json_requested() {
        println!("{}", serde_json::Value::Object(json));
    }
    Ok(())
}
