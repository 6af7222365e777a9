//! The note's closed forms (eq 2–7, the mirror ŷ, the covariance, the dropped-axis cases)
//! against two independent routes: a weighted least squares by QR of the whitened system (no
//! normal equations; `lv2_support`), and the framework's Kalman filter (exact prior from two
//! axes, update with the third), plus the library's own WLS; and the covariances by the
//! framework's generic moment propagators applied to eq 6 and eq 7 as functions of the readings.
//! The worked example is tested with the `lv2_fusion` example (`tests/it/lv2_fusion_example.rs`
//! of the estim package).

use core::f64::consts::SQRT_2;

use estim_core::derivative::check_jacobian;
use estim_core::nalgebra::{
    DMatrix, DVector, Matrix2, Matrix2x3, Matrix3, U1, U2, U3, Vector1, Vector2, Vector3,
};
use estim_core::propagate::{Linearized, MomentPropagator, Moments, Unscented};
use estim_core::{Differentiable, Gaussian, VectorFunction};
use estim_filters::{Estimator, FadingMemoryRls, KalmanFilter, Update};
use estim_models::lv2::xyq::{
    self, Eq6Coefficients, XyqAxes, XyqReading, XyqSigmas, combine_independent, eq5_x_hat,
    eq5_y_hat, parity_chi2, parity_residual, x_hat_2, y_hat_2,
};
use estim_models::lv2::{AxisStatus, XyqModel};
use proptest::prelude::*;

use crate::lv2_support;

/// WLS from scratch (QR of the whitened system, see `lv2_support`).
fn naive_wls(h: &DMatrix<f64>, sigmas: &[f64], z: &[f64]) -> (DVector<f64>, DMatrix<f64>, f64) {
    lv2_support::qr_wls(h, sigmas, z)
}

fn xyq_h() -> DMatrix<f64> {
    DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 1.0 / SQRT_2, 1.0 / SQRT_2])
}

/// Round-off bound for comparing two solutions of the same WLS problem: the normal equations
/// lose up to κ = (σmax/σmin)² (condition of the information matrix) times ε; 64 covers the
/// few operations on each side.
fn tol(s: &XyqSigmas) -> f64 {
    let (lo, hi) = (s.x.min(s.y).min(s.q), s.x.max(s.y).max(s.q));
    64.0 * (hi / lo).powi(2) * f64::EPSILON
}

fn sigmas() -> impl Strategy<Value = XyqSigmas> {
    (1e-3..1.0f64, 1e-3..1.0f64, 1e-3..1.0f64).prop_map(|(x, y, q)| XyqSigmas { x, y, q })
}

fn reading() -> impl Strategy<Value = XyqReading> {
    (-20.0..20.0f64, -20.0..20.0f64, -20.0..20.0f64).prop_map(|(x, y, q)| XyqReading { x, y, q })
}

fn scale(r: &XyqReading) -> f64 {
    r.x.abs().max(r.y.abs()).max(r.q.abs()).max(1.0)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    /// Eq 5 (as printed), eq 6 (precomputed), eq 3 (two independent estimates) and their
    /// mirrors for ŷ equal the joint WLS estimate, computed naively and by the library.
    #[test]
    fn eq5_and_eq6_equal_weighted_least_squares(r in reading(), s in sigmas()) {
        let (est, _, _) = naive_wls(&xyq_h(), &[s.x, s.y, s.q], &[r.x, r.y, r.q]);
        let lib = XyqModel::xyq(&s).unwrap().fuse(&r.to_vector()).unwrap();
        let c = Eq6Coefficients::new(&s);
        let eq3 = combine_independent(r.x, s.x * s.x, x_hat_2(&r), s.var_x2()).0;
        let eq3_y = combine_independent(r.y, s.y * s.y, y_hat_2(&r), s.var_y2()).0;
        let bound = tol(&s) * scale(&r);
        for (name, x, y) in [
            ("eq 5", eq5_x_hat(&r, &s), eq5_y_hat(&r, &s)),
            ("eq 6", c.x_hat(&r), c.y_hat(&r)),
            ("eq 3", eq3, eq3_y),
            ("library WLS", lib.estimate[0], lib.estimate[1]),
        ] {
            prop_assert!((x - est[0]).abs() <= bound, "{name} x̂ {x} vs WLS {}", est[0]);
            prop_assert!((y - est[1]).abs() <= bound, "{name} ŷ {y} vs WLS {}", est[1]);
        }
        // Eq 6's weights are a convex combination (f₁ + f₂ = 1: unbiased).
        prop_assert!((c.f1 + c.f2 - 1.0).abs() <= 4.0 * f64::EPSILON);
        prop_assert!((c.g1 + c.g2 - 1.0).abs() <= 4.0 * f64::EPSILON);
    }

    /// The full covariance (with the x̂–ŷ term the note omits) and the χ² equal WLS's
    /// (HᵀR⁻¹H)⁻¹ and rᵀR⁻¹r, and the framework route (exact prior from x, y; Kalman update
    /// with q) gives the same estimate, covariance and χ² (as the NIS).
    #[test]
    fn closed_form_covariance_equals_wls_and_filter(r in reading(), s in sigmas()) {
        let (est, p, chi2) = naive_wls(&xyq_h(), &[s.x, s.y, s.q], &[r.x, r.y, r.q]);
        let closed = xyq::fuse(&r, &s, XyqAxes::ALL).unwrap();
        let model = XyqModel::xyq(&s).unwrap();
        let status = [AxisStatus::Used; 3];
        let lib = model.fuse_screened(&r.to_vector(), &status).unwrap();
        let filt = model.fuse_with_filter(&r.to_vector(), &status).unwrap();
        prop_assert_eq!(&filt.initial_axes, &vec![0, 1]);
        prop_assert_eq!(&filt.update_axes, &vec![2]);
        let pmax = p.amax();
        let bound = tol(&s);
        for (name, cov) in [("closed", closed.covariance), ("library", lib.covariance), ("filter", filt.covariance)] {
            for i in 0..2 {
                for j in 0..2 {
                    prop_assert!((cov[(i, j)] - p[(i, j)]).abs() <= bound * pmax,
                        "{name} P[{i},{j}] {} vs {}", cov[(i, j)], p[(i, j)]);
                }
            }
        }
        let xs = scale(&r);
        prop_assert!((filt.estimate - Vector2::new(est[0], est[1])).amax() <= bound * xs);
        // χ²: the eq 7 form (x̃ − (√2 q̃ − ỹ))²/(σx² + 2σq² + σy²) written out here, the
        // library's parity χ², WLS rᵀR⁻¹r (naive, library) and the filter's NIS. The χ² is a
        // difference of nearly equal readings divided by s₁: compare relative to (scale)²/s₁.
        let eq7 = (r.x - (SQRT_2 * r.q - r.y)).powi(2) / (s.x * s.x + 2.0 * s.q * s.q + s.y * s.y);
        let chi_scale = xs * xs / s.s1();
        for (name, v) in [("parity", parity_chi2(&r, &s)), ("closed", closed.chi2),
                          ("library", lib.chi2), ("filter NIS", filt.chi2), ("naive", chi2)] {
            prop_assert!((v - eq7).abs() <= bound * chi_scale, "{name} χ² {v} vs eq 7 {eq7}");
        }
        prop_assert_eq!(lib.dof, 1);
        prop_assert_eq!(filt.dof, 1);
    }

    /// One axis lost: the closed forms of `xyq::fuse` equal WLS on the two remaining rows
    /// (naive), the library WLS with the axis marked missing, and the filter route.
    #[test]
    fn dropped_axis_closed_forms_equal_wls(r in reading(), s in sigmas(), lost in 0usize..3) {
        let used = XyqAxes { x: lost != 0, y: lost != 1, q: lost != 2 };
        let closed = xyq::fuse(&r, &s, used).unwrap();
        let rows: Vec<usize> = (0..3).filter(|&i| i != lost).collect();
        let h = xyq_h().select_rows(&rows);
        let sig = [s.x, s.y, s.q];
        let z = [r.x, r.y, r.q];
        let (est, p, _) = naive_wls(&h, &[sig[rows[0]], sig[rows[1]]], &[z[rows[0]], z[rows[1]]]);
        let mut status = [AxisStatus::Used; 3];
        status[lost] = AxisStatus::Missing;
        let model = XyqModel::xyq(&s).unwrap();
        let lib = model.fuse_screened(&r.to_vector(), &status).unwrap();
        let filt = model.fuse_with_filter(&r.to_vector(), &status).unwrap();
        let bound = tol(&s);
        let pmax = p.amax();
        for (name, e, cov) in [("closed", closed.estimate, closed.covariance),
                               ("library", lib.estimate, lib.covariance),
                               ("filter", filt.estimate, filt.covariance)] {
            prop_assert!((e - Vector2::new(est[0], est[1])).amax() <= bound * scale(&r), "{name}");
            prop_assert!((cov - Matrix2::new(p[(0, 0)], p[(0, 1)], p[(1, 0)], p[(1, 1)])).amax() <= bound * pmax, "{name}");
        }
        prop_assert_eq!(closed.dof, 0);
        prop_assert_eq!(lib.dof, 0);
        prop_assert_eq!(closed.chi2, 0.0);
        // No redundancy left: the residual vanishes (to round-off of the readings).
        prop_assert!(lib.chi2 <= 1e-18 * scale(&r).powi(2) / s.x.min(s.y).min(s.q).powi(2) + 1e-20);
        // Dropping an axis can only lose precision.
        let full = xyq::covariance(&s);
        prop_assert!(closed.covariance[(0, 0)] >= full[(0, 0)] * (1.0 - 1e-12));
        prop_assert!(closed.covariance[(1, 1)] >= full[(1, 1)] * (1.0 - 1e-12));
    }

    /// Eq 7's x-check x̃ − x̂₂ and the y-check ỹ − ŷ₂ are one and the same residual.
    #[test]
    fn x_and_y_parity_checks_are_one_residual(r in reading()) {
        let x_check = r.x - x_hat_2(&r);
        let y_check = r.y - y_hat_2(&r);
        let p = parity_residual(&r);
        prop_assert!((x_check - y_check).abs() <= 8.0 * f64::EPSILON * scale(&r));
        prop_assert!((x_check - p).abs() <= 8.0 * f64::EPSILON * scale(&r));
    }

    /// Every linear unbiased estimator aᵀz of x has aᵀH = (1, 0): a = (1, 0, 0) − t n with
    /// n = (1, 1, −√2), i.e. (1 − t) x̂₁ + t x̂₂. Its variance aᵀRa is smallest at eq 3's t,
    /// where it equals P₁₁ of the WLS: eq 3 is the BLUE.
    #[test]
    fn eq3_is_the_best_of_the_unbiased_family(s in sigmas(), t in -3.0..3.0f64, r in reading()) {
        let n = Vector3::new(1.0, 1.0, -SQRT_2);
        let a = Vector3::new(1.0, 0.0, 0.0) - n * t;
        let h = estim_core::nalgebra::Matrix3x2::new(1.0, 0.0, 0.0, 1.0, 1.0 / SQRT_2, 1.0 / SQRT_2);
        let at_h = a.transpose() * h;
        prop_assert!((at_h[0] - 1.0).abs() < 1e-12 && at_h[1].abs() < 1e-12);
        // It is (1 − t) x̂₁ + t x̂₂.
        let est = a.dot(&r.to_vector());
        prop_assert!((est - ((1.0 - t) * r.x + t * x_hat_2(&r))).abs() <= 1e-13 * scale(&r) * (1.0 + t.abs()));
        let rm = estim_core::nalgebra::Matrix3::from_diagonal(&Vector3::new(s.x * s.x, s.y * s.y, s.q * s.q));
        let var = (a.transpose() * rm * a)[(0, 0)];
        let p11 = xyq::covariance(&s)[(0, 0)];
        prop_assert!(var >= p11 * (1.0 - 1e-12));
        let t_star = s.x * s.x / (s.x * s.x + s.var_x2());
        let a_star = Vector3::new(1.0, 0.0, 0.0) - n * t_star;
        let var_star = (a_star.transpose() * rm * a_star)[(0, 0)];
        prop_assert!((var_star - p11).abs() <= 1e-12 * p11);
        prop_assert!((combine_independent(0.0, s.x * s.x, 0.0, s.var_x2()).1 - p11).abs() <= 1e-12 * p11);
    }
}

/// The Kalman filter from the exact two-axis prior, the fading-memory RLS with γ = 1 from
/// the same prior, and one batch update with the remaining axes all reproduce WLS.
#[test]
fn rls_gamma_one_from_exact_prior_equals_wls() {
    let s = XyqSigmas {
        x: 0.010,
        y: 0.012,
        q: 0.008,
    };
    let r = XyqReading {
        x: 1.0,
        y: 0.5,
        q: 1.07,
    };
    let model = XyqModel::xyq(&s).unwrap();
    let z = r.to_vector();
    let wls = model.fuse(&z).unwrap();
    let prior = model.exact_prior(&z, &[0, 1]).unwrap();
    let q_axis = model.axis(2).unwrap();
    let mut rls = FadingMemoryRls::new(prior.clone(), 1.0).unwrap();
    let rep = rls.update(&q_axis, &Vector1::new(r.q)).unwrap();
    let rest = model.select(&[2]).unwrap();
    let mut kf = KalmanFilter::new(prior);
    kf.update(&rest, &DVector::from_element(1, r.q)).unwrap();
    for (est, cov) in [
        (rls.state(), rls.covariance()),
        (kf.state(), kf.covariance()),
    ] {
        assert!((est - wls.estimate).amax() < 1e-14);
        assert!((cov - wls.covariance).amax() < 1e-18); // P ~ 1e-4: relative 1e-14
    }
    assert!((rep.nis - wls.chi2).abs() < 1e-13);
}

/// A diffuse prior N(0, κ I) updated with all three axes only approximates WLS: the estimate
/// error shrinks like 1/κ (the prior's information 1/κ against the axes' ≈ 10⁴), so it is
/// never exact. This is why the library starts from the exact two-axis solution instead.
#[test]
fn diffuse_prior_only_approximates_wls() {
    let s = XyqSigmas {
        x: 0.010,
        y: 0.012,
        q: 0.008,
    };
    let r = XyqReading {
        x: 1.0,
        y: 0.5,
        q: 1.07,
    };
    let model = XyqModel::xyq(&s).unwrap();
    let wls = model.fuse(&r.to_vector()).unwrap();
    let gap = |kappa: f64| {
        let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity() * kappa).unwrap();
        let mut kf = KalmanFilter::new(prior);
        kf.update(&model, &r.to_vector()).unwrap();
        (kf.state() - wls.estimate).amax()
    };
    let (g2, g4) = (gap(1e2), gap(1e4));
    // Leading order: θ̂_κ − θ̂ ≈ −P θ̂/κ, |P θ̂| ≈ 1e-4: gap(1e2) ≈ 1e-6, gap(1e4) ≈ 1e-8.
    assert!(g2 > 1e-7 && g2 < 1e-5, "{g2}");
    assert!((g2 / g4 - 100.0).abs() < 5.0, "gap ratio {}", g2 / g4);
}

/// Eq 6 (and its mirror) as a function z = (x̃, ỹ, q̃) ↦ (x̂, ŷ), to push the reading
/// distribution through the framework's generic moment propagators.
struct Eq6Map(Eq6Coefficients);

impl VectorFunction<f64, U3, U2> for Eq6Map {
    fn eval(&self, z: &Vector3<f64>) -> Vector2<f64> {
        let r = XyqReading {
            x: z[0],
            y: z[1],
            q: z[2],
        };
        Vector2::new(self.0.x_hat(&r), self.0.y_hat(&r))
    }
}

impl Differentiable<f64, U3, U2> for Eq6Map {
    fn jacobian(&self, _: &Vector3<f64>) -> Matrix2x3<f64> {
        let c = &self.0;
        Matrix2x3::new(c.f1, -c.f2, SQRT_2 * c.f2, -c.g2, c.g1, SQRT_2 * c.g2)
    }
}

/// The parity z ↦ x̃ + ỹ − √2 q̃ (eq 7).
struct ParityMap;

impl VectorFunction<f64, U3, U1> for ParityMap {
    fn eval(&self, z: &Vector3<f64>) -> Vector1<f64> {
        Vector1::new(parity_residual(&XyqReading {
            x: z[0],
            y: z[1],
            q: z[2],
        }))
    }
}

proptest! {
    /// The covariance of (x̂, ŷ) and the variance s₁ of the parity, by propagating the
    /// readings' distribution N(H θ, R) through eq 6 and eq 7 with the generic cubature
    /// (unscented) propagator (function values only, so independent of any derivative written
    /// here) and
    /// the linearised one (with the Jacobian above, itself checked by finite differences).
    /// Also: the estimate is unbiased (mean of x̂, ŷ = θ) and uncorrelated with the parity
    /// (the WLS residual is orthogonal to the estimate).
    #[test]
    fn covariance_by_moment_propagation(s in sigmas(), x in -5.0..5.0f64, y in -5.0..5.0f64) {
        let map = Eq6Map(Eq6Coefficients::new(&s));
        let mean = XyqReading::noise_free(x, y).to_vector();
        let r = Matrix3::from_diagonal(&Vector3::new(s.x * s.x, s.y * s.y, s.q * s.q));
        let jac = check_jacobian(&map, &mean).unwrap();
        prop_assert!(jac.is_accurate(1e-8), "{jac}");
        let p = xyq::covariance(&s);
        let ut: Moments<f64, U3, U2> = Unscented::cubature().propagate(&mean, &r, &map).unwrap();
        let lin: Moments<f64, U3, U2> = Linearized.propagate(&mean, &r, &map).unwrap();
        // Cubature points (equal positive weights) at ±√3 σ around readings up to ≈ 7: the
        // deviations g(z ± √3σ eᵢ) − ḡ lose ≈ ε |z|/σ ≤ 2e-12 relative; 1e-10 covers it.
        for (name, m, tol) in [("cubature", &ut, 1e-10), ("linearized", &lin, 1e-12)] {
            prop_assert!((m.covariance - p).amax() <= tol * p.amax(), "{name}: {} vs {p}", m.covariance);
            prop_assert!((m.mean - Vector2::new(x, y)).amax() <= 1e-12 * (1.0 + x.abs() + y.abs()), "{name} mean");
        }
        let par: Moments<f64, U3, U1> = Unscented::cubature().propagate(&mean, &r, &ParityMap).unwrap();
        prop_assert!((par.covariance[(0, 0)] - s.s1()).abs() <= 1e-10 * s.s1());
        prop_assert!(par.mean[0].abs() <= 1e-12 * (1.0 + x.abs() + y.abs()));
        // cov(θ̂, r) = J R nᵀ = 0: the estimate carries no information about the parity.
        let n = Vector3::new(1.0, 1.0, -SQRT_2);
        let cross = map.jacobian(&mean) * r * n;
        prop_assert!(cross.amax() <= 1e-12 * s.s1());
    }
}
