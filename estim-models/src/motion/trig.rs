//! The θ-functions of turning motion, with their θ → 0 limits exact (no 0/0).
//!
//! Each is an entire function of θ; for |θ| < [`SERIES_LIMIT`] it is evaluated by its Taylor
//! series (12 terms in θ²: the first omitted term is below θ²⁴/25! < 10⁻²⁵ there), above it by
//! the closed form, whose cancellation error is at most ~16ε/θ² ≤ 4·10⁻¹⁵ relative at
//! |θ| ≥ 1. The unit tests check both routes agree across the limit.

use estim_core::Real;
use estim_core::scalar::real;

/// Below this |θ| the functions use their series.
pub(crate) const SERIES_LIMIT: f64 = 1.0;

const TERMS: usize = 12;

/// Σₘ c(m) θ^{2m}, m = 0..TERMS, by Horner in θ².
fn series<T: Real>(theta: T, c: impl Fn(usize) -> f64) -> T {
    let t2 = theta * theta;
    (0..TERMS)
        .rev()
        .fold(T::zero(), |acc, m| acc * t2 + real::<T>(c(m)))
}

fn factorial(k: usize) -> f64 {
    (1..=k).fold(1.0, |acc, i| acc * i as f64)
}

fn sign(m: usize) -> f64 {
    if m.is_multiple_of(2) { 1.0 } else { -1.0 }
}

fn small<T: Real>(theta: T) -> bool {
    theta.abs() < real::<T>(SERIES_LIMIT)
}

/// sin θ / θ.
pub(crate) fn sinc<T: Real>(theta: T) -> T {
    if small(theta) {
        series(theta, |m| sign(m) / factorial(2 * m + 1))
    } else {
        theta.sin() / theta
    }
}

/// (1 − cos θ) / θ².
pub(crate) fn cosc<T: Real>(theta: T) -> T {
    if small(theta) {
        series(theta, |m| sign(m) / factorial(2 * m + 2))
    } else {
        let s = (theta * real::<T>(0.5)).sin();
        real::<T>(2.0) * s * s / (theta * theta)
    }
}

/// (θ − sin θ) / θ³.
pub(crate) fn sinc3<T: Real>(theta: T) -> T {
    if small(theta) {
        series(theta, |m| sign(m) / factorial(2 * m + 3))
    } else {
        (theta - theta.sin()) / (theta * theta * theta)
    }
}

/// d/dθ (sin θ / θ) = (θ cos θ − sin θ) / θ², as θ · e(θ); this returns e(θ) =
/// (θ cos θ − sin θ) / θ³.
pub(crate) fn dsinc_over_theta<T: Real>(theta: T) -> T {
    if small(theta) {
        series(theta, |m| {
            -sign(m) * 2.0 * (m as f64 + 1.0) / factorial(2 * m + 3)
        })
    } else {
        let (s, c) = theta.sin_cos();
        (theta * c - s) / (theta * theta * theta)
    }
}

/// d²/dθ² (sin θ / θ) = (2 sin θ − 2θ cos θ − θ² sin θ) / θ³.
pub(crate) fn d2sinc<T: Real>(theta: T) -> T {
    if small(theta) {
        series(theta, |m| {
            -sign(m) * 2.0 * (m as f64 + 1.0) * (2.0 * m as f64 + 1.0) / factorial(2 * m + 3)
        })
    } else {
        let (s, c) = theta.sin_cos();
        let two = real::<T>(2.0);
        (two * s - two * theta * c - theta * theta * s) / (theta * theta * theta)
    }
}

/// d/dθ ((1 − cos θ) / θ) = (θ sin θ − (1 − cos θ)) / θ².
pub(crate) fn dcosc1<T: Real>(theta: T) -> T {
    if small(theta) {
        series(theta, |m| {
            sign(m) * (2.0 * m as f64 + 1.0) / factorial(2 * m + 2)
        })
    } else {
        let (s, _) = theta.sin_cos();
        (theta * s - theta * theta * cosc(theta)) / (theta * theta)
    }
}

/// d²/dθ² ((1 − cos θ) / θ) = θ · f(θ); this returns f(θ) =
/// (θ² cos θ − 2θ sin θ + 2(1 − cos θ)) / θ⁴.
pub(crate) fn d2cosc1_over_theta<T: Real>(theta: T) -> T {
    if small(theta) {
        series(theta, |m| {
            -sign(m) * (2.0 * m as f64 + 3.0) * (2.0 * m as f64 + 2.0) / factorial(2 * m + 4)
        })
    } else {
        let (s, c) = theta.sin_cos();
        let two = real::<T>(2.0);
        let t2 = theta * theta;
        (t2 * c - two * theta * s + two * t2 * cosc(theta)) / (t2 * t2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The series (below the limit) against the plain closed forms at θ ∈ {0.7, 0.9, 1⁻}.
    /// The closed forms (1 − cos θ computed directly) carry ≲ 30ε/θ⁴ ≈ 3·10⁻¹⁴ relative
    /// cancellation at θ = 0.7, hence 10⁻¹². A wrong coefficient of order m shows as
    /// ≳ θ^{2m}/(2m+4)! ≥ 10⁻¹⁰ for m ≤ 4 (at θ ≈ 1, ≥ 10⁻¹¹ for m = 5); the higher orders weigh
    /// < 10⁻¹² in total.
    #[test]
    fn series_and_closed_forms_agree_at_the_limit() {
        type Pair = (&'static str, fn(f64) -> f64, fn(f64) -> f64);
        let closed: [Pair; 7] = [
            ("sinc", sinc, |t| t.sin() / t),
            ("cosc", cosc, |t| (1.0 - t.cos()) / (t * t)),
            ("sinc3", sinc3, |t| (t - t.sin()) / t.powi(3)),
            ("dsinc/θ", dsinc_over_theta, |t| {
                (t * t.cos() - t.sin()) / t.powi(3)
            }),
            ("d2sinc", d2sinc, |t| {
                (2.0 * t.sin() - 2.0 * t * t.cos() - t * t * t.sin()) / t.powi(3)
            }),
            ("dcosc1", dcosc1, |t| {
                (t * t.sin() - (1.0 - t.cos())) / (t * t)
            }),
            ("d2cosc1/θ", d2cosc1_over_theta, |t| {
                (t * t * t.cos() - 2.0 * t * t.sin() + 2.0 * (1.0 - t.cos())) / t.powi(4)
            }),
        ];
        for (name, f, reference) in closed {
            for theta in [0.999_999_9, -0.999_999_9, 0.9, 0.7] {
                let (a, b) = (f(theta), reference(theta));
                assert!(
                    (a - b).abs() <= 1e-12 * b.abs(),
                    "{name}({theta}): {a} vs {b}"
                );
            }
            // θ = 0 is finite, no 0/0.
            assert!(f(0.0).is_finite(), "{name}(0)");
        }
        assert_eq!(sinc(0.0), 1.0);
        assert_eq!(cosc(0.0), 0.5);
        assert_eq!(sinc3(0.0), 1.0 / 6.0);
    }
}
