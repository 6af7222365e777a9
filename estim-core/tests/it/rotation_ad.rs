//! The rotation helpers over a dual-number scalar (`autodiff::so3_exp`, `so3_log` and the
//! quaternion products): their values equal the `f64` helpers of `manifold`, and automatic
//! derivatives through them equal the closed-form derivatives of the rotation group, so a
//! quaternion error state can be differentiated automatically (issue 38).
//!
//! Tolerances: values are a few quaternion products, a sin_cos and an atan2 on angles ≤ π,
//! each a few ulps: 1e-12 absolute (≈ 30 ε · π with margin), as in `manifold`. The derivative
//! entries are O(1) (|J| ≤ π/2 · … for angles ≤ 2.5) and go through the same few operations
//! on duals, so the same 1e-12 holds; a wrong derivative (a missing term, the left Jacobian
//! for the right one) is off by O(|a|) ≥ 0.1.

use core::f64::consts::PI;

use crate::common::config;
use estim_core::autodiff::{
    AdScalar, AutoDiff, AutoDiffFunction, quaternion_conjugate, quaternion_lift,
    quaternion_product, quaternion_rotate, so3_exp, so3_log,
};
use estim_core::manifold;
use estim_core::nalgebra::{Matrix3, U3, UnitQuaternion, Vector3};
use estim_core::{Differentiable, TwiceDifferentiable};
use proptest::prelude::*;

/// See the module docs.
const TOL: f64 = 1e-12;

fn ball(radius: f64) -> impl Strategy<Value = Vector3<f64>> {
    prop::array::uniform3(-1.0..1.0f64)
        .prop_filter("inside the unit ball", |v| Vector3::from(*v).norm() <= 1.0)
        .prop_map(move |v| Vector3::from(v) * radius)
}

/// δ ↦ Log(Exp(a) ⊗ Exp(δ)): the attitude-error composition of `AttitudeError`'s ⊞.
struct Compose(Vector3<f64>);
impl AutoDiffFunction<f64, U3, U3> for Compose {
    fn eval<D: AdScalar<f64>>(&self, d: &Vector3<D>) -> Vector3<D> {
        let a = so3_exp::<f64, D>(&self.0.map(D::from));
        so3_log::<f64, D>(&quaternion_product(&a, &so3_exp(d)))
    }
}

/// δθ ↦ R(q_ref ⊗ Exp(δθ))ᵀ m: a magnetometer about a reference attitude.
struct BodyField {
    reference: UnitQuaternion<f64>,
    field: Vector3<f64>,
}
impl AutoDiffFunction<f64, U3, U3> for BodyField {
    fn eval<D: AdScalar<f64>>(&self, d: &Vector3<D>) -> Vector3<D> {
        let q = quaternion_product(&quaternion_lift::<f64, D>(&self.reference), &so3_exp(d));
        quaternion_rotate(&quaternion_conjugate(&q), &self.field.map(D::from))
    }
}

/// J_r⁻¹(φ) = I + ½[φ]× + (1/θ² − (1 + cos θ)/(2θ sin θ))[φ]×²: the inverse right Jacobian
/// of SO(3) (Chirikjian 2011; Solà et al. 2018, eq. 144), d Log(Exp(φ) Exp(δ))/dδ at δ = 0.
fn inverse_right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    let c = 1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin());
    Matrix3::identity() + k * 0.5 + k * k * c
}

proptest! {
    #![proptest_config(config(96, 0x38a1))]

    #[test]
    fn generic_exp_and_log_are_the_f64_ones(v in ball(PI - 0.01), w in ball(2.5)) {
        let q = so3_exp::<f64, f64>(&v);
        let want = manifold::so3_exp(&v);
        prop_assert!((q.coords - want.as_ref().coords).norm() < TOL, "{q} vs {want}");
        let back = so3_log::<f64, f64>(&q);
        prop_assert!((back - manifold::so3_log(&want)).norm() < TOL);
        let composed = so3_log::<f64, f64>(&quaternion_product(&so3_exp(&w), &q));
        let want = manifold::so3_log(&(manifold::so3_exp(&w) * manifold::so3_exp(&v)));
        prop_assert!((composed - want).norm() < TOL);
        let u = Vector3::new(0.3, -0.7, 1.1);
        let rotated = quaternion_rotate::<f64, f64>(&q, &u);
        prop_assert!((rotated - manifold::so3_exp(&v) * u).norm() < TOL);
    }

    #[test]
    fn ad_jacobian_of_the_composition_is_the_inverse_right_jacobian(a in ball(2.5)) {
        prop_assume!(a.norm() > 1e-3); // the closed form divides by θ² (the AD side does not)
        let j = AutoDiff::new(Compose(a)).jacobian(&Vector3::zeros());
        let want = inverse_right_jacobian(&a);
        prop_assert!((j - want).norm() < TOL, "{j} vs {want}");
    }

    #[test]
    fn ad_jacobian_of_a_rotated_field_is_the_cross_matrix(v in ball(PI - 0.01)) {
        let (reference, field) = (manifold::so3_exp(&v), Vector3::new(0.21, -0.03, 0.44));
        let j = AutoDiff::new(BodyField { reference, field }).jacobian(&Vector3::zeros());
        // b = (R Exp(δθ))ᵀ m ≈ (I − [δθ]×) Rᵀ m = Rᵀ m + [Rᵀ m]× δθ.
        let want = (reference.inverse() * field).cross_matrix();
        prop_assert!((j - want).norm() < TOL, "{j} vs {want}");
    }
}

#[test]
fn log_of_exp_is_the_identity_with_zero_hessians_at_the_identity() {
    // Log(Exp(v)) = v: Jacobian I and Hessians 0, also through the series branches at v = 0.
    struct RoundTrip;
    impl AutoDiffFunction<f64, U3, U3> for RoundTrip {
        fn eval<D: AdScalar<f64>>(&self, v: &Vector3<D>) -> Vector3<D> {
            so3_log::<f64, D>(&so3_exp(v))
        }
    }
    let g = AutoDiff::new(RoundTrip);
    for v in [
        Vector3::zeros(),
        Vector3::new(1e-5, -2e-5, 0.0),
        Vector3::new(0.4, 1.0, -2.0),
    ] {
        let j = g.jacobian(&v);
        assert!((j - Matrix3::identity()).norm() < TOL, "at {v}: {j}");
        for k in 0..3 {
            let h = g.hessian(&v, k).unwrap_or_else(Matrix3::zeros);
            assert!(h.norm() < 1e-10, "at {v}, component {k}: {h}");
        }
    }
}
