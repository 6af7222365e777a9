//! Lu's accelerometer-calibration filter (estim-models `lu`, §2.6) in `f32` over the recorded
//! GPS fixes of [`table`](super::table): from δx̂ = 0, P = M₀, [`GPS_EVERY`] predictions
//! δx̄ = Φ δx̂, M = Φ P Φᵀ + Q per fix, then the update with δz = z − (p_c, v_c), Joseph form.
//! The same code runs on the firmware and, included by path, in the host test that compares
//! the two.
//!
//! [`GPS_EVERY`]: super::table::GPS_EVERY

use estim_core::nalgebra::{Matrix2, Matrix2x3, Matrix3, U0, Vector2, Vector3};
use estim_core::{Error, Gaussian, LinearMeasurement, LinearProcess, NoInput};
use estim_filters::{Estimator, KalmanFilter, Predict, Update};

use super::table;

/// The error-state process δx⁺ = Φ δx + w, w ~ N(0, Q), with the recorded Φ and Q.
pub fn process() -> NoInput<LinearProcess<f32, estim_core::nalgebra::U3, U0>> {
    LinearProcess::without_input(
        Matrix3::from_row_slice(&table::TRANSITION),
        Matrix3::from_row_slice(&table::PROCESS_NOISE),
    )
}

/// The GPS fix as an error-state measurement: δz = H δx + η, H = \[\[1, 0, 0\], \[0, 1, 0\]\],
/// η ~ N(0, R) with the recorded R.
pub fn gps() -> LinearMeasurement<f32, estim_core::nalgebra::U3, estim_core::nalgebra::U2> {
    LinearMeasurement {
        observation: Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
        noise: Matrix2::from_row_slice(&table::GPS_NOISE),
    }
}

/// The filter at t = 0: N(0, M₀).
pub fn filter() -> Result<KalmanFilter<f32, estim_core::nalgebra::U3>, Error> {
    let prior = Matrix3::from_diagonal(&Vector3::from(table::PRIOR_VARIANCE));
    Ok(KalmanFilter::new(Gaussian::new(Vector3::zeros(), prior)?))
}

/// The whole record: the final error estimate δx̂ and its covariance P at the last fix.
pub fn run() -> Result<(Vector3<f32>, Matrix3<f32>), Error> {
    let (process, gps) = (process(), gps());
    let mut kf = filter()?;
    for fix in &table::FIXES {
        for _ in 0..table::GPS_EVERY {
            kf.predict(&process, &(), table::DT)?;
        }
        kf.update(&gps, &Vector2::from(*fix))?;
    }
    Ok((*kf.state(), *kf.covariance()))
}
