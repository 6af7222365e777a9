//! The χ² distribution (statrs): its quantiles are what the probability gate of the update
//! ([`Gate::Probability`](crate::Gate::Probability)) compares the NIS with, and the
//! consistency checks' bands and p-values are built on it. A module of its own so that the
//! gate needs nothing of the validation tooling.

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// The most degrees of freedom the crate evaluates a χ² distribution for: 2³⁶ ≈ 6.9 · 10¹⁰
/// (`usize::MAX` on 32-bit targets), beyond the NIS or NEES sums of runs (10⁷ steps of 10³
/// components) and ensembles (10⁶ runs of 10⁴). Above it statrs' regularised incomplete
/// gamma function drifts (P(a, a) off by 5 · 10⁻⁵ at a = 2³⁶ and 1.3 · 10⁻³ at 2⁴⁰, measured
/// against 1/2 + 1/(3√(2πa))), and from about 2⁵⁴ its series never ends (its counter stops
/// growing at 2⁵³).
pub const MAX_DEGREES_OF_FREEDOM: usize = if usize::BITS > 36 {
    (1u64 << 36) as usize
} else {
    usize::MAX
};

/// χ²_dof, or `None` for dof = 0 or above [`MAX_DEGREES_OF_FREEDOM`] (or a dof statrs
/// refuses).
pub(crate) fn distribution(dof: usize) -> Option<ChiSquared> {
    if dof == 0 || dof > MAX_DEGREES_OF_FREEDOM {
        return None;
    }
    ChiSquared::new(dof as f64).ok()
}

/// The `p` quantile F⁻¹(p) of χ²_dof, if it is finite; `None` for dof = 0. `p` must be in
/// (0, 1) (F⁻¹ is ∞ at 1).
pub(crate) fn quantile(dof: usize, p: f64) -> Option<f64> {
    Some(distribution(dof)?.inverse_cdf(p)).filter(|q| q.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values χ²₁(0.95) = 3.841458820694124 and χ²₂(0.99) = −2 ln 0.01 (closed
    /// form for two degrees of freedom); statrs' inversion is iterative, so agreement to a
    /// few ulps of 10⁻¹² relative is what to expect.
    #[test]
    fn quantiles_match_reference_values() {
        let q1 = quantile(1, 0.95).unwrap();
        assert!((q1 - 3.841_458_820_694_124).abs() < 1e-12 * q1);
        let q2 = quantile(2, 0.99).unwrap();
        assert!((q2 + 2.0 * 0.01f64.ln()).abs() < 1e-12 * q2);
        assert_eq!(quantile(0, 0.5), None);
        assert_eq!(quantile(3, 1.0), None);
        // Counts whose quantile statrs would take days for (its series stalls at 2⁵³).
        assert!(quantile(MAX_DEGREES_OF_FREEDOM, 0.5).is_some());
        assert_eq!(quantile(MAX_DEGREES_OF_FREEDOM + 1, 0.5), None);
        assert_eq!(quantile(usize::MAX, 0.5), None);
    }
}
