//! Rotations over a generic scalar, for models written once for [`AutoDiff`](super::AutoDiff)
//! (attitude measurements about an [`AttitudeReference`](crate::manifold::AttitudeReference)).

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::{AdReal, AdScalar};

/// R(Exp(v)) = I + a \[v\]× + b \[v\]×², a = sin θ / θ, b = 2 sin²(θ/2) / θ², θ = |v|: the
/// rotation matrix of the rotation vector v (Rodrigues), for any scalar.
///
/// Smooth at v = 0 to every order the duals see: below θ² = 10⁻⁶ it uses the series
/// a = 1 − θ²/6 + θ⁴/120, b = ½ − θ²/24 + θ⁴/720 (the next terms are < 10⁻²⁰), so Jacobians
/// and Hessians at a recentred error state (v = 0) are exact.
///
/// ```
/// use estim_core::autodiff::rotation_exp;
/// use estim_core::manifold::so3_exp;
/// use estim_core::nalgebra::Vector3;
///
/// let v = Vector3::new(0.3, -1.2, 2.0);
/// let r = rotation_exp::<f64, f64>(&v);
/// assert!((r - so3_exp(&v).to_rotation_matrix().into_inner()).norm() < 1e-14);
/// ```
pub fn rotation_exp<T: AdReal, D: AdScalar<T>>(v: &Vector3<D>) -> Matrix3<D> {
    let theta2 = v.dot(v);
    let (a, b) = if theta2.re() < T::narrow(1e-6) {
        let t4 = theta2 * theta2;
        (
            D::one() - theta2 / T::narrow(6.0) + t4 / T::narrow(120.0),
            D::from(T::narrow(0.5)) - theta2 / T::narrow(24.0) + t4 / T::narrow(720.0),
        )
    } else {
        let theta = theta2.sqrt();
        let s = (theta * T::narrow(0.5)).sin();
        (theta.sin() / theta, s * s * T::narrow(2.0) / theta2)
    };
    let k = Matrix3::new(
        D::zero(),
        -v[2],
        v[1],
        v[2],
        D::zero(),
        -v[0],
        -v[1],
        v[0],
        D::zero(),
    );
    let k2 = k * k;
    Matrix3::identity() + k * a + k2 * b
}

/// R(q) as a matrix over the scalar `D` (for a reference attitude in a generic model).
pub fn rotation_matrix<T: AdReal, D: AdScalar<T>>(q: &UnitQuaternion<T>) -> Matrix3<D> {
    q.to_rotation_matrix().into_inner().map(D::from)
}
