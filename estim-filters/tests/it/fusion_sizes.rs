//! One driver for static and runtime sizes, f64 and f32: the same late deliveries through a
//! `Dyn`-sized Kalman filter and through an `f32` one give the static f64 driver's estimate.

use estim_core::nalgebra::{
    DMatrix, DVector, Dyn, Matrix1, Matrix1x2, Matrix2, U1, U2, Vector1, Vector2,
};
use estim_core::{
    Gaussian, LinearMeasurement, LinearProcessModel, ProcessJacobian, ProcessModel, error::Result,
};
use estim_filters::fusion::{FusionDriver, Innovation, SensorSet, SensorSettings};
use estim_filters::{Estimator, KalmanFilter, Update};
use rand::Rng;

use crate::common::rng;
use crate::fusion_support::{
    POSITION_SIGMA, Q, Reading, VELOCITY_SIGMA, kf_driver, measurements, settings,
};

/// The constant-velocity cart of `fusion_support` at runtime size 2.
struct DynCart;

impl ProcessModel<f64, Dyn> for DynCart {
    type Input = ();
    fn transition(&self, x: &DVector<f64>, _: &(), dt: f64) -> DVector<f64> {
        DVector::from_vec(vec![x[0] + dt * x[1], x[1]])
    }
    fn process_noise(&self, _: &DVector<f64>, _: &(), dt: f64) -> DMatrix<f64> {
        let q = crate::fusion_support::noise(Q, dt);
        DMatrix::from_column_slice(2, 2, q.as_slice())
    }
}

impl ProcessJacobian<f64, Dyn> for DynCart {
    fn transition_jacobian(&self, _: &DVector<f64>, _: &(), dt: f64) -> DMatrix<f64> {
        DMatrix::from_row_slice(2, 2, &[1.0, dt, 0.0, 1.0])
    }
}

impl LinearProcessModel<f64, Dyn> for DynCart {}

/// Position and velocity sensors with runtime sizes.
struct DynSensors([LinearMeasurement<f64, Dyn, Dyn>; 2]);

impl<F: Update<f64, Dyn, Dyn, LinearMeasurement<f64, Dyn, Dyn>>> SensorSet<f64, Dyn, F>
    for DynSensors
{
    type Reading = (usize, f64);
    fn count(&self) -> usize {
        2
    }
    fn sensor(&self, r: &(usize, f64)) -> usize {
        r.0
    }
    fn dimension(&self, _: usize) -> usize {
        1
    }
    fn update(&self, f: &mut F, r: &(usize, f64)) -> Result<Innovation<f64>> {
        let z = DVector::from_element(1, r.1);
        f.update(&self.0[r.0], &z).map(|r| Innovation::of(&r))
    }
}

/// The cart in `f32` (static sizes).
struct Cart32;

impl ProcessModel<f32, U2> for Cart32 {
    type Input = ();
    fn transition(&self, x: &Vector2<f32>, _: &(), dt: f32) -> Vector2<f32> {
        Vector2::new(x[0] + dt * x[1], x[1])
    }
    fn process_noise(&self, _: &Vector2<f32>, _: &(), dt: f32) -> Matrix2<f32> {
        crate::fusion_support::noise(Q, f64::from(dt)).cast()
    }
}

impl ProcessJacobian<f32, U2> for Cart32 {
    fn transition_jacobian(&self, _: &Vector2<f32>, _: &(), dt: f32) -> Matrix2<f32> {
        Matrix2::new(1.0, dt, 0.0, 1.0)
    }
}

impl LinearProcessModel<f32, U2> for Cart32 {}

struct Sensors32([LinearMeasurement<f32, U2, U1>; 2]);

impl<F: Update<f32, U2, U1, LinearMeasurement<f32, U2, U1>>> SensorSet<f32, U2, F> for Sensors32 {
    type Reading = (usize, f32);
    fn count(&self) -> usize {
        2
    }
    fn sensor(&self, r: &(usize, f32)) -> usize {
        r.0
    }
    fn dimension(&self, _: usize) -> usize {
        1
    }
    fn update(&self, f: &mut F, r: &(usize, f32)) -> Result<Innovation<f32>> {
        f.update(&self.0[r.0], &Vector1::new(r.1))
            .map(|r| Innovation::of(&r))
    }
}

fn split(r: &Reading) -> (usize, f64) {
    match r {
        Reading::Position(z) => (0, z[0]),
        Reading::Velocity(z) => (1, z[0]),
        Reading::Unknown => unreachable!(),
    }
}

#[test]
fn runtime_sizes_and_f32_run_the_same_driver() {
    let (_, taken) = measurements(21, 300);
    let mut delays = rng(77);
    let mut arrivals: Vec<_> = taken
        .iter()
        .map(|m| (m.step + delays.random_range(0..=30), *m))
        .collect();
    arrivals.sort_by_key(|a| a.0);
    let judged = SensorSettings::gated(0.9999);

    let mut fixed = kf_driver(judged.clone());
    let p = crate::fusion_support::prior();
    let dyn_prior = Gaussian::new(
        DVector::from_column_slice(p.mean().as_slice()),
        DMatrix::from_column_slice(2, 2, p.covariance().as_slice()),
    )
    .unwrap();
    let sensor = |h: [f64; 2], r: f64| LinearMeasurement {
        observation: DMatrix::from_row_slice(1, 2, &h),
        noise: DMatrix::from_element(1, 1, r),
    };
    let sensors = DynSensors([
        sensor([1.0, 0.0], POSITION_SIGMA.powi(2)),
        sensor([0.0, 1.0], VELOCITY_SIGMA.powi(2)),
    ]);
    let mut runtime = FusionDriver::new(
        KalmanFilter::new(dyn_prior),
        DynCart,
        (),
        sensors,
        0.0,
        settings(),
        judged.clone(),
    )
    .unwrap();
    let sensor32 = |h: Matrix1x2<f32>, r: f64| LinearMeasurement {
        observation: h,
        noise: Matrix1::new(r as f32),
    };
    let prior32 = Gaussian::new(p.mean().cast::<f32>(), p.covariance().cast::<f32>()).unwrap();
    let sensors32 = Sensors32([
        sensor32(Matrix1x2::new(1.0, 0.0), POSITION_SIGMA.powi(2)),
        sensor32(Matrix1x2::new(0.0, 1.0), VELOCITY_SIGMA.powi(2)),
    ]);
    let mut single = FusionDriver::new(
        KalmanFilter::new(prior32),
        Cart32,
        (),
        sensors32,
        0.0,
        settings(),
        judged,
    )
    .unwrap();
    for (_, m) in &arrivals {
        let a = fixed.fuse(m.time(), m.reading).unwrap();
        let b = runtime.fuse(m.time(), split(&m.reading)).unwrap();
        let (s, z) = split(&m.reading);
        let c = single.fuse(m.time(), (s, z as f32)).unwrap();
        assert_eq!(a.replayed, b.replayed);
        assert_eq!(a.replayed, c.replayed);
    }
    let (x, px) = (fixed.filter().state(), fixed.filter().covariance());
    // Runtime sizes run the products on faer, in another order than nalgebra's static kernels:
    // agreement to rounding (1e-12 of the entries' scale), not to the bit.
    for i in 0..2 {
        assert!((runtime.filter().state()[i] - x[i]).abs() < 1e-12 * (1.0 + x[i].abs()));
        for j in 0..2 {
            let d = runtime.filter().covariance()[(i, j)] - px[(i, j)];
            assert!(d.abs() < 1e-12 * px[(i, i)].max(px[(j, j)]));
        }
    }
    // f32 carries 7 digits; over ~60 updates the relative error stays below 1e-4.
    for i in 0..2 {
        let d = f64::from(single.filter().state()[i]) - x[i];
        assert!(d.abs() < 1e-4 * (1.0 + x[i].abs()), "component {i}: {d}");
    }
    assert_eq!(fixed.health(0).accepted, runtime.health(0).accepted);
    assert_eq!(fixed.health(0).accepted, single.health(0).accepted);
}
