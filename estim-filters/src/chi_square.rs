//! The χ² distribution (statrs): its quantiles are what the probability gate of the update
//! ([`Gate::Probability`](crate::Gate::Probability)) compares the NIS with, and the
//! consistency checks' bands and p-values are built on it. A module of its own so that the
//! gate needs nothing of the validation tooling.

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// χ²_dof, or `None` for dof = 0 (or a dof statrs refuses).
pub(crate) fn distribution(dof: usize) -> Option<ChiSquared> {
    if dof == 0 {
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
    }
}
