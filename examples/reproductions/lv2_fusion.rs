//! LV2 note: best estimates of x and y from redundant x, y and q = (x + y)/√2 accelerometer axes.
//!
//! Fuses the reading x̃ = 1.00, ỹ = 0.50, q̃ = 1.07 m/s² (σx = 0.010, σy = 0.012, σq = 0.008
//! m/s²) by the note's closed forms (eq 2–6), by weighted least squares and by the framework's
//! Kalman filter; tests consistency (eq 7) with a χ² threshold; fuses without each axis; then
//! runs the χ² Monte Carlo (fault-free and with a biased axis) and the saturation scenario.
//!
//! `cargo run --release --example lv2_fusion [-- --quick] [-- --json]`
//!
//! The χ² Monte Carlo also runs in shards (`--shard I/N --out FILE`, `--merge FILE...`,
//! `--stats FILE`; `sharding`): its readings come in seeded batches whose sums (counts of the
//! χ² at the CDF's points included) merge to the bits of one process.
//!
//! Figures: `target/figures/lv2_error_ellipses.svg` (1σ ellipses of (x̂, ŷ) with and without
//! each axis), `target/figures/lv2_chi2_cdf.svg` (Monte Carlo χ² CDF against χ²₁, fault-free
//! and with a biased x axis).

use core::f64::consts::SQRT_2;

use crate::common::{Headline, Output, Series, equal_axes_plot, line_plot};
use crate::exact_sum::ExactSums;
use crate::sharding::{self, Session, shard_runs};
use estim::filters::monte_carlo::run_seed;
use estim::models::lv2::simulate::{RotatingAcceleration, SensorArray, sample_xyq};
use estim::models::lv2::stats::{chi2_1_cdf, chi2_1_power, chi2_quantile_upper, chi2_sf};
use estim::models::lv2::xyq::{
    self, Eq6Coefficients, XyqAxes, XyqEstimate, XyqReading, XyqSigmas, eq5_x_hat, eq5_y_hat,
    parity_chi2,
};
use estim::models::lv2::{AxisStatus, FilterFusion, Fusion, FusionError, XyqModel, screen};
use estim::nalgebra::{Matrix2, U2, U3, Vector2};
use rand::SeedableRng;
use rand::rngs::StdRng;

/// Everything the example runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Lv2Config {
    /// The reading fused in the worked example (m/s²).
    pub reading: XyqReading,
    /// The channel noise (m/s²).
    pub sigmas: XyqSigmas,
    /// False-alarm rate α of the consistency test.
    pub false_alarm: f64,
    /// The χ² Monte Carlo.
    pub monte_carlo: MonteCarloConfig,
    /// The saturation run.
    pub saturation: SaturationConfig,
}

impl Lv2Config {
    /// The issue's scenario with 10⁶ Monte Carlo readings.
    pub fn full() -> Self {
        Self {
            reading: XyqReading {
                x: 1.00,
                y: 0.50,
                q: 1.07,
            },
            sigmas: XyqSigmas {
                x: 0.010,
                y: 0.012,
                q: 0.008,
            },
            false_alarm: 1e-3,
            monte_carlo: MonteCarloConfig {
                runs: 1_000_000,
                batch: 1_000,
                seed: 2004,
                truth: Vector2::new(1.0, 0.5),
                bias: 0.08,
                cdf_points: 161,
            },
            saturation: SaturationConfig {
                sample_rate_hz: 100.0,
                duration_s: 60.0,
                magnitude: 2.1,
                frequency_hz: 0.5,
                full_scale: 2.0,
                dropout: 0.01,
                seed: 1217,
            },
        }
    }

    /// The same scenario with 10⁵ Monte Carlo readings and a 20 s saturation run.
    pub fn quick() -> Self {
        let mut c = Self::full();
        c.monte_carlo.runs = 100_000;
        c.saturation.duration_s = 20.0;
        c
    }
}

impl Default for Lv2Config {
    fn default() -> Self {
        Self::full()
    }
}

/// The χ² Monte Carlo settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonteCarloConfig {
    /// Number of readings.
    pub runs: usize,
    /// Readings per seeded batch, at most: the readings are split evenly into
    /// ⌈runs/batch⌉ batches, batch b drawn from its own stream seeded `run_seed(seed, b)` (the
    /// Monte Carlo runner's), so that shards of batches run apart.
    pub batch: usize,
    /// Master seed.
    pub seed: u64,
    /// The true (x, y) (m/s²); the statistics do not depend on it.
    pub truth: Vector2<f64>,
    /// The bias (m/s²) put on one axis at a time for the detection test.
    pub bias: f64,
    /// Points of the CDF curves returned for the figure.
    pub cdf_points: usize,
}

/// The saturation run settings (the note gives none: a 100 Hz sampler, a ±2 m/s² range and a
/// 2.1 m/s² acceleration turning at 0.5 Hz make each axis saturate about 20 % of the time,
/// one axis at a time; 1 % random drop-outs exercise the missing mask and occasionally leave
/// too few axes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SaturationConfig {
    /// Sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Duration (s).
    pub duration_s: f64,
    /// Magnitude of the turning acceleration (m/s²).
    pub magnitude: f64,
    /// Its turning rate (Hz).
    pub frequency_hz: f64,
    /// Full-scale range of every channel (m/s²): readings clip at ±full scale.
    pub full_scale: f64,
    /// Probability that a channel's sample is lost.
    pub dropout: f64,
    /// RNG seed.
    pub seed: u64,
}

/// The worked example: one reading fused every way.
#[derive(Clone, Debug, PartialEq)]
pub struct FusionExample {
    /// The reading.
    pub reading: XyqReading,
    /// The channel noise.
    pub sigmas: XyqSigmas,
    /// Eq 6's precomputed coefficients.
    pub coefficients: Eq6Coefficients,
    /// x̂₁ = x̃ and x̂₂ = √2 q̃ − ỹ (eq 2).
    pub x_hat_1_2: (f64, f64),
    /// σ²x2 = 2σq² + σy² (eq 4).
    pub var_x2: f64,
    /// Eq 3 applied to (x̂₁, σx²) and (x̂₂, σ²x2): (x̂, its variance).
    pub eq3: (f64, f64),
    /// Eq 5 as printed and its mirror for ŷ.
    pub eq5: Vector2<f64>,
    /// The closed-form fusion (eq 6 and mirror, covariance, parity χ²).
    pub fused: XyqEstimate,
    /// The general weighted least squares on the x, y, q model.
    pub wls: Fusion<f64, U2, U3>,
    /// The Kalman filter route (exact prior from x, y, update with q).
    pub filter: FilterFusion<f64, U2>,
    /// Largest |difference| between the closed forms (eq 3, 5, 6, covariance, χ²) and the
    /// WLS and Kalman-filter routes.
    pub route_difference: RouteDifference,
    /// P(χ²₁ > χ²) for this reading.
    pub p_value: f64,
    /// The χ²₁ threshold at the configured false-alarm rate.
    pub threshold: f64,
    /// χ² ≤ threshold.
    pub consistent: bool,
    /// Fused from ỹ and q̃ (x lost).
    pub without_x: XyqEstimate,
    /// Fused from x̃ and q̃ (y lost).
    pub without_y: XyqEstimate,
    /// x̃ and ỹ alone (q lost).
    pub without_q: XyqEstimate,
}

/// Largest absolute differences between the closed forms and the other routes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RouteDifference {
    /// Over the estimate entries (m/s²).
    pub estimate: f64,
    /// Over the covariance entries ((m/s²)²).
    pub covariance: f64,
    /// Of the χ².
    pub chi2: f64,
}

/// Fuses `reading` by every route. Errors: invalid σ's.
pub fn fusion_example(
    reading: &XyqReading,
    sigmas: &XyqSigmas,
    false_alarm: f64,
) -> Result<FusionExample, FusionError> {
    let sigmas = XyqSigmas::new(sigmas.x, sigmas.y, sigmas.q)?;
    let coefficients = Eq6Coefficients::new(&sigmas);
    let fused = xyq::fuse(reading, &sigmas, XyqAxes::ALL)?;
    let eq5 = Vector2::new(eq5_x_hat(reading, &sigmas), eq5_y_hat(reading, &sigmas));
    let x_hat_1_2 = (reading.x, xyq::x_hat_2(reading));
    let var_x2 = sigmas.var_x2();
    let eq3 = xyq::combine_independent(x_hat_1_2.0, sigmas.x * sigmas.x, x_hat_1_2.1, var_x2);
    let model = XyqModel::xyq(&sigmas)?;
    let z = reading.to_vector();
    let status = [AxisStatus::Used; 3];
    let wls = model.fuse_screened(&z, &status)?;
    let filter = model.fuse_with_filter(&z, &status)?;
    let mut diff = RouteDifference {
        estimate: 0.0,
        covariance: 0.0,
        chi2: 0.0,
    };
    for (est, cov, chi2) in [
        (&wls.estimate, &wls.covariance, wls.chi2),
        (&filter.estimate, &filter.covariance, filter.chi2),
    ] {
        diff.estimate = diff
            .estimate
            .max((est - fused.estimate).amax())
            .max((est - eq5).amax())
            .max((est[0] - eq3.0).abs());
        diff.covariance = diff
            .covariance
            .max((cov - fused.covariance).amax())
            .max((cov[(0, 0)] - eq3.1).abs());
        diff.chi2 = diff.chi2.max((chi2 - fused.chi2).abs());
    }
    let without = |x: bool, y: bool, q: bool| xyq::fuse(reading, &sigmas, XyqAxes { x, y, q });
    let threshold = chi2_quantile_upper(false_alarm, 1);
    Ok(FusionExample {
        reading: *reading,
        sigmas,
        coefficients,
        x_hat_1_2,
        var_x2,
        eq3,
        eq5,
        fused,
        wls,
        filter,
        route_difference: diff,
        p_value: chi2_sf(fused.chi2, 1),
        threshold,
        consistent: fused.chi2 <= threshold,
        without_x: without(false, true, true)?,
        without_y: without(true, false, true)?,
        without_q: without(true, true, false)?,
    })
}

/// Detection of a bias on one axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultDetection {
    /// The biased axis: 'x', 'y' or 'q'.
    pub axis: char,
    /// The bias (m/s²).
    pub bias: f64,
    /// The shift of the standardised parity (x̃ + ỹ − √2 q̃)/√s₁ it causes: b/√s₁ for x and
    /// y, −√2 b/√s₁ for q.
    pub parity_shift: f64,
    /// Fraction of readings with χ² > threshold.
    pub detection_rate: f64,
    /// The predicted rate Φ(δ − √c) + Φ(−δ − √c).
    pub predicted_rate: f64,
    /// Mean of (x̂ − x, ŷ − y) over the readings (m/s²).
    pub mean_error: Vector2<f64>,
    /// The predicted bias of (x̂, ŷ): (bx − σx² p/s₁, by − σy² p/s₁), p = bx + by − √2 bq.
    pub predicted_mean_error: Vector2<f64>,
}

/// One point of the χ² CDF curves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CdfPoint {
    /// The χ² value.
    pub chi2: f64,
    /// Empirical P(χ² ≤ value), fault-free readings.
    pub empirical: f64,
    /// χ²₁ CDF.
    pub theory: f64,
    /// Empirical P(χ² ≤ value) with the bias on x.
    pub empirical_biased: f64,
    /// Noncentral χ²₁ CDF with the x bias's shift.
    pub theory_biased: f64,
}

/// The χ² Monte Carlo results.
#[derive(Clone, Debug, PartialEq)]
pub struct MonteCarloResult {
    /// Number of readings.
    pub runs: usize,
    /// Degrees of freedom of the χ² (three axes, two unknowns: 1).
    pub dof: usize,
    /// Nominal false-alarm rate α.
    pub false_alarm: f64,
    /// The χ²₁ threshold at α.
    pub threshold: f64,
    /// Mean χ² of fault-free readings (χ²₁: 1).
    pub chi2_mean: f64,
    /// Variance of χ² of fault-free readings (χ²₁: 2).
    pub chi2_variance: f64,
    /// Fraction of fault-free readings with χ² > threshold.
    pub false_alarm_rate: f64,
    /// Mean of (x̂ − x, ŷ − y), fault-free (m/s²).
    pub mean_error: Vector2<f64>,
    /// Sample covariance of (x̂ − x, ŷ − y), fault-free ((m/s²)²).
    pub empirical_covariance: Matrix2<f64>,
    /// The closed-form P.
    pub predicted_covariance: Matrix2<f64>,
    /// The covariance with q unused, diag(σx², σy²), for comparison.
    pub covariance_without_q: Matrix2<f64>,
    /// A bias on x, on y, on q (one at a time, same noise draws).
    pub faults: Vec<FaultDetection>,
    /// CDF curves for the figure.
    pub cdf: Vec<CdfPoint>,
}

/// The sums over batches of the χ² Monte Carlo ([`ExactSums`]): Σe (2), Σeeᵀ (xx, xy, yy),
/// Σχ², Σ(χ²)², alarms, detections per biased axis (3), Σ of the biased estimates' errors
/// (3 × 2), then at each CDF point the count of fault-free χ² ≤ it, then of x-biased ones.
const SUM_E: usize = 0;
const SUM_EE: usize = 2;
const SUM_CHI2: usize = 5;
const SUM_CHI2_SQ: usize = 6;
const ALARMS: usize = 7;
const DETECTIONS: usize = 8;
const FAULT_ERR: usize = 11;
const CDF: usize = 17;

/// The biases put on one axis at a time.
fn biases(b: f64) -> [(char, [f64; 3]); 3] {
    [
        ('x', [b, 0.0, 0.0]),
        ('y', [0.0, b, 0.0]),
        ('q', [0.0, 0.0, b]),
    ]
}

/// Batch `batch` of the χ² Monte Carlo: its readings (seed `run_seed(config.seed, batch)`),
/// their sums in reading order, added to `sums`.
fn monte_carlo_batch(
    sigmas: &XyqSigmas,
    config: &MonteCarloConfig,
    threshold: f64,
    grid: &[f64],
    batch: usize,
    sums: &mut ExactSums,
) {
    let c = Eq6Coefficients::new(sigmas);
    let mut rng = StdRng::seed_from_u64(run_seed(config.seed, batch));
    let truth = config.truth;
    let biases = biases(config.bias);
    let readings = shard_runs(batch, config.runs.div_ceil(config.batch), config.runs);
    let (mut sum_e, mut sum_ee) = (Vector2::zeros(), Matrix2::zeros());
    let (mut sum_chi2, mut sum_chi2_sq) = (0.0, 0.0);
    let mut alarms = 0usize;
    let mut detections = [0usize; 3];
    let mut fault_err = [Vector2::<f64>::zeros(); 3];
    // Histograms over the CDF grid: bin j counts the χ² in (grid[j−1], grid[j]].
    let mut hist = vec![0usize; 2 * (grid.len() + 1)];
    let (clean_hist, x_hist) = hist.split_at_mut(grid.len() + 1);
    for _ in readings {
        let clean = sample_xyq(&truth, sigmas, [0.0; 3], &mut rng);
        let e = Vector2::new(c.x_hat(&clean), c.y_hat(&clean)) - truth;
        sum_e += e;
        sum_ee += e * e.transpose();
        let chi2 = parity_chi2(&clean, sigmas);
        alarms += usize::from(chi2 > threshold);
        sum_chi2 += chi2;
        sum_chi2_sq += chi2 * chi2;
        clean_hist[grid.partition_point(|v| *v < chi2)] += 1;
        for (k, (_, bias)) in biases.iter().enumerate() {
            let r = XyqReading {
                x: clean.x + bias[0],
                y: clean.y + bias[1],
                q: clean.q + bias[2],
            };
            let chi2 = parity_chi2(&r, sigmas);
            detections[k] += usize::from(chi2 > threshold);
            fault_err[k] += Vector2::new(c.x_hat(&r), c.y_hat(&r)) - truth;
            if k == 0 {
                x_hist[grid.partition_point(|v| *v < chi2)] += 1;
            }
        }
    }
    sums.add_slice(SUM_E, sum_e.as_slice());
    sums.add_slice(SUM_EE, &[sum_ee[(0, 0)], sum_ee[(0, 1)], sum_ee[(1, 1)]]);
    sums.add_slice(SUM_CHI2, &[sum_chi2, sum_chi2_sq, alarms as f64]);
    for k in 0..3 {
        sums.add(DETECTIONS + k, detections[k] as f64);
        sums.add_slice(FAULT_ERR + 2 * k, fault_err[k].as_slice());
    }
    // Counts of χ² ≤ grid[i]: the bins up to i.
    for (offset, h) in [(CDF, &*clean_hist), (CDF + grid.len(), &*x_hist)] {
        let mut below = 0usize;
        for (i, n) in h[..grid.len()].iter().enumerate() {
            below += n;
            sums.add(offset + i, below as f64);
        }
    }
}

/// Runs the χ² Monte Carlo: `config.runs` seeded readings at `config.truth`, fused by eq 6.
/// Errors: invalid σ's.
pub fn monte_carlo(
    sigmas: &XyqSigmas,
    config: &MonteCarloConfig,
    false_alarm: f64,
) -> Result<MonteCarloResult, Box<dyn std::error::Error>> {
    Ok(sharding::whole(monte_carlo_in(
        sigmas,
        config,
        false_alarm,
        &Session::whole(),
    )?)?)
}

/// [`monte_carlo`] in `session`: the batches ([`MonteCarloConfig::batch`]) are its runs
/// (whole, a shard of them: `None`, or the merge of the shards).
pub fn monte_carlo_in(
    sigmas: &XyqSigmas,
    config: &MonteCarloConfig,
    false_alarm: f64,
    session: &Session,
) -> Result<Option<MonteCarloResult>, Box<dyn std::error::Error>> {
    let sigmas = XyqSigmas::new(sigmas.x, sigmas.y, sigmas.q)?;
    let threshold = chi2_quantile_upper(false_alarm, 1);
    let config = MonteCarloConfig {
        runs: config.runs.max(2),
        batch: config.batch.max(1),
        ..*config
    };
    let b = config.bias;
    let biases = biases(b);
    let runs = config.runs;
    let s1 = sigmas.s1();
    let shift_x = b / s1.sqrt();
    let top = (shift_x.abs() + 3.5).powi(2).max(1.5 * threshold);
    let points = config.cdf_points.max(2);
    let grid: Vec<f64> = (0..points)
        .map(|i| top * i as f64 / (points - 1) as f64)
        .collect();
    let batches = runs.div_ceil(config.batch);
    let Some(sums) = session.sums("readings", batches, CDF + 2 * points, |batch, sums| {
        monte_carlo_batch(&sigmas, &config, threshold, &grid, batch, sums);
        Ok(())
    })?
    else {
        return Ok(None);
    };
    let nf = runs as f64;
    let v = |i: usize| sums.value(i);
    let mean_error = Vector2::new(v(SUM_E), v(SUM_E + 1)) / nf;
    let sum_ee = Matrix2::new(v(SUM_EE), v(SUM_EE + 1), v(SUM_EE + 1), v(SUM_EE + 2));
    let empirical_covariance = (sum_ee - mean_error * mean_error.transpose() * nf) / (nf - 1.0);
    let chi2_mean = v(SUM_CHI2) / nf;
    // Σ(χ² − mean)² = Σ(χ²)² − n mean²: χ²₁ has E(χ²)² = 3 against mean² = 1, no cancellation.
    let chi2_variance = (v(SUM_CHI2_SQ) - nf * chi2_mean * chi2_mean) / (nf - 1.0);
    let faults = biases
        .iter()
        .enumerate()
        .map(|(k, (axis, bias))| {
            let p = bias[0] + bias[1] - SQRT_2 * bias[2];
            let shift = p / s1.sqrt();
            FaultDetection {
                axis: *axis,
                bias: b,
                parity_shift: shift,
                detection_rate: v(DETECTIONS + k) / nf,
                predicted_rate: chi2_1_power(shift, threshold),
                mean_error: Vector2::new(v(FAULT_ERR + 2 * k), v(FAULT_ERR + 2 * k + 1)) / nf,
                predicted_mean_error: Vector2::new(
                    bias[0] - sigmas.x * sigmas.x * p / s1,
                    bias[1] - sigmas.y * sigmas.y * p / s1,
                ),
            }
        })
        .collect::<Vec<_>>();
    let cdf = grid
        .iter()
        .enumerate()
        .map(|(i, &chi2)| CdfPoint {
            chi2,
            empirical: v(CDF + i) / nf,
            theory: chi2_1_cdf(chi2, 0.0),
            empirical_biased: v(CDF + points + i) / nf,
            theory_biased: chi2_1_cdf(chi2, shift_x),
        })
        .collect();
    Ok(Some(MonteCarloResult {
        runs,
        dof: 1,
        false_alarm,
        threshold,
        chi2_mean,
        chi2_variance,
        false_alarm_rate: v(ALARMS) / nf,
        mean_error,
        empirical_covariance,
        predicted_covariance: xyq::covariance(&sigmas),
        covariance_without_q: Matrix2::new(sigmas.x.powi(2), 0.0, 0.0, sigmas.y.powi(2)),
        faults,
        cdf,
    }))
}

/// Errors of one way of fusing over the saturation run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunErrors {
    /// Samples with an estimate.
    pub estimated: usize,
    /// Samples without one (fewer than two usable axes: the typed error).
    pub no_estimate: usize,
    /// RMS of (x̂ − x, ŷ − y) over the estimated samples (m/s²).
    pub rms_error: Vector2<f64>,
    /// √(mean of the diagonal of P) over the same samples: what the estimator claims (m/s²).
    pub predicted_rms: Vector2<f64>,
    /// Estimated samples whose χ² exceeded the threshold (only samples with 3 axes can).
    pub flagged: usize,
    /// Estimated samples that used all three axes.
    pub three_axes: usize,
}

/// The saturation run results.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SaturationResult {
    /// Number of samples.
    pub samples: usize,
    /// Readings at the rail, per channel (x, y, q).
    pub saturated: [usize; 3],
    /// Readings lost, per channel.
    pub missing: [usize; 3],
    /// Samples with at least one used reading at the rail in the naive fusion.
    pub clipped_samples: usize,
    /// The note's policy: drop missing and saturated channels, fuse the rest.
    pub screened: RunErrors,
    /// Drop only missing channels; use clipped readings as if valid.
    pub naive: RunErrors,
    /// Samples where x or y alone (no q) would give no estimate (x or y dropped by screening).
    pub xy_only_no_estimate: usize,
}

fn accumulate(
    errs: &mut (RunErrors, Vector2<f64>, Vector2<f64>),
    fused: Result<Fusion<f64, U2, U3>, FusionError>,
    truth: &Vector2<f64>,
    false_alarm: f64,
) -> Result<(), FusionError> {
    match fused {
        Ok(f) => {
            let e = f.estimate - truth;
            errs.0.estimated += 1;
            errs.1 += e.component_mul(&e);
            errs.2 += f.covariance.diagonal();
            errs.0.three_axes += usize::from(f.dof == 1);
            errs.0.flagged += usize::from(!f.is_consistent(false_alarm));
            Ok(())
        }
        Err(FusionError::TooFewAxes { .. } | FusionError::DependentAxes { .. }) => {
            errs.0.no_estimate += 1;
            Ok(())
        }
        Err(e) => Err(e),
    }
}

fn finish(errs: (RunErrors, Vector2<f64>, Vector2<f64>)) -> RunErrors {
    let (mut r, se, sp) = errs;
    let n = r.estimated.max(1) as f64;
    r.rms_error = (se / n).map(f64::sqrt);
    r.predicted_rms = (sp / n).map(f64::sqrt);
    r
}

/// Runs the saturation scenario: a [`RotatingAcceleration`] of `magnitude` sensed by the x, y,
/// q channels with range ±`full_scale`, fused with and without the saturation screen.
/// Errors: invalid σ's or configuration.
pub fn saturation_run(
    sigmas: &XyqSigmas,
    config: &SaturationConfig,
    false_alarm: f64,
) -> Result<SaturationResult, FusionError> {
    let model = XyqModel::xyq(sigmas)?;
    let mut array = SensorArray::new(model.clone());
    array.full_scale = Some(config.full_scale);
    array.dropout = config.dropout;
    let truth = RotatingAcceleration {
        offset: Vector2::zeros(),
        magnitude: config.magnitude,
        frequency_hz: config.frequency_hz,
    };
    let samples = (config.duration_s * config.sample_rate_hz).round().max(0.0) as usize;
    let mut rng = StdRng::seed_from_u64(config.seed);
    let zero = || {
        (
            RunErrors {
                estimated: 0,
                no_estimate: 0,
                rms_error: Vector2::zeros(),
                predicted_rms: Vector2::zeros(),
                flagged: 0,
                three_axes: 0,
            },
            Vector2::zeros(),
            Vector2::zeros(),
        )
    };
    let (mut screened, mut naive) = (zero(), zero());
    let (mut saturated, mut missing) = ([0usize; 3], [0usize; 3]);
    let (mut clipped_samples, mut xy_only_no_estimate) = (0, 0);
    for k in 0..samples {
        let theta = truth.at(k as f64 / config.sample_rate_hz);
        let s = array.sample(&theta, &mut rng);
        let status = screen(&s.reading, &s.missing, Some(config.full_scale))?;
        for i in 0..3 {
            saturated[i] += usize::from(status[i] == AxisStatus::Saturated);
            missing[i] += usize::from(status[i] == AxisStatus::Missing);
        }
        xy_only_no_estimate +=
            usize::from(status[0] != AxisStatus::Used || status[1] != AxisStatus::Used);
        accumulate(
            &mut screened,
            model.fuse_screened(&s.reading, &status),
            &theta,
            false_alarm,
        )?;
        let naive_status = screen(&s.reading, &s.missing, None)?;
        clipped_samples +=
            usize::from((0..3).any(|i| s.clipped[i] && naive_status[i] == AxisStatus::Used));
        accumulate(
            &mut naive,
            model.fuse_screened(&s.reading, &naive_status),
            &theta,
            false_alarm,
        )?;
    }
    Ok(SaturationResult {
        samples,
        saturated,
        missing,
        clipped_samples,
        screened: finish(screened),
        naive: finish(naive),
        xy_only_no_estimate,
    })
}

/// All three experiments' results.
#[derive(Clone, Debug, PartialEq)]
pub struct Lv2Results {
    /// The configuration that produced them.
    pub config: Lv2Config,
    /// The worked example.
    pub example: FusionExample,
    /// The χ² Monte Carlo.
    pub monte_carlo: MonteCarloResult,
    /// The saturation run.
    pub saturation: SaturationResult,
}

/// Runs the three experiments. Errors: invalid configuration.
pub fn run_experiment(config: &Lv2Config) -> Result<Lv2Results, Box<dyn std::error::Error>> {
    Ok(sharding::whole(run_experiment_in(
        config,
        &Session::whole(),
    )?)?)
}

/// [`run_experiment`] in `session`: the χ² Monte Carlo whole, a shard of it (then nothing
/// else runs: `None`) or the merge of the shards.
pub fn run_experiment_in(
    config: &Lv2Config,
    session: &Session,
) -> Result<Option<Lv2Results>, Box<dyn std::error::Error>> {
    let example = fusion_example(&config.reading, &config.sigmas, config.false_alarm)?;
    let Some(monte_carlo) = monte_carlo_in(
        &config.sigmas,
        &config.monte_carlo,
        config.false_alarm,
        session,
    )?
    else {
        return Ok(None);
    };
    Ok(Some(Lv2Results {
        config: config.clone(),
        example,
        monte_carlo,
        saturation: saturation_run(&config.sigmas, &config.saturation, config.false_alarm)?,
    }))
}

/// The note's claims next to what estim computes.
pub fn headlines(r: &Lv2Results) -> Vec<Headline> {
    let ex = &r.example;
    let mc = &r.monte_carlo;
    let sat = &r.saturation;
    let p = ex.fused.covariance;
    let s = ex.sigmas;
    let h = |quantity: &str, paper: &str, estim: String, note: &str| Headline {
        quantity: quantity.into(),
        paper: paper.into(),
        estim,
        note: note.into(),
    };
    let fault = |c: char| mc.faults.iter().find(|f| f.axis == c).copied();
    let rate = |c: char| fault(c).map_or(f64::NAN, |f| f.detection_rate);
    vec![
        h(
            "x̂ (eq 5/6)",
            "minimum-variance x̂ from x̃, ỹ, q̃ (eq 5; eq 6 precomputed)",
            format!(
                "x̂ = {:.6} m/s² (eq 5 {:.6}); WLS and Kalman routes agree to {:.1e} m/s²",
                ex.fused.estimate[0], ex.eq5[0], ex.route_difference.estimate
            ),
            "eq 5 = x-component of the joint WLS: both are the unique BLUE of x",
        ),
        h(
            "cost of eq 6",
            "2 adds and 3 multiplies per estimate",
            "2 adds, 3 multiplies for x̂ (eq 6); x̂ and ŷ together: 4 adds, 3 multiplies via the parity r".into(),
            "x̂ = x̃ − (σx²/s₁) r, ŷ = ỹ − (σy²/s₁) r share r = x̃ + ỹ − √2 q̃",
        ),
        h(
            "var(x̂)",
            "implied by eq 3/4: σx² σ²x2/(σx² + σ²x2)",
            format!(
                "{:.4e} (m/s²)² closed form; Monte Carlo {:.4e} ({} runs); σx² alone {:.4e}",
                p[(0, 0)],
                mc.empirical_covariance[(0, 0)],
                mc.runs,
                s.x * s.x
            ),
            "",
        ),
        h(
            "ŷ and cov(x̂, ŷ)",
            "not given (only x̂ is derived)",
            format!(
                "ŷ = {:.6} m/s²; cov = {:.4e} (m/s²)², correlation {:.3}; Monte Carlo cov {:.4e}",
                ex.fused.estimate[1],
                p[(0, 1)],
                p[(0, 1)] / (p[(0, 0)] * p[(1, 1)]).sqrt(),
                mc.empirical_covariance[(0, 1)]
            ),
            "x̂ and ŷ are correlated (−σx²σy²/s₁): a downstream filter needs the full 2×2 P",
        ),
        h(
            "consistency (eq 7)",
            "x̂₁ ≈ x̂₂ (no statistic or threshold given)",
            format!(
                "χ² = {:.4} (p = {:.3}); Monte Carlo mean χ² {:.4} (dof 1), false alarms {:.2e} at α = {:.0e}",
                ex.fused.chi2, ex.p_value, mc.chi2_mean, mc.false_alarm_rate, mc.false_alarm
            ),
            "χ² = (x̂₁ − x̂₂)²/(σx² + 2σq² + σy²) is the WLS residual rᵀR⁻¹r; the y-check is the same residual",
        ),
        h(
            "one axis lost",
            "the remaining measurements still provide both x and y, with some loss of precision",
            format!(
                "σx̂: {:.4} (all) → {:.4} (x lost), σŷ: {:.4} → {:.4} (y lost) m/s²",
                p[(0, 0)].sqrt(),
                ex.without_x.covariance[(0, 0)].sqrt(),
                p[(1, 1)].sqrt(),
                ex.without_y.covariance[(1, 1)].sqrt()
            ),
            "",
        ),
        h(
            "isolating a bad axis",
            "not enough information to eliminate a bad sensor output",
            format!(
                "a {:.3} m/s² bias is detected at rate x {:.3}, y {:.3}, q {:.3} (α = {:.0e}); the three faults move the one parity",
                mc.faults.first().map_or(f64::NAN, |f| f.bias),
                rate('x'),
                rate('y'),
                rate('q'),
                mc.false_alarm
            ),
            "one redundancy: detection, not isolation, as the note says",
        ),
        h(
            "saturation",
            "detect saturation and eliminate the saturated measurement",
            format!(
                "RMS x error {:.4} m/s² screened (claimed {:.4}) vs {:.4} using clipped readings; {} of {} samples without an estimate (x, y only: {})",
                sat.screened.rms_error[0],
                sat.screened.predicted_rms[0],
                sat.naive.rms_error[0],
                sat.screened.no_estimate,
                sat.samples,
                sat.xy_only_no_estimate
            ),
            "the note's scenario has no numbers; ours is a 2.1 m/s² turning acceleration on ±2 m/s² channels",
        ),
    ]
}

/// Points of the k-σ error ellipse {center + k L (cos t, sin t)}, L Lᵀ = `cov` (Cholesky),
/// closed (first point repeated), for plotting. Empty if `cov` is not positive definite.
pub fn error_ellipse(
    center: &Vector2<f64>,
    cov: &Matrix2<f64>,
    k: f64,
    points: usize,
) -> Vec<(f64, f64)> {
    let Some(chol) = cov.cholesky() else {
        return Vec::new();
    };
    let l = chol.l();
    let points = points.max(3);
    (0..=points)
        .map(|i| {
            let t = 2.0 * core::f64::consts::PI * i as f64 / points as f64;
            let p = center + l * Vector2::new(t.cos(), t.sin()) * k;
            (p[0], p[1])
        })
        .collect()
}

fn sd_rho(p: &Matrix2<f64>) -> (f64, f64, f64) {
    let (sx, sy) = (p[(0, 0)].sqrt(), p[(1, 1)].sqrt());
    (sx, sy, p[(0, 1)] / (sx * sy))
}

/// Runs the experiment (quick or full), prints its tables, writes its figures.
pub fn run(quick: bool) -> Result<Output, Box<dyn std::error::Error>> {
    Ok(sharding::whole(run_in(quick, &Session::whole())?)?)
}

/// The example body as `session` says (whole, one shard of the χ² Monte Carlo: `None`, or the
/// merge of the shards); `--stats` gets the Monte Carlo's statistics.
pub fn run_in(
    quick: bool,
    session: &Session,
) -> Result<Option<Output>, Box<dyn std::error::Error>> {
    let cfg = if quick {
        Lv2Config::quick()
    } else {
        Lv2Config::full()
    };
    let Some(res) = run_experiment_in(&cfg, session)? else {
        return Ok(None);
    };
    let mc = &res.monte_carlo;
    let mut stats = vec![mc.chi2_mean, mc.chi2_variance, mc.false_alarm_rate];
    stats.extend(mc.mean_error.iter().chain(&mc.empirical_covariance));
    for f in &mc.faults {
        stats.push(f.detection_rate);
        stats.extend(&f.mean_error);
    }
    for c in &mc.cdf {
        stats.extend([c.empirical, c.empirical_biased]);
    }
    session.summary("readings", &stats);
    let ex = &res.example;
    let r = ex.reading;
    let s = ex.sigmas;

    println!("LV2 redundant-axis fusion (all values in m/s²)");
    println!(
        "reading x̃ = {:.3}, ỹ = {:.3}, q̃ = {:.3};  σx = {:.3}, σy = {:.3}, σq = {:.3}",
        r.x, r.y, r.q, s.x, s.y, s.q
    );
    let c = ex.coefficients;
    println!(
        "eq 6 coefficients: s₁ = {:.4e}, f₁ = {:.6}, f₂ = {:.6}  (ŷ: g₁ = {:.6}, g₂ = {:.6})",
        c.s1, c.f1, c.f2, c.g1, c.g2
    );

    println!("\n{:<44} {:>12} {:>12}", "route", "x̂", "ŷ");
    println!(
        "{:<44} {:>12.7} {:>12}",
        "x̂₁ = x̃ (eq 2)", ex.x_hat_1_2.0, ""
    );
    println!(
        "{:<44} {:>12.7} {:>12}",
        "x̂₂ = √2 q̃ − ỹ (eq 2)", ex.x_hat_1_2.1, ""
    );
    println!(
        "{:<44} {:>12.7} {:>12}",
        "eq 3 (x̂₁, x̂₂ weighted by σx², σ²x2 of eq 4)", ex.eq3.0, ""
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "eq 5 as printed (and mirror for ŷ)", ex.eq5[0], ex.eq5[1]
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "eq 6 precomputed coefficients", ex.fused.estimate[0], ex.fused.estimate[1]
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "weighted least squares (HᵀR⁻¹H)⁻¹HᵀR⁻¹z", ex.wls.estimate[0], ex.wls.estimate[1]
    );
    println!(
        "{:<44} {:>12.7} {:>12.7}",
        "Kalman filter: exact prior (x, y), update q", ex.filter.estimate[0], ex.filter.estimate[1]
    );
    let d = ex.route_difference;
    println!(
        "largest route difference: estimate {:.1e}, covariance {:.1e}, χ² {:.1e}",
        d.estimate, d.covariance, d.chi2
    );

    println!(
        "\n{:<22} {:>10} {:>10} {:>10} {:>10} {:>9}",
        "axes used", "x̂", "ŷ", "σx̂", "σŷ", "ρ(x̂,ŷ)"
    );
    let rows: [(&str, &XyqEstimate); 4] = [
        ("x, y, q", &ex.fused),
        ("y, q (x lost)", &ex.without_x),
        ("x, q (y lost)", &ex.without_y),
        ("x, y (q lost)", &ex.without_q),
    ];
    for (name, e) in rows {
        let (sx, sy, rho) = sd_rho(&e.covariance);
        println!(
            "{name:<22} {:>10.6} {:>10.6} {:>10.6} {:>10.6} {:>9.3}",
            e.estimate[0], e.estimate[1], sx, sy, rho
        );
    }
    let p = ex.fused.covariance;
    println!(
        "P (x, y, q) = [[{:.4e}, {:.4e}], [{:.4e}, {:.4e}]]",
        p[(0, 0)],
        p[(0, 1)],
        p[(1, 0)],
        p[(1, 1)]
    );

    println!("\nConsistency (eq 7)");
    println!(
        "parity r = x̂₁ − x̂₂ = x̃ + ỹ − √2 q̃ = {:.6};  χ² = r²/s₁ = {:.4} (dof 1), p = {:.3}",
        ex.fused.parity.unwrap_or(f64::NAN),
        ex.fused.chi2,
        ex.p_value
    );
    println!(
        "threshold at α = {:.0e}: {:.3} → {}",
        cfg.false_alarm,
        ex.threshold,
        if ex.consistent { "consistent" } else { "FAULT" }
    );

    let mc = &res.monte_carlo;
    println!("\nMonte Carlo, {} seeded readings", mc.runs);
    println!(
        "fault-free χ²: mean {:.4} (χ²₁: 1), variance {:.4} (2), false alarms {:.2e} (α = {:.0e})",
        mc.chi2_mean, mc.chi2_variance, mc.false_alarm_rate, mc.false_alarm
    );
    let (e, q) = (mc.empirical_covariance, mc.predicted_covariance);
    println!(
        "cov(x̂ − x, ŷ − y): Monte Carlo [[{:.4e}, {:.4e}], [·, {:.4e}]]  closed form [[{:.4e}, {:.4e}], [·, {:.4e}]]",
        e[(0, 0)],
        e[(0, 1)],
        e[(1, 1)],
        q[(0, 0)],
        q[(0, 1)],
        q[(1, 1)]
    );
    println!(
        "\n{:<12} {:>10} {:>14} {:>12} {:>12} {:>20} {:>20}",
        "biased axis",
        "bias",
        "parity shift",
        "detected",
        "predicted",
        "mean error (x, y)",
        "predicted"
    );
    for f in &mc.faults {
        println!(
            "{:<12} {:>10.3} {:>13.3}σ {:>12.4} {:>12.4} {:>9.5}, {:>8.5} {:>9.5}, {:>8.5}",
            f.axis,
            f.bias,
            f.parity_shift,
            f.detection_rate,
            f.predicted_rate,
            f.mean_error[0],
            f.mean_error[1],
            f.predicted_mean_error[0],
            f.predicted_mean_error[1]
        );
    }

    let sat = &res.saturation;
    let sc = &cfg.saturation;
    println!(
        "\nSaturation: {:.1} m/s² turning at {} Hz, range ±{} m/s², {} Hz for {} s ({} samples), {:.0} % drop-outs",
        sc.magnitude,
        sc.frequency_hz,
        sc.full_scale,
        sc.sample_rate_hz,
        sc.duration_s,
        sat.samples,
        100.0 * sc.dropout
    );
    println!(
        "at the rail: x {}, y {}, q {};  missing: x {}, y {}, q {}",
        sat.saturated[0],
        sat.saturated[1],
        sat.saturated[2],
        sat.missing[0],
        sat.missing[1],
        sat.missing[2]
    );
    println!(
        "{:<34} {:>10} {:>12} {:>12} {:>12} {:>12} {:>8}",
        "fusion", "estimated", "RMS x", "RMS y", "claimed x", "claimed y", "χ² flags"
    );
    for (name, e) in [
        ("drop saturated (the note)", &sat.screened),
        ("use clipped readings", &sat.naive),
    ] {
        println!(
            "{name:<34} {:>10} {:>12.5} {:>12.5} {:>12.5} {:>12.5} {:>8}",
            e.estimated,
            e.rms_error[0],
            e.rms_error[1],
            e.predicted_rms[0],
            e.predicted_rms[1],
            e.flagged
        );
    }
    println!(
        "samples with a clipped reading in use (naive): {}; the χ² test flags {} of the naive fusions",
        sat.clipped_samples, sat.naive.flagged
    );
    println!(
        "samples without an estimate (fewer than 2 axes): {} with q; {} with x and y alone",
        sat.screened.no_estimate, sat.xy_only_no_estimate
    );

    println!("\n{:<22} | {:<58} | estim", "claim", "note");
    for h in headlines(&res) {
        println!("{:<22} | {:<58} | {}", h.quantity, h.paper, h.estim);
        if !h.note.is_empty() {
            println!("{:<22} | {:<58} |   ({})", "", "", h.note);
        }
    }

    // Figures.
    let ellipses: Vec<(String, Vec<(f64, f64)>)> = rows
        .iter()
        .map(|(name, e)| {
            (
                name.to_string(),
                error_ellipse(&e.estimate, &e.covariance, 1.0, 120),
            )
        })
        .collect();
    let series: Vec<Series<'_>> = ellipses
        .iter()
        .map(|(label, points)| Series {
            label,
            points: points.clone(),
        })
        .collect();
    match equal_axes_plot(
        "lv2_error_ellipses.svg",
        "1σ error ellipses of (x̂, ŷ), LV2 example",
        "x [m/s²]",
        "y [m/s²]",
        &series,
    ) {
        Ok(path) => println!("\nfigure: {}", path.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }
    let cdf = |f: fn(&CdfPoint) -> f64| mc.cdf.iter().map(|c| (c.chi2, f(c))).collect::<Vec<_>>();
    let thr = vec![(mc.threshold, 0.0), (mc.threshold, 1.0)];
    let series = [
        Series {
            label: "Monte Carlo, fault-free",
            points: cdf(|c| c.empirical),
        },
        Series {
            label: "χ²₁",
            points: cdf(|c| c.theory),
        },
        Series {
            label: "Monte Carlo, x biased",
            points: cdf(|c| c.empirical_biased),
        },
        Series {
            label: "noncentral χ²₁",
            points: cdf(|c| c.theory_biased),
        },
        Series {
            label: "threshold (α = 1e-3)",
            points: thr,
        },
    ];
    match line_plot(
        "lv2_chi2_cdf.svg",
        "CDF of the parity χ²",
        "χ²",
        "P(χ² ≤ value)",
        &series,
    ) {
        Ok(path) => println!("figure: {}", path.display()),
        Err(e) => eprintln!("figure failed: {e}"),
    }

    let json = {
        let json = serde_json::json!({
            "x_hat": ex.fused.estimate[0],
            "y_hat": ex.fused.estimate[1],
            "cov": [[p[(0, 0)], p[(0, 1)]], [p[(1, 0)], p[(1, 1)]]],
            "chi2": ex.fused.chi2,
            "x_hat_without_x": ex.without_x.estimate[0],
            "y_hat_without_y": ex.without_y.estimate[1],
        });
        json
    };
    let headlines = headlines(&res);
    Ok(Some(Output { json, headlines }))
}
