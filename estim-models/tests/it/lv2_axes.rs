//! The general redundant-axes model: derivative check, WLS against an independent WLS and
//! against the framework's filters for random axis sets (planar and spatial, static and
//! runtime sizes), the parity-space form of the χ², screening of missing/saturated axes, and
//! the typed errors.

use core::f64::consts::{FRAC_1_SQRT_2, PI, SQRT_2};

use estim_core::derivative::check_measurement_model;
use estim_core::nalgebra::{
    DMatrix, DVector, Dim, Dyn, OMatrix, OVector, SMatrix, SVector, SymmetricEigen, U2, U3,
    Vector1, Vector2, Vector3,
};
use estim_core::{Error, MeasurementHessian};
use estim_filters::{Estimator, FadingMemoryRls, KalmanFilter, Update};
use estim_models::lv2::xyq::{self, XyqAxes, XyqReading, XyqSigmas};
use estim_models::lv2::{
    AxisStatus, FusionError, PlanarAxes, RedundantAxes, SpatialAxes, XyqModel, screen,
};
use proptest::prelude::*;

use crate::lv2_support;

/// The independent QR-based WLS on the rows `used`.
fn naive_wls<N: Dim, M: Dim>(
    axes: &RedundantAxes<f64, N, M>,
    z: &OVector<f64, M>,
    used: &[usize],
) -> (DVector<f64>, DMatrix<f64>, f64)
where
    estim_core::nalgebra::DefaultAllocator: estim_core::Alloc<N, M>,
{
    let h = DMatrix::from_fn(used.len(), axes.state_dim(), |r, c| {
        axes.directions()[(used[r], c)]
    });
    let sig: Vec<f64> = used.iter().map(|&i| axes.sigmas()[i]).collect();
    let zu: Vec<f64> = used.iter().map(|&i| z[i]).collect();
    lv2_support::qr_wls(&h, &sig, &zu)
}

/// Unit direction in space from two angles.
fn spatial_dir(az: f64, el: f64) -> Vector3<f64> {
    Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
}

/// Minimum angular separation between planar axes (mod π): keeps the random sets
/// well-conditioned enough that the round-off bound below is meaningful (2° ⇒ the information
/// matrix's condition stays below ≈ 10⁴ · σ ratio²).
fn spread_ok(angles: &[f64]) -> bool {
    let mut a: Vec<f64> = angles.iter().map(|t| t.rem_euclid(PI)).collect();
    a.sort_by(f64::total_cmp);
    a.windows(2).any(|w| w[1] - w[0] > 2f64.to_radians())
        && (a[a.len() - 1] - a[0]) > 2f64.to_radians()
}

/// Round-off bound for two solutions of one WLS problem with information-matrix condition
/// `cond`: 256 cond ε (normal equations on both sides, a few dozen operations).
fn bound(cond: f64) -> f64 {
    256.0 * cond * f64::EPSILON
}

fn condition(p: &DMatrix<f64>) -> f64 {
    let e = SymmetricEigen::new(p.clone()).eigenvalues;
    e.max() / e.min()
}

/// Compares the library WLS, the naive WLS, the Kalman route and the RLS(γ = 1) route.
fn check_routes<N: Dim, M: Dim>(
    axes: &RedundantAxes<f64, N, M>,
    z: &OVector<f64, M>,
) -> Result<(), TestCaseError>
where
    estim_core::nalgebra::DefaultAllocator:
        estim_core::Alloc<N, M> + estim_core::Alloc<N, estim_core::nalgebra::U1>,
{
    let m = axes.len();
    let used: Vec<usize> = (0..m).collect();
    let (est, p, chi2) = naive_wls(axes, z, &used);
    let tol = bound(condition(&p));
    let zs = z.amax().max(1.0);
    let pmax = p.amax();
    let status = vec![AxisStatus::Used; m];
    let lib = axes.fuse_screened(z, &status).unwrap();
    let filt = axes.fuse_with_filter(z, &status).unwrap();
    prop_assert_eq!(lib.dof, m - axes.state_dim());
    prop_assert_eq!(filt.dof, m - axes.state_dim());
    // RLS with γ = 1 from the same exact prior, one axis at a time.
    let prior = axes.exact_prior(z, &filt.initial_axes).unwrap();
    let mut rls = FadingMemoryRls::new(prior, 1.0).unwrap();
    let mut rls_chi2 = 0.0;
    for &i in &filt.update_axes {
        rls_chi2 += rls
            .update(&axes.axis(i).unwrap(), &Vector1::new(z[i]))
            .unwrap()
            .nis;
    }
    // The library WLS solves the same normal equations: round-off ≈ cond · ε relative.
    // The filter routes start from the exact N-axis solution (θ₀, P₀) and subtract from it,
    // so their round-off is relative to |P₀| and |θ₀| (which the pivoted choice of the
    // initial axes keeps close to |P| and |θ̂|).
    let p0 = axes.exact_prior(z, &filt.initial_axes).unwrap();
    let cond = condition(&p);
    let est_scale = est.amax().max(p0.mean().amax());
    let cov_scale = pmax.max(p0.covariance().amax());
    let chi2_scale = (zs / axes.sigmas().min()).powi(2) * m as f64;
    let cases = [
        (
            "library",
            lib.estimate.as_slice().to_vec(),
            lib.covariance.as_slice().to_vec(),
            lib.chi2,
        ),
        (
            "kalman",
            filt.estimate.as_slice().to_vec(),
            filt.covariance.as_slice().to_vec(),
            filt.chi2,
        ),
        (
            "rls",
            rls.state().as_slice().to_vec(),
            rls.covariance().as_slice().to_vec(),
            rls_chi2,
        ),
    ];
    for (name, e, c, x2) in cases {
        for (a, b) in e.iter().zip(est.iter()) {
            prop_assert!((a - b).abs() <= tol * est_scale, "{name} θ̂ {a} vs {b}");
        }
        for (a, b) in c.iter().zip(p.iter()) {
            prop_assert!((a - b).abs() <= tol * cov_scale, "{name} P {a} vs {b}");
        }
        // χ² is a sum of squared residuals of size ≤ |z|/σ: compare on that scale.
        prop_assert!(
            (x2 - chi2).abs() <= tol * chi2_scale,
            "{name} χ² {x2} vs {chi2}"
        );
        let _ = cond;
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// The model's Jacobian H and zero Hessians pass the framework's derivative checker
    /// (trivially linear, but the check is what a user would run), planar and spatial.
    #[test]
    fn measurement_model_passes_derivative_check(
        angles in prop::array::uniform4(-PI..PI),
        sig in prop::array::uniform4(0.001..1.0f64),
        x in prop::array::uniform2(-50.0..50.0f64),
        dirs in prop::array::uniform5((-PI..PI, -1.5..1.5f64)),
        x3 in prop::array::uniform3(-50.0..50.0f64),
    ) {
        let planar = PlanarAxes::<4>::planar(&SVector::from(angles), SVector::from(sig)).unwrap();
        let report = check_measurement_model(&planar, &Vector2::from(x)).unwrap();
        // Linear: central differences are exact up to round-off of |x| ≈ 50 over h ≈ 3e-4.
        prop_assert!(report.is_accurate(1e-9), "{report}");
        prop_assert!(planar.measurement_hessian(&Vector2::from(x), 0).is_none());
        let h = SMatrix::<f64, 5, 3>::from_fn(|r, c| spatial_dir(dirs[r].0, dirs[r].1)[c]);
        let spatial = SpatialAxes::<5>::new(h, SVector::repeat(0.01)).unwrap();
        let report = check_measurement_model(&spatial, &Vector3::from(x3)).unwrap();
        prop_assert!(report.is_accurate(1e-9), "{report}");
        let dynamic = spatial.select(&[4, 0, 2, 3]).unwrap();
        let report = check_measurement_model(&dynamic, &Vector3::from(x3)).unwrap();
        prop_assert!(report.is_accurate(1e-9), "{report}");
    }

    /// Random planar sets of 4 axes (static sizes): closed WLS = naive WLS = Kalman route =
    /// RLS(γ = 1) route, estimate, covariance and χ².
    #[test]
    fn random_planar_axis_sets_all_routes_agree(
        angles in prop::array::uniform4(-PI..PI),
        sig in prop::array::uniform4(0.001..1.0f64),
        z in prop::array::uniform4(-20.0..20.0f64),
    ) {
        prop_assume!(spread_ok(&angles));
        let axes = PlanarAxes::<4>::planar(&SVector::from(angles), SVector::from(sig)).unwrap();
        check_routes(&axes, &SVector::from(z))?;
    }

    /// Random spatial sets of 3 to 8 axes (runtime sizes).
    #[test]
    fn random_spatial_axis_sets_all_routes_agree(
        dirs in prop::collection::vec((-PI..PI, -1.4..1.4f64), 3..9),
        sig in prop::collection::vec(0.001..1.0f64, 8),
        z in prop::collection::vec(-20.0..20.0f64, 8),
    ) {
        let m = dirs.len();
        let h = OMatrix::<f64, Dyn, U3>::from_fn(m, |r, c| spatial_dir(dirs[r].0, dirs[r].1)[c]);
        let axes = RedundantAxes::new(h, DVector::from_column_slice(&sig[..m])).unwrap();
        let zv = DVector::from_column_slice(&z[..m]);
        // Skip nearly coplanar random draws (condition of HᵀH > 1e6): they are valid but the
        // comparison bound would be vacuous; the dependent case is tested separately.
        let hh = axes.directions().transpose() * axes.directions();
        let e = SymmetricEigen::new(hh).eigenvalues;
        prop_assume!(e.min() > 1e-6 * e.max());
        check_routes(&axes, &zv)?;
    }

    /// The χ² in parity-space form: with the columns of V spanning the left null space of H
    /// (Vᵀ H = 0), rᵀR⁻¹r = (Vᵀz)ᵀ (Vᵀ R V)⁻¹ (Vᵀz). For x, y, q: V = (1, 1, −√2) and this is
    /// (x̃ + ỹ − √2 q̃)²/s₁, eq 7.
    #[test]
    fn chi2_equals_parity_space_form(
        angles in prop::array::uniform5(-PI..PI),
        sig in prop::array::uniform5(0.01..1.0f64),
        z in prop::array::uniform5(-5.0..5.0f64),
    ) {
        prop_assume!(spread_ok(&angles));
        let axes = PlanarAxes::<5>::planar(&SVector::from(angles), SVector::from(sig)).unwrap();
        let zv = SVector::from(z);
        let lib = axes.fuse(&zv).unwrap();
        let h = DMatrix::from_fn(5, 2, |r, c| axes.directions()[(r, c)]);
        let proj = DMatrix::identity(5, 5) - &h * (h.transpose() * &h).try_inverse().unwrap() * h.transpose();
        let eig = SymmetricEigen::new(proj);
        let cols: Vec<usize> = (0..5).filter(|&i| eig.eigenvalues[i] > 0.5).collect();
        prop_assert_eq!(cols.len(), 3);
        let v = eig.eigenvectors.select_columns(&cols);
        let r = DMatrix::from_diagonal(&DVector::from_fn(5, |i, _| sig[i] * sig[i]));
        let vz = v.transpose() * DVector::from_column_slice(&z);
        let parity = (vz.transpose() * (v.transpose() * r * &v).try_inverse().unwrap() * &vz)[(0, 0)];
        prop_assert!((parity - lib.chi2).abs() <= 1e-8 * (1.0 + lib.chi2), "{parity} vs {}", lib.chi2);
        prop_assert_eq!(lib.dof, 3);
    }
}

/// With fewer than two usable axes (or three in space), or dependent ones, every fusion
/// returns the typed error and nothing panics.
#[test]
fn too_few_or_dependent_axes_are_typed_errors() {
    let s = XyqSigmas {
        x: 0.01,
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
    for keep in 0..3 {
        let mut status = [AxisStatus::Missing; 3];
        status[keep] = AxisStatus::Used;
        let expect = FusionError::TooFewAxes {
            usable: 1,
            required: 2,
        };
        assert_eq!(model.fuse_screened(&z, &status).unwrap_err(), expect);
        assert_eq!(model.fuse_with_filter(&z, &status).unwrap_err(), expect);
        let used = XyqAxes {
            x: keep == 0,
            y: keep == 1,
            q: keep == 2,
        };
        assert_eq!(xyq::fuse(&r, &s, used).unwrap_err(), expect);
    }
    let none = [AxisStatus::Saturated; 3];
    assert_eq!(
        model.fuse_screened(&z, &none).unwrap_err(),
        FusionError::TooFewAxes {
            usable: 0,
            required: 2
        }
    );
    // Two parallel (opposite) planar axes: enough axes, no span.
    let parallel =
        PlanarAxes::<2>::planar(&Vector2::new(0.3, 0.3 + PI), Vector2::new(0.01, 0.02)).unwrap();
    let zp = Vector2::new(1.0, -1.0);
    let expect = FusionError::DependentAxes {
        usable: 2,
        required: 2,
    };
    assert_eq!(parallel.fuse(&zp).unwrap_err(), expect);
    assert_eq!(
        parallel
            .fuse_with_filter(&zp, &[AxisStatus::Used; 2])
            .unwrap_err(),
        expect
    );
    // Four coplanar axes in space.
    let h = SMatrix::<f64, 4, 3>::from_fn(|r, c| spatial_dir(r as f64, 0.0)[c]);
    let coplanar = SpatialAxes::<4>::new(h, SVector::repeat(0.01)).unwrap();
    let zc = SVector::<f64, 4>::new(1.0, 2.0, 3.0, 4.0);
    assert_eq!(
        coplanar.fuse(&zc).unwrap_err(),
        FusionError::DependentAxes {
            usable: 4,
            required: 3
        }
    );
    assert_eq!(
        coplanar
            .fuse_with_filter(&zc, &[AxisStatus::Used; 4])
            .unwrap_err(),
        FusionError::DependentAxes {
            usable: 4,
            required: 3
        }
    );
    // An empty runtime set.
    let empty =
        RedundantAxes::<f64, U2, Dyn>::new(OMatrix::<f64, Dyn, U2>::zeros(0), DVector::zeros(0))
            .unwrap();
    assert!(empty.is_empty());
    assert_eq!(
        empty.fuse(&DVector::zeros(0)).unwrap_err(),
        FusionError::TooFewAxes {
            usable: 0,
            required: 2
        }
    );
    // The filter route skips a dependent axis when choosing its exact prior: x, −x, y.
    let h = SMatrix::<f64, 3, 2>::new(1.0, 0.0, -1.0, 0.0, 0.0, 1.0);
    let xxy = PlanarAxes::<3>::new(h, Vector3::new(0.01, 0.02, 0.01)).unwrap();
    let zz = Vector3::new(1.0, -1.01, 0.5);
    let f = xxy.fuse_with_filter(&zz, &[AxisStatus::Used; 3]).unwrap();
    assert_eq!(
        (f.initial_axes.clone(), f.update_axes.clone()),
        (vec![0, 2], vec![1])
    );
    let w = xxy.fuse(&zz).unwrap();
    assert!((f.estimate - w.estimate).amax() < 1e-14 && (f.chi2 - w.chi2).abs() < 1e-12);
}

/// Invalid construction data is rejected with the framework's typed errors.
#[test]
fn invalid_axes_are_rejected() {
    let h = SMatrix::<f64, 3, 2>::new(1.0, 0.0, 0.0, 1.0, FRAC_1_SQRT_2, FRAC_1_SQRT_2);
    assert!(matches!(
        PlanarAxes::<3>::new(h, Vector3::new(0.01, 0.0, 0.01)),
        Err(FusionError::Core(Error::NotPositiveDefinite { .. }))
    ));
    assert!(matches!(
        PlanarAxes::<3>::new(h, Vector3::new(0.01, f64::NAN, 0.01)),
        Err(FusionError::Core(Error::NonFinite { .. }))
    ));
    let mut bad = h;
    bad[(1, 1)] = f64::INFINITY;
    assert!(matches!(
        PlanarAxes::<3>::new(bad, Vector3::repeat(0.01)),
        Err(FusionError::Core(Error::NonFinite { .. }))
    ));
    assert!(matches!(
        RedundantAxes::<f64, U2, Dyn>::new(
            OMatrix::<f64, Dyn, U2>::zeros(3),
            DVector::repeat(2, 0.01)
        ),
        Err(FusionError::Core(Error::DimensionMismatch { .. }))
    ));
    assert!(matches!(
        XyqSigmas::new(0.01, -1.0, 0.01),
        Err(FusionError::Core(Error::NotPositiveDefinite { .. }))
    ));
    assert!(
        XyqModel::xyq(&XyqSigmas {
            x: 0.0,
            y: 0.01,
            q: 0.01
        })
        .is_err()
    );
}

/// Screening: a saturated or missing axis is dropped and the estimate equals the fusion of
/// the other two (the closed form without that axis); a NaN reading is dropped as
/// non-finite; a reading just below full scale is kept; bad masks and a NaN marked "used"
/// are typed errors.
#[test]
fn saturated_and_missing_axes_are_dropped() {
    let s = XyqSigmas {
        x: 0.01,
        y: 0.012,
        q: 0.008,
    };
    let model = XyqModel::xyq(&s).unwrap();
    let fs = 2.0;
    // True (2.3, 0.4): x beyond full scale, read at the rail.
    let r = XyqReading {
        x: fs,
        y: 0.41,
        q: (2.3 + 0.4) / SQRT_2 - 0.004,
    };
    let z = r.to_vector();
    let status = screen(&z, &[], Some(fs)).unwrap();
    assert_eq!(
        status,
        vec![AxisStatus::Saturated, AxisStatus::Used, AxisStatus::Used]
    );
    let f = model.fuse_screened(&z, &status).unwrap();
    let closed = xyq::fuse(&r, &s, xyq::screen(&r, [false; 3], Some(fs))).unwrap();
    assert_eq!(
        closed.used,
        XyqAxes {
            x: false,
            y: true,
            q: true
        }
    );
    assert!((f.estimate - closed.estimate).amax() < 1e-14);
    assert!((f.estimate[0] - (SQRT_2 * r.q - r.y)).abs() < 1e-14);
    assert!((f.covariance - closed.covariance).amax() < 1e-18);
    assert_eq!(f.residual[0], 0.0);
    // Using the clipped x would bias x̂ by ≈ f₁·(2.0 − 2.3) and fail the χ² test.
    let naive = model.fuse(&z).unwrap();
    assert!(naive.estimate[0] < 2.1 && !naive.is_consistent(1e-3));
    assert!(f.estimate[0] > 2.28 && f.estimate[0] < 2.32);
    // Just below full scale: kept.
    let below = Vector3::new(fs - 1e-9, 0.4, 1.0);
    assert_eq!(screen(&below, &[], Some(fs)).unwrap()[0], AxisStatus::Used);
    assert_eq!(
        screen(&Vector3::new(-fs, 0.4, 1.0), &[], Some(fs)).unwrap()[0],
        AxisStatus::Saturated
    );
    // Missing mask and NaN.
    let zn = Vector3::new(1.0, f64::NAN, 1.07);
    let st = screen(&zn, &[false, false, true], None).unwrap();
    assert_eq!(
        st,
        vec![AxisStatus::Used, AxisStatus::NonFinite, AxisStatus::Missing]
    );
    assert_eq!(
        model.fuse_screened(&zn, &st).unwrap_err(),
        FusionError::TooFewAxes {
            usable: 1,
            required: 2
        }
    );
    let fy = model.fuse(&zn).unwrap(); // NaN y dropped automatically: x and q remain
    assert!((fy.estimate[1] - (SQRT_2 * 1.07 - 1.0)).abs() < 1e-14);
    assert!(matches!(
        screen(&z, &[true], None),
        Err(FusionError::Core(Error::DimensionMismatch { .. }))
    ));
    assert!(matches!(
        model.fuse_screened(&zn, &[AxisStatus::Used; 3]),
        Err(FusionError::Core(Error::NonFinite { .. }))
    ));
    assert!(matches!(
        model.fuse_screened(&z, &[AxisStatus::Used; 2]),
        Err(FusionError::Core(Error::DimensionMismatch { .. }))
    ));
    assert!(xyq::fuse(&XyqReading { x: f64::NAN, ..r }, &s, XyqAxes::ALL).is_err());
}

/// One batch Kalman update with the remaining axes as a runtime-sized model equals the
/// sequential scalar updates of `fuse_with_filter`.
#[test]
fn batch_update_equals_sequential_updates() {
    let angles = SVector::<f64, 6>::from_fn(|i, _| 0.37 + i as f64 * 0.9);
    let sig = SVector::<f64, 6>::from_fn(|i, _| 0.005 * (1.0 + i as f64));
    let axes = PlanarAxes::<6>::planar(&angles, sig).unwrap();
    let z = SVector::<f64, 6>::from_fn(|i, _| (i as f64 * 1.3).sin());
    let seq = axes.fuse_with_filter(&z, &[AxisStatus::Used; 6]).unwrap();
    let prior = axes.exact_prior(&z, &seq.initial_axes).unwrap();
    let rest = axes.select(&seq.update_axes).unwrap();
    let zr = DVector::from_iterator(rest.len(), seq.update_axes.iter().map(|&i| z[i]));
    let mut kf = KalmanFilter::new(prior);
    let rep = kf.update(&rest, &zr).unwrap();
    assert!((kf.state() - seq.estimate).amax() < 1e-14);
    assert!((kf.covariance() - seq.covariance).amax() < 1e-18);
    assert!((rep.nis - seq.chi2).abs() < 1e-10 * seq.chi2.max(1.0));
}
