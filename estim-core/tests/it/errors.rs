//! Parameter validation of the propagators and the errors they return for bad data: invalid
//! unscented parameters (at construction, and n + κ ≤ 0 at propagation), too few samples,
//! indefinite covariances, non-finite results, and — with dynamic sizes — functions,
//! Jacobians, Hessians or covariances of the wrong shape: always an `Error`, never a panic.

use crate::common;

use common::*;
use estim_core::nalgebra::{
    DMatrix, DVector, Dyn, Matrix2, Matrix3, OMatrix, OVector, U2, U3, U6, Vector2, Vector3,
};
use estim_core::{
    Differentiable, Error, Linearized, MomentPropagator, Moments, Parameter, Quantity, Sampled,
    SecondOrder, SecondOrderGaussian, Stage, TwiceDifferentiable, Unscented, VectorFunction,
};

fn invalid(parameter: Parameter, value: f64) -> impl Fn(Result<Unscented<f64>, Error>) {
    move |r| match r {
        Err(Error::InvalidParameter {
            parameter: p,
            value: v,
        }) => {
            assert_eq!(p, parameter);
            assert!(
                v == value || (v.is_nan() && value.is_nan()),
                "reported {v}, expected {value}"
            );
        }
        other => panic!("expected InvalidParameter {parameter:?} = {value}, got {other:?}"),
    }
}

#[test]
fn unscented_parameters_are_validated() {
    for alpha in [0.0, -1e-3, -1.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        invalid(Parameter::UnscentedAlpha, alpha)(Unscented::new(alpha, 2.0, 0.0));
    }
    for beta in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        invalid(Parameter::UnscentedBeta, beta)(Unscented::new(1e-3, beta, 0.0));
    }
    for kappa in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        invalid(Parameter::UnscentedKappa, kappa)(Unscented::new(1e-3, 2.0, kappa));
        invalid(Parameter::UnscentedKappa, kappa)(Unscented::julier(kappa));
    }
    // Valid corner values: tiny α with a negative κ, a negative β with α²κ ≥ |β| (the
    // conditions on n are checked later; see ukf_region.rs).
    let ut = Unscented::new(1e-8, 1.0, -2.0).unwrap();
    assert_eq!((ut.alpha(), ut.beta(), ut.kappa()), (1e-8, 1.0, -2.0));
    let ut = Unscented::new(1.0, -1.0, 4.0).unwrap();
    assert_eq!((ut.alpha(), ut.beta(), ut.kappa()), (1.0, -1.0, 4.0));
    let d = Unscented::<f64>::default();
    assert_eq!((d.alpha(), d.beta(), d.kappa()), (1e-3, 2.0, 0.0));
    let c = Unscented::<f64>::cubature();
    assert_eq!((c.alpha(), c.beta(), c.kappa()), (1.0, 0.0, 0.0));
    let j = Unscented::julier(3.0).unwrap();
    assert_eq!((j.alpha(), j.beta(), j.kappa()), (1.0, 0.0, 3.0));
    // f32: the rejected value is reported as f64.
    match Unscented::<f32>::new(-0.5, 2.0, 0.0) {
        Err(Error::InvalidParameter {
            parameter: Parameter::UnscentedAlpha,
            value,
        }) => assert_eq!(value, -0.5),
        other => panic!("{other:?}"),
    }
}

#[test]
fn unscented_needs_n_plus_kappa_positive_at_propagation() {
    let g = TrigSum::products(U3, U3);
    let (mu, c) = (Vector3::new(0.1, 0.2, 0.3), Matrix3::identity() * 0.01);
    // n = 3: κ = −3 gives n + κ = 0, κ = −5 gives −2.
    for kappa in [-3.0, -5.0, -100.0] {
        // Julier's set (β = 0) with κ < 0 is refused for every n (ukf_region.rs).
        invalid(Parameter::UnscentedKappa, kappa)(Unscented::julier(kappa));
        let ut = Unscented::new(0.5, 2.0, kappa).unwrap();
        assert!(matches!(
            ut.propagate(&mu, &c, &g),
            Err(Error::InvalidParameter {
                parameter: Parameter::UnscentedKappa,
                ..
            })
        ));
    }
    // κ = −2.5 (n + κ = 0.5 > 0, and α²κ + nβ = 0.5 ≥ 0 with β = 1) is valid.
    assert!(
        Unscented::new(1.0, 1.0, -2.5)
            .unwrap()
            .propagate(&mu, &c, &g)
            .is_ok()
    );
    // The same parameters are fine for a larger state: validity depends on n.
    let g6 = AffineMap {
        a: OMatrix::<f64, U2, U6>::repeat(1.0),
        b: Vector2::zeros(),
    };
    let (mu6, c6) = (
        OVector::<f64, U6>::zeros(),
        OMatrix::<f64, U6, U6>::identity(),
    );
    assert!(
        Unscented::new(1.0, 1.0, -5.0)
            .unwrap()
            .propagate(&mu6, &c6, &g6)
            .is_ok()
    );
}

#[test]
fn sampled_needs_two_samples() {
    for n in [0usize, 1] {
        assert_eq!(
            Sampled::new(n, 1),
            Err(Error::InvalidParameter {
                parameter: Parameter::SampleCount,
                value: n as f64
            })
        );
    }
    let s = Sampled::new(2, 42).unwrap();
    assert_eq!((s.samples(), s.seed()), (2, 42));
    let g = TrigSum::products(U3, U3);
    assert!(
        s.propagate(&Vector3::zeros(), &Matrix3::identity(), &g)
            .is_ok()
    );
}

#[test]
fn factorising_propagators_reject_indefinite_covariance() {
    let g = TrigSum::products(U3, U3);
    let mu = Vector3::new(0.1, 0.2, 0.3);
    let c = Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    let not_psd = Err(Error::NotPositiveSemiDefinite {
        stage: Stage::Propagation,
        quantity: Quantity::Covariance,
    });
    assert_eq!(Unscented::default().propagate(&mu, &c, &g), not_psd);
    assert_eq!(
        Sampled::new(100, 1).unwrap().propagate(&mu, &c, &g),
        not_psd
    );
    // Zero-variance directions are fine.
    let c = Matrix3::from_diagonal(&Vector3::new(0.1, 0.0, 0.2));
    assert!(Unscented::default().propagate(&mu, &c, &g).is_ok());
    assert!(Sampled::new(100, 1).unwrap().propagate(&mu, &c, &g).is_ok());
}

/// A function that is NaN (or infinite) in some output or in its Jacobian.
struct Poisoned {
    value: bool,
}

impl VectorFunction<f64, U2, U2> for Poisoned {
    fn eval(&self, x: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(x[0], if self.value { f64::NAN } else { x[1] })
    }
}

impl Differentiable<f64, U2, U2> for Poisoned {
    fn jacobian(&self, _: &Vector2<f64>) -> Matrix2<f64> {
        Matrix2::new(1.0, 0.0, 0.0, if self.value { 1.0 } else { f64::INFINITY })
    }
}

impl TwiceDifferentiable<f64, U2, U2> for Poisoned {
    fn hessian(&self, _: &Vector2<f64>, _: usize) -> Option<Matrix2<f64>> {
        None
    }
}

#[test]
fn non_finite_results_are_errors() {
    let (mu, c) = (Vector2::new(1.0, 2.0), Matrix2::identity());
    let mean = Err(Error::NonFinite {
        stage: Stage::Propagation,
        quantity: Quantity::Mean,
    });
    let g = Poisoned { value: true };
    assert_eq!(Linearized.propagate(&mu, &c, &g), mean);
    assert_eq!(SecondOrder.propagate(&mu, &c, &g), mean);
    assert_eq!(SecondOrderGaussian.propagate(&mu, &c, &g), mean);
    assert_eq!(Unscented::default().propagate(&mu, &c, &g), mean);
    assert_eq!(Sampled::new(10, 1).unwrap().propagate(&mu, &c, &g), mean);
    // An infinite Jacobian makes the covariance non-finite.
    let g = Poisoned { value: false };
    assert_eq!(
        Linearized.propagate(&mu, &c, &g),
        Err(Error::NonFinite {
            stage: Stage::Propagation,
            quantity: Quantity::Covariance
        })
    );
}

/// ℝⁿ → ℝ² (dynamic) with configurable mistakes: Jacobian rows/columns, Hessian size, an
/// output that grows to length 3 when x₀ > `grow_above`, and a `difference_into` of wrong length.
#[derive(Clone, Copy)]
struct Misshapen {
    jacobian_shape: (usize, usize),
    hessian_dim: usize,
    grow_above: f64,
    difference_len: Option<usize>,
}

impl Misshapen {
    fn good(n: usize) -> Self {
        Self {
            jacobian_shape: (2, n),
            hessian_dim: n,
            grow_above: f64::INFINITY,
            difference_len: None,
        }
    }
}

impl VectorFunction<f64, Dyn, Dyn> for Misshapen {
    fn eval(&self, x: &DVector<f64>) -> DVector<f64> {
        let m = if x[0] > self.grow_above { 3 } else { 2 };
        DVector::from_fn(m, |i, _| x[0] * (i + 1) as f64 + x[0] * x[0])
    }

    fn difference_into(&self, a: &DVector<f64>, b: &DVector<f64>, out: &mut DVector<f64>) {
        *out = match self.difference_len {
            Some(len) => DVector::zeros(len),
            None => a - b,
        };
    }
}

impl Differentiable<f64, Dyn, Dyn> for Misshapen {
    fn jacobian(&self, x: &DVector<f64>) -> DMatrix<f64> {
        let (r, c) = self.jacobian_shape;
        DMatrix::from_fn(r, c, |i, j| {
            if j == 0 {
                (i + 1) as f64 + 2.0 * x[0]
            } else {
                0.0
            }
        })
    }
}

impl TwiceDifferentiable<f64, Dyn, Dyn> for Misshapen {
    fn hessian(&self, _: &DVector<f64>, _: usize) -> Option<DMatrix<f64>> {
        let mut h = DMatrix::zeros(self.hessian_dim, self.hessian_dim);
        if self.hessian_dim > 0 {
            h[(0, 0)] = 2.0;
        }
        Some(h)
    }
}

fn mismatch(quantity: Quantity, expected: (usize, usize), found: (usize, usize)) -> Error {
    Error::DimensionMismatch {
        stage: Stage::Propagation,
        quantity,
        expected_rows: expected.0,
        expected_cols: expected.1,
        found_rows: found.0,
        found_cols: found.1,
    }
}

/// Drops the moments, keeping the error.
fn err(r: Result<Moments<f64, Dyn, Dyn>, Error>) -> Result<(), Error> {
    r.map(|_| ())
}

#[test]
fn dynamic_shape_mismatches_are_errors_not_panics() {
    let n = 3;
    let mu = DVector::from_vec(vec![0.5, -0.2, 0.1]);
    let c = DMatrix::identity(n, n) * 0.04;
    let good = Misshapen::good(n);
    assert!(Linearized.propagate(&mu, &c, &good).is_ok());
    assert!(SecondOrderGaussian.propagate(&mu, &c, &good).is_ok());
    assert!(Unscented::default().propagate(&mu, &c, &good).is_ok());
    assert!(
        Sampled::new(50, 1)
            .unwrap()
            .propagate(&mu, &c, &good)
            .is_ok()
    );

    // Covariance of the wrong shape, for every propagator.
    let bad_c = DMatrix::identity(n, n - 1);
    let e = Err(mismatch(Quantity::Covariance, (3, 3), (3, 2)));
    assert_eq!(err(Linearized.propagate(&mu, &bad_c, &good)), e);
    assert_eq!(err(SecondOrder.propagate(&mu, &bad_c, &good)), e);
    assert_eq!(err(SecondOrderGaussian.propagate(&mu, &bad_c, &good)), e);
    assert_eq!(err(Unscented::default().propagate(&mu, &bad_c, &good)), e);
    assert_eq!(
        err(Sampled::new(50, 1).unwrap().propagate(&mu, &bad_c, &good)),
        e
    );

    // A Jacobian with a wrong number of rows or columns.
    for shape in [(3, 3), (1, 3), (2, 2), (2, 4)] {
        let g = Misshapen {
            jacobian_shape: shape,
            ..good
        };
        let e = Err(mismatch(Quantity::Jacobian, (2, 3), shape));
        assert_eq!(err(Linearized.propagate(&mu, &c, &g)), e, "{shape:?}");
        assert_eq!(err(SecondOrder.propagate(&mu, &c, &g)), e, "{shape:?}");
        assert_eq!(
            err(SecondOrderGaussian.propagate(&mu, &c, &g)),
            e,
            "{shape:?}"
        );
    }

    // A Hessian of the wrong size.
    for dim in [2, 4] {
        let g = Misshapen {
            hessian_dim: dim,
            ..good
        };
        let e = Err(mismatch(Quantity::Hessian, (3, 3), (dim, dim)));
        assert_eq!(err(SecondOrder.propagate(&mu, &c, &g)), e);
        assert_eq!(err(SecondOrderGaussian.propagate(&mu, &c, &g)), e);
    }

    // An output whose length changes away from the mean (3 instead of 2 at sigma points and
    // samples with x₀ > μ₀).
    let g = Misshapen {
        grow_above: 0.5,
        ..good
    };
    let e = Err(mismatch(Quantity::FunctionValue, (2, 1), (3, 1)));
    assert_eq!(err(Unscented::default().propagate(&mu, &c, &g)), e);
    assert_eq!(err(Unscented::cubature().propagate(&mu, &c, &g)), e);
    assert_eq!(err(Sampled::new(50, 1).unwrap().propagate(&mu, &c, &g)), e);
    // …and one that is already wrong at the mean (3 outputs, Jacobian for 2).
    let g = Misshapen {
        grow_above: 0.0,
        ..good
    };
    assert_eq!(
        err(Linearized.propagate(&mu, &c, &g)),
        Err(mismatch(Quantity::Jacobian, (3, 3), (2, 3)))
    );

    // A `difference_into` that returns the wrong length.
    let g = Misshapen {
        difference_len: Some(1),
        ..good
    };
    let e = Err(mismatch(Quantity::FunctionValue, (2, 1), (1, 1)));
    assert_eq!(err(Unscented::default().propagate(&mu, &c, &g)), e);
    assert_eq!(err(Sampled::new(50, 1).unwrap().propagate(&mu, &c, &g)), e);
}

/// The public checks on a runtime-sized matrix that is not square: a typed error (they
/// indexed out of bounds with more rows than columns), and `symmetrize` panics at the caller.
#[test]
fn checks_refuse_matrices_that_are_not_square() {
    use estim_core::checks::{
        ensure_nonnegative_diagonal, ensure_psd, ensure_symmetric, symmetrize,
    };
    let (stage, quantity) = (Stage::Update, Quantity::MeasurementNoise);
    for (rows, cols) in [(3, 2), (2, 3), (1, 0)] {
        let m = DMatrix::<f64>::from_element(rows, cols, 1.0);
        let mismatch = Err(Error::DimensionMismatch {
            stage,
            quantity,
            expected_rows: rows,
            expected_cols: rows,
            found_rows: rows,
            found_cols: cols,
        });
        assert_eq!(ensure_symmetric(&m, stage, quantity), mismatch);
        assert_eq!(ensure_nonnegative_diagonal(&m, stage, quantity), mismatch);
        assert_eq!(ensure_psd(&m, stage, quantity), mismatch);
        let mut m = m;
        let at = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| symmetrize(&mut m)));
        assert!(at.is_err(), "{rows} × {cols}");
    }
    // Square ones are unaffected, the empty one included.
    let empty = DMatrix::<f64>::zeros(0, 0);
    assert_eq!(ensure_symmetric(&empty, stage, quantity), Ok(()));
    assert_eq!(ensure_psd(&empty, stage, quantity), Ok(()));
}
