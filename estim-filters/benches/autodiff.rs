//! Automatic against analytic derivatives in whole filter steps: a 6-state / 4-measurement
//! nonlinear problem, the EKF (Jacobians) and the second-order EKF (Jacobians and Hessians),
//! each with the model's hand-written derivatives and with `AutoDiff` of the same equations
//! written once over a dual scalar.
//!
//! The problem: a planar vehicle x = (p_x, p_y, v, ψ, ω, a), Euler-discretised
//! (p⁺ = p + Δt v (cos ψ, sin ψ), v⁺ = v + Δt a, ψ⁺ = ψ + Δt ω), seen in range and bearing from
//! two beacons. One iteration is one predict and one update along a 64-step trajectory (the
//! shared [`common::Steps`] loop). Before timing, the AD and analytic filters run in lockstep
//! and must agree to 10⁻¹² relative (they compute the same derivatives, to rounding).
//!
//! Where the time goes: the same group also times the derivatives alone, as one step asks for
//! them (`derivatives_*`: F and H for the EKF; F, H and the 6 + 4 Hessians for the second-order
//! EKF, at the 64 filtered states), three ways: analytic, through `AutoDiff`, and by a
//! hand-written loop of num-dual passes over the same generic equations with no adapter, no
//! cache and no lock (`*_dual_loop`: 6 first-order dual passes per Jacobian, 21 hyper-dual
//! passes for all Hessians of one function), plus f and h on plain `f64` (`model_f64`).
//! `AutoDiff` / loop is the adapter's own overhead; loop / analytic is the floor given num-dual
//! and this scheme.
//!
//! Targets (issue 19): AD EKF within 2× of the analytic EKF, AD second-order EKF within 4×.
//! Ratios in BENCHMARKS.md.
//!
//! Run with `cargo bench -p estim-filters-benches --bench autodiff`.

mod common;

use std::hint::black_box;
use std::time::Duration;

use common::Steps;
use criterion::{Criterion, criterion_group, criterion_main};
use estim_core::autodiff::num_dual::{Dual64, HyperDual64};
use estim_core::autodiff::{AdScalar, AutoDiff, AutoDiffMeasurement, AutoDiffProcess};
use estim_core::nalgebra::{
    Matrix4, Matrix4x6, Matrix6, SMatrix, SVector, U4, U6, Vector4, Vector6,
};
use estim_core::{
    Gaussian, MeasurementHessian, MeasurementJacobian, MeasurementModel, ProcessHessian,
    ProcessJacobian, ProcessModel, wrap_angle,
};
use estim_filters::{Ekf, Estimator, Predict, SecondOrderEkf, Update};

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

/// The derivatives one step asks of its two models, in buffers kept across iterations.
#[derive(Clone, Debug, Default)]
struct Derivatives {
    f: Matrix6<f64>,
    h: Matrix4x6<f64>,
    hf: [Matrix6<f64>; 6],
    hh: [Matrix6<f64>; 4],
    /// How many of the 10 Hessians were reported non-affine.
    nonlinear: usize,
}

/// F and H through the models' traits, as the EKF asks for them.
fn jacobians<P, S>(p: &P, s: &S, x: &Vector6<f64>, d: &mut Derivatives)
where
    P: ProcessJacobian<f64, U6, Input = ()>,
    S: MeasurementJacobian<f64, U6, U4>,
{
    p.transition_jacobian_into(x, &(), DT, &mut d.f);
    s.measurement_jacobian_into(x, &mut d.h);
}

/// F, H and every Hessian of f and h through the models' traits, as the second-order EKF asks
/// for them (one component at a time).
fn hessians<P, S>(p: &P, s: &S, x: &Vector6<f64>, d: &mut Derivatives)
where
    P: ProcessHessian<f64, U6, Input = ()>,
    S: MeasurementHessian<f64, U6, U4>,
{
    jacobians(p, s, x, d);
    d.nonlinear = 0;
    for (k, h) in d.hf.iter_mut().enumerate() {
        d.nonlinear += usize::from(p.transition_hessian_into(x, &(), DT, k, h));
    }
    for (k, h) in d.hh.iter_mut().enumerate() {
        d.nonlinear += usize::from(s.measurement_hessian_into(x, k, h));
    }
}

/// The Jacobian of `g` by 6 first-order dual passes, written out: no adapter.
#[inline(always)]
fn dual_jacobian<const M: usize>(
    g: impl Fn(&Vector6<Dual64>) -> SVector<Dual64, M>,
    x: &Vector6<f64>,
    out: &mut SMatrix<f64, M, 6>,
) {
    let mut xd = x.map(Dual64::from_re);
    for j in 0..6 {
        xd[j].eps = 1.0;
        let y = g(&xd);
        xd[j].eps = 0.0;
        for (o, yk) in out.column_mut(j).iter_mut().zip(y.iter()) {
            *o = yk.eps;
        }
    }
}

/// Every Hessian of `g` by 21 hyper-dual passes (xᵢ + ε₁, xⱼ + ε₂, i ≤ j), written out: no
/// adapter, no cache.
#[inline(always)]
fn hyperdual_hessians<const M: usize>(
    g: impl Fn(&Vector6<HyperDual64>) -> SVector<HyperDual64, M>,
    x: &Vector6<f64>,
    out: &mut [Matrix6<f64>; M],
) {
    let mut xd = x.map(HyperDual64::from_re);
    for i in 0..6 {
        xd[i].eps1 = 1.0;
        for j in i..6 {
            xd[j].eps2 = 1.0;
            let y = g(&xd);
            xd[j].eps2 = 0.0;
            for (h, yk) in out.iter_mut().zip(y.iter()) {
                (h[(i, j)], h[(j, i)]) = (yk.eps1eps2, yk.eps1eps2);
            }
        }
        xd[i].eps1 = 0.0;
    }
}

/// f on any scalar, at the bench's step.
#[inline(always)]
fn f_on<D: AdScalar<f64>>(x: &Vector6<D>) -> Vector6<D> {
    AutoDiffProcess::transition(&Car, x, &(), DT)
}

/// h on any scalar.
#[inline(always)]
fn h_on<D: AdScalar<f64>>(x: &Vector6<D>) -> Vector4<D> {
    AutoDiffMeasurement::measure(&RangeBearing, x)
}

/// F and H by the hand-written dual loop.
fn loop_jacobians(x: &Vector6<f64>, d: &mut Derivatives) {
    dual_jacobian(f_on, x, &mut d.f);
    dual_jacobian(h_on, x, &mut d.h);
}

/// F, H and all Hessians by the hand-written dual and hyper-dual loops.
fn loop_hessians(x: &Vector6<f64>, d: &mut Derivatives) {
    loop_jacobians(x, d);
    hyperdual_hessians(f_on, x, &mut d.hf);
    hyperdual_hessians(h_on, x, &mut d.hh);
}

/// The filtered states of the analytic second-order EKF along the trajectory: the points the
/// derivative benches are evaluated at.
fn filtered_states(prior: &Gaussian<f64, U6>, zs: &[Vector4<f64>]) -> Vec<Vector6<f64>> {
    let mut filter = SecondOrderEkf::new(prior.clone());
    zs.iter()
        .map(|z| {
            filter.predict(&Car, &(), DT).unwrap();
            filter.update(&RangeBearing, z).unwrap();
            *filter.state()
        })
        .collect()
}

/// The hand-written loop gives what the adapter gives, to the bit (the same passes).
fn check_loop(xs: &[Vector6<f64>], car: &AutoDiff<Car>, sensor: &AutoDiff<RangeBearing>) {
    let (mut a, mut b) = (Derivatives::default(), Derivatives::default());
    for x in xs {
        hessians(car, sensor, x, &mut a);
        loop_hessians(x, &mut b);
        assert_eq!((a.f, a.h), (b.f, b.h), "Jacobians differ at {x}");
        // The adapter reports f₂..f₅ affine (nothing written); the loop writes their zeros.
        assert_eq!(a.nonlinear, 6, "two process and four measurement Hessians");
        assert!(b.hf[2..].iter().all(|h| h.iter().all(|v| *v == 0.0)));
        assert_eq!(a.hf[..2], b.hf[..2], "process Hessians differ at {x}");
        assert_eq!(a.hh, b.hh, "measurement Hessians differ at {x}");
    }
}

fn autodiff_6x4(c: &mut Criterion) {
    let (zs, prior) = trajectory();
    let gap = lockstep(Ekf::new(prior.clone()), Ekf::new(prior.clone()), &zs);
    eprintln!("lockstep EKF analytic vs AD: largest relative gap {gap:.1e}");
    assert!(
        gap < 1e-12,
        "AD EKF differs from the analytic one by {gap:e}"
    );
    let gap = lockstep(
        SecondOrderEkf::new(prior.clone()),
        SecondOrderEkf::new(prior.clone()),
        &zs,
    );
    eprintln!("lockstep second-order EKF analytic vs AD: largest relative gap {gap:.1e}");
    assert!(gap < 1e-12, "AD second-order EKF differs by {gap:e}");

    let (car, sensor) = (AutoDiff::new(Car), AutoDiff::new(RangeBearing));
    let mut group = Steps::<STEPS>::new(
        c.benchmark_group("autodiff_6x4"),
        "autodiff_6x4",
        "AUTODIFF_BENCH_STEPS",
    );
    group.bench("Ekf_analytic", &Ekf::new(prior.clone()), |f, i| {
        f.predict(black_box(&Car), &(), DT).unwrap();
        f.update(black_box(&RangeBearing), &zs[i]).unwrap()
    });
    group.bench("Ekf_autodiff", &Ekf::new(prior.clone()), |f, i| {
        f.predict(black_box(&car), &(), DT).unwrap();
        f.update(black_box(&sensor), &zs[i]).unwrap()
    });
    group.bench(
        "SecondOrderEkf_analytic",
        &SecondOrderEkf::new(prior.clone()),
        |f, i| {
            f.predict(black_box(&Car), &(), DT).unwrap();
            f.update(black_box(&RangeBearing), &zs[i]).unwrap()
        },
    );
    group.bench(
        "SecondOrderEkf_autodiff",
        &SecondOrderEkf::new(prior.clone()),
        |f, i| {
            f.predict(black_box(&car), &(), DT).unwrap();
            f.update(black_box(&sensor), &zs[i]).unwrap()
        },
    );

    // The derivatives alone, at the filtered states, cycled as the steps are.
    let xs = filtered_states(&prior, &zs);
    check_loop(&xs, &car, &sensor);
    let d0 = Derivatives::default();
    group.bench("derivatives_Ekf_analytic", &d0, |d, i| {
        jacobians(black_box(&Car), black_box(&RangeBearing), &xs[i], d)
    });
    group.bench("derivatives_Ekf_autodiff", &d0, |d, i| {
        jacobians(black_box(&car), black_box(&sensor), &xs[i], d)
    });
    group.bench("derivatives_Ekf_dual_loop", &d0, |d, i| {
        loop_jacobians(black_box(&xs[i]), d)
    });
    group.bench("derivatives_SecondOrderEkf_analytic", &d0, |d, i| {
        hessians(black_box(&Car), black_box(&RangeBearing), &xs[i], d)
    });
    group.bench("derivatives_SecondOrderEkf_autodiff", &d0, |d, i| {
        hessians(black_box(&car), black_box(&sensor), &xs[i], d)
    });
    group.bench("derivatives_SecondOrderEkf_dual_loop", &d0, |d, i| {
        loop_hessians(black_box(&xs[i]), d)
    });
    group.bench("model_f64", &(), |_, i| {
        let x = black_box(&xs[i]);
        (f_on::<f64>(x), h_on::<f64>(x))
    });
    group.finish();
}

fn config() -> Criterion {
    // Modest times: a shared, noisy 2-core machine.
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
}

criterion_group! {
    name = benches;
    config = config();
    targets = autodiff_6x4
}
criterion_main!(benches);
