//! **estim's extension, not in the paper**: Lu's GPS/accelerometer problem with GPS latency,
//! outliers and a stuck channel, fused by estim's time-aware driver
//! (`estim::filters::fusion::FusionDriver`).
//!
//! Lu's scenario (estim_models::lu: 200 Hz accelerometer mechanisation, 3-state error-state
//! Kalman filter, 5 Hz GPS position and velocity), with every GPS fix delivered 0–300 ms late
//! (uniform, in 5 ms steps). The GPS position and velocity channels are two sensors of the
//! driver (δz = z − mechanisation, 1 component each). Two scenarios:
//!
//! - *latency*: nothing else wrong;
//! - *faults*: also 100 σ outliers (each channel, probability 2 % per fix, from 1 s on) and,
//!   from 12 s on, a stuck position channel (it repeats the fix taken at 12 s).
//!
//! Why outliers start after 1 s: at the first fixes the prior is wider than a 100 σ velocity
//! outlier (σ_v(0) = 1 m/s, 100 σ = 4 m/s), so no NIS test can tell it from a good fix. With
//! outliers from t = 0, one run in 400 accepted one at its first fix; the filter then rejected
//! every good velocity fix, the monitor excluded the good channel and the run never recovered
//! (ANEES 52 over the 400 runs instead of 3.2). That is a limit of any gate, not of the replay:
//! a prior honest about its spread lets a plausible outlier in.
//!
//! Three ways to fuse:
//!
//! - *latency ignored*: a fix is fused when it arrives, against the mechanisation then (as if
//!   current), no gate;
//! - *at time taken*: fused at the time it was taken (the driver replays its history), no gate;
//! - *delayed + gating + fault exclusion*: at the time taken, NIS gate at 0.9999, a windowed NIS
//!   χ² monitor per channel (W = 20, α = 10⁻⁴, NIS clipped at the 99 % quantile) that excludes
//!   a faulty channel until it recovers, reset after 5 rejections.
//!
//! Every 0.2 s the driver is advanced to the current time and the real-time estimate is
//! recorded against the true error state on estim's Monte Carlo runner: ANEES (with its 99 %
//! band), RMS position and velocity error, and for the monitor the detection delay of the stuck
//! channel (from 12 s to the first exclusion), whose bound is derived in the module docs of
//! `estim_filters::fusion`: ⌈q / c⌉ fixes over the clip, plus the latency.
//!
//! `cargo run --release --example lu_delays [-- --json] [-- --quick]`

use std::sync::Mutex;
use std::time::Instant;

use crate::common::{Band, Headline, Output, Series, band_plot, line_plot};
use crate::sharding::Session;
use estim::core::{Gaussian, LinearMeasurement, error::Result as EstimResult};
use estim::filters::fusion::{
    DuplicatePolicy, FusionDriver, FusionError, FusionSettings, Innovation, MonitorSettings,
    ResetSettings, SensorSet, SensorSettings, SensorStatus,
};
use estim::filters::monte_carlo::{EnsembleStats, MonteCarlo, Recorder};
use estim::filters::{KalmanFilter, Update, ValidationError};
use estim::models::lu::{ErrorStateProcess, GpsMeasurement, Mechanisation, Scenario, Simulator};
use estim::nalgebra::{Matrix1, Matrix1x3, U1, U3, Vector1, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// How the fixes are fused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// Fused on arrival against the current mechanisation, as if current; no gate.
    LatencyIgnored,
    /// Fused at the time taken; no gate.
    AtTimeTaken,
    /// At the time taken, with gate, fault monitor and reset.
    Robust,
}

impl Method {
    /// All three.
    pub const ALL: [Method; 3] = [Method::LatencyIgnored, Method::AtTimeTaken, Method::Robust];

    /// The table label.
    pub fn label(self) -> &'static str {
        match self {
            Method::LatencyIgnored => "latency ignored",
            Method::AtTimeTaken => "at time taken",
            Method::Robust => "delayed + gating + fault exclusion",
        }
    }
}

/// One configuration of the experiment.
#[derive(Clone, Debug, PartialEq)]
pub struct DelayConfig {
    /// Lu's scenario (duration shortened).
    pub scenario: Scenario,
    /// Monte Carlo realizations.
    pub runs: usize,
    /// Master seed.
    pub seed: u64,
    /// Largest GPS latency, in accelerometer steps (60 × 5 ms = 300 ms).
    pub max_latency_steps: usize,
    /// Probability of a 100 σ outlier per channel and fix (0: none).
    pub outlier_probability: f64,
    /// The stuck position channel's onset \[s\] (`None`: never).
    pub stuck_from: Option<f64>,
    /// How the fixes are fused.
    pub method: Method,
}

impl DelayConfig {
    /// The latency scenario: 20 s, 400 runs (60 with `quick`, over 10 s).
    pub fn latency(quick: bool, method: Method) -> Self {
        let seconds = if quick { 10.0 } else { 20.0 };
        Self {
            scenario: Scenario::paper().with_duration(seconds),
            runs: if quick { 60 } else { 400 },
            seed: 2710,
            max_latency_steps: 60,
            outlier_probability: 0.0,
            stuck_from: None,
            method,
        }
    }

    /// The faults scenario: the latency scenario plus outliers (2 %) and a stuck position
    /// channel from 12 s (6 s when `quick`).
    pub fn faults(quick: bool, method: Method) -> Self {
        Self {
            outlier_probability: 0.02,
            stuck_from: Some(if quick { 6.0 } else { 12.0 }),
            ..Self::latency(quick, method)
        }
    }

    /// The scenario's name.
    pub fn scenario_label(&self) -> &'static str {
        if self.stuck_from.is_some() || self.outlier_probability > 0.0 {
            "latency + outliers + stuck"
        } else {
            "latency"
        }
    }
}

/// A GPS channel's reading: the error-state measurement δz of one component.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Channel {
    /// δz_p = z_p − p_c \[m\].
    Position(Vector1<f64>),
    /// δz_v = z_v − v_c \[m/s\].
    Velocity(Vector1<f64>),
}

/// The two GPS channels as two sensors of the driver.
pub struct GpsChannels {
    position: LinearMeasurement<f64, U3, U1>,
    velocity: LinearMeasurement<f64, U3, U1>,
}

impl GpsChannels {
    /// From Lu's GPS noise.
    pub fn new(gps: &GpsMeasurement) -> Self {
        Self {
            position: LinearMeasurement {
                observation: Matrix1x3::new(1.0, 0.0, 0.0),
                noise: Matrix1::new(gps.position_variance),
            },
            velocity: LinearMeasurement {
                observation: Matrix1x3::new(0.0, 1.0, 0.0),
                noise: Matrix1::new(gps.velocity_variance),
            },
        }
    }
}

impl<F: Update<f64, U3, U1, LinearMeasurement<f64, U3, U1>>> SensorSet<f64, U3, F> for GpsChannels {
    type Reading = Channel;
    fn count(&self) -> usize {
        2
    }
    fn sensor(&self, r: &Channel) -> usize {
        match r {
            Channel::Position(_) => 0,
            Channel::Velocity(_) => 1,
        }
    }
    fn dimension(&self, _: usize) -> usize {
        1
    }
    fn update(&self, filter: &mut F, r: &Channel) -> EstimResult<Innovation<f64>> {
        match r {
            Channel::Position(z) => filter.update(&self.position, z).map(|r| Innovation::of(&r)),
            Channel::Velocity(z) => filter.update(&self.velocity, z).map(|r| Innovation::of(&r)),
        }
    }
}

type LuDriver = FusionDriver<f64, U3, KalmanFilter<f64, U3>, ErrorStateProcess, GpsChannels>;

/// The driver of a method: history 0.5 s (32 records), sub-steps of one accelerometer period.
pub fn make_driver(scenario: &Scenario, method: Method) -> Result<LuDriver, FusionError> {
    let prior = Gaussian::new(Vector3::zeros(), scenario.error_prior_covariance())?;
    let settings = FusionSettings {
        horizon: 0.5,
        capacity: 32,
        max_step: scenario.dt,
        max_substeps: 1_000_000,
        // Lu's protocol drops a second fix of a channel at one time.
        duplicates: DuplicatePolicy::Refuse,
    };
    let judged = |state: usize, variance: f64| {
        SensorSettings::gated(0.9999)
            .with_monitor(MonitorSettings {
                window: 20,
                false_alarm: 1e-4,
                clip_probability: 0.99,
            })
            .with_reset(ResetSettings {
                after_rejections: 5,
                states: vec![state],
                variance: 1e4 * variance,
                blow_up_variance: None,
            })
    };
    let driver = FusionDriver::new(
        KalmanFilter::new(prior),
        ErrorStateProcess::new(scenario.accel_noise_variance),
        (),
        GpsChannels::new(&scenario.gps()),
        0.0,
        settings,
        SensorSettings::default(),
    )?;
    Ok(match method {
        Method::Robust => driver
            .with_sensor_settings(0, judged(0, scenario.gps_position_variance))?
            .with_sensor_settings(1, judged(1, scenario.gps_velocity_variance))?,
        _ => driver,
    })
}

/// One Monte Carlo configuration's results.
#[derive(Clone, Debug)]
pub struct DelayResult {
    /// The configuration.
    pub config: DelayConfig,
    /// Slot times \[s\] (0 and every 0.2 s).
    pub time: Vec<f64>,
    /// The runner's statistics of the real-time estimate at each slot.
    pub stats: EnsembleStats,
    /// Per run: the detection delay of the stuck channel \[s\] (`None`: not detected).
    pub detection_delay: Vec<Option<f64>>,
    /// Per run: exclusions of a channel before any stuck onset (false alarms or outlier-driven).
    pub early_exclusions: Vec<u64>,
    /// Fixes dropped because another fix of the same channel arrived in the same step (only
    /// when latency is ignored: both would be fused at one time).
    pub dropped: usize,
}

impl DelayResult {
    /// ANEES at each slot after the first second.
    pub fn anees(&self) -> Vec<(f64, f64)> {
        self.series(|s| s.mean_nees)
    }

    /// RMS error of component `i` at each slot after the first second.
    pub fn rms(&self, i: usize) -> Vec<(f64, f64)> {
        self.series(|s| (s.error_covariance[(i, i)] + s.mean_error[i].powi(2)).sqrt())
    }

    fn series(
        &self,
        f: impl Fn(&estim::filters::monte_carlo::EstimateStats) -> f64,
    ) -> Vec<(f64, f64)> {
        self.time
            .iter()
            .zip(&self.stats.slots)
            .filter(|(t, _)| **t >= 1.0)
            .filter_map(|(&t, s)| s.estimate.as_ref().map(|e| (t, f(e))))
            .collect()
    }

    /// The ANEES averaged over the slots after the first second.
    pub fn mean_anees(&self) -> f64 {
        mean(self.anees().iter().map(|p| p.1))
    }

    /// The fraction of those slots whose ANEES is in its 99 % band.
    pub fn fraction_in_band(&self) -> f64 {
        let band = estim::filters::consistency::ChiSquareBand::two_sided(3, self.config.runs, 0.99)
            .expect("3 states, runs ≥ 2");
        let a = self.anees();
        a.iter().filter(|p| band.contains(p.1)).count() as f64 / a.len() as f64
    }

    /// The RMS of component `i` over the slots after the first second.
    pub fn mean_rms(&self, i: usize) -> f64 {
        mean(self.rms(i).iter().map(|p| p.1 * p.1)).sqrt()
    }

    /// Mean and largest detection delay over the runs that detected, and how many did.
    pub fn detection(&self) -> Option<(f64, f64, usize)> {
        let d: Vec<f64> = self.detection_delay.iter().flatten().copied().collect();
        if d.is_empty() {
            return None;
        }
        Some((
            mean(d.iter().copied()),
            d.iter().copied().fold(0.0, f64::max),
            d.len(),
        ))
    }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n as f64
}

/// A fix as delivered.
#[derive(Clone, Copy, Debug)]
struct Delivery {
    taken: usize,
    arrival: usize,
    position: f64,
    velocity: f64,
}

/// What one shard keeps beside the runner's statistics: (run, detection delay, early
/// exclusions) of each of its runs, and the fixes it dropped.
type PerShard = (Vec<(usize, Option<f64>, u64)>, usize);

/// Runs one configuration on the Monte Carlo runner.
pub fn run_config(config: &DelayConfig) -> Result<DelayResult, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(run_config_in(
        config,
        &Session::whole(),
    )?)?)
}

/// [`run_config`] as `session` says: whole, one shard (`None`) or the merge of the shards.
pub fn run_config_in(
    config: &DelayConfig,
    session: &Session,
) -> Result<Option<DelayResult>, Box<dyn std::error::Error>> {
    let scenario = config.scenario;
    scenario.validate()?;
    make_driver(&scenario, config.method)?;
    let slots = scenario.updates() + 1;
    let mc = MonteCarlo::new(config.runs, slots)?.with_seed(config.seed);
    let per_run = Mutex::new(Vec::with_capacity(config.runs));
    let dropped = Mutex::new(0usize);
    let realization = |run: usize, seed: u64, rec: &mut Recorder| -> Result<(), ValidationError> {
        let (delay, early, drop) = realize(config, seed, rec).map_err(|e| match e {
            FusionError::Filter(e) => ValidationError::from(e),
            other => panic!("the example's own events are valid: {other}"),
        })?;
        per_run
            .lock()
            .expect("no panic holds it")
            .push((run, delay, early));
        *dropped.lock().expect("no panic holds it") += drop;
        Ok(())
    };
    let key = format!("{} / {}", config.scenario_label(), config.method.label());
    let stats = session.run(&key, &mc, realization)?;
    let mine: PerShard = (
        per_run.into_inner().expect("no panic holds it"),
        dropped.into_inner().expect("no panic holds it"),
    );
    let (Some(stats), Some(shards)) = (stats, session.extra(&key, mine)?) else {
        return Ok(None);
    };
    let mut per_run: Vec<_> = shards.iter().flat_map(|s| s.0.iter().copied()).collect();
    per_run.sort_by_key(|r| r.0);
    Ok(Some(DelayResult {
        config: config.clone(),
        time: (0..slots)
            .map(|k| if k == 0 { 0.0 } else { scenario.update_time(k) })
            .collect(),
        stats,
        detection_delay: per_run.iter().map(|r| r.1).collect(),
        early_exclusions: per_run.iter().map(|r| r.2).collect(),
        dropped: shards.iter().map(|s| s.1).sum(),
    }))
}

/// One realization: simulates, delivers the fixes late, fuses them, records the real-time
/// estimate every 0.2 s. Returns the detection delay, the exclusions before the onset, and the
/// fixes dropped.
fn realize(
    config: &DelayConfig,
    seed: u64,
    rec: &mut Recorder,
) -> Result<(Option<f64>, u64, usize), FusionError> {
    let s = config.scenario;
    let mut sim = Simulator::new(&s, seed);
    let mut faults = StdRng::seed_from_u64(seed ^ 0x00de_1a75);
    let mut mech = Mechanisation::new(s.position_mean, s.velocity_mean);
    let mut history = Vec::with_capacity(s.steps + 1); // the mechanisation at every step
    history.push(mech);
    let mut driver = make_driver(&s, config.method)?;
    let truth0 = sim.truth().error_state(&mech);
    rec.record_filter(0, &truth0, driver.filter())
        .map_err(validation_to_fusion)?;
    let stuck_step = config.stuck_from.map(|t| (t / s.dt).round() as usize);
    let mut stuck_value = None;
    let mut pending: Vec<Delivery> = Vec::new();
    let (mut detected, mut early, mut dropped) = (None, 0u64, 0usize);
    let sigma = (
        s.gps_position_variance.sqrt(),
        s.gps_velocity_variance.sqrt(),
    );
    for _ in 0..s.steps {
        let a = sim.accelerometer();
        mech.step(a, s.dt);
        history.push(mech);
        let step = sim.step_index();
        if sim.gps_due() {
            let z = sim.gps();
            let (mut p, mut v) = (z[0], z[1]);
            // Draws in a fixed order whatever the configuration (same fixes for every method).
            let latency = faults.random_range(0..=config.max_latency_steps);
            let (op, ov): (f64, f64) = (faults.random(), faults.random());
            let (sp, sv): (bool, bool) = (faults.random(), faults.random());
            let warm = step as f64 * s.dt >= 1.0;
            if warm && op < config.outlier_probability {
                p += if sp { 100.0 } else { -100.0 } * sigma.0;
            }
            if warm && ov < config.outlier_probability {
                v += if sv { 100.0 } else { -100.0 } * sigma.1;
            }
            if stuck_step.is_some_and(|onset| step >= onset) {
                p = *stuck_value.get_or_insert(p);
            }
            pending.push(Delivery {
                taken: step,
                arrival: step + latency,
                position: p,
                velocity: v,
            });
        }
        // Deliver what arrives now, in order of arrival.
        let mut k = 0;
        while k < pending.len() {
            if pending[k].arrival != step {
                k += 1;
                continue;
            }
            let d = pending.remove(k);
            let at = match config.method {
                Method::LatencyIgnored => d.arrival,
                _ => d.taken,
            };
            let m = &history[at];
            for reading in [
                Channel::Position(Vector1::new(d.position - m.position)),
                Channel::Velocity(Vector1::new(d.velocity - m.velocity)),
            ] {
                match driver.fuse(at as f64 * s.dt, reading) {
                    Ok(_) => {}
                    Err(FusionError::Duplicate { .. }) => dropped += 1,
                    Err(e) => return Err(e),
                }
            }
            let position = driver.health(0);
            match stuck_step {
                // Detected: the position channel is excluded at or after the onset (already
                // excluded at the onset counts as a delay of 0).
                Some(onset) if step >= onset => {
                    if detected.is_none() && position.status == SensorStatus::Excluded {
                        detected = Some((step - onset) as f64 * s.dt);
                    }
                }
                _ => early = position.faults,
            }
        }
        if step.is_multiple_of(s.gps_every) {
            driver.advance_to(step as f64 * s.dt)?;
            let slot = step / s.gps_every;
            let truth = sim.truth().error_state(&mech);
            rec.record_filter(slot, &truth, driver.filter())
                .map_err(validation_to_fusion)?;
        }
    }
    Ok((detected, early + driver.health(1).faults, dropped))
}

fn validation_to_fusion(e: ValidationError) -> FusionError {
    match e {
        ValidationError::Estimation(e) => FusionError::Filter(e),
        other => panic!("the example's slots are valid: {other}"),
    }
}

/// The detection-delay bound of the stuck channel \[s\]: its first stuck fix repeats the true
/// value, every later one is off by ≈ 20 m (NIS ≫ c), and ⌈q / c⌉ such fixes fill the
/// monitor's window past q; the last of them arrives at most the largest latency later. Plus
/// one fix period because the onset need not fall on a fix.
pub fn detection_bound(config: &DelayConfig) -> Result<f64, FusionError> {
    let s = config.scenario;
    let driver = make_driver(&s, Method::Robust)?;
    let (q, c) = driver
        .monitor_thresholds(0)
        .expect("the robust method has a monitor");
    let period = s.gps_every as f64 * s.dt;
    Ok(((q / c).ceil() + 2.0) * period + config.max_latency_steps as f64 * s.dt)
}

/// The six configurations: two scenarios × three methods.
pub fn configs(quick: bool) -> Vec<DelayConfig> {
    let mut out = Vec::new();
    for faults in [false, true] {
        for method in Method::ALL {
            out.push(if faults {
                DelayConfig::faults(quick, method)
            } else {
                DelayConfig::latency(quick, method)
            });
        }
    }
    out
}

/// Each result's curve `f`, in log10, labelled by its method.
fn log_curves(
    results: &[DelayResult],
    f: impl Fn(&DelayResult) -> Vec<(f64, f64)>,
) -> Vec<(&'static str, Vec<(f64, f64)>)> {
    results
        .iter()
        .map(|r| {
            let points = f(r).iter().map(|&(t, v)| (t, v.log10())).collect();
            (r.config.method.label(), points)
        })
        .collect()
}

fn as_series<'a>(curves: &'a [(&'static str, Vec<(f64, f64)>)]) -> Vec<Series<'a>> {
    curves
        .iter()
        .map(|(label, points)| Series {
            label,
            points: points.clone(),
        })
        .collect()
}

/// The example body.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(run_in(quick, &Session::whole())?)?)
}

/// The example body as `session` says (whole, one shard: `None`, or the merge of the shards).
pub fn run_in(
    quick: bool,
    session: &Session,
) -> Result<Option<Output>, Box<dyn std::error::Error>> {
    let start = Instant::now();
    let results = configs(quick)
        .iter()
        .map(|c| run_config_in(c, session))
        .collect::<Result<Vec<_>, _>>()?;
    // Every configuration runs (its shard) before a shard stops here.
    let Some(results) = results.into_iter().collect::<Option<Vec<_>>>() else {
        return Ok(None);
    };
    let wall_s = start.elapsed().as_secs_f64();
    let first = &results[0].config;
    println!(
        "Lu + GPS latency (estim's extension, not in the paper): {} runs x {} s, latency 0-{} ms, wall {wall_s:.2} s\n",
        first.runs,
        first.scenario.duration(),
        first.max_latency_steps as f64 * first.scenario.dt * 1e3
    );
    let band = estim::filters::consistency::ChiSquareBand::two_sided(3, first.runs, 0.99)?;
    println!(
        "  {:<27} | {:<35} | {:>10} | {:>8} | {:>9} | {:>10} | detection delay (mean / max, detected)",
        "scenario", "method", "ANEES", "in band", "RMS dp [m]", "RMS dv [m/s]"
    );
    let mut rows = Vec::new();
    for r in &results {
        let detection = r.detection();
        let detection_text = match (r.config.stuck_from, detection) {
            (None, _) => "-".to_string(),
            (Some(_), _) if r.config.method != Method::Robust => "(no monitor)".to_string(),
            (Some(_), None) => "not detected".to_string(),
            (Some(_), Some((m, x, n))) => format!("{m:.2} s / {x:.2} s, {n}/{}", r.config.runs),
        };
        println!(
            "  {:<27} | {:<35} | {:>10.3} | {:>7.0}% | {:>9.3} | {:>10.4} | {detection_text}",
            r.config.scenario_label(),
            r.config.method.label(),
            r.mean_anees(),
            100.0 * r.fraction_in_band(),
            r.mean_rms(0),
            r.mean_rms(1),
        );
        rows.push(serde_json::json!({
            "scenario": r.config.scenario_label(),
            "method": r.config.method.label(),
            "anees": r.mean_anees(),
            "fraction_in_band": r.fraction_in_band(),
            "rms_position": r.mean_rms(0),
            "rms_velocity": r.mean_rms(1),
            "detection_mean_s": detection.map(|d| d.0),
            "detection_max_s": detection.map(|d| d.1),
            "detected_runs": detection.map(|d| d.2),
            "early_exclusions": r.early_exclusions.iter().sum::<u64>(),
            "dropped": r.dropped,
        }));
    }
    println!(
        "\n  ANEES: mean over the 0.2 s slots after 1 s; 99 % band of one slot [{:.3}, {:.3}]; 'in band': share of slots inside it.",
        band.lower, band.upper
    );

    let mut figures = Vec::new();
    let curves = log_curves(&results[..3], DelayResult::anees);
    let series = as_series(&curves);
    let times: Vec<f64> = curves[0].1.iter().map(|p| p.0).collect();
    let bands = [Band {
        label: "99 % band (ANEES of a consistent filter)",
        points: times
            .iter()
            .map(|&t| (t, band.lower.log10(), band.upper.log10()))
            .collect(),
    }];
    if let Ok(p) = band_plot(
        "lu_delays_anees.svg",
        "Lu + GPS latency 0-300 ms: real-time ANEES (estim's extension)",
        "t [s]",
        "log10 ANEES",
        &series,
        &bands,
    ) {
        figures.push(p);
    }
    let curves = log_curves(&results[3..], |r| r.rms(0));
    let series = as_series(&curves);
    if let Ok(p) = line_plot(
        "lu_delays_faults_rms.svg",
        "Lu + latency, 100-sigma outliers, stuck position: RMS position error (estim's extension)",
        "t [s]",
        "log10 RMS position error [m]",
        &series,
    ) {
        figures.push(p);
    }
    for f in &figures {
        println!("  figure: {}", f.display());
    }

    let find = |faults: bool, method: Method| {
        results
            .iter()
            .find(|r| r.config.method == method && r.config.stuck_from.is_some() == faults)
            .expect("every configuration ran")
    };
    let not_in_paper = "not in the paper (estim's extension)".to_string();
    let ignored = find(false, Method::LatencyIgnored);
    let taken = find(false, Method::AtTimeTaken);
    let robust = find(true, Method::Robust);
    let headlines = vec![
        Headline {
            quantity: "GPS latency 0-300 ms: real-time ANEES (3 states)".into(),
            paper: not_in_paper.clone(),
            estim: format!(
                "latency ignored {:.1}; fused at the time taken {:.3} ({:.0} % of slots in the 99 % band)",
                ignored.mean_anees(),
                taken.mean_anees(),
                100.0 * taken.fraction_in_band()
            ),
            note: "fusing a late fix as current puts the position off by v x latency (100 m/s x 0.15 s on average)".into(),
        },
        Headline {
            quantity: "100-sigma outliers and a stuck position channel: RMS position error".into(),
            paper: not_in_paper.clone(),
            estim: format!(
                "at time taken, no gate {:.2} m; delayed + gating + fault exclusion {:.3} m (ANEES {:.3})",
                find(true, Method::AtTimeTaken).mean_rms(0),
                robust.mean_rms(0),
                robust.mean_anees()
            ),
            note: String::new(),
        },
        Headline {
            quantity: "stuck position channel: detection delay".into(),
            paper: not_in_paper,
            estim: match robust.detection() {
                Some((m, x, n)) => format!("mean {m:.2} s, max {x:.2} s ({n}/{} runs)", robust.config.runs),
                None => "not detected".into(),
            },
            note: format!(
                "bound {:.2} s: (ceil(q/c) + 2) fixes of 0.2 s + 0.3 s latency, q = chi2_20(1 - 1e-4) = 52.4, c = chi2_1(0.99) = 6.63",
                detection_bound(&robust.config)?
            ),
        },
    ];
    println!("\nHeadlines:");
    for h in &headlines {
        println!("- {h}");
    }
    Ok(Some(Output {
        json: serde_json::json!({ "configs": rows, "wall_s": wall_s }),
        headlines,
    }))
}
