//! The `attitude` example (AHRS on the quaternion error state) in small form: 30 runs × 10 s
//! (100 updates each), EKF and UKF.
//!
//! Thresholds. A consistent filter's per-update average NEES leaves its 99 % band on ≈ 1 % of
//! updates (more with their correlation): ≤ 5 %. Measured (this seed and size, the example's
//! `--quick`): 0 % for both. The reference quaternion is renormalised after every product:
//! within 4 ε of unit norm.

use crate::attitude::{Filter, monte_carlo};

#[test]
fn ahrs_ekf_and_ukf_are_consistent_and_unit() {
    for filter in [Filter::Ekf, Filter::Ukf] {
        let s = monte_carlo(filter, 30, 10.0, 0xa7).unwrap();
        assert!(
            s.outside_band <= 0.05,
            "{filter:?}: {:.3} of updates outside",
            s.outside_band
        );
        assert!(
            s.worst_norm_error <= 4.0 * f64::EPSILON,
            "{filter:?}: {:e}",
            s.worst_norm_error
        );
    }
}
