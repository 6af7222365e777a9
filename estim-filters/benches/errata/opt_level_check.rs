//! Broad check for optimisation-level divergences (see the module docs of
//! `estim_filters::update`, "Optimised builds"): every filter on the models of
//! `benches/autodiff.rs` (Ekf, SecondOrderEkf, GaussianSecondOrderEkf, Ukf, Iekf in each
//! covariance form; SrEkf, SrUkf), with analytic and with automatic derivatives, 64 steps;
//! prints a hash of the bits of every posterior state and covariance. Rust does not contract
//! or reassociate floating point, so the hashes must be identical at every opt-level. The
//! models and trajectory are the bench's (module `vehicle`); a bench target of the bench
//! package, so every lint compiles it.
//!
//! To run it: compare the output of the binary built by
//! `cargo rustc -p estim-filters-benches --profile bench --bench opt_level_check` with and without
//! `-- -C opt-level=1` (the filter code is generic, so it is all compiled in this crate).
//! At `05d49fa`: all 17 × 2 hashes identical between opt-level 1 and 3, and identical to
//! those of `df5c075` at opt-level 1. (At `df5c075` this file did not show the miscompile:
//! it depends on the calling function; `slp_joseph_repro.rs` does.)

// The lockstep of analytic and AD filters is the SLP repro's and the bench's, not used here.
#[allow(dead_code)]
#[path = "../vehicle.rs"]
mod vehicle;

use estim_core::autodiff::AutoDiff;
use estim_core::nalgebra::{U4, U6, Vector4, Vector6};
use estim_core::{MeasurementModel, ProcessModel};
use estim_filters::{
    CovarianceUpdate, Ekf, GaussianSecondOrderEkf, Iekf, Predict, SecondOrderEkf, SrEkf, SrUkf,
    Ukf, Update,
};
use vehicle::{Car, DT, RangeBearing, trajectory};

/// Runs `filter` along the trajectory with models `p`, `h`; returns the bits of every
/// posterior state and covariance, folded.
fn run<F, P, H>(mut filter: F, p: &P, h: &H, zs: &[Vector4<f64>]) -> (u64, Vector6<f64>)
where
    F: Predict<f64, U6, P> + Update<f64, U6, U4, H>,
    P: ProcessModel<f64, U6, Input = ()>,
    H: MeasurementModel<f64, U6, U4>,
{
    let mut hash: u64 = 0xcbf29ce484222325;
    for z in zs {
        filter.predict(p, &(), DT).unwrap();
        filter.update(h, z).unwrap();
        for v in filter.state().iter().chain(filter.covariance().iter()) {
            hash = (hash ^ v.to_bits()).wrapping_mul(0x100000001b3);
        }
    }
    (hash, *filter.state())
}

macro_rules! check {
    ($name:expr, $make:expr, $zs:expr) => {{
        let (car, sensor) = (AutoDiff::new(Car), AutoDiff::new(RangeBearing));
        let (a, xa) = run($make, &Car, &RangeBearing, $zs);
        let (b, xb) = run($make, &car, &sensor, $zs);
        println!(
            "{:<28} analytic {a:016x} autodiff {b:016x} gap {:.1e}",
            $name,
            (xa - xb).amax()
        );
    }};
}

fn main() {
    let (zs, prior) = trajectory();
    let zs = &zs;
    let forms = [
        ("Joseph", CovarianceUpdate::Joseph),
        ("Standard", CovarianceUpdate::Standard),
        ("Symmetrized", CovarianceUpdate::Symmetrized),
    ];
    for (name, form) in forms {
        check!(
            format!("Ekf/{name}"),
            Ekf::new(prior.clone()).with_covariance_update(form),
            zs
        );
        check!(
            format!("SecondOrderEkf/{name}"),
            SecondOrderEkf::new(prior.clone()).with_covariance_update(form),
            zs
        );
        check!(
            format!("GaussianSecondOrder/{name}"),
            GaussianSecondOrderEkf::new(prior.clone()).with_covariance_update(form),
            zs
        );
        check!(
            format!("Ukf/{name}"),
            Ukf::new(prior.clone()).with_covariance_update(form),
            zs
        );
        check!(
            format!("Iekf/{name}"),
            Iekf::new(prior.clone()).with_covariance_update(form),
            zs
        );
    }
    check!("SrEkf", SrEkf::new(prior.clone()), zs);
    check!("SrUkf", SrUkf::new(prior.clone()), zs);
}
