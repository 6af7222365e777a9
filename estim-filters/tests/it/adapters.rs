//! The model adapters change the call, not the math: a process without input filters exactly
//! like the same process with a zero input, and an offset measurement like the plain one on
//! z − d, in every filter (the offset also through the batched sigma points and Hessians).

use crate::common::{assert_bitwise_eq, gaussian_matrix, random_spd, rng};
use estim_core::nalgebra::{DMatrix, DVector, Matrix3, U1, U2, U3, Vector1, Vector2, Vector3};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::{
    Ekf, Estimator, GaussianSecondOrderEkf, KalmanFilter, Predict, SecondOrderEkf, Ukf, Update,
};

#[test]
fn a_process_without_input_filters_like_a_zero_input() {
    let mut r = rng(11);
    let f = crate::common::random_stable(&mut r, U3, 0.9);
    let q = random_spd(&mut r, U3, 0.5, 0.05);
    let sensor = LinearMeasurement {
        observation: gaussian_matrix(&mut r, U2, U3),
        noise: random_spd(&mut r, U2, 0.5, 0.1),
    };
    let free = LinearProcess::without_input(f, q);
    let zero_input = LinearProcess {
        transition: f,
        input: gaussian_matrix(&mut r, U3, U1),
        noise: q,
    };
    let prior = Gaussian::new(Vector3::new(1.0, -2.0, 0.5), Matrix3::identity()).unwrap();
    let (mut a, mut b) = (
        KalmanFilter::new(prior.clone()),
        KalmanFilter::new(prior.clone()),
    );
    let (mut ua, mut ub) = (Ukf::new(prior.clone()), Ukf::new(prior));
    for k in 0..20 {
        let z = Vector2::new(k as f64 * 0.1, 1.0 - k as f64 * 0.05);
        a.predict(&free, &(), 0.1).unwrap();
        b.predict(&zero_input, &Vector1::zeros(), 0.1).unwrap();
        ua.predict(&free, &(), 0.1).unwrap();
        ub.predict(&zero_input, &Vector1::zeros(), 0.1).unwrap();
        for filter in [&mut a, &mut b] {
            filter.update(&sensor, &z).unwrap();
        }
        for filter in [&mut ua, &mut ub] {
            filter.update(&sensor, &z).unwrap();
        }
    }
    // B·0 adds exact zeros, so the two runs agree to the bit.
    assert_bitwise_eq(a.state(), b.state(), "KF state");
    assert_bitwise_eq(a.covariance(), b.covariance(), "KF covariance");
    assert_bitwise_eq(ua.state(), ub.state(), "UKF state");
    assert_bitwise_eq(ua.covariance(), ub.covariance(), "UKF covariance");

    // Runtime sizes: the input matrix is n × 0, and the step is the static one.
    let dmat = |m: &Matrix3<f64>| DMatrix::from_column_slice(3, 3, m.as_slice());
    let dynamic = LinearProcess::without_input(dmat(&f), dmat(&q));
    assert_eq!(dynamic.0.input.shape(), (3, 0));
    let start = Vector3::new(1.0, -2.0, 0.5);
    let mut d = KalmanFilter::new(
        Gaussian::new(
            DVector::from_column_slice(start.as_slice()),
            dmat(&Matrix3::identity()),
        )
        .unwrap(),
    );
    let mut s = KalmanFilter::new(Gaussian::new(start, Matrix3::identity()).unwrap());
    d.predict(&dynamic, &(), 0.1).unwrap();
    s.predict(&free, &(), 0.1).unwrap();
    // Different kernels (faer for Dyn): agreement to a few ulp of the entries (≤ 10).
    assert!((d.state() - DVector::from_column_slice(s.state().as_slice())).amax() < 1e-13);
    assert!((d.covariance() - dmat(s.covariance())).amax() < 1e-13);
}

#[test]
fn an_offset_measurement_updates_like_the_plain_one_on_z_minus_d() {
    let mut r = rng(12);
    let plain = LinearMeasurement {
        observation: gaussian_matrix(&mut r, U2, U3),
        noise: random_spd(&mut r, U2, 0.5, 0.1),
    };
    let d = Vector2::new(0.75, -3.0);
    let offset = plain.clone().with_offset(d);
    let prior = Gaussian::new(
        Vector3::new(1.0, -2.0, 0.5),
        random_spd(&mut r, U3, 1.0, 0.1),
    )
    .unwrap();
    let z = Vector2::new(0.3, -2.2);
    // The innovations (z − d) − H x and z − (H x + d) differ by rounding: a few ε of |z| + |d|.
    let tol = 1e-13;
    macro_rules! check {
        ($filter:ty) => {{
            let mut with = <$filter>::new(prior.clone());
            let mut without = <$filter>::new(prior.clone());
            let a = with.update(&offset, &z).unwrap();
            let b = without.update(&plain, &(z - d)).unwrap();
            assert!(
                (a.innovation - b.innovation).amax() < tol,
                stringify!($filter)
            );
            assert!(
                (with.state() - without.state()).amax() < tol,
                stringify!($filter)
            );
            assert!(
                (with.covariance() - without.covariance()).amax() < tol,
                stringify!($filter)
            );
        }};
    }
    check!(KalmanFilter<f64, U3>);
    check!(Ekf<f64, U3>);
    check!(SecondOrderEkf<f64, U3>);
    check!(GaussianSecondOrderEkf<f64, U3>);
    check!(Ukf<f64, U3>);
}
