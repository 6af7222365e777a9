//! The particle algorithms beyond the filter: the transition log-density, the FFBSi particle
//! smoother against the RTS smoother.
//!
//! Every test is seeded, so each runs the same numbers in CI; each statistical bound is a
//! z- or t-test whose false-failure rate (for a fresh seed) is stated beside it.

use estim_core::nalgebra::{Matrix1, Matrix2, U0, U1, U2, Vector1, Vector2};
use estim_core::rand::Rng;
use estim_core::rand_distr::{Distribution, StandardNormal};
use estim_core::{
    Error, Gaussian, LinearMeasurement, LinearProcess, NoInput, Parameter, ProcessModel, Quantity,
    Stage,
};
use estim_filters::particle::{
    AdditiveGaussian, Ffbsi, NonGaussian, ParticleFilter, ProcessSampler, TransitionDensity,
    log_transition_density,
};
use estim_filters::smoother::Rts;
use estim_filters::{Estimator, KalmanFilter, Update};

use crate::common::{normal, rng};

/// x⁺ = 0.9 x + w, Q = 0.5.
type Ar1 = NoInput<LinearProcess<f64, U1, U0>>;

/// x⁺ = 0.9 x + w, Q = 0.5; z = x + v, R = 1; x₀ ~ N(0, 1).
fn ar1() -> (Ar1, LinearMeasurement<f64, U1, U1>, Gaussian<f64, U1>) {
    (
        LinearProcess::without_input(Matrix1::new(0.9), Matrix1::new(0.5)),
        LinearMeasurement {
            observation: Matrix1::new(1.0),
            noise: Matrix1::new(1.0),
        },
        Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap(),
    )
}

/// T readings simulated from the model (seeded).
fn readings(steps: usize, seed: u64) -> Vec<f64> {
    let mut g = rng(seed);
    let mut x = normal(&mut g);
    (0..steps)
        .map(|_| {
            x = 0.9 * x + 0.5f64.sqrt() * normal(&mut g);
            x + normal(&mut g)
        })
        .collect()
}

fn mean_and_variance(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    (
        mean,
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0),
    )
}

/// The RTS smoother's means and variances at steps 0..=T (predict, then update, each step).
fn rts(zs: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (process, sensor, prior) = ar1();
    let mut kf = KalmanFilter::new(prior);
    let mut rts = Rts::new();
    for &z in zs {
        rts.predict(&mut kf, &process, &(), 1.0).unwrap();
        kf.update(&sensor, &Vector1::new(z)).unwrap();
    }
    let smoothed = rts.smooth(&kf).unwrap();
    (
        smoothed.iter().map(|g| g.mean()[0]).collect(),
        smoothed.iter().map(|g| g.covariance()[(0, 0)]).collect(),
    )
}

/// A forward pass of `count` particles over `zs`, recorded for FFBSi.
fn forward(zs: &[f64], count: usize, seed: u64) -> (Ffbsi<f64, U1>, ParticleFilter<f64, U1>) {
    let (process, sensor, prior) = ar1();
    let mut pf = ParticleFilter::new(prior, count, seed).unwrap();
    let mut ffbsi = Ffbsi::new();
    for &z in zs {
        ffbsi.predict(&mut pf, &process, &(), 1.0).unwrap();
        pf.update(&sensor, &Vector1::new(z)).unwrap();
    }
    (ffbsi, pf)
}

/// The Gaussian transition density is log N(x⁺; f(x), Q) by Q's Cholesky factor (checked
/// against the scalar formula and a 2-D density written out by hand); a singular Q has none
/// and says so with a typed error.
#[test]
fn transition_log_density_is_the_gaussian_one_and_rejects_a_singular_q() {
    let (process, _, _) = ar1();
    let (x, next) = (Vector1::new(1.0), Vector1::new(0.2));
    let log_p = log_transition_density(
        &AdditiveGaussian(&process),
        &next,
        &x,
        &(),
        1.0,
        Stage::Smoothing,
    )
    .unwrap();
    let r: f64 = 0.2 - 0.9;
    let expected = -r * r / (2.0 * 0.5) - 0.5 * (2.0 * std::f64::consts::PI * 0.5).ln();
    // Both sides are a handful of f64 operations on O(1) numbers.
    assert!((log_p - expected).abs() < 1e-13, "{log_p} vs {expected}");

    // A correlated 2-D Q: −½ rᵀ Q⁻¹ r − ½ log det(2πQ) with the 2 × 2 inverse by hand.
    let q = Matrix2::new(2.0, 0.6, 0.6, 1.0);
    let cv = LinearProcess::without_input(Matrix2::new(1.0, 1.0, 0.0, 1.0), q);
    let (x, next) = (Vector2::new(1.0, -1.0), Vector2::new(0.5, 0.5));
    let r = next - Vector2::new(0.0, -1.0);
    let det = 2.0 * 1.0 - 0.6 * 0.6;
    let quad = (1.0 * r[0] * r[0] - 2.0 * 0.6 * r[0] * r[1] + 2.0 * r[1] * r[1]) / det;
    let expected = -0.5 * quad - (2.0 * std::f64::consts::PI).ln() - 0.5 * det.ln();
    let log_p =
        log_transition_density(&AdditiveGaussian(&cv), &next, &x, &(), 1.0, Stage::Update).unwrap();
    assert!((log_p - expected).abs() < 1e-13, "{log_p} vs {expected}");

    // Noise on the velocity only: the position is deterministic, no density.
    let singular = LinearProcess::without_input(
        Matrix2::new(1.0, 1.0, 0.0, 1.0),
        Matrix2::new(0.0, 0.0, 0.0, 0.1),
    );
    assert_eq!(
        log_transition_density(
            &AdditiveGaussian(&singular),
            &next,
            &x,
            &(),
            1.0,
            Stage::Smoothing
        ),
        Err(Error::NotPositiveDefinite {
            stage: Stage::Smoothing,
            quantity: Quantity::ProcessNoise
        })
    );
}

/// FFBSi's smoothed means and variances converge to the RTS smoother's like N^-1/2.
///
/// R = 40 seeded forward passes over the same 8 readings, each smoothed with its own seed, for
/// (N particles, M paths) = (100, 25) and (400, 100). At k ∈ {0, 4, 8} the errors
/// e = (FFBSi − RTS) of the mean and of the variance (the paths' 1/M variance times M/(M − 1),
/// which removes the sample variance's −P/M bias) are independent across seeds, with a bias
/// O(1/N) and a spread of variance a/M + b/N (backward sampling plus the forward filter's
/// error; Douc, Garivier, Moulines & Olsson 2011).
/// - unbiasedness: |ē| ≤ 4 s/√R (a t-test with 39 degrees of freedom, false-failure rate
///   ≈ 3·10⁻⁴ per check, 12 checks: < 0.4 %); the O(1/N) bias is well inside s/√R here;
/// - the rate: N and M both grow fourfold, so a/M + b/N falls fourfold and the RMS error
///   ratio is 1/2. Each RMS of R = 40 near-normal errors has relative standard error
///   1/√(2R) = 0.11, the ratio ≈ 0.16: 3σ gives [0.26, 0.74] (false-failure rate ≈ 0.3 % per
///   check; a smoother that did not converge has ratio ≈ 1).
#[test]
fn ffbsi_converges_to_the_rts_smoother() {
    let zs = readings(8, 21);
    let (rts_means, rts_vars) = rts(&zs);
    let (process, _, _) = ar1();
    let runs = 40u64;
    let checked = [0usize, 4, 8];
    // rms[config][moment][checked step]
    let mut rms = [[[0.0; 3]; 2]; 2];
    for (c, (count, paths)) in [(100usize, 25usize), (400, 100)].into_iter().enumerate() {
        let mut errors = vec![[vec![], vec![]]; checked.len()];
        for seed in 0..runs {
            let (ffbsi, pf) = forward(&zs, count, 100 + seed);
            let smoothed = ffbsi.smooth(&pf, &process, paths, 500 + seed).unwrap();
            assert_eq!(smoothed.len(), zs.len() + 1);
            assert_eq!(smoothed.paths(), paths);
            for (s, &k) in checked.iter().enumerate() {
                let unbiased = paths as f64 / (paths as f64 - 1.0);
                errors[s][0].push(smoothed.mean(k)[0] - rts_means[k]);
                errors[s][1].push(smoothed.covariance(k)[(0, 0)] * unbiased - rts_vars[k]);
            }
        }
        for (s, &k) in checked.iter().enumerate() {
            for (moment, e) in errors[s].iter().enumerate() {
                let (mean, var) = mean_and_variance(e);
                let se = (var / runs as f64).sqrt();
                assert!(
                    mean.abs() <= 4.0 * se,
                    "N = {count}, M = {paths}, k = {k}, moment {moment}: bias {mean}, se {se}"
                );
                rms[c][moment][s] = (e.iter().map(|x| x * x).sum::<f64>() / runs as f64).sqrt();
            }
        }
    }
    for moment in 0..2 {
        for (s, &k) in checked.iter().enumerate() {
            let ratio = rms[1][moment][s] / rms[0][moment][s];
            assert!(
                (0.26..=0.74).contains(&ratio),
                "k = {k}, moment {moment}: rms {} → {}, ratio {ratio} (expected 0.5)",
                rms[0][moment][s],
                rms[1][moment][s]
            );
        }
    }
    // Scale: at (400, 100) the mean's error is a small fraction of the smoothed spread.
    for (s, &k) in checked.iter().enumerate() {
        assert!(rms[1][0][s] < 0.15 * rts_vars[k].sqrt(), "k = {k}");
    }
}

/// The same Gaussian random walk as a model with its own sampler and density.
struct OwnWalk;

impl ProcessModel<f64, U1> for OwnWalk {
    type Input = ();
    fn transition(&self, x: &Vector1<f64>, _: &(), _: f64) -> Vector1<f64> {
        x * 0.9
    }
    fn process_noise(&self, _: &Vector1<f64>, _: &(), _: f64) -> Matrix1<f64> {
        Matrix1::new(0.5)
    }
}

impl ProcessSampler<f64, U1> for OwnWalk {
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        x: &Vector1<f64>,
        _: &(),
        _: f64,
        rng: &mut R,
    ) -> Vector1<f64> {
        let e: f64 = StandardNormal.sample(rng);
        Vector1::new(0.9 * x[0] + 0.5f64.sqrt() * e)
    }
}

impl TransitionDensity<f64, U1> for OwnWalk {
    fn log_transition_density(&self, next: &Vector1<f64>, x: &Vector1<f64>, _: &(), _: f64) -> f64 {
        let r = next[0] - 0.9 * x[0];
        -r * r - 0.5 * std::f64::consts::PI.ln()
    }
}

/// A model's own density drives the backward pass: written as the same Gaussian, it draws the
/// same trajectories from the same record (the backward weights agree to round-off, and a
/// draw flips only if a uniform lands within ~1e-15 of a cumulative weight).
/// Seeds reproduce the paths bit for bit, and another seed gives other paths.
#[test]
fn own_density_and_seeds_reproduce_the_gaussian_paths() {
    let zs = readings(6, 3);
    let (process, _, _) = ar1();
    let (ffbsi, pf) = forward(&zs, 200, 8);
    let gaussian = ffbsi.smooth(&pf, &process, 50, 1).unwrap();
    let own = ffbsi
        .smooth_with(&pf, &NonGaussian(OwnWalk), 50, 1)
        .unwrap();
    for k in 0..gaussian.len() {
        // The states are copies of the same particles: equal to the bit.
        assert_eq!(gaussian.at(k), own.at(k), "k = {k}");
    }
    assert_eq!(ffbsi.smooth(&pf, &process, 50, 1).unwrap(), gaussian);
    assert_ne!(ffbsi.smooth(&pf, &process, 50, 2).unwrap(), gaussian);
}

/// Bad input: typed errors, and neither the record nor the filter changes.
#[test]
fn ffbsi_bad_input_gives_typed_errors_and_changes_nothing() {
    let zs = readings(3, 4);
    let (process, _, prior) = ar1();
    let (mut ffbsi, mut pf) = forward(&zs, 50, 5);
    let (record, filter) = (ffbsi.clone(), pf.clone());
    assert_eq!(
        ffbsi.smooth(&pf, &process, 0, 1),
        Err(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: 0.0
        })
    );
    // A NaN Δt: nothing recorded, the filter unchanged.
    assert!(matches!(
        ffbsi.predict(&mut pf, &process, &(), f64::NAN),
        Err(Error::NonFinite {
            quantity: Quantity::TimeStep,
            ..
        })
    ));
    assert_eq!(ffbsi.len(), record.len());
    assert_eq!(pf, filter);
    // A filter of another particle count.
    let other = ParticleFilter::new(prior, 60, 5).unwrap();
    assert!(matches!(
        ffbsi.smooth(&other, &process, 10, 1),
        Err(Error::DimensionMismatch {
            quantity: Quantity::Weights,
            ..
        })
    ));
    assert!(matches!(
        ffbsi.record(&other, (), 1.0),
        Err(Error::DimensionMismatch { .. })
    ));
    assert_eq!(ffbsi.len(), record.len());
    // A process whose Q is NaN.
    let broken = LinearProcess::without_input(Matrix1::new(0.9), Matrix1::new(f64::NAN));
    assert_eq!(
        ffbsi.smooth(&pf, &broken, 10, 1),
        Err(Error::NonFinite {
            stage: Stage::Smoothing,
            quantity: Quantity::ProcessNoise
        })
    );
    assert_eq!(pf, filter);
}

/// A constant-velocity model with noise on the velocity only filters (the sampler uses Q's
/// PSD factor) but has no transition density: smoothing it is a typed error naming Q.
#[test]
fn ffbsi_of_a_singular_process_noise_is_a_typed_error() {
    let cv: NoInput<LinearProcess<f64, U2, U0>> = LinearProcess::without_input(
        Matrix2::new(1.0, 1.0, 0.0, 1.0),
        Matrix2::new(0.0, 0.0, 0.0, 0.1),
    );
    let sensor = LinearMeasurement {
        observation: estim_core::nalgebra::Matrix1x2::new(1.0, 0.0),
        noise: Matrix1::new(1.0),
    };
    let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity()).unwrap();
    let mut pf = ParticleFilter::new(prior, 100, 1).unwrap();
    let mut ffbsi = Ffbsi::new();
    for z in [0.5, 1.4, 2.2] {
        ffbsi.predict(&mut pf, &cv, &(), 1.0).unwrap();
        pf.update(&sensor, &Vector1::new(z)).unwrap();
    }
    assert!(pf.state().iter().all(|v| v.is_finite()));
    assert_eq!(
        ffbsi.smooth(&pf, &cv, 10, 1),
        Err(Error::NotPositiveDefinite {
            stage: Stage::Smoothing,
            quantity: Quantity::ProcessNoise
        })
    );
}
