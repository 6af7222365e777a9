//! Rotations over a generic scalar, for models written once for [`AutoDiff`](super::AutoDiff)
//! (attitude measurements about an [`AttitudeReference`](crate::manifold::AttitudeReference),
//! error-state transitions on the quaternion manifold).
//!
//! [`so3_exp`] and [`so3_log`] are the twins of [`manifold::so3_exp`](crate::manifold::so3_exp)
//! and [`manifold::so3_log`](crate::manifold::so3_log) for any [`AdScalar`]: the same values
//! on `T` (to rounding), exact derivatives on duals, also at the identity. nalgebra's
//! quaternion arithmetic needs its `RealField`, which the dual numbers do not implement, so
//! the quaternions here are plain [`Quaternion`] values (coordinates `(i, j, k, w)` in
//! `coords`) handled by [`quaternion_product`], [`quaternion_conjugate`],
//! [`quaternion_rotate`] and [`quaternion_lift`].

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

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

/// Exp(v) = (cos ½θ, sin ½θ · v/θ), θ = |v|: the unit quaternion of the rotation vector v,
/// for any scalar (see [`manifold::so3_exp`](crate::manifold::so3_exp)).
///
/// Smooth at v = 0 to every order the duals see: below θ² = 10⁻⁶ it uses the series
/// cos ½θ = 1 − θ²/8 + θ⁴/384 and sin ½θ / θ = ½ − θ²/48 + θ⁴/3840 (the next terms are
/// below 10⁻²⁰), so Jacobians and Hessians at v = 0 are exact.
///
/// ```
/// use estim_core::autodiff::{AdScalar, AutoDiff, AutoDiffFunction, quaternion_rotate, so3_exp};
/// use estim_core::nalgebra::{U3, Vector3};
/// use estim_core::Differentiable;
///
/// /// The body-frame field b = R(Exp(δθ))ᵀ m for an attitude error δθ.
/// struct Field(Vector3<f64>);
/// impl AutoDiffFunction<f64, U3, U3> for Field {
///     fn eval<D: AdScalar<f64>>(&self, x: &Vector3<D>) -> Vector3<D> {
///         let q = so3_exp::<f64, D>(x);
///         let inverse = estim_core::autodiff::quaternion_conjugate(&q);
///         quaternion_rotate(&inverse, &self.0.map(D::from))
///     }
/// }
/// let m = Vector3::new(0.2, -0.1, 0.45);
/// // ∂b/∂δθ at δθ = 0 is [m]×.
/// let j = AutoDiff::new(Field(m)).jacobian(&Vector3::zeros());
/// assert!((j - m.cross_matrix()).norm() < 1e-15);
/// ```
pub fn so3_exp<T: AdReal, D: AdScalar<T>>(v: &Vector3<D>) -> Quaternion<D> {
    let theta2 = v.dot(v);
    let (w, k) = if theta2.re() < T::narrow(1e-6) {
        let t4 = theta2 * theta2;
        (
            D::one() - theta2 / T::narrow(8.0) + t4 / T::narrow(384.0),
            D::from(T::narrow(0.5)) - theta2 / T::narrow(48.0) + t4 / T::narrow(3840.0),
        )
    } else {
        let theta = theta2.sqrt();
        let (s, c) = (theta * T::narrow(0.5)).sin_cos();
        (c, s / theta)
    };
    Quaternion::new(w, v[0] * k, v[1] * k, v[2] * k)
}

/// Log(q): the rotation vector of the unit quaternion q (angle in \[0, π\]; q and −q give the
/// same vector), for any scalar: v = 2 atan2(s, w) / s · (x, y, z), s = |(x, y, z)|, after
/// flipping q to w ≥ 0 (see [`manifold::so3_log`](crate::manifold::so3_log)).
///
/// Smooth at the identity: below s² = 10⁻⁶ w² it uses the series
/// 2 atan(s/w) / s = (2/w)(1 − r/3 + r²/5), r = s²/w² (the next term is below 10⁻¹⁸).
///
/// ```
/// use estim_core::autodiff::{quaternion_product, so3_exp, so3_log};
/// use estim_core::nalgebra::Vector3;
///
/// let (a, b) = (Vector3::new(0.3, -1.2, 2.0), Vector3::new(0.0, 0.1, 0.0));
/// let v = so3_log::<f64, f64>(&so3_exp::<f64, f64>(&a));
/// assert!((v - a).norm() < 1e-14);
/// let ab = so3_log::<f64, f64>(&quaternion_product(&so3_exp(&a), &so3_exp(&b)));
/// let want = estim_core::manifold::so3_log(
///     &(estim_core::manifold::so3_exp(&a) * estim_core::manifold::so3_exp(&b)),
/// );
/// assert!((ab - want).norm() < 1e-14);
/// ```
pub fn so3_log<T: AdReal, D: AdScalar<T>>(q: &Quaternion<D>) -> Vector3<D> {
    let (mut w, mut v) = (
        q.coords[3],
        Vector3::new(q.coords[0], q.coords[1], q.coords[2]),
    );
    if w.re() < T::zero() {
        w = -w;
        v = -v;
    }
    let s2 = v.dot(&v);
    let w2 = w * w;
    let scale = if s2.re() < T::narrow(1e-6) * w2.re() {
        let r = s2 / w2;
        (D::one() - r / T::narrow(3.0) + r * r / T::narrow(5.0)) * T::narrow(2.0) / w
    } else {
        let s = s2.sqrt();
        s.atan2(w) * T::narrow(2.0) / s
    };
    v * scale
}

/// The Hamilton product a ⊗ b, for any scalar.
pub fn quaternion_product<T: AdReal, D: AdScalar<T>>(
    a: &Quaternion<D>,
    b: &Quaternion<D>,
) -> Quaternion<D> {
    let (a, b) = (&a.coords, &b.coords);
    let (ax, ay, az, aw) = (a[0], a[1], a[2], a[3]);
    let (bx, by, bz, bw) = (b[0], b[1], b[2], b[3]);
    Quaternion::new(
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )
}

/// The conjugate q* = (w, −x, −y, −z): the inverse of a unit quaternion.
pub fn quaternion_conjugate<T: AdReal, D: AdScalar<T>>(q: &Quaternion<D>) -> Quaternion<D> {
    let c = &q.coords;
    Quaternion::new(c[3], -c[0], -c[1], -c[2])
}

/// R(q) v = q ⊗ (0, v) ⊗ q* for a unit quaternion q, as v + 2w (u × v) + 2 u × (u × v),
/// u = (x, y, z).
pub fn quaternion_rotate<T: AdReal, D: AdScalar<T>>(
    q: &Quaternion<D>,
    v: &Vector3<D>,
) -> Vector3<D> {
    let c = &q.coords;
    let u = Vector3::new(c[0], c[1], c[2]);
    let t = u.cross(v) * D::from(T::narrow(2.0));
    v + t * c[3] + u.cross(&t)
}

/// A quaternion over `T` (a reference attitude, say) as a constant over the scalar `D`.
pub fn quaternion_lift<T: AdReal, D: AdScalar<T>>(q: &UnitQuaternion<T>) -> Quaternion<D> {
    let c = &q.as_ref().coords;
    Quaternion::new(D::from(c[3]), D::from(c[0]), D::from(c[1]), D::from(c[2]))
}
