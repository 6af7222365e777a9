//! Boje section 3: the rate accuracy of the accelerometer pair (eq 17–19) at R = 0.1 m,
//! Δt = 0.01 s, σ = 1.4 mg, ω = 80 °/s — eq 18's closed form, eq 17 iterated to steady state,
//! the printed eq 19 (erratum), and a Monte Carlo of the scalar EKF (estim's `Ekf` on a 1-state
//! model) at constant rate on simulated accelerometer samples.
//!
//! `cargo run --release --example boje_rate [-- --json] [-- --quick]`

use crate::common::{Headline, Output, Series, line_plot};
use crate::exact_sum::ExactSums;
use crate::sharding::{self, Session};
use estim::core::error::Result;
use estim::core::nalgebra::{Matrix1, Vector1, Vector4};
use estim::core::{Error, Gaussian, Parameter};
use estim::filters::monte_carlo::run_seed;
use estim::filters::{Ekf, Estimator, Predict, Update};
use estim::models::boje::geometry::{STANDARD_GRAVITY, invert, sensor_signals};
use estim::models::boje::rate::{
    ScalarRateProcess, ScalarRateSquared, iterate_riccati, steady_state_eq18, steady_state_eq19,
    steady_state_eq19_printed,
};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

/// Settings of the section 3 analysis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateConfig {
    /// R, m (paper: 0.1).
    pub half_separation: f64,
    /// Δt, s (paper: 0.01).
    pub dt: f64,
    /// Accelerometer noise std per channel, mg (paper: 1.4).
    pub sigma_mg: f64,
    /// The constant rate ω₀, °/s (paper: 80).
    pub rate_deg_s: f64,
    /// Accelerometer noise density, µg/√Hz (ADIS16003: 110).
    pub accel_density_ug: f64,
    /// Accelerometer full scale, g (ADIS16003: 1.7).
    pub accel_full_scale_g: f64,
    /// Gyro noise density, °/s/√Hz (ADIS16080: 0.05).
    pub gyro_density_deg_s: f64,
    /// Gyro full scale, °/s (ADIS16080: 80).
    pub gyro_full_scale_deg_s: f64,
    /// Monte Carlo runs of the scalar EKF.
    pub runs: usize,
    /// Accelerometer steps per run.
    pub steps: usize,
    /// Steps discarded at the start of each run (transient).
    pub burn_in: usize,
    /// Initial std of the rate estimate, °/s (the initial error is drawn from it).
    pub initial_std_deg_s: f64,
    /// Seed.
    pub seed: u64,
}

impl RateConfig {
    /// The paper's section 3 numbers; 200 runs × 18 000 steps (3 min at 100 Hz), first 1000
    /// steps discarded (the filter's time constant is ≈ 36 steps).
    pub fn paper() -> Self {
        Self {
            half_separation: 0.1,
            dt: 0.01,
            sigma_mg: 1.4,
            rate_deg_s: 80.0,
            accel_density_ug: 110.0,
            accel_full_scale_g: 1.7,
            gyro_density_deg_s: 0.05,
            gyro_full_scale_deg_s: 80.0,
            runs: 200,
            steps: 18_000,
            burn_in: 1_000,
            initial_std_deg_s: 1.0,
            seed: 3,
        }
    }

    /// As [`paper`](Self::paper) with 40 runs.
    pub fn quick() -> Self {
        Self {
            runs: 40,
            ..Self::paper()
        }
    }

    /// σ per channel in m/s².
    pub fn sigma(&self) -> f64 {
        self.sigma_mg * 1e-3 * STANDARD_GRAVITY
    }

    /// ω₀ in rad/s.
    pub fn rate(&self) -> f64 {
        self.rate_deg_s.to_radians()
    }
}

/// What [`rate_experiment`] returns. Variances in (rad/s)², stds in °/s.
#[derive(Clone, Debug, PartialEq)]
pub struct RateResult {
    /// The settings used.
    pub config: RateConfig,
    /// q = λ33 Δt², (rad/s)².
    pub q: f64,
    /// r = λ44, (rad/s)⁴.
    pub r: f64,
    /// c = 2ω₀, rad/s.
    pub c: f64,
    /// Eq 18 steady state (predicted variance).
    pub p_eq18: f64,
    /// Eq 17 iterated to steady state.
    pub p_riccati: f64,
    /// Iterations eq 17 took (relative change ≤ 1e-13).
    pub riccati_iterations: usize,
    /// Eq 17's trajectory from p₀ = (initial std)².
    pub riccati_trace: Vec<f64>,
    /// Eq 19 corrected.
    pub p_eq19: f64,
    /// Eq 19 as printed.
    pub p_eq19_printed: f64,
    /// √(eq 18), °/s.
    pub rate_std_eq18_deg_s: f64,
    /// √(eq 17 iterated), °/s.
    pub rate_std_riccati_deg_s: f64,
    /// √(eq 17 iterated − q): the filtered (after the θ̇² update) std, °/s.
    pub rate_std_filtered_deg_s: f64,
    /// √(eq 19 as printed), °/s — the paper's 0.24.
    pub rate_std_eq19_printed_deg_s: f64,
    /// RMS of the predicted rate error of the scalar EKF over runs and post-burn-in steps, °/s.
    pub rate_rms_simulated_deg_s: f64,
    /// RMS of the filtered (post-update) rate error, °/s.
    pub rate_rms_filtered_simulated_deg_s: f64,
    /// Mean of the EKF's own √P (predicted) over the same steps, °/s.
    pub rate_sqrt_p_simulated_deg_s: f64,
    /// RMS predicted error across runs at each step, °/s (for a figure).
    pub rms_over_time_deg_s: Vec<f64>,
    /// √P of the first run at each step, °/s.
    pub sqrt_p_over_time_deg_s: Vec<f64>,
    /// Noise bandwidth used for the datasheet conversions, (π/2)/Δt, Hz.
    pub noise_bandwidth_hz: f64,
    /// Accelerometer noise std from its density, mg (paper: 1.4).
    pub accel_noise_mg: f64,
    /// Gyro noise std from its density, °/s (paper: 0.63).
    pub gyro_noise_deg_s: f64,
    /// Full-scale rate of the pair, √(a_full/R), °/s (paper: 740).
    pub full_scale_rate_deg_s: f64,
    /// (gyro noise / gyro full scale) / (accel noise / accel full scale) (paper: ≈ 10).
    pub noise_to_full_scale_ratio: f64,
}

/// Runs the section 3 analysis and the scalar EKF Monte Carlo.
///
/// Errors: runs, steps ≤ burn-in, or non-positive parameters (reported as invalid sample
/// count / non-finite values), and filter errors.
pub fn rate_experiment(
    config: &RateConfig,
) -> std::result::Result<RateResult, Box<dyn std::error::Error>> {
    Ok(sharding::whole(rate_experiment_in(
        config,
        &Session::whole(),
    )?)?)
}

/// [`rate_experiment`] in `session` (a whole run, a shard or a merge of its Monte Carlo runs):
/// `None` in a shard.
pub fn rate_experiment_in(
    config: &RateConfig,
    session: &Session,
) -> std::result::Result<Option<RateResult>, Box<dyn std::error::Error>> {
    if config.runs == 0 || config.steps <= config.burn_in {
        return Err(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: config.runs.min(config.steps) as f64,
        }
        .into());
    }
    let (dt, rr) = (config.dt, config.half_separation);
    let sigma = config.sigma();
    let omega = config.rate();
    // Equal channel variances σ²: λ33 = λ44 = 2σ²/(4R²).
    let lambda33 = 2.0 * sigma * sigma / (4.0 * rr * rr);
    let lambda44 = lambda33;
    let (q, r, c) = (lambda33 * dt * dt, lambda44, 2.0 * omega);
    let p0 = config.initial_std_deg_s.to_radians().powi(2);
    let (p_riccati, riccati_iterations, riccati_trace) =
        iterate_riccati(p0, q, r, c, 0.0, 1e-13, 100_000)?;
    let p_eq18 = steady_state_eq18(q, r, c);
    let p_eq19 = steady_state_eq19(dt, sigma, rr, c);
    let p_eq19_printed = steady_state_eq19_printed(dt, sigma, rr, c);
    let deg = |p: f64| p.sqrt().to_degrees();

    let Some(mc) = simulate_scalar_ekf(config, lambda33, lambda44, session)? else {
        return Ok(None);
    };

    let bandwidth = std::f64::consts::FRAC_PI_2 / dt;
    let accel_noise_mg = config.accel_density_ug * 1e-3 * bandwidth.sqrt();
    let gyro_noise_deg_s = config.gyro_density_deg_s * bandwidth.sqrt();
    let full_scale = (config.accel_full_scale_g * STANDARD_GRAVITY / rr).sqrt();
    let ratio = (gyro_noise_deg_s / config.gyro_full_scale_deg_s)
        / (accel_noise_mg * 1e-3 / config.accel_full_scale_g);

    Ok(Some(RateResult {
        config: *config,
        q,
        r,
        c,
        p_eq18,
        p_riccati,
        riccati_iterations,
        riccati_trace,
        p_eq19,
        p_eq19_printed,
        rate_std_eq18_deg_s: deg(p_eq18),
        rate_std_riccati_deg_s: deg(p_riccati),
        rate_std_filtered_deg_s: deg(p_riccati - q),
        rate_std_eq19_printed_deg_s: deg(p_eq19_printed),
        rate_rms_simulated_deg_s: mc.rms_predicted.to_degrees(),
        rate_rms_filtered_simulated_deg_s: mc.rms_filtered.to_degrees(),
        rate_sqrt_p_simulated_deg_s: mc.mean_sqrt_p.to_degrees(),
        rms_over_time_deg_s: mc.rms_over_time.iter().map(|v| v.to_degrees()).collect(),
        sqrt_p_over_time_deg_s: mc.sqrt_p_first_run.iter().map(|v| v.to_degrees()).collect(),
        noise_bandwidth_hz: bandwidth,
        accel_noise_mg,
        gyro_noise_deg_s,
        full_scale_rate_deg_s: full_scale.to_degrees(),
        noise_to_full_scale_ratio: ratio,
    }))
}

struct ScalarMonteCarlo {
    rms_predicted: f64,
    rms_filtered: f64,
    mean_sqrt_p: f64,
    rms_over_time: Vec<f64>,
    sqrt_p_first_run: Vec<f64>,
}

/// The sums over runs of the scalar EKF Monte Carlo ([`ExactSums`], so that shards merge to
/// the bits of one process): the squared predicted error at each step, then over the
/// post-burn-in steps of each run the squared predicted error, the squared filtered error and
/// √P.
fn scalar_sums(steps: usize) -> usize {
    steps + 3
}

/// Run `run` of the scalar EKF at constant rate ω₀ on simulated accelerometer samples (seed
/// `run_seed(config.seed, run)`, the Monte Carlo runner's): for each step, the sample a =
/// M(θᵢ)(0, 0, 0, ω₀²) + N(0, σ² I₄) (an object spinning in place), u = θ̈ = g3(a), y = θ̇² =
/// g4(a) (independent: v and u channels); update with y, then predict with u. Adds its terms
/// to `sums` ([`scalar_sums`]) and gives √P at each step.
fn scalar_run(
    config: &RateConfig,
    lambda33: f64,
    lambda44: f64,
    run: usize,
    sums: &mut ExactSums,
) -> Result<Vec<f64>> {
    let (dt, rr) = (config.dt, config.half_separation);
    let sigma = config.sigma();
    let omega = config.rate();
    let process = ScalarRateProcess {
        angular_accel_variance: lambda33,
    };
    let sensor = ScalarRateSquared { noise: lambda44 };
    let p0 = config.initial_std_deg_s.to_radians().powi(2);
    let mut rng = StdRng::seed_from_u64(run_seed(config.seed, run));
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let clean = Vector4::new(0.0, 0.0, 0.0, omega * omega);
    let start = omega + p0.sqrt() * normal();
    let mut filter = Ekf::new(Gaussian::new(Vector1::new(start), Matrix1::new(p0))?);
    let mut theta = 0.0;
    let mut sqrt_p_over_time = Vec::with_capacity(config.steps);
    let (mut total_sq, mut total_sq_filtered, mut total_sqrt_p) = (0.0, 0.0, 0.0);
    for i in 0..config.steps {
        let mut a = sensor_signals(theta, &clean, rr);
        for v in a.iter_mut() {
            *v += sigma * normal();
        }
        let g = invert(theta, &a, rr);
        filter.update(&sensor, &Vector1::new(g[3]))?;
        let filtered_error = omega - filter.state()[0];
        filter.predict(&process, &g[2], dt)?;
        theta += omega * dt;
        let e = omega - filter.state()[0];
        sums.add(i, e * e);
        let sqrt_p = filter.covariance()[(0, 0)].sqrt();
        sqrt_p_over_time.push(sqrt_p);
        if i >= config.burn_in {
            total_sq += e * e;
            total_sq_filtered += filtered_error * filtered_error;
            total_sqrt_p += sqrt_p;
        }
    }
    sums.add_slice(config.steps, &[total_sq, total_sq_filtered, total_sqrt_p]);
    Ok(sqrt_p_over_time)
}

/// The scalar EKF Monte Carlo of `config.runs` runs ([`scalar_run`]) through `session`:
/// `None` in a shard.
fn simulate_scalar_ekf(
    config: &RateConfig,
    lambda33: f64,
    lambda44: f64,
    session: &Session,
) -> std::result::Result<Option<ScalarMonteCarlo>, Box<dyn std::error::Error>> {
    let mut first = None;
    let sums = session.sums(
        "runs",
        config.runs,
        scalar_sums(config.steps),
        |run, sums| {
            let sqrt_p = scalar_run(config, lambda33, lambda44, run, sums)?;
            if run == 0 {
                first = Some(sqrt_p);
            }
            Ok(())
        },
    )?;
    let Some(sums) = sums else {
        return Ok(None);
    };
    // A merge ran no run here: run 0 again for its √P (same seed, same bits).
    let sqrt_p_first_run = match first {
        Some(s) => s,
        None => scalar_run(
            config,
            lambda33,
            lambda44,
            0,
            &mut ExactSums::new(scalar_sums(config.steps)),
        )?,
    };
    let s = config.steps;
    let n = (config.runs * (config.steps - config.burn_in)) as f64;
    Ok(Some(ScalarMonteCarlo {
        rms_predicted: (sums.value(s) / n).sqrt(),
        rms_filtered: (sums.value(s + 1) / n).sqrt(),
        mean_sqrt_p: sums.value(s + 2) / n,
        rms_over_time: (0..s)
            .map(|i| (sums.value(i) / config.runs as f64).sqrt())
            .collect(),
        sqrt_p_first_run,
    }))
}

impl RateResult {
    /// Paper vs estim for section 3.
    pub fn headlines(&self) -> Vec<Headline> {
        vec![
            Headline {
                quantity: "rate std at 80 °/s (eq 19)".into(),
                paper: "0.24 °/s".into(),
                estim: format!(
                    "{:.4} °/s (eq 18 = eq 17 iterated {:.4}; scalar EKF Monte Carlo rms {:.4}, √P {:.4}); printed eq 19 gives {:.4}",
                    self.rate_std_eq18_deg_s,
                    self.rate_std_riccati_deg_s,
                    self.rate_rms_simulated_deg_s,
                    self.rate_sqrt_p_simulated_deg_s,
                    self.rate_std_eq19_printed_deg_s
                ),
                note: "eq 19 as printed has 1/(cΔt)² for 4/(cΔt)² (E6); 0.24 follows from the typo, the filter gives ≈ 0.335 (still below the gyro's 0.63)".into(),
            },
            Headline {
                quantity: "full-scale rate, R = 0.1 m".into(),
                paper: "740 °/s".into(),
                estim: format!("{:.1} °/s = √(1.7 g / R)", self.full_scale_rate_deg_s),
                note: String::new(),
            },
            Headline {
                quantity: "accelerometer noise at Δt = 0.01 s".into(),
                paper: "1.4 mg".into(),
                estim: format!(
                    "{:.3} mg = 110 µg/√Hz · √({:.1} Hz)",
                    self.accel_noise_mg, self.noise_bandwidth_hz
                ),
                note: "noise bandwidth (π/2)/Δt (first-order low-pass at 1/Δt) reproduces the paper's figures".into(),
            },
            Headline {
                quantity: "gyro noise at the same bandwidth".into(),
                paper: "0.63 °/s".into(),
                estim: format!("{:.3} °/s", self.gyro_noise_deg_s),
                note: String::new(),
            },
            Headline {
                quantity: "noise/full-scale ratio gyro vs accelerometer".into(),
                paper: "about 10".into(),
                estim: format!("{:.2}", self.noise_to_full_scale_ratio),
                note: String::new(),
            },
        ]
    }
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> std::result::Result<Output, Box<dyn std::error::Error>> {
    Ok(sharding::whole(run_in(quick, &Session::whole())?)?)
}

/// The example body as `session` says (whole, one shard: `None`, or the merge of the shards);
/// `--stats` gets the Monte Carlo's results (RMS predicted and filtered, mean √P, and the RMS
/// at each step).
pub fn run_in(
    quick: bool,
    session: &Session,
) -> std::result::Result<Option<Output>, Box<dyn std::error::Error>> {
    let config = if quick {
        RateConfig::quick()
    } else {
        RateConfig::paper()
    };
    let Some(r) = rate_experiment_in(&config, session)? else {
        return Ok(None);
    };
    let mut stats = vec![
        r.rate_rms_simulated_deg_s,
        r.rate_rms_filtered_simulated_deg_s,
        r.rate_sqrt_p_simulated_deg_s,
    ];
    stats.extend(&r.rms_over_time_deg_s);
    session.summary("runs", &stats);
    println!(
        "Boje section 3: R = {} m, Δt = {} s, σ = {} mg = {:.6} m/s², ω₀ = {} °/s",
        config.half_separation,
        config.dt,
        config.sigma_mg,
        config.sigma(),
        config.rate_deg_s
    );
    println!(
        "q = λ33 Δt² = {:.5e} (rad/s)², r = λ44 = {:.5e} (rad/s)⁴, c = 2ω₀ = {:.6} rad/s",
        r.q, r.r, r.c
    );
    println!("{:<52} {:>14} {:>10}", "route", "p (rad/s)²", "std °/s");
    let rows = [
        ("eq 18 closed form (predicted)", r.p_eq18),
        ("eq 17 iterated to steady state (predicted)", r.p_riccati),
        ("eq 17 steady state − q (filtered)", r.p_riccati - r.q),
        ("eq 19 corrected (1 + √(1 + 4/(cΔt)²))", r.p_eq19),
        ("eq 19 as printed (1 + √(1 + 1/(cΔt)²))", r.p_eq19_printed),
    ];
    for (name, p) in rows {
        println!("{:<52} {:>14.6e} {:>10.4}", name, p, p.sqrt().to_degrees());
    }
    println!(
        "eq 17 converged in {} iterations from p₀ = ({} °/s)²",
        r.riccati_iterations, config.initial_std_deg_s
    );
    println!(
        "scalar EKF Monte Carlo, {} runs × {} steps (first {} dropped): rms predicted {:.4} °/s, rms filtered {:.4} °/s, mean √P {:.4} °/s",
        config.runs,
        config.steps,
        config.burn_in,
        r.rate_rms_simulated_deg_s,
        r.rate_rms_filtered_simulated_deg_s,
        r.rate_sqrt_p_simulated_deg_s
    );
    println!();
    println!("{:<46} | {:<12} | estim", "headline", "paper");
    for h in r.headlines() {
        println!("{:<46} | {:<12} | {}", h.quantity, h.paper, h.estim);
        if !h.note.is_empty() {
            println!("{:<46}   note: {}", "", h.note);
        }
    }

    let eq18 = r.rate_std_eq18_deg_s;
    let printed = r.rate_std_eq19_printed_deg_s;
    let iters = r.riccati_trace.len().min(400);
    let trace: Vec<(f64, f64)> = r.riccati_trace[..iters]
        .iter()
        .enumerate()
        .map(|(i, p)| (i as f64, p.sqrt().to_degrees()))
        .collect();
    let flat = |v: f64| vec![(0.0, v), ((iters - 1) as f64, v)];
    match line_plot(
        "boje_rate_riccati.svg",
        "Boje eq 17 iterated vs eq 18 and the printed eq 19",
        "iteration (Δt steps)",
        "rate std (°/s)",
        &[
            Series {
                label: "√p, eq 17",
                points: trace,
            },
            Series {
                label: "eq 18",
                points: flat(eq18),
            },
            Series {
                label: "eq 19 as printed",
                points: flat(printed),
            },
        ],
    ) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
    let n = r.rms_over_time_deg_s.len().min(3000);
    let t = |i: usize| i as f64 * config.dt;
    match line_plot(
        "boje_rate_monte_carlo.svg",
        "Boje section 3: scalar EKF at 80 °/s, Monte Carlo",
        "t (s)",
        "rate error (°/s)",
        &[
            Series {
                label: "RMS predicted error over runs",
                points: (0..n).map(|i| (t(i), r.rms_over_time_deg_s[i])).collect(),
            },
            Series {
                label: "filter √P (run 1)",
                points: (0..n)
                    .map(|i| (t(i), r.sqrt_p_over_time_deg_s[i]))
                    .collect(),
            },
            Series {
                label: "eq 18",
                points: vec![(0.0, eq18), (t(n - 1), eq18)],
            },
            Series {
                label: "eq 19 as printed",
                points: vec![(0.0, printed), (t(n - 1), printed)],
            },
        ],
    ) {
        Ok(p) => println!("figure: {}", p.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
    let json = {
        serde_json::json!({
            "rate_std_eq18_deg_s": r.rate_std_eq18_deg_s,
            "rate_std_riccati_deg_s": r.rate_std_riccati_deg_s,
            "rate_rms_simulated_deg_s": r.rate_rms_simulated_deg_s,
        })
    };
    let headlines = r.headlines();
    Ok(Some(Output { json, headlines }))
}
