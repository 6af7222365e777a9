//! The covariance update forms over long runs: Joseph and Symmetrized keep P exactly
//! symmetric; Standard agrees with Joseph to round-off on a well-conditioned problem.

use crate::common;

use common::{LinearSystem, Trajectory, random_dyn_system, random_static_system, rng, simulate};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, LinearMeasurement, LinearProcess};
use estim_filters::{
    CovarianceUpdate, Estimator, FadingMemoryRls, KalmanFilter, Predict, Ukf, Update,
};

const STEPS: usize = 200;

/// P[i][j] and P[j][i] are the same bits.
#[track_caller]
fn assert_exactly_symmetric<N: Dim>(p: &OMatrix<f64, N, N>, what: &str)
where
    DefaultAllocator: Alloc<N>,
{
    let n = p.nrows();
    for i in 0..n {
        for j in 0..i {
            assert_eq!(
                p[(i, j)].to_bits(),
                p[(j, i)].to_bits(),
                "{what}: P[{i}][{j}] = {:e} vs P[{j}][{i}] = {:e}",
                p[(i, j)],
                p[(j, i)]
            );
        }
    }
    assert!(*p == p.transpose(), "{what}");
}

type Run<N> = Vec<OMatrix<f64, N, N>>;

/// Runs `filter`, checking exact symmetry after every predict and update when `symmetric` is
/// set, and returns the covariances and states after each update.
fn run<F, N, M, U>(
    mut filter: F,
    system: &LinearSystem<N, M, U>,
    traj: &Trajectory<N, M, U>,
    symmetric: bool,
    what: &str,
) -> (Run<N>, Vec<OVector<f64, N>>)
where
    N: Dim,
    M: Dim,
    U: Dim,
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
    F: Predict<f64, N, LinearProcess<f64, N, U>> + Update<f64, N, M, LinearMeasurement<f64, N, M>>,
{
    let (mut ps, mut xs) = (Vec::new(), Vec::new());
    for (k, (u, z)) in traj.inputs.iter().zip(&traj.measurements).enumerate() {
        filter.predict(&system.process, u, 1.0).unwrap();
        if symmetric {
            assert_exactly_symmetric(filter.covariance(), &format!("{what}, step {k} predict"));
        }
        filter.update(&system.measurement, z).unwrap();
        if symmetric {
            assert_exactly_symmetric(filter.covariance(), &format!("{what}, step {k} update"));
        }
        ps.push(filter.covariance().clone());
        xs.push(filter.state().clone());
    }
    (ps, xs)
}

/// Standard vs Joseph: algebraically equal with the optimal gain; on these well-conditioned
/// systems (R ≥ 0.05 I, Q ≥ 0.01 I) they differ by round-off ~ε cond(S) per step, contracted
/// by the stable filter, so 1e-10 relative over 200 steps has a wide margin (measured ~10⁻¹⁴).
const STANDARD_VS_JOSEPH_TOL: f64 = 1e-10;

fn check_forms<N, M, U>(system: &LinearSystem<N, M, U>, traj: &Trajectory<N, M, U>)
where
    N: Dim,
    M: Dim,
    U: Dim,
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    let prior = || system.prior.clone();
    let (joseph, xj) = run(KalmanFilter::new(prior()), system, traj, true, "KF Joseph");
    run(
        KalmanFilter::new(prior()).with_covariance_update(CovarianceUpdate::Symmetrized),
        system,
        traj,
        true,
        "KF Symmetrized",
    );
    let (standard, xs) = run(
        KalmanFilter::new(prior()).with_covariance_update(CovarianceUpdate::Standard),
        system,
        traj,
        false,
        "KF Standard",
    );
    for k in 0..STEPS {
        common::assert_estimates_close(
            &xs[k],
            &standard[k],
            &xj[k],
            &joseph[k],
            STANDARD_VS_JOSEPH_TOL,
            &format!("Standard vs Joseph, step {k}"),
        );
    }
    // The unscented filter's Joseph and Symmetrized updates are exactly symmetric too.
    run(Ukf::new(prior()), system, traj, true, "Ukf Joseph");
    run(
        Ukf::new(prior()).with_covariance_update(CovarianceUpdate::Symmetrized),
        system,
        traj,
        true,
        "Ukf Symmetrized",
    );
}

#[test]
fn joseph_and_symmetrized_stay_exactly_symmetric_static() {
    for seed in 0..10 {
        let mut r = rng(900 + seed);
        let system = random_static_system(&mut r);
        let traj = simulate(&mut r, &system, STEPS);
        check_forms(&system, &traj);
    }
}

#[test]
fn joseph_and_symmetrized_stay_exactly_symmetric_dynamic() {
    for (seed, n, m) in [(1, 6, 3), (2, 8, 2), (3, 5, 5)] {
        let mut r = rng(950 + seed);
        let system = random_dyn_system(&mut r, n, m, 1);
        let traj = simulate(&mut r, &system, STEPS);
        check_forms(&system, &traj);
    }
}

/// Standard vs Joseph for the fading-memory RLS with γ = 0.95, after k + 1 updates.
///
/// Unlike the Kalman filters above, nothing contracts the round-off here: this RLS observes
/// 2 of 4 states and divides P by γ before every update, so the unobserved directions' P
/// grows like γ⁻ᵏ, and so does the effect on the state of the ε-sized differences the two
/// forms leave in P. Measured (seed 77): 2.5·10⁻¹⁴ at k = 20, 1.1·10⁻¹² at k = 40,
/// 1.2·10⁻¹⁰ at k = 194 — between 0.3 % and 15 % of 10⁻¹² γ⁻ᵏ (the largest ratio at k = 40),
/// before and after the update rework of issue #6. A fixed 10⁻¹⁰ passed with a margin of 1.08
/// before that rework and failed after it (1.18·10⁻¹⁰ at k = 194): the bound must grow.
fn rls_standard_vs_joseph_tol(k: usize) -> f64 {
    1e-12 * 0.95_f64.powi(-(k as i32))
}

#[test]
fn rls_covariance_forms() {
    let mut r = rng(77);
    let system = random_static_system(&mut r);
    let traj = simulate(&mut r, &system, STEPS);
    let mut joseph = FadingMemoryRls::new(system.prior.clone(), 0.95).unwrap();
    let mut symmetrized = FadingMemoryRls::new(system.prior.clone(), 0.95)
        .unwrap()
        .with_covariance_update(CovarianceUpdate::Symmetrized);
    let mut standard = FadingMemoryRls::new(system.prior.clone(), 0.95)
        .unwrap()
        .with_covariance_update(CovarianceUpdate::Standard);
    for (k, z) in traj.measurements.iter().enumerate() {
        joseph.update(&system.measurement, z).unwrap();
        symmetrized.update(&system.measurement, z).unwrap();
        standard.update(&system.measurement, z).unwrap();
        assert_exactly_symmetric(joseph.covariance(), &format!("RLS Joseph, step {k}"));
        assert_exactly_symmetric(
            symmetrized.covariance(),
            &format!("RLS Symmetrized, step {k}"),
        );
        common::assert_estimates_close(
            standard.state(),
            standard.covariance(),
            joseph.state(),
            joseph.covariance(),
            rls_standard_vs_joseph_tol(k),
            &format!("RLS Standard vs Joseph, step {k}"),
        );
    }
}
