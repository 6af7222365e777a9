//! The filters whose footprint `docs/embedded.md` lists: EKF, UKF and square-root UKF (cubature sigma points,
//! whose weights are all positive, so f32 loses nothing to a large negative centre weight) on
//!
//! - 3 states, 2 measurements: Lu's error-state model of [`lu`](super::lu);
//! - 6 states, 4 measurements: the same model on two independent axes (Φ, Q, H, R block
//!   diagonal, two GPS fixes per update), the size of a planar navigation filter.
//!
//! Both models are linear, so both filters estimate the same thing as the Kalman filter; what
//! differs, and what the footprint measures, is the code and the stack of each propagator.

use estim_core::nalgebra::{
    Const, DefaultAllocator, Dim, Matrix3, Matrix4, Matrix4x6, Matrix6, OVector, U0, U2, U3, U4,
    U6, Vector3, Vector6,
};
use estim_core::{
    Alloc, Error, Gaussian, LinearMeasurement, LinearProcess, NoInput, ProcessModel, Unscented,
};
use estim_filters::{Ekf, GaussianFilter, Predict, SrUkf, Ukf, Update};

use super::table;

/// The 3-state process (Lu's Φ and Q).
pub fn process3() -> NoInput<LinearProcess<f32, U3, U0>> {
    super::lu::process()
}

/// The 3-state GPS measurement (2 components).
pub fn gps3() -> LinearMeasurement<f32, U3, U2> {
    super::lu::gps()
}

/// The 6-state process: Lu's Φ and Q on each of two axes, x = (δp₁, δv₁, b₁, δp₂, δv₂, b₂).
pub fn process6() -> NoInput<LinearProcess<f32, U6, U0>> {
    let (phi, q) = (
        Matrix3::from_row_slice(&table::TRANSITION),
        Matrix3::from_row_slice(&table::PROCESS_NOISE),
    );
    let (mut transition, mut noise) = (Matrix6::zeros(), Matrix6::zeros());
    for axis in [0, 3] {
        transition
            .fixed_view_mut::<3, 3>(axis, axis)
            .copy_from(&phi);
        noise.fixed_view_mut::<3, 3>(axis, axis).copy_from(&q);
    }
    LinearProcess::without_input(transition, noise)
}

/// The 6-state GPS measurement: (δp₁, δv₁, δp₂, δv₂) with Lu's R on each axis.
pub fn gps6() -> LinearMeasurement<f32, U6, U4> {
    let mut observation = Matrix4x6::zeros();
    for (row, state) in [(0, 0), (1, 1), (2, 3), (3, 4)] {
        observation[(row, state)] = 1.0;
    }
    let [rp, rv] = [table::GPS_NOISE[0], table::GPS_NOISE[3]];
    LinearMeasurement {
        observation,
        noise: Matrix4::from_diagonal(&[rp, rv, rp, rv].into()),
    }
}

/// N(0, M₀) on 3 states.
pub fn prior3() -> Result<Gaussian<f32, U3>, Error> {
    let m0 = Vector3::from(table::PRIOR_VARIANCE);
    Gaussian::new(Vector3::zeros(), Matrix3::from_diagonal(&m0))
}

/// N(0, diag(M₀, M₀)) on 6 states.
pub fn prior6() -> Result<Gaussian<f32, U6>, Error> {
    let [a, b, c] = table::PRIOR_VARIANCE;
    let m0 = Vector6::from([a, b, c, a, b, c]);
    Gaussian::new(Vector6::zeros(), Matrix6::from_diagonal(&m0))
}

/// An EKF on `prior`.
pub fn ekf<N: Dim>(prior: Gaussian<f32, N>) -> Ekf<f32, N>
where
    DefaultAllocator: Alloc<N>,
{
    Ekf::new(prior)
}

/// A UKF with cubature sigma points on `prior`.
pub fn ukf<N: Dim>(prior: Gaussian<f32, N>) -> Ukf<f32, N>
where
    DefaultAllocator: Alloc<N>,
{
    GaussianFilter::with_propagator(prior, Unscented::cubature())
}

/// A square-root UKF (the covariance carried as its Cholesky factor) with cubature sigma
/// points on `prior`.
pub fn srukf<N: Dim>(prior: Gaussian<f32, N>) -> SrUkf<f32, N>
where
    DefaultAllocator: Alloc<N>,
{
    SrUkf::with_propagator(prior, Unscented::cubature())
}

/// One predict (Δt of the record) and one update with `z`: the unit whose peak stack the
/// firmware measures. Not inlined, so that its frame is its own.
#[inline(never)]
pub fn step<F, P, H, const N: usize, const M: usize>(
    filter: &mut F,
    process: &P,
    gps: &H,
    z: &OVector<f32, Const<M>>,
) -> Result<(), Error>
where
    P: ProcessModel<f32, Const<N>, Input = ()>,
    H: estim_core::MeasurementModel<f32, Const<N>, Const<M>>,
    F: Predict<f32, Const<N>, P> + Update<f32, Const<N>, Const<M>, H>,
{
    filter.predict(process, &(), table::DT)?;
    filter.update(gps, z).map(|_| ())
}
