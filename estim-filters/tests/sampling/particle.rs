//! The particle filter: convergence to the Kalman filter on a linear-Gaussian model, the
//! unbiased likelihood estimate, the resampling schemes' offspring statistics, bad input and
//! bit-exact reproducibility.
//!
//! Every test is seeded, so each runs the same numbers in CI; each statistical bound is a
//! z-test whose false-failure rate (for a fresh seed) is stated beside it.

use estim_core::nalgebra::{Matrix1, U1, Vector1};
use estim_core::{
    Error, Gaussian, LinearMeasurement, LinearProcess, MeasurementModel, Parameter, Quantity, Stage,
};
use estim_filters::particle::{
    MeasurementLikelihood, NonGaussian, ParticleFilter, ParticleRng, ResampleWhen, Resampling,
    resample,
};
use estim_filters::{Estimator, KalmanFilter, Predict, Rollback, Update, UpdateReport};

use crate::particle_common::{
    ar1, assert_late_reading_replays_bit_identically, dyn_linear, mean_and_variance, readings,
};

/// The Kalman filter's means, variances and total log-likelihood over `zs` (predict, then
/// update, each step).
fn kalman(zs: &[f64]) -> (Vec<f64>, Vec<f64>, f64) {
    let (process, sensor, prior) = ar1();
    let mut kf = KalmanFilter::new(prior);
    let (mut means, mut vars, mut ll) = (vec![], vec![], 0.0);
    for &z in zs {
        kf.predict(&process, &(), 1.0).unwrap();
        ll += kf.update(&sensor, &Vector1::new(z)).unwrap().log_likelihood;
        means.push(kf.state()[0]);
        vars.push(kf.covariance()[(0, 0)]);
    }
    (means, vars, ll)
}

/// Runs a particle filter over `zs`; the means, variances and its log-likelihood estimate.
fn particle(zs: &[f64], pf: &mut ParticleFilter<f64, U1>) -> (Vec<f64>, Vec<f64>, f64) {
    let (process, sensor, _) = ar1();
    let (mut means, mut vars) = (vec![], vec![]);
    for &z in zs {
        pf.predict(&process, &(), 1.0).unwrap();
        pf.update(&sensor, &Vector1::new(z)).unwrap();
        means.push(pf.state()[0]);
        vars.push(pf.covariance()[(0, 0)]);
    }
    (means, vars, pf.log_likelihood())
}

/// The particle means and variances converge to the Kalman filter's like N^-1/2.
///
/// For each N in {250, 1000}, K = 40 filters (seeds 0..40) run over the same 10 readings; the
/// errors eₖ = (particle − Kalman) at the last step are independent across seeds with mean
/// O(1/N) (the bias of a ratio estimator) and standard deviation σ_N = c/√N (the Monte Carlo
/// CLT for SMC, Chopin 2004). Two checks per moment:
/// - unbiasedness: |ē| ≤ 4 s/√K (a t-test with 39 degrees of freedom: false-failure rate
///   ≈ 3·10⁻⁴ per check; the O(1/N) bias is ≪ s/√K = O(1/√(NK)) at these sizes);
/// - the rate: the RMS error ratio ρ = rms(1000)/rms(250) estimates 1/2. The RMS of K = 40
///   normal errors has relative standard error 1/√(2K) = 0.11, so ρ has ≈ 0.16 relative
///   standard error; 3σ gives ρ ∈ [0.26, 0.74] (two-sided false-failure rate ≈ 0.3 %). A
///   filter that did not converge (ρ ≈ 1) or converged wrongly fails it.
#[test]
fn moments_converge_to_the_kalman_filter_like_one_over_root_n() {
    let zs = readings(10, 11);
    let (kf_means, kf_vars, _) = kalman(&zs);
    let last = zs.len() - 1;
    let runs = 40;
    let mut rms = [[0.0; 2]; 2]; // [N index][mean, variance]
    for (k, &count) in [250usize, 1000].iter().enumerate() {
        let mut errors = [vec![], vec![]];
        for seed in 0..runs {
            let (_, _, prior) = ar1();
            let mut pf = ParticleFilter::new(prior, count, seed).unwrap();
            let (means, vars, _) = particle(&zs, &mut pf);
            errors[0].push(means[last] - kf_means[last]);
            errors[1].push(vars[last] - kf_vars[last]);
        }
        for (moment, e) in errors.iter().enumerate() {
            let (mean, var) = mean_and_variance(e);
            let se = (var / runs as f64).sqrt();
            assert!(
                mean.abs() <= 4.0 * se,
                "N = {count}, moment {moment}: bias {mean} vs standard error {se}"
            );
            rms[k][moment] = (e.iter().map(|x| x * x).sum::<f64>() / runs as f64).sqrt();
        }
    }
    for moment in 0..2 {
        let ratio = rms[1][moment] / rms[0][moment];
        assert!(
            (0.26..=0.74).contains(&ratio),
            "moment {moment}: rms {:?}, ratio {ratio} (expected 0.5)",
            rms.map(|r| r[moment])
        );
    }
    // Scale sanity: at N = 1000 the mean's error is a small fraction of the posterior spread.
    assert!(rms[1][0] < 0.1 * kf_vars[last].sqrt(), "rms {}", rms[1][0]);
}

/// E[exp(ℓ̂ − ℓ)] = 1: the particle likelihood estimate is unbiased (Del Moral 2004), with
/// resampling every step and adaptive (ESS < N/2), and Var ℓ̂ falls like 1/N.
///
/// K = 300 seeded runs of N = 40 particles over 10 readings; ℓ from the Kalman filter. The
/// sample mean of rᵢ = exp(ℓ̂ᵢ − ℓ) is within 4 standard errors s/√K of 1 (the CLT on K = 300
/// draws whose spread, Var ℓ̂ ≈ 0.2 here, makes r close to log-normal with small skew:
/// false-failure rate below 10⁻³). For the variance: Var ℓ̂ at N = 40 and N = 160 (the same
/// K) have ratio 4 asymptotically; each sample variance of K = 300 near-normal draws has
/// relative standard error √(2/299) = 0.08, the ratio ≈ 0.12, so [2.4, 6.7] is beyond 4σ on
/// the log scale (false-failure rate ≈ 10⁻⁴).
///
/// The z-test on exp(ℓ̂ − ℓ) uses the sample standard error, which a heavy right tail
/// inflates (a likelihood increment computed without the previous weights, the bug this test
/// is for, gave a mean of 10¹⁰² ± 10¹⁰² and passed it). So also the log-normal form of the same
/// statement (Bérard, Del Moral & Doucet 2014: ℓ̂ − ℓ ≈ N(−σ²/2, σ²), which is E exp = 1):
/// |mean(ℓ̂ − ℓ) + s²/2| ≤ 4 standard errors √(s²/K + s⁴/(2(K − 1))) (false-failure rate
/// ≈ 6·10⁻⁵ for normal ℓ̂; that bug failed it by 14 standard errors).
#[test]
fn likelihood_estimate_is_unbiased_with_and_without_adaptive_resampling() {
    let zs = readings(10, 5);
    let (_, _, exact) = kalman(&zs);
    let runs = 300u64;
    for when in [ResampleWhen::Always, ResampleWhen::EssBelow(0.5)] {
        let mut log_liks = [vec![], vec![]];
        for (k, count) in [40usize, 160].into_iter().enumerate() {
            for seed in 0..runs {
                let (_, _, prior) = ar1();
                let mut pf = ParticleFilter::new(prior, count, 1000 + seed)
                    .unwrap()
                    .with_trigger(when)
                    .unwrap();
                log_liks[k].push(particle(&zs, &mut pf).2);
            }
        }
        let ratios: Vec<f64> = log_liks[0].iter().map(|l| (l - exact).exp()).collect();
        let (mean, var) = mean_and_variance(&ratios);
        let se = (var / runs as f64).sqrt();
        let errors: Vec<f64> = log_liks[0].iter().map(|l| l - exact).collect();
        let (log_mean, log_var) = mean_and_variance(&errors);
        let log_se =
            (log_var / runs as f64 + log_var * log_var / (2.0 * (runs as f64 - 1.0))).sqrt();
        assert!(
            (log_mean + log_var / 2.0).abs() <= 4.0 * log_se,
            "{when:?}: mean(ℓ̂ − ℓ) = {log_mean}, Var ℓ̂ = {log_var}, standard error {log_se}"
        );
        assert!(
            (mean - 1.0).abs() <= 4.0 * se,
            "{when:?}: mean exp(ℓ̂ − ℓ) = {mean}, standard error {se}"
        );
        let variance_ratio = mean_and_variance(&log_liks[0]).1 / mean_and_variance(&log_liks[1]).1;
        assert!(
            (2.4..=6.7).contains(&variance_ratio),
            "{when:?}: Var ℓ̂(40) / Var ℓ̂(160) = {variance_ratio}"
        );
    }
}

/// Offspring counts Oᵢ have E[Oᵢ] = M Wᵢ for every scheme, multinomial's variance is
/// M Wᵢ (1 − Wᵢ), and the other schemes' total variance is at most multinomial's.
///
/// R = 4000 resamplings of M = 8 from fixed weights (stream r per repetition). Means: a
/// z-test per weight and scheme with the sample variance, |z| ≤ 4 (32 tests, Bonferroni
/// false-failure rate ≤ 32 · 6.3·10⁻⁵ = 0.2 %); a count with zero sample variance must equal
/// M Wᵢ exactly. Multinomial variance: s² has variance σ⁴ (2/(R − 1) + κ/R) with κ the
/// binomial excess kurtosis (1 − 6p(1 − p))/(M p (1 − p)); |s²/σ² − 1| ≤ 4 of those standard
/// errors (8 tests). Ordering: Σᵢ s²ᵢ for residual, stratified and systematic is at most
/// multinomial's theoretical total Σ M Wᵢ(1 − Wᵢ) plus 4 of the multinomial's standard errors
/// for that sum (√(2/R) relative: a bound that a multinomial-like scheme would fail only by
/// chance; these schemes are far below it).
#[test]
fn offspring_counts_have_the_right_mean_and_variance_ordering() {
    let weights = [0.05, 0.3, 0.0, 0.15, 0.125, 0.2, 0.1, 0.075];
    let m = 8usize;
    let reps = 4000u64;
    let multinomial_var: Vec<f64> = weights.iter().map(|w| m as f64 * w * (1.0 - w)).collect();
    let multinomial_total: f64 = multinomial_var.iter().sum();
    for scheme in [
        Resampling::Multinomial,
        Resampling::Stratified,
        Resampling::Systematic,
        Resampling::Residual,
    ] {
        let mut counts = vec![vec![0.0; reps as usize]; weights.len()];
        let mut ancestors = vec![0; m];
        for r in 0..reps {
            resample(
                scheme,
                &weights,
                &mut ParticleRng::stream(3, r, 0),
                &mut ancestors,
            )
            .unwrap();
            for &a in &ancestors {
                counts[a][r as usize] += 1.0;
            }
        }
        let mut total_var = 0.0;
        for (i, w) in weights.iter().enumerate() {
            let expected = m as f64 * w;
            let (mean, var) = mean_and_variance(&counts[i]);
            total_var += var;
            if var == 0.0 {
                assert_eq!(mean, expected, "{scheme:?} weight {i}");
            } else {
                let z = (mean - expected) / (var / reps as f64).sqrt();
                assert!(
                    z.abs() <= 4.0,
                    "{scheme:?} weight {i}: mean {mean}, expected {expected}, z {z}"
                );
            }
            if scheme == Resampling::Multinomial && *w > 0.0 {
                let p = *w;
                let kurtosis = (1.0 - 6.0 * p * (1.0 - p)) / (m as f64 * p * (1.0 - p));
                let se = (2.0 / (reps as f64 - 1.0) + kurtosis / reps as f64).sqrt();
                let rel = var / multinomial_var[i] - 1.0;
                assert!(
                    rel.abs() <= 4.0 * se,
                    "multinomial weight {i}: s²/σ² − 1 = {rel}, se {se}"
                );
            }
        }
        if scheme != Resampling::Multinomial {
            let bound = multinomial_total * (1.0 + 4.0 * (2.0 / reps as f64).sqrt());
            assert!(
                total_var <= bound,
                "{scheme:?}: total variance {total_var} > {bound}"
            );
        }
    }
}

/// `resample` on bad weights: typed errors with the ancestors untouched, never a panic;
/// unnormalised weights are normalised (weights × 4, exact in binary, draw the same ancestors
/// bit for bit for every scheme).
#[test]
fn resample_normalises_weights_and_refuses_bad_ones() {
    let weights = [0.05, 0.3, 0.0, 0.15, 0.125, 0.2, 0.1, 0.075];
    let scaled = weights.map(|w| 4.0 * w);
    for scheme in [
        Resampling::Multinomial,
        Resampling::Stratified,
        Resampling::Systematic,
        Resampling::Residual,
    ] {
        let (mut a, mut b) = ([0; 8], [0; 8]);
        resample(scheme, &weights, &mut ParticleRng::stream(5, 1, 0), &mut a).unwrap();
        resample(scheme, &scaled, &mut ParticleRng::stream(5, 1, 0), &mut b).unwrap();
        assert_eq!(a, b, "{scheme:?}");
        let bad_weights: [(&[f64], Error); 6] = [
            (
                &[],
                Error::InvalidParameter {
                    parameter: Parameter::SampleCount,
                    value: 0.0,
                },
            ),
            (
                &[0.5, -0.25, 0.75],
                Error::InvalidParameter {
                    parameter: Parameter::Weight,
                    value: -0.25,
                },
            ),
            (&[0.0, 0.0], degenerate()),
            (&[f64::NAN, 1.0], degenerate()),
            (&[f64::INFINITY, 1.0], degenerate()),
            (&[f64::MAX, f64::MAX], degenerate()),
        ];
        for (bad, error) in bad_weights {
            let mut ancestors = [7; 8];
            let mut rng = ParticleRng::stream(5, 1, 0);
            assert_eq!(
                resample(scheme, bad, &mut rng, &mut ancestors),
                Err(error),
                "{scheme:?} {bad:?}"
            );
            assert_eq!(ancestors, [7; 8]);
        }
        // −0.0 has its sign bit set but is a valid weight (zero).
        let mut c = [0; 8];
        let signed_zero = weights.map(|w| if w == 0.0 { -0.0 } else { w });
        resample(
            scheme,
            &signed_zero,
            &mut ParticleRng::stream(5, 1, 0),
            &mut c,
        )
        .unwrap();
        assert_eq!(a, c, "{scheme:?}");
        // Nothing to draw: nothing checked.
        assert!(resample(scheme, &[], &mut ParticleRng::stream(5, 1, 0), &mut []).is_ok());
    }
}

/// The error of a weight set with no mass (NaN, infinite, overflowing or all zero).
fn degenerate() -> Error {
    Error::NonFinite {
        stage: Stage::Prediction,
        quantity: Quantity::Weights,
    }
}

/// A bounded sensor: z = x + v, v uniform on [−a, a].
struct Bounded {
    a: f64,
    nan: bool,
}

impl MeasurementModel<f64, U1, U1> for Bounded {
    fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> {
        *x
    }
    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(self.a * self.a / 3.0)
    }
}

impl MeasurementLikelihood<f64, U1, U1> for Bounded {
    fn log_likelihood(&self, z: &Vector1<f64>, x: &Vector1<f64>) -> f64 {
        if self.nan {
            f64::NAN
        } else if (z[0] - x[0]).abs() <= self.a {
            -(2.0 * self.a).ln()
        } else {
            f64::NEG_INFINITY
        }
    }
}

/// Zero particles, an invalid trigger, NaN data, a NaN likelihood, a measurement no particle
/// explains, bad Q and R, a negative Δt: typed errors, and the filter bit-identical after.
#[test]
fn bad_input_gives_typed_errors_and_leaves_the_filter_unchanged() {
    let (process, sensor, prior) = ar1();
    assert!(matches!(
        ParticleFilter::new(prior.clone(), 0, 1),
        Err(Error::InvalidParameter { .. })
    ));
    let pf = ParticleFilter::new(prior.clone(), 200, 1).unwrap();
    assert!(
        pf.clone()
            .with_trigger(ResampleWhen::EssBelow(0.0))
            .is_err()
    );
    assert!(
        pf.clone()
            .with_trigger(ResampleWhen::EssBelow(f64::NAN))
            .is_err()
    );
    let mut pf = pf.with_trigger(ResampleWhen::Never).unwrap();
    pf.predict(&process, &(), 1.0).unwrap();
    pf.update(&sensor, &Vector1::new(0.3)).unwrap();
    let before = pf.clone();
    let weights = |e: &Result<_, Error>| {
        matches!(
            e,
            Err(Error::NonFinite {
                quantity: Quantity::Weights,
                ..
            })
        )
    };

    let e = pf.update(&sensor, &Vector1::new(f64::NAN));
    assert!(
        matches!(
            e,
            Err(Error::NonFinite {
                quantity: Quantity::Measurement,
                ..
            })
        ),
        "{e:?}"
    );
    assert_eq!(pf, before);

    let e = pf.update_with(
        &NonGaussian(Bounded { a: 0.1, nan: false }),
        &Vector1::new(1e3),
    );
    assert!(weights(&e), "{e:?}");
    assert_eq!(pf, before);

    // A NaN log-density is a bug in the model, not a measurement no particle explains.
    let e = pf.update_with(
        &NonGaussian(Bounded { a: 0.1, nan: true }),
        &Vector1::new(0.0),
    );
    assert_eq!(
        e.err(),
        Some(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::FunctionValue
        })
    );
    assert_eq!(pf, before);
    let nan_h = LinearMeasurement {
        observation: Matrix1::new(f64::NAN),
        noise: Matrix1::new(1.0),
    };
    let e = pf.update(&nan_h, &Vector1::new(0.0));
    assert_eq!(
        e.err(),
        Some(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::FunctionValue
        })
    );
    assert_eq!(pf, before);
    // A Gaussian reading 10³⁰⁰ away: every log-weight −∞ (r² overflows), no NaN.
    let e = pf.update(&sensor, &Vector1::new(1e300));
    assert!(weights(&e), "{e:?}");
    assert_eq!(pf, before);

    let bad_r = LinearMeasurement {
        observation: Matrix1::new(1.0),
        noise: Matrix1::new(0.0),
    };
    let e = pf.update(&bad_r, &Vector1::new(0.0));
    assert!(
        matches!(
            e,
            Err(Error::NotPositiveDefinite {
                quantity: Quantity::MeasurementNoise,
                ..
            })
        ),
        "{e:?}"
    );
    assert_eq!(pf, before);

    let bad_q = LinearProcess::without_input(Matrix1::new(0.9), Matrix1::new(-1.0));
    let e = pf.predict(&bad_q, &(), 1.0);
    assert!(
        matches!(
            e,
            Err(Error::NotPositiveSemiDefinite {
                quantity: Quantity::ProcessNoise,
                ..
            })
        ),
        "{e:?}"
    );
    assert_eq!(pf, before);

    let nan_f = LinearProcess::without_input(Matrix1::new(f64::NAN), Matrix1::new(1.0));
    assert!(pf.predict(&nan_f, &(), 1.0).is_err());
    assert_eq!(pf, before);
    assert!(pf.predict(&process, &(), -1.0).is_err());
    assert_eq!(pf, before);

    // And the filter still works: a singular Q (zero) is allowed.
    let still = LinearProcess::without_input(Matrix1::new(1.0), Matrix1::new(0.0));
    pf.predict(&still, &(), 1.0).unwrap();
    assert_eq!(pf.particles(), before.particles());
}

/// The same seed gives the same bits; a snapshot restored (into the same or a cloned filter)
/// continues bit-identically; `reset` replays the constructor.
#[test]
fn snapshots_and_seeds_reproduce_bit_for_bit() {
    let (process, sensor, prior) = ar1();
    let zs = readings(12, 2);
    let run = |pf: &mut ParticleFilter<f64, _>, zs: &[f64]| {
        for &z in zs {
            pf.predict(&process, &(), 1.0).unwrap();
            pf.update(&sensor, &Vector1::new(z)).unwrap();
        }
    };
    for scheme in [
        Resampling::Multinomial,
        Resampling::Residual,
        Resampling::Stratified,
    ] {
        let mut a = ParticleFilter::new(prior.clone(), 300, 9)
            .unwrap()
            .with_resampling(scheme);
        let mut b = a.clone();
        run(&mut a, &zs[..6]);
        run(&mut b, &zs[..6]);
        assert_eq!(a, b);
        let snapshot = a.snapshot();
        let mut c = a.clone();
        run(&mut a, &zs[6..]);
        run(&mut c, &zs[6..]);
        assert_eq!(a, c);
        let end = a.clone();
        a.restore(&snapshot);
        run(&mut a, &zs[6..]);
        assert_eq!(a, end);
        assert_eq!(a.log_likelihood().to_bits(), end.log_likelihood().to_bits());
        let mut into = b.snapshot();
        a.snapshot_into(&mut into);
        b.restore(&into);
        assert_eq!(a, b);
    }
    let mut a = ParticleFilter::new(prior.clone(), 300, 9).unwrap();
    let fresh = a.clone();
    run(&mut a, &zs);
    a.reset(prior.clone());
    assert_eq!(a, fresh);
    let other = ParticleFilter::new(prior, 300, 10).unwrap();
    assert_ne!(other.particles(), fresh.particles());
}

/// The auxiliary filter on the linear-Gaussian model: unbiased likelihood and means that
/// converge to the Kalman filter's.
///
/// Likelihood: K = 300 runs of N = 40, the same 4-standard-error z-test as the bootstrap
/// filter's (false-failure rate below 10⁻³). Means: K = 40 runs of N = 1000; |bias| ≤ 4 s/√K
/// (t-test, false-failure rate ≈ 3·10⁻⁴), and the RMS error below a tenth of the posterior
/// standard deviation σ: after its resampling the cloud holds N equally weighted particles,
/// so the Monte Carlo error of one step is ≈ σ/√N = σ/32, accumulating over the 10 steps to a
/// few times that; a filter converging to the wrong posterior is off by a fraction of σ.
///
/// Not with a sharp sensor: the look-ahead density N(z; h(μᵢ), R) is narrower than the true
/// predictive N(z; h(μᵢ), R + H Q Hᵀ), so g/η is heavy-tailed and the likelihood estimate,
/// though unbiased, has a huge variance (R = 0.1 here gave a sample mean of 0.19 ± 0.05 over
/// 300 runs: the rare large values that make the mean 1 were not drawn).
#[test]
fn auxiliary_filter_is_unbiased_and_converges() {
    let (process, sharp, prior) = ar1();
    let zs = readings(10, 8);
    let mut kf = KalmanFilter::new(prior.clone());
    let mut exact = 0.0;
    for &z in &zs {
        kf.predict(&process, &(), 1.0).unwrap();
        exact += kf.update(&sharp, &Vector1::new(z)).unwrap().log_likelihood;
    }
    let run = |count: usize, seed: u64| {
        let mut apf = ParticleFilter::new(prior.clone(), count, seed).unwrap();
        let mut reported = 0.0;
        for &z in &zs {
            reported += apf
                .auxiliary_step(&process, &(), 1.0, &sharp, &Vector1::new(z))
                .unwrap()
                .log_likelihood;
        }
        assert_eq!(reported, apf.log_likelihood());
        apf
    };
    let ratios: Vec<f64> = (0..300)
        .map(|s| (run(40, 500 + s).log_likelihood() - exact).exp())
        .collect();
    let (mean, var) = mean_and_variance(&ratios);
    let se = (var / 300.0).sqrt();
    assert!(
        (mean - 1.0).abs() <= 4.0 * se,
        "mean exp(ℓ̂ − ℓ) = {mean}, standard error {se}"
    );

    let errors: Vec<f64> = (0..40)
        .map(|s| run(1000, s).state()[0] - kf.state()[0])
        .collect();
    let (bias, var) = mean_and_variance(&errors);
    assert!(
        bias.abs() <= 4.0 * (var / 40.0).sqrt(),
        "bias {bias}, sd {}",
        var.sqrt()
    );
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / 40.0).sqrt();
    assert!(rms < 0.1 * kf.covariance()[(0, 0)].sqrt(), "rms {rms}");
}

/// The auxiliary step's failures leave the filter bit-identical, and a snapshot replays it.
#[test]
fn auxiliary_step_is_atomic_and_reproducible() {
    let (process, sensor, prior) = ar1();
    let mut apf = ParticleFilter::new(prior, 200, 4).unwrap();
    apf.auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(0.2))
        .unwrap();
    let before = apf.clone();
    assert!(
        apf.auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(f64::NAN))
            .is_err()
    );
    assert_eq!(apf, before);
    let mut report = estim_filters::UpdateReport::zeros(U1);
    let e = apf.auxiliary_step_with(
        &estim_filters::particle::AdditiveGaussian(&process),
        &(),
        1.0,
        &NonGaussian(Bounded { a: 0.1, nan: false }),
        &Vector1::new(1e3),
        &mut report,
    );
    assert!(
        matches!(
            e,
            Err(Error::NonFinite {
                quantity: Quantity::Weights,
                ..
            })
        ),
        "{e:?}"
    );
    assert_eq!(apf, before);
    let snapshot = apf.snapshot();
    apf.auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(-0.4))
        .unwrap();
    let after = apf.clone();
    apf.restore(&snapshot);
    apf.auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(-0.4))
        .unwrap();
    assert_eq!(apf, after);
}

/// Through the estimator contract: the batch function runs a particle filter bit-identically
/// to a hand loop, and a failing step restores the whole cloud (not just a Gaussian).
#[test]
fn filter_sequence_runs_a_particle_filter_and_restores_the_cloud() {
    let (process, sensor, prior) = ar1();
    let zs = readings(6, 21);
    let mut measurements: Vec<Option<Vector1<f64>>> = vec![None];
    measurements.extend(zs.iter().map(|&z| Some(Vector1::new(z))));
    let inputs = vec![(); zs.len()];
    let start = ParticleFilter::new(prior, 300, 17).unwrap();
    let mut batch = start.clone();
    let run =
        estim_filters::filter_sequence(&mut batch, &process, &inputs, 1.0, &sensor, &measurements)
            .unwrap();
    let mut hand = start.clone();
    particle(&zs, &mut hand);
    assert_eq!(batch, hand);
    assert_eq!(
        run.log_likelihood.to_bits(),
        hand.log_likelihood().to_bits()
    );
    assert_eq!(run.estimates.last().unwrap().mean(), hand.state());

    measurements[4] = Some(Vector1::new(f64::NAN));
    let mut failing = start.clone();
    assert!(
        estim_filters::filter_sequence(
            &mut failing,
            &process,
            &inputs,
            1.0,
            &sensor,
            &measurements
        )
        .is_err()
    );
    assert_eq!(failing, start);
}

/// A particle filter through the Monte Carlo runner: 5 runs × 10 steps of the AR(1) model with
/// N = 200 particles, each run's truth, readings and filter seeded by the run's seed. The
/// runner's statistics at every step (mean error, error variance, mean filter variance, mean
/// NEES, mean NIS and log-likelihood) equal those computed here from the same seeded runs,
/// and the sharded and sequential runs equal `run` bit for bit.
///
/// Tolerance 1e-12 relative: the same five numbers per statistic, summed here in run order and
/// by the runner in its own order and formula (a running mean), agree to a few ulps; a wrong
/// slot, run or seed changes them at the 1e-2 level.
#[test]
fn particle_filter_runs_through_the_monte_carlo_runner() {
    use estim_filters::Recorder;
    use estim_filters::monte_carlo::MonteCarlo;

    let (process, sensor, prior) = ar1();
    let (runs, steps, count) = (5, 10, 200);
    // One run: the truth x, the filter's x̂ and P, and its update report, per step.
    type Step = (f64, f64, f64, UpdateReport<f64, U1>);
    let run = |seed: u64| -> Result<Vec<Step>, Error> {
        let mut g = crate::common::rng(seed);
        let mut x = crate::common::normal(&mut g);
        let mut pf = ParticleFilter::new(prior.clone(), count, seed)?;
        (0..steps)
            .map(|_| {
                x = 0.9 * x + 0.5f64.sqrt() * crate::common::normal(&mut g);
                let z = x + crate::common::normal(&mut g);
                pf.predict(&process, &(), 1.0)?;
                let report = pf.update(&sensor, &Vector1::new(z))?;
                Ok((x, pf.state()[0], pf.covariance()[(0, 0)], report))
            })
            .collect()
    };
    let realization = |_: usize, seed: u64, rec: &mut Recorder| {
        for (k, (x, mean, var, report)) in run(seed)?.iter().enumerate() {
            let p = Matrix1::new(*var);
            rec.record_estimate(k, &Vector1::new(*x), &Vector1::new(*mean), &p)?;
            rec.record_innovation(k, report)?;
        }
        Ok(())
    };
    let mc = MonteCarlo::new(runs, steps).unwrap().with_seed(31);
    let stats = mc.run(realization).unwrap();

    // By hand, from the same seeds.
    let mut values = vec![vec![]; steps];
    for r in 0..runs {
        for (k, (x, mean, var, report)) in run(mc.run_seed(r)).unwrap().into_iter().enumerate() {
            values[k].push([x, mean, var, report.nis, report.log_likelihood]);
        }
    }
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1e-300);
    let rf = runs as f64;
    for (k, slot) in stats.slots.iter().enumerate() {
        let v = &values[k];
        let errors: Vec<f64> = v.iter().map(|[x, mean, ..]| x - mean).collect();
        let mean_error = errors.iter().sum::<f64>() / rf;
        let error_var = errors.iter().map(|e| (e - mean_error).powi(2)).sum::<f64>() / (rf - 1.0);
        let mean_var = v.iter().map(|s| s[2]).sum::<f64>() / rf;
        let nees = v.iter().map(|s| (s[0] - s[1]).powi(2) / s[2]).sum::<f64>() / rf;
        let nis = v.iter().map(|s| s[3]).sum::<f64>() / rf;
        let ll = v.iter().map(|s| s[4]).sum::<f64>() / rf;
        let e = slot.estimate.as_ref().unwrap();
        let i = slot.innovation.as_ref().unwrap();
        assert_eq!((e.samples, i.samples), (runs, runs));
        for (name, got, want) in [
            ("mean error", e.mean_error[0], mean_error),
            ("error variance", e.error_covariance[(0, 0)], error_var),
            ("mean variance", e.mean_covariance[(0, 0)], mean_var),
            ("mean NEES", e.mean_nees, nees),
            ("mean NIS", i.mean_nis, nis),
            ("mean log-likelihood", i.mean_log_likelihood, ll),
        ] {
            assert!(
                close(got, want),
                "step {k} {name}: runner {got}, by hand {want}"
            );
        }
    }
    let shards = (0..2)
        .map(|s| mc.run_shard(s, 2, realization))
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    assert_eq!(mc.merge_shards(shards).unwrap(), stats);
    assert_eq!(mc.run_sequential(realization).unwrap(), stats);
}

/// A checkpoint resumes bit-identically (serde_json with `float_roundtrip`), and a corrupt one
/// is an error, not a panic: unnormalised weights, a weight count that disagrees with the
/// particles, zero particles, a non-number particle, an invalid trigger, stored weights that
/// disagree with the log-weights, a state of the wrong dimension.
#[cfg(feature = "serde")]
#[test]
fn checkpoints_resume_bit_identically_and_reject_corrupt_input() {
    use estim_core::nalgebra::Dyn;
    let (process, sensor, prior) = ar1();
    let zs = readings(8, 4);
    let mut pf = ParticleFilter::new(prior.clone(), 64, 2)
        .unwrap()
        .with_resampling(Resampling::Residual);
    particle(&zs[..4], &mut pf);
    let saved = serde_json::to_value(&pf).unwrap();
    let mut resumed: ParticleFilter<f64, U1> = serde_json::from_value(saved.clone()).unwrap();
    assert_eq!(resumed, pf);
    particle(&zs[4..], &mut pf);
    particle(&zs[4..], &mut resumed);
    assert_eq!(resumed, pf);
    let _ = (process, sensor);

    let corrupt = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v = saved.clone();
        edit(&mut v);
        serde_json::from_value::<ParticleFilter<f64, U1>>(v).is_err()
    };
    assert!(corrupt(&|v| v["log_weights"][3] = serde_json::json!(0.5)));
    assert!(corrupt(&|v| {
        let w = v["log_weights"].as_array_mut().unwrap();
        w.pop();
    }));
    assert!(corrupt(&|v| v["log_weights"] = serde_json::json!([])));
    assert!(corrupt(&|v| v["particles"][0][5] = serde_json::json!(null)));
    assert!(corrupt(
        &|v| v["trigger"] = serde_json::json!({ "EssBelow": 2.0 })
    ));
    // The stored weights must agree with the log-weights (to √ε relative).
    assert!(corrupt(&|v| v["weights"][3] = serde_json::json!(0.5)));
    assert!(corrupt(&|v| v["weights"][3] = serde_json::json!(-0.0625)));
    assert!(corrupt(&|v| {
        v["weights"].as_array_mut().unwrap().pop();
    }));
    // A checkpoint written before the weights were stored reads with Wᵢ = exp(log Wᵢ): the
    // same log-weights, and an ESS equal to the stored weights' to round-off (each weight
    // within a few ulps times |log Wᵢ| ≤ 20 here; 1e-12 relative leaves margin).
    let at_save: ParticleFilter<f64, U1> = serde_json::from_value(saved.clone()).unwrap();
    let mut old = saved.clone();
    old.as_object_mut().unwrap().remove("weights");
    let old: ParticleFilter<f64, U1> = serde_json::from_value(old).unwrap();
    assert_eq!(old.log_weights(), at_save.log_weights());
    let (a, b) = (old.effective_sample_size(), at_save.effective_sample_size());
    assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
    // The wrong state dimension for a dynamic-size filter: a shape error, not a panic.
    let dynamic: ParticleFilter<f64, Dyn> = ParticleFilter::new(prior.into_dyn(), 8, 1).unwrap();
    let mut v = serde_json::to_value(&dynamic).unwrap();
    v["state"] = serde_json::json!([[0.0, 1.0], 2, null]);
    let e = serde_json::from_value::<ParticleFilter<f64, Dyn>>(v).unwrap_err();
    assert!(e.to_string().contains("shape"), "{e}");
    // A cloud claiming 2⁶³ − 1 particles: nalgebra would multiply rows × columns unchecked
    // (issue 41, defect 5); read through `ShapeChecked`, it is an error, not a panic.
    let mut v = serde_json::to_value(&dynamic).unwrap();
    v["particles"][2] = serde_json::json!(i64::MAX);
    let e = serde_json::from_value::<ParticleFilter<f64, Dyn>>(v).unwrap_err();
    assert!(e.to_string().contains("entries"), "{e}");
}

/// The fusion driver rolls a particle filter back for a late reading (the cloud, its weights
/// and its random counter, not a Gaussian), so fusing out of order gives the same bits as
/// fusing in time order.
#[test]
fn fusion_driver_replays_a_late_reading_bit_identically() {
    let (process, sensor, prior) = ar1();
    let pf = ParticleFilter::new(prior, 200, 6).unwrap();
    assert_late_reading_replays_bit_identically(pf, process, sensor);
}

/// Runtime sizes and f32: a 2-state filter with `Dyn` dimensions follows the static one (the
/// same streams, the same operations: equal to round-off), and an f32 filter the f64 one (the
/// normals are drawn in f64 and rounded, so the clouds differ only by f32 rounding: within
/// 10⁻⁴ for states of order 1, ~10³ f32 ulps, room for the sums over 300 weights; a resampling
/// decision could flip on a near-tie of cumulative weights, which these seeds do not hit).
#[test]
fn runtime_sizes_and_f32_follow_the_static_f64_filter() {
    use estim_core::nalgebra::{DVector, Dyn, Matrix1x2, Matrix2, U2, Vector2};
    let f = Matrix2::new(1.0, 0.1, 0.0, 1.0);
    let q = Matrix2::new(1e-3, 0.0, 0.0, 1e-2);
    let h = Matrix1x2::new(1.0, 0.0);
    let process = LinearProcess::without_input(f, q);
    let sensor = LinearMeasurement {
        observation: h,
        noise: Matrix1::new(0.1),
    };
    let prior = Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::identity()).unwrap();
    let zs = [0.12, 0.18, 0.33];
    let mut fixed = ParticleFilter::new(prior.clone(), 300, 12).unwrap();
    let (dyn_process, dyn_sensor) = dyn_linear(&f, &q, &h, 0.1);
    let mut dynamic: ParticleFilter<f64, Dyn> =
        ParticleFilter::new(prior.clone().into_dyn(), 300, 12).unwrap();
    let process32 = LinearProcess::without_input(f.cast::<f32>(), q.cast::<f32>());
    let sensor32 = LinearMeasurement {
        observation: h.cast::<f32>(),
        noise: Matrix1::new(0.1f32),
    };
    let prior32 = Gaussian::new(Vector2::new(0.0f32, 1.0), Matrix2::identity()).unwrap();
    let mut single: ParticleFilter<f32, U2> = ParticleFilter::new(prior32, 300, 12).unwrap();
    for &z in &zs {
        fixed.predict(&process, &(), 1.0).unwrap();
        fixed.update(&sensor, &Vector1::new(z)).unwrap();
        dynamic.predict(&dyn_process, &(), 1.0).unwrap();
        dynamic
            .update(&dyn_sensor, &DVector::from_element(1, z))
            .unwrap();
        single.predict(&process32, &(), 1.0).unwrap();
        single.update(&sensor32, &Vector1::new(z as f32)).unwrap();
    }
    let spread = fixed.covariance()[(0, 0)].sqrt();
    for i in 0..2 {
        assert!((dynamic.state()[i] - fixed.state()[i]).abs() <= 1e-12 * spread);
        assert!((single.state()[i] as f64 - fixed.state()[i]).abs() <= 1e-4);
    }
    assert_eq!(dynamic.particles().shape(), (2, 300));
}

/// z = x + v with Laplace noise of scale b: log p(z | x) = −|z − x|/b − log 2b.
struct Laplace {
    b: f64,
}

impl MeasurementModel<f64, U1, U1> for Laplace {
    fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> {
        *x
    }
    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(2.0 * self.b * self.b)
    }
}

impl MeasurementLikelihood<f64, U1, U1> for Laplace {
    fn log_likelihood(&self, z: &Vector1<f64>, x: &Vector1<f64>) -> f64 {
        -(z[0] - x[0]).abs() / self.b - (2.0 * self.b).ln()
    }
}

/// A random walk with Student-t (ν = 3) steps of scale 0.3.
struct HeavyWalk;

impl estim_core::ProcessModel<f64, U1> for HeavyWalk {
    type Input = ();
    fn transition(&self, x: &Vector1<f64>, _: &(), _: f64) -> Vector1<f64> {
        *x
    }
    fn process_noise(&self, _: &Vector1<f64>, _: &(), _: f64) -> Matrix1<f64> {
        Matrix1::new(3.0 * 0.09)
    }
}

impl estim_filters::particle::ProcessSampler<f64, U1> for HeavyWalk {
    fn sample_transition<R: rand::Rng + ?Sized>(
        &self,
        x: &Vector1<f64>,
        _: &(),
        _: f64,
        rng: &mut R,
    ) -> Vector1<f64> {
        use rand_distr::Distribution;
        x.add_scalar(0.3 * rand_distr::StudentT::new(3.0).unwrap().sample(rng))
    }
}

/// A non-Gaussian likelihood gives the exact posterior mean (an independent route: trapezoid
/// quadrature of N(x; 0, 1) e^{−|z − x|/b} on [−8, 8], 16 001 nodes, error ≪ 10⁻⁸), and the
/// `NonGaussianFilter` step traits run the same bits as the `NonGaussian` methods, through
/// `filter_sequence` too.
///
/// Tolerance: one update of N = 4000 prior draws is importance sampling; its mean has standard
/// error ≈ σ_post/√ESS (Kong 1992), and 4 of those fail by chance with probability ≈ 6·10⁻⁵.
#[test]
fn non_gaussian_models_give_the_exact_posterior_and_run_through_the_step_traits() {
    use estim_filters::particle::NonGaussianFilter;
    let sensor = Laplace { b: 0.5 };
    let z = 1.3;
    let (_, _, prior) = ar1();
    let mut pf = ParticleFilter::new(prior.clone(), 4000, 31).unwrap();
    pf.update_with(&NonGaussian(Laplace { b: 0.5 }), &Vector1::new(z))
        .unwrap();
    let (mut w0, mut w1, mut w2) = (0.0, 0.0, 0.0);
    let nodes = 16_001;
    for k in 0..nodes {
        let x = -8.0 + 16.0 * k as f64 / (nodes - 1) as f64;
        let end = if k == 0 || k == nodes - 1 { 0.5 } else { 1.0 };
        let d = end * (-x * x / 2.0 - (z - x).abs() / 0.5).exp();
        w0 += d;
        w1 += d * x;
        w2 += d * x * x;
    }
    let (mean, var) = (w1 / w0, w2 / w0 - (w1 / w0).powi(2));
    let se = (var / pf.effective_sample_size()).sqrt();
    assert!(
        (pf.state()[0] - mean).abs() <= 4.0 * se,
        "{} vs {mean} (se {se})",
        pf.state()[0]
    );

    let zs = readings(5, 13);
    let mut measurements: Vec<Option<Vector1<f64>>> = vec![None];
    measurements.extend(zs.iter().map(|&z| Some(Vector1::new(z))));
    let start = ParticleFilter::new(prior, 300, 3).unwrap();
    let mut stepped = NonGaussianFilter::new(start.clone());
    let run = estim_filters::filter_sequence(
        &mut stepped,
        &HeavyWalk,
        &vec![(); zs.len()],
        1.0,
        &sensor,
        &measurements,
    )
    .unwrap();
    let mut hand = start;
    for &z in &zs {
        hand.predict_with(&NonGaussian(HeavyWalk), &(), 1.0)
            .unwrap();
        hand.update_with(&NonGaussian(Laplace { b: 0.5 }), &Vector1::new(z))
            .unwrap();
    }
    assert_eq!(stepped.inner(), &hand);
    assert_eq!(
        run.log_likelihood.to_bits(),
        hand.log_likelihood().to_bits()
    );
}

/// Static sizes: after construction a bootstrap step, an auxiliary step and a snapshot round
/// trip allocate nothing (the cloud, weights, ancestors and resampling scratch are the filter's
/// own buffers), for every resampling scheme.
#[test]
fn static_size_steps_allocate_nothing() {
    use crate::counting::allocations_during;
    let (process, sensor, prior) = ar1();
    for scheme in [
        Resampling::Multinomial,
        Resampling::Stratified,
        Resampling::Systematic,
        Resampling::Residual,
    ] {
        let mut pf = ParticleFilter::new(prior.clone(), 256, 1)
            .unwrap()
            .with_resampling(scheme)
            .with_trigger(ResampleWhen::Always)
            .unwrap();
        let mut report = estim_filters::UpdateReport::zeros(U1);
        let mut snapshot = pf.snapshot();
        // One warm-up step: the Q factor cache is filled at the first prediction.
        pf.predict(&process, &(), 1.0).unwrap();
        let count = allocations_during(|| {
            for k in 0..3 {
                pf.predict(&process, &(), 1.0).unwrap();
                pf.update_into(&sensor, &Vector1::new(0.1 * k as f64), &mut report)
                    .unwrap();
                pf.auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(0.2))
                    .unwrap();
                pf.snapshot_into(&mut snapshot);
                pf.restore(&snapshot);
            }
        });
        assert_eq!(count, 0, "{scheme:?}");
    }
}

/// Runtime sizes: a model whose Q, R or h(x) has the wrong shape is a typed error (not a
/// panic in a product), and the filter is unchanged.
#[test]
fn runtime_shape_errors_are_typed_and_atomic() {
    use estim_core::nalgebra::{DMatrix, DVector, Dyn};
    let prior = Gaussian::new(DVector::from_element(2, 0.0), DMatrix::identity(2, 2)).unwrap();
    let mut pf: ParticleFilter<f64, Dyn> = ParticleFilter::new(prior, 50, 1).unwrap();
    let before = pf.clone();
    let wrong_q = LinearProcess::without_input(DMatrix::identity(2, 2), DMatrix::identity(3, 3));
    let e = pf.predict(&wrong_q, &(), 1.0);
    assert!(
        matches!(
            e,
            Err(Error::DimensionMismatch {
                quantity: Quantity::ProcessNoise,
                ..
            })
        ),
        "{e:?}"
    );
    assert_eq!(pf, before);
    let wrong_r = LinearMeasurement {
        observation: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        noise: DMatrix::identity(2, 2),
    };
    let e = pf.update(&wrong_r, &DVector::from_element(1, 0.0));
    assert!(
        matches!(
            e,
            Err(Error::DimensionMismatch {
                quantity: Quantity::MeasurementNoise,
                ..
            })
        ),
        "{e:?}"
    );
    assert_eq!(pf, before);
    let wrong_h = LinearMeasurement {
        observation: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        noise: DMatrix::identity(1, 1),
    };
    let e = pf.update(&wrong_h, &DVector::from_element(2, 0.0));
    assert!(matches!(e, Err(Error::DimensionMismatch { .. })), "{e:?}");
    assert_eq!(pf, before);
}
