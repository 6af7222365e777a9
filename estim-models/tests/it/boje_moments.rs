//! Boje eq 4–13 and 8–11: every closed form against an independent route — the generic moment
//! propagators on the underlying function (eq 5, or the trig products), the exact Gaussian
//! expectation, and Monte Carlo. The moments and λ examples are tested with the examples, in
//! the estim package's tests (`tests/it/boje_examples.rs`).

use estim_core::nalgebra::{Matrix4, Vector4};
use estim_core::{Linearized, MomentPropagator, Sampled, SecondOrder};
use estim_models::boje::geometry::{invert, sensor_matrix};
use estim_models::boje::{
    ChannelVariances, InversionInput, inertial_mean, lambda, lambda_as_printed,
};
use proptest::prelude::*;

/// Round-off allowance for closed form vs propagator: both evaluate the same sums of a few
/// products in different orders, so they differ by a few ulps of the largest term; 1e-12 of the
/// largest entry leaves 4 orders of margin and is far below any real mistake (a wrong λ is off
/// by O(σ²/R²), i.e. O(1) relative).
const ROUNDOFF: f64 = 1e-12;

fn input_strategy() -> impl Strategy<Value = InversionInput> {
    (
        -10.0..10.0f64,
        0.0..0.3f64,
        (
            -50.0..50.0f64,
            -50.0..50.0f64,
            -50.0..50.0f64,
            -50.0..50.0f64,
        ),
        (1e-3..1e-1f64, 1e-3..1e-1f64, 1e-3..1e-1f64, 1e-3..1e-1f64),
        0.1..2.0f64,
    )
        .prop_map(|(theta, st, a, s, r)| InversionInput {
            theta,
            theta_variance: st * st,
            accel: Vector4::new(a.0, a.1, a.2, a.3),
            variances: ChannelVariances::from_std(s.0, s.1, s.2, s.3),
            half_separation: r,
        })
}

fn max_abs(m: &Matrix4<f64>) -> f64 {
    m.abs().max()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Eq 5 inverts eq 4: invert(θ, M(θ) s) = s for any s.
    #[test]
    fn eq5_inverts_eq4(theta in -10.0..10.0f64, s in (-50.0..50.0f64, -50.0..50.0f64, -50.0..50.0f64, 0.0..100.0f64), r in 0.1..2.0f64) {
        let s = Vector4::new(s.0, s.1, s.2, s.3);
        let back = invert(theta, &(sensor_matrix(theta, r) * s), r);
        prop_assert!((back - s).abs().max() <= 1e-12 * (1.0 + s.abs().max() * (1.0 + r) / r));
    }

    /// Eq 12 (closed form) = generic SecondOrder mean of eq 5 with C_z = diag(σ²_θ, σ²_a…),
    /// entry by entry.
    #[test]
    fn eq12_mean_equals_generic_second_order(input in input_strategy()) {
        let closed = inertial_mean(&input).unwrap();
        let generic = SecondOrder.propagate(&input.mean(), &input.covariance(), &input.function()).unwrap();
        let scale = 1.0 + closed.abs().max();
        for k in 0..4 {
            prop_assert!((closed[k] - generic.mean[k]).abs() <= ROUNDOFF * scale, "k={k}: {} vs {}", closed[k], generic.mean[k]);
        }
    }

    /// Eq 13 corrected (closed form) = J C_z Jᵀ from the generic Linearized and SecondOrder
    /// propagators, all 16 entries, with unequal channel variances.
    #[test]
    fn eq13_lambda_equals_generic_jcjt(input in input_strategy()) {
        let closed = lambda(&input).unwrap();
        let (mean, cov, g) = (input.mean(), input.covariance(), input.function());
        let lin = Linearized.propagate(&mean, &cov, &g).unwrap().covariance;
        let so = SecondOrder.propagate(&mean, &cov, &g).unwrap().covariance;
        let scale = max_abs(&closed);
        for a in 0..4 {
            for b in 0..4 {
                prop_assert!((closed[(a, b)] - lin[(a, b)]).abs() <= ROUNDOFF * scale, "({a},{b}) {} vs {}", closed[(a, b)], lin[(a, b)]);
                prop_assert!((closed[(a, b)] - so[(a, b)]).abs() <= ROUNDOFF * scale);
            }
        }
    }
}

/// Erratum E1: eq 13 as printed swaps λ33 and λ44. With unequal channel variances the generic
/// J C Jᵀ of eq 5 (and a 10⁶-sample Monte Carlo) give λ33 = (σ²_v1 + σ²_v2)/(4R²),
/// λ44 = (σ²_u1 + σ²_u2)/(4R²); the printed formulas give the other way round; the other 14
/// entries agree.
#[test]
fn lambda33_lambda44_swapped_in_paper() {
    let input = InversionInput {
        theta: 0.4,
        theta_variance: 0.05f64.powi(2),
        accel: Vector4::new(0.3, -0.2, 0.5, 0.1),
        // Very different u and v variances: 1e-4, 4e-4, 9e-4, 1.6e-3.
        variances: ChannelVariances::from_std(0.01, 0.02, 0.03, 0.04),
        half_separation: 0.5,
    };
    let (mean, cov, g) = (input.mean(), input.covariance(), input.function());
    let generic = Linearized.propagate(&mean, &cov, &g).unwrap().covariance;
    let printed = lambda_as_printed(&input).unwrap();
    let corrected = lambda(&input).unwrap();
    let r2 = 4.0 * 0.25;
    assert!((generic[(2, 2)] - (4e-4 + 1.6e-3) / r2).abs() < 1e-15);
    assert!((generic[(3, 3)] - (1e-4 + 9e-4) / r2).abs() < 1e-15);
    assert!((printed[(2, 2)] - generic[(2, 2)]).abs() > 0.4 * generic[(2, 2)]);
    assert!((printed[(3, 3)] - generic[(3, 3)]).abs() > 0.4 * generic[(3, 3)]);
    assert_eq!(printed[(2, 2)], corrected[(3, 3)]);
    assert_eq!(printed[(3, 3)], corrected[(2, 2)]);
    for a in 0..4 {
        for b in 0..4 {
            if a != b || a < 2 {
                assert!((printed[(a, b)] - generic[(a, b)]).abs() <= ROUNDOFF * max_abs(&generic));
            }
        }
    }
    // Monte Carlo: θ̈ and θ̇² are linear in the a's, so their sampled variances have relative
    // standard error √(2/(N−1)) = 1.4e-3; 1 % is 7 standard errors and the swap is a factor 2.
    let sampled = Sampled::new(1_000_000, 11)
        .unwrap()
        .propagate(&mean, &cov, &g)
        .unwrap()
        .covariance;
    assert!((sampled[(2, 2)] / corrected[(2, 2)] - 1.0).abs() < 0.01);
    assert!((sampled[(3, 3)] / corrected[(3, 3)] - 1.0).abs() < 0.01);
}

/// The paper's remark after eq 13: with equal channel variances λ13 = λ14 = λ23 = λ24 = 0 (and
/// λ33 = λ44 = σ²/(2R²)).
#[test]
fn equal_channels_cross_terms_vanish() {
    let input = InversionInput {
        theta: 1.1,
        theta_variance: 1e-3,
        accel: Vector4::new(3.0, -1.0, 2.0, 0.5),
        variances: ChannelVariances::equal(0.01),
        half_separation: 0.5,
    };
    let l = lambda(&input).unwrap();
    for (a, b) in [(0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
        assert_eq!(l[(a, b)], 0.0);
    }
    assert!((l[(2, 2)] - 1e-4 / (2.0 * 0.25)).abs() < 1e-18);
    assert_eq!(l[(2, 2)], l[(3, 3)]);
}
