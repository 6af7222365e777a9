//! The navigation sensors as measurement models on the 15-state ([`super::STATE`]), with their
//! Jacobians on the attitude manifold.

use estim_core::nalgebra::{Const, Matrix1, Matrix3, SMatrix, SVector, Vector1, Vector3};
use estim_core::{MeasurementJacobian, MeasurementModel, wrap_angle};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

use super::ins::{ATTITUDE, POSITION, STATE, VELOCITY, attitude};

type State = SVector<f64, STATE>;
type N = Const<STATE>;

/// A GNSS position fix in the local NED frame (convert it with
/// [`Origin::ned`](super::Origin::ned)): z = p + v, v ~ N(0, R).
///
/// ```
/// use estim_core::MeasurementModel;
/// use estim_core::nalgebra::{Matrix3, SVector, Vector3};
/// use estim_models::nav::{GnssPosition, POSITION};
///
/// let gnss = GnssPosition { noise: Matrix3::from_diagonal(&Vector3::new(0.25, 0.25, 1.0)) };
/// let mut x = SVector::<f64, 15>::zeros();
/// x[POSITION] = 3.0;
/// assert_eq!(gnss.measure(&x), Vector3::new(3.0, 0.0, 0.0));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GnssPosition {
    /// R \[m²\].
    pub noise: Matrix3<f64>,
}

/// A GNSS velocity in NED (from speed, course and vertical speed:
/// v = (s cos χ, s sin χ, v_D)): z = v + v, v ~ N(0, R).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GnssVelocity {
    /// R \[(m/s)²\].
    pub noise: Matrix3<f64>,
}

/// A barometric height above the origin: z = −p_D + v, v ~ N(0, σ²) (subtract the height at
/// the origin first).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaroHeight {
    /// σ² \[m²\].
    pub variance: f64,
}

/// A 3-axis magnetometer: z = R(q)ᵀ m + v, m the earth field in NED (any unit, the same as z),
/// v ~ N(0, R).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Magnetometer {
    /// m in NED.
    pub field: Vector3<f64>,
    /// R.
    pub noise: Matrix3<f64>,
}

/// A heading (yaw) ψ = atan2(R₁₀, R₀₀) of R(q) body → NED \[rad\], with a wrapped residual:
/// z = ψ + v, v ~ N(0, σ²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Heading {
    /// σ² \[rad²\].
    pub variance: f64,
}

/// The rows of a block-selection Jacobian: I at `at`.
fn select(at: usize) -> SMatrix<f64, 3, STATE> {
    let mut h = SMatrix::<f64, 3, STATE>::zeros();
    h.fixed_view_mut::<3, 3>(0, at)
        .copy_from(&Matrix3::identity());
    h
}

impl MeasurementModel<f64, N, Const<3>> for GnssPosition {
    fn measure(&self, x: &State) -> Vector3<f64> {
        x.fixed_rows::<3>(POSITION).into_owned()
    }
    fn measurement_noise(&self, _: &State) -> Matrix3<f64> {
        self.noise
    }
}

impl MeasurementJacobian<f64, N, Const<3>> for GnssPosition {
    fn measurement_jacobian(&self, _: &State) -> SMatrix<f64, 3, STATE> {
        select(POSITION)
    }
}

impl MeasurementModel<f64, N, Const<3>> for GnssVelocity {
    fn measure(&self, x: &State) -> Vector3<f64> {
        x.fixed_rows::<3>(VELOCITY).into_owned()
    }
    fn measurement_noise(&self, _: &State) -> Matrix3<f64> {
        self.noise
    }
}

impl MeasurementJacobian<f64, N, Const<3>> for GnssVelocity {
    fn measurement_jacobian(&self, _: &State) -> SMatrix<f64, 3, STATE> {
        select(VELOCITY)
    }
}

impl MeasurementModel<f64, N, Const<1>> for BaroHeight {
    fn measure(&self, x: &State) -> Vector1<f64> {
        Vector1::new(-x[POSITION + 2])
    }
    fn measurement_noise(&self, _: &State) -> Matrix1<f64> {
        Matrix1::new(self.variance)
    }
}

impl MeasurementJacobian<f64, N, Const<1>> for BaroHeight {
    fn measurement_jacobian(&self, _: &State) -> SMatrix<f64, 1, STATE> {
        let mut h = SMatrix::<f64, 1, STATE>::zeros();
        h[POSITION + 2] = -1.0;
        h
    }
}

impl MeasurementModel<f64, N, Const<3>> for Magnetometer {
    fn measure(&self, x: &State) -> Vector3<f64> {
        attitude(x).inverse() * self.field
    }
    fn measurement_noise(&self, _: &State) -> Matrix3<f64> {
        self.noise
    }
}

impl MeasurementJacobian<f64, N, Const<3>> for Magnetometer {
    /// (R Exp(δθ))ᵀ m ≈ Rᵀm + \[Rᵀm\]× δθ.
    fn measurement_jacobian(&self, x: &State) -> SMatrix<f64, 3, STATE> {
        let mut h = SMatrix::<f64, 3, STATE>::zeros();
        h.fixed_view_mut::<3, 3>(0, ATTITUDE)
            .copy_from(&self.measure(x).cross_matrix());
        h
    }
}

impl MeasurementModel<f64, N, Const<1>> for Heading {
    fn measure(&self, x: &State) -> Vector1<f64> {
        let r = attitude(x).to_rotation_matrix().into_inner();
        Vector1::new(r[(1, 0)].atan2(r[(0, 0)]))
    }
    fn measurement_noise(&self, _: &State) -> Matrix1<f64> {
        Matrix1::new(self.variance)
    }
    /// Wrapped to (−π, π].
    fn residual_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
        *out = Vector1::new(wrap_angle(a[0] - b[0]));
    }
}

impl MeasurementJacobian<f64, N, Const<1>> for Heading {
    /// c = R e₀ moves by −R \[e₀\]× δθ, and dψ = (c₀ dc₁ − c₁ dc₀) / (c₀² + c₁²).
    fn measurement_jacobian(&self, x: &State) -> SMatrix<f64, 1, STATE> {
        let r = attitude(x).to_rotation_matrix().into_inner();
        let g = -(r * Vector3::x().cross_matrix());
        let (c0, c1) = (r[(0, 0)], r[(1, 0)]);
        let row = (g.row(1) * c0 - g.row(0) * c1) / (c0 * c0 + c1 * c1);
        let mut h = SMatrix::<f64, 1, STATE>::zeros();
        h.fixed_view_mut::<1, 3>(0, ATTITUDE).copy_from(&row);
        h
    }
}
