//! Named bounds for functions generic over the filter: "a filter over these models" and "a
//! filter that can be smoothed", so that a user writes one trait instead of the step traits
//! (or the propagator bounds of [`GaussianFilter`](crate::GaussianFilter)) it bundles.
//!
//! Both have blanket impls: every type with the bundled traits has them, nothing to implement.
//! With several sensors, add one [`Update`] bound per further measurement model.

use estim_core::Real;
use estim_core::nalgebra::{DefaultAllocator, Dim};

use estim_core::Alloc;

use crate::traits::{Predict, PredictCross, ProcessInput, Rollback, Update};

/// A filter over these models: it predicts through the process model `P`
/// (x⁺ = f(x, u, Δt) + w, [`Predict`]), updates with the measurement model `H` of `M`
/// components (z = h(x) + v, [`Update`]), and can be put back as it was ([`Rollback`]).
/// What [`filter_sequence`](crate::filter_sequence) and a hand-written loop need; every
/// filter of the Kalman family, the IEKF and the square-root filters have it for the models
/// they accept.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, U1, U2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::{Ekf, FilterOver, KalmanFilter, Ukf};
///
/// type Motion = LinearProcess<f64, U2, U1>;
/// type Position = LinearMeasurement<f64, U2, U1>;
///
/// /// Runs any filter over the constant-velocity model and a position sensor; returns the
/// /// sum of the NIS (each ~ χ²(1) when the filter is consistent).
/// fn track<F: FilterOver<f64, U2, U1, Motion, Position>>(
///     filter: &mut F,
///     motion: &Motion,
///     sensor: &Position,
///     zs: &[f64],
/// ) -> Result<f64, estim_core::Error> {
///     let mut nis = 0.0;
///     for &z in zs {
///         filter.predict(motion, &Vector1::zeros(), 1.0)?;
///         nis += filter.update(sensor, &Vector1::new(z))?.nis;
///     }
///     Ok(nis)
/// }
///
/// let motion = Motion {
///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
///     input: Matrix2x1::zeros(),
///     noise: Matrix2::identity() * 1e-2,
/// };
/// let sensor = Position { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
/// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?;
/// let zs = [1.1, 1.9, 3.2, 4.0];
/// // The same function for three filters: on a linear model they agree.
/// let kf = track(&mut KalmanFilter::new(prior.clone()), &motion, &sensor, &zs)?;
/// let ekf = track(&mut Ekf::new(prior.clone()), &motion, &sensor, &zs)?;
/// let ukf = track(&mut Ukf::new(prior), &motion, &sensor, &zs)?;
/// // Tolerance: the three differ only by rounding in their propagation of the same moments.
/// assert!((kf - ekf).abs() < 1e-9 && (kf - ukf).abs() < 1e-9);
/// # Ok::<(), estim_core::Error>(())
/// ```
pub trait FilterOver<T, N, M, P, H>: Predict<T, N, P> + Update<T, N, M, H> + Rollback
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessInput<T, N> + ?Sized,
    H: ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
}

impl<T, N, M, P, H, F> FilterOver<T, N, M, P, H> for F
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessInput<T, N> + ?Sized,
    H: ?Sized,
    DefaultAllocator: Alloc<N, M>,
    F: Predict<T, N, P> + Update<T, N, M, H> + Rollback + ?Sized,
{
}

/// A filter that can be smoothed over these models: a [`FilterOver`] whose prediction also
/// gives the cross-covariance C = cov(xₖ, xₖ₊₁) ([`PredictCross`]) that the
/// Rauch–Tung–Striebel backward pass needs (G = C (P⁻)⁻¹, x̂ˢₖ = x̂ₖ ⊞ G (x̂ˢₖ₊₁ ⊟ x̂⁻ₖ₊₁)).
/// What [`Rts::predict`](crate::Rts::predict) and
/// [`smooth_sequence`](crate::smooth_sequence) need: every Gaussian filter of the family,
/// full-covariance or square-root, and the IEKF.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, U1, U2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::{KalmanFilter, Smoothable, SrUkf, SmootherError, smooth_sequence};
///
/// type Motion = LinearProcess<f64, U2, U1>;
/// type Position = LinearMeasurement<f64, U2, U1>;
///
/// /// The smoothed position at every time of a recording with gaps (`None`).
/// fn smoothed_positions<F: Smoothable<f64, U2, U1, Motion, Position>>(
///     filter: &mut F,
///     motion: &Motion,
///     sensor: &Position,
///     zs: &[Option<Vector1<f64>>],
/// ) -> Result<Vec<f64>, SmootherError> {
///     let inputs = vec![Vector1::zeros(); zs.len() - 1];
///     let run = smooth_sequence(filter, motion, &inputs, 1.0, sensor, zs)?;
///     Ok(run.estimates.iter().map(|e| e.mean()[0]).collect())
/// }
///
/// let motion = Motion {
///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
///     input: Matrix2x1::zeros(),
///     noise: Matrix2::identity() * 1e-2,
/// };
/// let sensor = Position { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
/// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?;
/// let zs = [Some(Vector1::new(0.1)), None, Some(Vector1::new(2.1)), Some(Vector1::new(2.9))];
/// let kf = smoothed_positions(&mut KalmanFilter::new(prior.clone()), &motion, &sensor, &zs)?;
/// let sr = smoothed_positions(&mut SrUkf::new(prior), &motion, &sensor, &zs)?;
/// // The gap at time 1 is filled from both sides (between 0.1 and 2.1); tolerance 0.3: the
/// // noise (σ = 0.5 per reading) leaves the smoothed value about 0.2 from the line's 1.05.
/// assert!((kf[1] - 1.0).abs() < 0.3);
/// // A square-root UKF smooths to the same values on a linear model, up to rounding.
/// assert!(kf.iter().zip(&sr).all(|(a, b)| (a - b).abs() < 1e-9));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait Smoothable<T, N, M, P, H>: FilterOver<T, N, M, P, H> + PredictCross<T, N, P>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessInput<T, N> + ?Sized,
    H: ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
}

impl<T, N, M, P, H, F> Smoothable<T, N, M, P, H> for F
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessInput<T, N> + ?Sized,
    H: ?Sized,
    DefaultAllocator: Alloc<N, M>,
    F: FilterOver<T, N, M, P, H> + PredictCross<T, N, P> + ?Sized,
{
}
