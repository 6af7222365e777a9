//! Consider (Schmidt) states: carried in the state and the covariance, never corrected.
//!
//! Split the state into estimated states a and consider states c (biases, offsets whose
//! uncertainty must be accounted for but which the filter must not adjust, e.g. because the
//! measurements cannot separate them). The Schmidt-Kalman update takes the optimal gain for a
//! and none for c, K = [K_a; 0], K_a = (Pₓᵤ S⁻¹)_a, and the covariance of that (suboptimal)
//! gain, the general Joseph form P⁺ = P − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ. By blocks:
//!
//! ```text
//! a⁺ = a + K_a ν                   c⁺ = c
//! P⁺_aa = P_aa − K_a S K_aᵀ        P⁺_ac = P_ac − K_a S K_cᵀ        P⁺_cc = P_cc
//! ```
//!
//! with K_c = (Pₓᵤ S⁻¹)_c the gain a full update would give c. The a-rows and the cross block
//! are those of the full Kalman update (K_a is the same, and P⁺_ac reduces to
//! P_ac − K_a (Pₓᵤ)_cᵀ = P_ac − K_a S K_cᵀ): so [`schmidt_update`] runs the filter's own update
//! and puts back c and P_cc. This holds for every moment propagator (the algebra uses only
//! Pₓᵤ and S), and the result is a valid covariance (that of the Schmidt gain's error).

use estim_core::nalgebra::{DefaultAllocator, Dim, OVector};
use estim_core::{Alloc, Gaussian, Real, error::Result};

use crate::report::{UpdateOutcome, UpdateReport};
use crate::traits::{Rollback, Update};

/// Updates `filter` with `z`, leaving the components listed in `consider` (and their
/// covariance block) as they were: the Schmidt-Kalman consider update of the
/// [module docs](self). The report is the full update's (the same ν, S, NIS and likelihood).
///
/// For the filters whose estimate is one Gaussian that [`Estimator::reset`](crate::Estimator::reset)
/// restores entirely (the Kalman family, square-root forms included; the square-root factor
/// is refactorised from the Schmidt covariance).
///
/// # Errors
///
/// The filter's update errors, or the Schmidt covariance failing [`Gaussian::new`]'s checks;
/// on error the filter is exactly as it was.
///
/// # Panics
///
/// If an index in `consider` is not a state component (a programmer error).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement};
/// use estim_filters::consider::schmidt_update;
/// use estim_filters::{Estimator, KalmanFilter};
///
/// // z = a + c: the measurement cannot separate a from the offset c, which we only consider.
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 1.0), noise: Matrix1::new(0.1) };
/// let prior = Gaussian::new(Vector2::new(0.0, 0.5), Matrix2::new(1.0, 0.0, 0.0, 0.25))?;
/// let mut kf = KalmanFilter::new(prior);
/// schmidt_update(&mut kf, &sensor, &Vector1::new(2.0), &[1])?;
/// assert_eq!(kf.state()[1], 0.5); // c not corrected
/// assert_eq!(kf.covariance()[(1, 1)], 0.25); // nor its variance
/// assert!(kf.covariance()[(0, 1)] < 0.0); // but a's error is now correlated with it
/// # Ok::<(), estim_core::Error>(())
/// ```
#[track_caller]
pub fn schmidt_update<T, N, M, H, F>(
    filter: &mut F,
    model: &H,
    z: &OVector<T, M>,
    consider: &[usize],
) -> Result<UpdateReport<T, M>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: ?Sized,
    F: Update<T, N, M, H> + Rollback,
    DefaultAllocator: Alloc<N, M>,
{
    let n = filter.state().nrows();
    for &c in consider {
        assert!(
            c < n,
            "consider index {c} is not a component of the {n}-state"
        );
    }
    let (x0, p0) = (filter.state().clone(), filter.covariance().clone());
    let saved = filter.snapshot();
    let report = filter.update(model, z)?;
    if report.outcome != UpdateOutcome::Applied || consider.is_empty() {
        return Ok(report);
    }
    let mut x = filter.state().clone();
    let mut p = filter.covariance().clone();
    for &i in consider {
        x[i] = x0[i];
        for &j in consider {
            p[(i, j)] = p0[(i, j)];
        }
    }
    match Gaussian::new(x, p) {
        Ok(posterior) => {
            filter.reset(posterior);
            Ok(report)
        }
        Err(e) => {
            filter.restore(&saved);
            Err(e)
        }
    }
}
