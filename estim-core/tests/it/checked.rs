//! Validate once: the checked linear models refuse a non-symmetric, an indefinite (with a
//! positive diagonal) and a non-finite Q or R with the exact typed error, accept
//! positive semi-definite singular ones, and build exactly the model the struct literal builds.

use estim_core::checked::check_noise;
use estim_core::nalgebra::{DMatrix, Matrix2, Matrix2x1, Matrix3};
use estim_core::{Error, LinearMeasurement, LinearProcess, Quantity, Stage};

const STAGE: Stage = Stage::Construction;

/// Both constructors on one matrix: the process with it as Q, the measurement as R.
fn both(noise: Matrix2<f64>) -> (Result<(), Error>, Result<(), Error>) {
    let process = LinearProcess::try_new(Matrix2::identity(), Matrix2x1::zeros(), noise);
    let measurement = LinearMeasurement::try_new(Matrix2::identity(), noise);
    (process.map(|_| ()), measurement.map(|_| ()))
}

#[test]
fn refuses_non_symmetric_indefinite_and_non_finite_noise() {
    // Off-diagonal 0.3 vs 0.0: asymmetric far beyond √ε relative.
    let asymmetric = Matrix2::new(1.0, 0.3, 0.0, 1.0);
    let (q, r) = both(asymmetric);
    assert_eq!(
        q,
        Err(Error::NotSymmetric {
            stage: STAGE,
            quantity: Quantity::ProcessNoise,
            row: 1,
            col: 0
        })
    );
    assert_eq!(
        r,
        Err(Error::NotSymmetric {
            stage: STAGE,
            quantity: Quantity::MeasurementNoise,
            row: 1,
            col: 0
        })
    );
    // Eigenvalues 3 and −1, diagonal positive: what the per-step check cannot see.
    let indefinite = Matrix2::new(1.0, 2.0, 2.0, 1.0);
    let (q, r) = both(indefinite);
    assert_eq!(
        q,
        Err(Error::NotPositiveSemiDefinite {
            stage: STAGE,
            quantity: Quantity::ProcessNoise
        })
    );
    assert_eq!(
        r,
        Err(Error::NotPositiveSemiDefinite {
            stage: STAGE,
            quantity: Quantity::MeasurementNoise
        })
    );
    // Just indefinite: eigenvalues 2 and −1e-6 (far beyond the 16 n ε max Qᵢᵢ ≈ 7e-15).
    let barely = Matrix2::new(1.0, 1.0 + 1e-6, 1.0 + 1e-6, 1.0);
    assert!(matches!(
        both(barely).0,
        Err(Error::NotPositiveSemiDefinite { .. })
    ));
    for bad in [f64::NAN, f64::INFINITY] {
        let (q, r) = both(Matrix2::new(1.0, 0.0, 0.0, bad));
        assert_eq!(
            q,
            Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::ProcessNoise
            })
        );
        assert_eq!(
            r,
            Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::MeasurementNoise
            })
        );
    }
    // A non-finite F or H.
    let nan_f = LinearProcess::try_new(
        Matrix2::new(1.0, f64::NAN, 0.0, 1.0),
        Matrix2x1::zeros(),
        Matrix2::identity(),
    );
    assert_eq!(
        nan_f.unwrap_err(),
        Error::NonFinite {
            stage: STAGE,
            quantity: Quantity::Jacobian
        }
    );
    // Runtime sizes: a Q of the wrong shape.
    let wrong = LinearProcess::try_new(
        DMatrix::<f64>::identity(3, 3),
        DMatrix::zeros(3, 1),
        DMatrix::identity(2, 2),
    );
    assert!(matches!(
        wrong.unwrap_err(),
        Error::DimensionMismatch {
            quantity: Quantity::ProcessNoise,
            ..
        }
    ));
}

/// Singular positive semi-definite noise is accepted: a bias without process noise
/// (diag(σ², 0)), a rank-one Q (x₂ = 2 x₁ exactly), zero R, and a singular 3 × 3 Q whose
/// unpivoted factorisation meets a zero pivot before a nonzero one.
#[test]
fn accepts_singular_positive_semi_definite_noise() {
    for noise in [
        Matrix2::new(1e-3, 0.0, 0.0, 0.0),
        Matrix2::new(1.0, 2.0, 2.0, 4.0),
        Matrix2::zeros(),
    ] {
        let (q, r) = both(noise);
        assert_eq!(q, Ok(()), "{noise}");
        assert_eq!(r, Ok(()), "{noise}");
    }
    let q3 = Matrix3::new(0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.0, 0.5, 0.25);
    assert_eq!(check_noise(&q3, Quantity::ProcessNoise), Ok(()));
}

/// `try_new` builds the model the struct literal builds, its matrices unchanged.
#[test]
fn checked_models_are_the_plain_models() {
    let (f, b) = (Matrix2::new(1.0, 0.1, 0.0, 1.0), Matrix2x1::new(0.005, 0.1));
    let q = Matrix2::new(2e-3, 1e-3, 1e-3, 1e-3);
    let checked = LinearProcess::try_new(f, b, q).unwrap();
    let plain = LinearProcess {
        transition: f,
        input: b,
        noise: q,
    };
    assert_eq!(checked, plain);
    let h = Matrix2::new(1.0, 0.0, 0.5, 1.0);
    let sensor = LinearMeasurement::try_new(h, Matrix2::identity() * 0.01).unwrap();
    assert_eq!(
        sensor,
        LinearMeasurement {
            observation: h,
            noise: Matrix2::identity() * 0.01
        }
    );
}
