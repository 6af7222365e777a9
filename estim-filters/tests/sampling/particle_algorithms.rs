//! The particle algorithms beyond the filter: the transition log-density, the FFBSi particle
//! smoother against the RTS smoother, the Rao-Blackwellised filter against the Kalman filter,
//! PMMH against a Metropolis chain on the exact likelihood, a guided proposal against the
//! bootstrap filter.
//!
//! Every test is seeded, so each runs the same numbers in CI; each statistical bound is a
//! z- or t-test whose false-failure rate (for a fresh seed) is stated beside it.

use estim_core::nalgebra::{
    DMatrix, DVector, Dyn, Matrix1, Matrix1x2, Matrix2, U0, U1, U2, Vector1, Vector2,
};
use estim_core::rand::Rng;
use estim_core::rand_distr::{Distribution, StandardNormal};
use estim_core::{
    Error, Gaussian, LinearMeasurement, LinearProcess, NoInput, Parameter, ProcessModel, Quantity,
    Stage,
};
use estim_filters::particle::{
    AdditiveGaussian, ConditionalMeasurement, ConditionalTransition,
    ConditionallyLinearMeasurement, ConditionallyLinearProcess, Ffbsi, NonGaussian, ParticleFilter,
    ProcessSampler, Proposal, RaoBlackwellised, ResampleWhen, TransitionDensity,
    log_transition_density, particle_log_likelihood, pmmh,
};
use estim_filters::smoother::Rts;
use estim_filters::{Estimator, KalmanFilter, Predict, Update};

use crate::common::{normal, rng};
use crate::particle_common::{ar1, dyn_linear, mean_and_variance, readings};

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
    eprintln!("FFBSi RMS errors [config][mean, variance][k = 0, 4, 8]: {rms:?}");
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

/// A checkpoint of the smoother (with the filter's own) resumes bit-identically: the resumed
/// pair records the same later steps and smooths to the same paths. A corrupt one is an
/// error, not a panic: unnormalised or missing log-weights, a non-number particle, a cloud of
/// another particle count, a negative Δt, a cloud claiming 2⁶³ − 1 particles.
#[cfg(feature = "serde")]
#[test]
fn ffbsi_checkpoints_resume_bit_identically_and_reject_corruption() {
    let zs = readings(6, 7);
    let (process, sensor, _) = ar1();
    let (mut ffbsi, mut pf) = forward(&zs[..3], 40, 3);
    let saved = serde_json::to_value(&ffbsi).unwrap();
    let mut resumed: Ffbsi<f64, U1> = serde_json::from_value(saved.clone()).unwrap();
    let mut resumed_pf: ParticleFilter<f64, U1> =
        serde_json::from_value(serde_json::to_value(&pf).unwrap()).unwrap();
    assert_eq!(resumed, ffbsi);
    for &z in &zs[3..] {
        for (s, f) in [(&mut ffbsi, &mut pf), (&mut resumed, &mut resumed_pf)] {
            s.predict(f, &process, &(), 1.0).unwrap();
            f.update(&sensor, &Vector1::new(z)).unwrap();
        }
    }
    assert_eq!(resumed, ffbsi);
    assert_eq!(
        resumed.smooth(&resumed_pf, &process, 30, 2).unwrap(),
        ffbsi.smooth(&pf, &process, 30, 2).unwrap()
    );
    // An empty record round-trips.
    let empty: Ffbsi<f64, U1> = Ffbsi::new();
    let back: Ffbsi<f64, U1> =
        serde_json::from_value(serde_json::to_value(&empty).unwrap()).unwrap();
    assert_eq!(back, empty);

    let corrupt = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v = saved.clone();
        edit(&mut v);
        serde_json::from_value::<Ffbsi<f64, U1>>(v).is_err()
    };
    assert!(corrupt(
        &|v| v["records"][1]["log_weights"][3] = serde_json::json!(0.5)
    ));
    assert!(corrupt(&|v| {
        v["records"][2]["log_weights"].as_array_mut().unwrap().pop();
    }));
    assert!(corrupt(
        &|v| v["records"][0]["particles"][0][5] = serde_json::json!(null)
    ));
    assert!(corrupt(&|v| v["records"][1]["dt"] = serde_json::json!(-1.0)));
    assert!(corrupt(&|v| v["records"][1]["dt"] = serde_json::json!(null)));
    // A later cloud of another particle count.
    let (other, _) = forward(&zs[..1], 41, 3);
    let other = serde_json::to_value(&other).unwrap();
    assert!(corrupt(&|v| v["records"][2] = other["records"][0].clone()));
    // A runtime-size cloud claiming 2⁶³ − 1 particles: a shape error, not a panic (issue 41).
    let dynamic: ParticleFilter<f64, Dyn> = ParticleFilter::new(ar1().2.into_dyn(), 8, 1).unwrap();
    let mut record: Ffbsi<f64, Dyn> = Ffbsi::new();
    record.record(&dynamic, (), 1.0).unwrap();
    let mut v = serde_json::to_value(&record).unwrap();
    v["records"][0]["particles"][2] = serde_json::json!(i64::MAX);
    let e = serde_json::from_value::<Ffbsi<f64, Dyn>>(v).unwrap_err();
    assert!(e.to_string().contains("entries"), "{e}");
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

/// Position xn and velocity xl of a constant-velocity target: xn⁺ = xn + xl + wn,
/// xl⁺ = xl + wl (Qn = 0.1, Ql = 0.05); z = xn + v (R = 0.5). The "nonlinear" part is linear,
/// so the Kalman filter of the whole state is the exact answer.
#[derive(Clone)]
pub(crate) struct SplitCv;

impl ConditionallyLinearProcess<f64, U1, U1> for SplitCv {
    type Input = ();
    fn conditional_transition(
        &self,
        xn: &Vector1<f64>,
        _: &(),
        dt: f64,
    ) -> ConditionalTransition<f64, U1, U1> {
        ConditionalTransition {
            nonlinear_mean: *xn,
            coupling: Matrix1::new(dt),
            nonlinear_noise: Matrix1::new(0.1),
            linear_mean: Vector1::zeros(),
            linear_transition: Matrix1::new(1.0),
            linear_noise: Matrix1::new(0.05),
        }
    }
}

#[derive(Clone)]
pub(crate) struct SplitPosition;

impl ConditionallyLinearMeasurement<f64, U1, U1, U1> for SplitPosition {
    fn conditional_measurement(&self, xn: &Vector1<f64>) -> ConditionalMeasurement<f64, U1, U1> {
        ConditionalMeasurement {
            offset: *xn,
            observation: Matrix1::zeros(),
            noise: Matrix1::new(0.5),
        }
    }
}

/// The same model on the whole state (position, velocity), prior N((0, 1), I).
/// The whole-state constant-velocity process.
pub(crate) type WholeCv = NoInput<LinearProcess<f64, U2, U0>>;

pub(crate) fn whole_cv() -> (WholeCv, LinearMeasurement<f64, U2, U1>, Gaussian<f64, U2>) {
    (
        LinearProcess::without_input(
            Matrix2::new(1.0, 1.0, 0.0, 1.0),
            Matrix2::new(0.1, 0.0, 0.0, 0.05),
        ),
        LinearMeasurement {
            observation: Matrix1x2::new(1.0, 0.0),
            noise: Matrix1::new(0.5),
        },
        Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::identity()).unwrap(),
    )
}

/// T position readings of the constant-velocity target (seeded).
pub(crate) fn cv_readings(steps: usize, seed: u64) -> Vec<f64> {
    let mut g = rng(seed);
    let (mut p, mut v) = (normal(&mut g), 1.0 + normal(&mut g));
    (0..steps)
        .map(|_| {
            p += v + 0.1f64.sqrt() * normal(&mut g);
            v += 0.05f64.sqrt() * normal(&mut g);
            p + 0.5f64.sqrt() * normal(&mut g)
        })
        .collect()
}

/// The Rao-Blackwellised filter on a model whose nonlinear part is also linear matches the
/// Kalman filter of the whole state, with a smaller spread over seeds than a plain particle
/// filter of the same N (the Rao-Blackwell theorem: the velocity is computed, not sampled).
///
/// R = 80 seeds, N = 200, 12 readings; errors e = (estimate − Kalman) at the last step for the
/// position and velocity means and the velocity variance.
/// - unbiasedness of the RBPF: |ē| ≤ 4 s/√R (t-test, 79 degrees of freedom: false-failure
///   rate ≈ 10⁻⁴ per check, 3 checks);
/// - the spread: ρ = rms(RBPF)/rms(PF) per quantity. Each RMS of R = 80 near-normal errors has
///   relative standard error 1/√(2R) = 0.08, so ρ has ≈ 0.11 relative standard error. Measured
///   here: ρ ≈ 0.73 for the position (sampled in both filters, better only through the better
///   weights), 0.52 for the velocity and 0.29 for its variance (computed, not sampled). The
///   bounds ρ ≤ 1 (position) and ρ ≤ 0.7 (velocity mean and variance) sit ≈ 3σ or more above
///   such values on the log scale (false-failure rate ≈ 0.2 % per check for a fresh seed); a
///   filter no better than the plain one (ρ ≈ 1) fails the velocity bounds at 3.2σ.
/// - the log-likelihood estimate is unbiased: the log-normal form of the likelihood test of
///   `particle::` (|mean(ℓ̂ − ℓ) + s²/2| ≤ 4 standard errors).
#[test]
fn rao_blackwellised_filter_matches_the_kalman_filter_with_less_spread() {
    let zs = cv_readings(12, 31);
    let (process, sensor, prior) = whole_cv();
    let mut kf = KalmanFilter::new(prior.clone());
    let mut exact_ll = 0.0;
    for &z in &zs {
        kf.predict(&process, &(), 1.0).unwrap();
        exact_ll += kf.update(&sensor, &Vector1::new(z)).unwrap().log_likelihood;
    }
    let runs = 80u64;
    let count = 200;
    let xn_prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap();
    let xl_prior = Gaussian::new(Vector1::new(1.0), Matrix1::new(1.0)).unwrap();
    // errors[filter][quantity]
    let mut errors = [[vec![], vec![], vec![]], [vec![], vec![], vec![]]];
    let mut log_errors = vec![];
    for seed in 0..runs {
        let mut rbpf =
            RaoBlackwellised::new(xn_prior.clone(), xl_prior.clone(), count, 40 + seed).unwrap();
        let mut pf = ParticleFilter::new(prior.clone(), count, 40 + seed).unwrap();
        for &z in &zs {
            rbpf.predict(&SplitCv, &(), 1.0).unwrap();
            rbpf.update(&SplitPosition, &Vector1::new(z)).unwrap();
            pf.predict(&process, &(), 1.0).unwrap();
            pf.update(&sensor, &Vector1::new(z)).unwrap();
        }
        errors[0][0].push(rbpf.nonlinear_mean()[0] - kf.state()[0]);
        errors[0][1].push(rbpf.linear_mean()[0] - kf.state()[1]);
        errors[0][2].push(rbpf.linear_covariance()[(0, 0)] - kf.covariance()[(1, 1)]);
        errors[1][0].push(pf.state()[0] - kf.state()[0]);
        errors[1][1].push(pf.state()[1] - kf.state()[1]);
        errors[1][2].push(pf.covariance()[(1, 1)] - kf.covariance()[(1, 1)]);
        log_errors.push(rbpf.log_likelihood() - exact_ll);
    }
    let rms = |e: &[f64]| (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
    let mut ratios = [0.0; 3];
    for quantity in 0..3 {
        let (mean, var) = mean_and_variance(&errors[0][quantity]);
        let se = (var / runs as f64).sqrt();
        assert!(
            mean.abs() <= 4.0 * se,
            "quantity {quantity}: bias {mean}, se {se}"
        );
        ratios[quantity] = rms(&errors[0][quantity]) / rms(&errors[1][quantity]);
    }
    eprintln!("RMS ratios RBPF / PF (position, velocity, velocity variance): {ratios:?}");
    assert!(ratios[0] <= 1.0, "position: ratio {}", ratios[0]);
    assert!(
        ratios[1] <= 0.7 && ratios[2] <= 0.7,
        "velocity: ratios {ratios:?}"
    );
    let (log_mean, log_var) = mean_and_variance(&log_errors);
    let log_se = (log_var / runs as f64 + log_var * log_var / (2.0 * (runs as f64 - 1.0))).sqrt();
    eprintln!("log-likelihood: mean error {log_mean}, var {log_var}");
    assert!((log_mean + log_var / 2.0).abs() <= 4.0 * log_se);
}

/// Bad input to the Rao-Blackwellised filter: typed errors, the filter unchanged.
#[test]
fn rao_blackwellised_bad_input_gives_typed_errors_and_changes_nothing() {
    let xn_prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap();
    let xl_prior = Gaussian::new(Vector1::new(1.0), Matrix1::new(1.0)).unwrap();
    assert_eq!(
        RaoBlackwellised::new(xn_prior.clone(), xl_prior.clone(), 0, 1).err(),
        Some(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: 0.0
        })
    );
    let mut rbpf = RaoBlackwellised::new(xn_prior, xl_prior, 50, 1).unwrap();
    rbpf.predict(&SplitCv, &(), 1.0).unwrap();
    rbpf.update(&SplitPosition, &Vector1::new(0.7)).unwrap();
    let same = |a: &RaoBlackwellised<f64, U1, U1>, b: &RaoBlackwellised<f64, U1, U1>| {
        a.nonlinear_particles() == b.nonlinear_particles()
            && a.log_weights() == b.log_weights()
            && a.log_likelihood() == b.log_likelihood()
            && a.linear_filters()
                .iter()
                .zip(b.linear_filters())
                .all(|(x, y)| x.state() == y.state() && x.covariance() == y.covariance())
    };
    let before = rbpf.clone();
    assert!(matches!(
        rbpf.update(&SplitPosition, &Vector1::new(f64::NAN)),
        Err(Error::NonFinite {
            quantity: Quantity::Measurement,
            ..
        })
    ));
    assert!(matches!(
        rbpf.predict(&SplitCv, &(), -1.0),
        Err(Error::InvalidParameter {
            parameter: Parameter::TimeStep,
            ..
        })
    ));
    /// A transition whose coupling is NaN for particles right of the origin: the step fails
    /// part-way through the cloud.
    struct HalfBroken;
    impl ConditionallyLinearProcess<f64, U1, U1> for HalfBroken {
        type Input = ();
        fn conditional_transition(
            &self,
            xn: &Vector1<f64>,
            u: &(),
            dt: f64,
        ) -> ConditionalTransition<f64, U1, U1> {
            let mut t = SplitCv.conditional_transition(xn, u, dt);
            if xn[0] > 0.0 {
                t.coupling[0] = f64::NAN;
            }
            t
        }
    }
    assert!(matches!(
        rbpf.predict(&HalfBroken, &(), 1.0),
        Err(Error::NonFinite {
            quantity: Quantity::Jacobian,
            ..
        })
    ));
    /// A sensor with a negative R: no innovation covariance to factor.
    struct Negative;
    impl ConditionallyLinearMeasurement<f64, U1, U1, U1> for Negative {
        fn conditional_measurement(
            &self,
            xn: &Vector1<f64>,
        ) -> ConditionalMeasurement<f64, U1, U1> {
            ConditionalMeasurement {
                offset: *xn,
                observation: Matrix1::zeros(),
                noise: Matrix1::new(-1.0),
            }
        }
    }
    assert!(rbpf.update(&Negative, &Vector1::new(0.7)).is_err());
    assert!(same(&rbpf, &before));
    assert_eq!(rbpf, before); // the joint moments and the step counter too
    // And it still steps as the untouched copy does, to the bit.
    let mut copy = before.clone();
    rbpf.predict(&SplitCv, &(), 1.0).unwrap();
    copy.predict(&SplitCv, &(), 1.0).unwrap();
    assert!(same(&rbpf, &copy));
}

/// The exact posterior mean and variance of the AR(1) coefficient φ (uniform prior on
/// (−1, 1)) by quadrature of the Kalman likelihood on a grid of 2000 midpoints (the posterior
/// is smooth with sd ≈ 0.1: the midpoint rule is exact to far below the chains' errors).
fn quadrature_posterior(zs: &[f64]) -> (f64, f64) {
    let cells = 2000;
    let grid: Vec<f64> = (0..cells)
        .map(|i| -1.0 + (i as f64 + 0.5) * 2.0 / cells as f64)
        .collect();
    let lls: Vec<f64> = grid.iter().map(|&phi| ar1_kalman_ll(zs, phi)).collect();
    let max = lls.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = lls.iter().map(|l| (l - max).exp()).collect();
    let total: f64 = w.iter().sum();
    let mean = grid.iter().zip(&w).map(|(g, w)| g * w).sum::<f64>() / total;
    let var = grid
        .iter()
        .zip(&w)
        .map(|(g, w)| (g - mean).powi(2) * w)
        .sum::<f64>()
        / total;
    (mean, var)
}

/// The Kalman log-likelihood of `zs` under x⁺ = φ x + w (Q = 0.5), z = x + v (R = 1).
fn ar1_kalman_ll(zs: &[f64], phi: f64) -> f64 {
    let (_, sensor, prior) = ar1();
    let process = LinearProcess::without_input(Matrix1::new(phi), Matrix1::new(0.5));
    let mut kf = KalmanFilter::new(prior);
    zs.iter()
        .map(|&z| {
            kf.predict(&process, &(), 1.0).unwrap();
            kf.update(&sensor, &Vector1::new(z)).unwrap().log_likelihood
        })
        .sum()
}

/// The chain's mean and variance, each with its batch-means standard error (B batches; the
/// variance through the batch means of (θ − θ̄)²).
fn batch_means(chain: &[f64], batches: usize) -> ((f64, f64), (f64, f64)) {
    let size = chain.len() / batches;
    let used = &chain[..size * batches];
    let mean = used.iter().sum::<f64>() / used.len() as f64;
    let squares: Vec<f64> = used.iter().map(|t| (t - mean).powi(2)).collect();
    let stats = |values: &[f64]| {
        let means: Vec<f64> = values
            .chunks(size)
            .map(|c| c.iter().sum::<f64>() / size as f64)
            .collect();
        let (m, v) = mean_and_variance(&means);
        (m, (v / batches as f64).sqrt())
    };
    (stats(used), stats(&squares))
}

/// PMMH with 20 particles targets the exact posterior: its mean and spread of φ agree with a
/// Metropolis chain on the exact Kalman likelihood (same proposal, prior and length), which
/// in turn agrees with quadrature.
///
/// 15 readings of the AR(1) model; prior uniform on (−1, 1); random walk of sd 0.2; 12 000
/// iterations after a burn-in of 500 (the start is near the mode). Monte Carlo errors from
/// batch means (B = 20 batches of 575, each far longer than the chains' autocorrelation,
/// printed as the acceptance rates: ≥ 0.1). The tests: |a − b| ≤ 4 √(se_a² + se_b²) for the
/// means and for the variances (batch means are t-distributed with 19 degrees of freedom:
/// a 4σ two-sided bound has false-failure rate ≈ 8·10⁻⁴ per check, 4 checks: < 0.4 %).
#[test]
fn pmmh_with_twenty_particles_targets_the_exact_posterior() {
    let zs = readings(15, 77);
    let readings_v: Vec<Vector1<f64>> = zs.iter().map(|&z| Vector1::new(z)).collect();
    let (_, sensor, prior) = ar1();
    let start = DVector::from_element(1, 0.8);
    let scale = DMatrix::from_element(1, 1, 0.2);
    let uniform = |theta: &DVector<f64>| {
        if theta[0].abs() < 1.0 {
            0.0
        } else {
            f64::NEG_INFINITY
        }
    };
    let (iterations, burn_in) = (12_000, 500);
    let particle = pmmh(&start, &scale, iterations, 3, uniform, |theta, seed| {
        let process = LinearProcess::without_input(Matrix1::new(theta[0]), Matrix1::new(0.5));
        particle_log_likelihood(&prior, &process, &(), 1.0, &sensor, &readings_v, 20, seed)
    })
    .unwrap();
    let exact = pmmh(&start, &scale, iterations, 4, uniform, |theta, _| {
        Ok(ar1_kalman_ll(&zs, theta[0]))
    })
    .unwrap();
    let (q_mean, q_var) = quadrature_posterior(&zs);
    let stats = |chain: &estim_filters::particle::PmmhChain| {
        let values: Vec<f64> = chain.samples.iter().skip(burn_in).cloned().collect();
        batch_means(&values, 20)
    };
    let ((p_mean, p_mean_se), (p_var, p_var_se)) = stats(&particle);
    let ((e_mean, e_mean_se), (e_var, e_var_se)) = stats(&exact);
    eprintln!(
        "quadrature {q_mean} {q_var}; PMMH {p_mean}±{p_mean_se} {p_var}±{p_var_se} (acc {}); \
         exact {e_mean}±{e_mean_se} {e_var}±{e_var_se} (acc {})",
        particle.acceptance_rate(),
        exact.acceptance_rate()
    );
    assert!(particle.acceptance_rate() >= 0.1 && exact.acceptance_rate() >= 0.1);
    let close = |a: f64, b: f64, se: f64| (a - b).abs() <= 4.0 * se;
    assert!(close(p_mean, e_mean, p_mean_se.hypot(e_mean_se)), "means");
    assert!(close(p_var, e_var, p_var_se.hypot(e_var_se)), "variances");
    assert!(
        close(e_mean, q_mean, e_mean_se),
        "exact chain vs quadrature mean"
    );
    assert!(
        close(e_var, q_var, e_var_se),
        "exact chain vs quadrature variance"
    );
    // A seed gives the same chain.
    let again = pmmh(&start, &scale, 50, 3, uniform, |theta, seed| {
        let process = LinearProcess::without_input(Matrix1::new(theta[0]), Matrix1::new(0.5));
        particle_log_likelihood(&prior, &process, &(), 1.0, &sensor, &readings_v, 20, seed)
    })
    .unwrap();
    assert_eq!(
        again.samples.columns(0, 51),
        particle.samples.columns(0, 51)
    );
}

/// Bad input to PMMH: typed errors.
#[test]
fn pmmh_bad_input_gives_typed_errors() {
    let start = DVector::from_element(1, 0.5);
    let flat = |_: &DVector<f64>| 0.0;
    let ll = |theta: &DVector<f64>, _: u64| Ok(-theta[0] * theta[0]);
    assert!(matches!(
        pmmh(&start, &DMatrix::from_element(2, 2, 0.1), 10, 1, flat, ll).map_err(Error::from),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        pmmh(
            &start,
            &DMatrix::from_element(1, 1, f64::NAN),
            10,
            1,
            flat,
            ll
        )
        .map_err(Error::from),
        Err(Error::NonFinite { .. })
    ));
    let nowhere = |_: &DVector<f64>| f64::NEG_INFINITY;
    assert_eq!(
        pmmh(
            &start,
            &DMatrix::from_element(1, 1, 0.1),
            10,
            1,
            nowhere,
            ll
        )
        .err()
        .map(|e| e.error),
        Some(Error::NonFinite {
            stage: Stage::Construction,
            quantity: Quantity::Mean
        })
    );
    let nan = |_: &DVector<f64>, _: u64| Ok(f64::NAN);
    assert_eq!(
        pmmh(&start, &DMatrix::from_element(1, 1, 0.1), 10, 1, flat, nan)
            .err()
            .map(|e| e.error),
        Some(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Weights
        })
    );
    assert!(matches!(
        pmmh(
            &start,
            &DMatrix::from_element(1, 1, 0.1),
            usize::MAX,
            1,
            flat,
            ll
        )
        .map_err(Error::from),
        Err(Error::InvalidParameter {
            parameter: Parameter::StepCount,
            ..
        })
    ));
}

/// PMMH tells a likelihood of zero from a model bug. AR(1) coefficient θ, prior uniform on
/// (−1, 1), 8 readings, 20 particles, 200 iterations from θ = 0.3.
///
/// - Above θ = 0.6 the closure's readings end with one at 10³⁰⁰ that no particle explains
///   (every log-weight −∞, the step's [`Quantity::Weights`] error): the estimate is `Ok(−∞)`,
///   the proposal rejected, and the chain runs to the end without visiting θ > 0.6.
/// - Above θ = 0.6 the sensor's gain is NaN instead (a bug in the model: h(x) NaN, the
///   step's [`Quantity::FunctionValue`] error): the chain stops at that iteration i with the
///   error, and the chain it returns is, bit for bit, the one a run of i − 1 iterations gives.
#[test]
fn pmmh_rejects_unexplained_readings_and_stops_on_a_nan_model() {
    let zs = readings(8, 5);
    let good: Vec<Vector1<f64>> = zs.iter().map(|&z| Vector1::new(z)).collect();
    let mut unexplained = good.clone();
    unexplained.push(Vector1::new(1e300));
    let (_, sensor, prior) = ar1();
    let (start, scale) = (
        DVector::from_element(1, 0.3),
        DMatrix::from_element(1, 1, 0.3),
    );
    let uniform = |theta: &DVector<f64>| {
        if theta[0].abs() < 1.0 {
            0.0
        } else {
            f64::NEG_INFINITY
        }
    };
    let process = |theta: f64| LinearProcess::without_input(Matrix1::new(theta), Matrix1::new(0.5));

    // The step's error, then the estimate, for the unexplained reading.
    let mut pf = ParticleFilter::new(prior.clone(), 20, 1).unwrap();
    pf.predict(&process(0.3), &(), 1.0).unwrap();
    assert_eq!(
        pf.update(&sensor, &Vector1::new(1e300)).err(),
        Some(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Weights
        })
    );
    let zero = particle_log_likelihood(
        &prior,
        &process(0.3),
        &(),
        1.0,
        &sensor,
        &unexplained,
        20,
        1,
    );
    assert_eq!(zero, Ok(f64::NEG_INFINITY));

    let mut refused = 0;
    let chain = pmmh(&start, &scale, 200, 9, uniform, |theta, seed| {
        let readings = if theta[0] > 0.6 {
            refused += 1;
            &unexplained
        } else {
            &good
        };
        particle_log_likelihood(
            &prior,
            &process(theta[0]),
            &(),
            1.0,
            &sensor,
            readings,
            20,
            seed,
        )
    })
    .unwrap();
    assert!(refused > 0, "no proposal above 0.6: the test tests nothing");
    assert_eq!(chain.samples.ncols(), 201);
    assert!(chain.samples.iter().all(|&t| t <= 0.6));
    assert!(chain.log_likelihoods.iter().all(|l| l.is_finite()));

    let nan_model = |theta: &DVector<f64>, seed: u64| {
        let gain = if theta[0] > 0.6 { f64::NAN } else { 1.0 };
        let sensor = LinearMeasurement {
            observation: Matrix1::new(gain),
            noise: Matrix1::new(1.0),
        };
        particle_log_likelihood(
            &prior,
            &process(theta[0]),
            &(),
            1.0,
            &sensor,
            &good,
            20,
            seed,
        )
    };
    let stopped = pmmh(&start, &scale, 200, 9, uniform, nan_model).unwrap_err();
    assert_eq!(
        stopped.error,
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::FunctionValue
        }
    );
    let i = stopped.iteration;
    assert!(i >= 1 && stopped.chain.samples.ncols() == i, "{i}");
    let before = pmmh(&start, &scale, i - 1, 9, uniform, nan_model).unwrap();
    assert_eq!(stopped.chain, before);
}

/// x⁺ = 0.9 x + w (Q = 0.5) read by a sharp sensor z = x + v (R = 0.05): the bootstrap
/// filter's weights degenerate (most particles land far from the reading).
const SHARP: f64 = 0.05;

/// The locally optimal proposal p(x⁺ | x, z) of that model: N(m, σ²) with
/// σ² = 1/(1/Q + 1/R), m = σ² (0.9 x / Q + z / R).
struct LocallyOptimal;

impl Proposal<f64, U1, U1> for LocallyOptimal {
    type Input = ();
    fn propose<R: Rng + ?Sized>(
        &self,
        x: &Vector1<f64>,
        _: &(),
        _: f64,
        z: &Vector1<f64>,
        rng: &mut R,
    ) -> (Vector1<f64>, f64) {
        let var = 1.0 / (1.0 / 0.5 + 1.0 / SHARP);
        let mean = var * (0.9 * x[0] / 0.5 + z[0] / SHARP);
        let e: f64 = StandardNormal.sample(rng);
        let log_q = -0.5 * e * e - 0.5 * (2.0 * std::f64::consts::PI * var).ln();
        (Vector1::new(mean + var.sqrt() * e), log_q)
    }
}

/// With the locally optimal proposal, the filter's moments converge to the Kalman filter's
/// like N^-1/2 and its weights vary less (higher ESS) than the bootstrap filter's.
///
/// 10 readings simulated with the sharp sensor; R = 40 seeds; resampling every step, so the
/// ESS after an update measures that step's weights alone.
/// - unbiased and converging: as `particle::moments_converge_to_the_kalman_filter_like_one_over_root_n`
///   (|ē| ≤ 4 s/√R, t-test with 39 degrees of freedom, false-failure rate ≈ 3·10⁻⁴ per check;
///   RMS ratio for N = 100 → 400 in [0.26, 0.74], ≈ 3σ of the ratio of two RMS over 40 runs);
/// - the ESS: the mean of ESS/N over the 400 (seed, step) updates at N = 400, guided minus
///   bootstrap, exceeds 4 standard errors of that difference (one-sided false-failure rate
///   3·10⁻⁵ if the guided filter were no better), and the guided filter's RMS error is below
///   the bootstrap's.
#[test]
fn locally_optimal_proposal_converges_with_higher_ess_than_bootstrap() {
    let mut g = rng(61);
    let mut x = normal(&mut g);
    let zs: Vec<f64> = (0..10)
        .map(|_| {
            x = 0.9 * x + 0.5f64.sqrt() * normal(&mut g);
            x + SHARP.sqrt() * normal(&mut g)
        })
        .collect();
    let (process, _, prior) = ar1();
    let sensor = LinearMeasurement {
        observation: Matrix1::new(1.0),
        noise: Matrix1::new(SHARP),
    };
    let mut kf = KalmanFilter::new(prior.clone());
    for &z in &zs {
        kf.predict(&process, &(), 1.0).unwrap();
        kf.update(&sensor, &Vector1::new(z)).unwrap();
    }
    let runs = 40u64;
    let mut rms = [[0.0; 2]; 2]; // [N][guided, bootstrap]
    let mut ess = [vec![], vec![]]; // at N = 400: [guided, bootstrap]
    for (c, count) in [100usize, 400].into_iter().enumerate() {
        let mut errors = [vec![], vec![]];
        for seed in 0..runs {
            let start = |s| {
                ParticleFilter::new(prior.clone(), count, s)
                    .unwrap()
                    .with_trigger(ResampleWhen::Always)
                    .unwrap()
            };
            let (mut guided, mut bootstrap) = (start(seed), start(seed));
            for &z in &zs {
                let z = Vector1::new(z);
                guided
                    .guided_step(&process, &LocallyOptimal, &(), 1.0, &sensor, &z)
                    .unwrap();
                bootstrap.predict(&process, &(), 1.0).unwrap();
                bootstrap.update(&sensor, &z).unwrap();
                if count == 400 {
                    ess[0].push(guided.effective_sample_size() / count as f64);
                    ess[1].push(bootstrap.effective_sample_size() / count as f64);
                }
            }
            errors[0].push(guided.state()[0] - kf.state()[0]);
            errors[1].push(bootstrap.state()[0] - kf.state()[0]);
        }
        let (mean, var) = mean_and_variance(&errors[0]);
        let se = (var / runs as f64).sqrt();
        assert!(mean.abs() <= 4.0 * se, "N = {count}: bias {mean}, se {se}");
        for f in 0..2 {
            rms[c][f] = (errors[f].iter().map(|e| e * e).sum::<f64>() / runs as f64).sqrt();
        }
    }
    let ratio = rms[1][0] / rms[0][0];
    let (g_mean, g_var) = mean_and_variance(&ess[0]);
    let (b_mean, b_var) = mean_and_variance(&ess[1]);
    let se = ((g_var + b_var) / ess[0].len() as f64).sqrt();
    eprintln!(
        "guided rms {:?}, ratio {ratio}; ESS/N guided {g_mean} bootstrap {b_mean} (se {se})",
        rms
    );
    assert!((0.26..=0.74).contains(&ratio), "rms {rms:?}, ratio {ratio}");
    assert!(
        g_mean - b_mean >= 4.0 * se,
        "ESS/N {g_mean} vs {b_mean}, se {se}"
    );
    assert!(
        rms[1][0] < rms[1][1],
        "rms guided {} vs bootstrap {}",
        rms[1][0],
        rms[1][1]
    );
}

/// A proposal that returns a NaN draw or a non-finite log q: typed errors, filter unchanged.
#[test]
fn guided_step_bad_proposals_give_typed_errors() {
    struct Bad(f64, f64);
    impl Proposal<f64, U1, U1> for Bad {
        type Input = ();
        fn propose<R: Rng + ?Sized>(
            &self,
            _: &Vector1<f64>,
            _: &(),
            _: f64,
            _: &Vector1<f64>,
            _: &mut R,
        ) -> (Vector1<f64>, f64) {
            (Vector1::new(self.0), self.1)
        }
    }
    let (process, sensor, prior) = ar1();
    let mut pf = ParticleFilter::new(prior, 50, 1).unwrap();
    let before = pf.clone();
    let z = Vector1::new(0.3);
    let step = |pf: &mut ParticleFilter<f64, U1>, q: &Bad| {
        pf.guided_step(&process, q, &(), 1.0, &sensor, &z)
    };
    assert!(matches!(
        step(&mut pf, &Bad(f64::NAN, 0.0)),
        Err(Error::NonFinite {
            quantity: Quantity::FunctionValue,
            ..
        })
    ));
    assert!(matches!(
        step(&mut pf, &Bad(0.0, f64::NEG_INFINITY)),
        Err(Error::NonFinite {
            quantity: Quantity::Weights,
            ..
        })
    ));
    assert_eq!(pf, before);
    // A well-formed (if poor) proposal steps.
    step(&mut pf, &Bad(0.1, 0.0)).unwrap();
    assert_ne!(pf, before);
}

/// The split constant-velocity model of `SplitCv` with runtime sizes (1 + 1).
struct SplitCvDyn;

impl ConditionallyLinearProcess<f64, Dyn, Dyn> for SplitCvDyn {
    type Input = ();
    fn conditional_transition(
        &self,
        xn: &DVector<f64>,
        _: &(),
        dt: f64,
    ) -> ConditionalTransition<f64, Dyn, Dyn> {
        ConditionalTransition {
            nonlinear_mean: xn.clone(),
            coupling: DMatrix::from_element(1, 1, dt),
            nonlinear_noise: DMatrix::from_element(1, 1, 0.1),
            linear_mean: DVector::zeros(1),
            linear_transition: DMatrix::from_element(1, 1, 1.0),
            linear_noise: DMatrix::from_element(1, 1, 0.05),
        }
    }
}

struct SplitPositionDyn;

impl ConditionallyLinearMeasurement<f64, Dyn, Dyn, Dyn> for SplitPositionDyn {
    fn conditional_measurement(&self, xn: &DVector<f64>) -> ConditionalMeasurement<f64, Dyn, Dyn> {
        ConditionalMeasurement {
            offset: xn.clone(),
            observation: DMatrix::zeros(1, 1),
            noise: DMatrix::from_element(1, 1, 0.5),
        }
    }
}

/// Runtime sizes follow the static ones: the FFBSi paths of a `Dyn` 2-state filter and the
/// Rao-Blackwellised filter with `Dyn` parts equal the static runs to round-off (the same
/// streams and the same operations; 10⁻¹² of the spread leaves room for a different order of
/// the small matrix kernels, and a backward draw could flip only on a near-tie of cumulative
/// weights, which these seeds do not hit). A runtime-size piece of the wrong shape is a typed
/// error.
#[test]
fn runtime_sizes_follow_the_static_algorithms() {
    let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
    let q = Matrix2::new(0.1, 0.02, 0.02, 0.05);
    let h = Matrix1x2::new(1.0, 0.0);
    let process = LinearProcess::without_input(f, q);
    let sensor = LinearMeasurement {
        observation: h,
        noise: Matrix1::new(0.5),
    };
    let (dyn_process, dyn_sensor) = dyn_linear(&f, &q, &h, 0.5);
    let prior = Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::identity()).unwrap();
    let zs = cv_readings(5, 8);
    let mut fixed = ParticleFilter::new(prior.clone(), 200, 3).unwrap();
    let mut dynamic: ParticleFilter<f64, Dyn> =
        ParticleFilter::new(prior.clone().into_dyn(), 200, 3).unwrap();
    let (mut fixed_record, mut dyn_record) = (Ffbsi::new(), Ffbsi::new());
    for &z in &zs {
        fixed_record
            .predict(&mut fixed, &process, &(), 1.0)
            .unwrap();
        fixed.update(&sensor, &Vector1::new(z)).unwrap();
        dyn_record
            .predict(&mut dynamic, &dyn_process, &(), 1.0)
            .unwrap();
        dynamic
            .update(&dyn_sensor, &DVector::from_element(1, z))
            .unwrap();
    }
    let fixed_paths = fixed_record.smooth(&fixed, &process, 40, 9).unwrap();
    let dyn_paths = dyn_record.smooth(&dynamic, &dyn_process, 40, 9).unwrap();
    let spread = fixed.covariance()[(0, 0)].sqrt();
    for k in 0..fixed_paths.len() {
        for i in 0..2 {
            let d = dyn_paths.mean(k)[i] - fixed_paths.mean(k)[i];
            assert!(d.abs() <= 1e-12 * spread, "k = {k}, i = {i}: {d}");
        }
    }
    // A Q of the wrong shape for the runtime-size state.
    let wrong = LinearProcess::without_input(
        DMatrix::from_column_slice(2, 2, f.as_slice()),
        DMatrix::identity(3, 3),
    );
    assert!(matches!(
        dyn_record.smooth(&dynamic, &wrong, 40, 9),
        Err(Error::DimensionMismatch { .. })
    ));

    let xn = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap();
    let xl = Gaussian::new(Vector1::new(1.0), Matrix1::new(1.0)).unwrap();
    let mut fixed = RaoBlackwellised::new(xn.clone(), xl.clone(), 100, 5).unwrap();
    let mut dynamic: RaoBlackwellised<f64, Dyn, Dyn> =
        RaoBlackwellised::new(xn.into_dyn(), xl.into_dyn(), 100, 5).unwrap();
    for &z in &zs {
        fixed.predict(&SplitCv, &(), 1.0).unwrap();
        fixed.update(&SplitPosition, &Vector1::new(z)).unwrap();
        dynamic.predict(&SplitCvDyn, &(), 1.0).unwrap();
        dynamic
            .update(&SplitPositionDyn, &DVector::from_element(1, z))
            .unwrap();
    }
    let spread = fixed.linear_covariance()[(0, 0)].sqrt();
    assert!((dynamic.linear_mean()[0] - fixed.linear_mean()[0]).abs() <= 1e-12 * spread);
    assert!((dynamic.nonlinear_mean()[0] - fixed.nonlinear_mean()[0]).abs() <= 1e-12 * spread);
    // A reading of the wrong length.
    assert!(matches!(
        dynamic.update(&SplitPositionDyn, &DVector::from_element(2, 0.0)),
        Err(Error::DimensionMismatch { .. })
    ));
}

/// q = p: the model's own transition as a proposal, drawing its normal from the particle's
/// stream as the bootstrap prediction does.
struct Prior;

impl Proposal<f64, U1, U1> for Prior {
    type Input = ();
    fn propose<R: Rng + ?Sized>(
        &self,
        x: &Vector1<f64>,
        _: &(),
        _: f64,
        _: &Vector1<f64>,
        rng: &mut R,
    ) -> (Vector1<f64>, f64) {
        let e: f64 = StandardNormal.sample(rng);
        let log_q = -0.5 * e * e - 0.5 * (2.0 * std::f64::consts::PI * 0.5).ln();
        (Vector1::new(0.9 * x[0] + 0.5f64.sqrt() * e), log_q)
    }
}

/// The bootstrap filter is the guided step with q = p: the same streams give the same
/// particles, log p − log q cancels to round-off, and the weights, moments and likelihood
/// equal the bootstrap predict-and-update's (10⁻¹² relative: a few roundings per step over
/// 6 steps, with adaptive resampling decided from the same weights).
#[test]
fn guided_step_with_the_prior_as_proposal_is_the_bootstrap_filter() {
    let zs = readings(6, 13);
    let (process, sensor, prior) = ar1();
    let mut guided = ParticleFilter::new(prior.clone(), 300, 21).unwrap();
    let mut bootstrap = ParticleFilter::new(prior, 300, 21).unwrap();
    for &z in &zs {
        let z = Vector1::new(z);
        let g = guided
            .guided_step(&process, &Prior, &(), 1.0, &sensor, &z)
            .unwrap();
        bootstrap.predict(&process, &(), 1.0).unwrap();
        let b = bootstrap.update(&sensor, &z).unwrap();
        assert!((g.log_likelihood - b.log_likelihood).abs() <= 1e-12 * b.log_likelihood.abs());
    }
    for (x, y) in guided.particles().iter().zip(bootstrap.particles().iter()) {
        assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()));
    }
    for (x, y) in guided.log_weights().iter().zip(bootstrap.log_weights()) {
        assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()));
    }
    let scale = bootstrap.log_likelihood().abs();
    assert!((guided.log_likelihood() - bootstrap.log_likelihood()).abs() <= 1e-12 * scale);
    assert!((guided.state()[0] - bootstrap.state()[0]).abs() <= 1e-12);
}

/// Counts whose particles or paths cannot be allocated are typed errors (they were a "capacity
/// overflow" panic or an allocation abort), and a zero-dimensional state is an empty cloud, not
/// a panic in the moments.
#[test]
fn unallocatable_counts_are_refused_and_an_empty_state_works() {
    let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap();
    let refused = |count: usize| {
        Some(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: count as f64,
        })
    };
    for count in [usize::MAX, usize::MAX / 4, 1 << 60] {
        assert_eq!(
            ParticleFilter::new(prior.clone(), count, 1).err(),
            refused(count)
        );
        assert_eq!(
            RaoBlackwellised::new(prior.clone(), prior.clone(), count, 1).err(),
            refused(count)
        );
    }
    let zs = readings(3, 3);
    let (process, _, _) = ar1();
    let (ffbsi, pf) = forward(&zs, 20, 8);
    assert_eq!(
        ffbsi.smooth(&pf, &process, usize::MAX / 2, 1).err(),
        refused(usize::MAX / 2)
    );
    let empty = Gaussian::new(DVector::<f64>::zeros(0), DMatrix::zeros(0, 0)).unwrap();
    let mut pf = ParticleFilter::new(empty.clone(), 10, 1).unwrap();
    assert_eq!(pf.state().len(), 0);
    pf.reset(empty);
    assert_eq!(pf.covariance().shape(), (0, 0));
}

/// q = p for a zero-dimensional state: the empty particle, log q = 0.
struct EmptyProposal;

impl Proposal<f64, Dyn, Dyn> for EmptyProposal {
    type Input = ();
    fn propose<R: Rng + ?Sized>(
        &self,
        _: &DVector<f64>,
        _: &(),
        _: f64,
        _: &DVector<f64>,
        _: &mut R,
    ) -> (DVector<f64>, f64) {
        (DVector::zeros(0), 0.0)
    }
}

/// A zero-dimensional state (no landmarks yet): every particle is empty, so every step weighs
/// them equally and the likelihood of z = c + v is exactly log N(z; c, R), through the
/// bootstrap, auxiliary and guided steps, serially and (with enough particles) on a
/// two-thread rayon pool.
/// Before, the weighing loops skipped every particle when the state had no components: the
/// log-weights kept stale values and the likelihood was not the model's.
#[test]
fn a_zero_dimensional_state_weighs_every_particle() {
    let empty = Gaussian::new(DVector::<f64>::zeros(0), DMatrix::zeros(0, 0)).unwrap();
    let process = LinearProcess::without_input(DMatrix::<f64>::zeros(0, 0), DMatrix::zeros(0, 0));
    let (c, r) = (0.5, 2.0);
    let sensor = LinearMeasurement {
        observation: DMatrix::<f64>::zeros(1, 0),
        noise: DMatrix::from_element(1, 1, r),
    }
    .with_offset(DVector::from_element(1, c));
    let exact = |z: f64| -0.5 * ((z - c) * (z - c) / r + (2.0 * std::f64::consts::PI * r).ln());
    let uniform = |pf: &ParticleFilter<f64, Dyn>| {
        let n = pf.count() as f64;
        pf.log_weights()
            .iter()
            .all(|&w| (w + n.ln()).abs() <= 1e-12)
    };
    // On two threads, so that PARALLEL_MIN particles take the rayon path.
    let run = || {
        for count in [10, 1500, estim_filters::particle::PARALLEL_MIN] {
            let mut bootstrap = ParticleFilter::new(empty.clone(), count, 3).unwrap();
            let mut auxiliary = bootstrap.clone();
            let mut guided = bootstrap.clone();
            let mut total = 0.0;
            for z in [0.1, 2.0, -1.5] {
                let zv = DVector::from_element(1, z);
                bootstrap.predict(&process, &(), 1.0).unwrap();
                let b = bootstrap.update(&sensor, &zv).unwrap();
                let a = auxiliary
                    .auxiliary_step(&process, &(), 1.0, &sensor, &zv)
                    .unwrap();
                let g = guided
                    .guided_step(&process, &EmptyProposal, &(), 1.0, &sensor, &zv)
                    .unwrap();
                total += exact(z);
                for (name, report) in [("bootstrap", &b), ("auxiliary", &a), ("guided", &g)] {
                    let error = report.log_likelihood - exact(z);
                    assert!(error.abs() <= 1e-12, "{name}, N = {count}: {error:e}");
                }
                for pf in [&bootstrap, &auxiliary, &guided] {
                    assert!(uniform(pf), "N = {count}: {:?}", &pf.log_weights()[..3]);
                    assert_eq!(pf.particles().shape(), (0, count));
                    assert!((pf.log_likelihood() - total).abs() <= 1e-12 * total.abs());
                }
            }
        }
    };
    #[cfg(feature = "parallel")]
    rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap()
        .install(run);
    #[cfg(not(feature = "parallel"))]
    run();
}
