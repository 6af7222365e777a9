//! The `particle_growth` example in small form: 20 runs × 50 steps of the growth model and 4
//! runs of the range-only localisation.
//!
//! Thresholds. Measured with the example's `--quick` (40 runs, same seed): RMSE 20.1 (EKF),
//! 4.3 (bootstrap), 4.7 (auxiliary); the particle filters' RMSE sits near the posterior spread
//! (the bimodal posterior's mean is between the modes), the EKF's near the prior spread of
//! the state (≈ 15). The checks are wide orderings, not values: each particle filter's RMSE
//! below 0.6 × the EKF's (measured ratio 0.22), and below 8. Localisation: every particle-filter
//! run ends within 2 m of the truth (measured ≤ 0.7 m), every EKF run more than 10 m away
//! (measured 34–40 m: it tracks the mirror image).

use crate::particle_growth::{growth_comparison, localisation};

#[test]
fn particle_filters_beat_the_ekf_on_the_growth_model() {
    let s = growth_comparison(20, 50, 0x1993).unwrap();
    let [ekf, _, bootstrap, auxiliary] = s.rmse;
    for pf in [bootstrap, auxiliary] {
        assert!(pf < 0.6 * ekf && pf < 8.0, "{:?}", s.rmse);
    }
}

#[test]
fn the_particle_filter_escapes_the_mirror_image_and_the_ekf_does_not() {
    let [ekf, _, pf] = localisation(4, 60, 0x1993).unwrap();
    assert!(pf.iter().all(|&e| e < 2.0), "{pf:?}");
    assert!(ekf.iter().all(|&e| e > 10.0), "{ekf:?}");
}
