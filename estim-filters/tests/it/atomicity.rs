//! Failures are atomic: any error in predict or update leaves the filter bit for bit as it
//! was, and the error names the right stage and quantity. Also gating and the statistics of
//! the update report (innovation, S, NIS, log-likelihood) against hand computation.

use crate::common;

use core::fmt::Debug;

use common::{UKF_SMALL_ALPHA_STATE_TOL, assert_bitwise_eq, gaussian_matrix, random_spd, rng};
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Matrix2, Matrix2x3, Matrix3, Matrix3x2, U1, U2, U3,
    Vector1, Vector2, Vector3,
};
use estim_core::propagate::Unscented;
use estim_core::{
    Alloc, Error, Gaussian, LinearMeasurement, LinearProcess, Parameter, Quantity, Stage,
};
use estim_filters::{
    Ekf, Estimator, FadingMemoryRls, Gate, GaussianFilter, GaussianSecondOrderEkf, KalmanFilter,
    Predict, PredictCorrelated, SecondOrderEkf, Ukf, Update, UpdateOutcome,
};

/// Runs `op`, which must fail with `expected`, and asserts the filter is unchanged: equal as a
/// whole (`==`, which covers its configuration) and bit for bit in state and covariance.
#[track_caller]
fn assert_fails_atomically<F, N, R>(
    filter: &mut F,
    expected: Error,
    op: impl FnOnce(&mut F) -> Result<R, Error>,
) where
    N: Dim,
    DefaultAllocator: Alloc<N>,
    F: Estimator<f64, N> + Clone + PartialEq + Debug,
    R: Debug,
{
    let before = filter.clone();
    let result = op(filter);
    assert_eq!(result.unwrap_err(), expected);
    assert!(*filter == before, "filter changed by a failed step");
    assert_bitwise_eq(filter.state(), before.state(), "state after a failed step");
    assert_bitwise_eq(
        filter.covariance(),
        before.covariance(),
        "covariance after a failed step",
    );
}

struct Models {
    process: LinearProcess<f64, U3, U1>,
    measurement: LinearMeasurement<f64, U3, U2>,
    cross: Matrix3x2<f64>,
    prior: Gaussian<f64, U3>,
}

fn models() -> Models {
    let mut r = rng(1);
    let q = random_spd(&mut r, U3, 0.5, 0.05);
    let rr = random_spd(&mut r, U2, 0.5, 0.1);
    Models {
        process: LinearProcess {
            transition: common::random_stable(&mut r, U3, 0.9),
            input: gaussian_matrix(&mut r, U3, U1),
            noise: q,
        },
        measurement: LinearMeasurement {
            observation: gaussian_matrix(&mut r, U2, U3),
            noise: rr,
        },
        // Small enough that Q − S R⁻¹ Sᵀ stays PSD.
        cross: gaussian_matrix(&mut r, U3, U2) * 0.01,
        prior: Gaussian::new(
            Vector3::new(0.5, -1.0, 2.0),
            random_spd(&mut r, U3, 1.0, 0.1),
        )
        .unwrap(),
    }
}

type Lp = LinearProcess<f64, U3, U1>;
type Lm = LinearMeasurement<f64, U3, U2>;

/// Every predict/update error a static-size Gaussian filter can hit on linear models.
fn check_static_filter<F>(name: &str, make: impl Fn(Gaussian<f64, U3>) -> F)
where
    F: Predict<f64, U3, Lp>
        + Update<f64, U3, U2, Lm>
        + PredictCorrelated<f64, U3, U2, Lp, Lm>
        + Clone
        + PartialEq
        + Debug,
{
    let m = models();
    let u = Vector1::new(0.3);
    let mut filter = make(m.prior.clone());
    // Move away from the prior so "unchanged" is not "reset".
    for z in [Vector2::new(0.1, 0.2), Vector2::new(-0.3, 1.0)] {
        filter.predict(&m.process, &u, 0.1).unwrap();
        filter.update(&m.measurement, &z).unwrap();
    }
    println!("{name}");

    // NaN measurement.
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
        },
        |f| f.update(&m.measurement, &Vector2::new(f64::NAN, 1.0)),
    );
    // Infinite measurement.
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
        },
        |f| f.update(&m.measurement, &Vector2::new(0.0, f64::NEG_INFINITY)),
    );
    // R indefinite with a positive diagonal: refused by the update's check of R.
    let negative_r = LinearMeasurement {
        observation: m.measurement.observation,
        noise: Matrix2::new(1.0, 1e3, 1e3, 1.0),
    };
    assert_fails_atomically(
        &mut filter,
        Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
        |f| f.update(&negative_r, &Vector2::new(0.0, 0.0)),
    );
    // A negative variance in R, named as such: R = −10³ I, and one small enough that S stays
    // positive definite (accepted before the diagonal check, with a posterior whose variances
    // went negative).
    let small = Matrix2::new(-1e-3, 0.0, 0.0, 0.09);
    let h = m.measurement.observation;
    let s = h * filter.covariance() * h.transpose() + small;
    assert!(
        s.cholesky().is_some(),
        "S = H P Hᵀ + R stays positive definite"
    );
    for noise in [-Matrix2::identity() * 1e3, small] {
        let model = LinearMeasurement {
            observation: m.measurement.observation,
            noise,
        };
        assert_fails_atomically(
            &mut filter,
            Error::NotPositiveSemiDefinite {
                stage: Stage::Update,
                quantity: Quantity::MeasurementNoise,
            },
            |f| f.update(&model, &Vector2::new(0.0, 0.0)),
        );
    }
    // NaN in R.
    let nan_r = LinearMeasurement {
        observation: m.measurement.observation,
        noise: Matrix2::new(1.0, 0.0, 0.0, f64::NAN),
    };
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
        |f| f.update(&nan_r, &Vector2::new(0.0, 0.0)),
    );
    // An update that fails late, after the gain is computed: H = 10⁻³ I-like and tiny R give
    // a gain ≈ 500, and an innovation of 10³⁰⁷ then overflows the new state.
    let tiny_h = LinearMeasurement {
        observation: Matrix2x3::new(1e-3, 0.0, 0.0, 0.0, 1e-3, 0.0),
        noise: Matrix2::identity() * 1e-12,
    };
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Mean,
        },
        |f| f.update(&tiny_h, &Vector2::new(1e307, -1e307)),
    );

    // NaN and infinite time steps.
    for dt in [f64::NAN, f64::INFINITY] {
        assert_fails_atomically(
            &mut filter,
            Error::NonFinite {
                stage: Stage::Prediction,
                quantity: Quantity::TimeStep,
            },
            |f| f.predict(&m.process, &u, dt),
        );
    }
    // A negative time step, even though this Q does not depend on Δt.
    assert_fails_atomically(
        &mut filter,
        Error::InvalidParameter {
            parameter: Parameter::TimeStep,
            value: -0.1,
        },
        |f| f.predict(&m.process, &u, -0.1),
    );
    // NaN in Q.
    let mut nan_q = m.process.clone();
    nan_q.noise[(1, 2)] = f64::NAN;
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
        },
        |f| f.predict(&nan_q, &u, 0.1),
    );
    // A negative variance in Q (P⁻ = F P Fᵀ + Q would lose positive definiteness silently).
    let mut negative_q = m.process.clone();
    negative_q.noise = -Matrix3::identity() * 5.0;
    assert_fails_atomically(
        &mut filter,
        Error::NotPositiveSemiDefinite {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
        },
        |f| f.predict(&negative_q, &u, 0.1),
    );
    // A prediction that fails after the moments are computed: F P Fᵀ overflows.
    let mut exploding = m.process.clone();
    exploding.transition = Matrix3::identity() * 1e200;
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Propagation,
            quantity: Quantity::Covariance,
        },
        |f| f.predict(&exploding, &u, 0.1),
    );

    // Correlated prediction: S inconsistent with Q and R (Q − S R⁻¹ Sᵀ indefinite).
    let huge_cross = Matrix3x2::from_element(10.0);
    assert_fails_atomically(
        &mut filter,
        Error::NotPositiveSemiDefinite {
            stage: Stage::Prediction,
            quantity: Quantity::NoiseCrossCovariance,
        },
        |f| {
            f.predict_correlated(
                &m.process,
                &u,
                0.1,
                &m.measurement,
                &Vector2::zeros(),
                &huge_cross,
            )
        },
    );
    // ... R not positive definite.
    assert_fails_atomically(
        &mut filter,
        Error::NotPositiveDefinite {
            stage: Stage::Prediction,
            quantity: Quantity::MeasurementNoise,
        },
        |f| {
            f.predict_correlated(
                &m.process,
                &u,
                0.1,
                &negative_r,
                &Vector2::zeros(),
                &m.cross,
            )
        },
    );
    // ... NaN in the reading, in S, in dt.
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::Measurement,
        },
        |f| {
            f.predict_correlated(
                &m.process,
                &u,
                0.1,
                &m.measurement,
                &Vector2::new(f64::NAN, 0.0),
                &m.cross,
            )
        },
    );
    let mut nan_cross = m.cross;
    nan_cross[(2, 1)] = f64::NAN;
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::NoiseCrossCovariance,
        },
        |f| {
            f.predict_correlated(
                &m.process,
                &u,
                0.1,
                &m.measurement,
                &Vector2::zeros(),
                &nan_cross,
            )
        },
    );
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::TimeStep,
        },
        |f| {
            f.predict_correlated(
                &m.process,
                &u,
                f64::NAN,
                &m.measurement,
                &Vector2::zeros(),
                &m.cross,
            )
        },
    );

    // The filter still works after all that, and a consistent S is accepted.
    filter
        .predict_correlated(
            &m.process,
            &u,
            0.1,
            &m.measurement,
            &Vector2::zeros(),
            &m.cross,
        )
        .unwrap();
    filter
        .update(&m.measurement, &Vector2::new(0.2, 0.1))
        .unwrap();
}

#[test]
fn failed_steps_leave_every_static_filter_unchanged() {
    check_static_filter("KalmanFilter", KalmanFilter::new);
    check_static_filter("Ekf", Ekf::new);
    check_static_filter("SecondOrderEkf", SecondOrderEkf::new);
    check_static_filter("GaussianSecondOrderEkf", GaussianSecondOrderEkf::new);
    check_static_filter("Ukf", Ukf::new);
    check_static_filter("cubature Ukf", |p| {
        GaussianFilter::with_propagator(p, Unscented::cubature())
    });
}

/// The unscented filter factorises P: a covariance that is not PSD (put there by `reset`
/// with an unchecked Gaussian) fails the prediction and the update, atomically.
#[test]
fn ukf_with_indefinite_covariance_fails_atomically() {
    let m = models();
    let bad = Gaussian::new_unchecked(
        Vector3::zeros(),
        Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, 1.0)),
    );
    let mut ukf = Ukf::new(m.prior.clone());
    ukf.reset(bad);
    let err = Error::NotPositiveSemiDefinite {
        stage: Stage::Propagation,
        quantity: Quantity::Covariance,
    };
    assert_fails_atomically(&mut ukf, err, |f| {
        f.predict(&m.process, &Vector1::new(0.0), 0.1)
    });
    assert_fails_atomically(&mut ukf, err, |f| {
        f.update(&m.measurement, &Vector2::zeros())
    });
}

/// Runtime sizes add shape errors: a measurement or a Q of the wrong size.
fn check_dynamic_filter<F>(name: &str, make: impl Fn(Gaussian<f64, estim_core::nalgebra::Dyn>) -> F)
where
    F: Predict<
            f64,
            estim_core::nalgebra::Dyn,
            LinearProcess<f64, estim_core::nalgebra::Dyn, estim_core::nalgebra::Dyn>,
        > + Update<
            f64,
            estim_core::nalgebra::Dyn,
            estim_core::nalgebra::Dyn,
            LinearMeasurement<f64, estim_core::nalgebra::Dyn, estim_core::nalgebra::Dyn>,
        > + Clone
        + PartialEq
        + Debug,
{
    println!("{name}");
    let process = LinearProcess {
        transition: DMatrix::identity(3, 3) * 0.9,
        input: DMatrix::zeros(3, 0),
        noise: DMatrix::identity(3, 3) * 0.1,
    };
    let measurement = LinearMeasurement {
        observation: DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.5, 0.0, 1.0, 0.0]),
        noise: DMatrix::identity(2, 2) * 0.2,
    };
    let none = DVector::zeros(0);
    let mut filter = make(
        Gaussian::new(
            DVector::from_vec(vec![1.0, 2.0, 3.0]),
            DMatrix::identity(3, 3),
        )
        .unwrap(),
    );
    filter.predict(&process, &none, 1.0).unwrap();
    filter
        .update(&measurement, &DVector::from_vec(vec![1.0, 1.5]))
        .unwrap();

    for len in [1, 3] {
        assert_fails_atomically(
            &mut filter,
            Error::DimensionMismatch {
                stage: Stage::Update,
                quantity: Quantity::Measurement,
                expected_rows: 2,
                expected_cols: 1,
                found_rows: len,
                found_cols: 1,
            },
            |f| f.update(&measurement, &DVector::from_element(len, 1.0)),
        );
    }
    let wrong_r = LinearMeasurement {
        observation: measurement.observation.clone(),
        noise: DMatrix::identity(3, 3),
    };
    assert_fails_atomically(
        &mut filter,
        Error::DimensionMismatch {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
            expected_rows: 2,
            expected_cols: 2,
            found_rows: 3,
            found_cols: 3,
        },
        |f| f.update(&wrong_r, &DVector::from_element(2, 1.0)),
    );
    let wrong_q = LinearProcess {
        transition: process.transition.clone(),
        input: process.input.clone(),
        noise: DMatrix::identity(2, 2),
    };
    assert_fails_atomically(
        &mut filter,
        Error::DimensionMismatch {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
            expected_rows: 3,
            expected_cols: 3,
            found_rows: 2,
            found_cols: 2,
        },
        |f| f.predict(&wrong_q, &none, 1.0),
    );
    // NaN measurement, dynamic.
    assert_fails_atomically(
        &mut filter,
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
        },
        |f| f.update(&measurement, &DVector::from_vec(vec![0.0, f64::NAN])),
    );
}

#[test]
fn failed_steps_leave_every_dynamic_filter_unchanged() {
    check_dynamic_filter("KalmanFilter", KalmanFilter::new);
    check_dynamic_filter("Ekf", Ekf::new);
    check_dynamic_filter("SecondOrderEkf", SecondOrderEkf::new);
    check_dynamic_filter("GaussianSecondOrderEkf", GaussianSecondOrderEkf::new);
    check_dynamic_filter("Ukf", Ukf::new);
}

#[test]
fn failed_rls_updates_leave_it_unchanged() {
    let m = models();
    let mut rls = FadingMemoryRls::new(m.prior.clone(), 0.95).unwrap();
    rls.update(&m.measurement, &Vector2::new(0.3, 0.4)).unwrap();
    assert_fails_atomically(
        &mut rls,
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
        },
        |f| f.update(&m.measurement, &Vector2::new(f64::NAN, 0.0)),
    );
    let negative_r = LinearMeasurement {
        observation: m.measurement.observation,
        noise: Matrix2::new(1.0, 1e3, 1e3, 1.0),
    };
    assert_fails_atomically(
        &mut rls,
        Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
        |f| f.update(&negative_r, &Vector2::zeros()),
    );
    let negative_variance = LinearMeasurement {
        observation: m.measurement.observation,
        noise: Matrix2::new(-1e-3, 0.0, 0.0, 0.09),
    };
    assert_fails_atomically(
        &mut rls,
        Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
        |f| f.update(&negative_variance, &Vector2::zeros()),
    );
    let mut dynamic = FadingMemoryRls::new(
        Gaussian::new(DVector::zeros(2), DMatrix::identity(2, 2)).unwrap(),
        0.9,
    )
    .unwrap();
    let model = LinearMeasurement {
        observation: DMatrix::identity(2, 2),
        noise: DMatrix::identity(2, 2),
    };
    assert_fails_atomically(
        &mut dynamic,
        Error::DimensionMismatch {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
            expected_rows: 2,
            expected_cols: 1,
            found_rows: 5,
            found_cols: 1,
        },
        |f| f.update(&model, &DVector::zeros(5)),
    );
}

// ---------------------------------------------------------------------------------------------
// Gating and the update report.

/// The report's statistics recomputed by hand from the filter's state before the update:
/// ν = z − H x̂, S = H P Hᵀ + R, NIS = νᵀ S⁻¹ ν (explicit inverse),
/// ln p(z) = −½ (NIS + ln det S + m ln 2π).
fn hand_report<F: Estimator<f64, U3>>(
    filter: &F,
    meas: &Lm,
    z: &Vector2<f64>,
) -> (Vector2<f64>, Matrix2<f64>, f64, f64) {
    let h = meas.observation;
    let nu = z - h * filter.state();
    let s = h * filter.covariance() * h.transpose() + meas.noise;
    let nis = (nu.transpose() * s.try_inverse().unwrap() * nu)[0];
    let log_likelihood =
        -0.5 * (nis + s.determinant().ln() + 2.0 * (2.0 * core::f64::consts::PI).ln());
    (nu, s, nis, log_likelihood)
}

/// Checks the report of one update against [`hand_report`], relative tolerance `tol`.
fn check_report<F>(name: &str, mut filter: F, tol: f64)
where
    F: Update<f64, U3, U2, Lm> + Clone,
{
    let m = models();
    for z in [
        Vector2::new(0.4, -0.2),
        Vector2::new(3.0, 5.0),
        Vector2::new(-10.0, 0.0),
    ] {
        let (nu, s, nis, ll) = hand_report(&filter, &m.measurement, &z);
        let report = filter.update(&m.measurement, &z).unwrap();
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1.0);
        assert!(
            (report.innovation - nu).amax() <= tol * nu.amax().max(1.0),
            "{name}: ν {} vs {nu}",
            report.innovation
        );
        assert!(
            (report.innovation_covariance - s).amax() <= tol * s.amax(),
            "{name}: S"
        );
        assert!(
            rel(report.nis, nis) <= tol,
            "{name}: NIS {} vs {nis}",
            report.nis
        );
        assert!(
            rel(report.log_likelihood, ll) <= tol,
            "{name}: ln p {} vs {ll}",
            report.log_likelihood
        );
        assert_eq!(report.outcome, UpdateOutcome::Applied);
    }
}

/// Tolerances: 1e-12 where the only difference is Cholesky solve vs explicit inverse and
/// log-diagonal vs determinant on a 2×2 S with cond ≲ 10² (round-off ~10⁻¹⁵). For the UKF with
/// α = 10⁻³, ẑ carries the ε/α² round-off of the sigma-point mean
/// (`common::UKF_SMALL_ALPHA_STATE_TOL`).
#[test]
fn update_report_matches_hand_computation() {
    let m = models();
    check_report("KalmanFilter", KalmanFilter::new(m.prior.clone()), 1e-12);
    check_report("Ekf", Ekf::new(m.prior.clone()), 1e-12);
    check_report(
        "SecondOrderEkf",
        SecondOrderEkf::new(m.prior.clone()),
        1e-12,
    );
    check_report(
        "cubature Ukf",
        GaussianFilter::with_propagator(m.prior.clone(), Unscented::cubature()),
        1e-12,
    );
    check_report("Ukf", Ukf::new(m.prior.clone()), UKF_SMALL_ALPHA_STATE_TOL);
    // RLS reports against the inflated covariance P/γ.
    let gamma = 0.8;
    let mut rls = FadingMemoryRls::new(m.prior.clone(), gamma).unwrap();
    let z = Vector2::new(1.0, -1.0);
    let inflated =
        KalmanFilter::new(Gaussian::new(*m.prior.mean(), m.prior.covariance() / gamma).unwrap());
    let (nu, s, nis, ll) = hand_report(&inflated, &m.measurement, &z);
    let report = rls.update(&m.measurement, &z).unwrap();
    assert!((report.innovation - nu).amax() <= 1e-12 * nu.amax());
    assert!((report.innovation_covariance - s).amax() <= 1e-12 * s.amax());
    assert!((report.nis - nis).abs() <= 1e-12 * nis);
    assert!((report.log_likelihood - ll).abs() <= 1e-12 * ll.abs().max(1.0));
}

/// A gated outlier is reported (with its NIS) and leaves the filter bit for bit unchanged; a
/// reading within the gate is applied. The gate is inclusive: NIS = threshold passes.
#[test]
fn gate_rejects_outliers_without_touching_the_filter() {
    let m = models();
    // χ²₂ 99% quantile.
    let threshold = 9.210_340_371_976_184;
    let mut kf = KalmanFilter::new(m.prior.clone())
        .with_gate(threshold)
        .unwrap();
    assert_eq!(kf.gate(), Some(Gate::Nis(threshold)));
    let outlier = Vector2::new(50.0, -50.0);
    let before = kf.clone();
    let (_, _, nis, _) = hand_report(&kf, &m.measurement, &outlier);
    let report = kf.update(&m.measurement, &outlier).unwrap();
    assert_eq!(report.outcome, UpdateOutcome::Gated);
    assert!(!report.applied());
    assert!(report.nis > threshold);
    assert!(
        (report.nis - nis).abs() <= 1e-12 * nis,
        "{} vs {nis}",
        report.nis
    );
    assert!(kf == before);
    assert_bitwise_eq(kf.state(), before.state(), "state after gating");
    assert_bitwise_eq(
        kf.covariance(),
        before.covariance(),
        "covariance after gating",
    );

    let inlier = m.measurement.observation * m.prior.mean() + Vector2::new(0.1, -0.1);
    let report = kf.update(&m.measurement, &inlier).unwrap();
    assert_eq!(report.outcome, UpdateOutcome::Applied);
    assert!(report.nis <= threshold);
    assert!(kf != before);

    // Boundary: a gate exactly at the reading's NIS lets it through, one ulp below rejects it.
    let probe = KalmanFilter::new(m.prior.clone());
    let exact = probe.clone().update(&m.measurement, &outlier).unwrap().nis;
    let mut at = probe.clone().with_gate(exact).unwrap();
    assert!(at.update(&m.measurement, &outlier).unwrap().applied());
    let mut below = probe
        .with_gate(f64::from_bits(exact.to_bits() - 1))
        .unwrap();
    assert!(!below.update(&m.measurement, &outlier).unwrap().applied());

    // The same for the UKF and RLS.
    let mut ukf = Ukf::new(m.prior.clone()).with_gate(threshold).unwrap();
    let before = ukf.clone();
    assert_eq!(
        ukf.update(&m.measurement, &outlier).unwrap().outcome,
        UpdateOutcome::Gated
    );
    assert!(ukf == before);
    let mut rls = FadingMemoryRls::new(m.prior.clone(), 0.9)
        .unwrap()
        .with_gate(threshold)
        .unwrap();
    let before = rls.clone();
    assert_eq!(
        rls.update(&m.measurement, &outlier).unwrap().outcome,
        UpdateOutcome::Gated
    );
    assert!(rls == before);
}

#[test]
fn invalid_gate_thresholds_are_rejected() {
    let m = models();
    for t in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let expected = |e: Error| {
            matches!(
                e,
                Error::InvalidParameter {
                    parameter: Parameter::GateThreshold,
                    ..
                }
            )
        };
        assert!(
            expected(KalmanFilter::new(m.prior.clone()).with_gate(t).unwrap_err()),
            "{t}"
        );
        assert!(
            expected(Ukf::new(m.prior.clone()).with_gate(t).unwrap_err()),
            "{t}"
        );
        assert!(
            expected(
                FadingMemoryRls::new(m.prior.clone(), 0.9)
                    .unwrap()
                    .with_gate(t)
                    .unwrap_err()
            ),
            "{t}"
        );
    }
}
