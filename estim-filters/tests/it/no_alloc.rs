//! Static sizes allocate nothing per step: predict and update of every filter on 6-state,
//! 4-measurement static models are run under a counting global allocator.

use std::hint::black_box;

use estim_core::nalgebra::{
    DMatrix, DVector, Matrix4, Matrix4x6, Matrix6, Matrix6x4, SMatrix, U1, U4, U6, Vector1,
    Vector4, Vector6,
};
use estim_core::propagate::Unscented;
use estim_core::{
    Gaussian, LinearMeasurement, LinearProcess, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel,
};
use estim_filters::{
    Ekf, FadingMemoryRls, GaussianFilter, GaussianSecondOrderEkf, KalmanFilter, Predict,
    PredictCorrelated, SecondOrderEkf, Ukf, Update,
};

use crate::counting;
use counting::allocations_during;

/// A nonlinear 6-state process with analytic Hessians: two coupled pendulum-like axes plus a
/// quadratic drag term, x = (θ₁, θ₂, ω₁, ω₂, a, b).
struct Pendulums;

impl ProcessModel<f64, U6> for Pendulums {
    type Input = Vector1<f64>;
    fn transition(&self, x: &Vector6<f64>, u: &Vector1<f64>, dt: f64) -> Vector6<f64> {
        Vector6::new(
            x[0] + dt * x[2],
            x[1] + dt * x[3],
            x[2] - dt * x[0].sin() + dt * u[0],
            x[3] - dt * x[1].sin() - dt * 0.1 * x[3] * x[3],
            0.99 * x[4],
            0.99 * x[5] + 0.01 * x[4],
        )
    }
    fn process_noise(&self, _: &Vector6<f64>, _: &Vector1<f64>, dt: f64) -> Matrix6<f64> {
        Matrix6::identity() * (0.01 * dt)
    }
}

impl ProcessJacobian<f64, U6> for Pendulums {
    fn transition_jacobian(&self, x: &Vector6<f64>, _: &Vector1<f64>, dt: f64) -> Matrix6<f64> {
        let mut j = Matrix6::identity();
        j[(0, 2)] = dt;
        j[(1, 3)] = dt;
        j[(2, 0)] = -dt * x[0].cos();
        j[(3, 1)] = -dt * x[1].cos();
        j[(3, 3)] = 1.0 - dt * 0.2 * x[3];
        j[(4, 4)] = 0.99;
        j[(5, 5)] = 0.99;
        j[(5, 4)] = 0.01;
        j
    }
}

impl ProcessHessian<f64, U6> for Pendulums {
    fn transition_hessian(
        &self,
        x: &Vector6<f64>,
        _: &Vector1<f64>,
        dt: f64,
        k: usize,
    ) -> Option<Matrix6<f64>> {
        let mut h = Matrix6::zeros();
        match k {
            2 => h[(0, 0)] = dt * x[0].sin(),
            3 => {
                h[(1, 1)] = dt * x[1].sin();
                h[(3, 3)] = -dt * 0.2;
            }
            _ => return None,
        }
        Some(h)
    }
}

/// A nonlinear 4-component measurement with analytic Hessians.
struct Sensors;

impl MeasurementModel<f64, U6, U4> for Sensors {
    fn measure(&self, x: &Vector6<f64>) -> Vector4<f64> {
        Vector4::new(
            x[0] * x[0] + x[1],
            x[1] * x[2],
            x[3].sin(),
            x[4] + x[5] * x[5] * x[5],
        )
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix4<f64> {
        Matrix4::identity() * 0.05
    }
}

impl MeasurementJacobian<f64, U6, U4> for Sensors {
    fn measurement_jacobian(&self, x: &Vector6<f64>) -> Matrix4x6<f64> {
        let mut j = Matrix4x6::zeros();
        j[(0, 0)] = 2.0 * x[0];
        j[(0, 1)] = 1.0;
        j[(1, 1)] = x[2];
        j[(1, 2)] = x[1];
        j[(2, 3)] = x[3].cos();
        j[(3, 4)] = 1.0;
        j[(3, 5)] = 3.0 * x[5] * x[5];
        j
    }
}

impl MeasurementHessian<f64, U6, U4> for Sensors {
    fn measurement_hessian(&self, x: &Vector6<f64>, k: usize) -> Option<Matrix6<f64>> {
        let mut h = Matrix6::zeros();
        match k {
            0 => h[(0, 0)] = 2.0,
            1 => {
                h[(1, 2)] = 1.0;
                h[(2, 1)] = 1.0;
            }
            2 => h[(3, 3)] = -x[3].sin(),
            _ => h[(5, 5)] = 6.0 * x[5],
        }
        Some(h)
    }
}

fn prior() -> Gaussian<f64, U6> {
    Gaussian::new(
        Vector6::new(0.3, -0.2, 0.1, 0.0, 0.5, 0.2),
        Matrix6::identity() * 0.1,
    )
    .unwrap()
}

fn linear_models() -> (LinearProcess<f64, U6, U1>, LinearMeasurement<f64, U6, U4>) {
    let mut f = Matrix6::identity() * 0.95;
    f[(0, 3)] = 0.1;
    f[(1, 4)] = 0.1;
    f[(2, 5)] = 0.1;
    let mut h = Matrix4x6::zeros();
    for i in 0..4 {
        h[(i, i)] = 1.0;
        h[(i, i + 2)] = 0.5;
    }
    (
        LinearProcess {
            transition: f,
            input: SMatrix::<f64, 6, 1>::from_element(0.1),
            noise: Matrix6::identity() * 0.01,
        },
        LinearMeasurement {
            observation: h,
            noise: Matrix4::identity() * 0.1,
        },
    )
}

const STEPS: usize = 20;

/// Readings for the steps, prepared outside the counted region.
fn readings() -> Vec<Vector4<f64>> {
    (0..STEPS)
        .map(|k| {
            let t = k as f64 * 0.1;
            Vector4::new(t.sin(), 0.1 * t, t.cos() * 0.2, 0.3)
        })
        .collect()
}

/// Predict + update on a nonlinear model for any filter that accepts it, counting.
fn count_nonlinear<F>(mut filter: F) -> usize
where
    F: Predict<f64, U6, Pendulums> + Update<f64, U6, U4, Sensors>,
{
    let zs = readings();
    let u = Vector1::new(0.05);
    allocations_during(|| {
        for z in &zs {
            filter.predict(&Pendulums, &u, 0.1).unwrap();
            let report = filter.update(&Sensors, z).unwrap();
            black_box(report);
        }
        black_box(&filter);
    })
}

/// Predict + update (+ correlated predict) on linear models for any filter, counting.
fn count_linear<F>(mut filter: F) -> usize
where
    F: Predict<f64, U6, LinearProcess<f64, U6, U1>>
        + Update<f64, U6, U4, LinearMeasurement<f64, U6, U4>>
        + PredictCorrelated<f64, U6, U4, LinearProcess<f64, U6, U1>, LinearMeasurement<f64, U6, U4>>,
{
    let (process, measurement) = linear_models();
    let cross = Matrix6x4::from_element(0.001);
    let zs = readings();
    let u = Vector1::new(0.05);
    allocations_during(|| {
        for z in &zs {
            filter.predict(&process, &u, 0.1).unwrap();
            let report = filter.update(&measurement, z).unwrap();
            black_box(report);
            filter
                .predict_correlated(&process, &u, 0.1, &measurement, z, &cross)
                .unwrap();
        }
        black_box(&filter);
    })
}

/// The nonlinear models' analytic derivatives are right (so the second-order filters above
/// exercise real Hessians).
#[test]
fn nonlinear_models_have_correct_derivatives() {
    let x = Vector6::new(0.3, -0.2, 0.1, 0.4, 0.5, 0.2);
    let u = Vector1::new(0.05);
    let report = estim_core::derivative::check_process_model(&Pendulums, &x, &u, 0.1).unwrap();
    assert!(report.is_accurate(1e-7), "{report}");
    let report = estim_core::derivative::check_measurement_model(&Sensors, &x).unwrap();
    assert!(report.is_accurate(1e-7), "{report}");
}

#[test]
fn counting_allocator_counts() {
    // Positive control: the counter sees this thread's heap allocations...
    assert!(allocations_during(|| drop(black_box(vec![1u8; 64]))) >= 1);
    // ... including those of a runtime-sized filter, which does allocate per step.
    let mut dynamic =
        KalmanFilter::new(Gaussian::new(DVector::zeros(6), DMatrix::identity(6, 6)).unwrap());
    let process = LinearProcess {
        transition: DMatrix::<f64>::identity(6, 6),
        input: DMatrix::zeros(6, 0),
        noise: DMatrix::identity(6, 6),
    };
    let none = DVector::zeros(0);
    assert!(allocations_during(|| dynamic.predict(&process, &none, 0.1).unwrap()) > 0);
}

#[test]
fn kalman_filter_does_not_allocate_per_step() {
    assert_eq!(count_linear(KalmanFilter::new(prior())), 0);
}

#[test]
fn ekf_does_not_allocate_per_step() {
    assert_eq!(count_linear(Ekf::new(prior())), 0);
    assert_eq!(count_nonlinear(Ekf::new(prior())), 0);
}

#[test]
fn second_order_ekfs_do_not_allocate_per_step() {
    assert_eq!(count_linear(SecondOrderEkf::new(prior())), 0);
    assert_eq!(count_nonlinear(SecondOrderEkf::new(prior())), 0);
    assert_eq!(count_nonlinear(GaussianSecondOrderEkf::new(prior())), 0);
}

#[test]
fn ukf_does_not_allocate_per_step() {
    assert_eq!(count_linear(Ukf::new(prior())), 0);
    assert_eq!(count_nonlinear(Ukf::new(prior())), 0);
    assert_eq!(
        count_nonlinear(GaussianFilter::with_propagator(
            prior(),
            Unscented::cubature()
        )),
        0
    );
}

#[test]
fn gated_and_failing_steps_do_not_allocate() {
    let (process, measurement) = linear_models();
    let mut kf = KalmanFilter::new(prior()).with_gate(1e-6).unwrap();
    let z = Vector4::new(10.0, 10.0, 10.0, 10.0);
    let bad = Vector4::new(f64::NAN, 0.0, 0.0, 0.0);
    let u = Vector1::new(0.0);
    let count = allocations_during(|| {
        black_box(kf.update(&measurement, &z).unwrap());
        black_box(kf.update(&measurement, &bad).unwrap_err());
        black_box(kf.predict(&process, &u, f64::NAN).unwrap_err());
    });
    assert_eq!(count, 0);
}

#[test]
fn fading_memory_rls_does_not_allocate_per_step() {
    let (_, measurement) = linear_models();
    let zs = readings();
    let mut rls = FadingMemoryRls::new(prior(), 0.95).unwrap();
    let linear = allocations_during(|| {
        for z in &zs {
            black_box(rls.update(&measurement, z).unwrap());
        }
    });
    assert_eq!(linear, 0);
    let mut rls = FadingMemoryRls::new(prior(), 0.95).unwrap();
    let nonlinear = allocations_during(|| {
        for z in &zs {
            black_box(rls.update(&Sensors, z).unwrap());
        }
    });
    assert_eq!(nonlinear, 0);
}

/// Static sizes above `kernel::STATIC_NALGEBRA_MAX` run faer's products on views of their
/// storage, and above 16 faer's Cholesky with its scratch on the stack; the step still
/// allocates nothing. A KF and a UKF at 12 states / 10 measurements (the factors of S and P
/// by the inlined loop) and at 24 / 20 (both by faer's), after one KF step.
#[test]
fn large_static_sizes_do_not_allocate_per_step() {
    large_static_steps_allocate_nothing::<12, 10>();
    large_static_steps_allocate_nothing::<24, 20>();
}

fn large_static_steps_allocate_nothing<const N: usize, const M: usize>() {
    let process = LinearProcess {
        transition: SMatrix::<f64, N, N>::from_fn(|i, j| {
            if i == j {
                0.95
            } else {
                0.01 / (1.0 + (i + j) as f64)
            }
        }),
        input: SMatrix::<f64, N, 0>::zeros(),
        noise: SMatrix::<f64, N, N>::identity() * 0.01,
    };
    let sensor = LinearMeasurement {
        observation: SMatrix::<f64, M, N>::from_fn(|i, j| if i == j { 1.0 } else { 0.1 }),
        noise: SMatrix::<f64, M, M>::identity() * 0.1,
    };
    let prior = Gaussian::new(SMatrix::<f64, N, 1>::zeros(), SMatrix::identity()).unwrap();
    let zs: Vec<_> = (0..8)
        .map(|k| SMatrix::<f64, M, 1>::from_fn(|i, _| ((k * M + i) as f64).sin()))
        .collect();
    let none = SMatrix::<f64, 0, 1>::zeros();
    let mut kf = KalmanFilter::new(prior.clone());
    let mut ukf = Ukf::new(prior);
    // One step first: at 24 / 20 faer's products (the gemm crate) make their per-thread
    // packing buffer on first use (`L2_SLAB`, one allocation per thread, the same for runtime
    // sizes; also there with the Cholesky factors by the inlined loop).
    kf.predict(&process, &none, 1.0).unwrap();
    black_box(kf.update(&sensor, &zs[0]).unwrap());
    let allocations = allocations_during(|| {
        for z in &zs {
            kf.predict(&process, &none, 1.0).unwrap();
            black_box(kf.update(&sensor, z).unwrap());
            ukf.predict(&process, &none, 1.0).unwrap();
            black_box(ukf.update(&sensor, z).unwrap());
        }
    });
    assert_eq!(allocations, 0, "{N} states, {M} measurements");
}
