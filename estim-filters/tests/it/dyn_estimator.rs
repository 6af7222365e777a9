//! `Estimator` is object safe: a `Box<dyn Estimator<f64, U4>>` holds any filter, and a user
//! trait combining `Estimator`, `Predict` and `Update` for fixed model types is object safe
//! too, so the filter can be chosen at run time.

use crate::common;

use common::{StaticSystem, UKF_SMALL_ALPHA_STATE_TOL, random_static_system, rng, simulate};
use estim_core::nalgebra::{Matrix4, U1, U2, U4, Vector4};
use estim_core::propagate::Unscented;
use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::{
    Ekf, Estimator, FadingMemoryRls, GaussianFilter, GaussianSecondOrderEkf, KalmanFilter, Predict,
    SecondOrderEkf, Ukf, Update,
};

#[test]
fn boxed_estimators_hold_every_filter() {
    let prior = Gaussian::new(
        Vector4::new(1.0, 2.0, 3.0, 4.0),
        Matrix4::from_diagonal(&Vector4::new(1.0, 2.0, 3.0, 4.0)),
    )
    .unwrap();
    let mut filters: Vec<Box<dyn Estimator<f64, U4>>> = vec![
        Box::new(KalmanFilter::new(prior.clone())),
        Box::new(Ekf::new(prior.clone())),
        Box::new(SecondOrderEkf::new(prior.clone())),
        Box::new(GaussianSecondOrderEkf::new(prior.clone())),
        Box::new(Ukf::new(prior.clone())),
        Box::new(GaussianFilter::with_propagator(
            prior.clone(),
            Unscented::<f64>::cubature(),
        )),
        Box::new(FadingMemoryRls::new(prior.clone(), 0.9).unwrap()),
    ];
    let other = Gaussian::new(Vector4::zeros(), Matrix4::identity() * 0.5).unwrap();
    for f in &mut filters {
        assert_eq!(f.state(), prior.mean());
        assert_eq!(f.covariance(), prior.covariance());
        assert_eq!(f.estimate(), prior);
        f.reset(other.clone());
        assert_eq!(f.estimate(), other);
    }
}

type Process = LinearProcess<f64, U4, U1>;
type Measurement = LinearMeasurement<f64, U4, U2>;

/// What an application that runs one linear system needs of its filter.
trait LinearFilter:
    Estimator<f64, U4> + Predict<f64, U4, Process> + Update<f64, U4, U2, Measurement>
{
}

impl<F> LinearFilter for F where
    F: Estimator<f64, U4> + Predict<f64, U4, Process> + Update<f64, U4, U2, Measurement>
{
}

fn choose(name: &str, prior: Gaussian<f64, U4>) -> Box<dyn LinearFilter> {
    match name {
        "kf" => Box::new(KalmanFilter::new(prior)),
        "ekf" => Box::new(Ekf::new(prior)),
        "soekf" => Box::new(SecondOrderEkf::new(prior)),
        "ukf" => Box::new(Ukf::new(prior)),
        "ckf" => Box::new(GaussianFilter::with_propagator(
            prior,
            Unscented::cubature(),
        )),
        _ => unreachable!(),
    }
}

/// Filters picked at run time through `Box<dyn LinearFilter>` run and agree with the KF on a
/// linear system (tolerances as in `equivalence.rs`: 1e-9, and the ε/α² bound for the
/// state of the α = 10⁻³ UKF).
#[test]
fn filters_chosen_at_run_time_run_through_trait_objects() {
    let mut r = rng(5);
    let system: StaticSystem = random_static_system(&mut r);
    let traj = simulate(&mut r, &system, 50);
    let mut filters: Vec<(&str, Box<dyn LinearFilter>)> = ["kf", "ekf", "soekf", "ukf", "ckf"]
        .into_iter()
        .map(|name| (name, choose(name, system.prior.clone())))
        .collect();
    for (u, z) in traj.inputs.iter().zip(&traj.measurements) {
        for (_, f) in &mut filters {
            f.predict(&system.process, u, 1.0).unwrap();
            assert!(f.update(&system.measurement, z).unwrap().applied());
        }
        let (x0, p0) = (*filters[0].1.state(), *filters[0].1.covariance());
        for (name, f) in &filters[1..] {
            let tol_x = if *name == "ukf" {
                UKF_SMALL_ALPHA_STATE_TOL
            } else {
                1e-9
            };
            let (dx, dp) = common::estimate_rel_diff(f.state(), f.covariance(), &x0, &p0);
            assert!(dx <= tol_x && dp <= 1e-9, "{name}: {dx:e}, {dp:e}");
        }
    }
}
