//! The consistency toolkit (`estim_filters::monte_carlo`, `estim_filters::consistency`) run on
//! each paper's filter: the Boje circle EKF (the paper's linear process, and the nonlinear
//! process for contrast), the Lu calibration filter (its consistent configuration), and the
//! Lee & Huang section IV CKF, alone and followed by the OTE — plus two Lee & Huang
//! diagnostics that are not the paper's (no bias and a drawn initial error, with the paper's Ψ
//! Jacobian and with the full Jacobian) to separate the causes of its inconsistency. What the
//! runs show is written up in the `# Consistency (estim's toolkit)` sections of the model
//! modules' docs (`estim::models::{boje, lu, lee_huang}`).
//!
//! Each filter runs on the seeded Monte Carlo runner with the module's own simulator; the
//! example prints each verdict table (every check at 99 %, Simes' rule) and one summary line
//! per filter, and with `--json` prints one JSON object last, keyed by filter, with each
//! check's outcome, p-value and worst single test.
//!
//! Note on the orthogonality check: it tests E\[(e − ē) x̂ᵀ\] = 0, which holds when the truth
//! is drawn from the filter's prior. The Boje and Lee & Huang simulators fly **one fixed
//! trajectory** (only the sensor noise and, for Boje, the initial estimate are random), so
//! x̂ = x − e with x fixed and cov(e, x̂) = −cov(e): the check fails by construction there,
//! whatever the filter. The summary line therefore also states the verdict without it.
//!
//! `cargo run --release --example consistency [-- --json] [-- --quick]`

use std::time::Instant;

use crate::common::{Headline, Output};
use crate::lee_huang::SectionIvConfig;
use crate::lu_calibration::{MonteCarloConfig, run_monte_carlo_in};
use crate::sharding::Session;
use estim::core::Error;
use estim::filters::ValidationError;
use estim::filters::consistency::{Check, Outcome, Verdict};
use estim::filters::monte_carlo::{EnsembleStats, MonteCarlo, Recorder};
use estim::filters::{Ekf, Estimator, KalmanFilter, Predict, PredictCorrelated, Update};
use estim::models::boje::filter::HEADING;
use estim::models::boje::geometry::rate_squared;
use estim::models::boje::{
    AccelerometerProcess, CircleConfig, NonlinearPlanarProcess, PlanarFilter, PlanarProcess,
    PositionHeadingMeasurement, RateSquaredMeasurement, circle::initial_prior, simulate_circle,
    wrap_angle,
};
use estim::models::lee_huang::{
    AttitudeMeasurement, CkfInput, FourAccelerometers, InsProcess, OwnShipTrajectoryEstimator,
    SensorConfig, simulate,
};
use estim::nalgebra::{Matrix3, U1, U3, U6, Vector1, Vector3, Vector6};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// Confidence of every check.
pub const CONFIDENCE: f64 = 0.99;

/// Master seed of the Boje and Lee & Huang Monte Carlos (Lu keeps its module's seed, 271).
pub const SEED: u64 = 2026;

/// Boje: slots at the GPS/compass fixes t = 1, 2, …, 19 s (a posteriori, after the fix).
/// Residual pair: the fix innovations at t = 5 s and t = 15 s (slots 4 and 14; one before and
/// one after the rate reversal at 10 s).
pub const BOJE_RESIDUAL_SLOTS: (usize, usize) = (4, 14);

/// Lee & Huang: one slot every 0.5 s (50 steps), t = 0.5 … 20 s (40 slots; t = 0 is left out:
/// the CKF starts at the true D(0), so its error there is exactly 0). Residual pair: the
/// attitude innovations at t = 10 s and 20 s (slots 19 and 39).
pub const LEE_HUANG_SLOT_STEPS: usize = 50;
/// See [`LEE_HUANG_SLOT_STEPS`].
pub const LEE_HUANG_RESIDUAL_SLOTS: (usize, usize) = (19, 39);

/// Which Boje process model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BojeProcess {
    /// The paper's linear process, σ²_θ folded into Q.
    Linear,
    /// estim's nonlinear process (θ inside f).
    Nonlinear,
}

/// One filter's Monte Carlo: its verdict and how long it took.
pub struct Run {
    /// Key in the JSON.
    pub key: &'static str,
    /// Description.
    pub label: &'static str,
    /// Slots per run.
    pub slots: usize,
    /// The runner's verdict at [`CONFIDENCE`].
    pub verdict: Verdict,
    /// Whether the truth is one fixed trajectory (orthogonality fails by construction).
    pub fixed_truth: bool,
    /// Wall time \[s\].
    pub wall_s: f64,
    /// The average NEES and its band at a few slots.
    pub nees_profile: Vec<NeesPoint>,
}

/// The average NEES at one slot with its band at [`CONFIDENCE`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeesPoint {
    /// Slot time \[s\].
    pub t: f64,
    /// Average NEES over the runs.
    pub mean: f64,
    /// Lower end of the band.
    pub lower: f64,
    /// Upper end of the band.
    pub upper: f64,
}

/// The average NEES and its band at the slots whose times are nearest to `pick`.
fn nees_profile(
    stats: &EnsembleStats,
    times: &[f64],
    pick: &[f64],
) -> Result<Vec<NeesPoint>, Box<dyn std::error::Error>> {
    let mut out = Vec::new();
    for &t in pick {
        let k = (0..times.len())
            .min_by(|&a, &b| (times[a] - t).abs().total_cmp(&(times[b] - t).abs()))
            .unwrap_or(0);
        if let Some(e) = stats.slots.get(k).and_then(|s| s.estimate.as_ref()) {
            let band = e.nees_band(CONFIDENCE)?;
            out.push(NeesPoint {
                t: times[k],
                mean: e.mean_nees,
                lower: band.lower,
                upper: band.upper,
            });
        }
    }
    Ok(out)
}

impl Run {
    /// `true` when every check except (for a fixed truth) orthogonality passed.
    pub fn consistent_apart_from_orthogonality(&self) -> bool {
        self.verdict
            .checks
            .iter()
            .all(|c| c.passed() || (self.fixed_truth && c.check == Check::Orthogonality))
    }

    /// One line: runs, slots, failed checks with p-values.
    pub fn summary(&self) -> String {
        let failed: Vec<String> = self
            .verdict
            .failures()
            .map(|c| format!("{} (p = {:.1e})", c.check.name(), c.p_value))
            .collect();
        let verdict = if self.verdict.consistent() {
            "CONSISTENT".to_string()
        } else {
            format!("NOT CONSISTENT: fails {}", failed.join(", "))
        };
        let extra = if self.fixed_truth && !self.verdict.consistent() {
            format!(
                "; apart from orthogonality (fixed truth): {}",
                if self.consistent_apart_from_orthogonality() {
                    "consistent"
                } else {
                    "not consistent"
                }
            )
        } else {
            String::new()
        };
        format!(
            "{}: {} runs x {} slots at {:.0}%: {verdict}{extra} [{:.2} s]",
            self.label,
            self.verdict.runs,
            self.slots,
            100.0 * CONFIDENCE,
            self.wall_s
        )
    }

    /// The NEES profile as one line.
    pub fn nees_line(&self) -> String {
        let parts: Vec<String> = self
            .nees_profile
            .iter()
            .map(|n| {
                format!(
                    "t={:.1}s: {:.3} [{:.2}, {:.2}]",
                    n.t, n.mean, n.lower, n.upper
                )
            })
            .collect();
        format!("average NEES [band]: {}", parts.join("; "))
    }

    /// The JSON object of this run.
    pub fn json(&self) -> serde_json::Value {
        let mut checks = serde_json::Map::new();
        for c in &self.verdict.checks {
            let outcome = match c.outcome {
                Outcome::Pass => "pass",
                Outcome::Fail => "fail",
                Outcome::NotRun => "not run",
            };
            let worst = c.worst.map(|w| {
                serde_json::json!({
                    "location": w.location.to_string(),
                    "value": finite(w.value),
                    "lower": finite(w.lower),
                    "upper": finite(w.upper),
                    "p_value": finite(w.p_value),
                })
            });
            checks.insert(
                check_key(c.check).into(),
                serde_json::json!({
                    "outcome": outcome,
                    "pass": c.passed(),
                    "p_value": finite(c.p_value),
                    "tests": c.tests,
                    "inside": c.inside,
                    "worst": worst,
                }),
            );
        }
        serde_json::json!({
            "label": self.label,
            "runs": self.verdict.runs,
            "slots": self.slots,
            "confidence": self.verdict.confidence,
            "consistent": self.verdict.consistent(),
            "fixed_truth": self.fixed_truth,
            "consistent_apart_from_orthogonality": self.consistent_apart_from_orthogonality(),
            "checks": checks,
            "wall_s": self.wall_s,
            "nees_profile": self.nees_profile.iter().map(|n| {
                serde_json::json!({"t": n.t, "mean_nees": finite(n.mean), "lower": n.lower, "upper": n.upper})
            }).collect::<Vec<_>>(),
        })
    }
}

fn finite(x: f64) -> serde_json::Value {
    if x.is_finite() {
        serde_json::json!(x)
    } else {
        serde_json::Value::Null
    }
}

fn check_key(c: Check) -> &'static str {
    match c {
        Check::MeanError => "mean_error",
        Check::ErrorCovariance => "error_covariance",
        Check::Nees => "nees",
        Check::Nis => "nis",
        Check::Orthogonality => "orthogonality",
        Check::ResidualCorrelation => "residual_correlation",
        Check::Whiteness => "whiteness",
        _ => "other",
    }
}

/// One Boje realization with the EKF on `process`: the module's simulator and prior (correct
/// ICs, x̂₀ − x₀ ~ N(0, P₀)), the module's step order (θ̇² update, fix update, correlated
/// prediction, as `filter_step`), recording after each fix update.
fn boje_realization<P>(
    config: &CircleConfig,
    process: &P,
    seed: u64,
    rec: &mut Recorder,
) -> Result<(), ValidationError>
where
    P: AccelerometerProcess,
    Ekf<f64, U6>: PlanarFilter<P>,
{
    let data = simulate_circle(config, seed)?;
    let prior = initial_prior(&data.truth[0], &config.initial, seed)?;
    let mut filter = Ekf::new(prior);
    let fix_model = config.fix_model();
    let every = config.fix_every();
    let rate = process.rate_measurement();
    for (i, accel) in data.accel.iter().enumerate() {
        let input = process.input(accel, filter.state(), filter.covariance())?;
        let z = Vector1::new(rate_squared(accel, process.half_separation()));
        Update::<f64, U6, U1, RateSquaredMeasurement>::update(&mut filter, &rate, &z)?;
        if let Some(y) = &data.fixes[i] {
            let report = Update::<f64, U6, U3, PositionHeadingMeasurement>::update(
                &mut filter,
                &fix_model,
                y,
            )?;
            let slot = i / every - 1;
            rec.record_innovation(slot, &report)?;
            rec.record_residual(slot, &report.innovation)?;
            // The heading state is unwrapped: compare it with the truth modulo 2π.
            let mut e = data.truth[i] - filter.state();
            e[HEADING] = wrap_angle(e[HEADING]);
            let truth = filter.state() + e;
            rec.record_filter(slot, &truth, &filter)?;
        }
        let s = process.noise_cross_covariance(&input, filter.state(), config.dt);
        filter.predict_correlated(process, &input, config.dt, &rate, &z, &s)?;
    }
    Ok(())
}

/// The Boje circle Monte Carlo (Table 1, t_end = 20 s, correct ICs) with the EKF.
pub fn boje(runs: usize, process: BojeProcess) -> Result<Run, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(boje_in(
        runs,
        process,
        &Session::whole(),
    )?)?)
}

/// [`boje`] as `session` says: whole, one shard (`None`) or the merge of the shards.
pub fn boje_in(
    runs: usize,
    process: BojeProcess,
    session: &Session,
) -> Result<Option<Run>, Box<dyn std::error::Error>> {
    let config = CircleConfig::paper();
    let slots = config.steps() / config.fix_every() - 1;
    let mc = MonteCarlo::new(runs, slots)?
        .with_seed(SEED)
        .with_residual_pair(BOJE_RESIDUAL_SLOTS.0, BOJE_RESIDUAL_SLOTS.1)?;
    let (key, label) = match process {
        BojeProcess::Linear => ("boje_ekf", "Boje circle EKF (paper's linear process)"),
        BojeProcess::Nonlinear => ("boje_ekf_nonlinear", "Boje circle EKF, nonlinear process"),
    };
    let start = Instant::now();
    let stats = match process {
        BojeProcess::Linear => {
            let p = PlanarProcess {
                half_separation: config.half_separation,
                variances: config.variances(),
            };
            session.run(key, &mc, |_, seed, rec| {
                boje_realization(&config, &p, seed, rec)
            })?
        }
        BojeProcess::Nonlinear => {
            let p = NonlinearPlanarProcess {
                half_separation: config.half_separation,
                variances: config.variances(),
            };
            session.run(key, &mc, |_, seed, rec| {
                boje_realization(&config, &p, seed, rec)
            })?
        }
    };
    let wall_s = start.elapsed().as_secs_f64();
    let Some(stats) = stats else {
        return Ok(None);
    };
    let times: Vec<f64> = (1..=slots)
        .map(|k| (k * config.fix_every()) as f64 * config.dt)
        .collect();
    Ok(Some(Run {
        key,
        label,
        slots,
        verdict: stats.verdict(CONFIDENCE)?,
        fixed_truth: true,
        wall_s,
        nees_profile: nees_profile(&stats, &times, &[1.0, 2.0, 5.0, 9.0, 12.0, 15.0, 19.0])?,
    }))
}

/// Which Lee & Huang filter, on which data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeeHuangCase {
    /// Section IV: the paper's CKF (Ψ Jacobian, linear Kalman filter), 10 mg input bias, the
    /// CKF started at the true D(0) with P(0) = diag(1, 1, 0.1, 0.1, (1°)², (1°/s)²).
    Ckf,
    /// The same CKF followed each cycle by the OTE (recorded after the OTE correction).
    CkfOte,
    /// Diagnostic, not the paper's: the same CKF without the input bias and with
    /// D̂(0) − D(0) ~ N(0, P(0)) per run (the data the filter's model assumes).
    CkfNoBiasDrawnPrior,
    /// Diagnostic, not the paper's: as [`CkfNoBiasDrawnPrior`](Self::CkfNoBiasDrawnPrior) but
    /// with the full Jacobian ∂f/∂D (the θ → velocity coupling kept) in the EKF.
    EkfFullJacobianNoBiasDrawnPrior,
}

/// The per-run loop shared by the Lee & Huang cases: predict with `predict`, update with the
/// attitude, the OTE if any, and record every [`LEE_HUANG_SLOT_STEPS`].
fn lee_huang_loop<F>(
    filter: &mut F,
    mut predict: impl FnMut(&mut F, &Vector3<f64>) -> Result<(), Error>,
    measurement: &AttitudeMeasurement,
    mut ote: Option<OwnShipTrajectoryEstimator>,
    sim: &estim::models::lee_huang::Simulation,
    rec: &mut Recorder,
) -> Result<(), ValidationError>
where
    F: Update<f64, U6, U1, AttitudeMeasurement>,
{
    for k in 1..sim.samples.len() {
        predict(filter, &sim.samples[k - 1].inputs)?;
        let report = filter.update(measurement, &Vector1::new(sim.samples[k].attitude))?;
        if let Some(o) = ote.as_mut() {
            o.correct(filter)?;
        }
        if k % LEE_HUANG_SLOT_STEPS == 0 {
            let slot = k / LEE_HUANG_SLOT_STEPS - 1;
            rec.record_innovation(slot, &report)?;
            rec.record_residual(slot, &report.innovation)?;
            let mut e: Vector6<f64> = sim.truth[k] - filter.state();
            e[4] = wrap_angle(e[4]);
            let truth = filter.state() + e;
            rec.record_filter(slot, &truth, filter)?;
        }
    }
    Ok(())
}

/// The Lee & Huang section IV Monte Carlo of `case`.
pub fn lee_huang_case(runs: usize, case: LeeHuangCase) -> Result<Run, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(lee_huang_case_in(
        runs,
        case,
        &Session::whole(),
    )?)?)
}

/// [`lee_huang_case`] as `session` says: whole, one shard (`None`) or the merge of the shards.
pub fn lee_huang_case_in(
    runs: usize,
    case: LeeHuangCase,
    session: &Session,
) -> Result<Option<Run>, Box<dyn std::error::Error>> {
    let config = SectionIvConfig::paper();
    let steps = config.steps();
    let unbiased = matches!(
        case,
        LeeHuangCase::CkfNoBiasDrawnPrior | LeeHuangCase::EkfFullJacobianNoBiasDrawnPrior
    );
    let sensors = SensorConfig {
        dt: config.dt,
        steps,
        accelerometers: FourAccelerometers::default(),
        input_bias: if unbiased {
            Vector3::zeros()
        } else {
            config.input_bias
        },
        input_noise_std: config.input_noise_std,
        attitude_std: config.attitude_std,
    };
    let full = InsProcess {
        input_noise: Matrix3::from_diagonal(
            &config
                .input_noise_std
                .component_mul(&config.input_noise_std),
        ),
        discretization: config.discretization,
        plane: config.scenario.plane,
    };
    let process = full.ckf();
    let measurement = AttitudeMeasurement {
        variance: config.attitude_std * config.attitude_std,
    };
    let slots = steps / LEE_HUANG_SLOT_STEPS;
    let mc = MonteCarlo::new(runs, slots)?
        .with_seed(SEED)
        .with_residual_pair(LEE_HUANG_RESIDUAL_SLOTS.0, LEE_HUANG_RESIDUAL_SLOTS.1)?;
    let (key, label) = match case {
        LeeHuangCase::Ckf => ("lee_huang_ckf", "Lee & Huang CKF (section IV)"),
        LeeHuangCase::CkfOte => ("lee_huang_ckf_ote", "Lee & Huang CKF+OTE (section IV)"),
        LeeHuangCase::CkfNoBiasDrawnPrior => (
            "lee_huang_ckf_no_bias",
            "Lee & Huang CKF, no bias, D(0) error drawn from P(0) (diagnostic)",
        ),
        LeeHuangCase::EkfFullJacobianNoBiasDrawnPrior => (
            "lee_huang_ekf_full_jacobian_no_bias",
            "Lee & Huang full-Jacobian EKF, no bias, D(0) error drawn from P(0) (diagnostic)",
        ),
    };
    let start = Instant::now();
    let stats = session.run(key, &mc, |_, seed, rec| -> Result<(), ValidationError> {
        let sim = simulate(&config.scenario, &sensors, seed)?;
        let mut initial = config.scenario.initial_state;
        if unbiased {
            let mut rng = StdRng::seed_from_u64(seed ^ 0x1ee_4a46);
            for i in 0..6 {
                let n: f64 = rng.sample(StandardNormal);
                initial[i] += config.initial_covariance[(i, i)].sqrt() * n;
            }
        }
        let prior = estim::core::Gaussian::new(initial, config.initial_covariance)?;
        let ote = if case == LeeHuangCase::CkfOte {
            Some(OwnShipTrajectoryEstimator::new(&config.ote)?)
        } else {
            None
        };
        if case == LeeHuangCase::EkfFullJacobianNoBiasDrawnPrior {
            let mut filter = Ekf::new(prior);
            let predict = |f: &mut Ekf<f64, U6>, u: &Vector3<f64>| f.predict(&full, u, config.dt);
            return lee_huang_loop(&mut filter, predict, &measurement, ote, &sim, rec);
        }
        let mut filter = KalmanFilter::new(prior);
        let predict = |f: &mut KalmanFilter<f64, U6>, u: &Vector3<f64>| {
            let input = CkfInput {
                signals: *u,
                attitude: f.state()[4],
            };
            f.predict(&process, &input, config.dt)
        };
        lee_huang_loop(&mut filter, predict, &measurement, ote, &sim, rec)
    })?;
    let wall_s = start.elapsed().as_secs_f64();
    let Some(stats) = stats else {
        return Ok(None);
    };
    let times: Vec<f64> = (1..=slots)
        .map(|k| (k * LEE_HUANG_SLOT_STEPS) as f64 * config.dt)
        .collect();
    Ok(Some(Run {
        key,
        label,
        slots,
        verdict: stats.verdict(CONFIDENCE)?,
        fixed_truth: true,
        wall_s,
        nees_profile: nees_profile(&stats, &times, &[0.5, 1.0, 2.0, 5.0, 10.0, 20.0])?,
    }))
}

/// The section IV CKF ([`LeeHuangCase::Ckf`]) or, with `ote`, CKF+OTE
/// ([`LeeHuangCase::CkfOte`]).
pub fn lee_huang(runs: usize, ote: bool) -> Result<Run, Box<dyn std::error::Error>> {
    lee_huang_case(
        runs,
        if ote {
            LeeHuangCase::CkfOte
        } else {
            LeeHuangCase::Ckf
        },
    )
}

/// The Lu calibration filter's own Monte Carlo (the consistent configuration, 30 s, every GPS
/// update, residuals at 20 s × 30 s) with `runs` realizations.
pub fn lu(runs: usize) -> Result<Run, Box<dyn std::error::Error>> {
    Ok(crate::sharding::whole(lu_in(runs, &Session::whole())?)?)
}

/// [`lu`] as `session` says: whole, one shard (`None`) or the merge of the shards.
pub fn lu_in(runs: usize, session: &Session) -> Result<Option<Run>, Box<dyn std::error::Error>> {
    let config = MonteCarloConfig::full().with_runs(runs);
    let start = Instant::now();
    let Some(r) = run_monte_carlo_in(&config, session)? else {
        return Ok(None);
    };
    let wall_s = start.elapsed().as_secs_f64();
    Ok(Some(Run {
        key: "lu",
        label: "Lu calibration filter (consistent configuration)",
        slots: r.time.len(),
        nees_profile: nees_profile(&r.stats, &r.time, &[0.0, 1.0, 5.0, 10.0, 20.0, 30.0])?,
        verdict: r.verdict,
        fixed_truth: false,
        wall_s,
    }))
}

/// Run counts: (Boje, Lee & Huang, Lu).
pub fn run_counts(quick: bool) -> (usize, usize, usize) {
    if quick {
        (200, 200, 500)
    } else {
        (1000, 1000, 5000)
    }
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
    let (n_boje, n_lh, n_lu) = run_counts(quick);
    let start = Instant::now();
    let runs = [
        boje_in(n_boje, BojeProcess::Linear, session)?,
        boje_in(n_boje, BojeProcess::Nonlinear, session)?,
        lu_in(n_lu, session)?,
        lee_huang_case_in(n_lh, LeeHuangCase::Ckf, session)?,
        lee_huang_case_in(n_lh, LeeHuangCase::CkfOte, session)?,
        lee_huang_case_in(n_lh, LeeHuangCase::CkfNoBiasDrawnPrior, session)?,
        lee_huang_case_in(n_lh, LeeHuangCase::EkfFullJacobianNoBiasDrawnPrior, session)?,
    ];
    // Every experiment runs (its shard) before a shard stops here.
    let Some(runs) = runs.into_iter().collect::<Option<Vec<_>>>() else {
        return Ok(None);
    };
    for r in &runs {
        println!("== {} ==", r.label);
        print!("{}", r.verdict);
        println!("{}\n", r.nees_line());
    }
    println!(
        "Summary (every check at {:.0}%, Simes):",
        100.0 * CONFIDENCE
    );
    for r in &runs {
        println!("- {}", r.summary());
    }
    println!("total wall time {:.2} s", start.elapsed().as_secs_f64());
    let mut json = serde_json::Map::new();
    for r in &runs {
        json.insert(r.key.into(), r.json());
    }
    let headlines = runs
        .iter()
        .map(|r| Headline {
            quantity: format!("consistency of the {}", r.label),
            paper: "—".into(),
            estim: r.summary(),
            note: if r.fixed_truth {
                "fixed truth trajectory: orthogonality fails by construction".into()
            } else {
                String::new()
            },
        })
        .collect();
    Ok(Some(Output {
        json: serde_json::Value::Object(json),
        headlines,
    }))
}
