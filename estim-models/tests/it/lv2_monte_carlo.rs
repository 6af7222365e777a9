//! Monte Carlo checks (seeded) of the model: the estimate covariance against P for uniform
//! noise, and a general spatial axis set. The χ² statistic's distribution and false-alarm rate,
//! the detection of a biased axis and the saturation run are the `lv2_fusion` example's, tested
//! with it (`tests/it/lv2_fusion_example.rs` of the estim package).
//!
//! Tolerances are k standard errors of the Monte Carlo estimate, with k = 5 (a seeded run
//! either passes or fails deterministically; 5σ keeps a correct implementation far from the
//! edge while a wrong formula, e.g. the wrong dof or a missing 2σq² term, misses by far more).

use core::f64::consts::SQRT_2;

use estim_core::nalgebra::{Matrix2, SMatrix, SVector, Vector2, Vector3};
use estim_models::lv2::simulate::SensorArray;
use estim_models::lv2::stats::chi2_quantile_upper;
use estim_models::lv2::xyq::{self, Eq6Coefficients, XyqReading, XyqSigmas};
use estim_models::lv2::{AxisStatus, SpatialAxes};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// The `lv2_fusion` example's channel noise (its `Lv2Config`): σx = 0.010, σy = 0.012,
/// σq = 0.008 m/s².
fn sigmas() -> XyqSigmas {
    XyqSigmas {
        x: 0.010,
        y: 0.012,
        q: 0.008,
    }
}

/// Eq 3 is the BLUE for any noise with these variances (Gauss–Markov): with uniform noise of
/// the same σ's the error covariance is still P. (The χ² false-alarm rate is not: it assumes
/// Gaussian noise; uniform noise has no tail beyond √3σ, so the rate is lower.)
#[test]
fn covariance_holds_for_uniform_noise() {
    let s = sigmas();
    let c = Eq6Coefficients::new(&s);
    let p = xyq::covariance(&s);
    let mut rng = StdRng::seed_from_u64(7);
    let n = 200_000;
    let truth = Vector2::new(0.3, -0.2);
    let (mut se, mut see) = (Vector2::zeros(), Matrix2::zeros());
    let mut alarms = 0;
    let thr = chi2_quantile_upper(1e-3, 1);
    let u = |rng: &mut StdRng, sd: f64| (rng.random::<f64>() * 2.0 - 1.0) * 3f64.sqrt() * sd;
    for _ in 0..n {
        let r = XyqReading {
            x: truth[0] + u(&mut rng, s.x),
            y: truth[1] + u(&mut rng, s.y),
            q: (truth[0] + truth[1]) / SQRT_2 + u(&mut rng, s.q),
        };
        let e = Vector2::new(c.x_hat(&r), c.y_hat(&r)) - truth;
        se += e;
        see += e * e.transpose();
        alarms += usize::from(xyq::parity_chi2(&r, &s) > thr);
    }
    let nf = n as f64;
    let cov = (see - se * se.transpose() / nf) / (nf - 1.0);
    // For non-Gaussian errors the sd of a sample variance involves the 4th moment; the errors
    // here are sums of three uniforms (kurtosis between 1.8 and 3), so the Gaussian se is an
    // upper bound: √((PᵢᵢPⱼⱼ + Pᵢⱼ²)/n).
    for i in 0..2 {
        for j in 0..2 {
            let se = ((p[(i, i)] * p[(j, j)] + p[(i, j)].powi(2)) / nf).sqrt();
            assert!(
                (cov[(i, j)] - p[(i, j)]).abs() < 5.0 * se,
                "[{i},{j}] {} vs {}",
                cov[(i, j)],
                p[(i, j)]
            );
        }
    }
    // The parity of uniform noise is bounded by √3 Σ|coefficients·σ|; in s₁ units this is
    // √3 (σx + σy + √2 σq)/√s₁ ≈ 3.0 < √10.83 = 3.29: no false alarm can occur at all.
    let bound = 3f64.sqrt() * (s.x + s.y + SQRT_2 * s.q) / s.s1().sqrt();
    assert!(bound * bound < thr);
    assert_eq!(alarms, 0);
}

/// A general spatial set (6 axes on a skewed cone, runtime-independent static sizes),
/// simulated with `SensorArray`: the WLS χ² has mean dof = 3, the false-alarm rate at α is α,
/// and the error covariance is the WLS P.
#[test]
fn general_spatial_set_chi2_and_covariance() {
    let dirs: Vec<Vector3<f64>> = (0..6)
        .map(|k| {
            let az = k as f64 * core::f64::consts::PI / 3.0;
            let el: f64 = if k % 2 == 0 { 0.6 } else { -0.3 };
            Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
        })
        .collect();
    let h = SMatrix::<f64, 6, 3>::from_fn(|r, c| dirs[r][c]);
    let sig = SVector::<f64, 6>::new(0.01, 0.02, 0.015, 0.01, 0.03, 0.012);
    let axes = SpatialAxes::<6>::new(h, sig).unwrap();
    let array = SensorArray::new(axes.clone());
    let truth = Vector3::new(0.1, -9.81, 0.4);
    let mut rng = StdRng::seed_from_u64(42);
    let n = 40_000;
    let (mut s_chi2, mut alarms) = (0.0, 0);
    let (mut se, mut see) = (Vector3::zeros(), estim_core::nalgebra::Matrix3::zeros());
    let thr = chi2_quantile_upper(0.01, 3);
    let mut p = estim_core::nalgebra::Matrix3::zeros();
    for _ in 0..n {
        let s = array.sample(&truth, &mut rng);
        let f = axes
            .fuse_screened(&s.reading, &[AxisStatus::Used; 6])
            .unwrap();
        assert_eq!(f.dof, 3);
        s_chi2 += f.chi2;
        alarms += usize::from(!f.is_consistent(0.01));
        let e = f.estimate - truth;
        se += e;
        see += e * e.transpose();
        p = f.covariance;
    }
    let nf = n as f64;
    assert!(
        (s_chi2 / nf - 3.0).abs() < 5.0 * (6.0 / nf).sqrt(),
        "mean χ² {}",
        s_chi2 / nf
    );
    let rate = alarms as f64 / nf;
    assert!(
        (rate - 0.01).abs() < 5.0 * (0.01 * 0.99 / nf).sqrt(),
        "rate {rate}"
    );
    let _ = thr;
    let cov = (see - se * se.transpose() / nf) / (nf - 1.0);
    for i in 0..3 {
        for j in 0..3 {
            let sd = ((p[(i, i)] * p[(j, j)] + p[(i, j)].powi(2)) / nf).sqrt();
            assert!(
                (cov[(i, j)] - p[(i, j)]).abs() < 5.0 * sd,
                "[{i},{j}] {} vs {}",
                cov[(i, j)],
                p[(i, j)]
            );
        }
    }
}
