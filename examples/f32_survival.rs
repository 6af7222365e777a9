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
//! (a) runs in three loops. *Open*: the filter holds the whole error state, which grows as
//! δp ≈ ½ b t² (≈ 4·10⁴ m, δv ≈ 150 m/s after 600 s). *Closed*: after each fix the estimate
//! is fed into a nominal x̄ kept in f64 (x̄ ← x̄ + x̂) and the filter restarts from x̂ = 0 with
//! its covariance kept (`reset` for the full-P forms, `SquareRootFilter::set_state` for the
//! square-root ones, which keeps the factor); the filter sees z − H x̄ and only ever holds a
//! small correction, as an INS/GPS error-state filter does. *Closed, nominal in T*: the same
//! with x̄ propagated in T.
//!
//! Why the open loop fails in f32 (the last table: an f64 KF with one quantity rounded to
//! f32). Rounding only the state after each prediction reproduces the f32 failure step
//! (120 000); rounding the state after each update fails only at 800 000, the covariance or
//! the measurements never. The prediction adds −Δt·b ≈ 1.2·10⁻³ m/s to δv ≈ 150 m/s, whose
//! ulp is 1.5·10⁻⁵: each increment is rounded to a whole number of ulps, and as δv changes
//! slowly the rounding repeats, a mean δv error of ≈ 5·10⁻⁷ m/s per step (printed with each
//! failure), i.e. a bias error of 10⁻⁴ m/s², ≈ 2σ of the bias the filter has learned. The
//! bias is the component that goes overconfident first (e²/P ≈ 5 against 1). The
//! covariance is not involved, which is why every covariance form fails at the same step;
//! the closed loop, which keeps the f32 state small, survives, and the closed loop with the
//! nominal in f32 fails at the same step again.
//!
//! `cargo run --release --example f32_survival` (add `-- --quick` for 10⁵ steps, `-- --seeds K`
//! for K Monte Carlo seeds, default 4).

use estim::filters::square_root::SquareRootFilter;
use estim::nalgebra::{Matrix2, Matrix2x3, Matrix3, U1, U2, U3, Vector1, Vector2, Vector3};
use estim::prelude::*;
use estim::rand::SeedableRng;
use estim::rand::rngs::StdRng;
use estim_core::Real;
use estim_core::propagate::PropagatorWorkspace;
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

/// How the filter's error state relates to the navigation solution (see the module docs).
#[derive(Clone, Copy, PartialEq)]
enum Loop {
    /// The filter estimates the whole error state δx, which grows as ½ b t².
    Open,
    /// After each fix the estimate is added to a nominal kept in f64 and the filter's state
    /// is reset to zero (its covariance kept): the filter only ever holds a small correction.
    Closed,
    /// [`Loop::Closed`] with the nominal propagated in the filter's scalar.
    ClosedNominalT,
}

/// What an f64 run rounds to f32 (the cause-finding runs; see the module docs).
#[derive(Clone, Copy, PartialEq)]
enum Probe {
    /// Nothing.
    None,
    /// The state after every prediction.
    StateAfterPredict,
    /// The state after every update.
    StateAfterUpdate,
    /// The covariance after every prediction and update.
    Covariance,
    /// The measurements.
    Measurement,
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
    /// The closed loop's reset: x̂ ← 0, the covariance (or its factor) kept as it is.
    fn zero_state(&mut self);
}

impl<T: Real, Pr: PropagatorWorkspace<T>> Filter<T> for GaussianFilter<T, U3, Pr>
where
    Self:
        Predict<T, U3, LinearProcess<T, U3, U1>> + Update<T, U3, U2, LinearMeasurement<T, U3, U2>>,
{
    fn zero_state(&mut self) {
        let p = *self.covariance();
        self.reset(Gaussian::new_unchecked(Vector3::zeros(), p));
    }
}

impl<T: Real, Pr> Filter<T> for SquareRootFilter<T, U3, Pr>
where
    Self:
        Predict<T, U3, LinearProcess<T, U3, U1>> + Update<T, U3, U2, LinearMeasurement<T, U3, U2>>,
{
    fn zero_state(&mut self) {
        // `reset` would factorise S Sᵀ again, in T, and lose what the factor holds.
        self.set_state(Vector3::zeros())
            .expect("a zero state has the right size and is finite");
    }
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
fn run<T: Real + Into<f64>>(
    setup: &Setup,
    kind: Kind,
    form: Form,
    lp: Loop,
    probe: Probe,
    seeds: u64,
) -> Outcome {
    let c = |v: f64| estim_core::scalar::real::<T>(v);
    let to32 = |v: T| c(Into::<f64>::into(v) as f32 as f64);
    let round = |filter: &mut Box<dyn Filter<T>>, state: bool| {
        let (x, p) = (*filter.state(), *filter.covariance());
        let (x, p) = if state {
            (x.map(to32), p)
        } else {
            (x, p.map(to32))
        };
        filter.reset(Gaussian::new_unchecked(x, p));
    };
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
    // The closed loop's nominal x̄ (the navigation solution's correction, = the prior mean):
    // propagated by the error dynamics (x̄ ← Φ x̄, what a mechanisation compensating the
    // estimated bias does) in f64, or in T for `Loop::ClosedNominalT`.
    let mut nominals = vec![Vector3::<f64>::zeros(); truths.len()];
    let propagate_nominal = |x: &Vector3<f64>| match lp {
        Loop::ClosedNominalT => (phi().map(c) * x.map(c)).map(Into::into),
        _ => phi() * x,
    };
    // The ensemble NEES at one fix is χ²(3S)/S for S consistent runs. The fixes of a window are
    // correlated in time (the bias error changes slowly), so the window mean is given the
    // band of one fix: conservative, and still far from the 10⁷ of an overconfident filter.
    let s = seeds as f64;
    let (lower, upper) = (chi2(3.0 * s, -3.29) / s, chi2(3.0 * s, 3.29) / s);
    let (mut sum, mut count, mut last) = (0.0, 0, f64::NAN);
    // Over the window: Σ eᵢ²/Pᵢᵢ per component (each 1 when consistent), and the rounding of
    // the propagated state (the filter's x̂, plus the nominal in closed loop) as the mean
    // per-step difference of its δv from Φ·(the same state) computed in f64.
    let (mut components, mut drift) = (Vector3::<f64>::zeros(), 0.0);
    let fail = |step, why: String, nees| Outcome {
        failure: Some((step, why)),
        nees,
    };
    for step in 1..=setup.steps {
        let fix = step % setup.fix_every == 0;
        let mut nees = 0.0;
        let runs = truths.iter_mut().zip(&mut rngs).zip(&mut filters);
        for (((x, rng), filter), nominal) in runs.zip(&mut nominals) {
            *x = phi() * *x - gamma() * (W.sqrt() * normal(rng));
            if lp != Loop::Open {
                let propagated = propagate_nominal(nominal);
                drift += (propagated - phi() * *nominal)[1];
                *nominal = propagated;
            }
            let before: Vector3<f64> = filter.state().map(Into::into);
            if let Err(e) = filter.predict(&process, &u, c(DT)) {
                return fail(step, format!("{e}"), last);
            }
            match probe {
                Probe::StateAfterPredict => round(filter, true),
                Probe::Covariance => round(filter, false),
                _ => {}
            }
            drift += (filter.state().map(Into::into) - phi() * before)[1];
            if !fix {
                continue;
            }
            let z = h * *x + lr * Vector2::new(normal(rng), normal(rng));
            let z = match probe {
                Probe::Measurement => z.map(|v| v as f32 as f64),
                _ => z,
            };
            // Closed loop: the filter sees z − H x̄, the measurement of the error x − x̄.
            if let Err(e) = filter.update(&sensor, &(z - h * *nominal).map(c)) {
                return fail(step, format!("{e}"), last);
            }
            match probe {
                Probe::StateAfterUpdate => round(filter, true),
                Probe::Covariance => round(filter, false),
                _ => {}
            }
            if lp != Loop::Open {
                // Feed the estimate back and restart the filter from a zero correction.
                *nominal += filter.state().map(Into::into);
                filter.zero_state();
            }
            let e = *x - *nominal - filter.state().map(Into::into);
            let p: Matrix3<f64> = filter.covariance().map(Into::into);
            match p.cholesky() {
                Some(chol) => {
                    nees += e.dot(&chol.solve(&e)) / s;
                    components += e.component_mul(&e).component_div(&p.diagonal()) / s;
                }
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
                let [dp, dv, b] = (components / WINDOW as f64).into();
                let drift = drift / (WINDOW * setup.fix_every) as f64 / s;
                return fail(
                    step,
                    format!(
                        "NEES {last:.3e} outside [{lower:.2}, {upper:.2}]; per component \
                         δp {dp:.2}, δv {dv:.2}, b {b:.2}; δv rounding {drift:.1e}/step"
                    ),
                    last,
                );
            }
            (sum, count, components, drift) = (0.0, 0, Vector3::zeros(), 0.0);
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
    let cell = |outcome: Outcome, steps: usize| {
        let failure = match outcome.failure {
            Some((s, why)) => format!("{s} ({why})"),
            None => format!("survived {steps}"),
        };
        let nees = if outcome.nees.is_finite() {
            format!("{:.2}", outcome.nees)
        } else {
            "—".into()
        };
        format!("{failure} | {nees}")
    };
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
            "| filter | form | loop | f32: steps to failure | f32: last NEES | f64: steps to failure | f64: last NEES |"
        );
        println!("|---|---|---|---|---|---|---|");
        let loops: &[(&str, Loop)] = match problem {
            Problem::Lu => &[
                ("open", Loop::Open),
                ("closed", Loop::Closed),
                ("closed, nominal in T", Loop::ClosedNominalT),
            ],
            Problem::Stiff => &[("open", Loop::Open)],
        };
        for &(lname, lp) in loops {
            for (kname, kind) in kinds {
                for (fname, form) in forms {
                    let f32_cell = cell(
                        run::<f32>(&setup, kind, form, lp, Probe::None, seeds),
                        setup.steps,
                    );
                    let f64_cell = cell(
                        run::<f64>(&setup, kind, form, lp, Probe::None, seeds),
                        setup.steps,
                    );
                    println!("| {kname} | {fname} | {lname} | {f32_cell} | {f64_cell} |");
                }
            }
        }
    }
    // The cause: an f64 KF (Joseph form, open loop) with one quantity rounded to f32.
    let setup = setup(Problem::Lu, steps);
    println!("\n(a), f64 KF (Joseph, open loop) with one quantity rounded to f32\n");
    println!("| rounded to f32 | steps to failure | last NEES |");
    println!("|---|---|---|");
    for (name, probe) in [
        ("nothing", Probe::None),
        ("the state after each prediction", Probe::StateAfterPredict),
        ("the state after each update", Probe::StateAfterUpdate),
        ("the covariance after each step", Probe::Covariance),
        ("the measurements", Probe::Measurement),
    ] {
        let form = Form::Full(CovarianceUpdate::Joseph);
        let outcome = run::<f64>(&setup, Kind::Kf, form, Loop::Open, probe, seeds);
        println!("| {name} | {} |", cell(outcome, setup.steps));
    }
}
