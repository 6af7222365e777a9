//! `Gaussian::new` accepts symmetric positive semi-definite covariances (including singular
//! ones and round-off-level negative pivots) and rejects, with the documented error, wrong
//! shapes, non-finite entries, asymmetry (naming the worst pair) and indefiniteness.

use crate::common;

use common::*;
use estim_core::nalgebra::{
    DMatrix, DVector, Matrix2, Matrix3, OMatrix, U1, U4, U5, Vector2, Vector3,
};
use estim_core::{Error, Gaussian, Quantity, Stage};
use proptest::prelude::*;

const NOT_PSD: Error = Error::NotPositiveSemiDefinite {
    stage: Stage::Construction,
    quantity: Quantity::Covariance,
};

proptest! {
    #![proptest_config(config(64, 0x66))]

    /// SPD covariances are accepted, static and dynamic, and returned unchanged.
    #[test]
    fn accepts_spd(mu in prop::collection::vec(-10.0..10.0f64, 4), cb in prop::collection::vec(-1.0..1.0f64, 16), scale in 1e-3..1e3f64) {
        let c = spd(U4, &cb, scale);
        let g = Gaussian::new(vector(U4, &mu), c).unwrap();
        prop_assert_eq!(g.covariance(), &c);
        prop_assert_eq!(g.dim(), 4);
        let (m, c2) = g.clone().into_parts();
        prop_assert_eq!(&m, g.mean());
        prop_assert_eq!(c2, c);
        let gd = Gaussian::new(DVector::from_column_slice(&mu), DMatrix::from_column_slice(4, 4, c.as_slice())).unwrap();
        prop_assert_eq!(gd.dim(), 4);
    }

    /// Rank-deficient covariances L Lᵀ, L lower triangular with some columns zero (those
    /// directions carry no variance) and the other pivots in [0.3, 1]: the semi-definite
    /// Cholesky reproduces the zero pivots up to the round-off of forming L Lᵀ, which the
    /// documented tolerance 16 n ε max Cᵢᵢ covers (each entry is a ≤ 5-term sum, off by
    /// ≤ 5ε max Cᵢᵢ). See `ill_conditioned_rank_deficient_is_accepted` for where it does not.
    #[test]
    fn accepts_rank_deficient(entries in prop::collection::vec(-1.0..1.0f64, 25), pivots in prop::collection::vec(0.3..1.0f64, 5), zero in prop::collection::vec(any::<bool>(), 5), scale in 1e-3..1e3f64) {
        let l = OMatrix::<f64, U5, U5>::from_fn(|i, j| {
            if zero[j] || i < j { 0.0 } else if i == j { pivots[j] } else { entries[i * 5 + j] }
        });
        let c = l * l.transpose() * scale;
        prop_assert!(Gaussian::new(OMatrix::<f64, U5, U1>::zeros(), c).is_ok());
        let cd = DMatrix::from_column_slice(5, 5, c.as_slice());
        prop_assert!(Gaussian::new(DVector::zeros(5), cd).is_ok());
    }

    /// An asymmetric pair beyond √ε relative is rejected, naming the worst pair.
    #[test]
    fn rejects_asymmetry_naming_the_pair(i in 0usize..4, j in 0usize..4, gap in 1e-6..1.0f64, cb in prop::collection::vec(-1.0..1.0f64, 16)) {
        prop_assume!(i != j);
        let mut c = spd(U4, &cb, 1.0);
        c[(i, j)] += gap;
        match Gaussian::new(OMatrix::<f64, U4, U1>::zeros(), c) {
            Err(Error::NotSymmetric { stage: Stage::Construction, quantity: Quantity::Covariance, row, col }) => {
                // The error names the pair (row, col) and (col, row); either order is the pair.
                prop_assert!((row, col) == (i, j) || (row, col) == (j, i), "named ({row}, {col}), corrupted ({i}, {j})");
            }
            other => prop_assert!(false, "expected NotSymmetric, got {:?}", other),
        }
    }
}

#[test]
fn accepts_singular_covariances() {
    // A component known exactly (zero variance).
    assert!(
        Gaussian::new(
            Vector3::new(1.0, 2.0, 3.0),
            Matrix3::from_diagonal(&Vector3::new(1.0, 0.0, 2.0))
        )
        .is_ok()
    );
    // Perfectly correlated components.
    assert!(Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::new(1.0, 1.0, 1.0, 1.0)).is_ok());
    assert!(Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::new(4.0, -2.0, -2.0, 1.0)).is_ok());
    // No uncertainty at all.
    assert!(Gaussian::new(Vector2::new(5.0, -5.0), Matrix2::zeros()).is_ok());
    // A rank-one v vᵀ formed in floating point.
    let v = Vector3::new(0.1, 0.7, -0.3);
    assert!(Gaussian::new(Vector3::zeros(), v * v.transpose()).is_ok());
    // A negative pivot at round-off level: −ε is inside 16 n ε max Cᵢᵢ = 32ε.
    assert!(Gaussian::new(Vector2::zeros(), Matrix2::new(1.0, 0.0, 0.0, -EPS)).is_ok());
    // Asymmetry at round-off level (10⁻¹² relative, below √ε ≈ 1.5·10⁻⁸) is accepted.
    assert!(Gaussian::new(Vector2::zeros(), Matrix2::new(1.0, 0.5 + 1e-12, 0.5, 1.0)).is_ok());
    // f32.
    assert!(
        Gaussian::new(
            Vector2::new(1.0f32, 2.0),
            Matrix2::new(2.0f32, 0.5, 0.5, 1.0)
        )
        .is_ok()
    );
    assert!(
        Gaussian::new(
            Vector2::new(1.0f32, 2.0),
            Matrix2::new(1.0f32, 1.0, 1.0, 1.0)
        )
        .is_ok()
    );
}

#[test]
fn rejects_non_finite() {
    let c = Matrix2::new(1.0, 0.0, 0.0, 1.0);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert_eq!(
            Gaussian::new(Vector2::new(bad, 0.0), c),
            Err(Error::NonFinite {
                stage: Stage::Construction,
                quantity: Quantity::Mean
            })
        );
        // Non-finite covariance entries, on the diagonal and off it (symmetrically).
        assert_eq!(
            Gaussian::new(Vector2::zeros(), Matrix2::new(bad, 0.0, 0.0, 1.0)),
            Err(Error::NonFinite {
                stage: Stage::Construction,
                quantity: Quantity::Covariance
            })
        );
        assert_eq!(
            Gaussian::new(Vector2::zeros(), Matrix2::new(1.0, bad, bad, 1.0)),
            Err(Error::NonFinite {
                stage: Stage::Construction,
                quantity: Quantity::Covariance
            })
        );
    }
    assert_eq!(
        Gaussian::new(Vector2::new(f32::NAN, 0.0), Matrix2::identity()),
        Err(Error::NonFinite {
            stage: Stage::Construction,
            quantity: Quantity::Mean
        })
    );
}

#[test]
fn rejects_asymmetric_with_worst_pair() {
    // Two asymmetric pairs; (2, 0)/(0, 2) differs more than (1, 0)/(0, 1).
    let c = Matrix3::new(
        2.0, 0.30, 0.5, //
        0.31, 2.0, 0.1, //
        0.2, 0.1, 2.0,
    );
    match Gaussian::new(Vector3::zeros(), c) {
        Err(Error::NotSymmetric {
            stage: Stage::Construction,
            quantity: Quantity::Covariance,
            row,
            col,
        }) => {
            assert!(
                (row, col) == (2, 0) || (row, col) == (0, 2),
                "named ({row}, {col})"
            );
        }
        other => panic!("expected NotSymmetric, got {other:?}"),
    }
    // An asymmetric matrix that is otherwise indefinite: symmetry is checked first.
    assert!(matches!(
        Gaussian::new(Vector2::zeros(), Matrix2::new(1.0, 5.0, 2.0, 1.0)),
        Err(Error::NotSymmetric { row: 1, col: 0, .. })
    ));
}

#[test]
fn rejects_indefinite() {
    assert_eq!(
        Gaussian::new(Vector2::zeros(), Matrix2::new(1.0, 2.0, 2.0, 1.0)),
        Err(NOT_PSD)
    );
    assert_eq!(
        Gaussian::new(Vector2::zeros(), Matrix2::new(1.0, 0.0, 0.0, -1e-3)),
        Err(NOT_PSD)
    );
    // −10⁻¹⁰ is far outside the 32ε ≈ 7·10⁻¹⁵ tolerance.
    assert_eq!(
        Gaussian::new(Vector2::zeros(), Matrix2::new(1.0, 0.0, 0.0, -1e-10)),
        Err(NOT_PSD)
    );
    // Zero variance but non-zero covariance with another component: det = −0.01 < 0.
    assert_eq!(
        Gaussian::new(Vector2::zeros(), Matrix2::new(0.0, 0.1, 0.1, 1.0)),
        Err(NOT_PSD)
    );
    // The same pattern behind a non-trivial first pivot.
    let c = Matrix3::new(
        1.0, 0.5, 0.2, //
        0.5, 0.25, 0.3, //
        0.2, 0.3, 1.0,
    );
    assert_eq!(Gaussian::new(Vector3::zeros(), c), Err(NOT_PSD));
    assert_eq!(
        Gaussian::new(Vector2::zeros(), Matrix2::new(1.0f32, 2.0, 2.0, 1.0)),
        Err(NOT_PSD)
    );
}

#[test]
fn rejects_wrong_dynamic_shape() {
    let mean = DVector::from_vec(vec![1.0, 2.0, 3.0]);
    let mismatch = |found_rows, found_cols| Error::DimensionMismatch {
        stage: Stage::Construction,
        quantity: Quantity::Covariance,
        expected_rows: 3,
        expected_cols: 3,
        found_rows,
        found_cols,
    };
    assert_eq!(
        Gaussian::new(mean.clone(), DMatrix::identity(3, 2)),
        Err(mismatch(3, 2))
    );
    assert_eq!(
        Gaussian::new(mean.clone(), DMatrix::identity(2, 2)),
        Err(mismatch(2, 2))
    );
    assert_eq!(
        Gaussian::new(mean.clone(), DMatrix::identity(4, 4)),
        Err(mismatch(4, 4))
    );
    // The shape is checked first: a NaN does not hide it.
    assert_eq!(
        Gaussian::new(
            DVector::from_vec(vec![f64::NAN, 0.0, 0.0]),
            DMatrix::identity(2, 2)
        ),
        Err(mismatch(2, 2))
    );
    assert!(Gaussian::new(mean, DMatrix::identity(3, 3)).is_ok());
    // Empty is a valid (trivial) Gaussian.
    assert!(Gaussian::new(DVector::<f64>::zeros(0), DMatrix::zeros(0, 0)).is_ok());
}

#[test]
fn new_unchecked_keeps_what_it_is_given() {
    let c = Matrix2::new(1.0, 2.0, 2.0, 1.0);
    let g = Gaussian::new_unchecked(Vector2::new(1.0, 2.0), c);
    assert_eq!(g.covariance(), &c);
}

/// Regression: the unpivoted semi-definite Cholesky rejected this exactly PSD matrix, because
/// round-off in its ill-conditioned leading block (amplified by ≈ ‖A₁₁⁻¹A₁₂‖², here ≈ 10⁴)
/// pushed the fourth pivot to −7.5·10⁻¹⁴ against a tolerance of 2.5·10⁻¹⁴. C = B Bᵀ (B 5 × 3,
/// found by proptest) has eigenvalues {0, 9·10⁻¹⁷, 0.11, 0.76, 1.87}. `psd_factor` now falls back
/// to diagonal pivoting, which stops cleanly at the rank; the root it returns must reproduce C
/// (to round-off relative to max Cᵢᵢ ≈ 1.9: 64 ε covers the O(n ε) factorisation error).
#[test]
fn ill_conditioned_rank_deficient_is_accepted() {
    let b = [
        -0.4699356065633261,
        0.3626130376989652,
        0.0,
        -0.9818426112350165,
        0.0, //
        0.4182398318046955,
        -0.36035857743228206,
        0.0,
        0.0,
        0.0, //
        0.9977118384261457,
        0.0,
        -0.3630082978048231,
        0.0,
        0.0,
    ];
    let b = OMatrix::<f64, U5, estim_core::nalgebra::U3>::from_column_slice(&b);
    let c = b * b.transpose();
    assert!(Gaussian::new(OMatrix::<f64, U5, U1>::zeros(), c).is_ok());
    let root = estim_core::linalg::psd_factor(&c, estim_core::Stage::Construction)
        .expect("PSD matrix must factor");
    let gap = (root * root.transpose() - c).amax();
    assert!(gap <= 64.0 * f64::EPSILON * 1.9, "S Sᵀ − C = {gap:e}");
}

/// An indefinite matrix whose leading pivots are zero is still rejected by the pivoted
/// fallback: diag(0, 0, 1) plus a coupling between the two zero-variance directions.
#[test]
fn indefinite_with_zero_leading_pivots_is_rejected() {
    let c = estim_core::nalgebra::Matrix3::new(0.0, 1e-3, 0.0, 1e-3, 0.0, 0.0, 0.0, 0.0, 1.0);
    assert!(matches!(
        estim_core::linalg::psd_factor(&c, estim_core::Stage::Construction),
        Err(estim_core::Error::NotPositiveSemiDefinite { .. })
    ));
}

/// The sample mean and covariance of 40 000 draws against μ and C. Standard errors: the mean's
/// entries √(Cᵢᵢ/n) ≤ 0.01; a covariance entry's √((CᵢᵢCⱼⱼ + Cᵢⱼ²)/n) ≤ 0.016 at this C. Bounds
/// are 5 standard errors (a false failure once in ~10⁶ seeds, and the seed is fixed).
#[test]
fn samples_have_the_gaussians_mean_and_covariance() {
    use estim_core::rand::SeedableRng;
    use estim_core::rand_distr::Distribution;
    let c = Matrix3::new(2.0, 0.6, -0.3, 0.6, 1.0, 0.2, -0.3, 0.2, 0.5);
    let g = Gaussian::new(Vector3::new(1.0, -2.0, 0.5), c).unwrap();
    let sampler = g.sampler().unwrap();
    let mut rng = estim_core::rand::rngs::StdRng::seed_from_u64(0x5a);
    let n = 40_000;
    let xs: Vec<Vector3<f64>> = (0..n).map(|_| sampler.sample(&mut rng)).collect();
    let mean = xs.iter().sum::<Vector3<f64>>() / n as f64;
    let cov = xs
        .iter()
        .map(|x| (x - mean) * (x - mean).transpose())
        .sum::<Matrix3<f64>>()
        / (n - 1) as f64;
    assert!((mean - g.mean()).abs().max() < 5.0 * 0.01, "{mean}");
    assert!((cov - c).abs().max() < 5.0 * 0.016, "{cov}");
}

/// A singular covariance (x₂ = 2 x₁) samples on its line; f32 samples; `into_dyn` keeps the
/// entries to the bit.
#[test]
fn samples_of_singular_and_f32_gaussians_and_into_dyn() {
    use estim_core::rand::SeedableRng;
    let mut rng = estim_core::rand::rngs::StdRng::seed_from_u64(3);
    let line = Gaussian::new(Vector2::<f64>::zeros(), Matrix2::new(1.0, 2.0, 2.0, 4.0)).unwrap();
    for _ in 0..100 {
        let x: Vector2<f64> = line.sample(&mut rng).unwrap();
        // Rounding of 2·z in the factor's product: a few ulps of |x|.
        assert!(
            (x[1] - 2.0 * x[0]).abs() <= 1e-12 * (1.0 + x.abs().max()),
            "{x}"
        );
    }
    let single = Gaussian::new(Vector2::new(1.0f32, 2.0), Matrix2::identity() * 0.25).unwrap();
    assert!(
        single
            .sample(&mut rng)
            .unwrap()
            .iter()
            .all(|v| v.is_finite())
    );
    let dynamic = line.clone().into_dyn();
    assert_eq!(dynamic.mean().as_slice(), line.mean().as_slice());
    assert_eq!(
        dynamic.covariance().as_slice(),
        line.covariance().as_slice()
    );
    // A covariance that skipped the checks is refused by the sampler, not sampled.
    let bad = Gaussian::new_unchecked(Vector2::zeros(), Matrix2::new(1.0, 3.0, 3.0, 1.0));
    assert!(bad.sampler().is_err());
}
