//! The iterated EKF: one iteration is the EKF bit for bit; on a linear model it is the Kalman
//! filter; its converged estimate is a stationary point of the MAP cost, which the step-size
//! safeguard never lets increase; on a range-only measurement its mean is closer than the
//! EKF's to the exact posterior mean (computed by quadrature), by a paired statistic over a
//! small Monte Carlo; bad input is a typed error that leaves the filter bit for bit unchanged.

use crate::common::{assert_bitwise_eq, normal, random_spd, rng};
use crate::counting::allocations_during;

use estim_core::nalgebra::{
    DMatrix, DVector, Dyn, Matrix1, Matrix2, RowVector2, U1, U2, Vector1, Vector2,
};
use estim_core::{
    Error, Gaussian, LinearMeasurement, LinearProcess, MeasurementJacobian, MeasurementModel,
    Parameter, Quantity, Stage,
};
use estim_filters::{
    Ekf, Estimator, Iekf, KalmanFilter, Predict, Update, UpdateOutcome, UpdateReport,
};

/// A range |p| to a 2-D position p, with variance `r`.
struct Range {
    r: f64,
}

impl MeasurementModel<f64, U2, U1> for Range {
    fn measure(&self, p: &Vector2<f64>) -> Vector1<f64> {
        Vector1::new(p.norm())
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> {
        Matrix1::new(self.r)
    }
}

impl MeasurementJacobian<f64, U2, U1> for Range {
    fn measurement_jacobian(&self, p: &Vector2<f64>) -> RowVector2<f64> {
        (p / p.norm()).transpose()
    }
}

/// The same range model on runtime sizes.
struct DynRange {
    r: f64,
}

impl MeasurementModel<f64, Dyn, Dyn> for DynRange {
    fn measure(&self, p: &DVector<f64>) -> DVector<f64> {
        DVector::from_element(1, p.norm())
    }
    fn measurement_noise(&self, _: &DVector<f64>) -> DMatrix<f64> {
        DMatrix::from_element(1, 1, self.r)
    }
}

impl MeasurementJacobian<f64, Dyn, Dyn> for DynRange {
    fn measurement_jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
        DMatrix::from_row_slice(1, 2, &[p[0] / p.norm(), p[1] / p.norm()])
    }
}

/// A prior at range 10 whose long axis (σ = 4) is at 45° to the line of sight, short axis
/// σ = 0.5: the EKF's correction P Hᵀ is then far from radial, along a line on which |p| is
/// curved, so relinearising matters.
fn oblique_prior() -> Gaussian<f64, U2> {
    let (c, s) = (
        core::f64::consts::FRAC_1_SQRT_2,
        core::f64::consts::FRAC_1_SQRT_2,
    );
    let rot = Matrix2::new(c, -s, s, c);
    let p = rot * Matrix2::new(16.0, 0.0, 0.0, 0.25) * rot.transpose();
    let p = (p + p.transpose()) * 0.5;
    Gaussian::new(Vector2::new(10.0, 0.0), p).unwrap()
}

/// The MAP cost J(x) = ½ (z − h(x))² / R + ½ (x − x⁻)ᵀ P⁻⁻¹ (x − x⁻), written out with a
/// plain inverse (independent of the filter's factorisations).
fn map_cost(prior: &Gaussian<f64, U2>, r: f64, z: f64, x: &Vector2<f64>) -> f64 {
    let d = x - prior.mean();
    let info = prior.covariance().try_inverse().unwrap();
    0.5 * (z - x.norm()).powi(2) / r + 0.5 * (d.transpose() * info * d)[0]
}

/// ∇J(x) = −Hᵀ (z − h(x)) / R + P⁻⁻¹ (x − x⁻), H = xᵀ/|x|.
fn map_gradient(prior: &Gaussian<f64, U2>, r: f64, z: f64, x: &Vector2<f64>) -> Vector2<f64> {
    let info = prior.covariance().try_inverse().unwrap();
    -(x / x.norm()) * ((z - x.norm()) / r) + info * (x - prior.mean())
}

/// With one iteration the update is the EKF's, bit for bit, state, covariance and report
/// (static and runtime sizes): the first Gauss–Newton step runs the EKF's own update code on
/// the same values, at its linearisation point the affine model returns h(x⁻) itself, and
/// with one iteration the step is never shortened.
/// Prediction is the EKF's too.
#[test]
fn one_iteration_is_the_ekf_bit_for_bit() {
    let prior = oblique_prior();
    let range = Range { r: 0.01 };
    let process = LinearProcess {
        transition: Matrix2::new(1.0, 0.1, -0.05, 1.0),
        input: Matrix2::zeros(),
        noise: Matrix2::new(0.02, 0.005, 0.005, 0.03),
    };
    let mut iekf = Iekf::new(prior.clone()).with_iterations(1, 0.0).unwrap();
    let mut ekf = Ekf::new(prior.clone());
    for z in [11.3, 12.0, 9.1] {
        iekf.predict(&process, &Vector2::zeros(), 1.0).unwrap();
        ekf.predict(&process, &Vector2::zeros(), 1.0).unwrap();
        assert_bitwise_eq(iekf.state(), ekf.state(), "predicted state");
        let a = iekf.update(&range, &Vector1::new(z)).unwrap();
        let b = ekf.update(&range, &Vector1::new(z)).unwrap();
        assert_bitwise_eq(iekf.state(), ekf.state(), "state");
        assert_bitwise_eq(iekf.covariance(), ekf.covariance(), "covariance");
        assert_eq!(a.nis.to_bits(), b.nis.to_bits());
        assert_eq!(a.log_likelihood.to_bits(), b.log_likelihood.to_bits());
        assert_bitwise_eq(&a.innovation, &b.innovation, "innovation");
        let its = a.iterations.unwrap();
        assert_eq!(its.count, 1);
        assert!(b.iterations.is_none());
    }

    let dyn_prior = prior.clone().into_dyn();
    let mut iekf = Iekf::new(dyn_prior.clone())
        .with_iterations(1, 0.0)
        .unwrap();
    let mut ekf = Ekf::new(dyn_prior);
    let z = DVector::from_element(1, 11.3);
    iekf.update(&DynRange { r: 0.01 }, &z).unwrap();
    ekf.update(&DynRange { r: 0.01 }, &z).unwrap();
    assert_eq!(iekf.state(), ekf.state());
    assert_eq!(iekf.covariance(), ekf.covariance());
}

/// On a linear measurement the Gauss–Newton point does not depend on the linearisation
/// point, so the second step moves only by round-off and the iteration converges at step 2,
/// agreeing with the Kalman filter to rounding: relative 1e-13 (a few hundred ε; the state and
/// covariance are O(1) and the second step recomputes ẑ as H x₁ + H (x⁻ − x₁)).
#[test]
fn on_a_linear_model_it_is_the_kalman_filter() {
    let mut r = rng(7);
    let p0 = random_spd(&mut r, U2, 1.0, 0.1);
    let prior = Gaussian::new(Vector2::new(0.3, -1.2), p0).unwrap();
    let sensor = LinearMeasurement {
        observation: Matrix2::new(1.0, 0.5, -0.3, 2.0),
        noise: random_spd(&mut r, U2, 0.2, 0.05),
    };
    let z = Vector2::new(1.0, 0.4);
    let mut iekf = Iekf::new(prior.clone()).with_iterations(50, 1e-12).unwrap();
    let mut kf = KalmanFilter::new(prior);
    let report = iekf.update(&sensor, &z).unwrap();
    kf.update(&sensor, &z).unwrap();
    let its = report.iterations.unwrap();
    assert!(its.converged, "{its:?}");
    assert_eq!(its.count, 2, "{its:?}");
    assert!((iekf.state() - kf.state()).abs().max() < 1e-13);
    assert!((iekf.covariance() - kf.covariance()).abs().max() < 1e-13);
}

/// The converged estimate is a stationary point of the MAP cost (the Gauss–Newton fixed
/// point: ∇J = 0), its cost is at most the EKF's (the first step is the EKF's, and the
/// safeguard never takes a step that raises J), and the covariance is the Joseph form at the
/// final linearisation, all checked with formulas written out here.
///
/// Tolerances: the step tolerance is 1e-12 relative to |x| ≈ 10, so x⁺ is within ~1e-11 of the
/// fixed point; ∇J there is at most that times the Hessian of J (|∂²J| ≤ 1/R + |P⁻⁻¹| ≈ 10²),
/// i.e. ~1e-9, plus round-off in J's terms (|z − h|/R ≈ 10², times ε): bound 1e-7. The
/// covariance is evaluated at H(x⁺), which differs from the filter's last linearisation by
/// ~1e-12 (relative): bound 1e-9 on entries of size ≤ 16.
#[test]
fn converges_to_the_map_estimate_with_the_joseph_covariance() {
    let prior = oblique_prior();
    let r = 0.01;
    let range = Range { r };
    for z in [13.0, 8.0, 10.5, 15.0] {
        let mut iekf = Iekf::new(prior.clone())
            .with_iterations(100, 1e-12)
            .unwrap();
        let mut ekf = Ekf::new(prior.clone());
        let report = iekf.update(&range, &Vector1::new(z)).unwrap();
        ekf.update(&range, &Vector1::new(z)).unwrap();
        let its = report.iterations.unwrap();
        assert!(its.converged, "z = {z}: {its:?}");
        let x = iekf.state();
        let g = map_gradient(&prior, r, z, x);
        assert!(g.norm() < 1e-7, "z = {z}: ∇J = {g}");
        let (j_iekf, j_ekf) = (
            map_cost(&prior, r, z, x),
            map_cost(&prior, r, z, ekf.state()),
        );
        assert!(j_iekf <= j_ekf, "z = {z}: J {j_iekf} > EKF's {j_ekf}");
        // Joseph at H(x⁺).
        let h = (x / x.norm()).transpose();
        let p = prior.covariance();
        let s = (h * p * h.transpose())[0] + r;
        let k = p * h.transpose() / s;
        let a = Matrix2::identity() - k * h;
        let joseph = a * p * a.transpose() + k * k.transpose() * r;
        assert!(
            (iekf.covariance() - joseph).abs().max() < 1e-9,
            "z = {z}: {} vs {joseph}",
            iekf.covariance()
        );
        // The report's statistics are the EKF's (first linearisation, at x⁻).
        let hx = prior.mean().norm();
        let h0 = (prior.mean() / hx).transpose();
        let s0 = (h0 * p * h0.transpose())[0] + r;
        assert!((report.innovation[0] - (z - hx)).abs() < 1e-12);
        assert!((report.nis - (z - hx).powi(2) / s0).abs() < 1e-10 * report.nis.max(1.0));
    }
}

/// The exact posterior mean of p given z = |p| + v (v ~ N(0, r)) under the prior N(m, P), by
/// quadrature in polar coordinates (p = ρ (cos θ, sin θ), area element ρ dρ dθ): ρ over
/// z ± 6√r (the likelihood factor, 2·`nr` intervals), θ over the whole circle (`nt` points; the
/// trapezoid rule on a smooth periodic integrand converges geometrically). The prior's
/// density has no mass near ρ = 0 here (|m| = 10 is 2.5 long-axis σ away), so z > 6√r for the
/// draws used.
fn exact_posterior_mean(
    prior: &Gaussian<f64, U2>,
    r: f64,
    z: f64,
    nr: usize,
    nt: usize,
) -> Vector2<f64> {
    let info = prior.covariance().try_inverse().unwrap();
    let m = prior.mean();
    let sd = r.sqrt();
    let (rho0, rho1) = ((z - 6.0 * sd).max(0.0), z + 6.0 * sd);
    let dr = (rho1 - rho0) / (2 * nr) as f64;
    let dt = 2.0 * core::f64::consts::PI / nt as f64;
    let (mut w, mut sx, mut sy) = (0.0, 0.0, 0.0);
    // Log-weights are shifted by their value at the best grid point found on a first pass, so
    // the exponentials neither underflow nor overflow.
    let log_weight = |rho: f64, th: f64| {
        let p = Vector2::new(rho * th.cos(), rho * th.sin());
        let d = p - m;
        -0.5 * (d.transpose() * info * d)[0] - 0.5 * (z - rho).powi(2) / r + rho.ln()
    };
    let mut best = f64::NEG_INFINITY;
    for i in 0..=2 * nr {
        for j in 0..nt {
            best = best.max(log_weight(rho0 + i as f64 * dr, j as f64 * dt));
        }
    }
    for i in 0..=2 * nr {
        let rho = rho0 + i as f64 * dr;
        // Simpson's weights in ρ.
        let simpson = if i == 0 || i == 2 * nr {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        for j in 0..nt {
            let th = j as f64 * dt;
            let wt = simpson * (log_weight(rho, th) - best).exp();
            w += wt;
            sx += wt * rho * th.cos();
            sy += wt * rho * th.sin();
        }
    }
    Vector2::new(sx / w, sy / w)
}

/// The quadrature is converged: doubling both resolutions moves the mean by < 1e-6, far below
/// the EKF–IEKF error differences (~0.1) the Monte Carlo below measures.
#[test]
fn posterior_quadrature_is_converged() {
    let prior = oblique_prior();
    for z in [13.0, 8.5] {
        let coarse = exact_posterior_mean(&prior, 0.01, z, 24, 1024);
        let fine = exact_posterior_mean(&prior, 0.01, z, 48, 2048);
        assert!((coarse - fine).norm() < 1e-6, "z = {z}: {coarse} vs {fine}");
    }
}

/// Range-only update from the oblique prior, with truths drawn from the prior (so the exact
/// posterior is the right reference) and z = |p| + v: over 60 draws, the IEKF's distance to
/// the exact posterior mean is smaller than the EKF's. Paired statistic: dₖ = eₖ(EKF) −
/// eₖ(IEKF) for the same draw; its mean must exceed 3 standard errors (a one-sided z-test at
/// ≈ 0.1 %, valid for 60 independent pairs by the central limit theorem), and the IEKF must be
/// closer in most draws (a sign count). The numbers (mean, SE, wins) are printed.
#[test]
fn range_only_iekf_is_closer_to_the_exact_posterior_mean_than_the_ekf() {
    let prior = oblique_prior();
    let r = 0.01;
    let range = Range { r };
    let root = prior.covariance().cholesky().unwrap().l();
    let mut g = rng(2026);
    let runs = 60;
    let mut diffs = Vec::with_capacity(runs);
    let mut wins = 0;
    for _ in 0..runs {
        let truth = prior.mean() + root * Vector2::new(normal(&mut g), normal(&mut g));
        let z = truth.norm() + r.sqrt() * normal(&mut g);
        let exact = exact_posterior_mean(&prior, r, z, 24, 1024);
        let mut ekf = Ekf::new(prior.clone());
        let mut iekf = Iekf::new(prior.clone()).with_iterations(30, 1e-10).unwrap();
        ekf.update(&range, &Vector1::new(z)).unwrap();
        iekf.update(&range, &Vector1::new(z)).unwrap();
        let (e_ekf, e_iekf) = ((ekf.state() - exact).norm(), (iekf.state() - exact).norm());
        diffs.push(e_ekf - e_iekf);
        wins += usize::from(e_iekf < e_ekf);
    }
    let mean = diffs.iter().sum::<f64>() / runs as f64;
    let var = diffs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (runs - 1) as f64;
    let se = (var / runs as f64).sqrt();
    println!("mean paired gain {mean:.4}, SE {se:.4}, IEKF closer in {wins}/{runs}");
    assert!(mean > 3.0 * se, "mean {mean}, SE {se}");
    assert!(2 * wins > runs, "IEKF closer in only {wins}/{runs}");
}

/// The safeguard: with h undefined (NaN) beyond a boundary that a full Gauss–Newton step
/// crosses, the step is halved until J is finite and no larger, so the update succeeds with a
/// finite estimate whose cost is at most the prior's.
#[test]
fn step_halving_keeps_the_iterate_where_the_cost_decreases() {
    /// z = √x₁ + v (NaN for x₁ < 0), x₂ unobserved.
    struct Root;
    impl MeasurementModel<f64, U2, U1> for Root {
        fn measure(&self, x: &Vector2<f64>) -> Vector1<f64> {
            Vector1::new(x[0].sqrt())
        }
        fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> {
            Matrix1::new(1e-4)
        }
    }
    impl MeasurementJacobian<f64, U2, U1> for Root {
        fn measurement_jacobian(&self, x: &Vector2<f64>) -> RowVector2<f64> {
            RowVector2::new(0.5 / x[0].sqrt(), 0.0)
        }
    }
    // Prior at x₁ = 1 (h = 1); z = 0.05: the linearised step 1 + 2 (0.05 − 1) = −0.9 lands
    // where h is undefined, so the first step is the EKF's only if J there were finite.
    let prior = Gaussian::new(Vector2::new(1.0, 0.0), Matrix2::identity()).unwrap();
    let mut iekf = Iekf::new(prior.clone()).with_iterations(50, 1e-12).unwrap();
    let report = iekf.update(&Root, &Vector1::new(0.05)).unwrap();
    let x = iekf.state();
    assert!(x[0] > 0.0 && x.iter().all(|v| v.is_finite()), "{x}");
    let cost = |x: &Vector2<f64>| {
        0.5 * (0.05 - x[0].sqrt()).powi(2) / 1e-4 + 0.5 * (x - prior.mean()).norm_squared()
    };
    assert!(cost(x) <= cost(prior.mean()));
    let its = report.iterations.unwrap();
    assert!(its.count > 1, "{its:?}");
    // The EKF itself steps to x₁ < 0, where the estimate is no longer in h's domain.
    let mut ekf = Ekf::new(prior);
    ekf.update(&Root, &Vector1::new(0.05)).unwrap();
    assert!(ekf.state()[0] < 0.0);
}

/// One failing update of the bad-input test.
type Case = Box<dyn Fn(&mut Iekf<f64, U2>) -> Result<UpdateReport<f64, U1>, Error>>;

/// Bad settings and bad input are typed errors; a failed update leaves the filter bit for bit
/// as it was; a gated update does not iterate and changes nothing; a report reused by a
/// one-step filter says `None`.
#[test]
fn bad_input_is_a_typed_error_and_leaves_the_filter_unchanged() {
    let prior = oblique_prior();
    for (max, tol, parameter) in [
        (0, 1e-9, Parameter::StepCount),
        (1001, 1e-9, Parameter::StepCount),
        (5, -1e-9, Parameter::Tolerance),
        (5, f64::NAN, Parameter::Tolerance),
        (5, f64::INFINITY, Parameter::Tolerance),
    ] {
        let e = Iekf::new(prior.clone())
            .with_iterations(max, tol)
            .unwrap_err();
        assert!(
            matches!(e, Error::InvalidParameter { parameter: p, .. } if p == parameter),
            "{e:?}"
        );
    }
    let mut iekf = Iekf::new(prior.clone()).with_iterations(20, 1e-10).unwrap();
    let cases: [(Case, Error); 3] = [
        (
            Box::new(|f| f.update(&Range { r: 0.01 }, &Vector1::new(f64::NAN))),
            Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Measurement,
            },
        ),
        (
            Box::new(|f| f.update(&Range { r: -0.01 }, &Vector1::new(12.0))),
            Error::NotPositiveSemiDefinite {
                stage: Stage::Update,
                quantity: Quantity::MeasurementNoise,
            },
        ),
        (
            Box::new(|f| f.update(&Range { r: f64::INFINITY }, &Vector1::new(12.0))),
            Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::MeasurementNoise,
            },
        ),
    ];
    for (op, expected) in cases {
        let before = iekf.clone();
        assert_eq!(op(&mut iekf).unwrap_err(), expected);
        assert!(iekf == before);
        assert_bitwise_eq(iekf.state(), before.state(), "state");
        assert_bitwise_eq(iekf.covariance(), before.covariance(), "covariance");
    }
    // Runtime sizes: a measurement of the wrong length.
    let mut dyn_iekf = Iekf::new(prior.clone().into_dyn());
    let before = dyn_iekf.clone();
    let e = dyn_iekf
        .update(&DynRange { r: 0.01 }, &DVector::from_element(2, 12.0))
        .unwrap_err();
    assert!(
        matches!(
            e,
            Error::DimensionMismatch {
                quantity: Quantity::Measurement,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(dyn_iekf == before);

    // Gated: NIS of a 20σ outlier above 9; nothing changes, no iterations.
    let mut gated = Iekf::new(prior.clone()).with_gate(9.0).unwrap();
    let before = gated.clone();
    let report = gated
        .update(&Range { r: 0.01 }, &Vector1::new(40.0))
        .unwrap();
    assert_eq!(report.outcome, UpdateOutcome::Gated);
    assert_eq!(report.iterations.unwrap().count, 0);
    assert!(gated == before);

    // A report an IEKF filled, reused by the EKF: its iterations are reset.
    let mut report = UpdateReport::zeros(U1);
    iekf.update_into(&Range { r: 0.01 }, &Vector1::new(12.0), &mut report)
        .unwrap();
    assert!(report.iterations.is_some());
    let mut ekf = Ekf::new(prior);
    ekf.update_into(&Range { r: 0.01 }, &Vector1::new(12.0), &mut report)
        .unwrap();
    assert!(report.iterations.is_none());
}

/// Static sizes: an iterated update (several steps, with the safeguard's factorisations and
/// cost evaluations) allocates nothing on the heap.
#[test]
fn static_size_updates_do_not_allocate() {
    let mut iekf = Iekf::new(oblique_prior())
        .with_iterations(20, 1e-10)
        .unwrap();
    let range = Range { r: 0.01 };
    let mut report = UpdateReport::zeros(U1);
    let n = allocations_during(|| {
        iekf.update_into(&range, &Vector1::new(13.0), &mut report)
            .unwrap();
    });
    assert!(report.iterations.unwrap().count > 1);
    assert_eq!(n, 0, "{n} heap allocations");
}
