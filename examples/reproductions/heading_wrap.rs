//! A heading across ±π: the same UKF with a plain vector state and with a wrapping ⊞.
//!
//! A vehicle drives a circle in the plane: state (x, y, θ), odometry input (v, ω) with
//! v = 2 m/s and ω = 0.8 rad/s, so θ crosses ±π every 7.9 s (13 times in 100 s).
//! The process model is the unicycle
//!
//! ```text
//! x⁺ = x + v Δt cos θ,  y⁺ = y + v Δt sin θ,  θ⁺ = wrap(θ + ω Δt),   Δt = 0.1 s,
//! ```
//!
//! with the heading wrapped into (−π, π], as models usually are, and additive noise
//! σ = (0.02 m, 0.02 m, 0.01 rad) per step. Measurements every step: a GPS position
//! (σ = 0.5 m) and a compass (σ = 0.05 rad, residual wrapped). Prior N(truth, diag(1 m²,
//! 1 m², 0.1² rad²)), the truth drawn from it, so a correct filter is consistent: the NEES of
//! e = x̂ ⊟ x (heading difference wrapped) is χ²₃.
//!
//! Filters: the cubature UKF (sigma points at ±√(3P) about the mean) on plain ℝ³, and the same
//! filter with `WrappedAngles::new([2])` as its state space. Without ⊞, at every crossing the
//! sigma points straddle ±π, their deviations f(χ) − f(x̂) jump by 2π, and the predicted mean
//! and P are wrong by ~π and ~π²; with ⊞ nothing changes at the crossing. A Monte Carlo
//! (200 runs, 1000 steps) gives the average NEES at each step against its 99 % χ² band, and
//! the worst heading error; a figure shows both filters' average NEES.
//!
//! `--shard I/N --out FILE` runs shard I of N of each filter's runs and writes their records to
//! FILE; `--merge FILE...` merges the N files and prints what one process prints, bit for bit;
//! `--stats FILE` writes the sums over runs exactly (`estim_reproductions::sharding`).
//!
//! `cargo run --release --example heading_wrap [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

use estim::core::WrappedAngles;
use estim::filters::consistency::{ChiSquareBand, nees};
use estim::nalgebra::{Matrix2, Matrix2x3, Matrix3, U2, U3, Vector2, Vector3};
use estim::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use crate::sharding::{self, Session};

/// Time step, s.
pub const DT: f64 = 0.1;
/// Speed, m/s, and turn rate, rad/s.
pub const SPEED: f64 = 2.0;
/// Turn rate, rad/s.
pub const TURN_RATE: f64 = 0.8;
/// Process noise standard deviations per step (x, y in m, θ in rad).
pub const PROCESS_SIGMA: [f64; 3] = [0.02, 0.02, 0.01];
/// GPS and compass noise standard deviations.
pub const GPS_SIGMA: f64 = 0.5;
/// Compass noise standard deviation, rad.
pub const COMPASS_SIGMA: f64 = 0.05;

/// The unicycle, heading wrapped; input (v, ω).
pub struct Unicycle;

impl ProcessModel<f64, U3> for Unicycle {
    type Input = Vector2<f64>;
    fn transition(&self, x: &Vector3<f64>, u: &Vector2<f64>, dt: f64) -> Vector3<f64> {
        let (s, c) = x[2].sin_cos();
        Vector3::new(
            x[0] + u[0] * dt * c,
            x[1] + u[0] * dt * s,
            wrap_angle(x[2] + u[1] * dt),
        )
    }
    fn process_noise(&self, _: &Vector3<f64>, _: &Vector2<f64>, _: f64) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::from(PROCESS_SIGMA.map(|s| s * s)))
    }
}

impl ProcessJacobian<f64, U3> for Unicycle {
    fn transition_jacobian(&self, x: &Vector3<f64>, u: &Vector2<f64>, dt: f64) -> Matrix3<f64> {
        let (s, c) = x[2].sin_cos();
        Matrix3::new(
            1.0,
            0.0,
            -u[0] * dt * s,
            0.0,
            1.0,
            u[0] * dt * c,
            0.0,
            0.0,
            1.0,
        )
    }
}

/// GPS position.
pub struct Gps;

impl MeasurementModel<f64, U3, U2> for Gps {
    fn measure(&self, x: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(x[0], x[1])
    }
    fn measurement_noise(&self, _: &Vector3<f64>) -> Matrix2<f64> {
        Matrix2::identity() * (GPS_SIGMA * GPS_SIGMA)
    }
}

impl MeasurementJacobian<f64, U3, U2> for Gps {
    fn measurement_jacobian(&self, _: &Vector3<f64>) -> Matrix2x3<f64> {
        Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    }
}

/// Compass: θ, residual wrapped.
pub struct Compass;

impl MeasurementModel<f64, U3, estim::nalgebra::U1> for Compass {
    fn measure(&self, x: &Vector3<f64>) -> estim::nalgebra::Vector1<f64> {
        estim::nalgebra::Vector1::new(x[2])
    }
    fn measurement_noise(&self, _: &Vector3<f64>) -> estim::nalgebra::Matrix1<f64> {
        estim::nalgebra::Matrix1::new(COMPASS_SIGMA * COMPASS_SIGMA)
    }
    fn residual_into(
        &self,
        a: &estim::nalgebra::Vector1<f64>,
        b: &estim::nalgebra::Vector1<f64>,
        out: &mut estim::nalgebra::Vector1<f64>,
    ) {
        *out = estim::nalgebra::Vector1::new(wrap_angle(a[0] - b[0]));
    }
}

impl MeasurementJacobian<f64, U3, estim::nalgebra::U1> for Compass {
    fn measurement_jacobian(&self, _: &Vector3<f64>) -> estim::nalgebra::Matrix1x3<f64> {
        estim::nalgebra::Matrix1x3::new(0.0, 0.0, 1.0)
    }
}

/// Which filter a run uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// Cubature UKF on plain ℝ³.
    PlainUkf,
    /// Cubature UKF with the heading wrapped by ⊞/⊟.
    WrappedUkf,
    /// EKF with the heading wrapped by ⊞/⊟.
    WrappedEkf,
}

/// The Monte Carlo's result for one filter.
#[derive(Clone, Debug)]
pub struct Summary {
    /// The average NEES over the runs at each step (after the update).
    pub average_nees: Vec<f64>,
    /// The 99 % band for one step's average.
    pub band: ChiSquareBand,
    /// The fraction of steps whose average NEES is outside the band.
    pub outside_band: f64,
    /// The largest |heading error| over all runs and steps, rad.
    pub worst_heading_error: f64,
    /// Estimates whose heading left (−π, π].
    pub out_of_range: usize,
}

fn normal(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

/// Heading error (wrapped) and position errors.
fn error(estimate: &Vector3<f64>, truth: &Vector3<f64>) -> Vector3<f64> {
    let mut e = estimate - truth;
    e[2] = wrap_angle(e[2]);
    e
}

/// One run: the NEES after each update, or the step's error if the filter failed.
fn run_one<F>(
    mut filter: F,
    truth0: Vector3<f64>,
    steps: usize,
    rng: &mut StdRng,
    out: &mut Vec<f64>,
) -> (f64, usize)
where
    F: Predict<f64, U3, Unicycle>
        + Update<f64, U3, U2, Gps>
        + Update<f64, U3, estim::nalgebra::U1, Compass>,
{
    let u = Vector2::new(SPEED, TURN_RATE);
    let mut truth = truth0;
    let (mut worst, mut out_of_range) = (0.0f64, 0);
    for _ in 0..steps {
        truth = Unicycle.transition(&truth, &u, DT)
            + Vector3::from(PROCESS_SIGMA.map(|s| s * normal(rng)));
        truth[2] = wrap_angle(truth[2]);
        let gps =
            Vector2::new(truth[0], truth[1]) + Vector2::new(normal(rng), normal(rng)) * GPS_SIGMA;
        let compass =
            estim::nalgebra::Vector1::new(wrap_angle(truth[2] + COMPASS_SIGMA * normal(rng)));
        let ok = filter.predict(&Unicycle, &u, DT).is_ok()
            && filter.update(&Gps, &gps).is_ok()
            && filter.update(&Compass, &compass).is_ok();
        let e = error(filter.state(), &truth);
        worst = worst.max(e[2].abs());
        let h = filter.state()[2];
        if !(h > -core::f64::consts::PI && h <= core::f64::consts::PI) {
            out_of_range += 1;
        }
        // A failed step (a covariance no longer positive definite) counts as an infinite NEES.
        out.push(if ok {
            nees(&e, filter.covariance()).unwrap_or(f64::INFINITY)
        } else {
            f64::INFINITY
        });
    }
    (worst, out_of_range)
}

/// The Monte Carlo for one filter variant: `runs` runs of `steps` steps, seeded.
pub fn monte_carlo(
    variant: Variant,
    runs: usize,
    steps: usize,
    seed: u64,
) -> Result<Summary, Box<dyn std::error::Error>> {
    Ok(sharding::whole(monte_carlo_in(
        variant,
        runs,
        steps,
        seed,
        &Session::whole(),
    )?)?)
}

/// Run `run` of the Monte Carlo of `variant`: its worst |heading error|, its headings out of
/// range, then its NEES at each step.
fn run_record(
    variant: Variant,
    run: usize,
    steps: usize,
    seed: u64,
) -> Result<Vec<f64>, Box<dyn std::error::Error>> {
    let prior_sigma = Vector3::new(1.0, 1.0, 0.1);
    let mut rng = StdRng::seed_from_u64(seed.wrapping_add(run as u64));
    // Truth from the prior; the filter starts at the prior mean (the circle's start,
    // heading 2.5 rad, half a second before the first crossing).
    let mean = Vector3::new(0.0, 0.0, 2.5);
    let mut truth = mean
        + prior_sigma.component_mul(&Vector3::new(
            normal(&mut rng),
            normal(&mut rng),
            normal(&mut rng),
        ));
    truth[2] = wrap_angle(truth[2]);
    let prior = Gaussian::new(mean, Matrix3::from_diagonal(&prior_sigma.map(|s| s * s)))?;
    let mut record = vec![0.0; 2];
    record.reserve(steps);
    let cubature = Unscented::cubature();
    let (w, o) = match variant {
        Variant::PlainUkf => run_one(
            Ukf::with_propagator(prior, cubature),
            truth,
            steps,
            &mut rng,
            &mut record,
        ),
        Variant::WrappedUkf => run_one(
            Ukf::with_propagator(prior, cubature).with_state_space(WrappedAngles::new([2])),
            truth,
            steps,
            &mut rng,
            &mut record,
        ),
        Variant::WrappedEkf => run_one(
            Ekf::new(prior).with_state_space(WrappedAngles::new([2])),
            truth,
            steps,
            &mut rng,
            &mut record,
        ),
    };
    record[0] = w;
    record[1] = o as f64;
    Ok(record)
}

/// [`monte_carlo`] in a sharding session (`--shard`/`--merge`): the runs' records folded in
/// run order, `None` in a shard.
pub fn monte_carlo_in(
    variant: Variant,
    runs: usize,
    steps: usize,
    seed: u64,
    session: &Session,
) -> Result<Option<Summary>, Box<dyn std::error::Error>> {
    let key = format!("{variant:?}");
    let Some(records) = session.records(&key, runs, |run| run_record(variant, run, steps, seed))?
    else {
        return Ok(None);
    };
    let mut sums = vec![0.0; steps];
    let (mut worst, mut out_of_range) = (0.0f64, 0);
    for record in &records {
        worst = worst.max(record[0]);
        out_of_range += record[1] as usize;
        for (s, v) in sums.iter_mut().zip(&record[2..]) {
            *s += v;
        }
    }
    let mut flat = vec![worst, out_of_range as f64];
    flat.extend_from_slice(&sums);
    session.summary(&key, &flat);
    let band = ChiSquareBand::two_sided(3, runs, 0.99)?;
    let average_nees: Vec<f64> = sums.iter().map(|s| s / runs as f64).collect();
    let outside = average_nees.iter().filter(|a| !band.contains(**a)).count();
    Ok(Some(Summary {
        outside_band: outside as f64 / steps as f64,
        average_nees,
        band,
        worst_heading_error: worst,
        out_of_range,
    }))
}

/// The example's `main` (`examples/heading_wrap.rs`): its flags, the run and its output.
pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (runs, steps) = if crate::common::quick_requested() {
        (50, 400)
    } else {
        (200, 1000)
    };
    let session = Session::from_args(
        "heading_wrap",
        sharding::settings(crate::common::quick_requested()),
    )?;
    let variants = [
        (Variant::PlainUkf, "UKF, plain vector state"),
        (Variant::WrappedUkf, "UKF, wrapped heading (⊞)"),
        (Variant::WrappedEkf, "EKF, wrapped heading (⊞)"),
    ];
    let mut results = Vec::new();
    for (variant, label) in variants {
        if let Some(s) = monte_carlo_in(variant, runs, steps, 0x4ead, &session)? {
            results.push((variant, label, s));
        }
    }
    session.finish()?;
    if results.len() < variants.len() {
        return Ok(());
    }
    let mut json = serde_json::Map::new();
    let mut summaries = Vec::new();
    for (variant, label, s) in results {
        println!(
            "{label:28} steps outside the 99% NEES band: {:5.1}%   worst |heading error| {:.3} rad   headings out of (−π, π]: {}",
            100.0 * s.outside_band,
            s.worst_heading_error,
            s.out_of_range
        );
        json.insert(
            format!("{variant:?}"),
            serde_json::json!({
                "outside_band": s.outside_band,
                "worst_heading_error": s.worst_heading_error,
                "out_of_range": s.out_of_range,
            }),
        );
        summaries.push((label, s));
    }
    let band = summaries[0].1.band;
    println!(
        "band for one step's average NEES over {runs} runs: [{:.3}, {:.3}] (χ²₃ mean 3)",
        band.lower, band.upper
    );
    let nees: Vec<(&str, &[f64])> = summaries
        .iter()
        .map(|(label, s)| (*label, s.average_nees.as_slice()))
        .collect();
    crate::common::nees_band_plot(
        "heading_wrap_nees.svg",
        "Average NEES across ±π crossings (clipped at 100)",
        DT,
        &nees,
        100.0,
        (band.lower, band.upper),
        "99% χ² band",
    );
    if crate::common::json_requested() {
        println!("{}", serde_json::Value::Object(json));
    }
    Ok(())
}
