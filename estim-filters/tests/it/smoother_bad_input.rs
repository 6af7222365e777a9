//! Bad input to the sequence functions: a typed error naming the time of the failing step,
//! and the filter the caller passed exactly as it was.

use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
use estim_core::{Error, Gaussian, LinearMeasurement, LinearProcess, Parameter, Quantity, Stage};
use estim_filters::smoother::{
    SmootherError, filter_sequence, smooth_sequence, smooth_sequence_with_cross_covariances,
};
use estim_filters::{KalmanFilter, Update};

type Process = LinearProcess<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1>;
type Sensor = LinearMeasurement<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1>;

fn system(q: f64) -> (Process, Sensor, KalmanFilter<f64, estim_core::nalgebra::U2>) {
    let process = LinearProcess {
        transition: Matrix2::new(1.0, 0.5, 0.0, 1.0),
        input: Matrix2x1::new(0.125, 0.5),
        noise: Matrix2::identity() * q,
    };
    let sensor = LinearMeasurement {
        observation: Matrix1x2::new(1.0, 0.0),
        noise: Matrix1::new(0.3),
    };
    // A filter that has already run, so "as it was" is not the prior.
    let mut kf =
        KalmanFilter::new(Gaussian::new(Vector2::new(0.2, 0.1), Matrix2::identity()).unwrap());
    kf.update(&sensor, &Vector1::new(0.4)).unwrap();
    (process, sensor, kf)
}

/// Runs the three sequence functions on the same data and checks that each fails with
/// `expected` and leaves the filter unchanged.
fn assert_all_fail(
    process: &Process,
    sensor: &Sensor,
    kf: &KalmanFilter<f64, estim_core::nalgebra::U2>,
    inputs: &[Vector1<f64>],
    dt: f64,
    zs: &[Option<Vector1<f64>>],
    expected: SmootherError,
) {
    let mut f = kf.clone();
    let e = filter_sequence(&mut f, process, inputs, dt, sensor, zs).unwrap_err();
    assert_eq!((e, &f), (expected, kf), "filter_sequence");
    let e = smooth_sequence(&mut f, process, inputs, dt, sensor, zs).unwrap_err();
    assert_eq!((e, &f), (expected, kf), "smooth_sequence");
    let e = smooth_sequence_with_cross_covariances(&mut f, process, inputs, dt, sensor, zs)
        .unwrap_err();
    assert_eq!(
        (e, &f),
        (expected, kf),
        "smooth_sequence_with_cross_covariances"
    );
}

fn data(steps: usize) -> (Vec<Vector1<f64>>, Vec<Option<Vector1<f64>>>) {
    let inputs = (0..steps).map(|k| Vector1::new(0.1 * k as f64)).collect();
    let zs = (0..=steps)
        .map(|k| (k != 2).then(|| Vector1::new(0.3 * k as f64)))
        .collect();
    (inputs, zs)
}

/// K inputs need K + 1 measurements: one too many or too few is refused before anything runs.
#[test]
fn lengths_that_disagree_are_refused() {
    let (process, sensor, kf) = system(0.01);
    let (inputs, zs) = data(5);
    for (inputs, zs, step, expected, found) in [
        (&inputs[..], &zs[..5], 5, 6, 5),
        (&inputs[..4], &zs[..], 5, 5, 6),
        (&inputs[..], &zs[..0], 0, 6, 0),
    ] {
        let expected = SmootherError {
            step,
            error: Error::DimensionMismatch {
                stage: Stage::Smoothing,
                quantity: Quantity::Measurement,
                expected_rows: expected,
                expected_cols: 1,
                found_rows: found,
                found_cols: 1,
            },
            state: None,
        };
        assert_all_fail(&process, &sensor, &kf, inputs, 0.5, zs, expected);
    }
}

/// A Δt that is NaN, infinite or negative is refused at time 0, before anything runs.
#[test]
fn bad_time_steps_are_refused() {
    let (process, sensor, kf) = system(0.01);
    let (inputs, zs) = data(5);
    let non_finite = Error::NonFinite {
        stage: Stage::Prediction,
        quantity: Quantity::TimeStep,
    };
    for (dt, error) in [
        (f64::NAN, non_finite),
        (f64::INFINITY, non_finite),
        (
            -0.5,
            Error::InvalidParameter {
                parameter: Parameter::TimeStep,
                value: -0.5,
            },
        ),
    ] {
        let expected = SmootherError {
            step: 0,
            error,
            state: None,
        };
        assert_all_fail(&process, &sensor, &kf, &inputs, dt, &zs, expected);
    }
}

/// A non-finite measurement at time 3 fails that update; a non-finite input at time 1 fails
/// the prediction from time 1. Both name their time and restore the filter.
#[test]
fn non_finite_data_fails_at_its_step() {
    let (process, sensor, kf) = system(0.01);
    let (inputs, mut zs) = data(5);
    zs[3] = Some(Vector1::new(f64::NAN));
    let mut f = kf.clone();
    let e = filter_sequence(&mut f, &process, &inputs, 0.5, &sensor, &zs).unwrap_err();
    assert_eq!(e.step, 3);
    assert!(matches!(e.error, Error::NonFinite { .. }), "{e}");
    assert_all_fail(&process, &sensor, &kf, &inputs, 0.5, &zs, e);

    let (mut inputs, zs) = data(5);
    inputs[1] = Vector1::new(f64::INFINITY);
    let e = filter_sequence(&mut f, &process, &inputs, 0.5, &sensor, &zs).unwrap_err();
    assert_eq!(e.step, 1);
    assert!(matches!(e.error, Error::NonFinite { .. }), "{e}");
    assert_all_fail(&process, &sensor, &kf, &inputs, 0.5, &zs, e);
}

/// F = [[1, 0], [1, 0]] and Q = 0 copy the position into the velocity: every predicted
/// covariance is singular along state 1 with both variances positive (not a fixed state, which
/// the smoother handles): filtering runs (the updates see S > 0), the backward pass fails
/// (here at the last recorded step, K − 1, the first it computes) naming state 1, and the filter is
/// restored; `filter_sequence` on the same data succeeds. An indefinite Q is refused earlier,
/// by the prediction.
#[test]
fn an_indefinite_predicted_covariance_fails_the_backward_pass() {
    let (mut process, sensor, kf) = system(0.0);
    process.transition = Matrix2::new(1.0, 0.0, 1.0, 0.0);
    let (inputs, zs) = data(5);
    let expected = SmootherError {
        step: 4,
        error: Error::NotPositiveDefinite {
            stage: Stage::Smoothing,
            quantity: Quantity::Covariance,
        },
        state: Some(1),
    };
    let mut f = kf.clone();
    assert!(filter_sequence(&mut f, &process, &inputs, 0.5, &sensor, &zs).is_ok());
    for result in [
        smooth_sequence(&mut f.clone(), &process, &inputs, 0.5, &sensor, &zs).map(|_| ()),
        smooth_sequence_with_cross_covariances(
            &mut f.clone(),
            &process,
            &inputs,
            0.5,
            &sensor,
            &zs,
        )
        .map(|_| ()),
    ] {
        assert_eq!(result.unwrap_err(), expected);
    }
    // From this other start the pivot of P⁻ along state 1 (exactly 0 in exact arithmetic) is
    // a few ulps of either sign, so which step fails first is round-off; the state named and
    // the cause are not, and the filter is restored.
    let mut g = kf.clone();
    let error = smooth_sequence(&mut g, &process, &inputs, 0.5, &sensor, &zs).unwrap_err();
    assert_eq!((error.error, error.state), (expected.error, expected.state));
    assert_eq!(g, kf);

    // An indefinite Q (eigenvalues 0.11 and −0.09, with a positive diagonal) is refused by
    // the first prediction's semi-definiteness check of Q (`Predict::predict`), before the
    // backward pass could fail at step 4.
    process.noise = Matrix2::new(0.01, 0.1, 0.1, 0.01);
    let forward_error = SmootherError {
        step: 0,
        error: Error::NotPositiveSemiDefinite {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
        },
        state: None,
    };
    let forward = filter_sequence(&mut g, &process, &inputs, 0.5, &sensor, &zs);
    assert_eq!(forward.unwrap_err(), forward_error);
    let mut g = kf.clone();
    let error = smooth_sequence(&mut g, &process, &inputs, 0.5, &sensor, &zs).unwrap_err();
    assert_eq!(error, forward_error);
    assert_eq!(g, kf);
}

/// Issue 41, defect 4: `Rts::with_lag` reserved the whole lag up front, so
/// `with_lag(usize::MAX)` panicked ("capacity overflow") and `with_lag(10⁹)` aborted
/// allocating 264 GB. The record now grows with the pass: a lag longer than the pass is the
/// whole-pass smoother, to the bit, and a short lag still keeps only `lag` records.
#[test]
fn a_huge_lag_is_the_whole_pass_smoother() {
    use estim_filters::smoother::Rts;
    let (process, sensor, kf) = system(0.01);
    let (inputs, zs) = data(20);
    let mut whole = Rts::new();
    let mut huge = Rts::with_lag(usize::MAX);
    let mut short = Rts::with_lag(3);
    let (mut a, mut b, mut c) = (kf.clone(), kf.clone(), kf);
    for (u, z) in inputs.iter().zip(&zs) {
        whole.predict(&mut a, &process, u, 0.5).unwrap();
        huge.predict(&mut b, &process, u, 0.5).unwrap();
        short.predict(&mut c, &process, u, 0.5).unwrap();
        if let Some(z) = z {
            for f in [&mut a, &mut b, &mut c] {
                f.update(&sensor, z).unwrap();
            }
        }
    }
    assert_eq!(huge.len(), inputs.len());
    assert_eq!(short.len(), 3);
    let (expected, found) = (whole.smooth(&a).unwrap(), huge.smooth(&b).unwrap());
    assert_eq!(expected, found);
    // The fixed-lag smoother's estimates are the last four of the whole pass's, to the bit:
    // the backward recursion over the last three steps runs on the same records.
    let lagged = short.smooth(&c).unwrap();
    assert_eq!(lagged[..], expected[expected.len() - 4..]);
}

/// A runtime-sized filter reset to another size after the predictions were recorded: the
/// backward pass returns a typed error at the first record it meets (it panicked on a shape
/// assertion in the copy of the predicted covariance).
#[test]
fn a_filter_of_another_size_is_refused() {
    use estim_core::nalgebra::{DMatrix, DVector, Dyn};
    use estim_filters::{Estimator, smoother::Rts};
    let gaussian = |n: usize| Gaussian::new(DVector::zeros(n), DMatrix::identity(n, n)).unwrap();
    let mut kf = KalmanFilter::<f64, Dyn>::new(gaussian(2));
    let process = LinearProcess {
        transition: DMatrix::<f64>::identity(2, 2),
        input: DMatrix::zeros(2, 1),
        noise: DMatrix::identity(2, 2) * 0.1,
    };
    let mut rts = Rts::new();
    for _ in 0..3 {
        rts.predict(&mut kf, &process, &DVector::zeros(1), 1.0)
            .unwrap();
    }
    assert_eq!(rts.smooth(&kf).unwrap().len(), 4);
    kf.reset(gaussian(3));
    let error = rts.smooth(&kf).unwrap_err();
    assert_eq!(error.step, 2);
    assert_eq!(
        error.error,
        Error::DimensionMismatch {
            stage: Stage::Smoothing,
            quantity: Quantity::Mean,
            expected_rows: 3,
            expected_cols: 1,
            found_rows: 2,
            found_cols: 1,
        }
    );
    assert!(rts.smooth_with_cross_covariances(&kf).is_err());
    assert!(rts.smooth_with_times(&kf).is_err());
}
