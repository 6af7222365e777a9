//! Reproduction of the optimised-build divergence of the analytic EKF (see the module docs of
//! `estim_filters::update`, "Optimised builds"): `benches/autodiff.rs` cut down to its models,
//! its trajectory and the EKF lockstep, no criterion. Not built by the workspace.
//!
//! To run it: copy it to `estim-filters/benches/slp_repro.rs`, add
//! `[[bench]] name = "slp_repro" path = "slp_repro.rs" harness = false` to `estim-filters/benches/Cargo.toml`, restore the
//! inlined `Standard`/`Symmetrized` arms of `update::apply` (as at `df5c075`) and
//!
//! ```text
//! cargo rustc -p estim-filters-benches --profile bench --bench slp_repro            # gap 4.1e-2
//! cargo rustc ... -- -C no-vectorize-slp                                    # 6.7e-16
//! cargo rustc ... -- -C codegen-units=1   (or -C opt-level=1, -C opt-level=2) # 6.7e-16
//! RUSTC_BOOTSTRAP=1 cargo rustc -j1 ... -- -C llvm-args=-debug-counter=slp-vectorized=0-N
//! ```
//!
//! then run `target/release/deps/slp_repro-*`. Non-incremental builds only: with
//! `CARGO_INCREMENTAL=1` the crate is split into other codegen units and the gap is 6.7e-16.
//! Bisecting N (`-j1` keeps the counter's order fixed) finds the one SLP tree that breaks it;
//! in a variant of this file that also logged every step it was N = 580 (0-579: 6.7e-16,
//! 0-580: 4.7e-2), a tree rooted at the stores of the `Symmetrized` arm's symmetrisation that
//! includes the product X = −K Pₓᵤᵀ computed before the arms (IR from
//! `-C llvm-args=-print-after=slp-vectorizer -C llvm-args=-filter-print-funcs=<lockstep>`).
//!
//! Other discriminators, all at `df5c075`: the whole build (every dependency) with
//! `RUSTC_BOOTSTRAP=1 RUSTFLAGS="-Zub-checks=yes -C debug-assertions=on"` in its own target
//! directory: no check fires and the gap is 6.7e-16 (the assertions change the code, so this
//! neither shows nor excludes the fault; it finds no precondition violated on the path). The
//! bench crate alone with those flags: no check fires, gap 4.4e-2; with `-Zmir-opt-level=0`:
//! 4.4e-2 (not a MIR optimisation of this crate). `valgrind --tool=memcheck` on the autodiff
//! bench binary with `AUTODIFF_BENCH_STEPS=autodiff_6x4/Ekf_analytic=0` (set-up and lockstep
//! only): 6,098 errors from 209 contexts (uninitialised values, the first at the finiteness
//! check of x⁺ in the inlined analytic update) at `df5c075`, 0 errors at `05d49fa`.

use estim_core::autodiff::{AdScalar, AutoDiff, AutoDiffMeasurement, AutoDiffProcess};
use estim_core::nalgebra::{Matrix4, Matrix4x6, Matrix6, U4, U6, Vector4, Vector6};
use estim_core::{
    Gaussian, MeasurementHessian, MeasurementJacobian, MeasurementModel, ProcessHessian,
    ProcessJacobian, ProcessModel, wrap_angle,
};
use estim_filters::{Ekf, Predict, Update};

const DT: f64 = 0.1;
const STEPS: usize = 64;
const BEACONS: [[f64; 2]; 2] = [[-60.0, -30.0], [-60.0, 40.0]];

/// The vehicle, analytic derivatives and the generic form in one type.
#[derive(Clone, Copy, Debug)]
struct Car;

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
struct RangeBearing;

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
    fn residual(&self, a: &Vector4<f64>, b: &Vector4<f64>) -> Vector4<f64> {
        let d = a - b;
        Vector4::new(d[0], wrap_angle(d[1]), d[2], wrap_angle(d[3]))
    }
}

impl MeasurementModel<f64, U6, U4> for RangeBearing {
    fn measure(&self, x: &Vector6<f64>) -> Vector4<f64> {
        AutoDiffMeasurement::measure::<f64>(self, x)
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix4<f64> {
        Self::noise()
    }
    fn residual(&self, a: &Vector4<f64>, b: &Vector4<f64>) -> Vector4<f64> {
        AutoDiffMeasurement::residual(self, a, b)
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
fn trajectory() -> (Vec<Vector4<f64>>, Gaussian<f64, U6>) {
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
fn lockstep<F>(mut analytic: F, mut automatic: F, zs: &[Vector4<f64>]) -> f64
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

fn main() {
    let (zs, prior) = trajectory();
    let gap = lockstep(Ekf::new(prior.clone()), Ekf::new(prior), &zs);
    println!("lockstep EKF analytic vs AD: largest relative gap {gap:.1e}");
}
