//! An AHRS: unit-quaternion attitude from a gyro, corrected by an accelerometer and a
//! magnetometer, with an EKF and a UKF on the multiplicative error state, models written once
//! and differentiated automatically.
//!
//! The attitude is q = q_ref ⊗ Exp(δθ) (`estim::core::manifold`): the filter's state is the
//! 3-dimensional body-frame attitude error δθ, with `AttitudeError` as its state space (⊞
//! composes rotations), and the reference q_ref is rotated by the gyro and recentred after
//! every update (q_ref ← q_ref ⊗ Exp(δθ̂), δθ̂ ← 0).
//!
//! ```text
//! gyro:       q_ref ← q_ref ⊗ Exp(ω_m Δt),  δθ⁺ = R(Exp(ω_m Δt))ᵀ δθ + w,  Q = σ_g² Δt² I₃
//! sensors:    z = (R(q)ᵀ g_n, R(q)ᵀ m_n) + v,  R(q) = R(q_ref) R(Exp(δθ)),  R = diag(σ_a² I₃, σ_m² I₃)
//! ```
//!
//! (ω_m = ω + n the gyro reading, Δt = 10 ms; the error rotates with the reference because
//! Exp(−ω Δt) Exp(δθ) Exp(ω Δt) = Exp(R(ω Δt)ᵀ δθ).) Both models are written once over a
//! generic scalar (`AutoDiffProcess`, `AutoDiffMeasurement`); `AutoDiff` gives the EKF its
//! Jacobians. Truth: a body rate ω(t) = (0.3 sin 0.5t, 0.2 cos 0.3t, 0.5) rad/s for 20 s,
//! the initial attitude drawn from the prior N(0, 0.03² I₃) about the filter's q_ref; gyro noise
//! σ_g = 0.01 rad/s, accelerometer (gravity 9.81 m/s² up the navigation z axis, no linear
//! acceleration) σ_a = 0.05 m/s², magnetometer (m_n = (0.2, 0, 0.45) G) σ_m = 0.005 G, both
//! at 10 Hz. A Monte Carlo (100 runs) gives the average NEES of the attitude error
//! e = Log(q̂⁻¹ ⊗ q) at every update against its 99 % χ²₃ band, and the worst deviation of
//! ‖q_ref‖ from 1; the figure shows both filters' average NEES.
//!
//! Measured (`--release`, 100 runs × 20 s): average NEES 2.91 for both filters, 1 % of the
//! updates outside the band, RMS error 0.0049 rad, |‖q‖ − 1| ≤ 2.2·10⁻¹⁶. With a 0.1 rad prior
//! instead, both are over-confident for the first second (average NEES 7.0 at the first
//! update, back in the band by the tenth): at 0.1 rad the accelerometer's curvature
//! ½ θ² g ≈ 0.05 m/s² is as large as its noise, which no linearisation (nor the α = 10⁻³
//! UKF) sees.
//!
//! `--shard I/N --out FILE` runs shard I of N of each filter's runs and writes their records to
//! FILE; `--merge FILE...` merges the N files and prints what one process prints, bit for bit;
//! `--stats FILE` writes the sums over runs exactly (`estim_reproductions::sharding`).
//!
//! `cargo run --release --features autodiff --example attitude [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

use estim::core::autodiff::{
    AdScalar, AutoDiff, AutoDiffMeasurement, AutoDiffProcess, rotation_exp, rotation_matrix,
};
use estim::core::manifold::{AttitudeError, AttitudeReference, so3_exp, so3_log};
use estim::filters::consistency::{ChiSquareBand, nees};
use estim::nalgebra::{Matrix3, Matrix6, U3, U6, UnitQuaternion, Vector3, Vector6};
use estim::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use estim_reproductions::sharding::{self, Session};

// The root tests include this file as a module and bring their own `crate::common`.
#[cfg(not(test))]
use estim_reproductions::common;

/// Gyro step, s.
pub const DT: f64 = 0.01;
/// Accelerometer and magnetometer every this many gyro steps.
pub const SENSOR_EVERY: usize = 10;
/// Gyro noise, rad/s.
pub const GYRO_SIGMA: f64 = 0.01;
/// Accelerometer noise, m/s².
pub const ACCEL_SIGMA: f64 = 0.05;
/// Magnetometer noise, G.
pub const MAG_SIGMA: f64 = 0.005;
/// Prior standard deviation of each attitude-error component, rad.
pub const PRIOR_SIGMA: f64 = 0.03;

fn gravity() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, 9.81)
}

fn magnetic_field() -> Vector3<f64> {
    Vector3::new(0.2, 0.0, 0.45)
}

/// The error state's transition over one gyro step: δθ⁺ = R(Exp(ω_m Δt))ᵀ δθ.
pub struct GyroError;

impl AutoDiffProcess<f64, U3> for GyroError {
    type Input = Vector3<f64>;
    fn transition<D: AdScalar<f64>>(
        &self,
        x: &Vector3<D>,
        omega: &Vector3<f64>,
        dt: f64,
    ) -> Vector3<D> {
        rotation_matrix::<f64, D>(&so3_exp(&(omega * dt))).transpose() * x
    }
    fn process_noise(&self, _: &Vector3<f64>, _: &Vector3<f64>, dt: f64) -> Matrix3<f64> {
        Matrix3::identity() * (GYRO_SIGMA * GYRO_SIGMA * dt * dt)
    }
}

/// Accelerometer and magnetometer about the reference attitude: z = R(q_ref Exp(δθ))ᵀ (g, m).
pub struct GravityAndField {
    /// R(q_ref)ᵀ g_n and R(q_ref)ᵀ m_n: the vectors seen at δθ = 0.
    at_reference: [Vector3<f64>; 2],
}

impl GravityAndField {
    /// The sensors about `reference`.
    pub fn about(reference: &AttitudeReference<f64>) -> Self {
        let r = reference.quaternion().inverse();
        Self {
            at_reference: [r * gravity(), r * magnetic_field()],
        }
    }
}

impl AutoDiffMeasurement<f64, U3, U6> for GravityAndField {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector3<D>) -> Vector6<D> {
        let rt = rotation_exp::<f64, D>(x).transpose();
        let [g, m] = self.at_reference.map(|v| rt * v.map(D::from));
        Vector6::new(g[0], g[1], g[2], m[0], m[1], m[2])
    }
    fn measurement_noise(&self, _: &Vector3<f64>) -> Matrix6<f64> {
        let (a, m) = (ACCEL_SIGMA * ACCEL_SIGMA, MAG_SIGMA * MAG_SIGMA);
        Matrix6::from_diagonal(&Vector6::new(a, a, a, m, m, m))
    }
}

/// Which filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    /// EKF, Jacobians by automatic differentiation.
    Ekf,
    /// UKF (α = 10⁻³, β = 2, κ = 0) with ⊞ = rotation composition.
    Ukf,
}

/// The Monte Carlo's result for one filter.
#[derive(Clone, Debug)]
pub struct Summary {
    /// Average NEES over the runs at each update.
    pub average_nees: Vec<f64>,
    /// The 99 % band for one update's average.
    pub band: ChiSquareBand,
    /// Fraction of updates whose average NEES is outside the band.
    pub outside_band: f64,
    /// Average over runs and updates (χ²₃ mean: 3).
    pub overall_nees: f64,
    /// RMS attitude error over runs and updates, rad.
    pub rms_error: f64,
    /// The largest |‖q_ref‖ − 1| seen.
    pub worst_norm_error: f64,
}

fn normal3(rng: &mut StdRng) -> Vector3<f64> {
    Vector3::from_fn(|_, _| StandardNormal.sample(rng))
}

fn true_rate(t: f64) -> Vector3<f64> {
    Vector3::new(0.3 * (0.5 * t).sin(), 0.2 * (0.3 * t).cos(), 0.5)
}

/// One run of `steps` gyro steps: pushes the NEES and the squared attitude error at each
/// update.
fn run_one<F>(
    mut filter: F,
    steps: usize,
    rng: &mut StdRng,
    nees_out: &mut Vec<f64>,
    errors: &mut Vec<f64>,
) -> Result<f64, Box<dyn std::error::Error>>
where
    F: Predict<f64, U3, AutoDiff<GyroError>> + Update<f64, U3, U6, AutoDiff<GravityAndField>>,
{
    let mut reference = AttitudeReference::new(UnitQuaternion::from_euler_angles(0.2, -0.1, 1.0));
    let mut truth = *reference.quaternion() * so3_exp(&(normal3(rng) * PRIOR_SIGMA));
    let gyro = AutoDiff::new(GyroError);
    let mut worst_norm: f64 = 0.0;
    for k in 1..=steps {
        let t = k as f64 * DT;
        let omega = true_rate(t - 0.5 * DT);
        truth *= so3_exp(&(omega * DT));
        let measured = omega + normal3(rng) * GYRO_SIGMA;
        reference.rotate(&measured, DT);
        filter.predict(&gyro, &measured, DT)?;
        if k % SENSOR_EVERY == 0 {
            let inv = truth.inverse();
            let (a, m) = (
                inv * gravity() + normal3(rng) * ACCEL_SIGMA,
                inv * magnetic_field() + normal3(rng) * MAG_SIGMA,
            );
            let z = Vector6::new(a[0], a[1], a[2], m[0], m[1], m[2]);
            filter.update(&AutoDiff::new(GravityAndField::about(&reference)), &z)?;
            // Fold the estimate into the reference; P is unchanged (see the manifold docs).
            let mut x = *filter.state();
            reference.recentre(&mut x, 0)?;
            let p = *filter.covariance();
            filter.reset(Gaussian::new(x, p)?);
            let e = so3_log(&(reference.quaternion().inverse() * truth));
            errors.push(e.norm_squared());
            nees_out.push(nees(&e, filter.covariance())?);
        }
        worst_norm = worst_norm.max((reference.quaternion().as_ref().norm() - 1.0).abs());
    }
    Ok(worst_norm)
}

/// The Monte Carlo for one filter: `runs` runs of `seconds` s, seeded.
pub fn monte_carlo(
    filter: Filter,
    runs: usize,
    seconds: f64,
    seed: u64,
) -> Result<Summary, Box<dyn std::error::Error>> {
    Ok(sharding::whole(monte_carlo_in(
        filter,
        runs,
        seconds,
        seed,
        &Session::whole(),
    )?)?)
}

/// Run `run` of the Monte Carlo of `filter` (`steps` gyro steps): its worst |‖q_ref‖ − 1|,
/// then the NEES at each update, then the squared attitude error at each update.
fn run_record(
    filter: Filter,
    run: usize,
    steps: usize,
    seed: u64,
) -> Result<Vec<f64>, Box<dyn std::error::Error>> {
    let updates = steps / SENSOR_EVERY;
    let mut rng = StdRng::seed_from_u64(seed.wrapping_add(run as u64));
    let prior = Gaussian::new(
        Vector3::zeros(),
        Matrix3::identity() * (PRIOR_SIGMA * PRIOR_SIGMA),
    )?;
    let space = AttitudeError::at(0);
    let mut record = vec![0.0];
    record.reserve(2 * updates);
    let mut errors = Vec::with_capacity(updates);
    record[0] = match filter {
        Filter::Ekf => run_one(
            Ekf::new(prior).with_state_space(space),
            steps,
            &mut rng,
            &mut record,
            &mut errors,
        )?,
        Filter::Ukf => run_one(
            Ukf::new(prior).with_state_space(space),
            steps,
            &mut rng,
            &mut record,
            &mut errors,
        )?,
    };
    record.extend(errors);
    Ok(record)
}

/// [`monte_carlo`] in a sharding session (`--shard`/`--merge`): the runs' records folded in
/// run order, `None` in a shard.
pub fn monte_carlo_in(
    filter: Filter,
    runs: usize,
    seconds: f64,
    seed: u64,
    session: &Session,
) -> Result<Option<Summary>, Box<dyn std::error::Error>> {
    let steps = (seconds / DT).round() as usize;
    let updates = steps / SENSOR_EVERY;
    let key = format!("{filter:?}");
    let Some(records) = session.records(&key, runs, |run| run_record(filter, run, steps, seed))?
    else {
        return Ok(None);
    };
    let mut sums = vec![0.0; updates];
    let (mut errors, mut worst_norm) = (0.0, 0.0f64);
    for record in &records {
        worst_norm = worst_norm.max(record[0]);
        let (values, squared) = record[1..].split_at(updates);
        for (s, v) in sums.iter_mut().zip(values) {
            *s += v;
        }
        for e in squared {
            errors += e;
        }
    }
    let mut flat = vec![errors, worst_norm];
    flat.extend_from_slice(&sums);
    session.summary(&key, &flat);
    let band = ChiSquareBand::two_sided(3, runs, 0.99)?;
    let average_nees: Vec<f64> = sums.iter().map(|s| s / runs as f64).collect();
    let outside = average_nees.iter().filter(|a| !band.contains(**a)).count();
    Ok(Some(Summary {
        outside_band: outside as f64 / updates as f64,
        overall_nees: average_nees.iter().sum::<f64>() / updates as f64,
        rms_error: (errors / (runs * updates) as f64).sqrt(),
        average_nees,
        band,
        worst_norm_error: worst_norm,
    }))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (runs, seconds) = if crate::common::quick_requested() {
        (30, 10.0)
    } else {
        (100, 20.0)
    };
    let session = Session::from_args(
        "attitude",
        sharding::settings(crate::common::quick_requested()),
    )?;
    let filters = [(Filter::Ekf, "EKF (AD Jacobians)"), (Filter::Ukf, "UKF")];
    let mut results = Vec::new();
    for (filter, label) in filters {
        if let Some(s) = monte_carlo_in(filter, runs, seconds, 0xa7, &session)? {
            results.push((filter, label, s));
        }
    }
    session.finish()?;
    if results.len() < filters.len() {
        return Ok(());
    }
    let mut json = serde_json::Map::new();
    let mut summaries = Vec::new();
    for (filter, label, s) in results {
        println!(
            "{label:20} average NEES {:.3} (χ²₃: 3), updates outside the 99% band {:4.1}%, RMS error {:.4} rad, worst |‖q‖ − 1| {:.1e}",
            s.overall_nees,
            100.0 * s.outside_band,
            s.rms_error,
            s.worst_norm_error
        );
        json.insert(
            format!("{filter:?}"),
            serde_json::json!({
                "average_nees": s.overall_nees,
                "outside_band": s.outside_band,
                "rms_error": s.rms_error,
                "worst_norm_error": s.worst_norm_error,
            }),
        );
        summaries.push((label, s));
    }
    let band = summaries[0].1.band;
    println!(
        "band for one update's average NEES over {runs} runs: [{:.3}, {:.3}]",
        band.lower, band.upper
    );
    let nees: Vec<(&str, &[f64])> = summaries
        .iter()
        .map(|(label, s)| (*label, s.average_nees.as_slice()))
        .collect();
    crate::common::nees_band_plot(
        "attitude_nees.svg",
        "AHRS on the quaternion error state: average NEES",
        DT * SENSOR_EVERY as f64,
        &nees,
        f64::INFINITY,
        (band.lower, band.upper),
        "99% χ²₃ band",
    );
    if crate::common::json_requested() {
        println!("{}", serde_json::Value::Object(json));
    }
    Ok(())
}
