//! The few distribution functions the consistency test needs: erfc, the normal CDF, the χ²
//! survival function and quantile for integer degrees of freedom, and the power of the
//! one-degree-of-freedom test against a mean shift.
//!
//! Accuracy (f64): erfc to ≈ 10⁻¹³ relative over x ≥ 0 (test `lv2_stats::erfc_matches_reference`),
//! χ² survival to ≈ 10⁻¹³ for few degrees of freedom, ≈ 5 · 10⁻¹² at 2000 (finite sums, exact
//! for integer dof, summed through logarithms; see [`chi2_sf`]).

use core::f64::consts::{FRAC_2_SQRT_PI, PI, SQRT_2};

/// The complementary error function erfc(x) = 1 − erf(x).
///
/// For 0 ≤ x < 2.5 the everywhere-positive series erf(x) = (2/√π) e^{−x²} Σ 2ⁿ x^{2n+1} /
/// (1·3···(2n+1)) (no cancellation); for x ≥ 2.5 the continued fraction
/// erfc(x) = e^{−x²}/√π · 1/(x + ½/(x + 1/(x + (3/2)/(x + …)))) evaluated backwards from depth
/// 120; erfc(−x) = 2 − erfc(x). NaN gives NaN.
pub fn erfc(x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x < 2.5 {
        let x2 = x * x;
        let mut term = x;
        let mut sum = x;
        let mut n = 0.0;
        while term > sum * 1e-17 {
            term *= 2.0 * x2 / (2.0 * n + 3.0);
            sum += term;
            n += 1.0;
        }
        1.0 - FRAC_2_SQRT_PI * (-x2).exp() * sum
    } else if x > 27.3 {
        0.0 // below the smallest subnormal
    } else {
        let mut f = x;
        for k in (1..=120).rev() {
            f = x + 0.5 * k as f64 / f;
        }
        (-x * x).exp() / (PI.sqrt() * f)
    }
}

/// The standard normal CDF Φ(x) = ½ erfc(−x/√2).
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * erfc(-x / SQRT_2)
}

/// P(χ²ₖ > x), the survival function of the χ² distribution with `dof` = k ≥ 1 degrees of
/// freedom, by the finite sums of the regularised incomplete gamma function at half-integer
/// order (h = x/2):
///
/// ```text
/// k even:  e^{−h} Σ_{j<k/2} hʲ/j!
/// k odd:   erfc(√h) + e^{−h} Σ_{j=0}^{(k−3)/2} h^{j+½}/Γ(j+3/2)
/// ```
///
/// The terms are summed through their logarithms, relative to the largest: e^{−h} alone
/// underflows from x ≈ 1490, where for k ≳ 1300 the sum is still of order one. The rounding
/// of the logarithms' recursion grows with k and x (relative error ≈ 10⁻¹⁴ at k ≤ 10,
/// ≈ 5 · 10⁻¹² at k = 2000 and 10⁻¹¹ at k = 3000 against mpmath; test `lv2_stats`).
///
/// `dof = 0` (no redundancy) gives 0 for x > 0 (χ²₀ is the point mass at 0) and 1 otherwise;
/// x ≤ 0 gives 1, x = ∞ gives 0.
pub fn chi2_sf(x: f64, dof: usize) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if dof == 0 || x == f64::INFINITY {
        return 0.0;
    }
    let h = 0.5 * x;
    let ln_h = h.ln();
    // tⱼ = tⱼ₋₁ · h/(j + s) from t₀: s = 0, t₀ = e^{−h} (k even); s = ½, t₀ = e^{−h} √h / Γ(3/2)
    // with Γ(3/2) = √π/2, after the erfc head (k odd).
    let (count, shift, ln_first, head) = if dof.is_multiple_of(2) {
        (dof / 2, 0.0, -h, 0.0)
    } else {
        let ln_first = -h + 0.5 * ln_h - (0.5 * PI.sqrt()).ln();
        ((dof - 1) / 2, 0.5, ln_first, erfc(h.sqrt()))
    };
    // One pass: Σ tⱼ = e^{largest} · scaled, rescaled whenever a larger term arrives (no
    // terms: e^{−∞} · 0 = 0).
    let (mut largest, mut scaled, mut ln_t) = (f64::NEG_INFINITY, 0.0, ln_first);
    for j in 0..count {
        if j > 0 {
            ln_t += ln_h - (j as f64 + shift).ln();
        }
        if ln_t > largest {
            scaled = scaled * (largest - ln_t).exp() + 1.0;
            largest = ln_t;
        } else {
            scaled += (ln_t - largest).exp();
        }
    }
    let sum = largest.exp() * scaled;
    (head + sum).min(1.0)
}

/// The χ² threshold c with P(χ²ₖ > c) = `false_alarm` (0 < α < 1), by bisection on
/// [`chi2_sf`] to relative width 10⁻¹⁴. `dof = 0` or α outside (0, 1) gives NaN.
pub fn chi2_quantile_upper(false_alarm: f64, dof: usize) -> f64 {
    if dof == 0 || !(false_alarm > 0.0 && false_alarm < 1.0) {
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
