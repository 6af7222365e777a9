//! Section 4: the circle example (Table 1), its simulator and Monte Carlo.
//!
//! Reading of the scenario (the paper leaves t_end and the orbit kinematics open; see the
//! module docs): a rigid arm, CG on a circle of radius 10 m about the origin, heading
//! θ = φ + π/2, rate ω(t) = sgn(t − t_end/2)·0.1·t rad/s (sgn(0) := +1), t_end = 20 s. The
//! truth is generated discretely consistent with the filter's model: velocities are exact at
//! the samples, uₖ = (v(tₖ₊₁) − v(tₖ))/h, xₖ₊₁ = A xₖ + B uₖ, and the accelerometer sample is
//! aₖ = M(θₖ)(uₖ, ωₖ²) + N(0, σ_a² I₄) (eq 4).

use estim_core::error::Result;
use estim_core::nalgebra::{Matrix6, Vector3, Vector4, Vector6};
use estim_core::{Error, Gaussian, Parameter};
use estim_filters::{Ekf, SecondOrderEkf, Ukf};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use super::filter::{
    AccelerometerProcess, HEADING, NonlinearPlanarProcess, PlanarFilter, PlanarProcess,
    PositionHeadingMeasurement, RATE, VX, VY, X, Y, filter_step, input_matrix, transition_matrix,
};
use super::geometry::{ChannelVariances, sensor_signals};
use super::{Headline, wrap_angle};

/// Which estim filter runs the 6-state model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FilterKind {
    /// [`Ekf`]: with the linear process this is exactly the paper's eq 16.
    Ekf,
    /// [`SecondOrderEkf`]: adds the Hessian mean terms (ŷ = ω̂² + P_θ̇θ̇ for θ̇²).
    SecondOrderEkf,
    /// [`Ukf`] with estim's default sigma points.
    Ukf,
}

/// Which process model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ProcessKind {
    /// The paper's linear process with σ²_θ folded into Q ([`PlanarProcess`]).
    Linear,
    /// θ inside f through eq 5 ([`NonlinearPlanarProcess`]).
    Nonlinear,
}

/// Initial estimate relative to the truth and initial covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialConditions {
    /// x̂₀ − x₀ when `draw_error` is false.
    pub offset: Vector6<f64>,
    /// diag(P₀).
    pub variances: Vector6<f64>,
    /// Draw x̂₀ − x₀ ~ N(0, P₀) per run instead of using `offset`.
    pub draw_error: bool,
}

impl InitialConditions {
    /// Fig 3 ("correct" ICs): P₀ = diag(0.1², 0.1², 0.01², 0.5², 0.5², 0.01²) (erratum E5) and,
    /// for a consistent Monte Carlo, x̂₀ − x₀ drawn from N(0, P₀).
    pub fn correct() -> Self {
        Self {
            offset: Vector6::zeros(),
            variances: Vector6::new(0.01, 0.01, 1e-4, 0.25, 0.25, 1e-4),
            draw_error: true,
        }
    }

    /// Fig 2 (wrong ICs): P₀ = diag(1, 1, 1, 25, 25, 1) (erratum E5),
    /// x̂₀ = x₀ + (1, −1, 0.5, 5, −5, 0.5) (the paper gives no values; about one σ each).
    pub fn wrong() -> Self {
        Self {
            offset: Vector6::new(1.0, -1.0, 0.5, 5.0, -5.0, 0.5),
            variances: Vector6::new(1.0, 1.0, 1.0, 25.0, 25.0, 1.0),
            draw_error: false,
        }
    }
}

/// Settings of the circle example.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CircleConfig {
    /// t_end, s (not given in the paper; 20 s).
    pub t_end: f64,
    /// Accelerometer period h, s (Table 1: 0.01).
    pub dt: f64,
    /// Circle radius, m (10).
    pub circle_radius: f64,
    /// R, half the sensor separation, m (0.5).
    pub half_separation: f64,
    /// The rate slope in ω = sgn(t − t_end/2)·slope·t, rad/s² (0.1).
    pub rate_slope: f64,
    /// σ_a per accelerometer channel, m/s² (Table 1: 9.8e-3).
    pub sigma_accel: f64,
    /// σ_xy of the position fixes, m (Table 1: 1.0).
    pub sigma_xy: f64,
    /// σ_yθ of the compass, rad (Table 1: 0.1).
    pub sigma_theta: f64,
    /// Period of the position/compass fixes, s (Table 1: 1.0).
    pub fix_period: f64,
    /// Monte Carlo runs.
    pub runs: usize,
    /// Seed of run 0 (run k uses seed + k).
    pub seed: u64,
    /// Start of the "settled" part over which averages are taken, s.
    pub settle_time: f64,
    /// The filter.
    pub filter: FilterKind,
    /// The process model.
    pub process: ProcessKind,
    /// ICs of the Monte Carlo runs.
    pub initial: InitialConditions,
}

impl CircleConfig {
    /// Table 1 with the documented reading: t_end = 20 s, 50 runs, settled part t ≥ 2 s,
    /// paper's filter (EKF, linear process), correct ICs.
    pub fn paper() -> Self {
        Self {
            t_end: 20.0,
            dt: 0.01,
            circle_radius: 10.0,
            half_separation: 0.5,
            rate_slope: 0.1,
            sigma_accel: 9.8e-3,
            sigma_xy: 1.0,
            sigma_theta: 0.1,
            fix_period: 1.0,
            runs: 50,
            seed: 7,
            settle_time: 2.0,
            filter: FilterKind::Ekf,
            process: ProcessKind::Linear,
            initial: InitialConditions::correct(),
        }
    }

    /// As [`paper`](Self::paper) with 20 runs.
    pub fn quick() -> Self {
        Self {
            runs: 20,
            ..Self::paper()
        }
    }

    /// Number of accelerometer steps, t_end/h (rounded).
    pub fn steps(&self) -> usize {
        (self.t_end / self.dt).round() as usize
    }

    /// Steps between fixes.
    pub fn fix_every(&self) -> usize {
        ((self.fix_period / self.dt).round() as usize).max(1)
    }

    /// The accelerometer channel variances (all σ_a²).
    pub fn variances(&self) -> ChannelVariances {
        ChannelVariances::equal(self.sigma_accel)
    }

    /// The GPS/compass model.
    pub fn fix_model(&self) -> PositionHeadingMeasurement {
        PositionHeadingMeasurement {
            sigma_xy: self.sigma_xy,
            sigma_theta: self.sigma_theta,
        }
    }

    fn validate(&self) -> Result<()> {
        let steps = self.steps();
        let ok = self.dt > 0.0
            && self.t_end > 0.0
            && steps >= 2
            && steps.is_multiple_of(2)
            && self.runs > 0
            && self.half_separation > 0.0;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidParameter {
                parameter: Parameter::SampleCount,
                value: steps as f64,
            })
        }
    }
}

/// Truth and sensor data of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct CircleData {
    /// tₖ = k h, k = 0..=K.
    pub times: Vec<f64>,
    /// The true state xₖ, k = 0..=K.
    pub truth: Vec<Vector6<f64>>,
    /// The true inertial input uₖ = (ẍ, ÿ, θ̈) over [tₖ, tₖ₊₁], k = 0..K.
    pub inputs: Vec<Vector3<f64>>,
    /// The accelerometer samples aₖ, k = 0..K.
    pub accel: Vec<Vector4<f64>>,
    /// The GPS/compass fix (x, y, θ wrapped) at step k, if any (k = fix period, 2·period, …
    /// < K).
    pub fixes: Vec<Option<Vector3<f64>>>,
}

/// ω(t) = sgn(t − t_end/2)·slope·t with sgn(0) = +1.
pub fn circle_rate(t: f64, config: &CircleConfig) -> f64 {
    let sign = if t >= config.t_end / 2.0 { 1.0 } else { -1.0 };
    sign * config.rate_slope * t
}

/// φ(t) = ∫₀ᵗ ω: −slope t²/2 before t_end/2, slope t²/2 − slope t_end²/4 after.
pub fn circle_angle(t: f64, config: &CircleConfig) -> f64 {
    let half = config.t_end / 2.0;
    if t >= half {
        0.5 * config.rate_slope * t * t - 0.25 * config.rate_slope * config.t_end * config.t_end
    } else {
        -0.5 * config.rate_slope * t * t
    }
}

/// Simulates one run of the circle scenario with the given seed.
///
/// Errors: invalid configuration (non-positive step, odd number of steps so t_end/2 is not a
/// sample, no runs).
pub fn simulate_circle(config: &CircleConfig, seed: u64) -> Result<CircleData> {
    config.validate()?;
    let k_steps = config.steps();
    let h = config.dt;
    let r = config.circle_radius;
    let every = config.fix_every();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let velocity = |k: usize| {
        let t = k as f64 * h;
        let (w, phi) = (circle_rate(t, config), circle_angle(t, config));
        let (s, c) = phi.sin_cos();
        Vector3::new(-r * w * s, r * w * c, w)
    };
    let (a, b) = (transition_matrix(h), input_matrix(h));
    let mut x = Vector6::new(0.0, 0.0, 0.0, r, 0.0, std::f64::consts::FRAC_PI_2);
    let v0 = velocity(0);
    x.fixed_view_mut::<3, 1>(0, 0).copy_from(&v0);
    let mut data = CircleData {
        times: Vec::with_capacity(k_steps + 1),
        truth: Vec::with_capacity(k_steps + 1),
        inputs: Vec::with_capacity(k_steps),
        accel: Vec::with_capacity(k_steps),
        fixes: Vec::with_capacity(k_steps),
    };
    let mut v = v0;
    for k in 0..k_steps {
        data.times.push(k as f64 * h);
        data.truth.push(x);
        let v_next = velocity(k + 1);
        let u = (v_next - v) / h;
        let inertial = Vector4::new(u[0], u[1], u[2], x[RATE] * x[RATE]);
        let mut sample = sensor_signals(x[HEADING], &inertial, config.half_separation);
        for s in sample.iter_mut() {
            *s += config.sigma_accel * normal();
        }
        let fix = if k > 0 && k.is_multiple_of(every) {
            Some(Vector3::new(
                x[X] + config.sigma_xy * normal(),
                x[Y] + config.sigma_xy * normal(),
                wrap_angle(x[HEADING] + config.sigma_theta * normal()),
            ))
        } else {
            None
        };
        data.inputs.push(u);
        data.accel.push(sample);
        data.fixes.push(fix);
        x = a * x + b * u;
        v = v_next;
    }
    data.times.push(k_steps as f64 * h);
    data.truth.push(x);
    Ok(data)
}

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
    prior: Gaussian<f64, estim_core::nalgebra::U6>,
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

/// The prior N(x̂₀, P₀) for a run whose true initial state is `truth0`; `rng_seed` draws the
/// initial error when `initial.draw_error`.
///
/// Errors: a negative or non-finite P₀.
pub fn initial_prior(
    truth0: &Vector6<f64>,
    initial: &InitialConditions,
    rng_seed: u64,
) -> Result<Gaussian<f64, estim_core::nalgebra::U6>> {
    let offset = if initial.draw_error {
        let mut rng = StdRng::seed_from_u64(rng_seed ^ 0x5eed_0f1c);
        initial.variances.map(|v| {
            let n: f64 = StandardNormal.sample(&mut rng);
            v.max(0.0).sqrt() * n
        })
    } else {
        initial.offset
    };
    Gaussian::new(truth0 + offset, Matrix6::from_diagonal(&initial.variances))
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

/// Accumulates per-step sums over runs.
struct Accumulator {
    sum_sq: Vec<Vector6<f64>>,
    sum_sqrt_p: Vec<Vector6<f64>>,
    runs: usize,
}

impl Accumulator {
    fn new(n: usize) -> Self {
        Self {
            sum_sq: vec![Vector6::zeros(); n],
            sum_sqrt_p: vec![Vector6::zeros(); n],
            runs: 0,
        }
    }

    fn add(&mut self, trace: &FilterTrace) {
        for (i, (e, s)) in trace.errors.iter().zip(&trace.sqrt_p).enumerate() {
            self.sum_sq[i] += e.component_mul(e);
            self.sum_sqrt_p[i] += s;
        }
        self.runs += 1;
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
) -> Result<(MonteCarloSummary, CircleData, FilterTrace)> {
    config.validate()?;
    let mut acc = Accumulator::new(config.steps() + 1);
    let (mut rate_nis, mut rate_n, mut fix_nis, mut fix_n) = (0.0, 0usize, 0.0, 0usize);
    let mut first = None;
    for run in 0..config.runs {
        let seed = config.seed.wrapping_add(run as u64);
        let data = simulate_circle(config, seed)?;
        let prior = initial_prior(&data.truth[0], &config.initial, seed)?;
        let trace = run_circle_filter(&data, config, prior)?;
        acc.add(&trace);
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
        if run == 0 {
            first = Some((data, trace));
        }
    }
    let Some((data, trace)) = first else {
        return Err(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: 0.0,
        });
    };
    let summary = MonteCarloSummary {
        filter: config.filter,
        process: config.process,
        runs: config.runs,
        settled: acc.stats(&data.times, config.settle_time, config.t_end),
        second_half: acc.stats(&data.times, config.t_end / 2.0, config.t_end),
        mean_rate_nis: rate_nis / rate_n.max(1) as f64,
        mean_fix_nis: fix_nis / fix_n.max(1) as f64,
        rms_over_time: acc.rms_over_time(),
        sqrt_p_over_time: acc.sqrt_p_over_time(),
    };
    Ok((summary, data, trace))
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
pub fn circle_experiment(config: &CircleConfig) -> Result<CircleResult> {
    let (mc, data, trace) = circle_monte_carlo(config)?;
    let wrong_prior = initial_prior(&data.truth[0], &InitialConditions::wrong(), config.seed)?;
    let wrong = run_circle_filter(&data, config, wrong_prior)?;
    let deviation = data
        .truth
        .iter()
        .map(|x| ((x[X].powi(2) + x[Y].powi(2)).sqrt() - config.circle_radius).abs())
        .fold(0.0, f64::max);
    let s = mc.settled;
    Ok(CircleResult {
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
    })
}

/// The same Monte Carlo (same data seeds, same ICs) for each (process, filter) pair: the
/// paper's linear process with EKF and second-order EKF, and the nonlinear process with EKF,
/// second-order EKF and UKF.
///
/// Errors: as [`circle_monte_carlo`].
pub fn circle_variants(config: &CircleConfig) -> Result<Vec<MonteCarloSummary>> {
    let pairs = [
        (ProcessKind::Linear, FilterKind::Ekf),
        (ProcessKind::Linear, FilterKind::SecondOrderEkf),
        (ProcessKind::Nonlinear, FilterKind::Ekf),
        (ProcessKind::Nonlinear, FilterKind::SecondOrderEkf),
        (ProcessKind::Nonlinear, FilterKind::Ukf),
    ];
    pairs
        .iter()
        .map(|&(process, filter)| {
            let c = CircleConfig {
                process,
                filter,
                ..*config
            };
            circle_monte_carlo(&c).map(|(s, _, _)| s)
        })
        .collect()
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
