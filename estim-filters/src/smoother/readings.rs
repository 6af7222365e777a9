//! A recorded log with irregular times and a model per reading, through the filter and the
//! smoother: [`filter_readings`], [`smooth_readings`].
//!
//! A reading is `(time, reading)`, and the sensors are the fusion driver's [`SensorSet`]:
//! which sensor a reading comes from and how it updates the filter. Why this and not a slice
//! of models or a closure per reading: a log of several sensors has readings of different
//! dimensions and models of different types (four range beacons and an odometer), which one
//! slice cannot hold without boxing; a [`SensorSet`] is that closure with a name, written once
//! for the batch functions and the [`FusionDriver`](crate::fusion::FusionDriver) alike, so
//! the same log runs through both (and the tests hold them to each other). A missing reading
//! is simply not in the log. The process input is asked of a closure, `input(t)`, the input
//! held from time t on (the driver's default convention), once per prediction.

use estim_core::nalgebra::{DefaultAllocator, Dim, convert};
use estim_core::{Alloc, Error, Gaussian, Real};

use super::{Rts, SmootherError, Track};
use crate::fusion::{Innovation, SensorSet};
use crate::traits::{Estimator, Predict, PredictCross, ProcessInput, Rollback};

/// A log filtered ([`filter_readings`]) or smoothed ([`smooth_readings`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ReadingsRun<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The estimate at the start and at each distinct reading time after it (after every
    /// reading at that time): filtered, or smoothed given the whole log.
    pub track: Track<T, N>,
    /// The innovation of each reading, in the log's order.
    pub innovations: Vec<Innovation<T>>,
    /// Σ ln N(νᵢ; 0, Sᵢ) over the readings the filter applied: the prediction-error
    /// log-likelihood of the log (what maximum-likelihood noise identification maximises).
    pub log_likelihood: T,
}

/// What is wrong with a log, or which step of it failed. The filter is left as it was.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ReadingsError {
    /// The start time (`index` `None`) or reading `index`'s time is NaN or ±∞.
    #[error("time {time} of reading {index:?} (None: the start) is not finite")]
    NonFiniteTime {
        /// The reading, `None` for the start time.
        index: Option<usize>,
        /// The time given.
        time: f64,
    },
    /// Reading `index` is earlier than the reading before it (or than the start).
    #[error(
        "reading {index} at {time} s is before the previous one at {previous} s: sort the log \
         by time (a stable sort keeps the order of readings at equal times)"
    )]
    NotSorted {
        /// The reading.
        index: usize,
        /// Its time.
        time: f64,
        /// The time before it.
        previous: f64,
    },
    /// Reading `index` names a sensor the set does not have.
    #[error("reading {index} names sensor {sensor}: SensorSet::sensor must be below {count}")]
    UnknownSensor {
        /// The reading.
        index: usize,
        /// The sensor it named.
        sensor: usize,
        /// The number of sensors.
        count: usize,
    },
    /// The prediction to reading `index`'s time, or its update, failed.
    #[error("reading {index} at {time} s: {error}")]
    Step {
        /// The reading.
        index: usize,
        /// Its time.
        time: f64,
        /// What failed.
        error: Error,
    },
    /// The backward pass failed at the estimate at `time`.
    #[error("smoothing the estimate at {time} s: {error}")]
    Smoothing {
        /// The time of the estimate being smoothed.
        time: f64,
        /// What failed (its `step` indexes [`ReadingsRun::track`]).
        error: SmootherError,
    },
}

/// The filter over a log of `(time, reading)` from `start` (the time of `filter`'s estimate):
/// for each reading, a prediction to its time if it is later than the last one (one
/// prediction of Δt, with `input(t)` from the time t it starts at), then its update
/// ([`SensorSet::update`]). Readings at equal times update in the log's order with no
/// prediction between. The filter ends at the last reading's time.
///
/// Errors (the filter restored to where it was, bit for bit): [`ReadingsError`]; the log is
/// checked before anything runs (times finite and non-decreasing, from `start` on; sensors
/// known).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, U1, U2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
/// use estim_filters::fusion::{Innovation, SensorSet};
/// use estim_filters::smoother::filter_readings;
/// use estim_filters::{KalmanFilter, Update};
///
/// /// Two sensors: position and velocity.
/// struct Cart([LinearMeasurement<f64, U2, U1>; 2]);
/// impl<F: Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>> SensorSet<f64, U2, F> for Cart {
///     type Reading = (usize, Vector1<f64>);
///     fn count(&self) -> usize { 2 }
///     fn sensor(&self, r: &Self::Reading) -> usize { r.0 }
///     fn dimension(&self, _: usize) -> usize { 1 }
///     fn update(&self, f: &mut F, r: &Self::Reading) -> Result<Innovation<f64>> {
///         f.update(&self.0[r.0], &r.1).map(|r| Innovation::of(&r))
///     }
/// }
/// let sensors = Cart([
///     LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.1) },
///     LinearMeasurement { observation: Matrix1x2::new(0.0, 1.0), noise: Matrix1::new(0.1) },
/// ]);
/// // A random walk whose Q is per prediction (a `LinearProcess` ignores Δt).
/// let walk = LinearProcess { transition: Matrix2::identity(), input: Matrix2x1::zeros(), noise: Matrix2::identity() * 1e-2 };
/// let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// // Irregular times, two readings at 0.35 s, no velocity before then.
/// let log = [(0.1, (0, Vector1::new(0.1))), (0.35, (0, Vector1::new(0.3))), (0.35, (1, Vector1::new(1.0))), (1.0, (0, Vector1::new(0.9)))];
/// let run = filter_readings(&mut kf, &walk, |_| Vector1::zeros(), &sensors, 0.0, &log)?;
/// assert_eq!(run.track.times, [0.0, 0.1, 0.35, 1.0]);
/// assert_eq!(run.innovations.len(), 4);
/// assert!(run.log_likelihood.is_finite());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn filter_readings<T, N, F, P, S>(
    filter: &mut F,
    process: &P,
    mut input: impl FnMut(f64) -> P::Input,
    sensors: &S,
    start: f64,
    readings: &[(f64, S::Reading)],
) -> Result<ReadingsRun<T, N>, ReadingsError>
where
    T: Real,
    N: Dim,
    F: Predict<T, N, P> + Rollback,
    P: ProcessInput<T, N> + ?Sized,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    check(sensors, start, readings)?;
    let before = filter.snapshot();
    let predict = |filter: &mut F, from: f64, dt: T| filter.predict(process, &input(from), dt);
    let result = forward(filter, sensors, start, readings, predict);
    if result.is_err() {
        filter.restore(&before);
    }
    result
}

/// [`filter_readings`], then the Rauch–Tung–Striebel backward pass: the track's estimates are
/// smoothed given the whole log (at the same times); the innovations and the log-likelihood
/// are the forward pass's. Errors as [`filter_readings`], and
/// [`ReadingsError::Smoothing`] (the filter restored).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, U1, U2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
/// use estim_filters::fusion::{Innovation, SensorSet};
/// use estim_filters::smoother::smooth_readings;
/// use estim_filters::{KalmanFilter, Update};
///
/// struct Position(LinearMeasurement<f64, U2, U1>);
/// impl<F: Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>> SensorSet<f64, U2, F> for Position {
///     type Reading = Vector1<f64>;
///     fn count(&self) -> usize { 1 }
///     fn sensor(&self, _: &Vector1<f64>) -> usize { 0 }
///     fn dimension(&self, _: usize) -> usize { 1 }
///     fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> {
///         f.update(&self.0, z).map(|r| Innovation::of(&r))
///     }
/// }
/// let sensor = Position(LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) });
/// let walk = LinearProcess { transition: Matrix2::identity(), input: Matrix2x1::zeros(), noise: Matrix2::identity() * 1e-2 };
/// let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?);
/// let log = [(0.2, Vector1::new(1.0)), (0.7, Vector1::new(1.1)), (0.9, Vector1::new(0.9))];
/// let run = smooth_readings(&mut kf, &walk, |_| Vector1::zeros(), &sensor, 0.0, &log)?;
/// // The estimate at the start is now informed by the readings after it.
/// assert_eq!(run.track.times[0], 0.0);
/// assert!(run.track.estimates[0].covariance()[(0, 0)] < 1.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn smooth_readings<T, N, F, P, S>(
    filter: &mut F,
    process: &P,
    mut input: impl FnMut(f64) -> P::Input,
    sensors: &S,
    start: f64,
    readings: &[(f64, S::Reading)],
) -> Result<ReadingsRun<T, N>, ReadingsError>
where
    T: Real,
    N: Dim,
    F: PredictCross<T, N, P> + Rollback,
    P: ProcessInput<T, N> + ?Sized,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    check(sensors, start, readings)?;
    let before = filter.snapshot();
    let mut rts = Rts::new();
    let predict = |filter: &mut F, from: f64, dt: T| {
        rts.set_clock(from);
        rts.predict(filter, process, &input(from), dt)
    };
    let result = forward(filter, sensors, start, readings, predict).and_then(|mut run| {
        let times = core::mem::take(&mut run.track.times);
        let smoothed = rts
            .backward(&*filter, None)
            .map_err(|error| ReadingsError::Smoothing {
                time: times.get(error.step).copied().unwrap_or(f64::NAN),
                error,
            })?;
        run.track = Track {
            times,
            estimates: smoothed,
        };
        Ok(run)
    });
    if result.is_err() {
        filter.restore(&before);
    }
    result
}

/// The log's times finite and non-decreasing from `start`, its sensors known.
fn check<T, N, F, S>(
    sensors: &S,
    start: f64,
    readings: &[(f64, S::Reading)],
) -> Result<(), ReadingsError>
where
    T: Real,
    N: Dim,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    if !start.is_finite() {
        return Err(ReadingsError::NonFiniteTime {
            index: None,
            time: start,
        });
    }
    let (mut previous, count) = (start, sensors.count());
    for (index, (time, reading)) in readings.iter().enumerate() {
        if !time.is_finite() {
            return Err(ReadingsError::NonFiniteTime {
                index: Some(index),
                time: *time,
            });
        }
        if *time < previous {
            return Err(ReadingsError::NotSorted {
                index,
                time: *time,
                previous,
            });
        }
        let sensor = sensors.sensor(reading);
        if sensor >= count {
            return Err(ReadingsError::UnknownSensor {
                index,
                sensor,
                count,
            });
        }
        previous = *time;
    }
    Ok(())
}

/// The forward pass over a checked log, predicting with `predict(filter, from, dt)`.
fn forward<T, N, F, S>(
    filter: &mut F,
    sensors: &S,
    start: f64,
    readings: &[(f64, S::Reading)],
    mut predict: impl FnMut(&mut F, f64, T) -> estim_core::error::Result<()>,
) -> Result<ReadingsRun<T, N>, ReadingsError>
where
    T: Real,
    N: Dim,
    F: Estimator<T, N>,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    let current = |f: &F| Gaussian::new_unchecked(f.state().clone(), f.covariance().clone());
    let mut run = ReadingsRun {
        track: Track {
            times: vec![start],
            estimates: vec![current(filter)],
        },
        innovations: Vec::with_capacity(readings.len()),
        log_likelihood: T::zero(),
    };
    let mut now = start;
    for (index, (time, reading)) in readings.iter().enumerate() {
        let fail = |error| ReadingsError::Step {
            index,
            time: *time,
            error,
        };
        if *time > now {
            predict(filter, now, convert(*time - now)).map_err(fail)?;
            now = *time;
            run.track.times.push(now);
            run.track.estimates.push(current(filter));
        }
        let innovation = sensors.update(filter, reading).map_err(fail)?;
        if innovation.applied {
            run.log_likelihood += innovation.log_likelihood;
        }
        run.innovations.push(innovation);
        if let Some(last) = run.track.estimates.last_mut() {
            *last = current(filter);
        }
    }
    Ok(run)
}
