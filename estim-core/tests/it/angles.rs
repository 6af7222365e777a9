//! Angle outputs: a function whose `difference_into` wraps into (−π, π], with the mean of the
//! angle at or near ±π so that sigma points and samples fall on both sides of the cut. The
//! unscented and sampled moments must be those of the unwrapped angle (modulo 2π for the
//! mean): wrapping is invisible as long as every deviation is below π. Without the wrapping
//! `difference_into`, the same function gives a variance of order π² (the control).

use crate::common;

use std::f64::consts::PI;

use common::*;
use estim_core::nalgebra::{Matrix2, U2, Vector2};
use estim_core::{Moments, Sampled, Unscented, VectorFunction};

/// Wraps into (−π, π].
fn wrap(a: f64) -> f64 {
    estim_core::wrap_angle(a)
}

/// y = (wrap(x₀ + 0.5 x₁ + k sin x₁), x₁): a heading (affine in x when k = 0) and a rate.
/// `wrapped` selects the wrapping difference for y₀; otherwise the default a − b.
struct Heading {
    k: f64,
    wrapped: bool,
}

impl VectorFunction<f64, U2, U2> for Heading {
    fn eval(&self, x: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(wrap(x[0] + 0.5 * x[1] + self.k * x[1].sin()), x[1])
    }

    fn difference_into(&self, a: &Vector2<f64>, b: &Vector2<f64>, out: &mut Vector2<f64>) {
        *out = if self.wrapped {
            Vector2::new(wrap(a[0] - b[0]), a[1] - b[1])
        } else {
            a - b
        };
    }
}

/// The same map without wrapping, as a TrigSum: x₀ + 0.5x₁ + k cos(x₁ − π/2), and x₁.
fn unwrapped(k: f64) -> TrigSum<f64, U2, U2> {
    let e = |i| unit(U2, i);
    TrigSum {
        m: U2,
        outputs: vec![
            vec![
                Term {
                    c0: 0.0,
                    b: e(0) + e(1) * 0.5,
                    a: Vector2::zeros(),
                    phase: 0.0,
                },
                Term {
                    c0: k,
                    b: Vector2::zeros(),
                    a: e(1),
                    phase: -PI / 2.0,
                },
            ],
            vec![Term {
                c0: 0.0,
                b: e(1),
                a: Vector2::zeros(),
                phase: 0.0,
            }],
        ],
    }
}

/// Mean and covariance of (x₀, x₁): heading `theta`, a zero-mean rate correlated with it, so
/// the output heading has mean wrap(θ) (plus k E sin x₁ = 0).
fn input(theta: f64) -> (Vector2<f64>, Matrix2<f64>) {
    (
        Vector2::new(theta, 0.0),
        Matrix2::new(0.09, 0.012, 0.012, 0.04),
    )
}

/// The unscented transform of the wrapped function equals that of the unwrapped one: the
/// mean modulo 2π, the covariance and cross-covariance exactly, up to round-off. Round-off:
/// `roundoff_unscented` of the TrigSum for each of the two runs, plus the wrapping itself, which
/// moves each deviation by at most 4ε·2π (two rem_euclid reductions of values ≤ 2π + |y|,
/// the subtractions), entering like any deviation error (see `roundoff_unscented`).
fn assert_wrapping_is_transparent(ut: (f64, f64, f64), theta: f64, k: f64) {
    let (mu, c) = input(theta);
    let p = Unscented::new(ut.0, ut.1, ut.2).unwrap();
    let wrapped: Moments<f64, U2, U2> = propagate(&p, &mu, &c, &Heading { k, wrapped: true });
    let rep = unwrapped(k);
    let plain = propagate(&p, &mu, &c, &rep);

    let n = 2.0;
    let scale = ut.0 * ut.0 * (n + ut.2);
    let lower = abs(&estim_core::linalg::psd_factor(&c, estim_core::Stage::Propagation).unwrap());
    let e_wrap = Vector2::new(4.0 * EPS * (2.0 * PI + plain.mean[0].abs() + 4.0), 0.0);
    let grad = rep
        .majorants(&mu, &(lower * Vector2::repeat(scale.sqrt())))
        .gradient;
    let wd = grad * lower * Vector2::repeat(1.0) / scale.sqrt();
    let base = rep.roundoff_unscented(&mu, &c, ut, gamma);
    let tol = ApproxBounds {
        mean: base.mean * 2.0 + e_wrap * (n / scale),
        cov: base.cov * 2.0
            + (wd * e_wrap.transpose() + e_wrap * wd.transpose())
            + (wd * e_wrap.transpose() + e_wrap * wd.transpose()) * (ut.1 - ut.0 * ut.0).abs() * n
                / scale,
        cross: base.cross * 2.0 + lower * Vector2::repeat(1.0) * e_wrap.transpose() / scale.sqrt(),
    };
    let what = format!("Unscented{ut:?} at θ = {theta}, k = {k}");
    // The wrapped mean is the plain one moved by a multiple of 2π.
    let shift = ((plain.mean[0] - wrapped.mean[0]) / (2.0 * PI)).round() * 2.0 * PI;
    let mean = Vector2::new(wrapped.mean[0] + shift, wrapped.mean[1]);
    assert_within(&format!("{what} mean"), &mean, &plain.mean, &tol.mean);
    assert_within(
        &format!("{what} covariance"),
        &wrapped.covariance,
        &plain.covariance,
        &tol.cov,
    );
    assert_within(
        &format!("{what} cross"),
        &wrapped.cross_covariance,
        &plain.cross_covariance,
        &tol.cross,
    );
    // Sane: the mean stays within one small deviation of the circle's range, and the
    // variance is that of x₀ + 0.5x₁ + …, not of order π².
    assert!(
        wrapped.mean[0].abs() <= PI + 0.1,
        "{what}: mean {}",
        wrapped.mean[0]
    );
    assert!(
        wrapped.covariance[(0, 0)] < 0.5,
        "{what}: variance {}",
        wrapped.covariance[(0, 0)]
    );
}

#[test]
fn unscented_wraps_angle_deviations() {
    // θ = π exactly (even the default α = 10⁻³ straddles the cut), just below π, just above
    // −π, and far from the cut as a reference.
    for theta in [PI, PI - 0.05, -PI + 0.01, 3.0, 0.5] {
        for ut in [
            (1e-3, 2.0, 0.0),
            (1.0, 0.0, 0.0),
            (1.0, 0.0, 1.0),
            (0.5, 2.0, 1.0),
        ] {
            for k in [0.0, 0.3] {
                assert_wrapping_is_transparent(ut, theta, k);
            }
        }
    }
}

/// For the affine heading (k = 0) the wrapped unscented moments are exact: the mean is
/// wrap(θ) ∈ (−π, π], the variance C₀₀ + C₀₁ + 0.25C₁₁ = 0.112.
#[test]
fn unscented_affine_heading_is_exact_across_the_cut() {
    for theta in [PI, PI - 0.05, -PI + 0.01] {
        let (mu, c) = input(theta);
        let g = Heading {
            k: 0.0,
            wrapped: true,
        };
        for p in [
            Unscented::default(),
            Unscented::cubature(),
            Unscented::julier(1.0).unwrap(),
        ] {
            let m = propagate(&p, &mu, &c, &g);
            let expected = wrap(theta);
            assert!(
                m.mean[0] > -PI && m.mean[0] <= PI,
                "mean {} outside (−π, π]",
                m.mean[0]
            );
            // Round-off (as in `assert_wrapping_is_transparent`): each deviation is off by
            // ≤ e = 8ε·2π (the wrap reductions dominate), the mean by n e/c (c = α²(n + κ);
            // ≈ 10⁻⁸ for the default α = 10⁻³, 10⁻¹⁴ for α = 1), the covariance and the
            // cross-covariance by ≤ 2 e w Σᵢ|dᵢ| ≤ 2e (|A||L|1)/√c with |A||L|1 ≤ 0.3 + 0.5·0.2.
            let c_ut = p.alpha() * p.alpha() * (2.0 + p.kappa());
            let e = 8.0 * EPS * 2.0 * PI;
            let tol_mean = 2.0 * e / c_ut + 4.0 * EPS * PI;
            let tol_cov = 2.0 * e * 0.4 / c_ut.sqrt() + 16.0 * EPS;
            approx::assert_abs_diff_eq!(wrap(m.mean[0] - expected), 0.0, epsilon = tol_mean);
            approx::assert_abs_diff_eq!(m.covariance[(0, 0)], 0.112, epsilon = tol_cov);
            approx::assert_abs_diff_eq!(
                m.cross_covariance[(0, 0)],
                0.09 + 0.5 * 0.012,
                epsilon = tol_cov
            );
        }
    }
}

/// The control: with the plain difference the deviation across the cut is ≈ 2π and the
/// "variance" is of order π² (or, for α = 10⁻³, of order π²/α²).
#[test]
fn without_wrapping_the_variance_explodes() {
    let (mu, c) = input(PI - 0.05);
    let g = Heading {
        k: 0.0,
        wrapped: false,
    };
    let m = propagate(&Unscented::cubature(), &mu, &c, &g);
    assert!(m.covariance[(0, 0)] > 1.0, "{}", m.covariance[(0, 0)]);
    let (mu, c) = input(PI);
    let m = propagate(&Unscented::default(), &mu, &c, &g);
    assert!(m.covariance[(0, 0)] > 1e5, "{}", m.covariance[(0, 0)]);
}

/// Monte Carlo with the wrapping difference: the circular mean within Z standard errors of
/// wrap(θ) and the variance within Z standard errors of the unwrapped
/// variance; deviations beyond π (where wrapping would alias) have probability
/// < 10⁻²⁰ here (σ ≈ 0.34, π/σ > 9).
#[test]
fn sampled_wraps_angle_deviations() {
    for theta in [PI, PI - 0.05, -PI + 0.01] {
        for k in [0.0, 0.3] {
            let (mu, c) = input(theta);
            let g = Heading { k, wrapped: true };
            let rep = unwrapped(k);
            let exact = rep.exact(&mu, &c);
            let m = propagate(&Sampled::new(100_000, 5).unwrap(), &mu, &c, &g);
            let se = sampling_error(&rep, &mu, &c, 100_000, 20_000, 6).scaled(Z);
            approx::assert_abs_diff_eq!(wrap(m.mean[0] - exact.mean[0]), 0.0, epsilon = se.mean[0]);
            assert!(m.mean[0].abs() <= PI + 0.01, "mean {}", m.mean[0]);
            assert_within(
                "Sampled covariance",
                &m.covariance,
                &exact.covariance,
                &se.cov,
            );
            assert_within(
                "Sampled cross",
                &m.cross_covariance,
                &exact.cross_covariance,
                &se.cross,
            );
        }
    }
}
