//! Monte Carlo consistency of the Kalman filter on a linear-Gaussian system: the average
//! NEES (and NIS) over runs falls in its two-sided 95% χ² band.

use crate::common;

use common::{
    StaticSystem, Z_975, chi2_quantile_wilson_hilferty, random_static_system, rng, simulate,
};
use estim_core::nalgebra::{Matrix4, U1, U2, U4};
use estim_core::{LinearMeasurement, LinearProcess};
use estim_filters::{Estimator, KalmanFilter, Predict, Update};

/// Monte Carlo runs.
const RUNS: usize = 200;
/// Steps per run: 100 rather than 50 so that the fraction-inside check below has enough
/// steps to be meaningful (see there).
const STEPS: usize = 100;

/// Per-step run-averaged NEES and NIS of a KF that uses `process`/`measurement` (possibly
/// mistuned) on data simulated from `truth`.
fn monte_carlo(
    truth: &StaticSystem,
    process: &LinearProcess<f64, U4, U1>,
    measurement: &LinearMeasurement<f64, U4, U2>,
    seed: u64,
) -> (Vec<f64>, Vec<f64>) {
    let mut r = rng(seed);
    let mut nees = vec![0.0; STEPS];
    let mut nis = vec![0.0; STEPS];
    for _ in 0..RUNS {
        let traj = simulate(&mut r, truth, STEPS);
        let mut kf = KalmanFilter::new(truth.prior.clone());
        for k in 0..STEPS {
            kf.predict(process, &traj.inputs[k], 1.0).unwrap();
            let report = kf.update(measurement, &traj.measurements[k]).unwrap();
            nis[k] += report.nis;
            let e = kf.state() - traj.truth[k];
            let p_inv: Matrix4<f64> = kf.covariance().cholesky().unwrap().inverse();
            nees[k] += e.dot(&(p_inv * e));
        }
    }
    let n = RUNS as f64;
    (
        nees.into_iter().map(|v| v / n).collect(),
        nis.into_iter().map(|v| v / n).collect(),
    )
}

/// The two-sided 95% band of the average of `RUNS` independent χ²_dof variables:
/// [χ²(0.025; RUNS·dof), χ²(0.975; RUNS·dof)] / RUNS (Bar-Shalom, Li & Kirubarajan §5.4).
/// The quantiles come from Wilson–Hilferty, accurate to ≲ 10⁻³ relative at 400–800 degrees
/// of freedom (well under the 1% that would matter here).
fn band(dof: usize) -> (f64, f64) {
    let k = (RUNS * dof) as f64;
    (
        chi2_quantile_wilson_hilferty(k, -Z_975) / RUNS as f64,
        chi2_quantile_wilson_hilferty(k, Z_975) / RUNS as f64,
    )
}

/// Asserts the per-step averages are consistent with χ²_dof:
///
/// - fraction of steps inside the band ≥ 90%. If the steps were independent, the number of
///   steps outside would be Binomial(100, 0.05): mean 5, standard deviation 2.2, so more than
///   10 outside (the 90% threshold) has probability ≈ 1.5%. Errors of consecutive steps are
///   correlated, which widens that spread; hence a 90% floor rather than 95%. The data are
///   seeded, so the outcome is deterministic.
/// - the time average of the per-step averages inside the same band: it has mean dof and, as
///   an average of equally distributed (correlated) variables, a variance no larger than a
///   single step's, so the single-step band is a valid (conservative) 95% band for it. The
///   band of RUNS·STEPS independent terms would be too narrow for correlated steps.
fn assert_consistent(values: &[f64], dof: usize, what: &str) {
    let (lo, hi) = band(dof);
    let inside = values.iter().filter(|v| (lo..=hi).contains(*v)).count();
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    println!(
        "{what}: band [{lo:.3}, {hi:.3}], {inside}/{} steps inside, time average {mean:.3}",
        values.len()
    );
    assert!(
        inside * 10 >= values.len() * 9,
        "{what}: only {inside}/{} steps inside [{lo}, {hi}]: {values:?}",
        values.len()
    );
    assert!(
        (lo..=hi).contains(&mean),
        "{what}: time-averaged {mean} outside [{lo}, {hi}]"
    );
}

#[test]
fn kalman_filter_nees_and_nis_fall_in_their_95_percent_chi2_bands() {
    let mut r = rng(31);
    let truth = random_static_system(&mut r);
    let (nees, nis) = monte_carlo(&truth, &truth.process, &truth.measurement, 32);
    assert_consistent(&nees, 4, "NEES (n = 4)");
    assert_consistent(&nis, 2, "NIS (m = 2)");
}

/// The check has power: a filter that believes the sensors are 5× more accurate than they are
/// (R/5) is overconfident, and its NEES lands above the band.
#[test]
fn mistuned_kalman_filter_fails_the_nees_band() {
    let mut r = rng(31);
    let truth = random_static_system(&mut r);
    let mistuned = LinearMeasurement {
        observation: truth.measurement.observation,
        noise: truth.measurement.noise / 5.0,
    };
    let (nees, _) = monte_carlo(&truth, &truth.process, &mistuned, 32);
    let (_, hi) = band(4);
    let mean = nees.iter().sum::<f64>() / nees.len() as f64;
    assert!(mean > hi, "mistuned NEES {mean} not above {hi}");
}

/// Wilson–Hilferty against exact quantiles (scipy.stats.chi2.ppf): within 1% at 10 degrees
/// of freedom, within 10⁻⁴ at the 400 and 800 the NIS and NEES bands use.
#[test]
fn wilson_hilferty_quantiles_are_accurate() {
    let rel = |a: f64, b: f64| (a - b).abs() / b;
    assert!(rel(chi2_quantile_wilson_hilferty(10.0, Z_975), 20.483_177_351) < 1e-2);
    assert!(rel(chi2_quantile_wilson_hilferty(10.0, -Z_975), 3.246_972_780) < 1e-2);
    assert!(rel(chi2_quantile_wilson_hilferty(400.0, Z_975), 457.305_481_966) < 1e-4);
    assert!(
        rel(
            chi2_quantile_wilson_hilferty(400.0, -Z_975),
            346.481_765_363
        ) < 1e-4
    );
    assert!(rel(chi2_quantile_wilson_hilferty(800.0, Z_975), 880.275_336_893) < 1e-4);
    assert!(
        rel(
            chi2_quantile_wilson_hilferty(800.0, -Z_975),
            723.512_593_262
        ) < 1e-4
    );
}
