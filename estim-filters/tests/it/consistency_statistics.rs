//! The single-run consistency statistics: NEES/NIS, χ² bands, whiteness, log-likelihood.

use crate::consistency_common;

use consistency_common::*;
use estim_core::nalgebra::{DMatrix, DVector, Matrix2, Vector1, Vector2, Vector3};
use estim_core::{Error, Quantity, Stage};
use estim_filters::consistency::{
    ChiSquareAverage, ChiSquareBand, FamilyRule, LogLikelihood, autocorrelation_bound, nees, nis,
    normalized_autocorrelation, whiteness,
};
use estim_filters::validation::{Setting, ValidationError};
use estim_filters::{KalmanFilter, Update};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

#[test]
fn nees_and_nis_by_cholesky() {
    // P = [[4, 2], [2, 3]]: P⁻¹ = [[3, −2], [−2, 4]]/8, so (1, 2) gives (3 − 8 + 16)/8.
    let p = Matrix2::new(4.0, 2.0, 2.0, 3.0);
    let e = Vector2::new(1.0, 2.0);
    assert!((nees(&e, &p).unwrap() - 11.0 / 8.0).abs() < 1e-15);
    assert!((nis(&e, &p).unwrap() - 11.0 / 8.0).abs() < 1e-15);
    // f32 filters: computed in f64 from the converted values.
    let p32 = Matrix2::new(4.0f32, 2.0, 2.0, 3.0);
    assert!((nees(&Vector2::new(1.0f32, 2.0), &p32).unwrap() - 11.0 / 8.0).abs() < 1e-7);
    // Not positive definite, non-finite, wrong runtime shape.
    let indefinite = Matrix2::new(1.0, 2.0, 2.0, 1.0);
    assert_eq!(
        nees(&e, &indefinite),
        Err(ValidationError::Estimation(Error::NotPositiveDefinite {
            stage: Stage::ConsistencyCheck,
            quantity: Quantity::Covariance
        }))
    );
    assert!(matches!(
        nees(&Vector2::new(f64::NAN, 0.0), &p),
        Err(ValidationError::Estimation(Error::NonFinite { .. }))
    ));
    assert!(matches!(
        nees(&DVector::from_element(3, 1.0), &DMatrix::identity(2, 2)),
        Err(ValidationError::Estimation(Error::DimensionMismatch { .. }))
    ));
}

#[test]
fn chi_square_bands_match_tables() {
    // χ²₁₀₀ quantiles 74.2219 (2.5%) and 129.5612 (97.5%), e.g. NIST/Abramowitz & Stegun:
    // the band of the average NEES of 50 runs of a 2-state filter.
    let band = ChiSquareBand::two_sided(2, 50, 0.95).unwrap();
    assert!((band.lower - 74.2219 / 50.0).abs() < 1e-5, "{band:?}");
    assert!((band.upper - 129.5612 / 50.0).abs() < 1e-5, "{band:?}");
    assert_eq!(band.expected(), 2.0);
    assert_eq!(band.degrees_of_freedom, 100);
    // χ²₃: 0.2158 and 9.3484 (one run of a 3-state filter); χ²₁ at 99%: 0.0000393, 7.8794.
    let band = ChiSquareBand::two_sided(3, 1, 0.95).unwrap();
    assert!((band.lower - 0.215795).abs() < 1e-5 && (band.upper - 9.348404).abs() < 1e-5);
    let band = ChiSquareBand::two_sided(1, 1, 0.99).unwrap();
    assert!((band.lower - 3.927e-5).abs() < 1e-7 && (band.upper - 7.879439).abs() < 1e-5);
    // Large: 1000 runs × 6 states (6000 dof) stays accurate (Wilson–Hilferty agrees to 1e-4).
    let band = ChiSquareBand::two_sided(6, 1000, 0.95).unwrap();
    let wh = |z: f64| {
        let k: f64 = 6000.0;
        k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3) / 1000.0
    };
    assert!((band.lower - wh(-1.959964)).abs() < 1e-4 && (band.upper - wh(1.959964)).abs() < 1e-4);
    // p-values: the band ends have p = 1 − confidence, the mean has p ≈ 1.
    let band = ChiSquareBand::two_sided(3, 20, 0.9).unwrap();
    assert!((band.p_value(band.lower).unwrap() - 0.1).abs() < 1e-9);
    assert!((band.p_value(band.upper).unwrap() - 0.1).abs() < 1e-9);
    assert!(band.p_value(band.expected()).unwrap() > 0.9);
    assert!(band.contains(3.0) && !band.contains(f64::NAN));
    // Invalid parameters.
    let conf = |c: f64| ValidationError::InvalidSetting {
        setting: Setting::Confidence,
        value: c,
    };
    assert_eq!(ChiSquareBand::two_sided(3, 20, 1.0), Err(conf(1.0)));
    assert_eq!(ChiSquareBand::two_sided(3, 20, 0.0), Err(conf(0.0)));
    assert!(ChiSquareBand::two_sided(3, 20, f64::NAN).is_err());
    assert!(ChiSquareBand::two_sided(0, 20, 0.95).is_err());
    assert!(ChiSquareBand::two_sided(3, 0, 0.95).is_err());
}

#[test]
fn autocorrelation_formula_and_bound() {
    // ν = 1, 2, −1, 1 at lag 1: Σ νₖνₖ₊₁ = 2 − 2 − 1 = −1, heads 1+4+1 = 6, tails 4+1+1 = 6.
    let seq: Vec<Vector1<f64>> = [1.0, 2.0, -1.0, 1.0]
        .iter()
        .map(|&v| Vector1::new(v))
        .collect();
    assert!((normalized_autocorrelation(&seq, 1).unwrap() + 1.0 / 6.0).abs() < 1e-15);
    assert!((normalized_autocorrelation(&seq, 0).unwrap() - 1.0).abs() < 1e-15);
    assert_eq!(
        normalized_autocorrelation(&seq, 4),
        Err(ValidationError::InvalidSetting {
            setting: Setting::Lag,
            value: 4.0
        })
    );
    assert!(normalized_autocorrelation(&[Vector1::new(0.0); 3], 1).is_err());
    // z₀.₉₇₅ / √100.
    assert!((autocorrelation_bound(100, 0.95).unwrap() - 0.1959964).abs() < 1e-6);
}

/// White noise passes the whiteness check; an AR(1) sequence with φ = 0.5 does not, and its
/// lag-1 autocorrelation estimates φ (K = 2000: standard error ≈ √((1 − φ²)/K) ≈ 0.02, so
/// ±0.06 is a 3σ tolerance).
#[test]
fn whiteness_separates_white_from_coloured() {
    let mut rng = StdRng::seed_from_u64(11);
    let white: Vec<Vector2<f64>> = (0..2000)
        .map(|_| Vector2::from_fn(|_, _| rng.sample(StandardNormal)))
        .collect();
    let test = whiteness(&white, 1..=10, 0.95).unwrap();
    assert!(test.check(FamilyRule::Simes).unwrap().passed(), "{test:?}");
    let mut ar = Vec::new();
    let mut v = 0.0;
    for _ in 0..2000 {
        v = 0.5 * v + rng.sample::<f64, _>(StandardNormal);
        ar.push(Vector1::new(v));
    }
    let test = whiteness(&ar, 1..=10, 0.95).unwrap();
    assert!((test.lags[0].value - 0.5).abs() < 0.06, "{test:?}");
    let check = test.check(FamilyRule::Simes).unwrap();
    assert!(!check.passed() && check.p_value < 1e-20, "{check:?}");
    assert!(whiteness(&ar, [0], 0.95).is_err());
}

/// One run of the tuned KF: the time-averaged NIS lies in its χ² band, the innovations are
/// white, and the log-likelihood is the sum of the reports' values and prefers the true R to a
/// tenfold one on the same measurements.
#[test]
fn single_run_nis_whiteness_and_likelihood() {
    let lu = Lu::new();
    let (_, wrong_r) = lu.mistuned(1.0, 10.0);
    let mut rng = StdRng::seed_from_u64(3);
    let p0 = lu.prior.covariance().cholesky().unwrap().l();
    let q = lu.process.noise.cholesky().unwrap().l();
    let normal3 = |rng: &mut StdRng| Vector3::from_fn(|_, _| rng.sample(StandardNormal));
    let mut x = lu.prior.mean() + p0 * normal3(&mut rng);
    let mut kf = KalmanFilter::new(lu.prior.clone());
    let mut other = KalmanFilter::new(lu.prior.clone());
    let (mut avg, mut ll, mut ll_other) = (
        ChiSquareAverage::new(),
        LogLikelihood::new(),
        LogLikelihood::new(),
    );
    let (mut innovations, mut sum) = (Vec::new(), 0.0);
    let steps = 1000;
    for k in 0..steps {
        use estim_filters::Predict;
        let u = input(k);
        x = lu.process.transition * x + lu.process.input * u + q * normal3(&mut rng);
        let v = Vector2::new(
            rng.sample(StandardNormal),
            0.1 * rng.sample::<f64, _>(StandardNormal),
        );
        let z = lu.sensor.observation * x + v;
        kf.predict(&lu.process, &u, DT).unwrap();
        other.predict(&lu.process, &u, DT).unwrap();
        let report = kf.update(&lu.sensor, &z).unwrap();
        ll_other.add(&other.update(&wrong_r, &z).unwrap());
        avg.push_report(&report).unwrap();
        ll.add(&report);
        sum += report.log_likelihood;
        // Whitened innovation L⁻¹ν, so both components count equally.
        let l = report.innovation_covariance.cholesky().unwrap().l();
        innovations.push(l.solve_lower_triangular(&report.innovation).unwrap());
    }
    assert_eq!(avg.terms(), steps);
    assert_eq!(avg.degrees_of_freedom(), 2 * steps);
    assert!(
        avg.band(0.99).unwrap().contains(avg.mean().unwrap()),
        "{avg:?}"
    );
    let test = whiteness(&innovations, 1..=5, 0.95).unwrap();
    assert!(test.check(FamilyRule::Simes).unwrap().passed(), "{test:?}");
    assert_eq!(ll.count(), steps);
    assert!((ll.total() - sum).abs() < 1e-9 * sum.abs());
    assert!(
        ll.total() > ll_other.total() + 100.0,
        "{ll:?} vs {ll_other:?}"
    );
    let mut merged = LogLikelihood::new();
    merged.merge(&ll);
    assert_eq!(merged.mean(), ll.mean());
}

/// Degrees of freedom that overflow a `usize` or that statrs cannot evaluate are typed errors:
/// before, `ChiSquareAverage` overflowed (a panic in debug builds, a wrapped total in release)
/// and a band for ≳ 2⁵⁴ degrees of freedom never returned (statrs' series stalls at 2⁵³).
#[test]
fn degrees_of_freedom_beyond_the_limit_are_refused() {
    use estim_filters::consistency::MAX_DEGREES_OF_FREEDOM;
    let dof_error = |r: Result<ChiSquareBand, ValidationError>| {
        matches!(
            r,
            Err(ValidationError::InvalidSetting {
                setting: Setting::DegreesOfFreedom,
                ..
            })
        )
    };
    assert!(dof_error(ChiSquareBand::for_sum(usize::MAX, 1, 0.95)));
    assert!(dof_error(ChiSquareBand::for_sum(
        MAX_DEGREES_OF_FREEDOM + 1,
        1,
        0.95
    )));
    assert!(dof_error(ChiSquareBand::two_sided(1 << 30, 1 << 30, 0.95)));
    // The largest accepted count: the band of the sum, k ± 1.96 √(2k) to within 10⁻³ of its width.
    let k = MAX_DEGREES_OF_FREEDOM as f64;
    let band = ChiSquareBand::for_sum(MAX_DEGREES_OF_FREEDOM, 1, 0.95).unwrap();
    let half_width = 1.959_963_984_540_054 * (2.0 * k).sqrt();
    assert!(
        (band.upper - k - half_width).abs() < 1e-3 * half_width,
        "{band:?}"
    );
    assert!(
        (k - band.lower - half_width).abs() < 1e-3 * half_width,
        "{band:?}"
    );

    let mut avg = ChiSquareAverage::new();
    avg.push(1.0, usize::MAX).unwrap();
    let before = avg;
    let overflow = avg.push(1.0, 1);
    assert!(
        matches!(
            overflow,
            Err(ValidationError::InvalidSetting {
                setting: Setting::DegreesOfFreedom,
                ..
            })
        ),
        "{overflow:?}"
    );
    assert_eq!(avg, before, "a refused push adds nothing");
    let mut one = ChiSquareAverage::new();
    one.push(2.0, 1).unwrap();
    assert!(avg.merge(&one).is_err());
    assert_eq!(avg, before, "a refused merge adds nothing");
    assert!(dof_error(avg.band(0.95)));
    one.merge(&one.clone()).unwrap();
    assert_eq!(
        (one.terms(), one.degrees_of_freedom(), one.sum()),
        (2, 2, 4.0)
    );
}
