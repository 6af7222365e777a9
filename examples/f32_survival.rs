//! Which covariance forms survive in `f32`: steps to failure of every filter (KF, EKF, UKF) ×
//! covariance form (Joseph, standard, symmetrised, square root) × scalar (f32, f64) on two
//! hard problems.
//!
//! (a) Lu's 3-state accelerometer-bias calibration (estim_models::lu): error state
//!     (δp, δv, b) at 200 Hz, Φ = [[1, Δt, −Δt²/2], [0, 1, −Δt], [0, 0, 1]], Q = Γ W Γᵀ
//!     (rank one: no process noise on the bias), GPS position and velocity every 40 steps,
//!     R = diag(1, 0.0016), P₀ = diag(100, 1, 0.01); run for 10⁶ steps (25 000 fixes).
//! (b) R ≪ P: the same process, P₀ = 10⁶ I, R = 10⁻¹² I (a GPS fix every step).
//!
//! A configuration runs S Monte Carlo seeds in lockstep. It *fails* at the first step where
//! one of its runs returns an error or, for (a), has a P that is not positive definite
//! (checked in f64 at each fix; for (b), a P with a negative or non-finite variance), or, for
//! (a), at the end of the first window of 250 fixes whose ensemble NEES
//! (eᵀP⁻¹e averaged over the runs and the window, e the true error) leaves the two-sided
//! 99.9 % band of χ²(3S)/S. For (b) the NEES is printed but not judged: with x ~ N(0, 10⁶ I)
//! an f32 state of |x| ≈ 10³ is resolved to ε|x| ≈ 6·10⁻⁵, far coarser than the σ = 10⁻⁶ its
//! measurements give, so no f32 filter can be consistent there; the question is whether it
//! keeps running with a valid P. The truth is simulated in f64; the filters run in T on the
//! same measurements.
//!
//! `cargo run --release --example f32_survival` (add `-- --quick` for 10⁵ steps, `-- --seeds K`
//! for K Monte Carlo seeds, default 4).

use estim::filters::square_root::SquareRootFilter;
use estim::nalgebra::{Matrix2, Matrix2x3, Matrix3, U1, U2, U3, Vector1, Vector2, Vector3};
use estim::prelude::*;
use estim::rand::SeedableRng;
use estim::rand::rngs::StdRng;
use estim_core::Real;
use rand_distr::{Distribution, StandardNormal};

const DT: f64 = 0.005;
const FIX_EVERY: usize = 40;
/// Fixes per NEES window.
const WINDOW: usize = 250;

#[derive(Clone, Copy, PartialEq)]
enum Problem {
    Lu,
    Stiff,
}

struct Setup {
    problem: Problem,
    steps: usize,
    fix_every: usize,
    p0: Matrix3<f64>,
    r: Matrix2<f64>,
}

fn setup(problem: Problem, steps: usize) -> Setup {
    match problem {
        Problem::Lu => Setup {
            problem,
            steps,
            fix_every: FIX_EVERY,
            p0: Matrix3::from_diagonal(&Vector3::new(100.0, 1.0, 0.01)),
            r: Matrix2::new(1.0, 0.0, 0.0, 0.0016),
        },
        Problem::Stiff => Setup {
            problem,
            steps: steps / FIX_EVERY,
            fix_every: 1,
            p0: Matrix3::identity() * 1e6,
            r: Matrix2::identity() * 1e-12,
        },
    }
}

fn phi() -> Matrix3<f64> {
    Matrix3::new(1.0, DT, -DT * DT / 2.0, 0.0, 1.0, -DT, 0.0, 0.0, 1.0)
}

fn gamma() -> Vector3<f64> {
    Vector3::new(DT * DT / 2.0, DT, 0.0)
}

const W: f64 = 0.0004;

/// The filter under test, named for the table.
#[derive(Clone, Copy)]
enum Kind {
    Kf,
    Ekf,
    Ukf,
}

#[derive(Clone, Copy)]
enum Form {
    Full(CovarianceUpdate),
    SquareRoot,
}

/// The χ²ₖ quantile at standard normal quantile z (Wilson–Hilferty; < 1 % error for k ≥ 100).
fn chi2(k: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// Any filter of the table, boxed.
trait Filter<T: Real>:
    Predict<T, U3, LinearProcess<T, U3, U1>> + Update<T, U3, U2, LinearMeasurement<T, U3, U2>>
{
}
impl<T: Real, F> Filter<T> for F where
    F: Predict<T, U3, LinearProcess<T, U3, U1>> + Update<T, U3, U2, LinearMeasurement<T, U3, U2>>
{
}

fn make<T: Real>(kind: Kind, form: Form, prior: Gaussian<T, U3>) -> Box<dyn Filter<T>> {
    match (kind, form) {
        (Kind::Kf, Form::Full(f)) => Box::new(KalmanFilter::new(prior).with_covariance_update(f)),
        (Kind::Ekf, Form::Full(f)) => Box::new(Ekf::new(prior).with_covariance_update(f)),
        (Kind::Ukf, Form::Full(f)) => Box::new(Ukf::new(prior).with_covariance_update(f)),
        (Kind::Kf, Form::SquareRoot) => Box::new(SrKalmanFilter::new(prior)),
        (Kind::Ekf, Form::SquareRoot) => Box::new(SrEkf::new(prior)),
        (Kind::Ukf, Form::SquareRoot) => {
            Box::new(SquareRootFilter::<T, U3, Unscented<T>>::new(prior))
        }
    }
}

/// How a run ended.
struct Outcome {
    /// The step of the first failure, and why; `None`: survived.
    failure: Option<(usize, String)>,
    /// The last complete window's ensemble NEES.
    nees: f64,
}

/// One configuration over `seeds` Monte Carlo runs in lockstep (run i from seed i).
fn run<T: Real + Into<f64>>(setup: &Setup, kind: Kind, form: Form, seeds: u64) -> Outcome {
    let c = |v: f64| estim_core::scalar::real::<T>(v);
    let process = LinearProcess {
        transition: phi().map(c),
        input: Vector3::zeros(),
        noise: (gamma() * gamma().transpose() * W).map(c),
    };
    let h = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let sensor = LinearMeasurement {
        observation: h.map(c),
        noise: setup.r.map(c),
    };
    let l0 = setup.p0.cholesky().unwrap().l();
    let lr = setup.r.cholesky().unwrap().l();
    let u = Vector1::zeros();
    let prior = Gaussian::new(Vector3::zeros(), setup.p0.map(c)).unwrap();
    let mut rngs: Vec<StdRng> = (0..seeds).map(StdRng::seed_from_u64).collect();
    let normal = |rng: &mut StdRng| -> f64 { StandardNormal.sample(rng) };
    let mut truths: Vec<Vector3<f64>> = rngs
        .iter_mut()
        .map(|r| l0 * Vector3::new(normal(r), normal(r), normal(r)))
        .collect();
    let mut filters: Vec<_> = (0..seeds)
        .map(|_| make(kind, form, prior.clone()))
        .collect();
    // The ensemble NEES at one fix is χ²(3S)/S for S consistent runs. The fixes of a window are
    // correlated in time (the bias error changes slowly), so the window mean is given the
    // band of one fix: conservative, and still far from the 10⁷ of an overconfident filter.
    let s = seeds as f64;
    let (lower, upper) = (chi2(3.0 * s, -3.29) / s, chi2(3.0 * s, 3.29) / s);
    let (mut sum, mut count, mut last) = (0.0, 0, f64::NAN);
    let fail = |step, why: String, nees| Outcome {
        failure: Some((step, why)),
        nees,
    };
    for step in 1..=setup.steps {
        let fix = step % setup.fix_every == 0;
        let mut nees = 0.0;
        for ((x, rng), filter) in truths.iter_mut().zip(&mut rngs).zip(&mut filters) {
            *x = phi() * *x - gamma() * (W.sqrt() * normal(rng));
            if let Err(e) = filter.predict(&process, &u, c(DT)) {
                return fail(step, format!("{e}"), last);
            }
            if !fix {
                continue;
            }
            let z = h * *x + lr * Vector2::new(normal(rng), normal(rng));
            if let Err(e) = filter.update(&sensor, &z.map(c)) {
                return fail(step, format!("{e}"), last);
            }
            let e = *x - filter.state().map(Into::into);
            let p: Matrix3<f64> = filter.covariance().map(Into::into);
            match p.cholesky() {
                Some(chol) => nees += e.dot(&chol.solve(&e)) / s,
                // (b) judges only errors and invalid covariances (see the module docs).
                None if setup.problem == Problem::Stiff => {
                    if !p.iter().all(|v| v.is_finite()) || p.diagonal().min() < 0.0 {
                        return fail(step, "P with a negative variance".into(), last);
                    }
                    nees = f64::NAN;
                }
                None => return fail(step, "P not positive definite".into(), last),
            }
        }
        if !fix {
            continue;
        }
        sum += nees;
        count += 1;
        if count == WINDOW {
            last = sum / WINDOW as f64;
            if setup.problem == Problem::Lu && !(lower..=upper).contains(&last) {
                return fail(
                    step,
                    format!("NEES {last:.3e} outside [{lower:.2}, {upper:.2}]"),
                    last,
                );
            }
            (sum, count) = (0.0, 0);
        }
    }
    Outcome {
        failure: None,
        nees: last,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let seeds: u64 = args
        .iter()
        .position(|a| a == "--seeds")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(4);
    let steps = if quick { 100_000 } else { 1_000_000 };
    let forms = [
        ("Joseph", Form::Full(CovarianceUpdate::Joseph)),
        ("Standard", Form::Full(CovarianceUpdate::Standard)),
        ("Symmetrized", Form::Full(CovarianceUpdate::Symmetrized)),
        ("square root", Form::SquareRoot),
    ];
    let kinds = [("KF", Kind::Kf), ("EKF", Kind::Ekf), ("UKF", Kind::Ukf)];
    for problem in [Problem::Lu, Problem::Stiff] {
        let setup = setup(problem, steps);
        println!(
            "\n{} ({} steps, {} seeds; NEES band per {WINDOW}-fix window, 3 dof, 99.9 %)\n",
            match problem {
                Problem::Lu => "(a) Lu bias calibration, no process noise on the bias",
                Problem::Stiff => "(b) R = 1e-12 I, P0 = 1e6 I, a fix every step",
            },
            setup.steps,
            seeds
        );
        println!(
            "| filter | form | f32: steps to failure | f32: last NEES | f64: steps to failure | f64: last NEES |"
        );
        println!("|---|---|---|---|---|---|");
        for (kname, kind) in kinds {
            for (fname, form) in forms {
                let mut cells = Vec::new();
                for f32_run in [true, false] {
                    let outcome = if f32_run {
                        run::<f32>(&setup, kind, form, seeds)
                    } else {
                        run::<f64>(&setup, kind, form, seeds)
                    };
                    cells.push(match outcome.failure {
                        Some((s, why)) => format!("{s} ({why})"),
                        None => format!("survived {}", setup.steps),
                    });
                    cells.push(if outcome.nees.is_finite() {
                        format!("{:.2}", outcome.nees)
                    } else {
                        "—".into()
                    });
                }
                println!("| {kname} | {fname} | {} |", cells.join(" | "));
            }
        }
    }
}
