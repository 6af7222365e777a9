//! Lu's accelerometer noise W from data (issue 22): the paper's filter listing prints
//! W = 0.0016 (m/s²)² while the text uses 0.0004 everywhere else (erratum E3). Here the data
//! decide: realizations simulated with W = 0.0004 (estim_models::lu's simulator, the paper's
//! scenario), and W with the GPS noises V_p, V_v estimated from them by EM
//! (`estim::filters::noise_id::em`, Q = W · G as a scalar multiple of a fixed shape, R
//! diagonal) and by maximum likelihood (`noise_id::likelihood`, θ = ln(W, V_p, V_v)) with
//! Hessian standard errors; then the likelihood ratio of W = 0.0016 against the estimate, with
//! V_p, V_v re-estimated under W = 0.0016 (the profile likelihood).
//!
//! **The model per GPS epoch (exact).** Between two fixes (40 accelerometer steps of Δt) the
//! error state δx = (δp, δv, b) of an open-loop mechanisation obeys δx⁺ = Φ δx − Γ w forty
//! times, so at the fixes δxₑ₊₁ = Φ⁴⁰ δxₑ + wₑ with wₑ ~ N(0, W G),
//! G = Σ_{i<40} Φⁱ Γ Γᵀ Φⁱᵀ: the same likelihood as the 200 Hz filter, 40× fewer steps. The
//! first epoch (t = 0) has no fix (a missing measurement), the prior is the paper's M₀.
//!
//! EM starts from the listing's W = 0.0016 and twice the true GPS noises; it climbs fast and then
//! crawls (W is weakly identified: EM's rate is set by the fraction of missing information), so
//! it is capped and maximum likelihood (L-BFGS) finishes from its estimate and gives the
//! standard errors. The paper's 30 s runs carry almost no information on W (with 10 of them the
//! standard error of Ŵ is 2.5 times W): the velocity random walk of W over one 0.2 s epoch has
//! variance 4·10⁻⁷ (m/s)² against the GPS velocity noise 1.6·10⁻³, and the bias and initial
//! errors absorb the slow part of the record. Runs of 600 s identify it.
//!
//! `cargo run --release --example lu_noise_id [-- --json] [-- --quick]`

use std::time::Instant;

use crate::common::{Headline, Output};
use estim::core::{Gaussian, LinearMeasurement, LinearProcess};
use estim::filters::KalmanFilter;
use estim::filters::consistency::ChiSquareBand;
use estim::filters::noise_id::em::estimate;
use estim::filters::noise_id::likelihood::sequence_log_likelihood;
use estim::filters::noise_id::{
    CovarianceStructure, EmSettings, LinearGaussian, MaximumLikelihood, MlEstimate, NoiseIdError,
    Record,
};
use estim::models::lu::{
    BiasCoupling, GpsMeasurement, Mechanisation, PRINTED_FILTER_ACCEL_NOISE_VARIANCE, Scenario,
    noise_input, simulate, transition_matrix,
};
use estim::nalgebra::{Matrix2, Matrix3, Matrix3x1, U1, U2, U3, Vector1, Vector2};

/// What to simulate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseIdConfig {
    /// Truth and sensors (the paper's, W = 0.0004).
    pub scenario: Scenario,
    /// Number of 30 s realizations (independent sequences for EM and ML).
    pub realizations: usize,
    /// Seed of the first realization (realization i uses `seed + i`).
    pub seed: u64,
    /// EM's iteration cap (EM is slow where W is weakly identified; ML then polishes).
    pub em_iterations: usize,
}

impl NoiseIdConfig {
    /// 8 realizations of the paper's scenario over 600 s; EM capped at 150 iterations.
    pub fn full() -> Self {
        Self {
            scenario: Scenario::paper().with_duration(600.0),
            realizations: 8,
            seed: 2271,
            em_iterations: 150,
        }
    }

    /// 1 realization; EM capped at 60 iterations.
    pub fn quick() -> Self {
        Self {
            realizations: 1,
            em_iterations: 60,
            ..Self::full()
        }
    }
}

/// One realization at the GPS epochs: δz = z − (p_c, v_c) (`None` at t = 0).
pub type EpochRecord = Vec<Option<Vector2<f64>>>;

/// The error-state model per GPS epoch, with accelerometer noise `w` and GPS noise variances.
pub fn epoch_model(
    scenario: &Scenario,
    w: f64,
    gps: (f64, f64),
) -> LinearGaussian<f64, U3, U2, U1> {
    let (f, shape) = epoch_transition(scenario);
    LinearGaussian {
        process: LinearProcess {
            transition: f,
            input: Matrix3x1::zeros(),
            noise: shape * w,
        },
        measurement: LinearMeasurement {
            observation: GpsMeasurement::observation(),
            noise: Matrix2::new(gps.0, 0.0, 0.0, gps.1),
        },
        prior: Gaussian::new_unchecked(
            estim::nalgebra::Vector3::zeros(),
            scenario.error_prior_covariance(),
        ),
    }
}

/// Φ⁴⁰ and G = Σ_{i<40} Φⁱ Γ Γᵀ Φⁱᵀ (module docs).
pub fn epoch_transition(scenario: &Scenario) -> (Matrix3<f64>, Matrix3<f64>) {
    let phi = transition_matrix(scenario.dt, BiasCoupling::Derived);
    let gamma = noise_input(scenario.dt);
    let (mut power, mut shape) = (Matrix3::identity(), Matrix3::zeros());
    for _ in 0..scenario.gps_every {
        let g = power * gamma;
        shape += g * g.transpose();
        power = phi * power;
    }
    (power, shape)
}

/// Simulates realization `seed` and forms its epoch record with an open-loop mechanisation.
/// Errors: an invalid scenario (see `simulate`).
pub fn epoch_record(scenario: &Scenario, seed: u64) -> Result<EpochRecord, estim::core::Error> {
    let sim = simulate(scenario, seed)?;
    let mut mechanisation = Mechanisation::new(scenario.position_mean, scenario.velocity_mean);
    let mut fixes = sim.gps.iter().peekable();
    let mut record = vec![None];
    for (j, &a) in sim.accelerometer.iter().enumerate() {
        mechanisation.step(a, scenario.dt);
        if let Some(&&(step, z)) = fixes.peek()
            && step == j + 1
        {
            fixes.next();
            record.push(Some(Vector2::new(
                z[0] - mechanisation.position,
                z[1] - mechanisation.velocity,
            )));
        }
    }
    Ok(record)
}

/// What the identification found.
#[derive(Clone, Debug)]
pub struct NoiseIdResult {
    /// The configuration.
    pub config: NoiseIdConfig,
    /// EM's (W, V_p, V_v).
    pub em: [f64; 3],
    /// EM iterations and whether it met its tolerance.
    pub em_iterations: usize,
    /// Whether EM converged.
    pub em_converged: bool,
    /// Whether EM's log-likelihood never decreased.
    pub em_monotone: bool,
    /// The ML fit in θ = ln(W, V_p, V_v).
    pub ml: MlEstimate,
    /// The ML (W, V_p, V_v) and their standard errors (delta method: se(e^θ) = e^θ se(θ)).
    pub ml_values: [f64; 3],
    /// Standard errors of `ml_values`.
    pub ml_standard_errors: [f64; 3],
    /// The profile log-likelihood at W = 0.0016 (V_p, V_v re-estimated).
    pub printed_log_likelihood: f64,
    /// 2 (ℓ̂ − ℓ(W = 0.0016)).
    pub likelihood_ratio: f64,
    /// The χ²₁ upper-tail probability of the likelihood ratio.
    pub p_value: f64,
    /// Wall time \[s\].
    pub wall_s: f64,
}

/// Runs the identification.
pub fn run_identification(
    config: &NoiseIdConfig,
) -> Result<NoiseIdResult, Box<dyn std::error::Error>> {
    let start = Instant::now();
    let s = &config.scenario;
    let records: Vec<EpochRecord> = (0..config.realizations)
        .map(|i| epoch_record(s, config.seed + i as u64))
        .collect::<Result<_, _>>()?;
    let inputs = vec![Vector1::zeros(); records[0].len() - 1];
    let (_, shape) = epoch_transition(s);
    let printed = PRINTED_FILTER_ACCEL_NOISE_VARIANCE;
    let start_gps = (2.0 * s.gps_position_variance, 2.0 * s.gps_velocity_variance);

    // EM.
    let em_records: Vec<_> = records
        .iter()
        .map(|zs| Record {
            inputs: &inputs,
            measurements: zs,
        })
        .collect();
    let settings = EmSettings::new()
        .with_process_noise(CovarianceStructure::ScalarMultiple(shape))
        .with_measurement_noise(CovarianceStructure::Diagonal)
        .with_iterations(config.em_iterations, 1e-12)?;
    let em = estimate(&epoch_model(s, printed, start_gps), &settings, &em_records)?;
    let em_w = em.model.process.noise[(1, 1)] / shape[(1, 1)];
    let em_monotone = em
        .history
        .windows(2)
        .all(|w| w[1] >= w[0] - 1e-10 * w[0].abs());

    // ML over θ = ln(W, V_p, V_v), and the profile at W = 0.0016.
    let log_likelihood = |w: f64, vp: f64, vv: f64| -> Result<f64, NoiseIdError> {
        let model = epoch_model(s, w, (vp, vv));
        let kf = KalmanFilter::new(model.prior.clone());
        records
            .iter()
            .map(|zs| {
                sequence_log_likelihood(&kf, &model.process, &inputs, 1.0, &model.measurement, zs)
            })
            .sum()
    };
    let ln = |v: f64| v.ln();
    // Gradient tolerance 10⁻⁷ on −ℓ/(1 + |ℓ₀|): θ to ~10⁻³ standard errors, enough here.
    let ml_settings = MaximumLikelihood::new().with_tolerance(1e-7)?;
    let em_values = [
        em_w,
        em.model.measurement.noise[(0, 0)],
        em.model.measurement.noise[(1, 1)],
    ];
    let ml = ml_settings.maximize(
        |t| log_likelihood(t[0].exp(), t[1].exp(), t[2].exp()),
        &em_values.map(ln),
    )?;
    let se = ml.standard_errors()?;
    let values = [0, 1, 2].map(|i| ml.parameters[i].exp());
    let profile = ml_settings.maximize(
        |t| log_likelihood(printed, t[0].exp(), t[1].exp()),
        &[ln(start_gps.0), ln(start_gps.1)],
    )?;
    let likelihood_ratio = 2.0 * (ml.log_likelihood - profile.log_likelihood);
    // One-sided χ²₁ tail from the two-sided p-value of the consistency module's band.
    let band = ChiSquareBand::for_sum(1, 1, 0.5)?;
    let p_value = 0.5 * band.p_value(likelihood_ratio.max(0.0))?;
    Ok(NoiseIdResult {
        config: *config,
        em: em_values,
        em_iterations: em.history.len(),
        em_converged: em.converged,
        em_monotone,
        ml_values: values,
        ml_standard_errors: [0, 1, 2].map(|i| values[i] * se[i]),
        ml,
        printed_log_likelihood: profile.log_likelihood,
        likelihood_ratio,
        p_value,
        wall_s: start.elapsed().as_secs_f64(),
    })
}

/// The headlines of the papers report.
pub fn headlines(r: &NoiseIdResult) -> Vec<Headline> {
    let s = &r.config.scenario;
    let [w, vp, vv] = r.ml_values;
    let [sw, svp, svv] = r.ml_standard_errors;
    vec![
        Headline {
            quantity: "accelerometer noise W from the data (E3)".into(),
            paper: "0.0004 in the text, 0.0016 in the filter listing".into(),
            estim: format!("{w:.5} ± {sw:.5} (ML); EM {:.5}", r.em[0]),
            note: format!(
                "{} simulated {} s runs with W = {}; EM from W = 0.0016, ML from EM",
                r.config.realizations,
                s.duration(),
                s.accel_noise_variance
            ),
        },
        Headline {
            quantity: "GPS noise variances (V_p, V_v) from the data".into(),
            paper: format!("{}, {}", s.gps_position_variance, s.gps_velocity_variance),
            estim: format!("{vp:.4} ± {svp:.4}, {vv:.6} ± {svv:.6}"),
            note: String::new(),
        },
        Headline {
            quantity: "likelihood ratio 2 ln(L(W-hat) / L(W = 0.0016))".into(),
            paper: "—".into(),
            estim: format!(
                "{:.1} (chi2_1 tail p = {:.1e})",
                r.likelihood_ratio, r.p_value
            ),
            note: "V_p, V_v re-estimated under W = 0.0016 (profile likelihood)".into(),
        },
    ]
}

/// Runs the example: prints the table and headlines, returns the JSON.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    let config = if quick {
        NoiseIdConfig::quick()
    } else {
        NoiseIdConfig::full()
    };
    let r = run_identification(&config)?;
    println!(
        "Lu noise identification: {} realizations x {} s, W = {} true",
        config.realizations,
        config.scenario.duration(),
        config.scenario.accel_noise_variance
    );
    println!(
        "  {:>10} | {:>10} | {:>10} {:>10} | {:>10}",
        "", "truth", "ML", "se", "EM (capped)"
    );
    let truth = [
        config.scenario.accel_noise_variance,
        config.scenario.gps_position_variance,
        config.scenario.gps_velocity_variance,
    ];
    for (i, name) in ["W", "V_p", "V_v"].iter().enumerate() {
        println!(
            "  {:>10} | {:>10.3e} | {:>10.3e} {:>10.2e} | {:>10.3e}",
            name, truth[i], r.ml_values[i], r.ml_standard_errors[i], r.em[i]
        );
    }
    println!(
        "  EM: {} iterations, converged {}, monotone {}; ML: {} L-BFGS iterations, {} evaluations",
        r.em_iterations, r.em_converged, r.em_monotone, r.ml.iterations, r.ml.evaluations
    );
    println!(
        "  log-likelihood: {:.3} at the estimate, {:.3} at W = 0.0016; ratio {:.2}, p {:.2e}",
        r.ml.log_likelihood, r.printed_log_likelihood, r.likelihood_ratio, r.p_value
    );
    let headlines = headlines(&r);
    for h in &headlines {
        println!("  {h}");
    }
    println!("  wall {:.3} s", r.wall_s);
    let json = serde_json::json!({
        "realizations": config.realizations,
        "truth": truth,
        "ml": r.ml_values,
        "ml_se": r.ml_standard_errors,
        "em": r.em,
        "em_iterations": r.em_iterations,
        "em_monotone": r.em_monotone,
        "log_likelihood": r.ml.log_likelihood,
        "log_likelihood_w_printed": r.printed_log_likelihood,
        "likelihood_ratio": r.likelihood_ratio,
        "p_value": r.p_value,
        "wall_s": r.wall_s,
    });
    Ok(Output { json, headlines })
}
