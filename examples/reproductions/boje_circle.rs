//! Boje section 4: the circle example (Table 1) with the 6-state filter of eq 14–16 —
//! Monte Carlo with correct initial conditions (Fig 3), a run with wrong initial conditions
//! (Fig 2), and (beyond the paper) the same data through a process with θ inside f, run by the
//! EKF, the second-order EKF and the UKF; and every Monte Carlo run smoothed (RTS, EKF on the
//! paper's process), filtered vs smoothed errors.
//!
//! Reading of the scenario (see `estim::models::boje` docs): rigid arm, CG on a 10 m circle,
//! heading tangent, ω = sgn(t − t_end/2)·0.1·t rad/s, t_end = 20 s. "Settled" = t ∈ [2, 20] s.
//!
//! `cargo run --release --example boje_circle [-- --json] [-- --quick]`
//!
//! Its seven Monte Carlos (the main one, the five variants, the smoothed one) also run in
//! shards (`--shard I/N --out FILE`, `--merge FILE...`, `--stats FILE`; `sharding`): their
//! per-step sums over runs go through [`ExactSums`], so a shard file holds each sum's exact
//! state (a few `f64` per sum, whatever the shard's run count), not every run's 192 000
//! terms, and the merge gives the bits of one process.

use crate::common::{Band, Headline, Output, Series, band_plot, line_plot};
use crate::exact_sum::ExactSums;
use crate::sharding::{self, Session};
use estim::core::error::Result;
use estim::core::nalgebra::{Matrix6, U6, Vector6};
use estim::core::nalgebra::{Matrix6x1, Vector1};
use estim::core::{Gaussian, MeasurementJacobian, MeasurementModel, ProcessJacobian, ProcessModel};
use estim::filters::smoother::Rts;
use estim::filters::{Ekf, Estimator, SecondOrderEkf, Ukf, Update};
use estim::models::boje::circle::initial_prior;
use estim::models::boje::filter::{
    AccelerometerProcess, HEADING, NonlinearPlanarProcess, PlanarFilter, PlanarProcess,
    RateSquaredMeasurement, VX, VY, X, Y, filter_step,
};
use estim::models::boje::geometry::rate_squared;
use estim::models::boje::{
    CircleConfig, CircleData, FilterKind, InitialConditions, ProcessKind, simulate_circle,
    wrap_angle,
};

/// The estimates of one filter run.
#[derive(Clone, Debug, PartialEq)]
pub struct FilterTrace {
    /// tᵢ, i = 0..=K.
    pub times: Vec<f64>,
    /// The one-step prediction x̂ᵢ (the paper's x̂ᵢ).
    pub estimates: Vec<Vector6<f64>>,
    /// xᵢ − x̂ᵢ (heading wrapped).
    pub errors: Vec<Vector6<f64>>,
    /// √diag(Pᵢ).
    pub sqrt_p: Vec<Vector6<f64>>,
    /// NIS of the θ̇² update at each step i < K.
    pub rate_nis: Vec<f64>,
    /// (tᵢ, NIS) of each GPS/compass update.
    pub fix_nis: Vec<(f64, f64)>,
}

fn record(
    trace: &mut FilterTrace,
    t: f64,
    truth: &Vector6<f64>,
    x: &Vector6<f64>,
    p: &Matrix6<f64>,
) {
    let mut e = truth - x;
    e[HEADING] = wrap_angle(e[HEADING]);
    trace.times.push(t);
    trace.estimates.push(*x);
    trace.errors.push(e);
    trace.sqrt_p.push(p.diagonal().map(|v| v.max(0.0).sqrt()));
}

fn run_with<F, P>(
    mut filter: F,
    process: &P,
    data: &CircleData,
    config: &CircleConfig,
) -> Result<FilterTrace>
where
    P: AccelerometerProcess,
    F: PlanarFilter<P>,
{
    let fix_model = config.fix_model();
    let n = data.truth.len();
    let mut trace = FilterTrace {
        times: Vec::with_capacity(n),
        estimates: Vec::with_capacity(n),
        errors: Vec::with_capacity(n),
        sqrt_p: Vec::with_capacity(n),
        rate_nis: Vec::with_capacity(n),
        fix_nis: Vec::new(),
    };
    for (i, accel) in data.accel.iter().enumerate() {
        record(
            &mut trace,
            data.times[i],
            &data.truth[i],
            filter.state(),
            filter.covariance(),
        );
        let fix = data.fixes[i].as_ref().map(|z| (&fix_model, z));
        let report = filter_step(&mut filter, process, accel, fix, config.dt)?;
        trace.rate_nis.push(report.rate_nis);
        if let Some(nis) = report.fix_nis {
            trace.fix_nis.push((data.times[i], nis));
        }
    }
    let last = n - 1;
    record(
        &mut trace,
        data.times[last],
        &data.truth[last],
        filter.state(),
        filter.covariance(),
    );
    Ok(trace)
}

/// Runs the configured filter and process on `data` from `prior`.
///
/// Errors: filter errors (see [`filter_step`]).
pub fn run_circle_filter(
    data: &CircleData,
    config: &CircleConfig,
    prior: Gaussian<f64, U6>,
) -> Result<FilterTrace> {
    let linear = PlanarProcess {
        half_separation: config.half_separation,
        variances: config.variances(),
    };
    let nonlinear = NonlinearPlanarProcess {
        half_separation: config.half_separation,
        variances: config.variances(),
    };
    match (config.process, config.filter) {
        (ProcessKind::Linear, FilterKind::Ekf) => run_with(Ekf::new(prior), &linear, data, config),
        (ProcessKind::Linear, FilterKind::SecondOrderEkf) => {
            run_with(SecondOrderEkf::new(prior), &linear, data, config)
        }
        (ProcessKind::Linear, FilterKind::Ukf) => run_with(Ukf::new(prior), &linear, data, config),
        (ProcessKind::Nonlinear, FilterKind::Ekf) => {
            run_with(Ekf::new(prior), &nonlinear, data, config)
        }
        (ProcessKind::Nonlinear, FilterKind::SecondOrderEkf) => {
            run_with(SecondOrderEkf::new(prior), &nonlinear, data, config)
        }
        (ProcessKind::Nonlinear, FilterKind::Ukf) => {
            run_with(Ukf::new(prior), &nonlinear, data, config)
        }
    }
}

/// Per-state-component averages over the settled part and all runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StateStats {
    /// Mean of √P_jj, order (ẋ, ẏ, θ̇, x, y, θ).
    pub sqrt_p: Vector6<f64>,
    /// RMS of the error (heading wrapped).
    pub rms: Vector6<f64>,
}

impl StateStats {
    /// rms / mean √P per component (≈ 1 for a consistent filter).
    pub fn ratio(&self) -> Vector6<f64> {
        self.rms.component_div(&self.sqrt_p)
    }

    /// Position √P averaged over x and y, m.
    pub fn position_sqrt_p(&self) -> f64 {
        0.5 * (self.sqrt_p[X] + self.sqrt_p[Y])
    }

    /// Position RMS error per axis, √((rms_x² + rms_y²)/2), m.
    pub fn position_rms(&self) -> f64 {
        (0.5 * (self.rms[X].powi(2) + self.rms[Y].powi(2))).sqrt()
    }

    /// Velocity √P averaged over ẋ and ẏ, m/s.
    pub fn velocity_sqrt_p(&self) -> f64 {
        0.5 * (self.sqrt_p[VX] + self.sqrt_p[VY])
    }

    /// Velocity RMS error per axis, m/s.
    pub fn velocity_rms(&self) -> f64 {
        (0.5 * (self.rms[VX].powi(2) + self.rms[VY].powi(2))).sqrt()
    }
}

/// Per-step sums over runs of the squared errors and √P: each run adds its terms to
/// [`ExactSums`] ([`add_trace`]), whose values do not depend on the order of the additions, so
/// shards of the runs merge to the bits of one process.
struct Accumulator {
    sum_sq: Vec<Vector6<f64>>,
    sum_sqrt_p: Vec<Vector6<f64>>,
    runs: usize,
}

/// The sums [`add_trace`] fills for `n` steps: the squared errors (6 per step), then √P.
fn trace_sums(n: usize) -> usize {
    12 * n
}

/// Adds a run's squared errors and √P at each step to the sums at `offset..offset +
/// trace_sums(n)`.
fn add_trace(sums: &mut ExactSums, offset: usize, trace: &FilterTrace) {
    let n = trace.errors.len();
    for (i, (e, s)) in trace.errors.iter().zip(&trace.sqrt_p).enumerate() {
        sums.add_slice(offset + 6 * i, e.component_mul(e).as_slice());
        sums.add_slice(offset + 6 * (n + i), s.as_slice());
    }
}

impl Accumulator {
    /// The sums over `runs` runs that [`add_trace`] filled for `n` steps at `offset`.
    fn from_sums(sums: &ExactSums, offset: usize, n: usize, runs: usize) -> Self {
        let at = |base: usize| -> Vec<Vector6<f64>> {
            (0..n)
                .map(|i| Vector6::from_fn(|j, _| sums.value(base + 6 * i + j)))
                .collect()
        };
        Self {
            sum_sq: at(offset),
            sum_sqrt_p: at(offset + 6 * n),
            runs,
        }
    }

    fn stats(&self, times: &[f64], from: f64, to: f64) -> StateStats {
        let (mut sq, mut sp, mut n) = (Vector6::zeros(), Vector6::zeros(), 0.0);
        for (i, t) in times.iter().enumerate() {
            if *t >= from && *t <= to {
                sq += self.sum_sq[i];
                sp += self.sum_sqrt_p[i];
                n += self.runs as f64;
            }
        }
        StateStats {
            sqrt_p: sp / n,
            rms: (sq / n).map(f64::sqrt),
        }
    }

    fn rms_over_time(&self) -> Vec<Vector6<f64>> {
        let n = self.runs as f64;
        self.sum_sq.iter().map(|s| (s / n).map(f64::sqrt)).collect()
    }

    fn sqrt_p_over_time(&self) -> Vec<Vector6<f64>> {
        let n = self.runs as f64;
        self.sum_sqrt_p.iter().map(|s| s / n).collect()
    }
}

/// One Monte Carlo summary (any filter/process pair).
#[derive(Clone, Debug, PartialEq)]
pub struct MonteCarloSummary {
    /// The filter.
    pub filter: FilterKind,
    /// The process model.
    pub process: ProcessKind,
    /// Runs.
    pub runs: usize,
    /// Averages over the settled part, t ∈ [settle_time, t_end].
    pub settled: StateStats,
    /// Averages over the second half, t ∈ [t_end/2, t_end] (after the rate reversal, largest
    /// accelerations).
    pub second_half: StateStats,
    /// Mean NIS of the θ̇² updates in the settled part (1 for a consistent filter).
    pub mean_rate_nis: f64,
    /// Mean NIS of the GPS/compass updates in the settled part (3 for a consistent filter).
    pub mean_fix_nis: f64,
    /// RMS error across runs at each step.
    pub rms_over_time: Vec<Vector6<f64>>,
    /// Mean √P across runs at each step.
    pub sqrt_p_over_time: Vec<Vector6<f64>>,
}

/// Runs `config.runs` Monte Carlo runs of the configured filter/process with
/// `config.initial`; run k uses the data of seed `config.seed + k`. Also returns run 0's data
/// and trace.
///
/// Errors: invalid configuration, filter errors.
pub fn circle_monte_carlo(
    config: &CircleConfig,
) -> Result<(MonteCarloSummary, CircleData, FilterTrace), Box<dyn std::error::Error>> {
    let (summary, first) = sharding::whole(circle_monte_carlo_in(
        config,
        "main",
        true,
        &Session::whole(),
    )?)?;
    let (data, trace) = sharding::whole(first)?;
    Ok((summary, data, trace))
}

/// Run `run` of the circle Monte Carlo: its data (seed `config.seed + run`) and the filter's
/// trace from the prior of `config.initial`.
fn circle_run(config: &CircleConfig, run: usize) -> Result<(CircleData, FilterTrace)> {
    let seed = config.seed.wrapping_add(run as u64);
    let data = simulate_circle(config, seed)?;
    let prior = initial_prior(&data.truth[0], &config.initial, seed)?;
    let trace = run_circle_filter(&data, config, prior)?;
    Ok((data, trace))
}

/// A Monte Carlo's summary and, when asked for, run 0's data and trace.
pub type SummaryAndFirst = (MonteCarloSummary, Option<(CircleData, FilterTrace)>);

/// [`circle_monte_carlo`] as experiment `key` of `session`: `None` in a shard; with `first`,
/// run 0's data and trace too (a merge runs run 0 again for them: same seed, same bits).
pub fn circle_monte_carlo_in(
    config: &CircleConfig,
    key: &str,
    first: bool,
    session: &Session,
) -> Result<Option<SummaryAndFirst>, Box<dyn std::error::Error>> {
    config.validate()?;
    let n = config.steps() + 1;
    // The traces' sums, then the settled NIS sums and counts: θ̇², fixes.
    let nis = trace_sums(n);
    let mut kept = None;
    let sums = session.sums(key, config.runs, nis + 4, |run, sums| {
        let (data, trace) = circle_run(config, run)?;
        add_trace(sums, 0, &trace);
        let (mut rate_nis, mut rate_n, mut fix_nis, mut fix_n) = (0.0, 0usize, 0.0, 0usize);
        for (t, nis) in trace.times.iter().zip(&trace.rate_nis) {
            if *t >= config.settle_time {
                rate_nis += nis;
                rate_n += 1;
            }
        }
        for (t, nis) in &trace.fix_nis {
            if *t >= config.settle_time {
                fix_nis += nis;
                fix_n += 1;
            }
        }
        sums.add_slice(nis, &[rate_nis, rate_n as f64, fix_nis, fix_n as f64]);
        if first && run == 0 {
            kept = Some((data, trace));
        }
        Ok(())
    })?;
    let Some(sums) = sums else {
        return Ok(None);
    };
    let kept = match kept {
        Some(k) => Some(k),
        None if first => Some(circle_run(config, 0)?),
        None => None,
    };
    // The step times (the same in every run).
    let times: Vec<f64> = (0..n).map(|i| i as f64 * config.dt).collect();
    let acc = Accumulator::from_sums(&sums, 0, n, config.runs);
    let summary = MonteCarloSummary {
        filter: config.filter,
        process: config.process,
        runs: config.runs,
        settled: acc.stats(&times, config.settle_time, config.t_end),
        second_half: acc.stats(&times, config.t_end / 2.0, config.t_end),
        mean_rate_nis: sums.value(nis) / sums.value(nis + 1).max(1.0),
        mean_fix_nis: sums.value(nis + 2) / sums.value(nis + 3).max(1.0),
        rms_over_time: acc.rms_over_time(),
        sqrt_p_over_time: acc.sqrt_p_over_time(),
    };
    Ok(Some((summary, kept)))
}

/// What [`circle_experiment`] returns.
#[derive(Clone, Debug, PartialEq)]
pub struct CircleResult {
    /// The settings used.
    pub config: CircleConfig,
    /// The Monte Carlo of the configured filter (correct ICs by default).
    pub monte_carlo: MonteCarloSummary,
    /// Position √P (mean of √P_xx, √P_yy over the settled part and runs), m.
    pub pos_sqrt_p_m: f64,
    /// Position RMS error per axis over the settled part, m.
    pub pos_rms_m: f64,
    /// Heading √P, rad.
    pub heading_sqrt_p_rad: f64,
    /// Heading RMS error, rad.
    pub heading_rms_rad: f64,
    /// Velocity √P (mean over ẋ, ẏ), m/s.
    pub vel_sqrt_p_m_s: f64,
    /// Velocity RMS error per axis, m/s.
    pub vel_rms_m_s: f64,
    /// Run 0's data (truth, samples, fixes).
    pub example_data: CircleData,
    /// Run 0's trace.
    pub example_run: FilterTrace,
    /// The wrong-IC run (Fig 2) on run 0's data.
    pub wrong_ic_run: FilterTrace,
    /// Largest distance of the discrete truth from the 10 m circle (run 0), m.
    pub truth_circle_deviation_m: f64,
}

/// Runs the circle example: the Monte Carlo with `config.initial`, and the Fig 2 wrong-IC run
/// on run 0's data.
///
/// Errors: invalid configuration, filter errors.
pub fn circle_experiment(
    config: &CircleConfig,
) -> Result<CircleResult, Box<dyn std::error::Error>> {
    Ok(sharding::whole(circle_experiment_in(
        config,
        &Session::whole(),
    )?)?)
}

/// [`circle_experiment`] in `session`: `None` in a shard.
pub fn circle_experiment_in(
    config: &CircleConfig,
    session: &Session,
) -> Result<Option<CircleResult>, Box<dyn std::error::Error>> {
    let Some((mc, first)) = circle_monte_carlo_in(config, "main", true, session)? else {
        return Ok(None);
    };
    let (data, trace) = sharding::whole(first)?;
    let wrong_prior = initial_prior(&data.truth[0], &InitialConditions::wrong(), config.seed)?;
    let wrong = run_circle_filter(&data, config, wrong_prior)?;
    let deviation = data
        .truth
        .iter()
        .map(|x| ((x[X].powi(2) + x[Y].powi(2)).sqrt() - config.circle_radius).abs())
        .fold(0.0, f64::max);
    let s = mc.settled;
    Ok(Some(CircleResult {
        config: *config,
        pos_sqrt_p_m: s.position_sqrt_p(),
        pos_rms_m: s.position_rms(),
        heading_sqrt_p_rad: s.sqrt_p[HEADING],
        heading_rms_rad: s.rms[HEADING],
        vel_sqrt_p_m_s: s.velocity_sqrt_p(),
        vel_rms_m_s: s.velocity_rms(),
        monte_carlo: mc,
        example_data: data,
        example_run: trace,
        wrong_ic_run: wrong,
        truth_circle_deviation_m: deviation,
    }))
}

/// The same Monte Carlo (same data seeds, same ICs) for each (process, filter) pair: the
/// paper's linear process with EKF and second-order EKF, and the nonlinear process with EKF,
/// second-order EKF and UKF.
///
/// Errors: as [`circle_monte_carlo`].
pub fn circle_variants(
    config: &CircleConfig,
) -> Result<Vec<MonteCarloSummary>, Box<dyn std::error::Error>> {
    sharding::whole(circle_variants_in(config, &Session::whole())?).map_err(Into::into)
}

/// [`circle_variants`] in `session`: `None` in a shard.
pub fn circle_variants_in(
    config: &CircleConfig,
    session: &Session,
) -> Result<Option<Vec<MonteCarloSummary>>, Box<dyn std::error::Error>> {
    let pairs = [
        (ProcessKind::Linear, FilterKind::Ekf),
        (ProcessKind::Linear, FilterKind::SecondOrderEkf),
        (ProcessKind::Nonlinear, FilterKind::Ekf),
        (ProcessKind::Nonlinear, FilterKind::SecondOrderEkf),
        (ProcessKind::Nonlinear, FilterKind::Ukf),
    ];
    // Every variant runs (a shard runs its part of each: no short cut at the first `None`).
    let summaries = pairs
        .iter()
        .map(|&(process, filter)| {
            let c = CircleConfig {
                process,
                filter,
                ..*config
            };
            let key = format!("{process:?} process, {filter:?}");
            Ok(circle_monte_carlo_in(&c, &key, false, session)?.map(|(s, _)| s))
        })
        .collect::<Result<Vec<_>, Box<dyn std::error::Error>>>()?;
    Ok(summaries.into_iter().collect())
}

/// One headline per variant of [`circle_variants`]: the settled velocity consistency
/// (RMS/√P for ẋ, ẏ) beside the position and heading √P.
pub fn variant_headlines(variants: &[MonteCarloSummary]) -> Vec<Headline> {
    variants
        .iter()
        .map(|s| {
            let r = s.settled.ratio();
            Headline {
                quantity: format!("velocity RMS/√P, {:?} process, {:?}", s.process, s.filter),
                paper: "— (the paper's model folds σ²_θ into Q)".into(),
                estim: format!(
                    "ẋ {:.2}, ẏ {:.2} (2nd half ẋ {:.2}); √P pos {:.3} m, θ {:.4} rad; {} runs",
                    r[VX],
                    r[VY],
                    s.second_half.ratio()[VX],
                    s.settled.position_sqrt_p(),
                    s.settled.sqrt_p[HEADING],
                    s.runs
                ),
                note: match s.process {
                    ProcessKind::Linear => {
                        "heading error treated as white input noise: velocity P optimistic".into()
                    }
                    ProcessKind::Nonlinear => {
                        "θ inside f: heading–velocity coupling carried in P".into()
                    }
                },
            }
        })
        .collect()
}

impl CircleResult {
    /// Paper vs estim for section 4.
    pub fn headlines(&self) -> Vec<Headline> {
        let s = &self.monte_carlo.settled;
        vec![
            Headline {
                quantity: "position std (Fig 3c)".into(),
                paper: "around 0.5 m".into(),
                estim: format!(
                    "√P {:.3} m (x {:.3}, y {:.3}); RMS error {:.3} m",
                    self.pos_sqrt_p_m, s.sqrt_p[X], s.sqrt_p[Y], self.pos_rms_m
                ),
                note: format!(
                    "{} runs, t ∈ [{}, {}] s, t_end and orbit kinematics are estim's reading",
                    self.monte_carlo.runs, self.config.settle_time, self.config.t_end
                ),
            },
            Headline {
                quantity: "heading std".into(),
                paper: "only 0.01 rad".into(),
                estim: format!(
                    "√P {:.4} rad; RMS error {:.4} rad",
                    self.heading_sqrt_p_rad, self.heading_rms_rad
                ),
                note: "compass σ is 0.1 rad: the accuracy comes from the accelerometers, as the paper says".into(),
            },
            Headline {
                quantity: "velocity std (not quoted)".into(),
                paper: "—".into(),
                estim: format!(
                    "√P {:.4} m/s; RMS error {:.4} m/s (ratio ẋ {:.2}, ẏ {:.2})",
                    self.vel_sqrt_p_m_s,
                    self.vel_rms_m_s,
                    s.ratio()[VX],
                    s.ratio()[VY]
                ),
                note: "σ²_θ folded into Q as white noise ignores the heading-error correlation: velocity P is optimistic".into(),
            },
        ]
    }
}

/// One step of the paper's process with its noise decorrelated from the θ̇² noise of the same
/// sample, as [`filter_step`]'s `predict_correlated` runs it: x⁺ = f(x, u) + D (z − h(x)) + w*
/// with D = S R⁻¹ and cov w* = Q − S R⁻¹ Sᵀ (S at the updated estimate). Given z, w* is
/// independent of every other noise, so this is an ordinary process model and the RTS
/// smoother applies to it exactly (Särkkä 2013 §8.2 on the transformed model).
#[derive(Clone, Copy, Debug)]
struct DecorrelatedStep<P> {
    process: P,
    rate: RateSquaredMeasurement,
    z: f64,
    cross: Matrix6x1<f64>,
}

impl<P: ProcessModel<f64, U6>> ProcessModel<f64, U6> for DecorrelatedStep<P> {
    type Input = P::Input;
    fn transition(&self, x: &Vector6<f64>, u: &P::Input, dt: f64) -> Vector6<f64> {
        let residual = self.z - self.rate.measure(x)[0];
        self.process.transition(x, u, dt) + self.cross * (residual / self.rate.noise)
    }
    fn process_noise(&self, x: &Vector6<f64>, u: &P::Input, dt: f64) -> Matrix6<f64> {
        self.process.process_noise(x, u, dt) - self.cross * self.cross.transpose() / self.rate.noise
    }
}

impl<P: ProcessJacobian<f64, U6>> ProcessJacobian<f64, U6> for DecorrelatedStep<P> {
    fn transition_jacobian(&self, x: &Vector6<f64>, u: &P::Input, dt: f64) -> Matrix6<f64> {
        self.process.transition_jacobian(x, u, dt)
            - self.cross * self.rate.measurement_jacobian(x) / self.rate.noise
    }
}

fn empty_trace(n: usize) -> FilterTrace {
    FilterTrace {
        times: Vec::with_capacity(n),
        estimates: Vec::with_capacity(n),
        errors: Vec::with_capacity(n),
        sqrt_p: Vec::with_capacity(n),
        rate_nis: Vec::new(),
        fix_nis: Vec::new(),
    }
}

/// One circle run through the EKF on the paper's process, filtered and smoothed.
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothedCircleRun {
    /// The one-step predictions x̂ᵢ (what [`run_circle_filter`] records).
    pub predicted: Vec<Vector6<f64>>,
    /// The filtered estimates after the updates at tᵢ (the last: the prediction at t_K, where
    /// no sample is processed), with their errors and √P.
    pub filtered: FilterTrace,
    /// The smoothed estimates given the whole run (RTS), at the same times.
    pub smoothed: FilterTrace,
}

/// Runs the paper's filter ([`filter_step`]'s steps: θ̇² update, fix update, decorrelated
/// prediction) with the EKF on the paper's process, recording each prediction through
/// [`Rts`], and smooths the run.
///
/// Errors: filter errors, a failed backward step.
pub fn smooth_circle_run(
    data: &CircleData,
    config: &CircleConfig,
    prior: Gaussian<f64, U6>,
) -> core::result::Result<SmoothedCircleRun, Box<dyn std::error::Error>> {
    let process = PlanarProcess {
        half_separation: config.half_separation,
        variances: config.variances(),
    };
    let (rate, fix_model) = (process.rate_measurement(), config.fix_model());
    let n = data.truth.len();
    let mut filter = Ekf::new(prior);
    let mut rts = Rts::new();
    let (mut predicted, mut filtered) = (Vec::with_capacity(n), empty_trace(n));
    for (i, accel) in data.accel.iter().enumerate() {
        predicted.push(*filter.state());
        let input = process.input(accel, filter.state(), filter.covariance())?;
        let z = rate_squared(accel, config.half_separation);
        let report = filter.update(&rate, &Vector1::new(z))?;
        filtered.rate_nis.push(report.nis);
        if let Some(y) = &data.fixes[i] {
            let report = filter.update(&fix_model, y)?;
            filtered.fix_nis.push((data.times[i], report.nis));
        }
        record(
            &mut filtered,
            data.times[i],
            &data.truth[i],
            filter.state(),
            filter.covariance(),
        );
        let cross = process.noise_cross_covariance(&input, filter.state(), config.dt);
        let step = DecorrelatedStep {
            process,
            rate,
            z,
            cross,
        };
        rts.predict(&mut filter, &step, &input, config.dt)?;
    }
    let last = n - 1;
    predicted.push(*filter.state());
    record(
        &mut filtered,
        data.times[last],
        &data.truth[last],
        filter.state(),
        filter.covariance(),
    );
    let mut smoothed = empty_trace(n);
    for (i, g) in rts.smooth(&filter)?.iter().enumerate() {
        record(
            &mut smoothed,
            data.times[i],
            &data.truth[i],
            g.mean(),
            g.covariance(),
        );
    }
    Ok(SmoothedCircleRun {
        predicted,
        filtered,
        smoothed,
    })
}

/// The smoothed circle Monte Carlo (EKF, paper's process, the runs and seeds of
/// [`circle_monte_carlo`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CircleSmoothing {
    /// Runs.
    pub runs: usize,
    /// The filter after each sample's updates, over the settled part.
    pub filtered: StateStats,
    /// The smoother, over the settled part.
    pub smoothed: StateStats,
    /// RMS error across runs at each step, filter.
    pub filtered_rms_over_time: Vec<Vector6<f64>>,
    /// RMS error across runs at each step, smoother.
    pub smoothed_rms_over_time: Vec<Vector6<f64>>,
    /// Run 0, filtered and smoothed.
    pub example: SmoothedCircleRun,
    /// Wall time of the whole smoothed Monte Carlo (forward and backward) \[s\].
    pub wall_s: f64,
}

/// Smooths every run of the circle Monte Carlo (`config.runs`, seeds `config.seed + k`, priors
/// from `config.initial`).
///
/// Errors: invalid configuration, filter errors, a failed backward step.
pub fn circle_smoothing(
    config: &CircleConfig,
) -> core::result::Result<CircleSmoothing, Box<dyn std::error::Error>> {
    Ok(sharding::whole(circle_smoothing_in(
        config,
        &Session::whole(),
    )?)?)
}

/// Run `run` of the smoothed circle Monte Carlo.
fn smoothing_run(
    config: &CircleConfig,
    run: usize,
) -> core::result::Result<SmoothedCircleRun, Box<dyn std::error::Error>> {
    let seed = config.seed.wrapping_add(run as u64);
    let data = simulate_circle(config, seed)?;
    let prior = initial_prior(&data.truth[0], &config.initial, seed)?;
    smooth_circle_run(&data, config, prior)
}

/// [`circle_smoothing`] in `session`: `None` in a shard (a merge runs run 0 again for the
/// example run: same seed, same bits).
pub fn circle_smoothing_in(
    config: &CircleConfig,
    session: &Session,
) -> core::result::Result<Option<CircleSmoothing>, Box<dyn std::error::Error>> {
    config.validate()?;
    let start = std::time::Instant::now();
    let steps = config.steps() + 1;
    let mut example = None;
    let sums = session.sums(
        "smoothing",
        config.runs,
        2 * trace_sums(steps),
        |run, sums| {
            let r = smoothing_run(config, run)?;
            add_trace(sums, 0, &r.filtered);
            add_trace(sums, trace_sums(steps), &r.smoothed);
            if run == 0 {
                example = Some(r);
            }
            Ok(())
        },
    )?;
    let Some(sums) = sums else {
        return Ok(None);
    };
    let example = match example {
        Some(e) => e,
        None => smoothing_run(config, 0)?,
    };
    let times = &example.filtered.times;
    let filtered = Accumulator::from_sums(&sums, 0, steps, config.runs);
    let smoothed = Accumulator::from_sums(&sums, trace_sums(steps), steps, config.runs);
    Ok(Some(CircleSmoothing {
        runs: config.runs,
        filtered: filtered.stats(times, config.settle_time, config.t_end),
        smoothed: smoothed.stats(times, config.settle_time, config.t_end),
        filtered_rms_over_time: filtered.rms_over_time(),
        smoothed_rms_over_time: smoothed.rms_over_time(),
        example,
        wall_s: start.elapsed().as_secs_f64(),
    }))
}

impl CircleSmoothing {
    /// The smoothing headline.
    pub fn headline(&self) -> Headline {
        let (f, s) = (&self.filtered, &self.smoothed);
        Headline {
            quantity: "circle run smoothed (RTS)".into(),
            paper: "forward filter only".into(),
            estim: format!(
                "settled RMS, filter → smoother ({} runs): position {:.3} → {:.3} m, heading {:.4} → {:.4} rad, velocity {:.4} → {:.4} m/s",
                self.runs,
                f.position_rms(),
                s.position_rms(),
                f.rms[HEADING],
                s.rms[HEADING],
                f.velocity_rms(),
                s.velocity_rms()
            ),
            note: "filter after each sample's θ̇² and fix updates; the smoother runs the same EKF \
                   steps (decorrelated prediction) backwards. It inherits the filter's velocity \
                   inconsistency (settled RMS/√P > 1, see the table above), more so as its √P is \
                   smaller"
                .into(),
        }
    }

    /// The JSON entry.
    pub fn json(&self) -> serde_json::Value {
        let (f, s) = (&self.filtered, &self.smoothed);
        serde_json::json!({
            "runs": self.runs,
            "pos_rms_m_filtered_smoothed": [f.position_rms(), s.position_rms()],
            "heading_rms_rad_filtered_smoothed": [f.rms[HEADING], s.rms[HEADING]],
            "vel_rms_m_s_filtered_smoothed": [f.velocity_rms(), s.velocity_rms()],
            "pos_sqrt_p_m_filtered_smoothed": [f.position_sqrt_p(), s.position_sqrt_p()],
            "heading_sqrt_p_rad_filtered_smoothed": [f.sqrt_p[HEADING], s.sqrt_p[HEADING]],
            "wall_s": self.wall_s,
        })
    }

    fn table(&self) {
        println!(
            "smoothed ({} runs, EKF, paper process; settled part; filter = after each sample's updates; {:.2} s):",
            self.runs, self.wall_s
        );
        println!(
            "{:<12} {:>12} {:>12} {:>14} {:>14}",
            "state", "filter √P", "filter RMS", "smoother √P", "smoother RMS"
        );
        for j in 0..6 {
            println!(
                "{:<12} {:>12.5} {:>12.5} {:>14.5} {:>14.5}",
                NAMES[j],
                self.filtered.sqrt_p[j],
                self.filtered.rms[j],
                self.smoothed.sqrt_p[j],
                self.smoothed.rms[j]
            );
        }
    }

    fn figures(&self) {
        let ex = &self.example;
        for (file, title, unit, j) in [
            (
                "boje_circle_smoothed_position.svg",
                "Boje circle, run 1: x error, filter vs RTS smoother, ±√P",
                "m",
                X,
            ),
            (
                "boje_circle_smoothed_heading.svg",
                "Boje circle, run 1: heading error, filter vs RTS smoother, ±√P",
                "rad",
                HEADING,
            ),
        ] {
            let line = |t: &FilterTrace| -> Vec<(f64, f64)> {
                t.times
                    .iter()
                    .zip(&t.errors)
                    .map(|(t, e)| (*t, e[j]))
                    .collect()
            };
            let band = |t: &FilterTrace| -> Vec<(f64, f64, f64)> {
                t.times
                    .iter()
                    .zip(&t.sqrt_p)
                    .map(|(t, s)| (*t, -s[j], s[j]))
                    .collect()
            };
            let rms = |v: &[Vector6<f64>]| -> Vec<(f64, f64)> {
                ex.filtered
                    .times
                    .iter()
                    .zip(v)
                    .map(|(t, e)| (*t, e[j]))
                    .collect()
            };
            match band_plot(
                file,
                title,
                "t (s)",
                unit,
                &[
                    Series {
                        label: "filter error",
                        points: line(&ex.filtered),
                    },
                    Series {
                        label: "smoother error",
                        points: line(&ex.smoothed),
                    },
                    Series {
                        label: "filter Monte Carlo RMS",
                        points: rms(&self.filtered_rms_over_time),
                    },
                    Series {
                        label: "smoother Monte Carlo RMS",
                        points: rms(&self.smoothed_rms_over_time),
                    },
                ],
                &[
                    Band {
                        label: "filter ±√P",
                        points: band(&ex.filtered),
                    },
                    Band {
                        label: "smoother ±√P",
                        points: band(&ex.smoothed),
                    },
                ],
            ) {
                Ok(p) => println!("figure: {}", p.display()),
                Err(e) => eprintln!("figure failed: {e}"),
            }
        }
    }
}

const NAMES: [&str; 6] = ["vx m/s", "vy m/s", "rate rad/s", "x m", "y m", "theta rad"];

fn plot_band(
    file: &str,
    title: &str,
    unit: &str,
    trace: &FilterTrace,
    rms: Option<&[f64]>,
    comps: &[(usize, &str)],
) {
    let t = &trace.times;
    let labels: Vec<_> = comps
        .iter()
        .map(|(_, name)| (format!("error {name}"), format!("±√P {name}")))
        .collect();
    let mut series: Vec<_> = comps
        .iter()
        .zip(&labels)
        .map(|((j, _), (label, _))| Series {
            label,
            points: t
                .iter()
                .zip(&trace.errors)
                .map(|(t, e)| (*t, e[*j]))
                .collect(),
        })
        .collect();
    let bands: Vec<_> = comps
        .iter()
        .zip(&labels)
        .map(|((j, _), (_, label))| Band {
            label,
            points: t
                .iter()
                .zip(&trace.sqrt_p)
                .map(|(t, s)| (*t, -s[*j], s[*j]))
                .collect(),
        })
        .collect();
    if let Some(rms) = rms {
        series.push(Series {
            label: "Monte Carlo RMS",
            points: t.iter().copied().zip(rms.iter().copied()).collect(),
        });
    }
    match band_plot(file, title, "t (s)", unit, &series, &bands) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    Ok(sharding::whole(run_in(quick, &Session::whole())?)?)
}

/// The example body as `session` says (whole, one shard of its seven Monte Carlos: `None`, or
/// the merge of the shards); `--stats` gets each Monte Carlo's settled statistics and its
/// curves over time.
pub fn run_in(
    quick: bool,
    session: &Session,
) -> Result<Option<Output>, Box<dyn std::error::Error>> {
    let config = if quick {
        CircleConfig::quick()
    } else {
        CircleConfig::paper()
    };
    let r = circle_experiment_in(&config, session)?;
    let variants = circle_variants_in(&config, session)?;
    let smoothing = circle_smoothing_in(&config, session)?;
    let (Some(r), Some(variants), Some(smoothing)) = (r, variants, smoothing) else {
        return Ok(None);
    };
    for (key, s) in std::iter::once(("main".to_string(), &r.monte_carlo)).chain(
        variants
            .iter()
            .map(|s| (format!("{:?} process, {:?}", s.process, s.filter), s)),
    ) {
        session.summary(&key, &summary_stats(s));
    }
    let mut stats = Vec::new();
    for t in [&smoothing.filtered, &smoothing.smoothed] {
        stats.extend(t.sqrt_p.iter().chain(&t.rms));
    }
    for v in [
        &smoothing.filtered_rms_over_time,
        &smoothing.smoothed_rms_over_time,
    ] {
        stats.extend(v.iter().flat_map(|x| x.iter().copied()));
    }
    session.summary("smoothing", &stats);
    let mc = &r.monte_carlo;
    println!(
        "Boje section 4: R = {} m, circle {} m, t_end = {} s, h = {} s, σ_a = {} m/s², σ_xy = {} m, σ_θ = {} rad, fixes every {} s",
        config.half_separation,
        config.circle_radius,
        config.t_end,
        config.dt,
        config.sigma_accel,
        config.sigma_xy,
        config.sigma_theta,
        config.fix_period
    );
    println!(
        "{} Monte Carlo runs, {:?} filter, {:?} process, correct ICs (x̂₀ − x₀ ~ N(0, P₀)); settled part t ∈ [{}, {}] s",
        mc.runs, mc.filter, mc.process, config.settle_time, config.t_end
    );
    println!(
        "{:<12} {:>12} {:>12} {:>8} {:>14}",
        "state", "mean √P", "RMS error", "ratio", "ratio 2nd half"
    );
    let (ratio, ratio2) = (mc.settled.ratio(), mc.second_half.ratio());
    for j in 0..6 {
        println!(
            "{:<12} {:>12.5} {:>12.5} {:>8.3} {:>14.3}",
            NAMES[j], mc.settled.sqrt_p[j], mc.settled.rms[j], ratio[j], ratio2[j]
        );
    }
    println!(
        "mean NIS: θ̇² {:.3} (1 expected), GPS/compass {:.3} (3 expected); truth stays within {:.3} m of the circle",
        mc.mean_rate_nis, mc.mean_fix_nis, r.truth_circle_deviation_m
    );
    println!();
    println!("{:<26} | {:<14} | estim", "headline", "paper");
    for h in r.headlines() {
        println!("{:<26} | {:<14} | {}", h.quantity, h.paper, h.estim);
        if !h.note.is_empty() {
            println!("{:<26}   note: {}", "", h.note);
        }
    }
    let w = &r.wrong_ic_run;
    println!();
    println!(
        "wrong ICs (Fig 2), x̂₀ = x₀ + (1, −1, 0.5, 5, −5, 0.5), P₀ = diag(1, 1, 1, 25, 25, 1):"
    );
    println!(
        "{:>6} {:>12} {:>10} {:>12} {:>10}",
        "t s", "|pos err| m", "√P_xx m", "θ err rad", "√P_θθ rad"
    );
    for t in [0.0, 0.99, 1.01, 2.0, 5.0, 10.0, 20.0] {
        if let Some(i) = w.times.iter().position(|s| (s - t).abs() < 1e-9) {
            let e = &w.errors[i];
            println!(
                "{:>6.2} {:>12.4} {:>10.4} {:>12.5} {:>10.5}",
                t,
                e[X].hypot(e[Y]),
                w.sqrt_p[i][X],
                e[HEADING],
                w.sqrt_p[i][HEADING]
            );
        }
    }

    // Stretch: θ inside f.
    println!();
    println!(
        "same data, {} runs each: settled rms/√P (velocity ratios ≈ 1 mean consistent)",
        config.runs
    );
    println!(
        "{:<10} {:<15} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>10} {:>10} {:>10}",
        "process", "filter", "vx", "vy", "rate", "x", "y", "theta", "√P pos", "√P θ", "√P vel"
    );
    for s in &variants {
        let q = s.settled.ratio();
        println!(
            "{:<10} {:<15} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>10.4} {:>10.5} {:>10.4}",
            format!("{:?}", s.process),
            format!("{:?}", s.filter),
            q[0],
            q[1],
            q[2],
            q[3],
            q[4],
            q[5],
            s.settled.position_sqrt_p(),
            s.settled.sqrt_p[HEADING],
            s.settled.velocity_sqrt_p()
        );
    }

    let col = |v: &[estim::nalgebra::Vector6<f64>], j: usize| {
        v.iter().map(|x| x[j]).collect::<Vec<f64>>()
    };
    let ex = &r.example_run;
    plot_band(
        "boje_circle_position.svg",
        "Boje Fig 3: position error, run 1, ±√P, Monte Carlo RMS (x)",
        "m",
        ex,
        Some(&col(&mc.rms_over_time, X)),
        &[(X, "x"), (Y, "y")],
    );
    plot_band(
        "boje_circle_heading.svg",
        "Boje Fig 3: heading error, run 1, ±√P, Monte Carlo RMS",
        "rad",
        ex,
        Some(&col(&mc.rms_over_time, HEADING)),
        &[(HEADING, "θ")],
    );
    plot_band(
        "boje_circle_velocity.svg",
        "Boje Fig 3: velocity error (ẋ), run 1, ±√P, Monte Carlo RMS",
        "m/s",
        ex,
        Some(&col(&mc.rms_over_time, VX)),
        &[(VX, "ẋ")],
    );
    plot_band(
        "boje_circle_wrong_ic_position.svg",
        "Boje Fig 2: wrong ICs, position error ±√P",
        "m",
        w,
        None,
        &[(X, "x"), (Y, "y")],
    );
    plot_band(
        "boje_circle_wrong_ic_heading.svg",
        "Boje Fig 2: wrong ICs, heading error ±√P",
        "rad",
        w,
        None,
        &[(HEADING, "θ")],
    );
    plot_band(
        "boje_circle_wrong_ic_velocity.svg",
        "Boje Fig 2: wrong ICs, velocity error ±√P",
        "m/s",
        w,
        None,
        &[(VX, "ẋ")],
    );
    if let (Some(lin), Some(non)) = (variants.first(), variants.get(2)) {
        let t = &r.example_run.times;
        let pts = |v: &[estim::nalgebra::Vector6<f64>]| {
            t.iter()
                .copied()
                .zip(v.iter().map(|x| x[VX]))
                .collect::<Vec<_>>()
        };
        match line_plot(
            "boje_circle_velocity_models.svg",
            "ẋ: Monte Carlo RMS vs mean √P, paper's process vs θ inside f (EKF)",
            "t (s)",
            "m/s",
            &[
                Series {
                    label: "RMS, paper process",
                    points: pts(&lin.rms_over_time),
                },
                Series {
                    label: "√P, paper process",
                    points: pts(&lin.sqrt_p_over_time),
                },
                Series {
                    label: "RMS, θ in f",
                    points: pts(&non.rms_over_time),
                },
                Series {
                    label: "√P, θ in f",
                    points: pts(&non.sqrt_p_over_time),
                },
            ],
        ) {
            Ok(p) => println!("figure: {}", p.display()),
            Err(e) => eprintln!("figure failed: {e}"),
        }
    }
    println!();
    smoothing.table();
    println!("{}", smoothing.headline());
    smoothing.figures();
    let json = {
        serde_json::json!({
            "pos_sqrt_p_m": r.pos_sqrt_p_m,
            "pos_rms_m": r.pos_rms_m,
            "heading_sqrt_p_rad": r.heading_sqrt_p_rad,
            "heading_rms_rad": r.heading_rms_rad,
            "vel_sqrt_p_m_s": r.vel_sqrt_p_m_s,
            "vel_rms_m_s": r.vel_rms_m_s,
            "smoothed": smoothing.json(),
        })
    };
    let mut headlines = r.headlines();
    headlines.push(smoothing.headline());
    Ok(Some(Output { json, headlines }))
}

/// A Monte Carlo's results for `--stats`: settled and second-half √P and RMS, mean NIS, and
/// the RMS and mean √P at each step.
fn summary_stats(s: &MonteCarloSummary) -> Vec<f64> {
    let mut v = Vec::new();
    for t in [&s.settled, &s.second_half] {
        v.extend(t.sqrt_p.iter().chain(&t.rms));
    }
    v.extend([s.mean_rate_nis, s.mean_fix_nis]);
    for curve in [&s.rms_over_time, &s.sqrt_p_over_time] {
        v.extend(curve.iter().flat_map(|x| x.iter().copied()));
    }
    v
}
