//! The position, range and bearing sensors (see the [module docs](super)).

use estim_core::nalgebra::{Const, SMatrix, SVector, U1, U2, Vector1, Vector2};
use estim_core::{
    LinearMeasurementModel, MeasurementHessian, MeasurementJacobian, MeasurementModel, Real,
    wrap_angle,
};

/// Checked at compile time: the state holds a D-dimensional position.
const fn assert_position_fits(d: usize, n: usize) {
    assert!(d <= n, "the state is shorter than the sensor's position");
}

/// A position fix: z = (x₀, …, x_{D−1}) + v, v ~ N(0, R). Linear.
///
/// ```
/// use estim_core::nalgebra::{Matrix2, Vector2, Vector4};
/// use estim_core::{MeasurementJacobian, MeasurementModel};
/// use estim_models::sensors::Position;
///
/// let gps = Position::<f64, 2> { noise: Matrix2::identity() * 4.0 };
/// let x = Vector4::new(1.0, 2.0, 3.0, 4.0);
/// assert_eq!(gps.measure(&x), Vector2::new(1.0, 2.0));
/// assert_eq!(gps.measurement_jacobian(&x)[(1, 1)], 1.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Position<T, const D: usize> {
    /// R, the fix's noise covariance.
    pub noise: SMatrix<T, D, D>,
}

impl<T: Real, const D: usize, const N: usize> MeasurementModel<T, Const<N>, Const<D>>
    for Position<T, D>
{
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, D> {
        const { assert_position_fits(D, N) };
        x.fixed_rows::<D>(0).into_owned()
    }

    fn measurement_noise(&self, _: &SVector<T, N>) -> SMatrix<T, D, D> {
        self.noise
    }
}

impl<T: Real, const D: usize, const N: usize> MeasurementJacobian<T, Const<N>, Const<D>>
    for Position<T, D>
{
    fn measurement_jacobian(&self, _: &SVector<T, N>) -> SMatrix<T, D, N> {
        const { assert_position_fits(D, N) };
        SMatrix::identity()
    }
}

impl<T: Real, const D: usize, const N: usize> MeasurementHessian<T, Const<N>, Const<D>>
    for Position<T, D>
{
    fn measurement_hessian(&self, _: &SVector<T, N>, _: usize) -> Option<SMatrix<T, N, N>> {
        None
    }
}

impl<T: Real, const D: usize, const N: usize> LinearMeasurementModel<T, Const<N>, Const<D>>
    for Position<T, D>
{
}

/// The range to a known point o: r = ‖p − o‖, p the first D components of the state.
///
/// ```text
/// ∂r/∂p = (p − o)ᵀ / r,    ∂²r/∂p² = (I − u uᵀ) / r,   u = (p − o)/r
/// ```
///
/// ```
/// use estim_core::nalgebra::{Vector1, Vector2, Vector4};
/// use estim_core::{MeasurementJacobian, MeasurementModel};
/// use estim_models::sensors::Range;
///
/// let beacon = Range { origin: Vector2::new(1.0, 1.0), variance: 0.01 };
/// let x = Vector4::new(4.0, 5.0, 0.0, 0.0);
/// assert_eq!(beacon.measure(&x), Vector1::new(5.0));
/// assert_eq!(beacon.measurement_jacobian(&x)[(0, 1)], 0.8);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range<T, const D: usize> {
    /// o, the sensor's (or beacon's) position.
    pub origin: SVector<T, D>,
    /// σ², the range noise variance, m².
    pub variance: T,
}

/// p − o and its norm.
fn offset<T: Real, const D: usize, const N: usize>(
    x: &SVector<T, N>,
    origin: &SVector<T, D>,
) -> (SVector<T, D>, T) {
    const { assert_position_fits(D, N) };
    let d = x.fixed_rows::<D>(0) - origin;
    let r = d.norm();
    (d, r)
}

/// ∂r/∂x (zero at r = 0).
fn range_gradient<T: Real, const D: usize, const N: usize>(
    d: &SVector<T, D>,
    r: T,
) -> SMatrix<T, 1, N> {
    let mut j = SMatrix::<T, 1, N>::zeros();
    if r > T::zero() {
        for i in 0..D {
            j[i] = d[i] / r;
        }
    }
    j
}

/// ∂²r/∂x² (zero at r = 0).
fn range_hessian<T: Real, const D: usize, const N: usize>(
    d: &SVector<T, D>,
    r: T,
) -> SMatrix<T, N, N> {
    let mut h = SMatrix::<T, N, N>::zeros();
    if r > T::zero() {
        let r3 = r * r * r;
        for i in 0..D {
            for j in 0..D {
                let identity = if i == j { r * r } else { T::zero() };
                h[(i, j)] = (identity - d[i] * d[j]) / r3;
            }
        }
    }
    h
}

/// (β, ∂β/∂x, and the three second derivatives (xx, xy, yy)) of the bearing (zero
/// derivatives at p = o).
fn bearing_parts<T: Real, const N: usize>(
    x: &SVector<T, N>,
    origin: &Vector2<T>,
) -> (T, SMatrix<T, 1, N>, [T; 3]) {
    let (d, _) = offset::<T, 2, N>(x, origin);
    let r2 = d.norm_squared();
    let beta = d[1].atan2(d[0]);
    let mut j = SMatrix::<T, 1, N>::zeros();
    let mut second = [T::zero(); 3];
    if r2 > T::zero() {
        j[0] = -d[1] / r2;
        j[1] = d[0] / r2;
        let r4 = r2 * r2;
        let two = T::one() + T::one();
        second = [
            two * d[0] * d[1] / r4,
            (d[1] * d[1] - d[0] * d[0]) / r4,
            -two * d[0] * d[1] / r4,
        ];
    }
    (beta, j, second)
}

fn bearing_hessian<T: Real, const N: usize>(second: [T; 3]) -> SMatrix<T, N, N> {
    let mut h = SMatrix::<T, N, N>::zeros();
    h[(0, 0)] = second[0];
    h[(0, 1)] = second[1];
    h[(1, 0)] = second[1];
    h[(1, 1)] = second[2];
    h
}

impl<T: Real, const D: usize, const N: usize> MeasurementModel<T, Const<N>, U1> for Range<T, D> {
    fn measure(&self, x: &SVector<T, N>) -> Vector1<T> {
        Vector1::new(offset(x, &self.origin).1)
    }

    fn measurement_noise(&self, _: &SVector<T, N>) -> SMatrix<T, 1, 1> {
        SMatrix::<T, 1, 1>::new(self.variance)
    }
}

impl<T: Real, const D: usize, const N: usize> MeasurementJacobian<T, Const<N>, U1> for Range<T, D> {
    fn measurement_jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 1, N> {
        let (d, r) = offset(x, &self.origin);
        range_gradient(&d, r)
    }
}

impl<T: Real, const D: usize, const N: usize> MeasurementHessian<T, Const<N>, U1> for Range<T, D> {
    fn measurement_hessian(&self, x: &SVector<T, N>, _: usize) -> Option<SMatrix<T, N, N>> {
        let (d, r) = offset(x, &self.origin);
        Some(range_hessian(&d, r))
    }
}

/// The bearing from a known point o in the plane: β = atan2(y − o_y, x − o_x) (rad,
/// counter-clockwise from the x axis), the residual wrapped into (−π, π].
///
/// ```text
/// ∂β/∂(x, y) = (−Δy, Δx)/r²,   ∂²β/∂x² = 2ΔxΔy/r⁴ = −∂²β/∂y²,   ∂²β/∂x∂y = (Δy² − Δx²)/r⁴
/// ```
///
/// ```
/// use estim_core::nalgebra::{U1, U3, Vector1, Vector2, Vector3};
/// use estim_core::MeasurementModel;
/// use estim_models::sensors::Bearing;
///
/// let sensor = Bearing { origin: Vector2::zeros(), variance: 1e-4 };
/// assert_eq!(sensor.measure(&Vector3::new(0.0, 2.0, 0.0)), Vector1::new(std::f64::consts::FRAC_PI_2));
/// // 179° and −179° are 2° apart. (Called directly, the residual names the state size: the
/// // sensor serves any.)
/// let mut r = Vector1::zeros();
/// MeasurementModel::<f64, U3, U1>::residual_into(&sensor, &Vector1::new(179f64.to_radians()), &Vector1::new(-179f64.to_radians()), &mut r);
/// assert!((r[0] + 2f64.to_radians()).abs() < 1e-12);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bearing<T> {
    /// o, the sensor's position.
    pub origin: Vector2<T>,
    /// σ², the bearing noise variance, rad².
    pub variance: T,
}

impl<T: Real, const N: usize> MeasurementModel<T, Const<N>, U1> for Bearing<T> {
    fn measure(&self, x: &SVector<T, N>) -> Vector1<T> {
        Vector1::new(bearing_parts(x, &self.origin).0)
    }

    fn measurement_noise(&self, _: &SVector<T, N>) -> SMatrix<T, 1, 1> {
        SMatrix::<T, 1, 1>::new(self.variance)
    }

    fn residual_into(&self, a: &Vector1<T>, b: &Vector1<T>, out: &mut Vector1<T>) {
        *out = Vector1::new(wrap_angle(a[0] - b[0]));
    }
}

impl<T: Real, const N: usize> MeasurementJacobian<T, Const<N>, U1> for Bearing<T> {
    fn measurement_jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 1, N> {
        bearing_parts(x, &self.origin).1
    }
}

impl<T: Real, const N: usize> MeasurementHessian<T, Const<N>, U1> for Bearing<T> {
    fn measurement_hessian(&self, x: &SVector<T, N>, _: usize) -> Option<SMatrix<T, N, N>> {
        Some(bearing_hessian(bearing_parts(x, &self.origin).2))
    }
}

/// Range and bearing from a known point o in the plane: z = (‖p − o‖, atan2(Δy, Δx)), with
/// independent noises; the bearing component of the residual is wrapped. The derivatives are
/// those of [`Range`] and [`Bearing`], row by row.
///
/// ```
/// use estim_core::nalgebra::{Vector2, Vector4};
/// use estim_core::MeasurementModel;
/// use estim_models::sensors::RangeBearing;
///
/// let radar = RangeBearing { origin: Vector2::zeros(), range_variance: 1.0, bearing_variance: 1e-4 };
/// let z = radar.measure(&Vector4::new(3.0, 3.0, 0.0, 0.0));
/// assert!((z - Vector2::new(18f64.sqrt(), std::f64::consts::FRAC_PI_4)).amax() < 1e-15);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeBearing<T> {
    /// o, the sensor's position.
    pub origin: Vector2<T>,
    /// σ_r², the range noise variance, m².
    pub range_variance: T,
    /// σ_β², the bearing noise variance, rad².
    pub bearing_variance: T,
}

impl<T: Real, const N: usize> MeasurementModel<T, Const<N>, U2> for RangeBearing<T> {
    fn measure(&self, x: &SVector<T, N>) -> Vector2<T> {
        Vector2::new(offset(x, &self.origin).1, bearing_parts(x, &self.origin).0)
    }

    fn measurement_noise(&self, _: &SVector<T, N>) -> SMatrix<T, 2, 2> {
        SMatrix::<T, 2, 2>::new(
            self.range_variance,
            T::zero(),
            T::zero(),
            self.bearing_variance,
        )
    }

    fn residual_into(&self, a: &Vector2<T>, b: &Vector2<T>, out: &mut Vector2<T>) {
        *out = Vector2::new(a[0] - b[0], wrap_angle(a[1] - b[1]));
    }
}

impl<T: Real, const N: usize> MeasurementJacobian<T, Const<N>, U2> for RangeBearing<T> {
    fn measurement_jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 2, N> {
        let (d, r) = offset(x, &self.origin);
        let mut j = SMatrix::<T, 2, N>::zeros();
        j.set_row(0, &range_gradient(&d, r));
        j.set_row(1, &bearing_parts(x, &self.origin).1);
        j
    }
}

impl<T: Real, const N: usize> MeasurementHessian<T, Const<N>, U2> for RangeBearing<T> {
    fn measurement_hessian(&self, x: &SVector<T, N>, k: usize) -> Option<SMatrix<T, N, N>> {
        match k {
            0 => {
                let (d, r) = offset(x, &self.origin);
                Some(range_hessian(&d, r))
            }
            _ => Some(bearing_hessian(bearing_parts(x, &self.origin).2)),
        }
    }
}
