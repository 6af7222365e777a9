//! The region of unscented parameters accepted: α²κ + nβ ≥ 0 and n + κ > 0 (see
//! `Unscented`'s docs). Checked at its boundary (exactly on it accepted, one ulp outside
//! refused with the parameter named), against a closed form that shows the region is tight:
//! for g(x) = (x − μ)ᵀ C⁻¹ (x − μ) every sigma point gives g = c, and the transform's variance
//! of g is n (α²κ + nβ), negative exactly outside the region.

use estim_core::nalgebra::{Const, Matrix2, OMatrix, OVector, RowVector2, Vector1, Vector2};
use estim_core::{Differentiable, Error, MomentPropagator, Parameter, Unscented, VectorFunction};

/// g(x) = (x − μ)ᵀ C⁻¹ (x − μ) for n = 2.
struct Mahalanobis {
    mean: Vector2<f64>,
    information: Matrix2<f64>,
}

impl VectorFunction<f64, Const<2>, Const<1>> for Mahalanobis {
    fn eval(&self, x: &Vector2<f64>) -> Vector1<f64> {
        let d = x - self.mean;
        Vector1::new((d.transpose() * self.information * d)[0])
    }
}

impl Differentiable<f64, Const<2>, Const<1>> for Mahalanobis {
    fn jacobian(&self, x: &Vector2<f64>) -> RowVector2<f64> {
        2.0 * (self.information * (x - self.mean)).transpose()
    }
}

fn problem() -> (Vector2<f64>, Matrix2<f64>, Mahalanobis) {
    let mean = Vector2::new(0.3, -0.2);
    let c = Matrix2::new(2.0, 0.5, 0.5, 1.0);
    let g = Mahalanobis {
        mean,
        information: c.try_inverse().unwrap(),
    };
    (mean, c, g)
}

fn variance(ut: &Unscented<f64>) -> Result<f64, Error> {
    let (mean, c, g) = problem();
    let (_, p): (OVector<f64, Const<1>>, OMatrix<f64, Const<1>, Const<1>>) =
        ut.propagate_mean_covariance(&mean, &c, &g)?;
    Ok(p[(0, 0)])
}

/// The next float below `x`.
fn below(x: f64) -> f64 {
    if x > 0.0 {
        f64::from_bits(x.to_bits() - 1)
    } else {
        f64::from_bits(x.to_bits() + 1)
    }
}

fn assert_refused(r: Result<impl core::fmt::Debug, Error>, parameter: Parameter) {
    match r {
        Err(Error::InvalidParameter { parameter: p, .. }) => assert_eq!(p, parameter),
        other => panic!("expected {parameter:?} refused, got {other:?}"),
    }
}

/// β < 0 side, n = 2, α = 1, κ = 2: the boundary is β = −α²κ/n = −1 (exactly representable).
/// On it the variance of the even g is n (α²κ + nβ) = 0 (to round-off: the two terms n c and
/// (β − α²) n² are ±8, and each of the ~10 roundings in g and the sums is ≤ ε of that: 32 ε · 8); one ulp below, refused naming β.
#[test]
fn negative_beta_boundary() {
    let on = Unscented::new(1.0, -1.0, 2.0).unwrap();
    assert!(on.check_dimension(2).is_ok());
    let v = variance(&on).unwrap();
    assert!(v.abs() <= 32.0 * f64::EPSILON * 8.0, "variance {v}");
    let outside = Unscented::new(1.0, below(-1.0), 2.0).unwrap(); // fine for n = 1
    assert!(outside.check_dimension(1).is_ok());
    assert_refused(outside.check_dimension(2), Parameter::UnscentedBeta);
    assert_refused(variance(&outside), Parameter::UnscentedBeta);
    // No n works when α²κ + β < 0: refused at construction.
    assert_refused(
        Unscented::new(1.0, below(-2.0), 2.0),
        Parameter::UnscentedBeta,
    );
    assert!(Unscented::new(1.0, -2.0, 2.0).is_ok());
}

/// κ < 0 side, n = 2, α = 2, β = 1: the boundary is κ = −nβ/α² = −0.5 (c = 6 > 0 there). On
/// it the variance is 0 to round-off (terms ±12, bound 32 ε · 12 as above); one ulp below, refused naming κ.
/// β = 0 with any κ < 0 (Julier's κ = 3 − n for n > 3) is refused at construction.
#[test]
fn negative_kappa_boundary() {
    let on = Unscented::new(2.0, 1.0, -0.5).unwrap();
    let v = variance(&on).unwrap();
    assert!(v.abs() <= 32.0 * f64::EPSILON * 12.0, "variance {v}");
    let outside = Unscented::new(2.0, 1.0, below(-0.5)).unwrap();
    assert_refused(outside.check_dimension(2), Parameter::UnscentedKappa);
    assert_refused(variance(&outside), Parameter::UnscentedKappa);
    assert!(outside.check_dimension(3).is_ok());
    assert_refused(Unscented::julier(-1.0), Parameter::UnscentedKappa);
    assert_refused(
        Unscented::new(1e-3, 0.0, -1e-300),
        Parameter::UnscentedKappa,
    );
    assert!(Unscented::julier(0.0).is_ok());
}

/// Inside the region the transform's variance of the even g is the closed form n (α²κ + nβ)
/// (every sigma point has g = c, g(μ) = 0), relative 1e-12 (the sums are of 2n equal terms of
/// size c² w plus the centre term: a few ε times the largest, c ≤ 10¹² here, relative to a
/// result of the same order); just outside it, the textbook weights (W₀ᶜ = 1 − n/c + 1 − α² + β,
/// Wᵢ = 1/(2c)) give the same closed form, negative: the region cannot be widened. The extreme
/// set α = 10³, κ = 10⁶ (W₀ᶜ ≈ −10⁶) is inside.
#[test]
fn the_region_is_tight_for_an_even_function() {
    let n = 2.0;
    for (alpha, beta, kappa) in [
        (1e-3, 2.0, 0.0),
        (1.0, 0.0, 0.0),
        (1.0, 0.0, 1.0),
        (1e3, 2.0, 1e6),
        (2.0, 1.0, -0.4),
        (1.0, -0.9, 2.0),
    ] {
        let ut = Unscented::new(alpha, beta, kappa).unwrap();
        let v = variance(&ut).unwrap();
        let closed = n * (alpha * alpha * kappa + n * beta);
        assert!(
            (v - closed).abs() <= 1e-12 * closed.abs().max(1.0),
            "({alpha}, {beta}, {kappa}): {v} vs {closed}"
        );
    }
    // Outside: (α, β, κ) = (1, −1.1, 2) and (2, 1, −0.6), by the textbook weights.
    for (alpha, beta, kappa) in [(1.0_f64, -1.1_f64, 2.0_f64), (2.0, 1.0, -0.6)] {
        let c = alpha * alpha * (n + kappa);
        let (wm0, w) = (1.0 - n / c, 1.0 / (2.0 * c));
        let wc0 = wm0 + 1.0 - alpha * alpha + beta;
        // g(μ) = 0, g(χ±ⱼ) = c: ȳ = 2n w c, var = W₀ᶜ ȳ² + 2n w (c − ȳ)².
        let mean = 2.0 * n * w * c;
        let textbook = wc0 * mean * mean + 2.0 * n * w * (c - mean).powi(2);
        let closed = n * (alpha * alpha * kappa + n * beta);
        assert!((textbook - closed).abs() < 1e-12 * closed.abs().max(1.0));
        assert!(textbook < 0.0, "{textbook}");
        assert!(
            Unscented::new(alpha, beta, kappa)
                .unwrap()
                .check_dimension(2)
                .is_err()
        );
    }
}
