//! Automatic against analytic derivatives in whole filter steps: a 6-state / 4-measurement
//! nonlinear problem, the EKF (Jacobians) and the second-order EKF (Jacobians and Hessians),
//! each with the model's hand-written derivatives and with `AutoDiff` of the same equations
//! written once over a dual scalar.
//!
//! The problem (module `vehicle`, shared with the errata programs in `errata/`): a planar
//! vehicle x = (p_x, p_y, v, ψ, ω, a), Euler-discretised
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
mod vehicle;

use std::hint::black_box;
use std::time::Duration;

use common::Steps;
use criterion::{Criterion, criterion_group, criterion_main};
use estim_core::autodiff::num_dual::{Dual64, HyperDual64};
use estim_core::autodiff::{AdScalar, AutoDiff, AutoDiffMeasurement, AutoDiffProcess};
use estim_core::nalgebra::{Matrix4x6, Matrix6, SMatrix, SVector, U4, U6, Vector4, Vector6};
use estim_core::{
    Gaussian, MeasurementHessian, MeasurementJacobian, ProcessHessian, ProcessJacobian,
};
use estim_filters::{Ekf, Estimator, Predict, SecondOrderEkf, Update};
use vehicle::{Car, DT, RangeBearing, STEPS, lockstep, trajectory};

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
    d.f = p.transition_jacobian(x, &(), DT);
    d.h = s.measurement_jacobian(x);
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
        if let Some(hk) = p.transition_hessian(x, &(), DT, k) {
            (*h, d.nonlinear) = (hk, d.nonlinear + 1);
        }
    }
    for (k, h) in d.hh.iter_mut().enumerate() {
        if let Some(hk) = s.measurement_hessian(x, k) {
            (*h, d.nonlinear) = (hk, d.nonlinear + 1);
        }
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
