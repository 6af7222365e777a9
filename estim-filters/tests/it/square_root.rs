//! The square-root filters (`SrKalmanFilter`, `SrEkf`, `SrUkf`): the Kalman filter on
//! well-conditioned problems, still working on ill-conditioned ones where the full-P forms fail,
//! and typed errors that leave the filter bit-identical.

use crate::common;

use common::{
    LinearSystem, Trajectory, UKF_SMALL_ALPHA_STATE_TOL, assert_runs_agree_to, random_dyn_system,
    random_static_system, rng, run, run_reference, simulate,
};
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Matrix1, Matrix2, Matrix2x3, Matrix3, OMatrix, U1, U3,
    Vector1, Vector2, Vector3,
};
use estim_core::propagate::Unscented;
use estim_core::{
    Alloc, Error, Gaussian, LinearMeasurement, LinearProcess, MeasurementModel, Quantity, Real,
    Stage,
};
use estim_filters::{
    CovarianceUpdate, Ekf, Estimator, KalmanFilter, Predict, SquareRootFilter, SrEkf,
    SrKalmanFilter, SrUkf, Update, UpdateOutcome,
};
use proptest::prelude::*;

/// Steps per run.
const STEPS: usize = 50;

/// Agreement with the hand-written Kalman filter (relative, `common::estimate_rel_diff`).
///
/// The array form and the Joseph form compute the same posterior; each is backward stable,
/// so they differ by the forward error of the Kalman recursion, ≈ c ε κ with κ the condition
/// number of S = H P Hᵀ + R and of P. The random systems have eigenvalues of Q ≥ 0.01,
/// R ≥ 0.05 and ‖P‖ ≲ 10, so κ ≲ 10³ and one step's difference is ≲ 10³ ε ≈ 2·10⁻¹³; the
/// stable closed loop (ρ ≤ 0.97) accumulates at most 1/(1 − ρ) ≈ 30 steps' worth: ≈ 7·10⁻¹².
/// 1e-9 (the equivalence tests' figure) leaves > 100× margin. The SR-UKF with α = 10⁻³ has
/// the same state round-off as the UKF (`common::UKF_SMALL_ALPHA_STATE_TOL`: ε/α² in the
/// sigma-point mean), which no factorisation changes.
const TOL: f64 = 1e-9;

fn check_system<N, M, U>(system: &LinearSystem<N, M, U>, traj: &Trajectory<N, M, U>)
where
    N: Dim,
    M: Dim,
    U: Dim,
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    let prior = || system.prior.clone();
    let truth = run_reference(system, traj);
    assert_runs_agree_to(
        &run(SrKalmanFilter::new(prior()), system, traj),
        &truth,
        TOL,
        TOL,
        "SR-KF",
    );
    assert_runs_agree_to(
        &run(SrEkf::new(prior()), system, traj),
        &truth,
        TOL,
        TOL,
        "SR-EKF",
    );
    assert_runs_agree_to(
        &run(SrUkf::new(prior()), system, traj),
        &truth,
        UKF_SMALL_ALPHA_STATE_TOL,
        TOL,
        "SR-UKF (alpha = 1e-3)",
    );
    // β − α² = −1 < 0: the centre term is a downdate.
    assert_runs_agree_to(
        &run(
            SquareRootFilter::with_propagator(prior(), Unscented::cubature()),
            system,
            traj,
        ),
        &truth,
        TOL,
        TOL,
        "SR cubature",
    );
    // And the Joseph-form filters of the same name agree with them, to the same tolerance.
    assert_runs_agree_to(
        &run(KalmanFilter::new(prior()), system, traj),
        &truth,
        TOL,
        TOL,
        "KF",
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn equal_to_the_kalman_filter_static(seed in any::<u64>()) {
        let mut r = rng(seed);
        let system = random_static_system(&mut r);
        let traj = simulate(&mut r, &system, STEPS);
        check_system(&system, &traj);
    }

    #[test]
    fn equal_to_the_kalman_filter_dynamic(seed in any::<u64>(), n in 1usize..7, m in 1usize..4) {
        let mut r = rng(seed);
        let system = random_dyn_system(&mut r, n, m, 1);
        let traj = simulate(&mut r, &system, STEPS);
        check_system(&system, &traj);
    }
}

/// The factor is lower triangular with a non-negative diagonal and reproduces the cached P.
#[test]
fn factor_is_triangular_and_reproduces_the_covariance() {
    let mut r = rng(7);
    let system = random_static_system(&mut r);
    let traj = simulate(&mut r, &system, 10);
    let mut ukf = SrUkf::new(system.prior.clone());
    for (u, z) in traj.inputs.iter().zip(&traj.measurements) {
        ukf.predict(&system.process, u, 1.0).unwrap();
        ukf.update(&system.measurement, z).unwrap();
        let s = ukf.factor();
        for i in 0..4 {
            assert!(s[(i, i)] >= 0.0);
            for j in i + 1..4 {
                assert_eq!(s[(i, j)], 0.0);
            }
        }
        // P is formed from S once per step: equal to S Sᵀ to the bit.
        let p = s * s.transpose();
        assert!((p - ukf.covariance()).abs().max() <= 4.0 * f64::EPSILON * p.abs().max());
    }
}

// ---------------------------------------------------------------------------------------
// Ill-conditioned: R ≪ P.

/// A process, a sensor and a prior.
type Stiff<T> = (
    LinearProcess<T, U3, U1>,
    LinearMeasurement<T, U3, estim_core::nalgebra::U2>,
    Gaussian<T, U3>,
);

/// The problem (b) on a 3-state system: P₀ = 10⁶ I, position and velocity measured
/// with R = 10⁻¹² I, a constant-velocity-plus-bias transition, Q = 10⁻⁶ I.
fn stiff_system<T: Real>() -> Stiff<T> {
    let c = |v: f64| estim_core::scalar::real::<T>(v);
    let process = LinearProcess {
        transition: Matrix3::new(1.0, 0.1, -0.005, 0.0, 1.0, -0.1, 0.0, 0.0, 1.0).map(c),
        input: Vector3::zeros(),
        noise: Matrix3::identity() * c(1e-6),
    };
    let sensor = LinearMeasurement {
        observation: Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0).map(c),
        noise: Matrix2::identity() * c(1e-12),
    };
    let prior = Gaussian::new(Vector3::zeros(), Matrix3::identity() * c(1e6)).unwrap();
    (process, sensor, prior)
}

/// Every update succeeds in the square-root forms, in f32 and f64, and P stays positive
/// semi-definite with the measured states known to ≈ √R. The f32 full-P forms fail where the
/// issue says: the first update is `NotPositiveDefinite` in every covariance form.
#[test]
fn r_much_smaller_than_p_square_root_forms_survive() {
    fn check<T: Real + Into<f64>>() {
        let (process, sensor, prior) = stiff_system::<T>();
        let z = Vector2::new(T::one(), T::one());
        let u = Vector1::zeros();
        let mut kf = SrKalmanFilter::new(prior.clone());
        let mut ekf = SrEkf::new(prior.clone());
        let mut ukf = SrUkf::new(prior.clone());
        for _ in 0..200 {
            kf.predict(&process, &u, T::one()).unwrap();
            ekf.predict(&process, &u, T::one()).unwrap();
            ukf.predict(&process, &u, T::one()).unwrap();
            kf.update(&sensor, &z).unwrap();
            ekf.update(&sensor, &z).unwrap();
            ukf.update(&sensor, &z).unwrap();
        }
        for p in [kf.covariance(), ekf.covariance(), ukf.covariance()] {
            let p = p.map(Into::into);
            let eig = p.symmetric_eigen().eigenvalues;
            // PSD to the rounding of forming S Sᵀ (≈ ε ‖P‖).
            assert!(eig.min() >= -1e-5 * p.abs().max(), "{eig}");
            assert!(p.diagonal().iter().all(|v| *v >= 0.0));
        }
    }
    check::<f32>();
    check::<f64>();
}

#[test]
fn r_much_smaller_than_p_full_forms_fail_in_f32() {
    let (process, sensor, prior) = stiff_system::<f32>();
    let z = Vector2::new(1.0f32, 1.0);
    let u = Vector1::zeros();
    for form in [
        CovarianceUpdate::Joseph,
        CovarianceUpdate::Standard,
        CovarianceUpdate::Symmetrized,
    ] {
        let mut kf = KalmanFilter::new(prior.clone()).with_covariance_update(form);
        let failed = (0..20)
            .any(|_| kf.predict(&process, &u, 1.0).is_err() || kf.update(&sensor, &z).is_err());
        assert!(failed, "{form:?}: the f32 full-P filter survived 20 steps");
    }
}

// ---------------------------------------------------------------------------------------
// Bad input: a typed error and the filter bit-identical.

fn bits<T: Real + Into<f64>, R: Dim, C: Dim>(m: &OMatrix<T, R, C>) -> Vec<u64>
where
    DefaultAllocator: estim_core::nalgebra::allocator::Allocator<R, C>,
{
    m.iter().map(|v| Into::<f64>::into(*v).to_bits()).collect()
}

fn snapshot<T: Real + Into<f64>, N: Dim, F: Estimator<T, N>>(
    f: &F,
    factor: &OMatrix<T, N, N>,
) -> Vec<u64>
where
    DefaultAllocator: Alloc<N>,
{
    [bits(f.state()), bits(f.covariance()), bits(factor)].concat()
}

/// Asserts `call` fails with `expected` and leaves `filter` as it was (`==` and bitwise).
fn assert_refused<T, N, Pr>(
    filter: &mut SquareRootFilter<T, N, Pr>,
    expected: Error,
    call: impl FnOnce(&mut SquareRootFilter<T, N, Pr>) -> Result<(), Error>,
) where
    T: Real + Into<f64>,
    N: Dim,
    Pr: Clone + PartialEq + std::fmt::Debug,
    DefaultAllocator: Alloc<N>,
{
    let before = filter.clone();
    let before_bits = snapshot(&before, before.factor());
    assert_eq!(call(filter), Err(expected));
    assert_eq!(*filter, before);
    assert_eq!(snapshot(filter, filter.factor()), before_bits);
}

fn bad_input_for<T: Real + Into<f64>, Pr: Clone + PartialEq + std::fmt::Debug + Default>()
where
    SquareRootFilter<T, U3, Pr>: Predict<T, U3, LinearProcess<T, U3, U1>>
        + Update<T, U3, estim_core::nalgebra::U2, LinearMeasurement<T, U3, estim_core::nalgebra::U2>>,
{
    let c = |v: f64| estim_core::scalar::real::<T>(v);
    let (process, sensor, _) = stiff_system::<T>();
    let prior = Gaussian::new(Vector3::new(c(1.0), c(2.0), c(3.0)), Matrix3::identity()).unwrap();
    let mut f: SquareRootFilter<T, U3, Pr> = SquareRootFilter::new(prior);
    let u = Vector1::zeros();
    f.predict(&process, &u, T::one()).unwrap();
    let z = Vector2::new(c(1.0), c(2.0));
    f.update(&sensor, &z).unwrap();

    let (pred, upd) = (Stage::Prediction, Stage::Update);
    let nan = c(f64::NAN);
    assert_refused(
        &mut f,
        Error::NonFinite {
            stage: upd,
            quantity: Quantity::Measurement,
        },
        |f| f.update(&sensor, &Vector2::new(nan, T::one())).map(|_| ()),
    );
    let mut indefinite_r = sensor.clone();
    indefinite_r.noise = Matrix2::new(c(1.0), c(2.0), c(2.0), c(1.0));
    assert_refused(
        &mut f,
        Error::NotPositiveSemiDefinite {
            stage: upd,
            quantity: Quantity::MeasurementNoise,
        },
        |f| f.update(&indefinite_r, &z).map(|_| ()),
    );
    let mut nan_r = sensor.clone();
    nan_r.noise[(1, 0)] = nan;
    assert_refused(
        &mut f,
        Error::NonFinite {
            stage: upd,
            quantity: Quantity::MeasurementNoise,
        },
        |f| f.update(&nan_r, &z).map(|_| ()),
    );
    let mut indefinite_q = process.clone();
    indefinite_q.noise = Matrix3::new(
        c(1.0),
        c(2.0),
        c(0.0),
        c(2.0),
        c(1.0),
        c(0.0),
        c(0.0),
        c(0.0),
        c(1.0),
    );
    assert_refused(
        &mut f,
        Error::NotPositiveSemiDefinite {
            stage: pred,
            quantity: Quantity::ProcessNoise,
        },
        |f| f.predict(&indefinite_q, &u, T::one()),
    );
    let mut nan_q = process.clone();
    nan_q.noise[(2, 2)] = nan;
    assert_refused(
        &mut f,
        Error::NonFinite {
            stage: pred,
            quantity: Quantity::ProcessNoise,
        },
        |f| f.predict(&nan_q, &u, T::one()),
    );
    let negative = Error::InvalidParameter {
        parameter: estim_core::Parameter::TimeStep,
        value: -1.0,
    };
    assert_refused(&mut f, negative, |f| f.predict(&process, &u, -T::one()));
    assert_refused(
        &mut f,
        Error::NonFinite {
            stage: pred,
            quantity: Quantity::TimeStep,
        },
        |f| f.predict(&process, &u, nan),
    );
    // dt = 0 is allowed (a prediction over no time adds Q(0)).
    let mut g = f.clone();
    g.predict(&process, &u, T::zero()).unwrap();
}

#[test]
fn bad_input_is_a_typed_error_and_leaves_the_filter_unchanged() {
    bad_input_for::<f64, estim_core::Affine>();
    bad_input_for::<f32, estim_core::Affine>();
    bad_input_for::<f64, estim_core::Linearized>();
    bad_input_for::<f32, estim_core::Linearized>();
    bad_input_for::<f64, Unscented<f64>>();
    bad_input_for::<f32, Unscented<f32>>();
}

/// h(x) = (x − 1)² with no noise: even about the prior mean x̂ = 1, so every sigma point
/// sees the same deviation from the predicted measurement.
struct EvenAboutOne;
impl<T: Real> MeasurementModel<T, U1, U1> for EvenAboutOne {
    fn measure(&self, x: &Vector1<T>) -> Vector1<T> {
        x.map(|v| (v - T::one()) * (v - T::one()))
    }
    fn measurement_noise(&self, _: &Vector1<T>) -> Matrix1<T> {
        Matrix1::zeros()
    }
}

/// The accepted unscented rules give a PSD predicted measurement covariance for every model
/// (estim_core::Unscented, "Accepted parameters"), so a centre downdate can fail only where
/// that covariance is singular. At the boundary α²κ + nβ = 0 (α = 1, β = ½, κ = −½, n = 1:
/// c = ½, w = 1/(2c) = 1) and a model even about x̂ = 1, the points 1 ± 1/√2 both deviate from
/// h(x̂) = 0 by d = ½, so cov(ẑ) = w Σ d² + (β − α²) w² (Σ d)² = ½ − ½ = 0, up to the rounding
/// of (±1/√2)²,
/// and with R = 0, S is singular. The square-root update must refuse it with a typed error and
/// leave the filter unchanged; the full-P UKF refuses it too.
#[test]
fn a_failed_downdate_is_a_typed_error() {
    fn check<T: Real + Into<f64>>() {
        let half = estim_core::scalar::real::<T>(0.5);
        let rule = Unscented::new(T::one(), half, -half).unwrap();
        rule.check_dimension(1).unwrap();
        let prior = Gaussian::new(Vector1::new(T::one()), Matrix1::new(T::one())).unwrap();
        let mut f = SrUkf::with_propagator(prior.clone(), rule);
        let z = Vector1::new(estim_core::scalar::real::<T>(1.5));
        assert_refused(
            &mut f,
            Error::NotPositiveDefinite {
                stage: Stage::Update,
                quantity: Quantity::InnovationCovariance,
            },
            |f| f.update(&EvenAboutOne, &z).map(|_| ()),
        );
        let mut full = estim_filters::GaussianFilter::with_propagator(prior, rule);
        assert!(full.update(&EvenAboutOne, &z).is_err());
    }
    check::<f64>();
    check::<f32>();
}

/// The SR-UKF checks the unscented parameters against the state dimension as the UKF does
/// (`Unscented::check_dimension`): α = 1, β = −1, κ = 2 is accepted by `Unscented::new`
/// (α²κ + β ≥ 0 at n = 1) but not at n = 3 (α²κ + 3β = −1 < 0), though c = α²(n + κ) = 5 > 0,
/// the only condition the SR-UKF checked before. Both steps refuse it with the UKF's error and
/// leave the filter unchanged.
#[test]
fn sr_ukf_checks_the_unscented_parameters_for_the_dimension() {
    let rule = Unscented::new(1.0, -1.0, 2.0).unwrap();
    let expected = rule.check_dimension(3).unwrap_err();
    assert!(matches!(
        expected,
        Error::InvalidParameter {
            parameter: estim_core::Parameter::UnscentedBeta,
            ..
        }
    ));
    let prior = Gaussian::new(Vector3::new(1.0, 0.0, -1.0), Matrix3::identity()).unwrap();
    let process = LinearProcess {
        transition: Matrix3::identity(),
        input: Matrix3::zeros(),
        noise: Matrix3::identity() * 0.1,
    };
    let sensor = LinearMeasurement {
        observation: Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
        noise: Matrix2::identity(),
    };
    let mut sr = SrUkf::with_propagator(prior.clone(), rule);
    assert_refused(&mut sr, expected, |f| {
        f.predict(&process, &Vector3::zeros(), 0.1)
    });
    assert_refused(&mut sr, expected, |f| {
        f.update(&sensor, &Vector2::new(1.0, 0.0)).map(|_| ())
    });
    let mut full = estim_filters::GaussianFilter::with_propagator(prior, rule);
    assert_eq!(
        full.predict(&process, &Vector3::zeros(), 0.1),
        Err(expected)
    );
}

/// Gating: the same NIS, log-likelihood and outcome as the Joseph-form filter, and a gated
/// update changes nothing.
#[test]
fn reports_and_gating_match_the_joseph_form() {
    let mut r = rng(11);
    let system = random_static_system(&mut r);
    let traj = simulate(&mut r, &system, 5);
    let mut sr = SrEkf::new(system.prior.clone()).with_gate(3.0).unwrap();
    let mut ekf = Ekf::new(system.prior.clone()).with_gate(3.0).unwrap();
    let mut gated = 0;
    for (u, z) in traj.inputs.iter().zip(&traj.measurements) {
        sr.predict(&system.process, u, 1.0).unwrap();
        ekf.predict(&system.process, u, 1.0).unwrap();
        let z = z * 3.0; // some of these fall outside the gate
        let before = sr.clone();
        let a = sr.update(&system.measurement, &z).unwrap();
        let b = ekf.update(&system.measurement, &z).unwrap();
        assert_eq!(a.outcome, b.outcome);
        // Same reasoning as TOL: round-off of order ε κ(S).
        assert!((a.nis - b.nis).abs() <= TOL * b.nis.max(1.0));
        assert!(
            (a.log_likelihood - b.log_likelihood).abs() <= TOL * b.log_likelihood.abs().max(1.0)
        );
        assert!(
            (a.innovation - b.innovation).abs().max() <= TOL * b.innovation.abs().max().max(1.0)
        );
        assert!(
            (a.innovation_covariance - b.innovation_covariance)
                .abs()
                .max()
                <= TOL * b.innovation_covariance.abs().max()
        );
        if a.outcome == UpdateOutcome::Gated {
            gated += 1;
            assert_eq!(sr, before);
        }
    }
    assert!(gated > 0, "the test should exercise the gate");
}

/// A measurement whose length does not match the model (runtime sizes) is a dimension error.
#[test]
fn runtime_size_mismatch_is_a_typed_error() {
    let prior = Gaussian::new(DVector::zeros(3), DMatrix::identity(3, 3)).unwrap();
    let sensor = LinearMeasurement {
        observation: DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
        noise: DMatrix::identity(2, 2),
    };
    let mut kf = SrKalmanFilter::new(prior.clone());
    let before = kf.clone();
    assert!(matches!(
        kf.update(&sensor, &DVector::zeros(3)),
        Err(Error::DimensionMismatch { .. })
    ));
    assert_eq!(kf, before);
    let mut ukf = SrUkf::new(prior);
    assert!(matches!(
        ukf.update(&sensor, &DVector::zeros(3)),
        Err(Error::DimensionMismatch { .. })
    ));
}

// ---------------------------------------------------------------------------------------
// f32 on Lu's bias calibration (the short version of `examples/f32_survival.rs`).

/// Lu's 3-state error model (estim_models::lu; written out here because estim-filters cannot
/// depend on estim-models): 200 Hz, GPS position and velocity every 40 steps, Q = Γ W Γᵀ of
/// rank one (no process noise on the bias). Open loop (the filter holds the whole error
/// state) and closed loop (after each fix the estimate goes into a nominal kept in f64 and
/// the filter restarts from x̂ = 0 with its factor kept, `SquareRootFilter::set_state`): the
/// configuration that stays consistent for 10⁶ steps in the example, where the open loop
/// leaves the band at step 120 000.
#[test]
fn f32_square_root_forms_stay_consistent_on_lu_calibration() {
    const DT: f64 = 0.005;
    const W: f64 = 0.0004;
    const SEEDS: usize = 8;
    const STEPS: usize = 4000; // 100 fixes
    let phi = Matrix3::new(1.0, DT, -DT * DT / 2.0, 0.0, 1.0, -DT, 0.0, 0.0, 1.0);
    let gamma = Vector3::new(DT * DT / 2.0, DT, 0.0);
    let h = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let r = Matrix2::<f64>::new(1.0, 0.0, 0.0, 0.0016);
    let p0 = Matrix3::from_diagonal(&Vector3::new(100.0, 1.0, 0.01));
    let c = |m: Matrix3<f64>| m.map(|v| v as f32);
    let process = LinearProcess {
        transition: c(phi),
        input: Vector3::<f32>::zeros(),
        noise: c(gamma * gamma.transpose() * W),
    };
    let sensor = LinearMeasurement {
        observation: h.map(|v| v as f32),
        noise: r.map(|v| v as f32),
    };
    let prior = Gaussian::new(Vector3::zeros(), c(p0)).unwrap();
    let u = Vector1::<f32>::zeros();
    /// One step: predict, update by z if any, then in closed loop restart from x̂ = 0; returns
    /// the estimate before the restart.
    type Boxed = Box<
        dyn FnMut(
            &LinearProcess<f32, U3, U1>,
            Option<&Vector2<f32>>,
        ) -> (Vector3<f32>, Matrix3<f32>),
    >;
    fn boxed<Pr: 'static>(
        mut f: SquareRootFilter<f32, U3, Pr>,
        process_input: Vector1<f32>,
        sensor: LinearMeasurement<f32, U3, estim_core::nalgebra::U2>,
        closed: bool,
    ) -> Boxed
    where
        SquareRootFilter<f32, U3, Pr>: Predict<f32, U3, LinearProcess<f32, U3, U1>>
            + Update<
                f32,
                U3,
                estim_core::nalgebra::U2,
                LinearMeasurement<f32, U3, estim_core::nalgebra::U2>,
            >,
    {
        Box::new(move |process, z| {
            f.predict(process, &process_input, 0.005)
                .expect("every prediction succeeds");
            let estimate = (*f.state(), *f.covariance());
            if let Some(z) = z {
                assert!(
                    f.update(&sensor, z)
                        .expect("every update succeeds")
                        .applied()
                );
                let estimate = (*f.state(), *f.covariance());
                if closed {
                    let factor = *f.factor();
                    f.set_state(Vector3::zeros()).unwrap();
                    assert_eq!(f.factor(), &factor, "the restart keeps the factor");
                }
                return estimate;
            }
            estimate
        })
    }
    for (name, closed) in [
        ("SR-KF", false),
        ("SR-EKF", false),
        ("SR-UKF", false),
        ("SR-KF", true),
        ("SR-EKF", true),
        ("SR-UKF", true),
    ] {
        let mut truths = Vec::new();
        let mut filters: Vec<Boxed> = Vec::new();
        let mut rngs = Vec::new();
        for seed in 0..SEEDS {
            let mut g = rng(1000 + seed as u64);
            let l0 = p0.cholesky().unwrap().l();
            truths.push(
                l0 * Vector3::new(
                    common::normal(&mut g),
                    common::normal(&mut g),
                    common::normal(&mut g),
                ),
            );
            rngs.push(g);
            filters.push(match name {
                "SR-KF" => boxed(
                    SrKalmanFilter::new(prior.clone()),
                    u,
                    sensor.clone(),
                    closed,
                ),
                "SR-EKF" => boxed(SrEkf::new(prior.clone()), u, sensor.clone(), closed),
                _ => boxed(SrUkf::new(prior.clone()), u, sensor.clone(), closed),
            });
        }
        // The closed loop's nominal, in f64 (zero, the prior mean, in open loop throughout).
        let mut nominals = vec![Vector3::<f64>::zeros(); SEEDS];
        let (mut sum, mut fixes) = (0.0, 0);
        for step in 1..=STEPS {
            let fix = step % 40 == 0;
            let runs = truths.iter_mut().zip(&mut rngs).zip(&mut filters);
            for (((x, g), f), nominal) in runs.zip(&mut nominals) {
                *x = phi * *x - gamma * (W.sqrt() * common::normal(g));
                *nominal = phi * *nominal;
                let z = fix.then(|| {
                    let v = Vector2::new(common::normal(g), r[(1, 1)].sqrt() * common::normal(g));
                    (h * (*x - *nominal) + v).map(|v| v as f32)
                });
                let (xhat, p) = f(&process, z.as_ref());
                if fix {
                    if closed {
                        *nominal += xhat.map(f64::from);
                    }
                    let e = *x
                        - *nominal
                        - if closed {
                            Vector3::zeros()
                        } else {
                            xhat.map(f64::from)
                        };
                    let p = p.map(f64::from);
                    let chol = p.cholesky().expect("P stays positive definite");
                    sum += e.dot(&chol.solve(&e)) / SEEDS as f64;
                }
            }
            fixes += usize::from(fix);
        }
        // Ensemble NEES averaged over the 100 fixes. At one fix it is χ²(3·8)/8 for consistent
        // runs; the fixes are correlated in time (the bias error changes slowly), so the mean
        // over fixes gets the band of a single fix, χ²₂₄ at 0.05 % and 99.95 % (Wilson–
        // Hilferty): [7.1, 53.0]/8 = [0.9, 6.6]. Conservative, and nowhere near the 10⁷ of an
        // overconfident filter.
        let nees = sum / fixes as f64;
        let (lo, hi) = (
            common::chi2_quantile_wilson_hilferty(24.0, -3.29) / 8.0,
            common::chi2_quantile_wilson_hilferty(24.0, 3.29) / 8.0,
        );
        assert!(
            (lo..=hi).contains(&nees),
            "{name} (closed loop: {closed}): NEES {nees} outside [{lo}, {hi}]"
        );
    }
}

/// Issue 41, defect 1: a step whose factor is finite but whose P = S Sᵀ overflows (from
/// N(0, I₂), F = 10²⁰⁰ I with Q = 0 gives S⁻ = 10²⁰⁰ I, P⁻ = 10⁴⁰⁰ I = ∞ in f64) returned `Ok`
/// with an infinite covariance. It is a typed error now, the filter unchanged, for the KF, EKF
/// and UKF forms.
#[test]
fn a_step_whose_covariance_overflows_is_refused() {
    fn check<Pr: Clone + PartialEq + std::fmt::Debug + Default>()
    where
        SquareRootFilter<f64, estim_core::nalgebra::U2, Pr>: Predict<f64, estim_core::nalgebra::U2, LinearProcess<f64, estim_core::nalgebra::U2, U1>>
            + Update<
                f64,
                estim_core::nalgebra::U2,
                U1,
                LinearMeasurement<f64, estim_core::nalgebra::U2, U1>,
            >,
    {
        let expected = |stage| Error::NonFinite {
            stage,
            quantity: Quantity::Covariance,
        };
        let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity()).unwrap();
        let huge = LinearProcess {
            transition: Matrix2::identity() * 1e200,
            input: estim_core::nalgebra::Matrix2x1::zeros(),
            noise: Matrix2::zeros(),
        };
        let mut f: SquareRootFilter<f64, _, Pr> = SquareRootFilter::new(prior);
        let u = Vector1::zeros();
        assert_refused(&mut f, expected(Stage::Prediction), |f| {
            f.predict(&huge, &u, 1.0)
        });
        // A factor of 10¹⁵⁴ I is finite and so is its P (10³⁰⁸ I); one more factor of 10 in S
        // through F = 10 I is still a finite S (10¹⁵⁵ I) but P = 10³¹⁰ I = ∞.
        let tenfold = LinearProcess {
            transition: Matrix2::identity() * 10.0,
            ..huge.clone()
        };
        let big = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 1e308).unwrap();
        let mut g: SquareRootFilter<f64, _, Pr> = SquareRootFilter::new(big);
        assert!(g.covariance().iter().all(|v| v.is_finite()));
        assert_refused(&mut g, expected(Stage::Prediction), |g| {
            g.predict(&tenfold, &u, 1.0)
        });
    }
    check::<estim_core::Affine>();
    check::<estim_core::Linearized>();
    check::<Unscented<f64>>();
}
