//! The few distribution functions the consistency test needs: erfc, the normal CDF, the χ²
//! survival function and quantile for integer degrees of freedom, and the power of the
//! one-degree-of-freedom test against a mean shift.
//!
//! All rest on statrs' regularised upper incomplete gamma function Q(a, x)
//! ([`statrs::function::gamma::checked_gamma_ur`]): erfc(x) = Q(½, x²) and
//! P(χ²ₖ > x) = Q(k/2, x/2). Measured against SciPy/mpmath (test `lv2_stats`): erfc to
//! ≈ 10⁻¹⁴ relative (worst 1.1 · 10⁻¹⁴ at x = 10), χ² survival to ≈ 10⁻¹⁵ for few degrees of
//! freedom and ≈ 10⁻¹² at k = 2000-3000.
//!
//! Two statrs 0.19 routes are *not* used, because they miss the tolerances the tests pin:
//! `statrs::function::erf::erfc` (and `Normal::cdf` on it) is off by up to 1.0 · 10⁻¹⁰
//! relative (x = 0.5; its interval constants are truncated to 10 digits, fixed upstream after
//! 0.19.1 in statrs-dev/statrs#412), and `ChiSquared::inverse_cdf(1 − α)` by 4.7 · 10⁻¹¹ at
//! k = 1, α = 10⁻³ (test tolerance 10⁻¹²). The quantile is therefore a bisection on the
//! survival function ([`chi2_quantile_upper`]).

use core::f64::consts::SQRT_2;

pub use estim_filters::consistency::MAX_DEGREES_OF_FREEDOM;
use statrs::function::gamma::checked_gamma_ur;

/// The complementary error function erfc(x) = 1 − erf(x), as Q(½, x²) (statrs' regularised
/// upper incomplete gamma; exact identity for x ≥ 0), and erfc(−x) = 2 − erfc(x).
/// erfc(0) = 1, erfc(∞) = 0, erfc(−∞) = 2, NaN gives NaN; underflows to 0 from x ≈ 26.6.
pub fn erfc(x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x == 0.0 {
        return 1.0;
    }
    if x == f64::INFINITY {
        return 0.0;
    }
    let x2 = x * x;
    if x2 == 0.0 {
        return 1.0; // x < 1.5e-162: erfc(x) = 1 − 2x/√π + … rounds to 1
    }
    // x² > 0, or +∞ for x > 1.3e154 (outside statrs' domain: erfc is 0 there).
    checked_gamma_ur(0.5, x2).unwrap_or(0.0)
}

/// The standard normal CDF Φ(x) = ½ erfc(−x/√2).
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * erfc(-x / SQRT_2)
}

/// P(χ²ₖ > x), the survival function of the χ² distribution with `dof` = k ≥ 1 degrees of
/// freedom: Q(k/2, x/2), statrs' regularised upper incomplete gamma function (relative error
/// ≈ 10⁻¹⁵ at k ≤ 10 and ≤ 1.3 · 10⁻¹² at k = 2000-3000 against mpmath; test `lv2_stats`).
///
/// `dof = 0` (no redundancy) gives 0 for x > 0 (χ²₀ is the point mass at 0) and 1 otherwise;
/// x ≤ 0 gives 1, x = ∞ gives 0, NaN gives NaN, and so does a `dof` above
/// [`MAX_DEGREES_OF_FREEDOM`] (where statrs drifts, and from ≈ 2⁵⁴ never returns).
pub fn chi2_sf(x: f64, dof: usize) -> f64 {
    if x.is_nan() || dof > MAX_DEGREES_OF_FREEDOM {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if dof == 0 || x == f64::INFINITY {
        return 0.0;
    }
    // a = k/2 > 0 and x/2 > 0 finite: statrs' domain, so the error arm is unreachable.
    checked_gamma_ur(0.5 * dof as f64, 0.5 * x).unwrap_or(f64::NAN)
}

/// The χ² threshold c with P(χ²ₖ > c) = `false_alarm` (0 < α < 1), by bisection on
/// [`chi2_sf`] to relative width 10⁻¹⁴. `dof = 0`, `dof` above [`MAX_DEGREES_OF_FREEDOM`] or
/// α outside (0, 1) gives NaN.
///
/// Own code rather than statrs' `ChiSquared::inverse_cdf(1 − α)`: that one inverts the CDF
/// near 1 and is off by 4.7 · 10⁻¹¹ relative at k = 1, α = 10⁻³ (measured; the test pins
/// 10⁻¹²); bisecting the survival function keeps the tail's resolution.
pub fn chi2_quantile_upper(false_alarm: f64, dof: usize) -> f64 {
    if dof == 0 || dof > MAX_DEGREES_OF_FREEDOM || !(false_alarm > 0.0 && false_alarm < 1.0) {
        return f64::NAN;
    }
    let mut hi = dof as f64 + 10.0;
    while chi2_sf(hi, dof) > false_alarm {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    while hi - lo > 1e-14 * hi {
        let mid = 0.5 * (lo + hi);
        if chi2_sf(mid, dof) > false_alarm {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// P(χ² > c) when χ² = u², u ~ N(δ, 1): the detection probability of the one-dof χ² test with
/// threshold `threshold` = c against a fault that shifts the standardised parity by δ,
/// Φ(δ − √c) + Φ(−δ − √c). δ = 0 gives the false-alarm rate.
pub fn chi2_1_power(shift: f64, threshold: f64) -> f64 {
    let s = threshold.max(0.0).sqrt();
    normal_cdf(shift - s) + normal_cdf(-shift - s)
}

/// P(χ² ≤ x) when χ² = u², u ~ N(δ, 1) (noncentral χ²₁ with noncentrality δ², CDF):
/// Φ(√x − δ) − Φ(−√x − δ).
pub fn chi2_1_cdf(x: f64, shift: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let s = x.sqrt();
    normal_cdf(s - shift) - normal_cdf(-s - shift)
}
