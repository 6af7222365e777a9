//! Lee & Huang (IEEE T-AES 2002): all-accelerometer planar INS, CKF alone vs CKF + own-ship
//! trajectory estimator (OTE), section IV (30° pitch, 2 g along body x, 10 mg bias).
//!
//! Runs the CKF (the paper's Ψ Jacobian, in the linear Kalman filter) and the CKF followed by
//! the OTE (fading-memory RLS, γ = 0.95, S_p = 0.01 I, P_p(0) = I) on the same simulated
//! sensor data over several seeds, plus estim's radial-consistent second scenario and a table of
//! variant readings. Prints tables and headlines, writes figures to `target/figures/`, and with
//! `--json` prints one JSON line last. `--quick` uses 5 seeds instead of 20.
//!
//! `cargo run --release --example lee_huang [-- --json] [-- --quick]`

use crate::common::{Headline, Output, Series, line_plot};
use crate::sharding::Session;
use estim::core::{Error, Gaussian, Parameter};
use estim::filters::{Ekf, Estimator, KalmanFilter, Predict, Update};
use estim::models::lee_huang::{
    AttitudeMeasurement, CkfInput, CkfProcess, Discretization, FourAccelerometers, InsProcess,
    LikelihoodForm, OteSettings, OteSteadyState, OwnShipTrajectoryEstimator, Plane,
    STANDARD_GRAVITY, Scenario, SensorConfig, ote_steady_state, rotation, simulate, wrap_angle,
};
use estim::nalgebra::{Matrix2, Matrix3, Matrix6, U6, Vector1, Vector2, Vector3, Vector6};

/// The labels of the configurations run by [`run_experiment`].
pub mod labels {
    /// Section IV with the paper's initial conditions.
    pub const PAPER: &str = "section IV, paper ICs";
    /// estim's radial-consistent scenario.
    pub const RADIAL: &str = "radial ICs, sigma_eps = 0.01 rad (estim's reading)";
    /// OTE with γ = 0.99, P_p(0) = S_p.
    pub const GAMMA_099: &str = "OTE gamma = 0.99, P_p(0) = S_p";
    /// OTE fed by eq 38/39 as printed.
    pub const PRINTED_LIKELIHOOD: &str = "OTE with eq 38/39 as printed (E2)";
    /// Full Jacobian (EKF) instead of Ψ.
    pub const FULL_JACOBIAN: &str = "full Jacobian (EKF) instead of Psi";
    /// Euler discretisation.
    pub const EULER: &str = "Euler discretisation (eq 33, E7)";
    /// Vertical plane with gravity.
    pub const VERTICAL: &str = "vertical plane with gravity (E4)";
    /// No accelerometer bias.
    pub const NO_BIAS: &str = "no bias";
    /// Radial ICs with the paper's attitude noise.
    pub const RADIAL_NOISY: &str = "radial ICs, paper sigma_eps = 1 rad";
}

/// Which Jacobian the CKF propagates its covariance with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum CkfJacobian {
    /// Ψ = I + F T (eq 33/36): the θ → velocity coupling dropped; [`CkfProcess`](CkfProcess)
    /// in the linear Kalman filter.
    #[default]
    Paper,
    /// The full ∂f/∂D: [`InsProcess`] in the EKF.
    Full,
}

/// One section IV configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct SectionIvConfig {
    /// A short name for tables.
    pub label: String,
    /// The true motion.
    pub scenario: Scenario,
    /// Sample period T \[s\].
    pub dt: f64,
    /// Run length \[s\].
    pub duration: f64,
    /// Number of seeds (Monte Carlo runs).
    pub seeds: usize,
    /// Seed of the first run; run i uses `first_seed + i`.
    pub first_seed: u64,
    /// Bias of the derived inputs (b_x, b_y, b_ω̇).
    pub input_bias: Vector3<f64>,
    /// σ_W per sample of the derived-input noise (truth and filter).
    pub input_noise_std: Vector3<f64>,
    /// σ_ε of the attitude measurement (truth and filter: R_v = σ_ε²).
    pub attitude_std: f64,
    /// CKF P(0); the CKF starts at the true D(0) (the paper's "given" initial conditions).
    pub initial_covariance: Matrix6<f64>,
    /// Discretisation (truth is exact; this is the filter's).
    pub discretization: Discretization,
    /// The CKF's Jacobian.
    pub jacobian: CkfJacobian,
    /// The OTE.
    pub ote: OteSettings,
    /// Record every n-th step.
    pub record_every: usize,
}

impl SectionIvConfig {
    /// Section IV as estim reads it (module docs, "Section IV"): T = 0.01 s, 20 s, 20 seeds,
    /// bias 10 mg on y_ax and y_ay, σ_W = √(0.01 T) per sample (Q_v = 0.01 I T, E8),
    /// σ_ε² = 0.01/T (R_v, E6), P(0) = diag(1, 1, 0.1, 0.1, (1°)², (1°/s)²), ZOH, Ψ Jacobian,
    /// OTE of the issue (γ = 0.95, S_p = 0.01 I, P_p(0) = I).
    pub fn paper() -> Self {
        let dt: f64 = 0.01;
        let bias = 0.010 * STANDARD_GRAVITY;
        let sw = (0.01 * dt).sqrt();
        let deg = 1f64.to_radians();
        Self {
            label: labels::PAPER.into(),
            scenario: Scenario::section_iv(),
            dt,
            duration: 20.0,
            seeds: 20,
            first_seed: 2002,
            input_bias: Vector3::new(bias, bias, 0.0),
            input_noise_std: Vector3::new(sw, sw, sw),
            attitude_std: (0.01 / dt).sqrt(),
            initial_covariance: Matrix6::from_diagonal(&Vector6::new(
                1.0,
                1.0,
                0.1,
                0.1,
                deg * deg,
                deg * deg,
            )),
            discretization: Discretization::ZeroOrderHold,
            jacobian: CkfJacobian::Paper,
            ote: OteSettings::issue(),
            record_every: 10,
        }
    }

    /// estim's second scenario (not the paper's): radial-consistent initial conditions
    /// ([`Scenario::radial`]) and an accurate attitude sensor σ_ε = 0.01 rad, otherwise as
    /// [`paper`](Self::paper).
    pub fn radial() -> Self {
        Self {
            label: labels::RADIAL.into(),
            scenario: Scenario::radial(),
            attitude_std: 0.01,
            ..Self::paper()
        }
    }

    /// The same with `seeds` runs.
    pub fn with_seeds(mut self, seeds: usize) -> Self {
        self.seeds = seeds;
        self
    }

    /// The number of filter steps.
    pub fn steps(&self) -> usize {
        (self.duration / self.dt).round() as usize
    }

    fn validate(&self) -> Result<(), Error> {
        if !(self.dt > 0.0 && self.dt.is_finite()) {
            return Err(Error::InvalidParameter {
                parameter: Parameter::StepSize,
                value: self.dt,
            });
        }
        // Duration finite and ≤ MAX_STEPS steps, seeds ≤ MAX_RUNS: a run that ends.
        estim_models::limits::steps_for_duration(self.duration, self.dt)?;
        estim_models::limits::check_runs(self.seeds)?;
        if self.seeds == 0 || self.record_every == 0 || self.steps() == 0 {
            return Err(Error::InvalidParameter {
                parameter: Parameter::SampleCount,
                value: self.seeds.min(self.record_every).min(self.steps()) as f64,
            });
        }
        Ok(())
    }

    fn sensors(&self) -> SensorConfig {
        SensorConfig {
            dt: self.dt,
            steps: self.steps(),
            accelerometers: FourAccelerometers::default(),
            input_bias: self.input_bias,
            input_noise_std: self.input_noise_std,
            attitude_std: self.attitude_std,
        }
    }

    fn process(&self) -> InsProcess {
        let var = self.input_noise_std.component_mul(&self.input_noise_std);
        InsProcess {
            input_noise: Matrix3::from_diagonal(&var),
            discretization: self.discretization,
            plane: self.scenario.plane,
        }
    }
}

/// Error statistics over the seeds at the recorded times. RMS values are over seeds:
/// position_rms = √(mean over seeds of |p̂ − p|²), likewise for velocity; σ values are
/// √(mean over seeds of the filter's variance) (trace of the 2 × 2 block for p and v).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ErrorHistory {
    /// Recorded times \[s\].
    pub time: Vec<f64>,
    /// RMS position error norm \[m\].
    pub position_rms: Vec<f64>,
    /// RMS velocity error norm \[m/s\].
    pub velocity_rms: Vec<f64>,
    /// RMS attitude error \[rad\].
    pub attitude_rms: Vec<f64>,
    /// RMS rate error \[rad/s\].
    pub rate_rms: Vec<f64>,
    /// Mean (over seeds) signed position error p̂ − p \[m\].
    pub position_mean: Vec<Vector2<f64>>,
    /// The filter's own √tr P_pp \[m\].
    pub position_sigma: Vec<f64>,
    /// The filter's own √tr P_vv \[m/s\].
    pub velocity_sigma: Vec<f64>,
    /// The filter's own √P_θθ \[rad\].
    pub attitude_sigma: Vec<f64>,
    /// The filter's own √P_ωω \[rad/s\].
    pub rate_sigma: Vec<f64>,
}

impl ErrorHistory {
    /// Index of the recorded time closest to `t`.
    pub fn index_at(&self, t: f64) -> usize {
        let mut best = 0;
        for (i, ti) in self.time.iter().enumerate() {
            if (ti - t).abs() < (self.time[best] - t).abs() {
                best = i;
            }
        }
        best
    }

    /// RMS position error at the last recorded time \[m\].
    pub fn final_position_rms(&self) -> f64 {
        self.position_rms.last().copied().unwrap_or(f64::NAN)
    }

    /// RMS velocity error at the last recorded time \[m/s\].
    pub fn final_velocity_rms(&self) -> f64 {
        self.velocity_rms.last().copied().unwrap_or(f64::NAN)
    }
}

/// The terms one run adds per filter and recorded time ([`Accumulator::terms`]).
const TERMS: usize = 10;

#[derive(Default)]
struct Accumulator {
    p2: Vec<f64>,
    v2: Vec<f64>,
    th2: Vec<f64>,
    w2: Vec<f64>,
    pm: Vec<Vector2<f64>>,
    sp: Vec<f64>,
    sv: Vec<f64>,
    sth: Vec<f64>,
    sw: Vec<f64>,
}

impl Accumulator {
    fn new(n: usize) -> Self {
        Self {
            p2: vec![0.0; n],
            v2: vec![0.0; n],
            th2: vec![0.0; n],
            w2: vec![0.0; n],
            pm: vec![Vector2::zeros(); n],
            sp: vec![0.0; n],
            sv: vec![0.0; n],
            sth: vec![0.0; n],
            sw: vec![0.0; n],
        }
    }

    /// One run's terms at one recorded time, in the order [`add`](Self::add) sums them.
    fn terms(est: &Vector6<f64>, p: &Matrix6<f64>, truth: &Vector6<f64>) -> [f64; TERMS] {
        let e = est - truth;
        let ep = Vector2::new(e[0], e[1]);
        let eth = wrap_angle(e[4]);
        [
            ep.norm_squared(),
            e[2] * e[2] + e[3] * e[3],
            eth * eth,
            e[5] * e[5],
            ep[0],
            ep[1],
            p[(0, 0)] + p[(1, 1)],
            p[(2, 2)] + p[(3, 3)],
            p[(4, 4)],
            p[(5, 5)],
        ]
    }

    /// Adds one run's [`terms`](Self::terms) at recorded time `i`.
    fn add(&mut self, i: usize, t: &[f64]) {
        self.p2[i] += t[0];
        self.v2[i] += t[1];
        self.th2[i] += t[2];
        self.w2[i] += t[3];
        self.pm[i] += Vector2::new(t[4], t[5]);
        self.sp[i] += t[6];
        self.sv[i] += t[7];
        self.sth[i] += t[8];
        self.sw[i] += t[9];
    }

    fn finish(self, time: Vec<f64>, runs: usize) -> ErrorHistory {
        let n = runs as f64;
        let rms = |v: Vec<f64>| v.into_iter().map(|s| (s / n).sqrt()).collect();
        ErrorHistory {
            time,
            position_rms: rms(self.p2),
            velocity_rms: rms(self.v2),
            attitude_rms: rms(self.th2),
            rate_rms: rms(self.w2),
            position_mean: self.pm.into_iter().map(|s| s / n).collect(),
            position_sigma: rms(self.sp),
            velocity_sigma: rms(self.sv),
            attitude_sigma: rms(self.sth),
            rate_sigma: rms(self.sw),
        }
    }
}

/// The CKF of either Jacobian, behind one interface.
enum Ckf {
    Paper(KalmanFilter<f64, U6>, CkfProcess),
    Full(Ekf<f64, U6>, InsProcess),
}

impl Ckf {
    fn new(config: &SectionIvConfig) -> Result<Self, Error> {
        let prior = Gaussian::new(config.scenario.initial_state, config.initial_covariance)?;
        let process = config.process();
        Ok(match config.jacobian {
            CkfJacobian::Paper => Ckf::Paper(KalmanFilter::new(prior), process.ckf()),
            CkfJacobian::Full => Ckf::Full(Ekf::new(prior), process),
        })
    }

    fn predict(&mut self, u: &Vector3<f64>, dt: f64) -> Result<(), Error> {
        match self {
            Ckf::Paper(f, p) => {
                let input = CkfInput {
                    signals: *u,
                    attitude: f.state()[4],
                };
                f.predict(p, &input, dt)
            }
            Ckf::Full(f, p) => f.predict(p, u, dt),
        }
    }

    fn update(&mut self, m: &AttitudeMeasurement, z: f64) -> Result<(), Error> {
        let z = Vector1::new(z);
        match self {
            Ckf::Paper(f, _) => f.update(m, &z).map(|_| ()),
            Ckf::Full(f, _) => f.update(m, &z).map(|_| ()),
        }
    }
}

impl Estimator<f64, U6> for Ckf {
    fn state(&self) -> &Vector6<f64> {
        match self {
            Ckf::Paper(f, _) => f.state(),
            Ckf::Full(f, _) => f.state(),
        }
    }

    fn covariance(&self) -> &Matrix6<f64> {
        match self {
            Ckf::Paper(f, _) => f.covariance(),
            Ckf::Full(f, _) => f.covariance(),
        }
    }

    fn reset(&mut self, prior: Gaussian<f64, U6>) {
        match self {
            Ckf::Paper(f, _) => f.reset(prior),
            Ckf::Full(f, _) => f.reset(prior),
        }
    }
}

/// The result of one section IV configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct SectionIvResult {
    /// The configuration run.
    pub config: SectionIvConfig,
    /// The CKF alone.
    pub ckf: ErrorHistory,
    /// The CKF with the OTE feeding back its velocity.
    pub ckf_ote: ErrorHistory,
    /// The OTE gain K_p of the last cycle (first seed).
    pub ote_final_gain: Matrix2<f64>,
    /// The OTE P_p after the last cycle (first seed).
    pub ote_final_covariance: Matrix2<f64>,
    /// ½ R(θ₀) (b_x, b_y) t² at the recorded times: the position error an exact attitude and
    /// the unobservable position/velocity predict from the bias alone (ω ≡ 0 scenarios).
    pub bias_drift: Vec<Vector2<f64>>,
}

/// Runs one configuration: for each seed, one simulation and two filters on its data (the CKF,
/// and the CKF followed each cycle by the OTE).
pub fn run_section_iv(config: &SectionIvConfig) -> Result<SectionIvResult, Error> {
    config.validate()?;
    let records = (0..config.seeds)
        .map(|run| section_iv_run(config, run))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(section_iv_result(config, &records))
}

/// [`run_section_iv`] as `session` says (`crate::sharding`): every seed's record summed in
/// seed order, `None` in a shard. `key` names the configuration in the shard files.
pub fn run_section_iv_in(
    config: &SectionIvConfig,
    key: &str,
    session: &Session,
) -> Result<Option<SectionIvResult>, Box<dyn std::error::Error>> {
    config.validate()?;
    let records = session.records(key, config.seeds, |run| Ok(section_iv_run(config, run)?))?;
    Ok(records.map(|r| {
        let result = section_iv_result(config, &r);
        let mut stats = Vec::new();
        for h in [&result.ckf, &result.ckf_ote] {
            for v in [
                &h.position_rms,
                &h.velocity_rms,
                &h.attitude_rms,
                &h.rate_rms,
                &h.position_sigma,
                &h.velocity_sigma,
                &h.attitude_sigma,
                &h.rate_sigma,
            ] {
                stats.extend_from_slice(v);
            }
            stats.extend(h.position_mean.iter().flat_map(|m| [m[0], m[1]]));
        }
        stats.extend(
            result
                .ote_final_gain
                .iter()
                .chain(&result.ote_final_covariance),
        );
        session.summary(key, &stats);
        result
    }))
}

/// The recorded steps of `config`.
fn recorded_steps(config: &SectionIvConfig) -> Vec<usize> {
    (0..=config.steps())
        .filter(|k| k % config.record_every == 0)
        .collect()
}

/// Run (seed index) `run` of one configuration: per recorded time the CKF's and then the
/// CKF + OTE's [`Accumulator::terms`], then the OTE's last gain and covariance (column-major).
fn section_iv_run(config: &SectionIvConfig, run: usize) -> Result<Vec<f64>, Error> {
    let steps = config.steps();
    let sensors = config.sensors();
    let measurement = AttitudeMeasurement {
        variance: config.attitude_std * config.attitude_std,
    };
    let recorded = recorded_steps(config);
    let mut record = Vec::with_capacity(2 * TERMS * recorded.len() + 8);
    let mut ote_gain = Matrix2::zeros();
    let mut ote_cov = Matrix2::zeros();
    let sim = simulate(&config.scenario, &sensors, config.first_seed + run as u64)?;
    let mut ckf = Ckf::new(config)?;
    let mut ckf_ote = Ckf::new(config)?;
    let mut ote = OwnShipTrajectoryEstimator::new(&config.ote)?;
    let mut slot = 0;
    for k in 0..=steps {
        if k > 0 {
            let u = &sim.samples[k - 1].inputs;
            let z = sim.samples[k].attitude;
            for f in [&mut ckf, &mut ckf_ote] {
                f.predict(u, config.dt)?;
                f.update(&measurement, z)?;
            }
            let step = ote.correct(&mut ckf_ote)?;
            ote_gain = step.gain;
            ote_cov = step.covariance;
        }
        if slot < recorded.len() && recorded[slot] == k {
            let truth = &sim.truth[k];
            record.extend(Accumulator::terms(ckf.state(), ckf.covariance(), truth));
            record.extend(Accumulator::terms(
                ckf_ote.state(),
                ckf_ote.covariance(),
                truth,
            ));
            slot += 1;
        }
    }
    record.extend(ote_gain.iter().chain(ote_cov.iter()));
    Ok(record)
}

/// One configuration's result from its runs' records, summed in run order; the OTE's gain and
/// covariance are run 0's.
fn section_iv_result(config: &SectionIvConfig, records: &[Vec<f64>]) -> SectionIvResult {
    let recorded = recorded_steps(config);
    let time: Vec<f64> = recorded.iter().map(|&k| k as f64 * config.dt).collect();
    let mut acc_ckf = Accumulator::new(recorded.len());
    let mut acc_ote = Accumulator::new(recorded.len());
    for record in records {
        for (slot, terms) in record
            .chunks_exact(2 * TERMS)
            .take(recorded.len())
            .enumerate()
        {
            acc_ckf.add(slot, &terms[..TERMS]);
            acc_ote.add(slot, &terms[TERMS..]);
        }
    }
    let last = |from: usize| {
        records.first().map_or_else(Matrix2::zeros, |r| {
            let n = 2 * TERMS * recorded.len() + from;
            Matrix2::from_column_slice(&r[n..n + 4])
        })
    };
    let (ote_gain, ote_cov) = (last(0), last(4));
    let b = Vector2::new(config.input_bias.x, config.input_bias.y);
    let rb = rotation(config.scenario.initial_state[4]) * b;
    let bias_drift = time.iter().map(|t| rb * (0.5 * t * t)).collect();
    SectionIvResult {
        config: config.clone(),
        ckf: acc_ckf.finish(time.clone(), config.seeds),
        ckf_ote: acc_ote.finish(time, config.seeds),
        ote_final_gain: ote_gain,
        ote_final_covariance: ote_cov,
        bias_drift,
    }
}

/// Settings of the whole Lee & Huang experiment.
#[derive(Clone, Debug, PartialEq)]
pub struct LeeHuangConfig {
    /// Section IV with the paper's initial conditions and the issue's OTE settings (the JSON
    /// numbers).
    pub paper: SectionIvConfig,
    /// estim's radial-consistent second scenario.
    pub radial: SectionIvConfig,
    /// Further readings, each run and summarised in the table.
    pub variants: Vec<SectionIvConfig>,
    /// The OTE settings of the steady-state check (the issue's).
    pub steady_state: OteSettings,
    /// Cycles iterated for the steady state.
    pub steady_state_steps: usize,
}

impl LeeHuangConfig {
    /// The full experiment: 20 seeds per configuration.
    pub fn full() -> Self {
        Self::with_seeds(20)
    }

    /// The fast form for the `papers` example: 5 seeds per configuration.
    pub fn quick() -> Self {
        Self::with_seeds(5)
    }

    /// Every configuration with `seeds` runs.
    pub fn with_seeds(seeds: usize) -> Self {
        let paper = SectionIvConfig::paper().with_seeds(seeds);
        let variant = |label: &str, f: &dyn Fn(&mut SectionIvConfig)| {
            let mut c = paper.clone();
            c.label = label.into();
            f(&mut c);
            c
        };
        let variants = vec![
            variant(labels::GAMMA_099, &|c| {
                c.ote.forgetting = 0.99;
                c.ote.initial_covariance = c.ote.weight;
            }),
            variant(labels::PRINTED_LIKELIHOOD, &|c| {
                c.ote.likelihood = LikelihoodForm::AsPrinted;
            }),
            variant(labels::FULL_JACOBIAN, &|c| {
                c.jacobian = CkfJacobian::Full;
            }),
            variant(labels::EULER, &|c| {
                c.discretization = Discretization::Euler;
            }),
            variant(labels::VERTICAL, &|c| {
                c.scenario.plane = Plane::Vertical;
            }),
            variant(labels::NO_BIAS, &|c| {
                c.input_bias = Vector3::zeros();
            }),
            variant(labels::RADIAL_NOISY, &|c| {
                c.scenario = Scenario::radial();
            }),
        ];
        Self {
            paper,
            radial: SectionIvConfig::radial().with_seeds(seeds),
            variants,
            steady_state: OteSettings::issue(),
            steady_state_steps: 2000,
        }
    }
}

/// One row of the variants table.
#[derive(Clone, Debug, PartialEq)]
pub struct VariantSummary {
    /// The configuration's label.
    pub label: String,
    /// CKF RMS position error at the end \[m\].
    pub ckf_final_position_rms: f64,
    /// CKF+OTE RMS position error at the end \[m\].
    pub ckf_ote_final_position_rms: f64,
    /// CKF RMS velocity error at the end \[m/s\].
    pub ckf_final_velocity_rms: f64,
    /// CKF+OTE RMS velocity error at the end \[m/s\].
    pub ckf_ote_final_velocity_rms: f64,
    /// CKF RMS attitude error at the end \[rad\].
    pub ckf_final_attitude_rms: f64,
}

impl VariantSummary {
    fn of(r: &SectionIvResult) -> Self {
        Self {
            label: r.config.label.clone(),
            ckf_final_position_rms: r.ckf.final_position_rms(),
            ckf_ote_final_position_rms: r.ckf_ote.final_position_rms(),
            ckf_final_velocity_rms: r.ckf.final_velocity_rms(),
            ckf_ote_final_velocity_rms: r.ckf_ote.final_velocity_rms(),
            ckf_final_attitude_rms: r.ckf.attitude_rms.last().copied().unwrap_or(f64::NAN),
        }
    }
}

/// Everything the example prints.
#[derive(Clone, Debug, PartialEq)]
pub struct LeeHuangResult {
    /// Section IV with the paper's ICs and the issue's OTE settings.
    pub paper: SectionIvResult,
    /// estim's radial-consistent scenario.
    pub radial: SectionIvResult,
    /// Summary rows: paper, radial, then the variants.
    pub variants: Vec<VariantSummary>,
    /// The OTE steady state for the issue's settings.
    pub steady_state: OteSteadyState,
}

/// Runs the whole experiment.
pub fn run_experiment(config: &LeeHuangConfig) -> Result<LeeHuangResult, Error> {
    let paper = run_section_iv(&config.paper)?;
    let radial = run_section_iv(&config.radial)?;
    let variants = config
        .variants
        .iter()
        .map(run_section_iv)
        .collect::<Result<Vec<_>, _>>()?;
    experiment_result(config, paper, radial, variants)
}

/// [`run_experiment`] as `session` says (`crate::sharding`): whole, one shard of every
/// configuration's seeds (`None`), or their merge.
pub fn run_experiment_in(
    config: &LeeHuangConfig,
    session: &Session,
) -> Result<Option<LeeHuangResult>, Box<dyn std::error::Error>> {
    let paper = run_section_iv_in(&config.paper, "paper", session)?;
    let radial = run_section_iv_in(&config.radial, "radial", session)?;
    let variants = config
        .variants
        .iter()
        .enumerate()
        .map(|(i, v)| run_section_iv_in(v, &format!("variant {i}"), session))
        .collect::<Result<Vec<_>, _>>()?;
    // Every configuration runs (its shard) before a shard stops here.
    let (Some(paper), Some(radial), Some(variants)) = (
        paper,
        radial,
        variants.into_iter().collect::<Option<Vec<_>>>(),
    ) else {
        return Ok(None);
    };
    Ok(Some(experiment_result(config, paper, radial, variants)?))
}

fn experiment_result(
    config: &LeeHuangConfig,
    paper: SectionIvResult,
    radial: SectionIvResult,
    results: Vec<SectionIvResult>,
) -> Result<LeeHuangResult, Error> {
    let mut variants = vec![VariantSummary::of(&paper), VariantSummary::of(&radial)];
    variants.extend(results.iter().map(VariantSummary::of));
    Ok(LeeHuangResult {
        paper,
        radial,
        variants,
        steady_state: ote_steady_state(&config.steady_state, config.steady_state_steps)?,
    })
}

impl LeeHuangResult {
    /// The summary row with label `label` (see [`labels`]).
    pub fn variant(&self, label: &str) -> Option<&VariantSummary> {
        self.variants.iter().find(|v| v.label == label)
    }
}

/// log₂ of the ratio of `h.position_rms` at `t` and `t/2`: the growth exponent k of a t^k law.
/// NaN for an empty history.
pub fn position_growth_exponent(h: &ErrorHistory, t: f64) -> f64 {
    let at = |t: f64| {
        h.position_rms
            .get(h.index_at(t))
            .copied()
            .unwrap_or(f64::NAN)
    };
    (at(t) / at(0.5 * t)).log2()
}

/// The paper's claims next to estim's numbers.
pub fn headlines(r: &LeeHuangResult) -> Vec<Headline> {
    let p = &r.paper;
    let n = p.config.seeds;
    let t_end = p.ckf.time.last().copied().unwrap_or(f64::NAN);
    let at = |h: &ErrorHistory, t: f64| {
        h.position_rms
            .get(h.index_at(t))
            .copied()
            .unwrap_or(f64::NAN)
    };
    let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    let var = |label: &str, f: fn(&VariantSummary) -> f64| r.variant(label).map_or(f64::NAN, f);
    let bias_end = p.bias_drift.last().map_or(f64::NAN, |b| b.norm());
    let deg = |x: f64| x.to_degrees();
    let ss = &r.steady_state;
    vec![
        Headline {
            quantity: "CKF position error (Figs 5-6)".into(),
            paper: "CKF diverges, poor performance".into(),
            estim: format!(
                "{:.1} / {:.1} / {:.1} m at 5 / 10 / {t_end:.0} s (RMS over {n} seeds), growth exponent {:.1} over 10-20 s",
                at(&p.ckf, 5.0),
                at(&p.ckf, 10.0),
                p.ckf.final_position_rms(),
                position_growth_exponent(&p.ckf, t_end),
            ),
            note: format!(
                "reproduced: x, y, v unobservable from theta alone. With sigma_eps = 1 rad most of it is attitude noise through the theta->v coupling the CKF drops (no bias: {:.1} m); the bias alone gives 1/2 |R b| t^2 = {bias_end:.1} m, the growth seen with an accurate attitude sensor (radial scenario CKF: {:.1} m)",
                var(labels::NO_BIAS, |v| v.ckf_final_position_rms),
                r.radial.ckf.final_position_rms(),
            ),
        },
        Headline {
            quantity: "CKF+OTE position/velocity error (Figs 5-8)".into(),
            paper: "converges within 5 s, good tracking accuracy".into(),
            estim: format!(
                "{:.1} m, {:.1} m/s at {t_end:.0} s vs CKF {:.1} m, {:.1} m/s (gamma = {}, RMS over {n} seeds); gamma = 0.99: {:.1} m",
                p.ckf_ote.final_position_rms(),
                p.ckf_ote.final_velocity_rms(),
                p.ckf.final_position_rms(),
                p.ckf.final_velocity_rms(),
                p.config.ote.forgetting,
                var(labels::GAMMA_099, |v| v.ckf_ote_final_position_rms),
            ),
            note: "not reproduced: g(D) is computed from the CKF's own state, so no position or velocity information enters; it imposes radial flight along the body axis, which the section IV ICs violate, and d*omega_hat multiplies rate errors by the range (E10)".into(),
        },
        Headline {
            quantity: "attitude and rate (Figs 9-10)".into(),
            paper: "satisfactory in both CKF and CKF+OTE".into(),
            estim: format!(
                "theta RMS {:.2} deg (sqrt P {:.2}), omega RMS {:.3} deg/s (sqrt P {:.3}) at {t_end:.0} s; identical with OTE",
                deg(last(&p.ckf.attitude_rms)),
                deg(last(&p.ckf.attitude_sigma)),
                deg(last(&p.ckf.rate_rms)),
                deg(last(&p.ckf.rate_sigma)),
            ),
            note: "reproduced: theta, omega are observable from E = theta and the OTE does not touch them".into(),
        },
        Headline {
            quantity: "OTE steady state (gamma = 0.95, S_p = 0.01 I, P_p(0) = I)".into(),
            paper: "for 0 < gamma < 1, K_p is prevented from shrinking to zero; P_p is the error covariance of r_e".into(),
            estim: format!(
                "K_p -> {:.6} I, P_p -> {:.3e} I after {} cycles (closed forms (1-gamma) I = {:.6} I, (1-gamma) S_p = {:.3e} I)",
                ss.gain[(0, 0)],
                ss.covariance[(0, 0)],
                ss.steps,
                ss.gain_closed_form[(0, 0)],
                ss.covariance_closed_form[(0, 0)],
            ),
            note: "gain reproduced; P_p is a fading-memory weight, the steady error covariance of smoothed white noise is S_p (1-gamma)/(1+gamma) (E9)".into(),
        },
        Headline {
            quantity: "estim's radial scenario (not in the paper)".into(),
            paper: "-".into(),
            estim: format!(
                "CKF {:.1} m vs CKF+OTE {:.1} m at {t_end:.0} s; velocity {:.2} vs {:.2} m/s",
                r.radial.ckf.final_position_rms(),
                r.radial.ckf_ote.final_position_rms(),
                r.radial.ckf.final_velocity_rms(),
                r.radial.ckf_ote.final_velocity_rms(),
            ),
            note: format!(
                "estim's reading: with radial ICs and sigma_eps = 0.01 rad the OTE removes the cross-track drift; the along-track 1/2 b t^2 remains, and its velocity error grows with range (d*omega_hat). With the paper's sigma_eps = 1 rad the radial ICs alone do not help: {:.1} m vs CKF {:.1} m",
                var(labels::RADIAL_NOISY, |v| v.ckf_ote_final_position_rms),
                var(labels::RADIAL_NOISY, |v| v.ckf_final_position_rms),
            ),
        },
        Headline {
            quantity: "OTE with eq 38/39 as printed".into(),
            paper: "eq 38/39".into(),
            estim: format!(
                "{:.0} m at {t_end:.0} s",
                var(labels::PRINTED_LIKELIHOOD, |v| v.ckf_ote_final_position_rms)
            ),
            note: "sin/cos swapped against eq 27/28 (E2); estim uses eq 27/28".into(),
        },
        Headline {
            quantity: "full Jacobian instead of Psi".into(),
            paper: "Psi = I + F T (eq 33/36)".into(),
            estim: format!(
                "EKF {:.1} m vs CKF {:.1} m at {t_end:.0} s",
                var(labels::FULL_JACOBIAN, |v| v.ckf_final_position_rms),
                p.ckf.final_position_rms(),
            ),
            note: "keeping the theta->velocity coupling lets the attitude measurement correct part of the velocity error it causes".into(),
        },
    ]
}

fn history_table(r: &SectionIvResult) {
    println!(
        "  {:>5} | {:>9} {:>9} | {:>9} {:>9} | {:>15} | {:>17}",
        "t [s]",
        "CKF |p|",
        "CKF |v|",
        "+OTE |p|",
        "+OTE |v|",
        "theta deg (sqP)",
        "omega deg/s (sqP)"
    );
    for t in [1.0, 2.0, 5.0, 10.0, 15.0, 20.0] {
        let (c, o) = (&r.ckf, &r.ckf_ote);
        let i = c.index_at(t);
        if (c.time[i] - t).abs() > 1e-9 {
            continue;
        }
        println!(
            "  {:>5.1} | {:>8.2}m {:>6.2}m/s | {:>8.2}m {:>6.2}m/s | {:>6.2} ({:>5.2}) | {:>7.3} ({:>6.3})",
            t,
            c.position_rms[i],
            c.velocity_rms[i],
            o.position_rms[i],
            o.velocity_rms[i],
            c.attitude_rms[i].to_degrees(),
            c.attitude_sigma[i].to_degrees(),
            c.rate_rms[i].to_degrees(),
            c.rate_sigma[i].to_degrees(),
        );
    }
}

fn series<'a>(
    label: &'a str,
    h: &ErrorHistory,
    f: impl Fn(&ErrorHistory, usize) -> f64,
) -> Series<'a> {
    Series {
        label,
        points: (0..h.time.len()).map(|i| (h.time[i], f(h, i))).collect(),
    }
}

fn figures(r: &LeeHuangResult) -> Vec<String> {
    let p = &r.paper;
    let n = p.config.seeds;
    let drift = Series {
        label: "1/2 |R b| t^2 (bias alone)",
        points: p
            .ckf
            .time
            .iter()
            .zip(&p.bias_drift)
            .map(|(t, b)| (*t, b.norm()))
            .collect(),
    };
    let mut out = Vec::new();
    let mut plot = |file: &str, title: String, y: &str, s: &[Series<'_>]| match line_plot(
        file, &title, "t [s]", y, s,
    ) {
        Ok(path) => out.push(path.display().to_string()),
        Err(e) => eprintln!("figure {file} failed: {e}"),
    };
    plot(
        "lee_huang_position_error.svg",
        format!("Section IV: position error, RMS over {n} seeds (paper ICs)"),
        "|p_hat - p| [m]",
        &[
            series("CKF", &p.ckf, |h, i| h.position_rms[i]),
            series("CKF + OTE (gamma 0.95)", &p.ckf_ote, |h, i| {
                h.position_rms[i]
            }),
            series("CKF own sqrt tr P_pp", &p.ckf, |h, i| h.position_sigma[i]),
            drift,
        ],
    );
    plot(
        "lee_huang_velocity_error.svg",
        format!("Section IV: velocity error, RMS over {n} seeds (paper ICs)"),
        "|v_hat - v| [m/s]",
        &[
            series("CKF", &p.ckf, |h, i| h.velocity_rms[i]),
            series("CKF + OTE (gamma 0.95)", &p.ckf_ote, |h, i| {
                h.velocity_rms[i]
            }),
        ],
    );
    plot(
        "lee_huang_attitude_error.svg",
        format!("Section IV: attitude error, RMS over {n} seeds (same with OTE)"),
        "[deg]",
        &[
            series("theta RMS error", &p.ckf, |h, i| {
                h.attitude_rms[i].to_degrees()
            }),
            series("sqrt P_theta", &p.ckf, |h, i| {
                h.attitude_sigma[i].to_degrees()
            }),
        ],
    );
    plot(
        "lee_huang_rate_error.svg",
        format!("Section IV: rate error, RMS over {n} seeds (same with OTE)"),
        "[deg/s]",
        &[
            series("omega RMS error", &p.ckf, |h, i| h.rate_rms[i].to_degrees()),
            series("sqrt P_omega", &p.ckf, |h, i| h.rate_sigma[i].to_degrees()),
        ],
    );
    let q = &r.radial;
    plot(
        "lee_huang_radial_position_error.svg",
        format!("estim's reading: radial ICs, sigma_eps = 0.01 rad, RMS over {n} seeds"),
        "|p_hat - p| [m]",
        &[
            series("CKF", &q.ckf, |h, i| h.position_rms[i]),
            series("CKF + OTE (gamma 0.95)", &q.ckf_ote, |h, i| {
                h.position_rms[i]
            }),
            Series {
                label: "1/2 |R b| t^2 (bias alone)",
                points: q
                    .ckf
                    .time
                    .iter()
                    .zip(&q.bias_drift)
                    .map(|(t, b)| (*t, b.norm()))
                    .collect(),
            },
        ],
    );
    out
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(run_in(quick, &Session::whole())?)?)
}

/// The example body as `session` says (whole, one shard: `None`, or the merge of the shards).
pub fn run_in(
    quick: bool,
    session: &Session,
) -> Result<Option<Output>, Box<dyn std::error::Error>> {
    let config = if quick {
        LeeHuangConfig::quick()
    } else {
        LeeHuangConfig::full()
    };
    let Some(r) = run_experiment_in(&config, session)? else {
        return Ok(None);
    };
    let n = r.paper.config.seeds;
    let t_end = r.paper.config.duration;

    println!(
        "Lee & Huang 2002, section IV: T = {} s, {t_end} s, RMS over {n} seeds",
        r.paper.config.dt
    );
    println!("(errors are RMS over seeds of the error norm; sqP = the filter's own sqrt P)\n");
    println!(
        "{} (CKF = paper's Psi Jacobian; OTE gamma = 0.95, S_p = 0.01 I, P_p(0) = I):",
        labels::PAPER
    );
    history_table(&r.paper);
    println!(
        "\n{} -- estim's second scenario, NOT the paper's:",
        labels::RADIAL
    );
    history_table(&r.radial);

    println!("\nReadings and variants, at {t_end} s:");
    println!(
        "  {:<52} | {:>9} {:>10} | {:>9} {:>10}",
        "configuration", "CKF |p|", "+OTE |p|", "CKF |v|", "+OTE |v|"
    );
    for v in &r.variants {
        println!(
            "  {:<52} | {:>8.1}m {:>9.1}m | {:>6.2}m/s {:>7.2}m/s",
            v.label,
            v.ckf_final_position_rms,
            v.ckf_ote_final_position_rms,
            v.ckf_final_velocity_rms,
            v.ckf_ote_final_velocity_rms
        );
    }

    let ss = &r.steady_state;
    println!(
        "\nOTE steady state (gamma = {}, S_p = {} I, P_p(0) = {} I) after {} cycles of FadingMemoryRls:",
        ss.settings.forgetting,
        ss.settings.weight[(0, 0)],
        ss.settings.initial_covariance[(0, 0)],
        ss.steps
    );
    println!(
        "  K_p = {:.12} I  (closed form (1-gamma) I = {:.12} I)",
        ss.gain[(0, 0)],
        ss.gain_closed_form[(0, 0)]
    );
    println!(
        "  P_p = {:.12e} I  (closed form (1-gamma) S_p = {:.12e} I)",
        ss.covariance[(0, 0)],
        ss.covariance_closed_form[(0, 0)]
    );

    println!("\nHeadlines (paper vs estim):");
    for h in headlines(&r) {
        println!(
            "- {}\n    paper: {}\n    estim: {}\n    note:  {}",
            h.quantity, h.paper, h.estim, h.note
        );
    }

    println!("\nFigures:");
    for f in figures(&r) {
        println!("  {f}");
    }

    let json = {
        let json = serde_json::json!({
            "ote_steady_gain": ss.gain[(0, 0)],
            "ote_steady_p": ss.covariance[(0, 0)],
            "ckf_final_pos_err_m": r.paper.ckf.final_position_rms(),
            "ckf_ote_final_pos_err_m": r.paper.ckf_ote.final_position_rms(),
        });
        json
    };
    let headlines = headlines(&r);
    Ok(Some(Output { json, headlines }))
}
