//! The Schmidt-Kalman consider update against its closed-form equations on a linear example:
//! K = [K_a; 0] with K_a the optimal gain's a-rows, P⁺ by the general Joseph form
//! (I − KH) P (I − KH)ᵀ + K R Kᵀ (valid for any gain), x⁺ = x + Kν.

use crate::common::{gaussian_matrix, random_spd, rng};
use estim_core::nalgebra::{Matrix2x4, Matrix4, U2, U4, Vector2, Vector4};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::consider::schmidt_update;
use estim_filters::{Ekf, Estimator, KalmanFilter, Predict, SrKalmanFilter};

/// Four states, the last two considered; two measurements touching all four; three update
/// and predict cycles. The filter (Joseph form from the full gain, then the blocks put back)
/// and the closed form (Joseph form with the Schmidt gain) are different routes: they agree to
/// rounding, ≲ 10⁻¹³ relative with κ(S), κ(P) ≲ 10² here; 10⁻¹² is the tolerance.
#[test]
fn schmidt_update_matches_the_closed_form() {
    let mut g = rng(0x5c4);
    let h: Matrix2x4<f64> = gaussian_matrix(&mut g, U2, U4);
    let r = random_spd(&mut g, U2, 0.5, 0.1);
    let sensor = LinearMeasurement {
        observation: h,
        noise: r,
    };
    let process = LinearProcess {
        transition: Matrix4::identity() + gaussian_matrix(&mut g, U4, U4) * 0.05,
        input: gaussian_matrix(&mut g, U4, U2),
        noise: random_spd(&mut g, U4, 0.01, 1e-3),
    };
    let prior = Gaussian::new(
        Vector4::new(1.0, -1.0, 0.3, 0.2),
        random_spd(&mut g, U4, 1.0, 0.1),
    )
    .unwrap();
    let (mut x, mut p) = (*prior.mean(), *prior.covariance());
    let mut kf = KalmanFilter::new(prior.clone());
    let mut ekf = Ekf::new(prior.clone());
    let mut sr = SrKalmanFilter::new(prior);
    let consider = [2, 3];
    for step in 0..3 {
        let z = Vector2::new(0.5 * step as f64, -0.3);
        let cc_before = kf.covariance().fixed_view::<2, 2>(2, 2).into_owned();
        let c_before = kf.state().fixed_rows::<2>(2).into_owned();
        // Closed form.
        let s = h * p * h.transpose() + r;
        let k_full = (s.lu().solve(&(h * p)).unwrap()).transpose();
        let mut k = k_full;
        k.fixed_rows_mut::<2>(2).fill(0.0);
        let nu = z - h * x;
        x += k * nu;
        let i_kh = Matrix4::identity() - k * h;
        p = i_kh * p * i_kh.transpose() + k * r * k.transpose();
        // The filters.
        schmidt_update(&mut kf, &sensor, &z, &consider).unwrap();
        schmidt_update(&mut ekf, &sensor, &z, &consider).unwrap();
        schmidt_update(&mut sr, &sensor, &z, &consider).unwrap();
        for (name, state, cov) in [
            ("kf", kf.state(), kf.covariance()),
            ("ekf", ekf.state(), ekf.covariance()),
            ("sr", sr.state(), sr.covariance()),
        ] {
            assert!(
                (state - x).amax() <= 1e-12 * x.amax().max(1.0),
                "{name} step {step}: x {state} vs {x}"
            );
            assert!(
                (cov - p).amax() <= 1e-12 * p.amax(),
                "{name} step {step}: P {cov} vs {p}"
            );
        }
        // The consider states and their covariance block are exactly what they were.
        assert_eq!(kf.covariance().fixed_view::<2, 2>(2, 2), cc_before);
        assert_eq!(kf.state().fixed_rows::<2>(2), c_before);
        let u = Vector2::new(0.1, 0.2);
        kf.predict(&process, &u, 1.0).unwrap();
        ekf.predict(&process, &u, 1.0).unwrap();
        sr.predict(&process, &u, 1.0).unwrap();
        x = process.transition * x + process.input * u;
        p = process.transition * p * process.transition.transpose() + process.noise;
    }
}

/// Nothing considered: the filter's own update, bit for bit.
#[test]
fn nothing_considered_is_the_plain_update() {
    let mut g = rng(0x5c5);
    let sensor = LinearMeasurement {
        observation: gaussian_matrix(&mut g, U2, U4),
        noise: random_spd(&mut g, U2, 0.5, 0.1),
    };
    let prior = Gaussian::new(Vector4::zeros(), random_spd(&mut g, U4, 1.0, 0.1)).unwrap();
    let mut a = KalmanFilter::new(prior.clone());
    let mut b = KalmanFilter::new(prior);
    let z = Vector2::new(1.0, 2.0);
    let ra = schmidt_update(&mut a, &sensor, &z, &[]).unwrap();
    let rb = estim_filters::Update::update(&mut b, &sensor, &z).unwrap();
    assert_eq!(ra, rb);
    assert_eq!(a.estimate(), b.estimate());
}
