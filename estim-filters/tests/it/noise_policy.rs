//! The per-step policy for noise computed by the model at each step (Q(x, u, Δt), R(x)),
//! case by case as documented in `estim_core::checked`: caught with a typed error that
//! leaves the filter bit for bit unchanged (negative variance, non-finite entry, an
//! indefinite matrix even with a positive diagonal, an S = H P Hᵀ + R not positive
//! definite); accepted (a semi-definite matrix; an asymmetric one, used through its
//! symmetric part, which the checked models refuse when built).

use crate::common::assert_bitwise_eq;

use estim_core::nalgebra::{DMatrix, DVector, Dyn, Matrix2, Matrix2x1, U2, Vector2};
use estim_core::{
    Error, Gaussian, LinearMeasurement, LinearProcess, MeasurementModel, ProcessModel, Quantity,
    Stage,
};
use estim_filters::{Ekf, Estimator, Predict, Update};

/// x⁺ = x, with Q(x) = the matrix it carries (a state-dependent noise evaluated per step).
struct NoisyProcess(Matrix2<f64>);
impl ProcessModel<f64, U2> for NoisyProcess {
    type Input = ();
    fn transition(&self, x: &Vector2<f64>, _: &(), _: f64) -> Vector2<f64> {
        *x
    }
    fn process_noise(&self, _: &Vector2<f64>, _: &(), _: f64) -> Matrix2<f64> {
        self.0
    }
}
impl estim_core::ProcessJacobian<f64, U2> for NoisyProcess {
    fn transition_jacobian(&self, _: &Vector2<f64>, _: &(), _: f64) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

/// z = x, with R(x) = the matrix it carries.
struct NoisySensor(Matrix2<f64>);
impl MeasurementModel<f64, U2, U2> for NoisySensor {
    fn measure(&self, x: &Vector2<f64>) -> Vector2<f64> {
        *x
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix2<f64> {
        self.0
    }
}
impl estim_core::MeasurementJacobian<f64, U2, U2> for NoisySensor {
    fn measurement_jacobian(&self, _: &Vector2<f64>) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

fn filter() -> Ekf<f64, U2> {
    Ekf::new(Gaussian::new(Vector2::new(0.5, -0.2), Matrix2::identity() * 0.1).unwrap())
}

#[track_caller]
fn fails_unchanged<R: core::fmt::Debug>(
    op: impl FnOnce(&mut Ekf<f64, U2>) -> Result<R, Error>,
    expected: Error,
) {
    let mut f = filter();
    let before = f.clone();
    assert_eq!(op(&mut f).unwrap_err(), expected);
    assert!(f == before);
    assert_bitwise_eq(f.state(), before.state(), "state");
    assert_bitwise_eq(f.covariance(), before.covariance(), "covariance");
}

#[test]
fn caught_per_step_with_a_typed_error_and_no_change() {
    let z = Vector2::new(0.4, 0.0);
    // A negative variance in Q(x) or R(x): the O(n) diagonal check.
    let negative = Matrix2::new(0.01, 0.0, 0.0, -0.01);
    fails_unchanged(
        |f| f.predict(&NoisyProcess(negative), &(), 1.0),
        Error::NotPositiveSemiDefinite {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
        },
    );
    fails_unchanged(
        |f| f.update(&NoisySensor(negative), &z),
        Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
    );
    // A NaN.
    let nan = Matrix2::new(0.01, 0.0, 0.0, f64::NAN);
    fails_unchanged(
        |f| f.predict(&NoisyProcess(nan), &(), 1.0),
        Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
        },
    );
    fails_unchanged(
        |f| f.update(&NoisySensor(nan), &z),
        Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
    );
    // Indefinite with a positive diagonal (eigenvalues of R: 1.01, −0.99): the
    // semi-definiteness check of R, before S is formed.
    let indefinite = Matrix2::new(0.01, 1.0, 1.0, 0.01);
    fails_unchanged(
        |f| f.update(&NoisySensor(indefinite), &z),
        Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
    );
    // Q with eigenvalues 0.06 and −0.04 and a positive diagonal: from P = 0.1 I, P⁻ = P + Q
    // would be positive definite, so only the check of Q sees it.
    let q = Matrix2::new(0.01, 0.05, 0.05, 0.01);
    fails_unchanged(
        |f| f.predict(&NoisyProcess(q), &(), 1.0),
        Error::NotPositiveSemiDefinite {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
        },
    );
    // R with eigenvalues 0.09, −0.01 and S = P + R positive definite (eigenvalues 0.19,
    // 0.09): without the check of R, P⁺ = P − P S⁻¹ P would have come back with an eigenvalue
    // 0.1 − 0.01/0.09 ≈ −0.011 and a positive diagonal, as `Ok`.
    let r = Matrix2::new(0.04, 0.05, 0.05, 0.04);
    fails_unchanged(
        |f| f.update(&NoisySensor(r), &z),
        Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        },
    );
    assert!(LinearMeasurement::try_new(Matrix2::identity(), r).is_err());
    assert!(LinearProcess::try_new(Matrix2::identity(), Matrix2x1::zeros(), q).is_err());

    // A semi-definite R whose S = P + R is singular (P = 0: the state is known): the
    // update's Cholesky factorisation of S refuses it.
    let mut known = Ekf::new(Gaussian::new(Vector2::new(0.5, -0.2), Matrix2::zeros()).unwrap());
    let before = known.clone();
    assert_eq!(
        known
            .update(&NoisySensor(Matrix2::zeros()), &z)
            .unwrap_err(),
        Error::NotPositiveDefinite {
            stage: Stage::Update,
            quantity: Quantity::InnovationCovariance,
        }
    );
    assert!(known == before);
}

/// Accepted per step: semi-definite noise (rank one, a zero row: Γ W Γᵀ and a bias without
/// noise), which the factorisation tier of the check passes, and an asymmetric R, used
/// through its symmetric part (the checked models refuse that one when built).
#[test]
fn semi_definite_and_asymmetric_noise_are_accepted() {
    // Rank one, not diagonally dominant (the Gershgorin tier cannot pass it): Γ Γᵀ with
    // Γ = (0.1, 0.2)ᵀ; and a zero variance with a positive one.
    for q in [
        Matrix2::new(0.01, 0.02, 0.02, 0.04),
        Matrix2::new(0.01, 0.0, 0.0, 0.0),
    ] {
        let mut f = filter();
        f.predict(&NoisyProcess(q), &(), 1.0).unwrap();
        assert!(
            (f.covariance() - (Matrix2::identity() * 0.1 + q))
                .abs()
                .max()
                < 1e-16
        );
        // R singular: the direction it measures exactly gets a zero posterior variance, to
        // rounding (a few ε of ‖P‖ ≈ 0.1).
        f.update(&NoisySensor(q), &Vector2::new(0.4, 0.0)).unwrap();
        let eig = f.covariance().symmetric_eigenvalues();
        assert!(
            eig.min() > -1e-16 && eig.min() < 1e-16 && eig.max() > 1e-3,
            "{eig}"
        );
    }

    // An asymmetric R: the update equals the one with (R + Rᵀ)/2 to rounding (S is formed as
    // the average of the two triangles of cov(ẑ) + R; the two orders of summation differ by
    // a few ε on entries of size 0.1: bound 1e-15).
    let asym = Matrix2::new(0.02, 0.01, 0.0, 0.02);
    let sym = (asym + asym.transpose()) * 0.5;
    let (mut a, mut b) = (filter(), filter());
    a.update(&NoisySensor(asym), &Vector2::new(0.4, 0.1))
        .unwrap();
    b.update(&NoisySensor(sym), &Vector2::new(0.4, 0.1))
        .unwrap();
    assert!((a.state() - b.state()).abs().max() < 1e-15);
    assert!((a.covariance() - b.covariance()).abs().max() < 1e-15);
    assert!(LinearMeasurement::try_new(Matrix2::identity(), asym).is_err());
}

/// x⁺ = x on runtime sizes, with Q(x) = the matrix it carries.
struct NoisyDynProcess(DMatrix<f64>);
impl ProcessModel<f64, Dyn> for NoisyDynProcess {
    type Input = ();
    fn transition(&self, x: &DVector<f64>, _: &(), _: f64) -> DVector<f64> {
        x.clone()
    }
    fn process_noise(&self, _: &DVector<f64>, _: &(), _: f64) -> DMatrix<f64> {
        self.0.clone()
    }
}
impl estim_core::ProcessJacobian<f64, Dyn> for NoisyDynProcess {
    fn transition_jacobian(&self, x: &DVector<f64>, _: &(), _: f64) -> DMatrix<f64> {
        DMatrix::identity(x.len(), x.len())
    }
}

/// The filter remembers the last Q a committed prediction checked and skips the check when
/// the next Q equals it entry for entry: any other Q is checked as before. An indefinite Q
/// after accepted ones, one entry away from the remembered Q, or of the wrong shape (runtime
/// sizes) is refused and leaves the filter unchanged; the remembered Q passes again after.
#[test]
fn a_remembered_noise_does_not_hide_a_changed_one() {
    let prediction = Stage::Prediction;
    let refused = Error::NotPositiveSemiDefinite {
        stage: prediction,
        quantity: Quantity::ProcessNoise,
    };
    // Rank one (the factorisation tier passes it); with its covariance 1 % larger, the
    // determinant 0.0004 − 1.0201 · 0.0004 < 0: an eigenvalue of about −1.6e-4.
    let good = Matrix2::new(0.01, 0.02, 0.02, 0.04);
    let near = Matrix2::new(0.01, 0.0202, 0.0202, 0.04);
    let mut f = filter();
    for _ in 0..3 {
        f.predict(&NoisyProcess(good), &(), 1.0).unwrap();
    }
    for bad in [near, Matrix2::new(0.01, 0.05, 0.05, 0.01)] {
        let before = f.clone();
        assert_eq!(
            f.predict(&NoisyProcess(bad), &(), 1.0).unwrap_err(),
            refused
        );
        assert!(f == before);
        assert_bitwise_eq(f.covariance(), before.covariance(), "covariance");
        f.predict(&NoisyProcess(good), &(), 1.0).unwrap();
    }
    // The remembered Q gives the same prediction as a fresh filter's checked one.
    let (mut a, mut b) = (f.clone(), filter());
    b.reset(Gaussian::new(*f.state(), *f.covariance()).unwrap());
    a.predict(&NoisyProcess(good), &(), 1.0).unwrap();
    b.predict(&NoisyProcess(good), &(), 1.0).unwrap();
    assert_bitwise_eq(a.covariance(), b.covariance(), "covariance");

    // Runtime sizes: a Q of another shape after an accepted one is a shape error.
    let prior = Gaussian::new(DVector::zeros(2), DMatrix::identity(2, 2) * 0.1).unwrap();
    let mut d = Ekf::<f64, Dyn>::new(prior);
    let q = DMatrix::from_row_slice(2, 2, &[0.01, 0.02, 0.02, 0.04]);
    d.predict(&NoisyDynProcess(q.clone()), &(), 1.0).unwrap();
    let before = d.clone();
    assert!(matches!(
        d.predict(&NoisyDynProcess(DMatrix::zeros(3, 3)), &(), 1.0),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(d == before);
    let bad = DMatrix::from_row_slice(2, 2, &[0.01, 0.05, 0.05, 0.01]);
    assert_eq!(
        d.predict(&NoisyDynProcess(bad), &(), 1.0).unwrap_err(),
        refused
    );
    assert!(d == before);
    d.predict(&NoisyDynProcess(q.clone()), &(), 1.0).unwrap();
    // Reset to another size: the remembered Q goes with the old size, so the old Q is a
    // shape error of the prediction, as for a fresh filter.
    d.reset(Gaussian::new(DVector::zeros(3), DMatrix::identity(3, 3)).unwrap());
    assert!(matches!(
        d.predict(&NoisyDynProcess(q), &(), 1.0),
        Err(Error::DimensionMismatch {
            stage: Stage::Prediction,
            quantity: Quantity::ProcessNoise,
            ..
        })
    ));
}
