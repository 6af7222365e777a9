//! Boje: every model's analytic Jacobian and Hessians against central finite differences of its
//! values (estim-core's derivative checker), at random points (proptest).
//!
//! Tolerance 1e-6 on |analytic − numeric| / max(1, |numeric|): with the checker's step
//! h = ε^⅓ max(1, |x|) the truncation error is ≈ h² |f'''| / 6 ≈ 4·10⁻¹¹ |f'''| and the
//! round-off ≈ ε |f| / h ≈ 4·10⁻¹¹ |f|; the inputs below keep |f|, |f'''| ≤ ~10³ (accelerations
//! ≤ 50 m/s², R ≥ 0.1 m), so correct derivatives pass with margin and a wrong entry (error O(1)
//! relative) cannot.

use estim_core::derivative::{check_derivatives, check_measurement_model, check_process_model};
use estim_core::nalgebra::{Vector1, Vector2, Vector4, Vector5, Vector6};
use estim_models::boje::{
    AccelerometerInversion, ChannelVariances, NonlinearPlanarProcess, PlanarInput, PlanarProcess,
    PositionHeadingMeasurement, RateSquaredMeasurement, ScalarRateProcess, ScalarRateSquared,
    TrigProducts, planar_input,
};
use proptest::prelude::*;

const TOL: f64 = 1e-6;

fn vec6() -> impl Strategy<Value = Vector6<f64>> {
    (
        -20.0..20.0f64,
        -20.0..20.0f64,
        -3.0..3.0f64,
        -50.0..50.0f64,
        -50.0..50.0f64,
        -10.0..10.0f64,
    )
        .prop_map(|(a, b, c, d, e, f)| Vector6::new(a, b, c, d, e, f))
}

fn accel() -> impl Strategy<Value = Vector4<f64>> {
    (
        -50.0..50.0f64,
        -50.0..50.0f64,
        -50.0..50.0f64,
        -50.0..50.0f64,
    )
        .prop_map(|(a, b, c, d)| Vector4::new(a, b, c, d))
}

fn variances() -> impl Strategy<Value = ChannelVariances> {
    (1e-4..1e-1f64, 1e-4..1e-1f64, 1e-4..1e-1f64, 1e-4..1e-1f64)
        .prop_map(|(a, b, c, d)| ChannelVariances::from_std(a, b, c, d))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Eq 5 as a function of z = (θ, a_u1, a_v1, a_u2, a_v2).
    #[test]
    fn inversion_eq5_derivatives(theta in -10.0..10.0f64, a in accel(), r in 0.1..2.0f64) {
        let g = AccelerometerInversion { half_separation: r };
        let z = Vector5::new(theta, a[0], a[1], a[2], a[3]);
        let rep = check_derivatives(&g, &z).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
    }

    /// (cos θ, sin θ, x cos θ, x sin θ) of the eq 8–11 examples.
    #[test]
    fn trig_products_derivatives(x in -10.0..10.0f64, theta in -10.0..10.0f64) {
        let rep = check_derivatives(&TrigProducts, &Vector2::new(x, theta)).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
    }

    /// θ̇² = x[2]² and the GPS/compass model.
    #[test]
    fn measurement_models_derivatives(x in vec6(), r in 1e-6..1.0f64) {
        let rep = check_measurement_model(&RateSquaredMeasurement { noise: r }, &x).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
        let fix = PositionHeadingMeasurement { sigma_xy: 1.0, sigma_theta: 0.1 };
        let rep = check_measurement_model(&fix, &x).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
    }

    /// The paper's linear process (its Hessians are zero through the LinearProcessModel
    /// marker, which the checker confirms).
    #[test]
    fn linear_process_derivatives(x in vec6(), a in accel(), v in variances(), dt in 1e-3..0.1f64, pth in 0.0..0.1f64) {
        let process = PlanarProcess { half_separation: 0.5, variances: v };
        let input: PlanarInput = planar_input(&a, x[5], pth, 0.5, v).unwrap();
        let rep = check_process_model(&process, &x, &input, dt).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
    }

    /// The variant with θ inside f through eq 5.
    #[test]
    fn nonlinear_process_derivatives(x in vec6(), a in accel(), v in variances(), dt in 1e-3..0.1f64, r in 0.1..2.0f64) {
        let process = NonlinearPlanarProcess { half_separation: r, variances: v };
        let rep = check_process_model(&process, &x, &a, dt).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
    }

    /// Section 3's scalar sub-model.
    #[test]
    fn scalar_rate_models_derivatives(w in -20.0..20.0f64, u in -100.0..100.0f64, dt in 1e-3..0.1f64) {
        let x = Vector1::new(w);
        let rep = check_process_model(&ScalarRateProcess { angular_accel_variance: 1e-3 }, &x, &u, dt).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
        let rep = check_measurement_model(&ScalarRateSquared { noise: 1e-3 }, &x).unwrap();
        prop_assert!(rep.is_accurate(TOL), "{rep}");
    }
}
