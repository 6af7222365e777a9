//! Static initial alignment: levelling from the accelerometer, heading from the magnetometer.

use estim_core::nalgebra::{UnitQuaternion, Vector3};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

use super::earth::NavError;

/// The attitude (body FRD → NED) of a vehicle at rest from the mean specific force `accel`
/// and the mean magnetometer reading `mag` (body frame), with `field` the earth field in NED
/// (its declination and inclination; any unit):
///
/// - levelling: at rest f = R(q)ᵀ (0, 0, −g), so roll φ = atan2(−f_y, −f_z) and pitch
///   θ = atan2(f_x, √(f_y² + f_z²));
/// - heading: the reading levelled by (φ, θ), l = R_y(θ) R_x(φ) m̃, is the field turned by
///   −ψ about the vertical, so ψ = atan2(m_E, m_N) − atan2(l_y, l_x).
///
/// Errors: [`NavError::NonFinite`] for a non-finite input, [`NavError::Degenerate`] for a
/// zero specific force or a reading or field with no horizontal component.
///
/// ```
/// use estim_core::nalgebra::{UnitQuaternion, Vector3};
/// use estim_models::nav::static_alignment;
///
/// let truth = UnitQuaternion::from_euler_angles(0.1, -0.2, 2.0);
/// let field = Vector3::new(0.19, -0.005, 0.45);
/// let accel = truth.inverse() * Vector3::new(0.0, 0.0, -9.81);
/// let mag = truth.inverse() * field;
/// let q = static_alignment(&accel, &mag, &field)?;
/// assert!(q.angle_to(&truth) < 1e-12);
/// # Ok::<(), estim_models::nav::NavError>(())
/// ```
pub fn static_alignment(
    accel: &Vector3<f64>,
    mag: &Vector3<f64>,
    field: &Vector3<f64>,
) -> Result<UnitQuaternion<f64>, NavError> {
    for (v, what) in [
        (accel, "specific force"),
        (mag, "magnetometer reading"),
        (field, "earth field"),
    ] {
        if !v.iter().all(|c| c.is_finite()) {
            return Err(NavError::NonFinite(what));
        }
    }
    if accel.norm() == 0.0 {
        return Err(NavError::Degenerate("specific force"));
    }
    let roll = (-accel[1]).atan2(-accel[2]);
    let pitch = accel[0].atan2(accel[1].hypot(accel[2]));
    let level = UnitQuaternion::from_euler_angles(roll, pitch, 0.0);
    let l = level * mag;
    if l[0].hypot(l[1]) == 0.0 {
        return Err(NavError::Degenerate("horizontal magnetometer reading"));
    }
    if field[0].hypot(field[1]) == 0.0 {
        return Err(NavError::Degenerate("horizontal earth field"));
    }
    let yaw = field[1].atan2(field[0]) - l[1].atan2(l[0]);
    Ok(UnitQuaternion::from_euler_angles(roll, pitch, yaw))
}
