//! The `heading_wrap` example in small form (40 runs × 300 steps, 4 crossings of ±π each):
//! with ⊞ the UKF and the EKF stay consistent across the crossings, without it the UKF fails.
//!
//! Thresholds. A consistent filter's per-step average NEES leaves its 99 % band on ≈ 1 % of
//! steps (more with the steps' correlation); ≤ 5 % allows for that. The worst heading error of
//! a consistent filter: its σ is ≈ 0.02 rad after the first updates, and 12 000 estimates put
//! the worst near 4.5σ; 0.2 rad is 10σ. Measured with the example's `--quick` (50 runs × 400
//! steps, same seed): 1.2 % and 0.103 rad with ⊞; without it 98.8 % of steps out of band and
//! errors of π.

use crate::heading_wrap::{Variant, monte_carlo};

const RUNS: usize = 40;
const STEPS: usize = 300;

#[test]
fn wrapped_heading_is_consistent_across_pi() {
    for variant in [Variant::WrappedUkf, Variant::WrappedEkf] {
        let s = monte_carlo(variant, RUNS, STEPS, 0x4ead).unwrap();
        assert!(
            s.outside_band <= 0.05,
            "{variant:?}: {:.3} of steps outside",
            s.outside_band
        );
        assert!(
            s.worst_heading_error < 0.2,
            "{variant:?}: {}",
            s.worst_heading_error
        );
        assert_eq!(s.out_of_range, 0, "{variant:?}");
    }
}

#[test]
fn plain_vector_heading_fails_at_the_crossings() {
    let s = monte_carlo(Variant::PlainUkf, RUNS, STEPS, 0x4ead).unwrap();
    assert!(
        s.outside_band > 0.5,
        "{:.3} of steps outside",
        s.outside_band
    );
    assert!(s.worst_heading_error > 1.0, "{}", s.worst_heading_error);
}
