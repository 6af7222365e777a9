//! The problem of the autodiff bench (`autodiff.rs`), shared with the errata programs
//! (`errata/`) that reproduce the optimised-build divergence on it: a planar vehicle
//! x = (p_x, p_y, v, ψ, ω, a), Euler-discretised (p⁺ = p + Δt v (cos ψ, sin ψ), v⁺ = v + Δt a,
//! ψ⁺ = ψ + Δt ω), seen in range and bearing from two beacons; each model with hand-written
//! derivatives and its equations written once over a dual scalar (`AutoDiff`); a 64-step
//! trajectory; and the lockstep of an analytic and an AD filter.

use estim_core::autodiff::{AdScalar, AutoDiff, AutoDiffMeasurement, AutoDiffProcess};
use estim_core::nalgebra::{Matrix4, Matrix4x6, Matrix6, U4, U6, Vector4, Vector6};
use estim_core::{
    Gaussian, MeasurementHessian, MeasurementJacobian, MeasurementModel, ProcessHessian,
    ProcessJacobian, ProcessModel, wrap_angle,
};
use estim_filters::{Predict, Update};

/// The time step Δt (s).
pub const DT: f64 = 0.1;
/// The trajectory's length.
pub const STEPS: usize = 64;
/// The beacons' positions (m).
pub const BEACONS: [[f64; 2]; 2] = [[-60.0, -30.0], [-60.0, 40.0]];

/// The vehicle, analytic derivatives and the generic form in one type.
#[derive(Clone, Copy, Debug)]
pub struct Car;

impl Car {
    fn noise() -> Matrix6<f64> {
        Matrix6::from_diagonal(&Vector6::new(1e-4, 1e-4, 1e-3, 1e-4, 1e-3, 5e-2))
    }
}

impl AutoDiffProcess<f64, U6> for Car {
    type Input = ();
    fn transition<D: AdScalar<f64>>(&self, x: &Vector6<D>, _: &(), dt: f64) -> Vector6<D> {
        let (s, c) = x[3].sin_cos();
        Vector6::new(
            x[0] + x[2] * c * dt,
            x[1] + x[2] * s * dt,
            x[2] + x[5] * dt,
            x[3] + x[4] * dt,
            x[4],
            x[5],
        )
    }
    fn process_noise(&self, _: &Vector6<f64>, _: &(), _: f64) -> Matrix6<f64> {
        Self::noise()
    }
}

impl ProcessModel<f64, U6> for Car {
    type Input = ();
    fn transition(&self, x: &Vector6<f64>, u: &(), dt: f64) -> Vector6<f64> {
        AutoDiffProcess::transition::<f64>(self, x, u, dt)
    }
    fn process_noise(&self, _: &Vector6<f64>, _: &(), _: f64) -> Matrix6<f64> {
        Self::noise()
    }
}

impl ProcessJacobian<f64, U6> for Car {
    fn transition_jacobian(&self, x: &Vector6<f64>, _: &(), dt: f64) -> Matrix6<f64> {
        let (s, c) = x[3].sin_cos();
        let mut f = Matrix6::identity();
        (f[(0, 2)], f[(0, 3)]) = (c * dt, -x[2] * s * dt);
        (f[(1, 2)], f[(1, 3)]) = (s * dt, x[2] * c * dt);
        (f[(2, 5)], f[(3, 4)]) = (dt, dt);
        f
    }
}

impl ProcessHessian<f64, U6> for Car {
    fn transition_hessian(
        &self,
        x: &Vector6<f64>,
        _: &(),
        dt: f64,
        k: usize,
    ) -> Option<Matrix6<f64>> {
        let (s, c) = x[3].sin_cos();
        // p_x, p_y are bilinear-trigonometric in (v, ψ); the rest is affine.
        let (cross, curvature) = match k {
            0 => (-s * dt, -x[2] * c * dt),
            1 => (c * dt, -x[2] * s * dt),
            _ => return None,
        };
        let mut h = Matrix6::zeros();
        (h[(2, 3)], h[(3, 2)], h[(3, 3)]) = (cross, cross, curvature);
        Some(h)
    }
}

/// Range and bearing to the two beacons.
#[derive(Clone, Copy, Debug)]
pub struct RangeBearing;

impl RangeBearing {
    fn noise() -> Matrix4<f64> {
        Matrix4::from_diagonal(&Vector4::new(0.25, 1e-4, 0.25, 1e-4))
    }
}

impl AutoDiffMeasurement<f64, U6, U4> for RangeBearing {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector6<D>) -> Vector4<D> {
        let [(r0, b0), (r1, b1)] = BEACONS.map(|b| {
            let (dx, dy) = (x[0] - b[0], x[1] - b[1]);
            ((dx * dx + dy * dy).sqrt(), dy.atan2(dx))
        });
        Vector4::new(r0, b0, r1, b1)
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix4<f64> {
        Self::noise()
    }
    fn residual_into(&self, a: &Vector4<f64>, b: &Vector4<f64>, out: &mut Vector4<f64>) {
        let d = a - b;
        *out = Vector4::new(d[0], wrap_angle(d[1]), d[2], wrap_angle(d[3]));
    }
}

impl MeasurementModel<f64, U6, U4> for RangeBearing {
    fn measure(&self, x: &Vector6<f64>) -> Vector4<f64> {
        AutoDiffMeasurement::measure::<f64>(self, x)
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix4<f64> {
        Self::noise()
    }
    fn residual_into(&self, a: &Vector4<f64>, b: &Vector4<f64>, out: &mut Vector4<f64>) {
        AutoDiffMeasurement::residual_into(self, a, b, out);
    }
}

impl MeasurementJacobian<f64, U6, U4> for RangeBearing {
    fn measurement_jacobian(&self, x: &Vector6<f64>) -> Matrix4x6<f64> {
        let mut j = Matrix4x6::zeros();
        for (i, b) in BEACONS.iter().enumerate() {
            let (dx, dy) = (x[0] - b[0], x[1] - b[1]);
            let r2 = dx * dx + dy * dy;
            let r = r2.sqrt();
            (j[(2 * i, 0)], j[(2 * i, 1)]) = (dx / r, dy / r);
            (j[(2 * i + 1, 0)], j[(2 * i + 1, 1)]) = (-dy / r2, dx / r2);
        }
        j
    }
}

impl MeasurementHessian<f64, U6, U4> for RangeBearing {
    fn measurement_hessian(&self, x: &Vector6<f64>, k: usize) -> Option<Matrix6<f64>> {
        let b = BEACONS[k / 2];
        let (dx, dy) = (x[0] - b[0], x[1] - b[1]);
        let r2 = dx * dx + dy * dy;
        // ∇²r = (dy², −dx dy, dx²)/r³, ∇²β = (2dx dy, dy² − dx², −2dx dy)/r⁴ on (p_x, p_y).
        let (a, off, c) = if k.is_multiple_of(2) {
            let r3 = r2 * r2.sqrt();
            (dy * dy / r3, -dx * dy / r3, dx * dx / r3)
        } else {
            let r4 = r2 * r2;
            (
                2.0 * dx * dy / r4,
                (dy * dy - dx * dx) / r4,
                -2.0 * dx * dy / r4,
            )
        };
        let mut h = Matrix6::zeros();
        (h[(0, 0)], h[(0, 1)], h[(1, 0)], h[(1, 1)]) = (a, off, off, c);
        Some(h)
    }
}

/// A 64-step trajectory (a 25 m circle at 5 m/s, gently accelerating) with deterministic
/// pseudo-noise, and a prior offset from its start.
pub fn trajectory() -> (Vec<Vector4<f64>>, Gaussian<f64, U6>) {
    let start = Vector6::new(25.0, 0.0, 5.0, std::f64::consts::FRAC_PI_2, 0.2, 0.1);
    let mut truth = start;
    let zs = (0..STEPS)
        .map(|k| {
            truth = ProcessModel::transition(&Car, &truth, &(), DT);
            let k = k as f64;
            let noise = Vector4::new(
                0.3 * (1.3 * k).sin(),
                0.005 * (2.1 * k).cos(),
                0.3 * (0.7 * k).cos(),
                0.005 * (1.9 * k).sin(),
            );
            MeasurementModel::measure(&RangeBearing, &truth) + noise
        })
        .collect();
    let mean = start + Vector6::new(1.0, -1.0, 0.5, 0.05, -0.02, 0.0);
    let p = Matrix6::from_diagonal(&Vector6::new(2.0, 2.0, 1.0, 0.01, 0.004, 0.1));
    (zs, Gaussian::new(mean, p).expect("valid prior"))
}

/// Runs the analytic and AD filters in lockstep; returns the largest relative state gap.
pub fn lockstep<F>(mut analytic: F, mut automatic: F, zs: &[Vector4<f64>]) -> f64
where
    F: Predict<f64, U6, Car>
        + Predict<f64, U6, AutoDiff<Car>>
        + Update<f64, U6, U4, RangeBearing>
        + Update<f64, U6, U4, AutoDiff<RangeBearing>>,
{
    let (car, sensor) = (AutoDiff::new(Car), AutoDiff::new(RangeBearing));
    let mut gap: f64 = 0.0;
    for z in zs {
        Predict::<f64, U6, Car>::predict(&mut analytic, &Car, &(), DT).unwrap();
        Update::<f64, U6, U4, RangeBearing>::update(&mut analytic, &RangeBearing, z).unwrap();
        Predict::<f64, U6, AutoDiff<Car>>::predict(&mut automatic, &car, &(), DT).unwrap();
        Update::<f64, U6, U4, AutoDiff<RangeBearing>>::update(&mut automatic, &sensor, z).unwrap();
        let (a, b) = (analytic.state(), automatic.state());
        gap = gap.max((a - b).amax() / a.amax().max(1.0));
        let (a, b) = (analytic.covariance(), automatic.covariance());
        gap = gap.max((a - b).amax() / a.amax().max(1.0));
    }
    gap
}
