//! A wrapped residual reaches every route that subtracts measurements: the adapters that wrap a
//! measurement model (offset, adaptive noise, lifted to a mode state, robust inflation), the
//! iterated EKF's linearisation and its cost, the square-root, unscented and particle updates
//! and the correlated prediction. A heading read as −π + δ and as π + δ is the same reading;
//! each route must give the same result for both (a route that fell back to a − b would see
//! an innovation 2π away). And a residual written with the wrong length (runtime sizes) is
//! never a panic: a typed error with the filter unchanged, or, in the iterated EKF's later
//! steps, a rejected step.

use std::f64::consts::PI;

use estim_core::adapter::Offset;
use estim_core::nalgebra::{
    DMatrix, DVector, Dyn, Matrix1, Matrix2, Matrix2x1, U2, Vector1, Vector2,
};
use estim_core::{
    Error, Gaussian, LinearProcess, MeasurementJacobian, MeasurementModel, ProcessModel, Quantity,
    Stage, Unscented, wrap_angle,
};
use estim_filters::imm::{LiftedMeasurement, StateMap};
use estim_filters::noise_id::MeasurementNoiseMatching;
use estim_filters::particle::ParticleFilter;
use estim_filters::robust::{RobustWeight, robust_update};
use estim_filters::{
    Ekf, Estimator, Iekf, Predict, PredictCorrelated, SrEkf, Ukf, Update, UpdateReport,
};

/// z = θ of the state (θ, ω) wrapped into (−π, π], σ = 0.05 rad; the residual wrapped too.
struct Heading;

impl MeasurementModel<f64, U2, estim_core::nalgebra::U1> for Heading {
    fn measure(&self, x: &Vector2<f64>) -> Vector1<f64> {
        Vector1::new(wrap_angle(x[0]))
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> {
        Matrix1::new(0.05 * 0.05)
    }
    fn residual_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
        *out = Vector1::new(wrap_angle(a[0] - b[0]));
    }
}

impl MeasurementJacobian<f64, U2, estim_core::nalgebra::U1> for Heading {
    fn measurement_jacobian(&self, _: &Vector2<f64>) -> estim_core::nalgebra::Matrix1x2<f64> {
        estim_core::nalgebra::Matrix1x2::new(1.0, 0.0)
    }
}

/// θ just below π, turning slowly.
fn prior() -> Gaussian<f64, U2> {
    Gaussian::new(
        Vector2::new(PI - 0.01, 0.02),
        Matrix2::new(0.1 * 0.1, 0.0, 0.0, 0.05 * 0.05),
    )
    .unwrap()
}

/// The heading `delta` past π, read on either side of the cut.
fn readings(delta: f64) -> [Vector1<f64>; 2] {
    [Vector1::new(-PI + delta), Vector1::new(PI + delta)]
}

/// The two runs agree (to the rounding of π + δ − 2π) and the innovation is the wrapped one.
fn assert_same<F: Estimator<f64, U2>>(
    runs: [(F, UpdateReport<f64, estim_core::nalgebra::U1>); 2],
    innovation: f64,
    what: &str,
) {
    let [(a, ra), (b, rb)] = runs;
    let tol = 1e-12;
    assert!((a.state() - b.state()).amax() < tol, "{what}: state");
    assert!(
        (a.covariance() - b.covariance()).amax() < tol,
        "{what}: covariance"
    );
    assert!(
        (ra.innovation[0] - rb.innovation[0]).abs() < tol,
        "{what}: innovations"
    );
    assert!(
        (ra.innovation[0] - innovation).abs() < tol,
        "{what}: {} not wrapped",
        ra.innovation[0]
    );
}

/// One update of a fresh `filter` per reading, with `model`.
fn both<F, H>(
    filter: impl Fn() -> F,
    model: &H,
    delta: f64,
) -> [(F, UpdateReport<f64, estim_core::nalgebra::U1>); 2]
where
    F: Estimator<f64, U2> + Update<f64, U2, estim_core::nalgebra::U1, H>,
{
    readings(delta).map(|z| {
        let mut f = filter();
        let report = f.update(model, &z).unwrap();
        (f, report)
    })
}

#[test]
fn every_adapter_and_update_route_wraps_the_residual() {
    // ν = (π + 0.01) − (π − 0.01) = 0.02, read as −π + 0.01 it is −2π + 0.02 before wrapping.
    let nu = 0.02;
    assert_same(both(|| Ekf::new(prior()), &Heading, 0.01), nu, "Ekf");
    // Sigma points spread by α = 1 (√3 σ = 0.17 rad): some cross π, so h wraps there and the
    // deviations from the mean measurement go through the residual too.
    let wide = || Ukf::with_propagator(prior(), Unscented::new(1.0, 2.0, 0.0).unwrap());
    assert_same(both(wide, &Heading, 0.01), nu, "Ukf");
    assert_same(both(|| SrEkf::new(prior()), &Heading, 0.01), nu, "SrEkf");
    let offset = Offset {
        model: Heading,
        offset: Vector1::new(0.0),
    };
    assert_same(both(|| Ekf::new(prior()), &offset, 0.01), nu, "Offset");
    let adaptive = MeasurementNoiseMatching::new(Matrix1::new(0.05 * 0.05), 10.0, 1e-8).unwrap();
    assert_same(
        both(|| Ekf::new(prior()), &adaptive.model(&Heading), 0.01),
        nu,
        "WithNoise",
    );
    let map = StateMap::<f64, U2, U2>::identity(U2);
    let lifted = LiftedMeasurement::new(&Heading, &map);
    assert_same(
        both(|| Ekf::new(prior()), &lifted, 0.01),
        nu,
        "LiftedMeasurement",
    );
    // The iterated EKF: step 0 is the EKF's (its report), later steps go through the
    // linearisation's residual and the MAP cost's.
    let iekf = || Iekf::new(prior()).with_iterations(6, 1e-14).unwrap();
    assert_same(both(iekf, &Heading, 0.01), nu, "Iekf");
}

#[test]
fn robust_inflation_wraps_the_residual() {
    // ν = 0.51, 5σ of S: Huber(1) inflates R, so the update runs with the inflated model.
    let runs = readings(0.5).map(|z| {
        let mut f = Ekf::new(prior());
        let r = robust_update(&mut f, &Heading, &z, RobustWeight::Huber(1.0)).unwrap();
        assert!(r.weight < 0.5, "{}", r.weight);
        (f, r.report)
    });
    assert_same(runs, 0.51, "robust_update");
}

#[test]
fn particle_weights_wrap_the_residual() {
    let [a, b] = readings(0.01).map(|z| {
        let mut f = ParticleFilter::new(prior(), 500, 3).unwrap();
        let before = f.particles().clone();
        let report = f.update(&Heading, &z).unwrap();
        // The innovation is Σ Wᵢ (z ⊖ h(xᵢ)) over the prior cloud (uniform weights).
        let want = before
            .row(0)
            .iter()
            .map(|&t| wrap_angle(z[0] - wrap_angle(t)))
            .sum::<f64>()
            / 500.0;
        assert!((report.innovation[0] - want).abs() < 1e-12, "{report:?}");
        (f, report)
    });
    // Same particles, log-weights equal to the rounding of the wrapped residuals.
    let (la, lb) = (a.0.log_weights(), b.0.log_weights());
    assert!(la.iter().zip(lb).all(|(x, y)| (x - y).abs() < 1e-9));
    assert!((a.1.innovation[0] - b.1.innovation[0]).abs() < 1e-12);
}

#[test]
fn correlated_prediction_wraps_the_residual() {
    let process = LinearProcess::without_input(
        Matrix2::new(1.0, 0.1, 0.0, 1.0),
        Matrix2::new(1e-4, 0.0, 0.0, 1e-3),
    );
    let cross = Matrix2x1::new(1e-5, 0.0);
    let [a, b] = readings(0.01).map(|z| {
        let mut f = Ukf::new(prior());
        f.predict_correlated(&process, &(), 0.1, &Heading, &z, &cross)
            .unwrap();
        f
    });
    assert!((a.state() - b.state()).amax() < 1e-12);
    assert!((a.covariance() - b.covariance()).amax() < 1e-12);
    // The correction D (z ⊖ h(x̂)) with D = S R⁻¹ = (0.004, 0) and the wrapped ν = 0.02.
    let mut plain = Ukf::new(prior());
    plain.predict(&process, &(), 0.1).unwrap();
    let shift = a.state() - plain.state();
    assert!((shift[0] - 0.004 * 0.02).abs() < 1e-9, "{shift}");
    assert!(shift[1].abs() < 1e-12, "{shift}");
}

/// z = x₀ on a runtime-sized state, R = 0.01, whose residual z ⊖ ẑ comes out `len` entries
/// long (instead of one) when ẑ₀ exceeds `wrong_above`.
struct Fickle {
    wrong_above: f64,
    len: usize,
}

impl MeasurementModel<f64, Dyn, Dyn> for Fickle {
    fn measure(&self, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_element(1, x[0])
    }
    fn measurement_noise(&self, _: &DVector<f64>) -> DMatrix<f64> {
        DMatrix::from_element(1, 1, 0.01)
    }
    fn residual_into(&self, a: &DVector<f64>, b: &DVector<f64>, out: &mut DVector<f64>) {
        *out = if b[0] > self.wrong_above {
            DVector::zeros(self.len)
        } else {
            a - b
        };
    }
}

impl MeasurementJacobian<f64, Dyn, Dyn> for Fickle {
    fn measurement_jacobian(&self, x: &DVector<f64>) -> DMatrix<f64> {
        let mut h = DMatrix::zeros(1, x.nrows());
        h[(0, 0)] = 1.0;
        h
    }
}

/// x⁺ = x on a runtime-sized state, Q = 0.01 I, whose value comes out three entries long when
/// x₀ > 0.
struct FickleProcess;

impl ProcessModel<f64, Dyn> for FickleProcess {
    type Input = ();
    fn transition(&self, x: &DVector<f64>, _: &(), _: f64) -> DVector<f64> {
        if x[0] > 0.0 {
            DVector::zeros(3)
        } else {
            x.clone()
        }
    }
    fn process_noise(&self, x: &DVector<f64>, _: &(), _: f64) -> DMatrix<f64> {
        DMatrix::identity(x.nrows(), x.nrows()) * 0.01
    }
}

fn dyn_prior() -> Gaussian<f64, Dyn> {
    Gaussian::new(DVector::zeros(2), DMatrix::identity(2, 2)).unwrap()
}

/// Runs `step` on `filter`: it must fail and leave the estimate as it was.
fn refused<F: Estimator<f64, Dyn>, R: std::fmt::Debug>(
    filter: &mut F,
    step: impl FnOnce(&mut F) -> Result<R, Error>,
    what: &str,
) -> Error {
    let (x, p) = (filter.state().clone(), filter.covariance().clone());
    let result = step(filter);
    assert_eq!(filter.state(), &x, "{what}: state changed");
    assert_eq!(filter.covariance(), &p, "{what}: covariance changed");
    result.expect_err(what)
}

#[test]
fn a_residual_of_the_wrong_length_is_never_a_panic() {
    let z = DVector::from_element(1, 1.0);
    for len in [0, 2] {
        let always = Fickle {
            wrong_above: f64::NEG_INFINITY,
            len,
        };
        let mismatch = |e: &Error| {
            matches!(
                e,
                Error::DimensionMismatch {
                    stage: Stage::Update,
                    quantity: Quantity::Innovation,
                    expected_rows: 1,
                    expected_cols: 1,
                    found_cols: 1,
                    found_rows,
                } if *found_rows == len
            )
        };
        let e = refused(&mut Ekf::new(dyn_prior()), |f| f.update(&always, &z), "Ekf");
        assert!(mismatch(&e), "{len}: {e:?}");
        let sr = &mut SrEkf::new(dyn_prior());
        let e = refused(sr, |f| f.update(&always, &z), "SrEkf");
        assert!(mismatch(&e), "{len}: {e:?}");
        let mut pf = ParticleFilter::new(dyn_prior(), 64, 1).unwrap();
        let e = refused(&mut pf, |f| f.update(&always, &z), "ParticleFilter");
        assert!(mismatch(&e), "{len}: {e:?}");

        // Right at the prior, wrong beyond ẑ₀ = 0.5: z = 1 pulls the Gauss–Newton point to
        // 0.99, where the MAP cost meets the misshapen residual; that step is rejected (its
        // cost is NaN), halved to 0.495 and accepted, and no later step passes 0.5.
        let later = Fickle {
            wrong_above: 0.5,
            len,
        };
        let mut iekf = Iekf::new(dyn_prior()).with_iterations(8, 1e-14).unwrap();
        let report = iekf
            .update(&later, &z)
            .expect("a rejected step, not an error");
        assert!(iekf.state()[0] <= 0.5, "{len}: {}", iekf.state()[0]);
        assert!(iekf.state()[0] > 0.4, "{len}: {}", iekf.state()[0]);
        assert!(!report.iterations.unwrap().converged, "{len}");

        // The correlated prediction meets it at the sigma points only (ẑ₀ = 0 at x̂, ±ε
        // there): NaN means, reported by the propagation.
        let later = Fickle {
            wrong_above: 0.0,
            len,
        };
        let process =
            LinearProcess::without_input(DMatrix::identity(2, 2), DMatrix::identity(2, 2) * 0.01);
        let cross = DMatrix::zeros(2, 1);
        let step =
            |f: &mut Ukf<f64, Dyn>| f.predict_correlated(&process, &(), 1.0, &later, &z, &cross);
        let e = refused(&mut Ukf::new(dyn_prior()), step, "predict_correlated");
        assert!(
            matches!(
                e,
                Error::NonFinite {
                    stage: Stage::Propagation,
                    quantity: Quantity::Mean
                }
            ),
            "{len}: {e:?}"
        );
    }
    // A process value of the wrong length at the sigma points: the propagator's length check.
    let sensor = Fickle {
        wrong_above: f64::INFINITY,
        len: 1,
    };
    let cross = DMatrix::zeros(2, 1);
    let step =
        |f: &mut Ukf<f64, Dyn>| f.predict_correlated(&FickleProcess, &(), 1.0, &sensor, &z, &cross);
    let e = refused(&mut Ukf::new(dyn_prior()), step, "predict_correlated, f");
    assert!(
        matches!(
            e,
            Error::DimensionMismatch {
                quantity: Quantity::FunctionValue,
                ..
            }
        ),
        "{e:?}"
    );
}
