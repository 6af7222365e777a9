//! The INS process models, the attitude measurement, the velocity likelihood g(D) and the
//! simulator's truth.

use estim_core::derivative::{
    check_derivatives, check_measurement_model, check_process_jacobian, check_process_model,
};
use estim_core::propagate::{MomentPropagator, Unscented};
use estim_core::{MeasurementModel, ProcessJacobian, ProcessModel, VectorFunction};
use estim_models::lee_huang::{
    AttitudeMeasurement, CkfInput, Discretization, InsProcess, Plane, Scenario, VelocityLikelihood,
    transition_matrix, velocity_likelihood_as_printed,
};
use nalgebra::{DMatrix, Matrix3, RowVector6, U3, U6, Vector1, Vector2, Vector3, Vector6};
use proptest::prelude::*;

fn process(discretization: Discretization, plane: Plane) -> InsProcess {
    InsProcess {
        input_noise: Matrix3::from_diagonal(&Vector3::new(1e-4, 2e-4, 3e-4)),
        discretization,
        plane,
    }
}

fn state() -> impl Strategy<Value = Vector6<f64>> {
    (
        -1e3f64..1e3,
        -1e3f64..1e3,
        -100f64..100.0,
        -100f64..100.0,
        -3.2f64..3.2,
        -2f64..2.0,
    )
        .prop_map(|(a, b, c, d, e, f)| Vector6::new(a, b, c, d, e, f))
}

fn input() -> impl Strategy<Value = Vector3<f64>> {
    (-40f64..40.0, -40f64..40.0, -10f64..10.0).prop_map(|(a, b, c)| Vector3::new(a, b, c))
}

// The checker's mixed error |analytic − numeric| / max(1, |numeric|): 1e-6 is its documented
// bound for correct f64 derivatives of smooth, well-scaled functions (FD error ≈ 1e-10 × the
// third derivative; here the state reaches 1e3, so steps are relative and the bound holds).
const TOL: f64 = 1e-6;

proptest! {
    /// InsProcess: Jacobian (incl. the θ → velocity column) and Hessians, both discretisations,
    /// with and without gravity.
    #[test]
    fn ins_process_derivatives_pass_the_checker(
        x in state(), u in input(), dt in 0.001f64..0.5, zoh: bool, vertical: bool,
    ) {
        let d = if zoh { Discretization::ZeroOrderHold } else { Discretization::Euler };
        let p = if vertical { Plane::Vertical } else { Plane::Horizontal };
        let report = check_process_model(&process(d, p), &x, &u, dt).unwrap();
        prop_assert!(report.is_accurate(TOL), "{report}");
    }

    /// CkfProcess is affine in D with Jacobian Ψ (so its declared zero Hessians are right too).
    #[test]
    fn ckf_process_is_affine_with_jacobian_psi(
        x in state(), u in input(), attitude in -3.2f64..3.2, dt in 0.001f64..0.5,
    ) {
        let ckf = process(Discretization::ZeroOrderHold, Plane::Horizontal).ckf();
        let input = CkfInput { signals: u, attitude };
        let report = check_process_model(&ckf, &x, &input, dt).unwrap();
        prop_assert!(report.is_accurate(TOL), "{report}");
        prop_assert_eq!(ckf.transition_jacobian(&x, &input, dt), transition_matrix(dt));
    }

    /// g(D) of eq 27/28: Jacobian and both Hessians, away from d = 0 (|p| ≥ 1 m).
    #[test]
    fn velocity_likelihood_derivatives_pass_the_checker(
        r in 1.0f64..5e3, bearing in -3.2f64..3.2, vx in -300f64..300.0, vy in -300f64..300.0,
        theta in -3.2f64..3.2, w in -0.5f64..0.5,
    ) {
        let x = Vector6::new(r * bearing.cos(), r * bearing.sin(), vx, vy, theta, w);
        let report = check_derivatives(&VelocityLikelihood, &x).unwrap();
        prop_assert!(report.is_accurate(TOL), "{report}");
    }

    /// The attitude measurement (linear, H = e₄ᵀ) and its wrapped residual.
    #[test]
    fn attitude_measurement_derivatives_and_wrapping(x in state(), a in -3.1f64..3.1, b in -3.1f64..3.1) {
        let m = AttitudeMeasurement { variance: 1.0 };
        let report = check_measurement_model(&m, &x).unwrap();
        prop_assert!(report.is_accurate(TOL), "{report}");
        let mut r = Vector1::zeros();
        m.residual_into(&Vector1::new(a), &Vector1::new(b), &mut r);
        let r = r[0];
        prop_assert!(r > -std::f64::consts::PI && r <= std::f64::consts::PI);
        prop_assert!(((r - (a - b)) / std::f64::consts::TAU).fract().abs() < 1e-12
            || ((r - (a - b)) / std::f64::consts::TAU).fract().abs() > 1.0 - 1e-12);
    }
}

/// The paper's CKF Jacobian Ψ is not the model's Jacobian: the finite-difference Jacobian of
/// f(D, u) = Ψ D + G_d(θ) u differs from Ψ exactly in column θ, rows x, y, v_x, v_y, by
/// ∂(G_d u)/∂θ — the coupling the CKF drops. (The checker must *fail* on Ψ.)
#[test]
fn paper_ckf_jacobian_drops_attitude_velocity_coupling() {
    let full = process(Discretization::ZeroOrderHold, Plane::Horizontal);
    let x = Vector6::new(10.0, 5.0, 2.0, 2.0, 30f64.to_radians(), 0.0);
    let u = Vector3::new(19.6, 0.0, 0.0);
    let dt = 0.01;
    assert!(
        check_process_jacobian(&full, &x, &u, dt)
            .unwrap()
            .is_accurate(TOL)
    );
    let diff = full.transition_jacobian(&x, &u, dt) - transition_matrix(dt);
    let (s, c) = x[4].sin_cos();
    let expected = [
        -0.5 * dt * dt * s * u.x,
        0.5 * dt * dt * c * u.x,
        -dt * s * u.x,
        dt * c * u.x,
    ];
    for i in 0..6 {
        for j in 0..6 {
            let e = if j == 4 && i < 4 { expected[i] } else { 0.0 };
            assert!((diff[(i, j)] - e).abs() < 1e-15, "({i},{j})");
        }
    }
    assert!(
        diff[(3, 4)].abs() > 0.1,
        "v_y depends on theta by T*2g*cos 30deg"
    );
}

/// Position and velocity are unobservable from the attitude: the observability matrix of
/// (Ψ, H = e₄ᵀ) has rank 2 (θ, ω only), so any accelerometer bias drifts the position freely.
#[test]
fn position_and_velocity_are_unobservable_from_attitude() {
    let psi = transition_matrix(0.01);
    let h = RowVector6::new(0.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let mut o = DMatrix::zeros(6, 6);
    let mut row = h;
    for k in 0..6 {
        o.row_mut(k).copy_from(&row);
        row *= psi;
    }
    assert_eq!(o.rank(1e-9), 2);
    // The unobservable directions are exactly x, y, v_x, v_y.
    for j in 0..4 {
        assert!(o.column(j).amax() == 0.0);
    }
}

/// Q = G_d Σ_W G_dᵀ is the covariance of f(D, u + W): the unscented propagator (exact for this
/// affine map of W) on w ↦ f(D, u + w) gives it entry by entry (to round-off, 1e-12 relative).
#[test]
fn process_noise_matches_unscented_propagation_of_input_noise() {
    struct InputNoiseMap<'a> {
        model: &'a InsProcess,
        x: Vector6<f64>,
        u: Vector3<f64>,
        dt: f64,
    }
    impl VectorFunction<f64, U3, U6> for InputNoiseMap<'_> {
        fn eval(&self, w: &Vector3<f64>) -> Vector6<f64> {
            self.model.transition(&self.x, &(self.u + w), self.dt)
        }
    }
    for d in [Discretization::ZeroOrderHold, Discretization::Euler] {
        let model = process(d, Plane::Vertical);
        let map = InputNoiseMap {
            model: &model,
            x: Vector6::new(10.0, 5.0, 2.0, 2.0, 0.7, 0.1),
            u: Vector3::new(19.6, -3.0, 0.5),
            dt: 0.05,
        };
        let moments = Unscented::default()
            .propagate(&Vector3::zeros(), &model.input_noise, &map)
            .unwrap();
        let q = model.process_noise(&map.x, &map.u, map.dt);
        let scale = q.amax();
        assert!(
            (moments.covariance - q).amax() < 1e-9 * scale,
            "{d:?}: {}",
            moments.covariance - q
        );
    }
}

/// ZOH is exact for the section IV truth (θ, f_b constant): the model fed with the true
/// derived inputs reproduces the closed-form truth after 2000 steps (1e-9 m: round-off of
/// 2000 additions on positions of 4 km).
#[test]
fn zoh_model_reproduces_constant_acceleration_truth() {
    for plane in [Plane::Horizontal, Plane::Vertical] {
        let scenario = Scenario {
            plane,
            ..Scenario::section_iv()
        };
        let model = process(Discretization::ZeroOrderHold, plane);
        let u = Vector3::new(scenario.specific_force.x, scenario.specific_force.y, 0.0);
        let dt = 0.01;
        let mut x = scenario.initial_state;
        for _ in 0..2000 {
            x = model.transition(&x, &u, dt);
        }
        let truth = scenario.state_at(20.0);
        assert!(
            (x - truth).amax() < 1e-9 * truth.amax(),
            "{plane:?}: {}",
            x - truth
        );
    }
}

/// Erratum E7: the paper's Euler step (no T²/2 position term) shifts the position by
/// −½ a T t: at 20 s with a = 2 g, T = 0.01 the offset is 1.96 m along a.
#[test]
fn euler_position_offset_is_half_a_t_t() {
    let scenario = Scenario::section_iv();
    let model = process(Discretization::Euler, Plane::Horizontal);
    let u = Vector3::new(scenario.specific_force.x, 0.0, 0.0);
    let (dt, steps) = (0.01, 2000);
    let mut x = scenario.initial_state;
    for _ in 0..steps {
        x = model.transition(&x, &u, dt);
    }
    let truth = scenario.state_at(20.0);
    let a = nalgebra::Rotation2::new(x[4]) * scenario.specific_force;
    let offset = Vector2::new(x[0] - truth[0], x[1] - truth[1]);
    let predicted = -a * (0.5 * dt * 20.0);
    assert!(
        (offset - predicted).norm() < 1e-9,
        "{offset} vs {predicted}"
    );
    assert!((offset.norm() - 1.961).abs() < 1e-3);
}

/// The simulator's closed-form truth against an independent route: RK4 integration of the
/// continuous equations (ṗ = v, v̇ = R(θ) f_b + g_vec, θ̇ = ω) with ω ≠ 0, and across the
/// series/exact switch at |ω t| = 10⁻². RK4 with h = 1e-3 s over 5 s has global error
/// O(h⁴) ≈ 1e-12 × derivatives; tolerance 1e-7 relative.
#[test]
fn simulator_closed_form_matches_rk4() {
    for (w, plane) in [
        (0.8, Plane::Vertical),
        (-0.3, Plane::Horizontal),
        (1e-3, Plane::Horizontal),
    ] {
        let mut scenario = Scenario {
            plane,
            ..Scenario::section_iv()
        };
        scenario.initial_state[5] = w;
        scenario.specific_force = Vector2::new(12.0, -4.0);
        let deriv = |s: &Vector6<f64>| {
            let a = nalgebra::Rotation2::new(s[4]) * scenario.specific_force + plane.gravity();
            Vector6::new(s[2], s[3], a.x, a.y, s[5], 0.0)
        };
        let h = 1e-3;
        let mut s = scenario.initial_state;
        for k in 1..=5000 {
            let k1 = deriv(&s);
            let k2 = deriv(&(s + k1 * (h / 2.0)));
            let k3 = deriv(&(s + k2 * (h / 2.0)));
            let k4 = deriv(&(s + k3 * h));
            s += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
            if k % 1000 == 0 {
                let t = k as f64 * h;
                let truth = scenario.state_at(t);
                assert!(
                    (s - truth).amax() < 1e-7 * (1.0 + truth.amax()),
                    "w = {w}, t = {t}: {}",
                    s - truth
                );
            }
        }
    }
}

/// Erratum E2: for a curved trajectory given in polar form (d(t), θ(t) = bearing), the
/// velocity from eq 27/28 (the consistent form, with θ the bearing) equals the finite-difference
/// velocity; eq 38/39 as printed do not.
#[test]
fn eq27_28_reproduce_polar_velocity_eq38_39_do_not() {
    let d = |t: f64| 50.0 + 3.0 * t + 0.2 * t * t;
    let bearing = |t: f64| 0.3 + 0.05 * t - 0.01 * t * t;
    let pos = |t: f64| Vector2::new(d(t) * bearing(t).cos(), d(t) * bearing(t).sin());
    let t = 2.0;
    let h = 1e-5;
    let v_fd = (pos(t + h) - pos(t - h)) / (2.0 * h);
    let p = pos(t);
    let rate = (bearing(t + h) - bearing(t - h)) / (2.0 * h);
    // State with θ = bearing and ω = bearing rate: then eq 27/28 are a change of coordinates.
    let x = Vector6::new(p.x, p.y, v_fd.x, v_fd.y, bearing(t), rate);
    let consistent = VelocityLikelihood.eval(&x);
    let printed = velocity_likelihood_as_printed(&x);
    assert!((consistent - v_fd).norm() < 1e-6, "{consistent} vs {v_fd}");
    assert!((printed - v_fd).norm() > 1.0, "{printed} vs {v_fd}");
}

/// Erratum E10: if θ is the bearing of the position and ω its rate (eq 23), g(D) ≡ (v_x, v_y)
/// for any position and velocity: the pseudo-measurement then carries no information. The
/// paper substitutes the body attitude and rate instead.
#[test]
fn likelihood_is_the_velocity_when_theta_is_the_bearing() {
    for (px, py, vx, vy) in [
        (10.0, 5.0, 2.0, 2.0),
        (-300.0, 40.0, 17.0, -90.0),
        (1.0, -1.0, 0.0, 5.0),
    ] {
        let bearing = f64::atan2(py, px);
        let rate = (px * vy - py * vx) / (px * px + py * py);
        let x = Vector6::new(px, py, vx, vy, bearing, rate);
        let g = VelocityLikelihood.eval(&x);
        assert!((g - Vector2::new(vx, vy)).norm() < 1e-12 * (1.0 + g.norm()));
    }
    // With the body attitude of section IV (30°, ω = 0) at t = 0 it is not the velocity.
    let x = Vector6::new(10.0, 5.0, 2.0, 2.0, 30f64.to_radians(), 0.0);
    assert!((VelocityLikelihood.eval(&x) - Vector2::new(2.0, 2.0)).norm() > 0.5);
}
