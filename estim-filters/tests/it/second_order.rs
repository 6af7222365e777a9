//! The second-order EKF against the EKF: identical when every Hessian is zero, different —
//! and better in RMS error — when the curvature of the model matters.

use crate::common;

use common::{gaussian_matrix, normal, random_spd, random_stable, rng, sample};
use estim_core::derivative::{check_measurement_model, check_process_model};
use estim_core::nalgebra::{
    Matrix1, Matrix1x2, Matrix2, Matrix2x1, Matrix2x3, Matrix3, U1, U2, U3, Vector1, Vector2,
    Vector3,
};
use estim_core::{
    Gaussian, LinearMeasurement, LinearProcess, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel,
};
use estim_filters::{Ekf, Estimator, GaussianSecondOrderEkf, Predict, SecondOrderEkf, Update};

// ---------------------------------------------------------------------------------------------
// Zero Hessians.

/// x⁺ = F x + B u + w, written by hand (not with the linear marker) so that it reports its
/// Hessians itself: `Some(0)` for the components listed in `explicit_zero`, `None` otherwise.
struct AffineProcess {
    f: Matrix3<f64>,
    b: Vector3<f64>,
    q: Matrix3<f64>,
    explicit_zero: [bool; 3],
}

impl ProcessModel<f64, U3> for AffineProcess {
    type Input = f64;
    fn transition(&self, x: &Vector3<f64>, u: &f64, _dt: f64) -> Vector3<f64> {
        self.f * x + self.b * *u
    }
    fn process_noise(&self, _: &Vector3<f64>, _: &f64, _: f64) -> Matrix3<f64> {
        self.q
    }
}

impl ProcessJacobian<f64, U3> for AffineProcess {
    fn transition_jacobian(&self, _: &Vector3<f64>, _: &f64, _: f64) -> Matrix3<f64> {
        self.f
    }
}

impl ProcessHessian<f64, U3> for AffineProcess {
    fn transition_hessian(
        &self,
        _: &Vector3<f64>,
        _: &f64,
        _: f64,
        k: usize,
    ) -> Option<Matrix3<f64>> {
        self.explicit_zero[k].then(Matrix3::zeros)
    }
}

/// z = H x + v with Hessians reported as for [`AffineProcess`].
struct AffineMeasurement {
    h: Matrix2x3<f64>,
    r: Matrix2<f64>,
    explicit_zero: [bool; 2],
}

impl MeasurementModel<f64, U3, U2> for AffineMeasurement {
    fn measure(&self, x: &Vector3<f64>) -> Vector2<f64> {
        self.h * x
    }
    fn measurement_noise(&self, _: &Vector3<f64>) -> Matrix2<f64> {
        self.r
    }
}

impl MeasurementJacobian<f64, U3, U2> for AffineMeasurement {
    fn measurement_jacobian(&self, _: &Vector3<f64>) -> Matrix2x3<f64> {
        self.h
    }
}

impl MeasurementHessian<f64, U3, U2> for AffineMeasurement {
    fn measurement_hessian(&self, _: &Vector3<f64>, k: usize) -> Option<Matrix3<f64>> {
        self.explicit_zero[k].then(Matrix3::zeros)
    }
}

/// With every Hessian zero — declared `Some(0)`, `None`, or a mix — the second-order
/// corrections ½⟨Hₖ, P⟩ and ½ tr(Hₖ P Hₗ P) are exactly 0.0, so SecondOrderEkf and
/// GaussianSecondOrderEkf reproduce the Ekf bit for bit (no tolerance needed: adding ±0.0
/// changes nothing).
#[test]
fn second_order_ekf_equals_ekf_bitwise_when_every_hessian_is_zero() {
    let patterns: [([bool; 3], [bool; 2]); 4] = [
        ([true, true, true], [true, true]),
        ([false, false, false], [false, false]),
        ([true, false, true], [false, true]),
        ([false, true, false], [true, false]),
    ];
    for (case, (pz, mz)) in patterns.into_iter().enumerate() {
        let mut r = rng(100 + case as u64);
        let process = AffineProcess {
            f: random_stable(&mut r, U3, 0.9),
            b: gaussian_matrix(&mut r, U3, U1),
            q: random_spd(&mut r, U3, 0.1, 0.01),
            explicit_zero: pz,
        };
        let measurement = AffineMeasurement {
            h: gaussian_matrix(&mut r, U2, U3),
            r: random_spd(&mut r, U2, 0.2, 0.05),
            explicit_zero: mz,
        };
        let x0 = Vector3::new(1.0, -2.0, 0.5);
        assert!(
            check_process_model(&process, &x0, &0.3, 1.0)
                .unwrap()
                .is_accurate(1e-7)
        );
        assert!(
            check_measurement_model(&measurement, &x0)
                .unwrap()
                .is_accurate(1e-7)
        );

        let prior = Gaussian::new(x0, random_spd(&mut r, U3, 1.0, 0.1)).unwrap();
        let mut ekf = Ekf::new(prior.clone());
        let mut soekf = SecondOrderEkf::new(prior.clone());
        let mut gsoekf = GaussianSecondOrderEkf::new(prior);
        for k in 0..50 {
            let u = normal(&mut r);
            let z = gaussian_matrix(&mut r, U2, U1) * 2.0;
            ekf.predict(&process, &u, 1.0).unwrap();
            soekf.predict(&process, &u, 1.0).unwrap();
            gsoekf.predict(&process, &u, 1.0).unwrap();
            let re = ekf.update(&measurement, &z).unwrap();
            let rs = soekf.update(&measurement, &z).unwrap();
            let rg = gsoekf.update(&measurement, &z).unwrap();
            let what = |f: &str| format!("case {case} step {k}: {f}");
            for (name, xs, ps) in [
                ("SOEKF", soekf.state(), soekf.covariance()),
                ("GSOEKF", gsoekf.state(), gsoekf.covariance()),
            ] {
                common::assert_bitwise_eq(ekf.state(), xs, &what(&format!("{name} state")));
                common::assert_bitwise_eq(ekf.covariance(), ps, &what(&format!("{name} P")));
            }
            assert_eq!(re, rs, "{}", what("SOEKF report"));
            assert_eq!(re, rg, "{}", what("GSOEKF report"));
        }
    }
}

/// The library's own linear models declare their Hessians `None`: same bitwise equality.
#[test]
fn second_order_ekf_equals_ekf_bitwise_on_linear_process_and_measurement() {
    let mut r = rng(3);
    let process = LinearProcess {
        transition: random_stable(&mut r, U3, 0.8),
        input: gaussian_matrix(&mut r, U3, U1),
        noise: random_spd(&mut r, U3, 0.1, 0.01),
    };
    let measurement = LinearMeasurement {
        observation: gaussian_matrix(&mut r, U2, U3),
        noise: random_spd(&mut r, U2, 0.2, 0.05),
    };
    let prior = Gaussian::new(Vector3::new(0.3, 0.1, -1.0), Matrix3::identity()).unwrap();
    let mut ekf = Ekf::new(prior.clone());
    let mut soekf = SecondOrderEkf::new(prior);
    for _ in 0..50 {
        let u = gaussian_matrix(&mut r, U1, U1);
        let z = gaussian_matrix(&mut r, U2, U1);
        ekf.predict(&process, &u, 1.0).unwrap();
        soekf.predict(&process, &u, 1.0).unwrap();
        assert_eq!(
            ekf.update(&measurement, &z).unwrap(),
            soekf.update(&measurement, &z).unwrap()
        );
        common::assert_bitwise_eq(ekf.state(), soekf.state(), "state");
        common::assert_bitwise_eq(ekf.covariance(), soekf.covariance(), "covariance");
    }
}

// ---------------------------------------------------------------------------------------------
// Curvature.

/// The range ‖p‖ from the origin to a 2-D position p: Hessian (I − p̂ p̂ᵀ)/‖p‖.
struct Range {
    sigma: f64,
}

impl MeasurementModel<f64, U2, U1> for Range {
    fn measure(&self, x: &Vector2<f64>) -> Vector1<f64> {
        Vector1::new(x.norm())
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> {
        Matrix1::new(self.sigma * self.sigma)
    }
}

impl MeasurementJacobian<f64, U2, U1> for Range {
    fn measurement_jacobian(&self, x: &Vector2<f64>) -> Matrix1x2<f64> {
        let r = x.norm();
        Matrix1x2::new(x[0] / r, x[1] / r)
    }
}

impl MeasurementHessian<f64, U2, U1> for Range {
    fn measurement_hessian(&self, x: &Vector2<f64>, _: usize) -> Option<Matrix2<f64>> {
        let r = x.norm();
        Some(Matrix2::identity() / r - x * x.transpose() / (r * r * r))
    }
}

/// Range-only tracking of a nearly static target 10 units down the x axis whose cross-range
/// position y is uncertain (σ_y = 2) and unobservable from range: r ≈ x + y²/(2x).
///
/// The EKF predicts the range as ‖x̂‖ = x̂ (ŷ = 0), ignoring the curvature term E[y²]/(2x)
/// = σ_y²/20 = 0.2, so averaging 100 noisy ranges drives x̂ to x + y²/20: biased by +0.2 on
/// average. The second-order EKF predicts ‖x̂‖ + ½⟨H, P⟩ = x̂ + P_yy/(2x̂), removing the bias;
/// what remains is the irreducible (y² − σ_y²)/20. In theory the range-direction RMS error
/// (after the noise has averaged out) is √3 σ_y²/20 ≈ 0.35 for the EKF and √2 σ_y²/20 ≈ 0.28
/// for the SOEKF. The ranging noise σ = 0.5 is large against the variance term the truncated
/// filter omits (½ (P_yy/x)² ≈ 0.08 vs R = 0.25), so the truncated filter stays consistent
/// enough for its mean correction to pay off.
#[test]
fn second_order_ekf_beats_ekf_in_rms_when_curvature_matters() {
    const RUNS: usize = 300;
    const STEPS: usize = 100;
    let prior = Gaussian::new(Vector2::new(10.0, 0.0), Matrix2::new(1.0, 0.0, 0.0, 4.0)).unwrap();
    let process = LinearProcess {
        transition: Matrix2::identity(),
        input: Matrix2x1::zeros(),
        noise: Matrix2::identity() * 1e-4,
    };
    let range = Range { sigma: 0.5 };
    assert!(
        check_measurement_model(&range, &Vector2::new(10.0, 1.0))
            .unwrap()
            .is_accurate(1e-7)
    );

    let mut r = rng(2024);
    let (mut sq_ekf, mut sq_so) = ([0.0; 2], [0.0; 2]);
    let (mut bias_ekf, mut bias_so) = (0.0, 0.0);
    let mut max_final_gap: f64 = 0.0;
    let u = Vector1::new(0.0);
    for _ in 0..RUNS {
        let mut x = sample(&mut r, prior.mean(), prior.covariance());
        let mut ekf = Ekf::new(prior.clone());
        let mut so = SecondOrderEkf::new(prior.clone());
        for _ in 0..STEPS {
            x += sample(&mut r, &Vector2::zeros(), &process.noise);
            let z = Vector1::new(x.norm() + range.sigma * normal(&mut r));
            ekf.predict(&process, &u, 1.0).unwrap();
            so.predict(&process, &u, 1.0).unwrap();
            ekf.update(&range, &z).unwrap();
            so.update(&range, &z).unwrap();
        }
        // Errors after the last step, when the ranging noise has averaged out.
        let (e_ekf, e_so) = (ekf.state() - x, so.state() - x);
        for i in 0..2 {
            sq_ekf[i] += e_ekf[i] * e_ekf[i];
            sq_so[i] += e_so[i] * e_so[i];
        }
        bias_ekf += e_ekf[0];
        bias_so += e_so[0];
        max_final_gap = max_final_gap.max((ekf.state() - so.state()).amax());
    }
    let n = RUNS as f64;
    let rms = |sq: [f64; 2]| ((sq[0] + sq[1]) / n).sqrt();
    let (rms_ekf, rms_so) = (rms(sq_ekf), rms(sq_so));
    let (rms_x_ekf, rms_x_so) = ((sq_ekf[0] / n).sqrt(), (sq_so[0] / n).sqrt());
    let (bias_ekf, bias_so) = (bias_ekf / n, bias_so / n);
    println!(
        "RMS total: EKF {rms_ekf:.4}, SOEKF {rms_so:.4}; range direction: EKF {rms_x_ekf:.4}, \
         SOEKF {rms_x_so:.4}; bias: EKF {bias_ekf:.4}, SOEKF {bias_so:.4}"
    );

    // They differ: the curvature correction moves the estimate (by ~0.2 in theory).
    assert!(
        max_final_gap > 0.1,
        "SOEKF and EKF barely differ: {max_final_gap}"
    );
    // Bias: the per-run x error has a spread of ≈ 0.3, so the mean of 300 runs has a standard
    // error ≈ 0.3/√300 ≈ 0.017; 0.06 is ≈ 3.5 standard errors around the theoretical values
    // (0.2 for the EKF, 0 for the SOEKF).
    assert!((bias_ekf - 0.2).abs() < 0.06, "EKF bias {bias_ekf}");
    assert!(bias_so.abs() < 0.06, "SOEKF bias {bias_so}");
    // RMS: the theoretical range-direction ratio is √(2/3) ≈ 0.82; require a clear win (10%),
    // and a win in the total RMS too (cross-range errors are the same for both filters, since
    // ŷ stays 0 and its gain is 0 for both).
    assert!(
        rms_x_so < 0.9 * rms_x_ekf,
        "range-direction RMS: SOEKF {rms_x_so} vs EKF {rms_x_ekf}"
    );
    assert!(
        rms_so < rms_ekf,
        "total RMS: SOEKF {rms_so} vs EKF {rms_ekf}"
    );
}

/// The filter hands the Hessians to the propagator in both steps: one predict and one update
/// of the SOEKF on quadratic models give the hand-computed second-order moments.
///
/// Process f(x) = (x₀ + x₁², x₁): mean f(μ) + ½ (0·P, 2 P₁₁)… = (μ₀ + μ₁² + P₁₁, μ₁).
/// Measurement h(x) = x₀ x₁: mean μ₀ μ₁ + P₀₁.
#[test]
fn second_order_ekf_applies_process_and_measurement_hessians() {
    struct Quadratic;
    impl ProcessModel<f64, U2> for Quadratic {
        type Input = ();
        fn transition(&self, x: &Vector2<f64>, _: &(), _: f64) -> Vector2<f64> {
            Vector2::new(x[0] + x[1] * x[1], x[1])
        }
        fn process_noise(&self, _: &Vector2<f64>, _: &(), _: f64) -> Matrix2<f64> {
            Matrix2::identity() * 0.01
        }
    }
    impl ProcessJacobian<f64, U2> for Quadratic {
        fn transition_jacobian(&self, x: &Vector2<f64>, _: &(), _: f64) -> Matrix2<f64> {
            Matrix2::new(1.0, 2.0 * x[1], 0.0, 1.0)
        }
    }
    impl ProcessHessian<f64, U2> for Quadratic {
        fn transition_hessian(
            &self,
            _: &Vector2<f64>,
            _: &(),
            _: f64,
            k: usize,
        ) -> Option<Matrix2<f64>> {
            (k == 0).then(|| Matrix2::new(0.0, 0.0, 0.0, 2.0))
        }
    }
    struct Product;
    impl MeasurementModel<f64, U2, U1> for Product {
        fn measure(&self, x: &Vector2<f64>) -> Vector1<f64> {
            Vector1::new(x[0] * x[1])
        }
        fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> {
            Matrix1::new(0.1)
        }
    }
    impl MeasurementJacobian<f64, U2, U1> for Product {
        fn measurement_jacobian(&self, x: &Vector2<f64>) -> Matrix1x2<f64> {
            Matrix1x2::new(x[1], x[0])
        }
    }
    impl MeasurementHessian<f64, U2, U1> for Product {
        fn measurement_hessian(&self, _: &Vector2<f64>, _: usize) -> Option<Matrix2<f64>> {
            Some(Matrix2::new(0.0, 1.0, 1.0, 0.0))
        }
    }
    let mu = Vector2::new(1.0, 2.0);
    let p = Matrix2::new(0.5, 0.2, 0.2, 0.3);
    assert!(
        check_process_model(&Quadratic, &mu, &(), 1.0)
            .unwrap()
            .is_accurate(1e-7)
    );
    assert!(
        check_measurement_model(&Product, &mu)
            .unwrap()
            .is_accurate(1e-7)
    );

    let prior = Gaussian::new(mu, p).unwrap();
    let mut so = SecondOrderEkf::new(prior.clone());
    let mut ekf = Ekf::new(prior);
    so.predict(&Quadratic, &(), 1.0).unwrap();
    ekf.predict(&Quadratic, &(), 1.0).unwrap();
    // Covariance is first order in both: F P Fᵀ + Q.
    let f = Matrix2::new(1.0, 4.0, 0.0, 1.0);
    let p_pred = f * p * f.transpose() + Matrix2::identity() * 0.01;
    // Exact small-integer arithmetic up to a few roundings of O(1) numbers: 1e-14 relative.
    let tol = 1e-14;
    assert!((so.covariance() - p_pred).amax() <= tol * p_pred.amax());
    assert!((ekf.covariance() - p_pred).amax() <= tol * p_pred.amax());
    let x_ekf = Vector2::new(1.0 + 4.0, 2.0);
    let x_so = Vector2::new(1.0 + 4.0 + 0.3, 2.0);
    assert!((ekf.state() - x_ekf).amax() <= tol * 5.0, "{}", ekf.state());
    assert!((so.state() - x_so).amax() <= tol * 5.0, "{}", so.state());

    // Update: the innovation is z minus the predicted measurement, which for the SOEKF
    // includes ½⟨[[0,1],[1,0]], P⁻⟩ = P⁻₀₁.
    let z = Vector1::new(12.0);
    let report_so = so.update(&Product, &z).unwrap();
    let report_ekf = ekf.update(&Product, &z).unwrap();
    let nu_ekf = 12.0 - x_ekf[0] * x_ekf[1];
    let nu_so = 12.0 - (x_so[0] * x_so[1] + p_pred[(0, 1)]);
    assert!((report_ekf.innovation[0] - nu_ekf).abs() <= tol * 12.0);
    assert!((report_so.innovation[0] - nu_so).abs() <= tol * 12.0);
}
