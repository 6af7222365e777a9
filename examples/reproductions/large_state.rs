//! A 200-state linear filter: the 1-D heat equation on a rod, observed at every other node.
//!
//! The rod [0, 1] m has 200 interior nodes (spacing h = 1/201 m) and its ends held at the
//! ambient temperature; the state is the temperature above ambient at each node. Explicit
//! (forward) Euler on u_t = D u_xx gives
//!
//! ```text
//! uᵢ⁺ = uᵢ + r (uᵢ₋₁ − 2uᵢ + uᵢ₊₁) + Δt bᵢ s + wᵢ,     r = D Δt / h²,
//! ```
//!
//! which is stable for r ≤ ½: the eigenvalues of F = I + r L (L the second-difference matrix)
//! are 1 − 4r sin²(kπ / (2(n + 1))), k = 1…n, inside (1 − 4r, 1), so |λ| < 1 needs r ≤ ½. We
//! take r = ¼, so F's eigenvalues lie in (0, 1) (no mode flips sign), and D = 10⁻⁴ m²/s (a
//! metal), which makes Δt = r h²/D = 61.9 ms. F is tridiagonal but stored dense. A heater at
//! x = 0.3 m adds s(t) = 2.5 (1 + sin(2π t / 5 s)) K/s at its node (the known input). Process
//! noise: white, (0.02 K)² per node and step. Measurements: the 100 odd-numbered nodes (every
//! other one), noise (0.1 K)² each, independent. Prior: 10 sin(πx) K with a squared-exponential
//! covariance (σ = 1 K, length 0.05 m) plus (0.1 K)² on the diagonal; the truth starts from a
//! draw of the prior, so a correct filter is consistent: the NEES of each step is χ²₂₀₀.
//!
//! Filters: `KalmanFilter<f64, Dyn>` and `Ukf<f64, Dyn>` (the default scaled unscented
//! transform, α = 10⁻³, β = 2, κ = 0, with 2n + 1 = 401 sigma points) from the same prior,
//! both driven by `estim_core::linear::{LinearProcess, LinearMeasurement}`. Printed: wall time
//! per step (predict + update on prepared filters; median and mean over the run), RMS
//! error against the truth, the NEES, and the largest KF−UKF difference against the round-off
//! bound it should respect (the UKF is exact on a linear model; α = 10⁻³ amplifies its
//! round-off).
//!
//! `cargo run --release --example large_state [-- --json] [-- --quick]`

use std::time::{Duration, Instant};

use estim::filters::ValidationError;
use estim::filters::consistency::{ChiSquareBand, nees};
use estim::nalgebra::{DMatrix, DVector, Dyn};
use estim::prelude::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// Interior nodes (states).
pub const NODES: usize = 200;
/// Measured nodes: every other one.
pub const MEASURED: usize = NODES / 2;
/// The diffusion number r = D Δt / h² (explicit Euler is stable for r ≤ ½).
pub const DIFFUSION_NUMBER: f64 = 0.25;
/// Thermal diffusivity D, m²/s.
pub const DIFFUSIVITY: f64 = 1e-4;
/// Process noise standard deviation per node and step, K.
pub const PROCESS_SIGMA: f64 = 0.02;
/// Measurement noise standard deviation, K.
pub const MEASUREMENT_SIGMA: f64 = 0.1;
/// The UKF's spread α (the default `Unscented`).
pub const ALPHA: f64 = 1e-3;
/// Steps of the full and the quick run.
pub const STEPS: usize = 200;
/// Steps with `--quick`.
pub const QUICK_STEPS: usize = 10;
/// Seed of the simulation.
pub const SEED: u64 = 2024;

/// The rod: process and measurement models, the prior, and the time step.
pub struct Rod {
    /// x⁺ = F x + B s + w.
    pub process: LinearProcess<f64, Dyn, Dyn>,
    /// z = H x + v at the odd-numbered nodes.
    pub sensors: LinearMeasurement<f64, Dyn, Dyn>,
    /// The prior on the initial temperatures.
    pub prior: Gaussian<f64, Dyn>,
    /// Δt, s.
    pub dt: f64,
    /// The measured nodes' indices.
    pub measured: Vec<usize>,
}

/// Node i's position, m (i = 0 … n − 1 are the interior nodes).
fn position(i: usize) -> f64 {
    (i + 1) as f64 / (NODES + 1) as f64
}

/// The heater's rate at time t, K/s.
fn heater(t: f64) -> f64 {
    2.5 * (1.0 + (2.0 * std::f64::consts::PI * t / 5.0).sin())
}

/// Builds the rod's models.
pub fn rod() -> Result<Rod, Error> {
    let n = NODES;
    let h = 1.0 / (n + 1) as f64;
    let dt = DIFFUSION_NUMBER * h * h / DIFFUSIVITY;
    let r = DIFFUSION_NUMBER;
    let transition = DMatrix::from_fn(n, n, |i, j| {
        if i == j {
            1.0 - 2.0 * r
        } else if i.abs_diff(j) == 1 {
            r
        } else {
            0.0
        }
    });
    let heater_node = (0.3 * (n + 1) as f64).round() as usize - 1;
    let input = DMatrix::from_fn(n, 1, |i, _| if i == heater_node { dt } else { 0.0 });
    let noise = DMatrix::identity(n, n) * PROCESS_SIGMA.powi(2);
    let measured: Vec<usize> = (0..MEASURED).map(|k| 2 * k + 1).collect();
    let mut observation = DMatrix::zeros(MEASURED, n);
    for (row, &node) in measured.iter().enumerate() {
        observation[(row, node)] = 1.0;
    }
    let sensor_noise = DMatrix::identity(MEASURED, MEASURED) * MEASUREMENT_SIGMA.powi(2);
    let mean = DVector::from_fn(n, |i, _| 10.0 * (std::f64::consts::PI * position(i)).sin());
    let length = 0.05;
    let cov = DMatrix::from_fn(n, n, |i, j| {
        let d = (position(i) - position(j)) / length;
        let nugget = if i == j { 0.1_f64.powi(2) } else { 0.0 };
        (-0.5 * d * d).exp() + nugget
    });
    Ok(Rod {
        process: LinearProcess {
            transition,
            input,
            noise,
        },
        sensors: LinearMeasurement {
            observation,
            noise: sensor_noise,
        },
        prior: Gaussian::new(mean, cov)?,
        dt,
        measured,
    })
}

/// A simulated run: heater inputs, true states and measurements after each step.
pub struct Truth {
    /// s(tₖ), K/s.
    pub inputs: Vec<DVector<f64>>,
    /// xₖ₊₁.
    pub states: Vec<DVector<f64>>,
    /// zₖ₊₁.
    pub measurements: Vec<DVector<f64>>,
}

fn normals(rng: &mut StdRng, len: usize) -> DVector<f64> {
    DVector::from_fn(len, |_, _| rng.sample(StandardNormal))
}

/// Simulates `steps` steps from a draw of the prior (seeded).
pub fn simulate(rod: &Rod, steps: usize, seed: u64) -> Truth {
    let mut rng = StdRng::seed_from_u64(seed);
    let l = rod
        .prior
        .covariance()
        .clone()
        .cholesky()
        .expect("the prior covariance is positive definite")
        .unpack();
    let mut x = rod.prior.mean() + l * normals(&mut rng, NODES);
    let mut truth = Truth {
        inputs: Vec::with_capacity(steps),
        states: Vec::with_capacity(steps),
        measurements: Vec::with_capacity(steps),
    };
    for k in 0..steps {
        let u = DVector::from_element(1, heater(k as f64 * rod.dt));
        x = &rod.process.transition * &x
            + &rod.process.input * &u
            + normals(&mut rng, NODES) * PROCESS_SIGMA;
        let z = &rod.sensors.observation * &x + normals(&mut rng, MEASURED) * MEASUREMENT_SIGMA;
        truth.inputs.push(u);
        truth.states.push(x.clone());
        truth.measurements.push(z);
    }
    truth
}

/// One filter's statistics over a run.
#[derive(Clone, Debug, Default)]
pub struct FilterStats {
    /// Wall time of predict + update per step (the filters are prepared, so the first step
    /// allocates nothing either).
    pub step_times: Vec<Duration>,
    /// NEES after each update.
    pub nees: Vec<f64>,
    /// Sum over steps of the squared error norm (for the RMS).
    squared_error: f64,
}

impl FilterStats {
    /// Median step time, ms.
    pub fn median_ms(&self) -> f64 {
        let mut t: Vec<f64> = self.step_times.iter().map(|d| d.as_secs_f64()).collect();
        t.sort_by(f64::total_cmp);
        if t.is_empty() {
            return f64::NAN;
        }
        let mid = t.len() / 2;
        let median = if t.len().is_multiple_of(2) {
            0.5 * (t[mid - 1] + t[mid])
        } else {
            t[mid]
        };
        1e3 * median
    }

    /// Mean step time, ms.
    pub fn mean_ms(&self) -> f64 {
        1e3 * self.step_times.iter().map(|d| d.as_secs_f64()).sum::<f64>()
            / self.step_times.len() as f64
    }

    /// RMS error over nodes and steps, K.
    pub fn rms(&self) -> f64 {
        (self.squared_error / (self.nees.len() * NODES) as f64).sqrt()
    }

    /// Average NEES.
    pub fn mean_nees(&self) -> f64 {
        self.nees.iter().sum::<f64>() / self.nees.len() as f64
    }

    fn min_nees(&self) -> f64 {
        self.nees.iter().copied().fold(f64::INFINITY, f64::min)
    }

    fn max_nees(&self) -> f64 {
        self.nees.iter().copied().fold(f64::NEG_INFINITY, f64::max)
    }

    fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "step_ms_median": self.median_ms(),
            "step_ms_mean": self.mean_ms(),
            "rms_error_k": self.rms(),
            "nees_mean": self.mean_nees(),
            "nees_min": self.min_nees(),
            "nees_max": self.max_nees(),
        })
    }
}

/// Everything the example measures.
pub struct LargeStateResult {
    /// Steps run.
    pub steps: usize,
    /// Δt, s.
    pub dt: f64,
    /// The Kalman filter's statistics.
    pub kf: FilterStats,
    /// The UKF's.
    pub ukf: FilterStats,
    /// max over steps and nodes of |x̂_KF − x̂_UKF|, K.
    pub max_state_diff: f64,
    /// max over steps of max |P_KF − P_UKF| / max |P_KF|.
    pub max_cov_rel_diff: f64,
    /// max over steps of |x̂|∞ (KF, predicted and updated), K.
    pub max_abs_state: f64,
    /// max over steps of the KF gain's largest row sum ‖K‖∞.
    pub max_gain_row_sum: f64,
    /// max over steps of κ₂(S), S = H P⁻ Hᵀ + R (KF).
    pub max_cond_s: f64,
    /// min over steps of √max Pᵢᵢ (KF, updated), K.
    pub min_sigma: f64,
    /// The round-off bound on `max_state_diff`, K (see [`state_diff_bound`]).
    pub state_diff_bound: f64,
    /// The round-off bound on `max_cov_rel_diff` (see [`cov_diff_bound`]).
    pub cov_diff_bound: f64,
}

/// The bound on the KF−UKF state difference, K, from the run's own scales.
///
/// The UKF is exact for linear maps, so the two differ by round-off only, of two kinds:
/// - The unscented mean is g(μ) + (1/2c) Σᵢ dᵢ with c = α² n: each sigma point's value g(χᵢ)
///   rounds with an error ≈ ε |g|, independently, and the weight amplifies their sum to
///   ≈ √(2n)/(2α²n) ε |g| = ½ √(2/n) ε |g| / α² (0.05 ε |g| / α² for n = 200). |g| is ≤ X = max
///   |x̂| in the prediction, and the update's ẑ = H x̂ (also ≤ X) reaches the state through the
///   gain, ≤ ‖K‖∞ X. Per step ½ √(2/n) (ε/α²) (1 + ‖K‖∞) X.
/// - Both filters' kernels (products of inner dimension n, the solve with S): ≤ 10 n ε κ(S)
///   relative, as for the large-filter test of estim-filters (estim-filters/tests/it/dynamic.rs), times X.
///
/// Errors of successive steps are added (no forgetting assumed), so the bound is `steps` times
/// the per-step sum.
pub fn state_diff_bound(
    steps: usize,
    max_abs_state: f64,
    max_gain_row_sum: f64,
    max_cond_s: f64,
) -> f64 {
    let n = NODES as f64;
    let eps = f64::EPSILON;
    let unscented = 0.5 * (2.0 / n).sqrt() * eps / (ALPHA * ALPHA) * (1.0 + max_gain_row_sum);
    let kernels = 10.0 * n * eps * max_cond_s;
    steps as f64 * (unscented + kernels) * max_abs_state
}

/// The bound on the KF−UKF covariance difference relative to max |P|.
///
/// The unscented covariance w Σᵢ dᵢ dᵢᵀ (w = 1/(2c), |dᵢ| ≈ √c σ) carries the sigma points'
/// rounding eᵢ ≈ ε |g| as w Σᵢ (dᵢ eᵢᵀ + eᵢ dᵢᵀ) ≈ √2 σ ε |g| / α (random signs over the 2n
/// points), and the cross-covariance w Σᵢ (χᵢ − μ) eᵢᵀ ≈ σ ε |g| / (√2 α). Relative to
/// max |P| ≥ σ²_min (σ_min the smallest √max Pᵢᵢ of the run), through the prediction and the
/// update's P⁺ = P⁻ − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ: ≤ √2 (ε/α) (X/σ_min) (1 + ‖K‖∞ + ‖K‖∞²) per
/// step, plus the kernels' 10 n ε κ(S); `steps` times that.
pub fn cov_diff_bound(
    steps: usize,
    max_abs_state: f64,
    max_gain_row_sum: f64,
    max_cond_s: f64,
    min_sigma: f64,
) -> f64 {
    let n = NODES as f64;
    let eps = f64::EPSILON;
    let g = max_gain_row_sum;
    let unscented = 2.0_f64.sqrt() * eps / ALPHA * (max_abs_state / min_sigma) * (1.0 + g + g * g);
    let kernels = 10.0 * n * eps * max_cond_s;
    steps as f64 * (unscented + kernels)
}

/// The KF gain's largest row sum ‖K‖∞ and κ₂(S) at the predicted covariance `p`.
fn gain_and_condition(rod: &Rod, p: &DMatrix<f64>) -> (f64, f64) {
    let pht = p.select_columns(&rod.measured);
    let s = pht.select_rows(&rod.measured) + &rod.sensors.noise;
    let eig = s.clone().symmetric_eigenvalues();
    let cond = eig.max() / eig.min();
    let k_t = s
        .cholesky()
        .expect("S is positive definite")
        .solve(&pht.transpose());
    let row_sum = k_t
        .column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    (row_sum, cond)
}

/// Runs both filters over `steps` steps.
pub fn experiment(steps: usize) -> Result<LargeStateResult, ValidationError> {
    let rod = rod()?;
    let truth = simulate(&rod, steps, SEED);
    let mut kf = KalmanFilter::new(rod.prior.clone());
    let mut ukf = Ukf::new(rod.prior.clone());
    // Size every runtime-size buffer now (the estimates are unchanged), so that no step below
    // allocates, the first one included; the reports are reused by `update_into`.
    let (mut kf_report, mut ukf_report) =
        (UpdateReport::zeros(Dyn(0)), UpdateReport::zeros(Dyn(0)));
    if let Some(u) = truth.inputs.first() {
        kf.prepare_predict(&rod.process, u, rod.dt)?;
        ukf.prepare_predict(&rod.process, u, rod.dt)?;
    }
    kf.prepare_update(&rod.sensors, &mut kf_report)?;
    ukf.prepare_update(&rod.sensors, &mut ukf_report)?;
    let (mut kf_stats, mut ukf_stats) = (FilterStats::default(), FilterStats::default());
    let mut out = LargeStateResult {
        steps,
        dt: rod.dt,
        kf: FilterStats::default(),
        ukf: FilterStats::default(),
        max_state_diff: 0.0,
        max_cov_rel_diff: 0.0,
        max_abs_state: rod.prior.mean().amax(),
        max_gain_row_sum: 0.0,
        max_cond_s: 0.0,
        min_sigma: f64::INFINITY,
        state_diff_bound: 0.0,
        cov_diff_bound: 0.0,
    };
    for ((u, z), x) in truth
        .inputs
        .iter()
        .zip(&truth.measurements)
        .zip(&truth.states)
    {
        // Kalman filter: predict, (untimed: gain and κ(S) for the bound), update.
        let start = Instant::now();
        kf.predict(&rod.process, u, rod.dt)?;
        let predict_time = start.elapsed();
        let (g, cond) = gain_and_condition(&rod, kf.covariance());
        out.max_gain_row_sum = out.max_gain_row_sum.max(g);
        out.max_cond_s = out.max_cond_s.max(cond);
        out.max_abs_state = out.max_abs_state.max(kf.state().amax());
        let start = Instant::now();
        kf.update_into(&rod.sensors, z, &mut kf_report)?;
        let kf_time = predict_time + start.elapsed();

        // UKF.
        let start = Instant::now();
        ukf.predict(&rod.process, u, rod.dt)?;
        ukf.update_into(&rod.sensors, z, &mut ukf_report)?;
        let ukf_time = start.elapsed();

        kf_stats.step_times.push(kf_time);
        ukf_stats.step_times.push(ukf_time);
        for (stats, filter_state, filter_cov) in [
            (&mut kf_stats, kf.state(), kf.covariance()),
            (&mut ukf_stats, ukf.state(), ukf.covariance()),
        ] {
            let e = x - filter_state;
            stats.squared_error += e.norm_squared();
            stats.nees.push(nees(&e, filter_cov)?);
        }
        out.max_abs_state = out.max_abs_state.max(kf.state().amax());
        out.min_sigma = out.min_sigma.min(kf.covariance().diagonal().max().sqrt());
        out.max_state_diff = out.max_state_diff.max((kf.state() - ukf.state()).amax());
        out.max_cov_rel_diff = out
            .max_cov_rel_diff
            .max((kf.covariance() - ukf.covariance()).amax() / kf.covariance().amax());
    }
    out.kf = kf_stats;
    out.ukf = ukf_stats;
    out.state_diff_bound = state_diff_bound(
        steps,
        out.max_abs_state,
        out.max_gain_row_sum,
        out.max_cond_s,
    );
    out.cov_diff_bound = cov_diff_bound(
        steps,
        out.max_abs_state,
        out.max_gain_row_sum,
        out.max_cond_s,
        out.min_sigma,
    );
    Ok(out)
}

/// The example body: 200 steps, or 10 with `quick`; returns the `--json` object.
pub fn run(quick: bool) -> Result<serde_json::Value, Box<dyn std::error::Error>> {
    let steps = if quick { QUICK_STEPS } else { STEPS };
    let start = Instant::now();
    let r = experiment(steps)?;
    let wall_s = start.elapsed().as_secs_f64();
    println!(
        "Heat equation on a rod: n = {NODES} states, m = {MEASURED} measurements (every other \
         node), explicit Euler with r = D Δt / h² = {DIFFUSION_NUMBER} ≤ 1/2 (stable), \
         Δt = {:.4} s, {steps} steps",
        r.dt
    );
    println!(
        "UKF: default scaled unscented transform, α = {ALPHA}, β = 2, κ = 0, {} sigma points\n",
        2 * NODES + 1
    );
    println!(
        "{:<14} {:>16} {:>14} {:>12} {:>11} {:>22}",
        "filter", "step median [ms]", "step mean [ms]", "RMS [K]", "mean NEES", "NEES min … max"
    );
    for (name, s) in [("KalmanFilter", &r.kf), ("Ukf", &r.ukf)] {
        println!(
            "{name:<14} {:>16.3} {:>14.3} {:>12.5} {:>11.2} {:>10.1} … {:<10.1}",
            s.median_ms(),
            s.mean_ms(),
            s.rms(),
            s.mean_nees(),
            s.min_nees(),
            s.max_nees()
        );
    }
    let band = ChiSquareBand::two_sided(NODES, 1, 0.95)?;
    println!(
        "(timed: predict + update on prepared filters, steps 1…{steps}; a consistent filter's NEES is χ²({NODES}) \
         at every step, mean {NODES}, 95% of single values in [{:.1}, {:.1}]; successive \
         steps are correlated, so the average is not tighter by √{steps})",
        band.lower, band.upper
    );
    println!(
        "\nKF vs UKF: max |x̂_KF − x̂_UKF| = {:.3e} K (round-off bound {:.3e} K), max |P_KF − \
         P_UKF| / max |P_KF| = {:.3e} (bound {:.3e}).",
        r.max_state_diff, r.state_diff_bound, r.max_cov_rel_diff, r.cov_diff_bound
    );
    println!(
        "The UKF is exact for a linear model; they differ by round-off only, which α = 10⁻³ \
         amplifies in the mean by ~1/α² (weights 1/(2α²n) on the sigma points' values)."
    );
    println!("total wall time {wall_s:.2} s");

    let json = serde_json::json!({
        "nodes": NODES,
        "measured": MEASURED,
        "steps": steps,
        "dt_s": r.dt,
        "diffusion_number": DIFFUSION_NUMBER,
        "alpha": ALPHA,
        "kf": r.kf.json(),
        "ukf": r.ukf.json(),
        "max_state_diff_k": r.max_state_diff,
        "state_diff_bound_k": r.state_diff_bound,
        "max_cov_rel_diff": r.max_cov_rel_diff,
        "cov_diff_bound": r.cov_diff_bound,
        "max_abs_state_k": r.max_abs_state,
        "max_gain_row_sum": r.max_gain_row_sum,
        "max_cond_s": r.max_cond_s,
        "min_sigma_k": r.min_sigma,
        "wall_s": wall_s,
    });
    Ok(json)
}

/// The example's `main` (`examples/large_state.rs`): its flags, the run and its output.
pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let json = run(std::env::args().any(|a| a == "--quick"))?;
    if std::env::args().any(|a| a == "--json") {
        println!("{json}");
    }
    Ok(())
}
