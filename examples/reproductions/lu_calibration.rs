//! Lu (UCLA MAE 271A report, 2017): accelerometer bias calibration from GPS, a 3-state
//! error-state Kalman filter (δp, δv, b) at 200 Hz with 5 Hz GPS position+velocity fixes, and
//! its Monte Carlo validation (§3.2) on estim's Monte Carlo runner.
//!
//! Runs 5000 realizations over 30 s (500 with `--quick`) with the consistent filter and prints
//! the four checks of the paper (ensemble mean error, ensemble covariance vs P, orthogonality,
//! residual correlation between 20 s and 30 s) with the runner's verdict table; then the same
//! Monte Carlo for each of the paper's printed variants (W = 0.0016, M₀ = diag(1, 100, 0.01),
//! Φ₁₃ = +Δt²/2, closed-form truth) and their verdicts; one realization filtered and smoothed
//! (Rauch–Tung–Striebel over all its steps: the bias and its σ from the whole run); the gains;
//! headlines. Writes figures to
//! `target/figures/`, and with `--json` prints one JSON line last. `--sequential` runs the
//! realizations on one thread (the default uses rayon; `RAYON_NUM_THREADS` sets the threads).
//!
//! `cargo run --release --example lu_calibration [-- --json] [-- --quick] [-- --sequential]`

use std::time::Instant;

use crate::common::{
    Band, Headline, Output, Series, band_plot, line_plot, lines_and_dots_plot, progress_bar,
};
use crate::sharding::Session;
use estim::core::Gaussian;
use estim::filters::ValidationError;
use estim::filters::consistency::{Check, Verdict};
use estim::filters::monte_carlo::{EnsembleStats, MonteCarlo, Progress, Recorder};
use estim::filters::smoother::Rts;
use estim::filters::{Estimator, KalmanFilter, Update};
use estim::models::lu::{
    AccelerationProfile, CovarianceAnalysis, CovarianceHistory, FilterSettings, LuFilter,
    Mechanisation, PAPER_RESIDUAL_CORRELATION, Realization, Scenario, Simulator, TruthIntegration,
    covariance_analysis, covariance_history, run_realization,
};
use estim::nalgebra::{Matrix2, Matrix3, Matrix3x2, Vector2, Vector3};

/// The labels of the Monte Carlo configurations.
pub mod labels {
    /// The consistent filter (estim's reading).
    pub const CONSISTENT: &str = "consistent filter (estim's reading)";
    /// Filter W = 0.0016 as in the listing.
    pub const PRINTED_NOISE: &str = "filter W = 0.0016 (listing, E3)";
    /// M₀ = diag(1, 100, 0.01) as in the listing.
    pub const PRINTED_PRIOR: &str = "M0 = diag(1, 100, 0.01) (listing, E2)";
    /// Φ₁₃ = +Δt²/2 as printed.
    pub const PRINTED_COUPLING: &str = "Phi13 = +dt^2/2 (printed, E4)";
    /// Closed-form truth with the Euler mechanisation.
    pub const EXACT_TRUTH: &str = "closed-form truth, Euler mechanisation (E5)";
}

/// How the runner executes the realizations.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Execution {
    /// [`MonteCarlo::run`]: on rayon's thread pool when estim-filters' `parallel` feature is on
    /// (as it is for the examples, through the root package's dev-dependency;
    /// `RAYON_NUM_THREADS` sets the threads), else sequential. The same bits either way.
    #[default]
    Default,
    /// [`MonteCarlo::run_sequential`] on the calling thread (same bits).
    Sequential,
}

/// One Monte Carlo validation (§3.2).
#[derive(Clone, Debug, PartialEq)]
pub struct MonteCarloConfig {
    /// A short name for tables.
    pub label: String,
    /// Truth and sensors.
    pub scenario: Scenario,
    /// What the filter assumes.
    pub filter: FilterSettings,
    /// Number of realizations N (the paper: 5000).
    pub runs: usize,
    /// Master seed of the runner (run i uses `run_seed(seed, i)`).
    pub seed: u64,
    /// Confidence of each check of the verdict.
    pub confidence: f64,
    /// The two times of the residual check (1/N) Σ r(t₁) r(t₂)ᵀ \[s\] (the paper: 20 s, 30 s).
    pub residual_times: (f64, f64),
    /// Parallel or sequential.
    pub execution: Execution,
}

impl MonteCarloConfig {
    /// The paper's validation with the consistent filter: 5000 runs over 30 s, residuals at
    /// 20 s and 30 s, checks at 99 %.
    pub fn full() -> Self {
        let scenario = Scenario::paper();
        Self {
            label: labels::CONSISTENT.into(),
            scenario,
            filter: FilterSettings::consistent(&scenario),
            runs: 5000,
            seed: 271,
            confidence: 0.99,
            residual_times: (20.0, 30.0),
            execution: Execution::Default,
        }
    }

    /// The same with 500 runs.
    pub fn quick() -> Self {
        Self::full().with_runs(500)
    }

    /// The same with `runs` realizations.
    pub fn with_runs(mut self, runs: usize) -> Self {
        self.runs = runs;
        self
    }

    /// The same with master seed `seed`.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// The same run sequentially or by default.
    pub fn with_execution(mut self, execution: Execution) -> Self {
        self.execution = execution;
        self
    }

    /// The listing's filter W = 0.0016 on the same truth (erratum E3).
    pub fn printed_noise(self) -> Self {
        Self {
            label: labels::PRINTED_NOISE.into(),
            filter: FilterSettings::printed_noise(&self.scenario),
            ..self
        }
    }

    /// The listing's M₀ = diag(1, 100, 0.01) (erratum E2).
    pub fn printed_prior(self) -> Self {
        Self {
            label: labels::PRINTED_PRIOR.into(),
            filter: FilterSettings::printed_prior(&self.scenario),
            ..self
        }
    }

    /// The printed Φ₁₃ = +Δt²/2 in the filter (erratum E4).
    pub fn printed_coupling(self) -> Self {
        Self {
            label: labels::PRINTED_COUPLING.into(),
            filter: FilterSettings::printed_coupling(&self.scenario),
            ..self
        }
    }

    /// The closed-form truth of §2.1 with the Euler mechanisation (erratum E5).
    pub fn exact_truth(self) -> Self {
        Self {
            label: labels::EXACT_TRUTH.into(),
            scenario: self.scenario.with_truth(TruthIntegration::Exact),
            ..self
        }
    }
}

/// The result of one Monte Carlo validation. Per-slot vectors have one entry per slot: slot 0
/// is t = 0 (the prior), slot k the k-th GPS update (t = 0.2 k s), all a posteriori.
#[derive(Clone, Debug, PartialEq)]
pub struct MonteCarloResult {
    /// The configuration run.
    pub config: MonteCarloConfig,
    /// Slot times \[s\].
    pub time: Vec<f64>,
    /// diag of the filter's P (mean over runs; the same in every run) at each slot.
    pub filter_variance: Vec<Vector3<f64>>,
    /// diag of the ensemble error covariance P^ave = 1/(N−1) Σ (e − ē)(e − ē)ᵀ.
    pub ensemble_variance: Vec<Vector3<f64>>,
    /// The ensemble mean error e^ave = (1/N) Σ e.
    pub mean_error: Vec<Vector3<f64>>,
    /// max over (i, j) of |corr(eᵢ, δx̂ⱼ)| across runs (the normalised orthogonality check;
    /// NaN at t = 0, where δx̂ = 0 in every run).
    pub orthogonality: Vec<f64>,
    /// The residual slots (t₁, t₂) actually used \[s\].
    pub residual_times: (f64, f64),
    /// (1/N) Σ r(t₁) r(t₂)ᵀ (rows: r(t₁) position, velocity; columns: r(t₂)).
    pub residual_correlation: Matrix2<f64>,
    /// Its standard error for independent zero-mean residuals with the filter's innovation
    /// covariances S(t₁), S(t₂): √(S₁ᵢᵢ S₂ⱼⱼ / N).
    pub residual_standard_error: Matrix2<f64>,
    /// Each entry normalised by the ensemble's own second moments (the runner's statistic,
    /// Bar-Shalom eq 5.4.2-12), times √N: ≈ N(0, 1) when the residuals are independent.
    pub residual_z: Matrix2<f64>,
    /// The exact moments the Monte Carlo estimates (covariance analysis of the same truth and
    /// filter), entry k at slot k.
    pub analysis: CovarianceAnalysis,
    /// The runner's statistics (all slots).
    pub stats: EnsembleStats,
    /// The runner's verdict at the configured confidence.
    pub verdict: Verdict,
    /// Wall time of the Monte Carlo run alone \[s\].
    pub wall_s: f64,
}

/// Summary numbers of a [`MonteCarloResult`] over the GPS updates (slots ≥ 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonteCarloSummary {
    /// max over updates of |e^ave| / √(P/N), per component (δp, δv, b): ≲ 3.5 when unbiased.
    pub max_mean_error_sigmas: Vector3<f64>,
    /// min over updates of P^ave/P, per component.
    pub covariance_ratio_min: Vector3<f64>,
    /// max over updates of P^ave/P, per component.
    pub covariance_ratio_max: Vector3<f64>,
    /// P^ave/P at the last update.
    pub covariance_ratio_end: Vector3<f64>,
    /// max over updates and entries of |corr(e, δx̂)|.
    pub max_orthogonality: f64,
    /// The same times √N (≈ the number of standard errors).
    pub max_orthogonality_sigmas: f64,
    /// max |residual_z| over the four entries.
    pub max_residual_z: f64,
    /// max over updates of |e^ave| per component \[m, m/s, m/s²\].
    pub max_mean_error: Vector3<f64>,
    /// The exact max over updates of |E e| (covariance analysis; 0 unless the truth is the
    /// closed form).
    pub exact_max_mean_error: Vector3<f64>,
    /// The exact cov(e)/P at the last update (covariance analysis).
    pub exact_covariance_ratio_end: Vector3<f64>,
    /// The exact min over updates of cov(e)/P.
    pub exact_covariance_ratio_min: Vector3<f64>,
    /// The exact max over updates of cov(e)/P.
    pub exact_covariance_ratio_max: Vector3<f64>,
    /// The exact max over updates and entries of |corr(e, δx̂)|.
    pub exact_max_orthogonality: f64,
}

impl MonteCarloResult {
    /// The slot nearest to time `t`.
    pub fn slot_at(&self, t: f64) -> usize {
        nearest(&self.time, t)
    }

    /// The summary over the updates.
    pub fn summary(&self) -> MonteCarloSummary {
        let n = self.config.runs as f64;
        let mut s = MonteCarloSummary {
            max_mean_error_sigmas: Vector3::zeros(),
            covariance_ratio_min: Vector3::repeat(f64::INFINITY),
            covariance_ratio_max: Vector3::repeat(f64::NEG_INFINITY),
            covariance_ratio_end: Vector3::repeat(f64::NAN),
            max_orthogonality: 0.0,
            max_orthogonality_sigmas: 0.0,
            max_residual_z: self.residual_z.abs().max(),
            max_mean_error: Vector3::zeros(),
            exact_max_mean_error: Vector3::zeros(),
            exact_covariance_ratio_end: Vector3::repeat(f64::NAN),
            exact_covariance_ratio_min: Vector3::repeat(f64::INFINITY),
            exact_covariance_ratio_max: Vector3::repeat(f64::NEG_INFINITY),
            exact_max_orthogonality: 0.0,
        };
        let a = &self.analysis;
        for k in 1..self.time.len() {
            let p = &self.filter_variance[k];
            let ratio = self.ensemble_variance[k].component_div(p);
            for i in 0..3 {
                let sig = (self.mean_error[k][i].abs() / (p[i] / n).sqrt()).max(0.0);
                s.max_mean_error_sigmas[i] = s.max_mean_error_sigmas[i].max(sig);
                s.covariance_ratio_min[i] = s.covariance_ratio_min[i].min(ratio[i]);
                s.covariance_ratio_max[i] = s.covariance_ratio_max[i].max(ratio[i]);
            }
            s.covariance_ratio_end = ratio;
            if self.orthogonality[k].is_finite() {
                s.max_orthogonality = s.max_orthogonality.max(self.orthogonality[k]);
            }
            s.max_mean_error = s.max_mean_error.sup(&self.mean_error[k].abs());
            if k < a.time.len() {
                let r = a.covariance_ratio(k);
                s.exact_covariance_ratio_end = r;
                s.exact_covariance_ratio_min = s.exact_covariance_ratio_min.inf(&r);
                s.exact_covariance_ratio_max = s.exact_covariance_ratio_max.sup(&r);
                s.exact_max_mean_error = s.exact_max_mean_error.sup(&a.mean_error[k].abs());
                let o = a.max_orthogonality(k);
                if o.is_finite() {
                    s.exact_max_orthogonality = s.exact_max_orthogonality.max(o);
                }
            }
        }
        s.max_orthogonality_sigmas = s.max_orthogonality * n.sqrt();
        s
    }

    /// Whether the verdict failed `check`.
    pub fn failed(&self, check: Check) -> bool {
        self.verdict.failed(check)
    }
}

/// Runs one Monte Carlo validation on the framework's runner: per realization, the seeded
/// simulator and the filter over the whole run, recording at t = 0 and at every GPS update the
/// error state δx against the filter (error, P, estimate δx̂), the NIS, and the residuals at
/// the two residual times.
pub fn run_monte_carlo(
    config: &MonteCarloConfig,
) -> Result<MonteCarloResult, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(run_monte_carlo_in(
        config,
        &Session::whole(),
    )?)?)
}

/// [`run_monte_carlo`] as `session` says: whole, one shard (`None`) or the merge of the
/// shards (keyed by the configuration's label).
pub fn run_monte_carlo_in(
    config: &MonteCarloConfig,
    session: &Session,
) -> Result<Option<MonteCarloResult>, Box<dyn std::error::Error>> {
    let scenario = config.scenario;
    let settings = config.filter;
    // Fail early (not inside a run) on an invalid scenario or prior.
    LuFilter::new(&scenario, &settings)?;
    let updates = scenario.updates();
    let slots = updates + 1;
    let (a, b) = (
        scenario.update_index(config.residual_times.0),
        scenario.update_index(config.residual_times.1),
    );
    let mc = MonteCarlo::new(config.runs, slots)?
        .with_seed(config.seed)
        .with_residual_pair(a, b)?;
    // a(t_j) once for all runs (bit-identical to each simulator computing it).
    let profile = AccelerationProfile::new(&scenario)?;
    let realization = |_run: usize, seed: u64, rec: &mut Recorder| -> Result<(), ValidationError> {
        let mut sim = Simulator::with_profile(&scenario, seed, &profile);
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
    let start = Instant::now();
    let bar = progress_bar("Lu Monte Carlo", config.runs);
    let progress = |p: Progress| bar.set_position(p.runs_done as u64);
    let stats = session.run_with(
        &config.label,
        &mc,
        realization,
        |mc, realization| match config.execution {
            Execution::Default => mc.run_with_progress(realization, progress),
            Execution::Sequential => mc.run_sequential_with_progress(realization, progress),
        },
    )?;
    bar.finish_and_clear();
    let Some(stats) = stats else {
        return Ok(None);
    };
    let wall_s = start.elapsed().as_secs_f64();
    let verdict = stats.verdict(config.confidence)?;

    let history = covariance_history(&scenario, &settings, scenario.steps)?;
    let analysis = covariance_analysis(&scenario, &settings)?;
    let mut out = MonteCarloResult {
        config: config.clone(),
        time: (0..slots)
            .map(|k| if k == 0 { 0.0 } else { scenario.update_time(k) })
            .collect(),
        filter_variance: Vec::with_capacity(slots),
        ensemble_variance: Vec::with_capacity(slots),
        mean_error: Vec::with_capacity(slots),
        orthogonality: Vec::with_capacity(slots),
        residual_times: (scenario.update_time(a), scenario.update_time(b)),
        residual_correlation: Matrix2::repeat(f64::NAN),
        residual_standard_error: Matrix2::repeat(f64::NAN),
        residual_z: Matrix2::repeat(f64::NAN),
        analysis,
        stats,
        verdict,
        wall_s,
    };
    for slot in &out.stats.slots {
        let Some(e) = &slot.estimate else {
            out.filter_variance.push(Vector3::repeat(f64::NAN));
            out.ensemble_variance.push(Vector3::repeat(f64::NAN));
            out.mean_error.push(Vector3::repeat(f64::NAN));
            out.orthogonality.push(f64::NAN);
            continue;
        };
        out.filter_variance
            .push(Vector3::from_fn(|i, _| e.mean_covariance[(i, i)]));
        out.ensemble_variance
            .push(Vector3::from_fn(|i, _| e.error_covariance[(i, i)]));
        out.mean_error
            .push(Vector3::from_fn(|i, _| e.mean_error[i]));
        let max = e
            .orthogonality_correlation
            .iter()
            .filter(|v| v.is_finite())
            .fold(
                f64::NAN,
                |m, v| if m.is_nan() { v.abs() } else { m.max(v.abs()) },
            );
        out.orthogonality.push(max);
    }
    if let Some(pair) = out.stats.residual_pairs.first()
        && pair.cross_correlation.shape() == (2, 2)
    {
        let n = pair.samples as f64;
        let h = nalgebra::Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
        let v = scenario.gps().noise_covariance();
        let s1 = h * history.prior[a] * h.transpose() + v;
        let s2 = h * history.prior[b] * h.transpose() + v;
        for i in 0..2 {
            for j in 0..2 {
                out.residual_correlation[(i, j)] = pair.cross_correlation[(i, j)];
                out.residual_standard_error[(i, j)] = (s1[(i, i)] * s2[(j, j)] / n).sqrt();
                out.residual_z[(i, j)] = pair.normalized[(i, j)] * n.sqrt();
            }
        }
    }
    Ok(Some(out))
}

/// The whole experiment of the example.
#[derive(Clone, Debug, PartialEq)]
pub struct LuConfig {
    /// The validation with the consistent filter.
    pub monte_carlo: MonteCarloConfig,
    /// The paper's printed variants (same runs and seed).
    pub variants: Vec<MonteCarloConfig>,
    /// Seed of the single realization shown in the figures.
    pub realization_seed: u64,
    /// Horizon of the long covariance/gain run (the gains' limits) \[s\].
    pub long_horizon: f64,
}

impl LuConfig {
    /// 5000 runs for the consistent filter and for each of the four variants (W = 0.0016,
    /// printed M₀, printed Φ₁₃, closed-form truth); gains to 3000 s.
    pub fn full() -> Self {
        Self::with_monte_carlo(MonteCarloConfig::full())
    }

    /// The same with 500 runs each.
    pub fn quick() -> Self {
        Self::with_monte_carlo(MonteCarloConfig::quick())
    }

    /// The experiment around `mc` (the variants copy its runs and seed).
    pub fn with_monte_carlo(mc: MonteCarloConfig) -> Self {
        Self {
            variants: vec![
                mc.clone().printed_noise(),
                mc.clone().printed_prior(),
                mc.clone().printed_coupling(),
                mc.clone().exact_truth(),
            ],
            monte_carlo: mc,
            realization_seed: 2017,
            long_horizon: 3000.0,
        }
    }
}

/// The result of [`run_experiment`].
#[derive(Clone, Debug, PartialEq)]
pub struct LuResult {
    /// The configuration.
    pub config: LuConfig,
    /// The consistent filter's validation.
    pub monte_carlo: MonteCarloResult,
    /// The variants, in the configured order.
    pub variants: Vec<MonteCarloResult>,
    /// The deterministic P and K at each update over the scenario (information form).
    pub covariance: CovarianceHistory,
    /// P at the end of the long horizon.
    pub long_horizon_covariance: Matrix3<f64>,
    /// K at the end of the long horizon.
    pub long_horizon_gain: Matrix3x2<f64>,
    /// One realization with the consistent filter (figures 8–10 of the paper).
    pub realization: Realization,
    /// The same realization filtered and smoothed (RTS over the whole run).
    pub smoothed: SmoothedRealization,
}

/// Runs the experiment: the consistent Monte Carlo, the variants, the covariance history and
/// the long-horizon gains, and one realization.
pub fn run_experiment(config: &LuConfig) -> Result<LuResult, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(run_experiment_in(
        config,
        &Session::whole(),
    )?)?)
}

/// [`run_experiment`] as `session` says: whole, one shard of each Monte Carlo (`None`) or
/// the merge of the shards.
pub fn run_experiment_in(
    config: &LuConfig,
    session: &Session,
) -> Result<Option<LuResult>, Box<dyn std::error::Error>> {
    let monte_carlo = run_monte_carlo_in(&config.monte_carlo, session)?;
    let variants = config
        .variants
        .iter()
        .map(|v| run_monte_carlo_in(v, session))
        .collect::<Result<Vec<_>, _>>()?;
    // Every variant runs (its shard) before a shard stops here.
    let (Some(monte_carlo), Some(variants)) = (
        monte_carlo,
        variants.into_iter().collect::<Option<Vec<_>>>(),
    ) else {
        return Ok(None);
    };
    let mc = &config.monte_carlo;
    let covariance = covariance_history(&mc.scenario, &mc.filter, mc.scenario.steps)?;
    let long = mc.scenario.with_duration(config.long_horizon);
    let long_history = covariance_history(&long, &mc.filter, long.steps)?;
    let last = long_history.posterior.len() - 1;
    let realization = run_realization(&mc.scenario, &mc.filter, config.realization_seed)?;
    let smoothed = run_smoothed_realization(&mc.scenario, &mc.filter, config.realization_seed)?;
    Ok(Some(LuResult {
        config: config.clone(),
        monte_carlo,
        variants,
        long_horizon_covariance: long_history.posterior[last],
        long_horizon_gain: long_history.gain[last],
        covariance,
        realization,
        smoothed,
    }))
}

/// One realization filtered forward and smoothed backward (Rauch–Tung–Striebel over the whole
/// run, every accelerometer step): the offline calibration. Entry j is time j Δt.
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothedRealization {
    /// Times \[s\], 0 … duration, every accelerometer step.
    pub time: Vec<f64>,
    /// The true error state δx = (δp, δv, b).
    pub truth: Vec<Vector3<f64>>,
    /// The forward filter's δx̂ given the data up to tⱼ (a posteriori at a fix, predicted
    /// between fixes).
    pub filtered: Vec<Vector3<f64>>,
    /// Its √diag P.
    pub filtered_sigma: Vec<Vector3<f64>>,
    /// The smoothed δx̂ˢ given every fix of the run.
    pub smoothed: Vec<Vector3<f64>>,
    /// Its √diag Pˢ.
    pub smoothed_sigma: Vec<Vector3<f64>>,
    /// Wall time of the backward pass alone \[s\].
    pub backward_wall_s: f64,
}

/// Summary numbers of a [`SmoothedRealization`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothingSummary {
    /// RMS over the run of b − b̂, forward filter \[m/s²\].
    pub bias_rms_filtered: f64,
    /// The same for the smoother.
    pub bias_rms_smoothed: f64,
    /// RMS over the run of δp − δp̂: filter, smoother \[m\].
    pub position_rms: (f64, f64),
    /// RMS over the run of δv − δv̂: filter, smoother \[m/s\].
    pub velocity_rms: (f64, f64),
    /// max over the run of |b̂ˢⱼ − b̂ˢ_K|: 0 up to rounding, b being a random constant.
    pub smoothed_bias_spread: f64,
}

impl SmoothedRealization {
    /// The index of the time nearest to `t`.
    pub fn index_at(&self, t: f64) -> usize {
        nearest(&self.time, t)
    }

    /// RMS errors over the run and the spread of the smoothed bias.
    pub fn summary(&self) -> SmoothingSummary {
        let n = self.time.len() as f64;
        let rms = |estimate: &[Vector3<f64>], i: usize| {
            (self
                .truth
                .iter()
                .zip(estimate)
                .map(|(x, e)| (x[i] - e[i]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        };
        let last = self.smoothed[self.smoothed.len() - 1][2];
        SmoothingSummary {
            bias_rms_filtered: rms(&self.filtered, 2),
            bias_rms_smoothed: rms(&self.smoothed, 2),
            position_rms: (rms(&self.filtered, 0), rms(&self.smoothed, 0)),
            velocity_rms: (rms(&self.filtered, 1), rms(&self.smoothed, 1)),
            smoothed_bias_spread: self
                .smoothed
                .iter()
                .map(|x| (x[2] - last).abs())
                .fold(0.0, f64::max),
        }
    }
}

/// Runs the filter of [`LuFilter`] (the same steps: prediction at every accelerometer sample,
/// update at every fix) on realization `seed`, recording the predictions through [`Rts`], then
/// smooths the whole run.
///
/// Errors: an invalid scenario or prior, a failed filter step, a failed backward step.
pub fn run_smoothed_realization(
    scenario: &Scenario,
    settings: &FilterSettings,
    seed: u64,
) -> Result<SmoothedRealization, Box<dyn std::error::Error>> {
    scenario.validate()?;
    settings.validate()?;
    let mut sim = Simulator::new(scenario, seed);
    let mut kf = KalmanFilter::new(Gaussian::new(
        Vector3::zeros(),
        settings.initial_covariance,
    )?);
    let mut mechanisation = Mechanisation::new(scenario.position_mean, scenario.velocity_mean);
    let (process, gps) = (settings.process(), scenario.gps());
    let mut rts = Rts::new();
    let steps = scenario.steps + 1;
    let mut out = SmoothedRealization {
        time: Vec::with_capacity(steps),
        truth: Vec::with_capacity(steps),
        filtered: Vec::with_capacity(steps),
        filtered_sigma: Vec::with_capacity(steps),
        smoothed: Vec::new(),
        smoothed_sigma: Vec::new(),
        backward_wall_s: 0.0,
    };
    fn record(
        out: &mut SmoothedRealization,
        t: f64,
        sim: &Simulator,
        kf: &KalmanFilter<f64, estim::nalgebra::U3>,
        m: &Mechanisation,
    ) {
        out.time.push(t);
        out.truth.push(sim.truth().error_state(m));
        out.filtered.push(*kf.state());
        out.filtered_sigma
            .push(kf.covariance().diagonal().map(f64::sqrt));
    }
    record(&mut out, 0.0, &sim, &kf, &mechanisation);
    for _ in 0..scenario.steps {
        let acceleration = sim.accelerometer();
        rts.predict(&mut kf, &process, &(), scenario.dt)?;
        mechanisation.step(acceleration, scenario.dt);
        if sim.gps_due() {
            let z = sim.gps();
            let dz = Vector2::new(z[0] - mechanisation.position, z[1] - mechanisation.velocity);
            kf.update(&gps, &dz)?;
        }
        record(&mut out, sim.time(), &sim, &kf, &mechanisation);
    }
    let start = Instant::now();
    let smoothed = rts.smooth(&kf)?;
    out.backward_wall_s = start.elapsed().as_secs_f64();
    out.smoothed = smoothed.iter().map(|g| *g.mean()).collect();
    out.smoothed_sigma = smoothed
        .iter()
        .map(|g| g.covariance().diagonal().map(f64::sqrt))
        .collect();
    Ok(out)
}

/// The smoothing table: bias estimate ± σ, filter vs smoother, and the truth.
fn smoothing_table(z: &SmoothedRealization) {
    println!(
        "Smoothed calibration (one realization, RTS over all {} steps, backward pass {:.1} ms):",
        z.time.len() - 1,
        1e3 * z.backward_wall_s
    );
    println!(
        "  {:>5} | {:>24} | {:>24} | {:>10}",
        "t [s]", "filter b_hat +- sigma", "smoother b_hat +- sigma", "true b"
    );
    for t in [0.0, 1.0, 5.0, 10.0, 20.0, 30.0] {
        let k = z.index_at(t);
        println!(
            "  {:>5.1} | {:>10.5} +- {:>10.3e} | {:>10.5} +- {:>10.3e} | {:>10.5}",
            z.time[k],
            z.filtered[k][2],
            z.filtered_sigma[k][2],
            z.smoothed[k][2],
            z.smoothed_sigma[k][2],
            z.truth[k][2]
        );
    }
    let s = z.summary();
    println!(
        "  RMS over the run, filter vs smoother: b {:.3e} vs {:.3e} m/s^2, dp {:.3} vs {:.3} m, dv {:.4} vs {:.4} m/s; smoothed b spread {:.1e}\n",
        s.bias_rms_filtered,
        s.bias_rms_smoothed,
        s.position_rms.0,
        s.position_rms.1,
        s.velocity_rms.0,
        s.velocity_rms.1,
        s.smoothed_bias_spread
    );
}

/// The smoothing headline.
fn smoothing_headline(z: &SmoothedRealization) -> Headline {
    let s = z.summary();
    let (k1, k5, end) = (z.index_at(1.0), z.index_at(5.0), z.time.len() - 1);
    Headline {
        quantity: "bias from the whole run (smoothed)".into(),
        paper: "forward filter only".into(),
        estim: format!(
            "smoothed σ_b = {:.2e} m/s² at every time (filter: {:.2e} at 1 s, {:.2e} at 5 s, {:.2e} at 30 s); RMS b error over the run {:.2e} (filter {:.2e})",
            z.smoothed_sigma[0][2],
            z.filtered_sigma[k1][2],
            z.filtered_sigma[k5][2],
            z.filtered_sigma[end][2],
            s.bias_rms_smoothed,
            s.bias_rms_filtered
        ),
        note: "b is a random constant (no process noise on it), so the smoother carries the \
               end-of-run estimate back to t = 0 unchanged: calibration is an offline problem \
               (RTS, Särkkä 2013 §8.2)"
            .into(),
    }
}

/// The smoothing entry of the JSON: b̂ and σ_b at 0, 5 and 30 s for both passes, the RMS
/// errors over the run.
fn smoothing_json(z: &SmoothedRealization) -> serde_json::Value {
    let s = z.summary();
    let at = [0.0, 5.0, 30.0];
    let col =
        |v: &[Vector3<f64>]| -> Vec<f64> { at.iter().map(|&t| v[z.index_at(t)][2]).collect() };
    serde_json::json!({
        "t": at,
        "bias_filtered": col(&z.filtered),
        "bias_sigma_filtered": col(&z.filtered_sigma),
        "bias_smoothed": col(&z.smoothed),
        "bias_sigma_smoothed": col(&z.smoothed_sigma),
        "bias_rms_filtered": s.bias_rms_filtered,
        "bias_rms_smoothed": s.bias_rms_smoothed,
        "position_rms_filtered_smoothed": [s.position_rms.0, s.position_rms.1],
        "velocity_rms_filtered_smoothed": [s.velocity_rms.0, s.velocity_rms.1],
        "backward_wall_s": z.backward_wall_s,
    })
}

/// The smoothing figures: b̂ ± σ, forward filter vs smoother, and the truth, over the whole
/// run; and the bias error b − b̂ ± σ of both from 5 s on (where the filter's σ no longer hides
/// the smoother's).
fn smoothing_figures(
    z: &SmoothedRealization,
) -> Vec<Result<std::path::PathBuf, Box<dyn std::error::Error>>> {
    let every = (z.time.len() / 600).max(1);
    let kept = |from: f64| {
        (0..z.time.len())
            .step_by(every)
            .filter(move |&k| z.time[k] >= from)
    };
    let line = |from: f64, f: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
        kept(from).map(|k| (z.time[k], f(k))).collect()
    };
    let band = |from: f64, centre: &dyn Fn(usize) -> f64, s: &[Vector3<f64>]| {
        kept(from)
            .map(|k| (z.time[k], centre(k) - s[k][2], centre(k) + s[k][2]))
            .collect::<Vec<_>>()
    };
    let (filtered, smoothed) = (&z.filtered, &z.smoothed);
    let error = |x: &[Vector3<f64>], k: usize| z.truth[k][2] - x[k][2];
    vec![
        band_plot(
            "lu_smoothed_bias.svg",
            "Lu: bias estimate, forward filter vs RTS smoother, one realization",
            "t [s]",
            "b [m/s^2]",
            &[
                Series {
                    label: "filter b_hat",
                    points: line(0.0, &|k| filtered[k][2]),
                },
                Series {
                    label: "smoother b_hat",
                    points: line(0.0, &|k| smoothed[k][2]),
                },
                Series {
                    label: "true b",
                    points: line(0.0, &|k| z.truth[k][2]),
                },
            ],
            &[
                Band {
                    label: "filter +-sigma",
                    points: band(0.0, &|k| filtered[k][2], &z.filtered_sigma),
                },
                Band {
                    label: "smoother +-sigma",
                    points: band(0.0, &|k| smoothed[k][2], &z.smoothed_sigma),
                },
            ],
        ),
        band_plot(
            "lu_smoothed_bias_error.svg",
            "Lu: bias error b - b_hat from 5 s, forward filter vs RTS smoother (+-sigma about 0)",
            "t [s]",
            "b - b_hat [m/s^2]",
            &[
                Series {
                    label: "filter error",
                    points: line(5.0, &|k| error(filtered, k)),
                },
                Series {
                    label: "smoother error",
                    points: line(5.0, &|k| error(smoothed, k)),
                },
            ],
            &[
                Band {
                    label: "filter +-sigma",
                    points: band(5.0, &|_| 0.0, &z.filtered_sigma),
                },
                Band {
                    label: "smoother +-sigma",
                    points: band(5.0, &|_| 0.0, &z.smoothed_sigma),
                },
            ],
        ),
    ]
}

fn vec3(v: &Vector3<f64>, precision: usize) -> String {
    format!("({:.p$}, {:.p$}, {:.p$})", v[0], v[1], v[2], p = precision)
}

fn vec3e(v: &Vector3<f64>) -> String {
    format!("({:.3e}, {:.3e}, {:.3e})", v[0], v[1], v[2])
}

fn mat2(m: &Matrix2<f64>) -> String {
    format!(
        "[[{:.1}, {:.1}], [{:.1}, {:.1}]]",
        m[(0, 0)],
        m[(0, 1)],
        m[(1, 0)],
        m[(1, 1)]
    )
}

fn mat2e(m: &Matrix2<f64>) -> String {
    format!(
        "[[{:.2e}, {:.2e}], [{:.2e}, {:.2e}]]",
        m[(0, 0)],
        m[(0, 1)],
        m[(1, 0)],
        m[(1, 1)]
    )
}

fn gains(k: &Matrix3x2<f64>) -> String {
    format!(
        "[[{:.4}, {:.4}], [{:.5}, {:.4}], [{:.1e}, {:.1e}]]",
        k[(0, 0)],
        k[(0, 1)],
        k[(1, 0)],
        k[(1, 1)],
        k[(2, 0)],
        k[(2, 1)]
    )
}

/// The verdict in one line: which checks failed, with their p-values.
pub fn verdict_line(v: &Verdict) -> String {
    let failed: Vec<String> = v
        .failures()
        .map(|c| format!("{} (p = {:.1e})", c.check.name(), c.p_value))
        .collect();
    if failed.is_empty() {
        format!(
            "all {} checks pass at {:.0} %",
            v.checks.len(),
            100.0 * v.confidence
        )
    } else {
        format!(
            "fails at {:.0} %: {}",
            100.0 * v.confidence,
            failed.join(", ")
        )
    }
}

fn check_p(r: &MonteCarloResult, check: Check) -> String {
    r.verdict.check(check).map_or("not run".into(), |c| {
        let p = if c.p_value >= 0.01 {
            format!("{:.2}", c.p_value)
        } else {
            format!("{:.1e}", c.p_value)
        };
        format!("{} (p = {p})", if c.passed() { "passes" } else { "FAILS" })
    })
}

/// The paper's claims next to estim's values.
pub fn headlines(r: &LuResult) -> Vec<Headline> {
    let mc = &r.monte_carlo;
    let s = mc.summary();
    let n = mc.config.runs;
    let sc = &mc.config.scenario;
    let h = |quantity: &str, paper: &str, estim: String, note: String| Headline {
        quantity: quantity.into(),
        paper: paper.into(),
        estim,
        note,
    };
    let variant = |label: &str| r.variants.iter().find(|v| v.config.label == label);
    let mut out = vec![h(
        "Monte Carlo size",
        "N_ave = 5000 realizations over t ∈ [0, 30] s (200 Hz accelerometer, 5 Hz GPS)",
        format!(
            "N = {n}, {} accelerometer steps, {} GPS fixes per run; wall {:.2} s",
            sc.steps,
            sc.updates(),
            mc.wall_s
        ),
        if n == 5000 {
            String::new()
        } else {
            "quick form: fewer runs than the paper".into()
        },
    )];

    let exact = variant(labels::EXACT_TRUTH);
    out.push(h(
        "ensemble mean error e^ave (§3.2)",
        "≈ 0 for all t_i ∈ [0, 30]",
        format!(
            "max over 150 fixes of |e^ave|/√(P/N) = {} for (δp, δv, b); mean-error check {}",
            vec3(&s.max_mean_error_sigmas, 2),
            check_p(mc, Check::MeanError)
        ),
        match exact {
            Some(e) => {
                let es = e.summary();
                format!(
                    "needs the Euler-consistent truth (E5): with the closed-form truth of §2.1 the \
                     mechanisation's quadrature error biases δv by up to {:.4} m/s (exact {:.4}), \
                     {:.0} √(P/N), and the check {}",
                    es.max_mean_error[1],
                    es.exact_max_mean_error[1],
                    es.max_mean_error_sigmas[1],
                    check_p(e, Check::MeanError)
                )
            }
            None => "consistent with zero mean".into(),
        },
    ));

    let w = variant(labels::PRINTED_NOISE);
    out.push(h(
        "ensemble covariance P^ave vs filter P (§3.2)",
        "P^ave(t_i) − P(t_i) ≈ 0",
        format!(
            "P^ave/P over the fixes: δp [{:.3}, {:.3}], δv [{:.3}, {:.3}], b [{:.3}, {:.3}]; at 30 s {}; covariance check {}, NEES {}",
            s.covariance_ratio_min[0],
            s.covariance_ratio_max[0],
            s.covariance_ratio_min[1],
            s.covariance_ratio_max[1],
            s.covariance_ratio_min[2],
            s.covariance_ratio_max[2],
            vec3(&s.covariance_ratio_end, 3),
            check_p(mc, Check::ErrorCovariance),
            check_p(mc, Check::Nees)
        ),
        match w {
            Some(w) => {
                let ws = w.summary();
                format!(
                    "with the listing's W = 0.0016 (E3) P^ave/P at 30 s = {} (exact {}): the filter \
                     is pessimistic in δv and b, and the verdict {}",
                    vec3(&ws.covariance_ratio_end, 3),
                    vec3(&ws.exact_covariance_ratio_end, 3),
                    verdict_line(&w.verdict)
                )
            }
            None => String::new(),
        },
    ));

    let phi = variant(labels::PRINTED_COUPLING);
    out.push(h(
        "orthogonality (1/N) Σ (e − e^ave) δx̂ᵀ (§3.2)",
        "about zero all the time",
        format!(
            "max over 150 fixes × 9 entries of |corr(e, δx̂)| = {:.4} ({:.1}/√N; exact 0); orthogonality check {}",
            s.max_orthogonality,
            s.max_orthogonality_sigmas,
            check_p(mc, Check::Orthogonality)
        ),
        match phi {
            Some(p) => {
                let ps = p.summary();
                format!(
                    "with the printed Φ₁₃ = +Δt²/2 (E4) the error correlates with b̂: max |corr| = {:.4} \
                     ({:.1}/√N; exact {:.4}), orthogonality check {}. The exact correlation is \
                     {:.1}/√N at N = {}; the 99 % check over 1350 entries needs about 4.5/√N, \
                     so it flags the printed sign only from N ≈ {:.0} runs (the paper's 5000: \
                     most seeds)",
                    ps.max_orthogonality,
                    ps.max_orthogonality_sigmas,
                    ps.exact_max_orthogonality,
                    check_p(p, Check::Orthogonality),
                    ps.exact_max_orthogonality * (p.config.runs as f64).sqrt(),
                    p.config.runs,
                    (4.5 / ps.exact_max_orthogonality).powi(2)
                )
            }
            None => String::new(),
        },
    ));

    let paper_c = Matrix2::new(
        PAPER_RESIDUAL_CORRELATION[0][0],
        PAPER_RESIDUAL_CORRELATION[0][1],
        PAPER_RESIDUAL_CORRELATION[1][0],
        PAPER_RESIDUAL_CORRELATION[1][1],
    );
    let se = mc.residual_standard_error;
    // The paper's N is 5000: its standard errors are √(N/5000) times this run's.
    let paper_z = paper_c.component_div(&(se * (n as f64 / 5000.0).sqrt()));
    let estim_z = mc.residual_correlation.component_div(&se);
    out.push(h(
        "residual check (1/N) Σ r(20) r(30)ᵀ (§3.2)",
        "[[0.0486, −0.0023], [0.0002, 0.0002]] ≈ 0",
        format!(
            "{} = {} standard errors (SE = {} for white residuals, N = {n}); residual check {}",
            mat2e(&mc.residual_correlation),
            mat2(&estim_z),
            mat2e(&se),
            check_p(mc, Check::ResidualCorrelation)
        ),
        format!(
            "the paper's entries are {} SE (at its N = 5000): not consistent with white residuals (E11). The \
             closed-form truth (E5) gives a nonzero mean velocity residual and C_r[v,v] = {:.1e}; \
             the rest is not explained by anything estim reproduces",
            mat2(&paper_z),
            exact.map_or(f64::NAN, |e| e.residual_correlation[(1, 1)])
        ),
    ));

    let k_end = r.covariance.posterior.len() - 1;
    out.push(h(
        "accuracy at 30 s",
        "\"the Kalman filter gives an excellent estimation in spite of the bias\" (no numbers)",
        format!(
            "√P(30 s) = {} (m, m/s, m/s²) vs prior σ (10, 1, 0.1); ensemble std/√P at 30 s = {}",
            vec3e(&r.covariance.sigma(k_end)),
            vec3(&s.covariance_ratio_end.map(f64::sqrt), 3)
        ),
        String::new(),
    ));

    out.push(h(
        "Kalman gains",
        "K converges; \"K₁₂ the only one that is not going to zero\"",
        format!(
            "K(30 s) = {}; K({:.0} s) = {} (rows δp, δv, b; columns p, v fix)",
            gains(&r.covariance.gain[k_end]),
            r.config.long_horizon,
            gains(&r.long_horizon_gain)
        ),
        "only the bias row (K₃₁, K₃₂) goes to zero (no process noise on b); K₁₁, K₂₁, K₂₂ settle \
         at nonzero values, K₁₂ (velocity fix → position) is the largest (E12)"
            .into(),
    ));

    if let Some(m) = variant(labels::PRINTED_PRIOR) {
        let ms = m.summary();
        out.push(h(
            "printed M₀ = diag(1, 100, 0.01)",
            "M₀ as listed in §2.6",
            format!(
                "P^ave/P for δp up to {:.1} (exact {:.1}), {:.2} at 30 s; max |corr(e, δx̂)| = {:.3}; verdict {}",
                ms.covariance_ratio_max[0],
                ms.exact_covariance_ratio_max[0],
                ms.covariance_ratio_end[0],
                ms.max_orthogonality,
                verdict_line(&m.verdict)
            ),
            "the listed M₀ swaps the position (100 m²) and velocity (1 (m/s)²) prior variances of \
             the state order (δp, δv, b) (E2); estim uses diag(100, 1, 0.01)"
                .into(),
        ));
    }
    out.push(smoothing_headline(&r.smoothed));
    out
}

/// The index of the time in `times` nearest to `t` (the first on a tie).
fn nearest(times: &[f64], t: f64) -> usize {
    let mut best = 0;
    for (i, &ti) in times.iter().enumerate() {
        if (ti - t).abs() < (times[best] - t).abs() {
            best = i;
        }
    }
    best
}

/// The example body, quick (500 runs) or full (5000), on the default execution.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    run_with(quick, Execution::Default)
}

fn table(r: &MonteCarloResult) {
    let n = r.config.runs as f64;
    println!(
        "  {:>5} | {:>26} | {:>26} | {:>30}",
        "t [s]",
        "filter sqrt P (dp, dv, b)",
        "ensemble std (dp, dv, b)",
        "e_ave / sqrt(P/N) (dp, dv, b)"
    );
    for t in [0.2, 1.0, 5.0, 10.0, 20.0, 30.0] {
        let k = r.slot_at(t);
        let p = r.filter_variance[k];
        let sd = r.ensemble_variance[k].map(f64::sqrt);
        let m = r.mean_error[k];
        println!(
            "  {:>5.1} | {:>8.4} {:>7.5} {:>9.2e} | {:>8.4} {:>7.5} {:>9.2e} | {:>9.2} {:>9.2} {:>9.2}",
            r.time[k],
            p[0].sqrt(),
            p[1].sqrt(),
            p[2].sqrt(),
            sd[0],
            sd[1],
            sd[2],
            m[0] / (p[0] / n).sqrt(),
            m[1] / (p[1] / n).sqrt(),
            m[2] / (p[2] / n).sqrt(),
        );
    }
}

fn figures(r: &LuResult) -> Vec<String> {
    let mc = &r.monte_carlo;
    let n = mc.config.runs;
    let mut out = Vec::new();
    let series = |label: &'static str, f: &dyn Fn(usize) -> f64| Series {
        label,
        points: (1..mc.time.len()).map(|k| (mc.time[k], f(k))).collect(),
    };
    let names = [
        ("position", "dp [m]"),
        ("velocity", "dv [m/s]"),
        ("bias", "b [m/s^2]"),
    ];
    // The filter is consistent, so the ensemble std follows sqrt P to within the Monte Carlo
    // error (1/sqrt(2N) relative): drawn as two lines of one width, the second hid the first
    // (lu_sigma_bias looked like one curve). The ensemble std is drawn as dots on the line.
    for (i, (name, unit)) in names.iter().enumerate() {
        let file = format!("lu_sigma_{name}.svg");
        match lines_and_dots_plot(
            &file,
            &format!("Lu: filter sqrt P vs ensemble std of the {name} error, N = {n}"),
            "t [s]",
            unit,
            &[series("filter sqrt P", &|k| {
                mc.filter_variance[k][i].sqrt()
            })],
            &[series("ensemble std (Monte Carlo)", &|k| {
                mc.ensemble_variance[k][i].sqrt()
            })],
        ) {
            Ok(path) => out.push(path.display().to_string()),
            Err(e) => eprintln!("figure {file} failed: {e}"),
        }
    }
    let mut plot = |file: &str, title: String, y: &str, s: &[Series<'_>]| match line_plot(
        file, &title, "t [s]", y, s,
    ) {
        Ok(path) => out.push(path.display().to_string()),
        Err(e) => eprintln!("figure {file} failed: {e}"),
    };
    plot(
        "lu_covariance_ratio.svg",
        format!("Lu: ensemble variance / filter P, N = {n} (1 = consistent)"),
        "P_ave / P",
        &[
            series("dp", &|k| {
                mc.ensemble_variance[k][0] / mc.filter_variance[k][0]
            }),
            series("dv", &|k| {
                mc.ensemble_variance[k][1] / mc.filter_variance[k][1]
            }),
            series("b", &|k| {
                mc.ensemble_variance[k][2] / mc.filter_variance[k][2]
            }),
        ],
    );
    let nf = n as f64;
    plot(
        "lu_mean_error.svg",
        format!("Lu: ensemble mean error in units of sqrt(P/N), N = {n}"),
        "e_ave / sqrt(P/N)",
        &[
            series("dp", &|k| {
                mc.mean_error[k][0] / (mc.filter_variance[k][0] / nf).sqrt()
            }),
            series("dv", &|k| {
                mc.mean_error[k][1] / (mc.filter_variance[k][1] / nf).sqrt()
            }),
            series("b", &|k| {
                mc.mean_error[k][2] / (mc.filter_variance[k][2] / nf).sqrt()
            }),
        ],
    );
    let mut orth = vec![series("consistent filter", &|k| mc.orthogonality[k])];
    for v in &r.variants {
        if v.config.label == labels::PRINTED_COUPLING {
            orth.push(Series {
                label: "printed Phi13 = +dt^2/2",
                points: (1..v.time.len())
                    .map(|k| (v.time[k], v.orthogonality[k]))
                    .collect(),
            });
        }
    }
    plot(
        "lu_orthogonality.svg",
        format!("Lu: max |corr(e, x_hat)| over the 9 entries, N = {n}"),
        "max |corr|",
        &orth,
    );
    let z = &r.realization;
    let mut banded = Vec::new();
    let one = |f: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
        (1..z.time.len()).map(|k| (z.time[k], f(k))).collect()
    };
    for (i, (name, unit)) in names.iter().enumerate() {
        let file = format!("lu_realization_{name}.svg");
        match band_plot(
            &file,
            &format!("Lu: one realization, {name} error with the filter's +-sigma"),
            "t [s]",
            unit,
            &[Series {
                label: "error",
                points: one(&|k| z.error[k][i]),
            }],
            &[Band {
                label: "filter +-sigma",
                points: (1..z.time.len())
                    .map(|k| (z.time[k], -z.sigma[k][i], z.sigma[k][i]))
                    .collect(),
            }],
        ) {
            Ok(path) => banded.push(path.display().to_string()),
            Err(e) => eprintln!("figure {file} failed: {e}"),
        }
    }
    for figure in smoothing_figures(&r.smoothed) {
        match figure {
            Ok(path) => banded.push(path.display().to_string()),
            Err(e) => eprintln!("smoothing figure failed: {e}"),
        }
    }
    let c = &r.covariance;
    let gain = |label: &'static str, i: usize, j: usize| Series {
        label,
        points: (1..c.time.len())
            .map(|k| (c.time[k], c.gain[k][(i, j)]))
            .collect(),
    };
    plot(
        "lu_gains.svg",
        "Lu: Kalman gains K (rows dp, dv, b; columns p fix, v fix)".into(),
        "K",
        &[
            gain("K11", 0, 0),
            gain("K12", 0, 1),
            gain("K21", 1, 0),
            gain("K22", 1, 1),
            gain("K31", 2, 0),
            gain("K32", 2, 1),
        ],
    );
    out.extend(banded);
    out
}

/// The example body with the given execution of the Monte Carlo runs.
pub fn run_with(quick: bool, execution: Execution) -> Result<Output, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(run_in(
        quick,
        execution,
        &Session::whole(),
    )?)?)
}

/// [`run_with`] as `session` says: whole, one shard of each Monte Carlo (`None`) or the merge
/// of the shards.
pub fn run_in(
    quick: bool,
    execution: Execution,
    session: &Session,
) -> Result<Option<Output>, Box<dyn std::error::Error>> {
    let mc = if quick {
        MonteCarloConfig::quick()
    } else {
        MonteCarloConfig::full()
    }
    .with_execution(execution);
    let config = LuConfig::with_monte_carlo(mc);
    let Some(r) = run_experiment_in(&config, session)? else {
        return Ok(None);
    };
    let m = &r.monte_carlo;
    let sc = &m.config.scenario;
    let n = m.config.runs;

    println!(
        "Lu 2017: accelerometer calibration with GPS. dt = {} s, GPS every {} steps ({} s), {} s, N = {n} realizations ({:?} execution)",
        sc.dt,
        sc.gps_every,
        sc.gps_every as f64 * sc.dt,
        sc.duration(),
        execution
    );
    println!(
        "Monte Carlo (consistent filter): wall {:.2} s for {n} x {} steps\n",
        m.wall_s, sc.steps
    );
    table(m);
    let s = m.summary();
    println!(
        "\n  max over fixes: |e_ave|/sqrt(P/N) = ({:.2}, {:.2}, {:.2}); P_ave/P in [{:.3}, {:.3}] / [{:.3}, {:.3}] / [{:.3}, {:.3}]; max |corr(e, x_hat)| = {:.4} ({:.2}/sqrt N)",
        s.max_mean_error_sigmas[0],
        s.max_mean_error_sigmas[1],
        s.max_mean_error_sigmas[2],
        s.covariance_ratio_min[0],
        s.covariance_ratio_max[0],
        s.covariance_ratio_min[1],
        s.covariance_ratio_max[1],
        s.covariance_ratio_min[2],
        s.covariance_ratio_max[2],
        s.max_orthogonality,
        s.max_orthogonality_sigmas
    );
    let (t1, t2) = m.residual_times;
    let c = &m.residual_correlation;
    let se = &m.residual_standard_error;
    println!(
        "  (1/N) sum r({t1}) r({t2})^T = [[{:.4}, {:.5}], [{:.5}, {:.2e}]]  (standard errors [[{:.4}, {:.5}], [{:.5}, {:.2e}]]; paper: [[0.0486, -0.0023], [0.0002, 0.0002]])\n",
        c[(0, 0)],
        c[(0, 1)],
        c[(1, 0)],
        c[(1, 1)],
        se[(0, 0)],
        se[(0, 1)],
        se[(1, 0)],
        se[(1, 1)]
    );
    println!("{}", m.verdict);

    smoothing_table(&r.smoothed);

    println!("The paper's printed variants (same N, same seeds):");
    println!(
        "  {:<46} | {:>22} | {:>9} | {:>13} | verdict",
        "variant", "P_ave/P at 30 s", "max corr", "max dv mean"
    );
    for v in &r.variants {
        let vs = v.summary();
        println!(
            "  {:<46} | {:>6.3} {:>6.3} {:>6.3}  | {:>9.4} | {:>9.4} m/s | {}",
            v.config.label,
            vs.covariance_ratio_end[0],
            vs.covariance_ratio_end[1],
            vs.covariance_ratio_end[2],
            vs.max_orthogonality,
            vs.max_mean_error[1],
            verdict_line(&v.verdict)
        );
    }
    for v in &r.variants {
        println!("\n{}:\n{}", v.config.label, v.verdict);
    }

    println!("\nHeadlines (paper vs estim):");
    let headlines = headlines(&r);
    for h in &headlines {
        println!(
            "- {}\n    paper: {}\n    estim: {}\n    note:  {}",
            h.quantity, h.paper, h.estim, h.note
        );
    }

    println!("\nFigures:");
    for f in figures(&r) {
        println!("  {f}");
    }

    let times = [10.0, 20.0, 30.0];
    let rows = |f: &dyn Fn(usize) -> [f64; 3]| -> Vec<[f64; 3]> {
        times.iter().map(|&t| f(m.slot_at(t))).collect()
    };
    let json = serde_json::json!({
        "t": times,
        "filter_p_diag": rows(&|k| m.filter_variance[k].into()),
        "ensemble_var_diag": rows(&|k| m.ensemble_variance[k].into()),
        "ensemble_mean_error": rows(&|k| m.mean_error[k].into()),
        "residual_corr_20_30": [[c[(0, 0)], c[(0, 1)]], [c[(1, 0)], c[(1, 1)]]],
        "wall_s": m.wall_s,
        "smoothed": smoothing_json(&r.smoothed),
    });
    Ok(Some(Output { json, headlines }))
}
