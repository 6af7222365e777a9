//! Runtime sizes allocate nothing per step once the filter's workspace is sized: every filter
//! runs predict + `update_into` on `Dyn` models that opt in through [`InPlace`], under a
//! counting global allocator. `prepare_predict` and `prepare_update` (once per sensor) size
//! the workspace right after construction; from then on no step allocates, the first one
//! included. Without them, the first prediction and the first update with each measurement
//! length size it instead (a positive control below shows the counter sees that).

use crate::common;
use crate::counting;
use common::assert_bitwise_eq;
use counting::allocations_during;

use std::hint::black_box;

use estim_core::nalgebra::{DMatrix, DVector, Dyn};
use estim_core::propagate::Unscented;
use estim_core::{
    Gaussian, InPlace, LinearMeasurement, LinearProcess, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel, WrappedAngles,
};
use estim_filters::{
    Ekf, Estimator, FadingMemoryRls, GaussianFilter, GaussianSecondOrderEkf, KalmanFilter, Predict,
    SecondOrderEkf, SrEkf, SrKalmanFilter, SrUkf, Ukf, Update, UpdateReport,
};

const DT: f64 = 0.1;

/// A chain of n damped pendulums, each pulled by the next:
/// fᵢ(x) = xᵢ + Δt (x₍ᵢ₊₁₎ − sin xᵢ) (the last without the pull). Every output is written in
/// place ([`InPlace`]); the owned methods go through the same code.
struct Chain;

impl ProcessModel<f64, Dyn> for Chain {
    type Input = ();
    fn transition(&self, x: &DVector<f64>, u: &(), dt: f64) -> DVector<f64> {
        let mut out = x.clone();
        self.value_into(x, u, dt, &mut out);
        out
    }
    fn process_noise(&self, x: &DVector<f64>, u: &(), dt: f64) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows(), x.nrows());
        self.noise_into(x, u, dt, &mut out);
        out
    }
    fn in_place(&self) -> Option<&dyn InPlace<f64, Dyn, Dyn, ()>> {
        Some(self)
    }
}

impl InPlace<f64, Dyn, Dyn, ()> for Chain {
    fn value_into(&self, x: &DVector<f64>, _: &(), dt: f64, out: &mut DVector<f64>) {
        let n = x.nrows();
        for i in 0..n {
            let pull = if i + 1 < n { x[i + 1] } else { 0.0 };
            out[i] = x[i] + dt * (pull - x[i].sin());
        }
    }
    fn noise_into(&self, _: &DVector<f64>, _: &(), dt: f64, out: &mut DMatrix<f64>) {
        out.fill_with_identity();
        *out *= 0.01 * dt;
    }
    fn jacobian_into(&self, x: &DVector<f64>, _: &(), dt: f64, out: &mut DMatrix<f64>) {
        let n = x.nrows();
        out.fill(0.0);
        for i in 0..n {
            out[(i, i)] = 1.0 - dt * x[i].cos();
            if i + 1 < n {
                out[(i, i + 1)] = dt;
            }
        }
    }
    fn hessian_into<'o>(
        &self,
        x: &DVector<f64>,
        _: &(),
        dt: f64,
        k: usize,
        out: &'o mut DMatrix<f64>,
    ) -> Option<&'o mut DMatrix<f64>> {
        out.fill(0.0);
        out[(k, k)] = dt * x[k].sin();
        Some(out)
    }
}

impl ProcessJacobian<f64, Dyn> for Chain {
    fn transition_jacobian(&self, x: &DVector<f64>, u: &(), dt: f64) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows(), x.nrows());
        self.jacobian_into(x, u, dt, &mut out);
        out
    }
}

impl ProcessHessian<f64, Dyn> for Chain {
    fn transition_hessian(
        &self,
        x: &DVector<f64>,
        u: &(),
        dt: f64,
        k: usize,
    ) -> Option<DMatrix<f64>> {
        let mut out = DMatrix::zeros(x.nrows(), x.nrows());
        self.hessian_into(x, u, dt, k, &mut out)?;
        Some(out)
    }
}

/// Every other state, with a quadratic term: hⱼ(x) = x₂ⱼ + 0.1 x₂ⱼ², m = n/2.
struct EveryOther;

impl MeasurementModel<f64, Dyn, Dyn> for EveryOther {
    fn measure(&self, x: &DVector<f64>) -> DVector<f64> {
        let mut out = DVector::zeros(x.nrows() / 2);
        self.value_into(x, &(), 0.0, &mut out);
        out
    }
    fn measurement_noise(&self, x: &DVector<f64>) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows() / 2, x.nrows() / 2);
        self.noise_into(x, &(), 0.0, &mut out);
        out
    }
    fn in_place(&self) -> Option<&dyn InPlace<f64, Dyn, Dyn>> {
        Some(self)
    }
}

impl InPlace<f64, Dyn, Dyn> for EveryOther {
    fn value_into(&self, x: &DVector<f64>, _: &(), _: f64, out: &mut DVector<f64>) {
        for j in 0..out.nrows() {
            let v = x[2 * j];
            out[j] = v + 0.1 * v * v;
        }
    }
    fn noise_into(&self, _: &DVector<f64>, _: &(), _: f64, out: &mut DMatrix<f64>) {
        out.fill_with_identity();
        *out *= 0.05;
    }
    fn jacobian_into(&self, x: &DVector<f64>, _: &(), _: f64, out: &mut DMatrix<f64>) {
        out.fill(0.0);
        for j in 0..out.nrows() {
            out[(j, 2 * j)] = 1.0 + 0.2 * x[2 * j];
        }
    }
    fn hessian_into<'o>(
        &self,
        _: &DVector<f64>,
        _: &(),
        _: f64,
        k: usize,
        out: &'o mut DMatrix<f64>,
    ) -> Option<&'o mut DMatrix<f64>> {
        out.fill(0.0);
        out[(2 * k, 2 * k)] = 0.2;
        Some(out)
    }
}

impl MeasurementJacobian<f64, Dyn, Dyn> for EveryOther {
    fn measurement_jacobian(&self, x: &DVector<f64>) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows() / 2, x.nrows());
        self.jacobian_into(x, &(), 0.0, &mut out);
        out
    }
}

impl MeasurementHessian<f64, Dyn, Dyn> for EveryOther {
    fn measurement_hessian(&self, x: &DVector<f64>, k: usize) -> Option<DMatrix<f64>> {
        let mut out = DMatrix::zeros(x.nrows(), x.nrows());
        self.hessian_into(x, &(), 0.0, k, &mut out)?;
        Some(out)
    }
}

fn prior(n: usize) -> Gaussian<f64, Dyn> {
    let mean = DVector::from_fn(n, |i, _| 0.1 * (i as f64).sin());
    Gaussian::new(mean, DMatrix::identity(n, n) * 0.2).unwrap()
}

fn linear_models(
    n: usize,
) -> (
    LinearProcess<f64, Dyn, Dyn>,
    LinearMeasurement<f64, Dyn, Dyn>,
) {
    let m = n / 2;
    let mut f = DMatrix::identity(n, n) * 0.95;
    for i in 0..n - 1 {
        f[(i, i + 1)] = 0.1;
    }
    let h = DMatrix::from_fn(m, n, |j, i| {
        if i == 2 * j {
            1.0
        } else if i == 2 * j + 1 {
            0.5
        } else {
            0.0
        }
    });
    (
        LinearProcess {
            transition: f,
            input: DMatrix::zeros(n, 0),
            noise: DMatrix::identity(n, n) * 0.01,
        },
        LinearMeasurement {
            observation: h,
            noise: DMatrix::identity(m, m) * 0.1,
        },
    )
}

const STEPS: usize = 10;

fn readings(m: usize) -> Vec<DVector<f64>> {
    (0..STEPS)
        .map(|k| DVector::from_fn(m, |j, _| (0.3 * k as f64 + j as f64).sin() * 0.2))
        .collect()
}

/// Asserts `filter`'s estimate is bit for bit (x, P).
fn assert_unchanged<F: Estimator<f64, Dyn>>(filter: &F, x: &DVector<f64>, p: &DMatrix<f64>) {
    assert_bitwise_eq(filter.state(), x, "state");
    assert_bitwise_eq(filter.covariance(), p, "covariance");
}

/// Prepared right after construction (which must not change the estimate), then allocations
/// over `STEPS` predict + update_into steps, the first one included.
fn count_nonlinear<F>(mut filter: F, n: usize) -> usize
where
    F: Predict<f64, Dyn, Chain> + Update<f64, Dyn, Dyn, EveryOther>,
{
    let zs = readings(n / 2);
    let mut report = UpdateReport::zeros(Dyn(0));
    let (x, p) = (filter.state().clone(), filter.covariance().clone());
    filter.prepare_predict(&Chain, &(), DT).unwrap();
    filter.prepare_update(&EveryOther, &mut report).unwrap();
    assert_unchanged(&filter, &x, &p);
    assert_eq!(report.innovation.nrows(), n / 2, "the report is sized too");
    allocations_during(|| {
        for z in &zs {
            filter.predict(&Chain, &(), DT).unwrap();
            filter.update_into(&EveryOther, z, &mut report).unwrap();
            black_box(&report);
        }
        black_box(&filter);
    })
}

type Process = LinearProcess<f64, Dyn, Dyn>;
type Measurement = LinearMeasurement<f64, Dyn, Dyn>;

/// The same on the linear models, which every filter accepts.
fn count_linear<F>(mut filter: F, n: usize) -> usize
where
    F: Predict<f64, Dyn, Process> + Update<f64, Dyn, Dyn, Measurement>,
{
    let (mut process, measurement) = linear_models(n);
    // Two inputs: x⁺ = F x + B u (the UKF maps its sigma points as F X + (B u) 1ᵀ).
    process.input = DMatrix::from_fn(n, 2, |i, j| 0.01 * (i + j) as f64);
    let u = DVector::from_vec(vec![0.3, -0.1]);
    let zs = readings(n / 2);
    let mut report = UpdateReport::zeros(Dyn(n / 2));
    let (x, p) = (filter.state().clone(), filter.covariance().clone());
    filter.prepare_predict(&process, &u, DT).unwrap();
    filter.prepare_update(&measurement, &mut report).unwrap();
    assert_unchanged(&filter, &x, &p);
    allocations_during(|| {
        for z in &zs {
            filter.predict(&process, &u, DT).unwrap();
            filter.update_into(&measurement, z, &mut report).unwrap();
            black_box(&report);
        }
        black_box(&filter);
    })
}

/// Sizes: small, and large enough for faer's blocked kernels.
const SIZES: [usize; 2] = [8, 100];

#[test]
fn chain_models_have_correct_derivatives() {
    let x = DVector::from_fn(6, |i, _| 0.3 - 0.1 * i as f64);
    let report = estim_core::derivative::check_process_model(&Chain, &x, &(), DT).unwrap();
    assert!(report.is_accurate(1e-7), "{report}");
    let report = estim_core::derivative::check_measurement_model(&EveryOther, &x).unwrap();
    assert!(report.is_accurate(1e-7), "{report}");
}

#[test]
fn warm_up_allocates_and_is_counted() {
    // Positive control: without preparation the first steps size the workspace, and the
    // counter sees it; the second ones do not.
    let (process, measurement) = linear_models(8);
    let mut kf = KalmanFilter::new(prior(8));
    let none = DVector::zeros(0);
    let mut report = UpdateReport::zeros(Dyn(4));
    let z = DVector::from_element(4, 0.1);
    let first = allocations_during(|| {
        kf.predict(&process, &none, DT).unwrap();
        kf.update_into(&measurement, &z, &mut report).unwrap();
    });
    assert!(first > 0);
    let second = allocations_during(|| {
        kf.predict(&process, &none, DT).unwrap();
        kf.update_into(&measurement, &z, &mut report).unwrap();
    });
    assert_eq!(second, 0);
}

#[test]
fn preparation_changes_nothing_and_fails_atomically() {
    let n = 8;
    let (process, measurement) = linear_models(n);
    let mut kf = KalmanFilter::new(prior(n));
    let mut report = UpdateReport::zeros(Dyn(0));
    kf.prepare_predict(&process, &DVector::zeros(0), DT)
        .unwrap();
    kf.prepare_update(&measurement, &mut report).unwrap();
    assert_unchanged(
        &kf,
        &prior(n).mean().clone(),
        &prior(n).covariance().clone(),
    );
    // A non-finite time step fails in preparation as in predict, and changes nothing.
    assert!(
        kf.prepare_predict(&process, &DVector::zeros(0), f64::NAN)
            .is_err()
    );
    // A prepared filter then steps exactly as an unprepared one.
    let mut fresh = KalmanFilter::new(prior(n));
    let z = DVector::from_element(n / 2, 0.3);
    for f in [&mut kf, &mut fresh] {
        f.predict(&process, &DVector::zeros(0), DT).unwrap();
        f.update_into(&measurement, &z, &mut report).unwrap();
    }
    assert_unchanged(&kf, fresh.state(), fresh.covariance());
}

#[test]
fn kalman_filter_does_not_allocate_per_dynamic_step() {
    for n in SIZES {
        assert_eq!(count_linear(KalmanFilter::new(prior(n)), n), 0, "n = {n}");
    }
}

#[test]
fn ekfs_do_not_allocate_per_dynamic_step() {
    for n in SIZES {
        assert_eq!(count_linear(Ekf::new(prior(n)), n), 0, "Ekf linear n = {n}");
        assert_eq!(count_nonlinear(Ekf::new(prior(n)), n), 0, "Ekf n = {n}");
        assert_eq!(
            count_nonlinear(SecondOrderEkf::new(prior(n)), n),
            0,
            "SecondOrderEkf n = {n}"
        );
    }
    // Hessian pairs make this O(m² n²): the small size only.
    assert_eq!(count_nonlinear(GaussianSecondOrderEkf::new(prior(8)), 8), 0);
}

#[test]
fn ukfs_do_not_allocate_per_dynamic_step() {
    for n in SIZES {
        assert_eq!(count_linear(Ukf::new(prior(n)), n), 0, "Ukf linear n = {n}");
        assert_eq!(count_nonlinear(Ukf::new(prior(n)), n), 0, "Ukf n = {n}");
        let cubature = GaussianFilter::with_propagator(prior(n), Unscented::cubature());
        assert_eq!(count_nonlinear(cubature, n), 0, "cubature n = {n}");
    }
}

#[test]
fn square_root_filters_do_not_allocate_per_dynamic_step() {
    // Runtime sizes up to 16 pre-array rows are triangularised by reflections, larger ones by
    // rotations: n = 8 (12 and 14 rows) and n = 100 take both kernels.
    for n in SIZES {
        let kf = SrKalmanFilter::new(prior(n));
        assert_eq!(count_linear(kf, n), 0, "SrKalmanFilter n = {n}");
        assert_eq!(
            count_linear(SrEkf::new(prior(n)), n),
            0,
            "SrEkf linear n = {n}"
        );
        assert_eq!(count_nonlinear(SrEkf::new(prior(n)), n), 0, "SrEkf n = {n}");
        assert_eq!(count_nonlinear(SrUkf::new(prior(n)), n), 0, "SrUkf n = {n}");
        // β < α²: R̃'s factor by a rank-one downdate.
        let cubature = SrUkf::with_propagator(prior(n), Unscented::cubature());
        assert_eq!(count_nonlinear(cubature, n), 0, "SR cubature n = {n}");
        // A state space: the correction x̂ ⊞ K̄ L⁻¹ν and the SR-UKF's ⊞/⊟ sigma points.
        let angles = WrappedAngles::new([0, 3]);
        let ekf = SrEkf::new(prior(n)).with_state_space(angles);
        assert_eq!(count_nonlinear(ekf, n), 0, "SrEkf on angles n = {n}");
        let ukf = SrUkf::new(prior(n)).with_state_space(angles);
        assert_eq!(count_nonlinear(ukf, n), 0, "SrUkf on angles n = {n}");
    }
}

#[test]
fn square_root_warm_up_allocates_once_and_a_failed_step_is_undone() {
    // Unprepared: the first step sizes the scratch (counted), the second allocates nothing.
    let n = 8;
    let (process, measurement) = linear_models(n);
    let none = DVector::zeros(0);
    let z = DVector::from_element(n / 2, 0.1);
    let mut report = UpdateReport::zeros(Dyn(n / 2));
    let mut kf = SrKalmanFilter::new(prior(n));
    let mut step = |kf: &mut SrKalmanFilter<f64, Dyn>| {
        allocations_during(|| {
            kf.predict(&process, &none, DT).unwrap();
            kf.update_into(&measurement, &z, &mut report).unwrap();
        })
    };
    assert!(step(&mut kf) > 0);
    assert_eq!(step(&mut kf), 0);
    // A prediction and an update that fail inside the cached scratch (a NaN in Q, a NaN
    // reading) change nothing, and the next steps equal those of a clone that never failed.
    let mut twin = kf.clone();
    let (x, p) = (kf.state().clone(), kf.covariance().clone());
    let mut bad_process = process.clone();
    bad_process.noise[(1, 1)] = f64::NAN;
    let bad = DVector::from_element(n / 2, f64::NAN);
    assert!(kf.predict(&bad_process, &none, DT).is_err());
    assert!(kf.update(&measurement, &bad).is_err());
    assert_unchanged(&kf, &x, &p);
    assert_eq!(kf.factor(), twin.factor());
    for filter in [&mut kf, &mut twin] {
        step(filter);
    }
    assert_unchanged(&kf, twin.state(), twin.covariance());
}

#[test]
fn fading_memory_rls_does_not_allocate_per_dynamic_step() {
    for n in SIZES {
        let (_, measurement) = linear_models(n);
        let zs = readings(n / 2);
        let mut rls = FadingMemoryRls::new(prior(n), 0.95).unwrap();
        let mut report = UpdateReport::zeros(Dyn(n / 2));
        rls.prepare_update(&measurement, &mut report).unwrap();
        assert_unchanged(
            &rls,
            &prior(n).mean().clone(),
            &prior(n).covariance().clone(),
        );
        let count = allocations_during(|| {
            for z in &zs {
                rls.update_into(&measurement, z, &mut report).unwrap();
            }
        });
        assert_eq!(count, 0, "n = {n}");
    }
}

#[test]
fn two_sensors_and_gated_updates_do_not_allocate_once_sized() {
    // One filter, two measurement lengths: each sizes its own workspace once.
    let n = 12;
    let (process, wide) = linear_models(n);
    let narrow = LinearMeasurement {
        observation: wide.observation.rows(0, 2).into_owned(),
        noise: DMatrix::identity(2, 2) * 0.1,
    };
    let none = DVector::zeros(0);
    let (z_wide, z_narrow) = (
        DVector::from_element(n / 2, 0.1),
        DVector::from_element(2, 0.1),
    );
    let (mut r_wide, mut r_narrow) = (UpdateReport::zeros(Dyn(n / 2)), UpdateReport::zeros(Dyn(2)));
    let mut kf = KalmanFilter::new(prior(n)).with_gate(1e6).unwrap();
    kf.prepare_predict(&process, &none, DT).unwrap();
    kf.prepare_update(&wide, &mut r_wide).unwrap();
    kf.prepare_update(&narrow, &mut r_narrow).unwrap();
    let far = DVector::from_element(2, 1e9);
    let count = allocations_during(|| {
        for _ in 0..5 {
            kf.predict(&process, &none, DT).unwrap();
            kf.update_into(&wide, &z_wide, &mut r_wide).unwrap();
            kf.update_into(&narrow, &z_narrow, &mut r_narrow).unwrap();
            // Gated: reported, not applied, and still no allocation.
            kf.update_into(&narrow, &far, &mut r_narrow).unwrap();
            assert!(!r_narrow.applied());
        }
    });
    assert_eq!(count, 0);
}
