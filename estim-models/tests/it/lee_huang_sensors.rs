//! Appendix B: the four-accelerometer forward model and its inversion.

use estim_models::lee_huang::{FourAccelerometers, Plane, RigidBodyMotion, rotation};
use nalgebra::{Vector2, Vector3, Vector4};
use proptest::prelude::*;

fn motion(theta: f64, w: f64, wdot: f64, ax: f64, ay: f64) -> RigidBodyMotion {
    RigidBodyMotion {
        attitude: theta,
        rate: w,
        angular_acceleration: wdot,
        acceleration: Vector2::new(ax, ay),
    }
}

fn gravity(vertical: bool) -> Vector2<f64> {
    if vertical {
        Plane::Vertical.gravity()
    } else {
        Plane::Horizontal.gravity()
    }
}

proptest! {
    /// The inversion (corrected signs, 1/ρ) recovers f_b = Rᵀ(a − g_vec) and ω̇ from the
    /// forward model, which computes each sensor's full rigid-body acceleration (tangential and
    /// centripetal terms included). Tolerance 1e-12 relative: both sides are a few flops on
    /// O(100) numbers.
    #[test]
    fn inversion_recovers_specific_force_and_angular_acceleration(
        theta in -3.2f64..3.2, w in -5.0f64..5.0, wdot in -20.0f64..20.0,
        ax in -50.0f64..50.0, ay in -50.0f64..50.0, rho in 0.05f64..2.0, vertical: bool,
    ) {
        let sensors = FourAccelerometers { radius: rho };
        let m = motion(theta, w, wdot, ax, ay);
        let g = gravity(vertical);
        let y = sensors.derived_inputs(&sensors.signals(&m, &g));
        let fb = m.body_specific_force(&g);
        let scale = 1.0 + fb.norm() + wdot.abs() + w * w * rho;
        prop_assert!((y.x - fb.x).abs() <= 1e-12 * scale, "y_ax {} vs f_bx {}", y.x, fb.x);
        prop_assert!((y.y - fb.y).abs() <= 1e-12 * scale, "y_ay {} vs f_by {}", y.y, fb.y);
        prop_assert!((y.z - wdot).abs() <= 1e-12 * scale / rho, "y_wdot {} vs {}", y.z, wdot);
    }

    /// Erratum E1: the printed y_ay = −(A₂ − A₄)/2 returns −f_by.
    #[test]
    fn printed_y_ay_sign_returns_minus_f_by(
        theta in -3.2f64..3.2, w in -5.0f64..5.0, wdot in -20.0f64..20.0,
        ax in -50.0f64..50.0, ay in -50.0f64..50.0,
    ) {
        let sensors = FourAccelerometers::default();
        let m = motion(theta, w, wdot, ax, ay);
        let g = Vector2::zeros();
        let printed = sensors.derived_inputs_as_printed(&sensors.signals(&m, &g));
        let fb = m.body_specific_force(&g);
        prop_assert!((printed.y + fb.y).abs() <= 1e-12 * (1.0 + fb.norm() + wdot.abs() + w * w));
    }

    /// Eq 60 read per sensor: Aᵢ = first component of [[cos φᵢ, sin φᵢ], [−sin φᵢ, cos φᵢ]]
    /// (a − g_vec) + ρ ω̇, φᵢ = θ + (i−1)π/2, with no second "· β" and the centripetal term
    /// dropping out (erratum E5). Agrees with the forward model to round-off.
    #[test]
    fn eq60_per_sensor_rotation_reading_matches_forward_model(
        theta in -3.2f64..3.2, w in -5.0f64..5.0, wdot in -20.0f64..20.0,
        ax in -50.0f64..50.0, ay in -50.0f64..50.0, vertical: bool,
    ) {
        let sensors = FourAccelerometers::default();
        let m = motion(theta, w, wdot, ax, ay);
        let g = gravity(vertical);
        let a = sensors.signals(&m, &g);
        let f = m.acceleration - g;
        for i in 0..4 {
            let phi = theta + i as f64 * std::f64::consts::FRAC_PI_2;
            let eq60 = phi.cos() * f.x + phi.sin() * f.y + wdot;
            prop_assert!((a[i] - eq60).abs() <= 1e-12 * (1.0 + f.norm() + wdot.abs() + w * w));
        }
    }
}

/// The forward model against an independent route: the sensor point's position along an
/// analytic trajectory (CG polynomial in t, θ cubic in t), differentiated twice by central
/// differences, minus gravity, projected on the rotated sensing direction. Tolerance 1e-5
/// relative: the second difference with h = 1e-4 has truncation O(h²·|x⁗|) ≈ 1e-8 and
/// round-off O(ε|x|/h²) ≈ 1e-8 on these magnitudes.
#[test]
fn forward_model_matches_finite_difference_of_sensor_points() {
    let sensors = FourAccelerometers { radius: 0.7 };
    let cg = |t: f64| {
        Vector2::new(
            3.0 + 2.0 * t + 4.0 * t * t,
            -1.0 + 0.5 * t - 3.0 * t * t * t,
        )
    };
    let theta = |t: f64| 0.4 + 1.5 * t - 0.8 * t * t + 0.3 * t * t * t;
    for &t in &[0.0, 0.37, 1.2] {
        let w = 1.5 - 1.6 * t + 0.9 * t * t;
        let wdot = -1.6 + 1.8 * t;
        let a = Vector2::new(8.0, -18.0 * t);
        for vertical in [false, true] {
            let g = gravity(vertical);
            let signals = sensors.signals(&motion(theta(t), w, wdot, a.x, a.y), &g);
            for (i, (l, beta)) in sensors
                .locations()
                .iter()
                .zip(sensors.directions().iter())
                .enumerate()
            {
                let point = |s: f64| cg(s) + rotation(theta(s)) * l;
                let h = 1e-4;
                let acc = (point(t + h) - point(t) * 2.0 + point(t - h)) / (h * h);
                let reading = (acc - g).dot(&(rotation(theta(t)) * beta));
                assert!(
                    (reading - signals[i]).abs() < 1e-5 * (1.0 + reading.abs()),
                    "sensor {i} at t = {t}: finite differences {reading}, model {}",
                    signals[i]
                );
            }
        }
    }
}

/// The centripetal term is perpendicular to every βᵢ: a pure spin (no ω̇, no translation) gives
/// zero on all four sensors in the horizontal plane.
#[test]
fn centripetal_term_drops_out() {
    let sensors = FourAccelerometers { radius: 1.3 };
    let a = sensors.signals(&motion(0.9, 7.0, 0.0, 0.0, 0.0), &Vector2::zeros());
    assert!(a.amax() < 1e-12, "{a}");
}

/// Erratum E13: ΣA/4 is ρ ω̇, so the printed y_ω̇ equals ω̇ only for ρ = 1.
#[test]
fn printed_angular_acceleration_needs_one_over_rho() {
    let sensors = FourAccelerometers { radius: 0.5 };
    let m = motion(0.2, 1.0, 3.0, 1.0, 2.0);
    let a = sensors.signals(&m, &Vector2::zeros());
    assert!((sensors.derived_inputs(&a).z - 3.0).abs() < 1e-12);
    assert!((sensors.derived_inputs_as_printed(&a).z - 1.5).abs() < 1e-12);
}

/// The per-sensor bias mapping gives back the requested derived-input bias, and a bias common
/// to all sensors appears only in y_ω̇.
#[test]
fn sensor_bias_mapping_round_trips() {
    for rho in [0.3, 1.0, 2.0] {
        let sensors = FourAccelerometers { radius: rho };
        let b = Vector3::new(0.098, -0.05, 0.02);
        let raw = sensors.sensor_bias_for(&b);
        assert!((sensors.derived_inputs(&raw) - b).amax() < 1e-15);
        let common = sensors.derived_inputs(&Vector4::repeat(0.1));
        assert!(common.x.abs() < 1e-15 && common.y.abs() < 1e-15);
        assert!((common.z - 0.1 / rho).abs() < 1e-15);
    }
}
