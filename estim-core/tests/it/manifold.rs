//! The ready-made state spaces: the ⊞/⊟ rules (x ⊞ 0 = x, (x ⊞ δ) ⊟ x = δ, x ⊞ (y ⊟ x) = y)
//! for wrapped angles and the attitude error; Exp/Log against nalgebra's own axis-angle
//! construction; unit-norm quaternions over 10⁶ compositions; the generic Rodrigues formula
//! (for automatic derivatives) against Exp, with its derivatives at δθ = 0.
//!
//! Tolerances: one ⊞ or ⊟ is a few quaternion products, an atan2 and a sin_cos, each
//! correct to a few ulps, on angles ≤ π: 1e-12 absolute (≈ 30 ε · π) is that with margin.
//! Near |δθ| = π the rotation-vector chart folds (δθ and δθ − 2π δθ/|δθ| are the same
//! rotation), so the rules are checked on |x|, |y| ≤ 2.5 and |δ| ≤ 0.5, where no fold occurs.

use core::f64::consts::PI;

use crate::common::config;
use estim_core::manifold::{AttitudeError, AttitudeReference, so3_exp, so3_log};
use estim_core::nalgebra::{DVector, UnitQuaternion, Vector3, Vector4, Vector5};
use estim_core::{Error, Quantity, Stage, StateSpace, WrappedAngles};
use proptest::prelude::*;

/// See the module docs.
const TOL: f64 = 1e-12;

fn ball(radius: f64) -> impl Strategy<Value = Vector3<f64>> {
    prop::array::uniform3(-1.0..1.0f64)
        .prop_filter("inside the unit ball", |v| Vector3::from(*v).norm() <= 1.0)
        .prop_map(move |v| Vector3::from(v) * radius)
}

fn rules<S: StateSpace<f64, estim_core::nalgebra::U5>>(
    space: &S,
    x: &Vector5<f64>,
    y: &Vector5<f64>,
    delta: &Vector5<f64>,
) {
    let (mut a, mut b) = (Vector5::zeros(), Vector5::zeros());
    space.plus_into(x, &Vector5::zeros(), &mut a);
    assert!((a - x).norm() < TOL, "x ⊞ 0 = {a}, x = {x}");
    space.plus_into(x, delta, &mut a);
    space.minus_into(&a, x, &mut b);
    assert!((b - delta).norm() < TOL, "(x ⊞ δ) ⊟ x = {b}, δ = {delta}");
    space.minus_into(y, x, &mut a);
    space.plus_into(x, &a, &mut b);
    let mut d = Vector5::zeros();
    space.minus_into(&b, y, &mut d);
    assert!(d.norm() < TOL, "x ⊞ (y ⊟ x) = {b}, y = {y}");
}

proptest! {
    #![proptest_config(config(96, 0x3a41))]

    #[test]
    fn attitude_error_rules(x in ball(2.5), y in ball(2.5), d in ball(0.5), rest in prop::array::uniform6(-5.0..5.0f64)) {
        // The block at components 1..4 of a 5-state, so the offset matters.
        let v = |a: &Vector3<f64>, r0: f64, r1: f64| Vector5::new(r0, a[0], a[1], a[2], r1);
        rules(&AttitudeError::at(1), &v(&x, rest[0], rest[1]), &v(&y, rest[2], rest[3]), &v(&d, rest[4], rest[5]));
    }

    #[test]
    fn wrapped_angle_rules(x in prop::array::uniform5(-PI..PI), y in prop::array::uniform5(-PI..PI), d in prop::array::uniform5(-3.0..3.0f64)) {
        let (x, y, d) = (Vector5::from(x), Vector5::from(y), Vector5::from(d));
        rules(&WrappedAngles::new([0, 3]), &x, &y, &d);
        // The wrapped components stay in (−π, π]; the others are plain sums.
        let mut out = Vector5::zeros();
        WrappedAngles::new([0, 3]).plus_into(&x, &(d * 3.0), &mut out);
        prop_assert!(out[0] > -PI && out[0] <= PI && out[3] > -PI && out[3] <= PI);
        prop_assert_eq!(out[1], x[1] + d[1] * 3.0);
    }

    #[test]
    fn exp_and_log_match_axis_angle(v in ball(PI)) {
        let q = so3_exp(&v);
        let reference = UnitQuaternion::from_scaled_axis(v);
        prop_assert!(q.angle_to(&reference) < TOL, "{q} vs {reference}");
        prop_assert!((so3_log(&q) - v).norm() < TOL * 10.0);
        // −q is the same rotation.
        let minus = UnitQuaternion::new_unchecked(-q.into_inner());
        prop_assert!((so3_log(&minus) - v).norm() < TOL * 10.0);
    }
}

#[test]
fn small_angles_keep_full_precision() {
    // Sigma points of a UKF with α = 10⁻³ are ≈ 10⁻⁴ rad apart: Exp/Log must not lose them
    // (acos-based angles would, at ≈ √ε ≈ 10⁻⁸ absolute).
    for scale in [1e-3, 1e-6, 1e-9, 1e-12] {
        let v = Vector3::new(0.3, -0.5, 0.8) * scale;
        let back = so3_log(&so3_exp(&v));
        assert!(
            (back - v).norm() <= 4.0 * f64::EPSILON * v.norm(),
            "{scale}: {back} vs {v}"
        );
    }
}

#[test]
fn quaternion_stays_unit_over_a_million_steps() {
    // 10⁶ body-rate steps of the reference, and 10⁶ ⊞ compositions of the error state with
    // recentring: the norm stays within a few ε of 1 (renormalised each time; without it the
    // error would grow like √steps · ε or worse).
    let mut reference = AttitudeReference::new(UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3));
    let omega = Vector3::new(0.7, -1.3, 2.9);
    let space = AttitudeError::at(0);
    let mut x = DVector::zeros(4);
    let step = DVector::from_vec(vec![1e-3, 2e-3, -3e-3, 1.0]);
    let mut worst: f64 = 0.0;
    let mut out = x.clone();
    for _ in 0..1_000_000 {
        reference.rotate(&omega, 0.01);
        space.plus_into(&x, &step, &mut out);
        std::mem::swap(&mut x, &mut out);
        reference.recentre(&mut x, 0).unwrap();
        let norm: f64 = reference.quaternion().as_ref().norm();
        worst = worst.max((norm - 1.0).abs());
    }
    assert!(worst <= 4.0 * f64::EPSILON, "worst |‖q‖ − 1| = {worst:e}");
    assert_eq!(x[3], 1e6, "the plain component adds exactly");
}

#[test]
fn recentring_keeps_the_attitude() {
    let mut reference = AttitudeReference::new(UnitQuaternion::from_euler_angles(-1.0, 0.5, 2.0));
    let mut x = Vector4::new(7.0, 0.2, -0.4, 1.1);
    let before = reference.attitude(&x, 1).unwrap();
    reference.recentre(&mut x, 1).unwrap();
    assert_eq!(x, Vector4::new(7.0, 0.0, 0.0, 0.0));
    assert!(reference.attitude(&x, 1).unwrap().angle_to(&before) < TOL);
}

/// A state too short for the attitude block (`at(2)` needs 5 components, the state has 4):
/// `check`, `attitude` and `recentre` return the typed error (and `recentre` changes
/// nothing), ⊞ and ⊟ give NaN in every component (a filter then fails its step with a typed
/// error: estim-filters' `state_space` tests). Before, each of them panicked.
#[test]
fn a_state_without_the_attitude_block_is_a_typed_error() {
    let short = Error::DimensionMismatch {
        stage: Stage::Construction,
        quantity: Quantity::Mean,
        expected_rows: 5,
        expected_cols: 1,
        found_rows: 4,
        found_cols: 1,
    };
    let space = AttitudeError::at(2);
    assert_eq!(space.check(4), Err(short));
    assert_eq!(space.check(5), Ok(()));
    let mut reference = AttitudeReference::new(UnitQuaternion::from_euler_angles(0.3, 0.2, 0.1));
    let kept = reference;
    let mut x = Vector4::new(0.1, 0.2, 0.3, 0.4);
    assert_eq!(reference.attitude(&x, 2), Err(short));
    assert_eq!(reference.recentre(&mut x, 2), Err(short));
    assert_eq!((reference, x), (kept, Vector4::new(0.1, 0.2, 0.3, 0.4)));
    let mut out = Vector4::<f64>::zeros();
    space.plus_into(&x, &x, &mut out);
    assert!(out.iter().all(|v| v.is_nan()), "x ⊞ δ = {out:?}");
    let mut out = DVector::<f64>::zeros(0);
    space.minus_into(&DVector::zeros(4), &DVector::zeros(4), &mut out);
    assert!(
        out.len() == 4 && out.iter().all(|v| v.is_nan()),
        "a ⊟ b = {out:?}"
    );
}

#[cfg(feature = "autodiff")]
mod rodrigues {
    use super::*;
    use estim_core::autodiff::{AdScalar, AutoDiff, AutoDiffFunction, rotation_exp};
    use estim_core::nalgebra::{Matrix3, OVector, U3, U9};
    use estim_core::{Differentiable, TwiceDifferentiable};

    /// v ↦ vec R(Exp(v)).
    struct Flattened;
    impl AutoDiffFunction<f64, U3, U9> for Flattened {
        fn eval<D: AdScalar<f64>>(&self, v: &Vector3<D>) -> OVector<D, U9> {
            OVector::<D, U9>::from_column_slice(rotation_exp::<f64, D>(v).as_slice())
        }
    }

    proptest! {
        #![proptest_config(config(96, 0x70d5))]

        #[test]
        fn rodrigues_is_exp(v in ball(PI)) {
            let r = rotation_exp::<f64, f64>(&v);
            let want = so3_exp(&v).to_rotation_matrix().into_inner();
            prop_assert!((r - want).norm() < TOL, "{r} vs {want}");
        }
    }

    #[test]
    fn derivatives_at_zero_are_the_generators() {
        // R(Exp(v)) = I + [v]× + ½[v]×² + O(|v|³): ∂R/∂vⱼ = [eⱼ]×, ∂²R/∂vᵢ∂vⱼ = ½([eᵢ]×[eⱼ]× +
        // [eⱼ]×[eᵢ]×), exactly (the series branch at 0).
        let g = AutoDiff::new(Flattened);
        let zero = Vector3::zeros();
        let j = g.jacobian(&zero);
        let cross = |e: &Vector3<f64>| e.cross_matrix();
        let e = |i| Vector3::ith(i, 1.0);
        for c in 0..3 {
            let want = cross(&e(c));
            assert_eq!(j.column(c).as_slice(), want.as_slice(), "column {c}");
        }
        for k in 0..9 {
            let h = g.hessian(&zero, k).unwrap_or_else(Matrix3::zeros);
            for a in 0..3 {
                for b in 0..3 {
                    let want = 0.5 * (cross(&e(a)) * cross(&e(b)) + cross(&e(b)) * cross(&e(a)));
                    assert_eq!(h[(a, b)], want.as_slice()[k], "entry {k}, ({a}, {b})");
                }
            }
        }
    }
}
