//! Rauch–Tung–Striebel smoothing of a recorded forward pass, for every Gaussian filter.
//!
//! The forward pass is the user's own loop over any filter that can be smoothed
//! ([`PredictCross`]: every Gaussian filter of the family, full-covariance or square-root,
//! and the IEKF), with [`Rts::predict`] in place of `predict` (so time-varying models,
//! inputs, Δt, state-dependent Q, several sensors and steps without a measurement all work as
//! in filtering). Each prediction records the filtered estimate (x̂ₖ, Pₖ), the prediction
//! (x̂⁻ₖ₊₁, P⁻ₖ₊₁) and the cross-covariance Cₖ = cov(xₖ, xₖ₊₁) that the filter's propagator
//! computes: C = P Fᵀ for the (extended) Kalman filter (S (F S)ᵀ in the square-root form),
//! the sigma-point sum for the UKF (unscented RTS; w γ S (Dₚ − Dₘ)ᵀ in the square-root
//! form), the linearised one for the second-order filters. The square-root filters are
//! smoothed in this same covariance form (P = S Sᵀ): a square-root backward pass would keep
//! the factor, but the RTS form is what every filter shares, and the tests hold both forms
//! to the same batch posterior. The backward pass ([`Rts::smooth`]) is then, from the
//! last estimate back (Särkkä, *Bayesian Filtering and Smoothing*, 2013, §8.2 and Thm 9.1):
//!
//! ```text
//! Gₖ   = Cₖ (P⁻ₖ₊₁)⁻¹                       (two triangular solves with the Cholesky factor
//!                                           of P⁻ₖ₊₁; never an inverse)
//! x̂ˢₖ  = x̂ₖ ⊞ Gₖ (x̂ˢₖ₊₁ ⊟ x̂⁻ₖ₊₁)
//! Pˢₖ  = Pₖ + Gₖ (Pˢₖ₊₁ − P⁻ₖ₊₁) Gₖᵀ          (symmetrised)
//! ```
//!
//! with ⊞/⊟ the filter's [`StateSpace`] (+/− by default). The lag-one smoothed
//! cross-covariances Pₖ₊₁,ₖ|K = Pˢₖ₊₁ Gₖᵀ that the E-step of EM needs come from the same pass
//! ([`Rts::smooth_with_cross_covariances`], [`smooth_sequence_with_cross_covariances`]).
//!
//! # What it allocates
//!
//! - [`Rts::predict`]: one record per prediction (two n-vectors and three n × n matrices; on
//!   the heap for runtime sizes), in a `VecDeque` that grows with the pass; with
//!   [`Rts::with_lag`] it grows the same way until it holds `lag` records, then the oldest
//!   record is dropped for each new one, so memory stays fixed from there on. Nothing is
//!   reserved at construction, so any lag is accepted (no bound to document, no error to
//!   handle) and costs only what the pass records: a lag longer than the pass is the
//!   whole-pass smoother.
//! - [`Rts::smooth`]: the `len() + 1` returned Gaussians; for runtime sizes also the factor,
//!   gain and two vectors once per call, and two n × n temporaries per step (the covariance
//!   expression). [`Rts::smooth_with_cross_covariances`] adds the `len()` returned matrices.
//! - [`filter_sequence`] / [`smooth_sequence`]: the [`Sequence`]'s vectors (reserved once),
//!   one [`Rollback`] snapshot of the filter at the start (put back on an error), and what
//!   the filter's own steps allocate; the smoothing forms add an [`Rts`] record of the whole sequence.
//!
//! Nothing the caller passes is modified on an error: the record, the filter (restored from
//! its snapshot by the sequence functions, bit for bit) and the data are as before the call.
//!
//! # Fixed states
//!
//! A state with zero variance (a known offset, a calibration held constant: no process noise
//! and an exact prior) passes every filter but makes P⁻ₖ₊₁ singular, so its Cholesky
//! factorisation fails. The backward pass then sets aside the states whose predicted variance
//! is zero (P⁻ᵢᵢ ≤ n ε maxⱼ P⁻ⱼⱼ: a positive semi-definite matrix has a zero row and column
//! there) and uses the Moore–Penrose inverse, G = C (P⁻)⁺, which for P⁻ = [A 0; 0 0] is
//! C [A⁻¹ 0; 0 0]: the other states are smoothed exactly as if the fixed ones were constants
//! of the model, and a fixed state's row of C is zero (it is uncorrelated with everything), so
//! it keeps its filtered value and zero variance. If P⁻ is still singular on the remaining
//! states, the error names the state index where the factorisation broke down
//! ([`SmootherError::state`]) and its likely cause.
//!
//! A square-root run is smoothed in this covariance form: the backward pass factorises
//! P⁻ = S⁻S⁻ᵀ, so it does not inherit the square-root filter's robustness (an `f32` or
//! ill-conditioned run the filter survives can still fail here with
//! [`Error::NotPositiveDefinite`] at its step).
//!
//! ```
//! use estim_filters::{KalmanFilter, Update};
//! use estim_filters::smoother::Rts;
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//!
//! let dt = 1.0;
//! let process = LinearProcess {
//!     transition: Matrix2::new(1.0, dt, 0.0, 1.0),
//!     input: Matrix2x1::zeros(),
//!     noise: Matrix2::identity() * 1e-2,
//! };
//! let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
//! let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?);
//! let mut rts = Rts::new();
//! for (k, z) in [0.1, 1.2, 1.9, 3.1, 3.9].into_iter().enumerate() {
//!     if k > 0 {
//!         rts.predict(&mut kf, &process, &Vector1::zeros(), dt)?;
//!     }
//!     kf.update(&sensor, &Vector1::new(z))?;
//! }
//! let smoothed = rts.smooth(&kf)?;
//! assert_eq!(smoothed.len(), 5);
//! // Every estimate now uses all five positions: the first is much better known.
//! assert!(smoothed[0].covariance()[(1, 1)] < 0.5);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::collections::VecDeque;

use estim_core::checks::{all_finite, symmetrize};
use estim_core::kernel::{self, CholeskyScratch};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1, try_convert};
use estim_core::{Alloc, Error, Gaussian, Quantity, Real, Stage, StateSpace, error::Result};

use crate::gaussian_filter::ensure_time_step;
use crate::report::{UpdateOutcome, UpdateReport};
use crate::traits::{OnStateSpace, Predict, PredictCross, ProcessInput, Rollback, Update};

mod fixed;
mod readings;

pub use readings::{ReadingsError, ReadingsRun, filter_readings, smooth_readings};

/// A failed backward step, with the index k of the estimate it was computing (0 = the first)
/// and, when the predicted covariance P⁻ₖ₊₁ could not be factorised, the state along which it
/// is singular.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("smoothing step {step}: {error}{}", state_cause(.state))]
pub struct SmootherError {
    /// The index of the smoothed estimate that failed.
    pub step: usize,
    /// What failed.
    pub error: Error,
    /// The state index i at which the Cholesky factorisation of P⁻ₖ₊₁ broke down (after the
    /// fixed, zero-variance states were set aside: module docs, "Fixed states"), if that is
    /// what failed.
    pub state: Option<usize>,
}

impl SmootherError {
    /// The error at backward step `step`, with no state named.
    pub(crate) fn at(step: usize, error: Error) -> Self {
        Self {
            step,
            error,
            state: None,
        }
    }
}

fn state_cause(state: &Option<usize>) -> String {
    match state {
        None => String::new(),
        Some(i) => format!(
            " at state {i}: the predicted covariance is singular or indefinite along it \
             (zero-variance states are handled as fixed, so state {i} is likely an exact \
             combination of other states, e.g. a constraint or a duplicated state, or its \
             variance went negative in the filter)"
        ),
    }
}

/// What one prediction of the forward pass leaves for the backward pass.
#[derive(Clone, Debug)]
struct Record<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
    predicted_state: OVector<T, N>,
    predicted_covariance: OMatrix<T, N, N>,
    cross: OMatrix<T, N, N>,
    /// The time of `state` \[s\] (the smoother's clock before the prediction).
    time: f64,
}

/// A Rauch–Tung–Striebel smoother over a forward pass driven through [`Rts::predict`]
/// (module docs). Memory: two n-vectors and three n × n matrices per recorded prediction; with
/// [`with_lag`](Self::with_lag), at most `lag` of them (a fixed-lag smoother).
#[derive(Clone, Debug)]
pub struct Rts<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    records: VecDeque<Record<T, N>>,
    lag: Option<usize>,
    /// The time of the filter's current estimate: the start plus every recorded Δt.
    clock: f64,
}

impl<T: Real, N: Dim> Default for Rts<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn default() -> Self {
        Self {
            records: VecDeque::new(),
            lag: None,
            clock: 0.0,
        }
    }
}

impl<T: Real, N: Dim> Rts<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// An empty record of the whole forward pass.
    pub fn new() -> Self {
        Self::default()
    }

    /// A fixed-lag smoother: only the last `lag` predictions are kept (memory fixed once
    /// `lag` are recorded), and [`smooth`](Self::smooth)'s first estimate is x̂ₖ₋ₗ given the
    /// data up to k: exact, because the backward recursion from k down to k − lag needs only
    /// the filtered estimates and predictions in between. `lag = 0` keeps nothing (the
    /// smoothed estimate is the filtered one). The record grows with the pass rather than
    /// being reserved here (module docs, "What it allocates"), so any `lag` is accepted,
    /// `usize::MAX` included: one longer than the pass is [`new`](Self::new)'s smoother.
    ///
    /// ```
    /// use estim_filters::{KalmanFilter, Update};
    /// use estim_filters::smoother::Rts;
    /// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
    /// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
    ///
    /// let process = LinearProcess {
    ///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
    ///     input: Matrix2x1::zeros(),
    ///     noise: Matrix2::identity() * 1e-2,
    /// };
    /// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
    /// let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
    /// let mut lagged = Rts::with_lag(3);
    /// for k in 0..100 {
    ///     lagged.predict(&mut kf, &process, &Vector1::zeros(), 1.0)?;
    ///     kf.update(&sensor, &Vector1::new(k as f64))?;
    ///     let three_steps_back = &lagged.smooth(&kf)?[0];
    ///     assert!(lagged.len() <= 3);
    /// #   let _ = three_steps_back;
    /// }
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn with_lag(lag: usize) -> Self {
        Self {
            // Not `with_capacity(lag)`: a huge lag would panic (capacity overflow) or abort
            // (allocation failure) here for records that may never come (issue 41).
            records: VecDeque::new(),
            lag: Some(lag),
            clock: 0.0,
        }
    }

    /// The number of predictions recorded.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// Whether no prediction is recorded.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Predicts `filter` through `model` ([`PredictCross::predict_with_cross_covariance`])
    /// and records what the backward pass needs. On an error nothing is recorded and the
    /// filter is unchanged.
    pub fn predict<F, P>(
        &mut self,
        filter: &mut F,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<()>
    where
        F: PredictCross<T, N, P>,
        P: ProcessInput<T, N> + ?Sized,
    {
        let (state, covariance) = (filter.state().clone(), filter.covariance().clone());
        let cross = filter.predict_with_cross_covariance(model, input, dt)?;
        let time = self.clock;
        self.clock += try_convert::<T, f64>(dt).unwrap_or(f64::NAN);
        if self.lag == Some(self.records.len()) && self.records.pop_front().is_none() {
            return Ok(()); // lag 0: nothing is kept
        }
        self.records.push_back(Record {
            state,
            covariance,
            predicted_state: filter.state().clone(),
            predicted_covariance: filter.covariance().clone(),
            cross,
            time,
        });
        Ok(())
    }

    /// The smoothed estimates at the times of the forward pass: `len() + 1` of them, the first
    /// at the state before the first recorded prediction, the last `filter`'s current estimate
    /// (the end of the forward pass, whose ⊞/⊟ are used). Leaves the record as it is; allocates
    /// the estimates and, for runtime sizes, a few n × n buffers.
    ///
    /// Errors, with the index of the estimate being computed: a predicted covariance that is
    /// not positive definite ([`Error::NotPositiveDefinite`], stage
    /// [`Smoothing`](Stage::Smoothing)), a non-finite result ([`Error::NonFinite`]), a record
    /// whose state size differs from `filter`'s ([`Error::DimensionMismatch`], quantity
    /// [`Mean`](Quantity::Mean): a runtime-sized filter reset to another size).
    pub fn smooth<F: OnStateSpace<T, N>>(
        &self,
        filter: &F,
    ) -> core::result::Result<Vec<Gaussian<T, N>>, SmootherError> {
        self.backward(filter, None)
    }

    /// [`smooth`](Self::smooth), and the lag-one smoothed cross-covariances that the E-step of
    /// EM needs (Shumway & Stoffer 1982; Särkkä 2013, Thm 12.4), from the same backward pass:
    ///
    /// ```text
    /// Pₖ₊₁,ₖ|K = cov(xₖ₊₁, xₖ | z₀ … z_K) = Pˢₖ₊₁ Gₖᵀ      k = 0 … len() − 1
    /// ```
    ///
    /// `cross_covariances[k]` pairs `estimates[k + 1]` (rows) with `estimates[k]` (columns), in
    /// the tangent space of ⊞/⊟. One extra n × n product per step and `len()` more matrices
    /// allocated; the errors are [`smooth`](Self::smooth)'s.
    ///
    /// ```
    /// use estim_filters::{KalmanFilter, Update};
    /// use estim_filters::smoother::Rts;
    /// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
    /// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
    ///
    /// let process = LinearProcess {
    ///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
    ///     input: Matrix2x1::zeros(),
    ///     noise: Matrix2::identity() * 1e-2,
    /// };
    /// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
    /// let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
    /// let mut rts = Rts::new();
    /// for (k, z) in [0.1, 1.2, 1.9, 3.1].into_iter().enumerate() {
    ///     if k > 0 {
    ///         rts.predict(&mut kf, &process, &Vector1::zeros(), 1.0)?;
    ///     }
    ///     kf.update(&sensor, &Vector1::new(z))?;
    /// }
    /// let pass = rts.smooth_with_cross_covariances(&kf)?;
    /// assert_eq!((pass.estimates.len(), pass.cross_covariances.len()), (4, 3));
    /// // Consecutive positions are strongly correlated given all the data.
    /// let (c, p0, p1) = (pass.cross_covariances[0], pass.estimates[0].covariance(), pass.estimates[1].covariance());
    /// assert!(c[(0, 0)] / f64::sqrt(p0[(0, 0)] * p1[(0, 0)]) > 0.5);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn smooth_with_cross_covariances<F: OnStateSpace<T, N>>(
        &self,
        filter: &F,
    ) -> core::result::Result<Smoothed<T, N>, SmootherError> {
        let mut cross_covariances = Vec::with_capacity(self.records.len());
        let estimates = self.backward(filter, Some(&mut cross_covariances))?;
        Ok(Smoothed {
            estimates,
            cross_covariances,
        })
    }

    /// This smoother with its clock at `time` \[s\]: the time of the filter's estimate before
    /// the first recorded prediction. Each [`predict`](Self::predict) advances the clock by
    /// its Δt, and [`smooth_with_times`](Self::smooth_with_times) returns each estimate with
    /// its time. (The clock starts at 0 otherwise.)
    ///
    /// ```
    /// use estim_filters::{KalmanFilter, Update};
    /// use estim_filters::smoother::Rts;
    /// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
    /// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
    ///
    /// let process = LinearProcess {
    ///     transition: Matrix2::new(1.0, 0.5, 0.0, 1.0),
    ///     input: Matrix2x1::zeros(),
    ///     noise: Matrix2::identity() * 1e-2,
    /// };
    /// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
    /// let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
    /// let mut rts = Rts::new().starting_at(100.0);
    /// for (dt, z) in [(0.5, 0.4), (0.25, 0.6), (1.0, 1.2)] {
    ///     rts.predict(&mut kf, &process, &Vector1::zeros(), dt)?;
    ///     kf.update(&sensor, &Vector1::new(z))?;
    /// }
    /// let track = rts.smooth_with_times(&kf)?;
    /// assert_eq!(track.times, [100.0, 100.5, 100.75, 101.75]);
    /// assert_eq!(track.estimates.len(), 4);
    /// assert_eq!(rts.time(), 101.75);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn starting_at(mut self, time: f64) -> Self {
        self.clock = time;
        self
    }

    /// The time of the filter's current estimate \[s\]: the start
    /// ([`starting_at`](Self::starting_at), else 0) plus the Δt of every prediction recorded.
    pub fn time(&self) -> f64 {
        self.clock
    }

    /// Sets the clock (the time of the filter's current estimate).
    pub(crate) fn set_clock(&mut self, time: f64) {
        self.clock = time;
    }

    /// [`smooth`](Self::smooth), each estimate with its time: the time of the state before each
    /// recorded prediction, then [`time`](Self::time) for the last (`filter`'s current
    /// estimate). Errors as [`smooth`](Self::smooth); example at
    /// [`starting_at`](Self::starting_at).
    pub fn smooth_with_times<F: OnStateSpace<T, N>>(
        &self,
        filter: &F,
    ) -> core::result::Result<Track<T, N>, SmootherError> {
        let estimates = self.backward(filter, None)?;
        let mut times = Vec::with_capacity(estimates.len());
        times.extend(self.records.iter().map(|r| r.time));
        times.push(self.clock);
        Ok(Track { times, estimates })
    }

    /// The backward pass; pushes Pₖ₊₁,ₖ|K into `cross` (in time order) if given.
    fn backward<F: OnStateSpace<T, N>>(
        &self,
        filter: &F,
        mut cross: Option<&mut Vec<OMatrix<T, N, N>>>,
    ) -> core::result::Result<Vec<Gaussian<T, N>>, SmootherError> {
        let space = filter.state_space();
        let n = filter.state().shape_generic().0;
        let mut smoothed = Vec::with_capacity(self.records.len() + 1);
        smoothed.push(Gaussian::new_unchecked(
            filter.state().clone(),
            filter.covariance().clone(),
        ));
        let mut cholesky = CholeskyScratch::default();
        let (mut factor, mut gain) = (OMatrix::zeros_generic(n, n), OMatrix::zeros_generic(n, n));
        let (mut dx, mut correction) =
            (OVector::zeros_generic(n, U1), OVector::zeros_generic(n, U1));
        for (step, record) in self.records.iter().enumerate().rev() {
            let fail = |error| SmootherError::at(step, error);
            // A runtime-sized filter reset to another size between predictions: every buffer
            // above has the filter's size (a record's values all have one size).
            if record.state.nrows() != n.value() {
                return Err(fail(Error::DimensionMismatch {
                    stage: Stage::Smoothing,
                    quantity: Quantity::Mean,
                    expected_rows: n.value(),
                    expected_cols: 1,
                    found_rows: record.state.nrows(),
                    found_cols: 1,
                }));
            }
            let next = smoothed.last().expect("starts with the last estimate");
            // G = C (P⁻)⁻¹ = C L⁻ᵀ L⁻¹, solved from the right in G's own storage.
            factor.copy_from(&record.predicted_covariance);
            if kernel::cholesky_in_place(&mut factor, &mut cholesky) {
                gain.copy_from(&record.cross);
                kernel::solve_right_lower_transpose_in_place(&factor, &mut gain);
                kernel::solve_right_lower_in_place(&factor, &mut gain);
            } else {
                // Fixed states (zero predicted variance): G = C (P⁻)⁺ on the others.
                fixed::gain(&record.predicted_covariance, &record.cross, &mut gain).map_err(
                    |state| SmootherError {
                        step,
                        error: Error::NotPositiveDefinite {
                            stage: Stage::Smoothing,
                            quantity: Quantity::Covariance,
                        },
                        state: Some(state),
                    },
                )?;
            }
            // x̂ˢ = x̂ ⊞ G (x̂ˢₖ₊₁ ⊟ x̂⁻).
            space.minus_into(next.mean(), &record.predicted_state, &mut dx);
            correction.gemv(T::one(), &gain, &dx, T::zero());
            let mut state = record.state.clone();
            space.plus_into(&record.state, &correction, &mut state);
            // Pˢ = P + G (Pˢₖ₊₁ − P⁻) Gᵀ, symmetrised.
            let difference = next.covariance() - &record.predicted_covariance;
            let mut covariance = &record.covariance + &gain * difference * gain.transpose();
            symmetrize(&mut covariance);
            let lag_one = cross.as_ref().map(|_| next.covariance() * gain.transpose());
            let finite = all_finite(&state)
                && all_finite(&covariance)
                && lag_one.as_ref().is_none_or(|c| all_finite(c));
            if !finite {
                return Err(fail(Error::NonFinite {
                    stage: Stage::Smoothing,
                    quantity: Quantity::Covariance,
                }));
            }
            if let (Some(cross), Some(lag_one)) = (cross.as_deref_mut(), lag_one) {
                cross.push(lag_one);
            }
            smoothed.push(Gaussian::new_unchecked(state, covariance));
        }
        smoothed.reverse();
        if let Some(cross) = cross {
            cross.reverse();
        }
        Ok(smoothed)
    }
}

/// Estimates with the times they are at: what the timed smoothers return
/// ([`Rts::smooth_with_times`], [`smooth_readings`],
/// [`FusionDriver::smooth`](crate::fusion::FusionDriver::smooth)).
#[derive(Clone, Debug, PartialEq)]
pub struct Track<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The time of each estimate \[s\], non-decreasing.
    pub times: Vec<f64>,
    /// The estimates, `estimates[k]` at `times[k]`.
    pub estimates: Vec<Gaussian<T, N>>,
}

/// A backward pass with its lag-one cross-covariances
/// ([`Rts::smooth_with_cross_covariances`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Smoothed<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The smoothed estimates x̂ˢₖ, Pˢₖ at the K + 1 times of the forward pass.
    pub estimates: Vec<Gaussian<T, N>>,
    /// The K lag-one smoothed cross-covariances: entry k is Pₖ₊₁,ₖ|K = cov(xₖ₊₁, xₖ | all
    /// data) = Pˢₖ₊₁ Gₖᵀ.
    pub cross_covariances: Vec<OMatrix<T, N, N>>,
}

/// A recorded sequence filtered ([`filter_sequence`]) or smoothed ([`smooth_sequence`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Sequence<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The estimate at each of the K + 1 times: filtered (after that time's measurement), or
    /// smoothed (given all of them).
    pub estimates: Vec<Gaussian<T, N>>,
    /// The update report at each time, `None` where the measurement was missing.
    pub updates: Vec<Option<UpdateReport<T, M>>>,
    /// Σ ln p(zₖ | z₀ … zₖ₋₁) over the measurements used (missing ones contribute nothing, gated
    /// ones neither): the prediction-error log-likelihood of the sequence.
    pub log_likelihood: T,
}

/// The filter run over a recorded sequence: at each time k = 0 … K the measurement
/// `measurements[k]` if present (missing ones are skipped, not replaced), then, for k < K, a
/// prediction with `inputs[k]` over `dt`. `measurements` has one entry more than `inputs`.
/// The filter ends at time K. Errors name the time k of the failing step and leave the filter
/// as it was before the call: lengths that disagree ([`Error::DimensionMismatch`], before
/// anything runs), a Δt, when there is a prediction, that is not finite ([`Error::NonFinite`]) or
/// negative ([`Error::InvalidParameter`]) (time 0, before anything runs), a failed update at time k (e.g. a non-finite measurement) or a
/// failed prediction from time k (e.g. a non-finite input, whose prediction is not finite).
///
/// ```
/// use estim_filters::KalmanFilter;
/// use estim_filters::smoother::filter_sequence;
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
///
/// let process = LinearProcess {
///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
///     input: Matrix2x1::zeros(),
///     noise: Matrix2::identity() * 1e-2,
/// };
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
/// let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// let zs = [Some(Vector1::new(0.1)), None, Some(Vector1::new(2.1))];
/// let run = filter_sequence(&mut kf, &process, &[Vector1::zeros(); 2], 1.0, &sensor, &zs)?;
/// assert_eq!(run.estimates.len(), 3);
/// assert!(run.updates[1].is_none() && f64::is_finite(run.log_likelihood));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn filter_sequence<T, N, M, F, P, H>(
    filter: &mut F,
    process: &P,
    inputs: &[P::Input],
    dt: T,
    measurement: &H,
    measurements: &[Option<OVector<T, M>>],
) -> core::result::Result<Sequence<T, N, M>, SmootherError>
where
    T: Real,
    N: Dim,
    M: Dim,
    F: Predict<T, N, P> + Update<T, N, M, H> + Rollback,
    P: ProcessInput<T, N> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    restoring_on_error(filter, |filter| {
        let predict = |filter: &mut F, input: &P::Input| filter.predict(process, input, dt);
        run(filter, inputs, dt, measurement, measurements, predict)
    })
}

/// [`filter_sequence`], then the Rauch–Tung–Striebel backward pass ([`Rts`]): the estimates
/// are smoothed (given every measurement); the update reports and the log-likelihood are the
/// forward pass's.
///
/// ```
/// use estim_filters::Ukf;
/// use estim_filters::smoother::smooth_sequence;
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
///
/// let process = LinearProcess {
///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
///     input: Matrix2x1::zeros(),
///     noise: Matrix2::identity() * 1e-2,
/// };
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
/// let mut ukf = Ukf::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// let zs = [Some(Vector1::new(0.1)), None, Some(Vector1::new(2.1)), Some(Vector1::new(2.9))];
/// let run = smooth_sequence(&mut ukf, &process, &[Vector1::zeros(); 3], 1.0, &sensor, &zs)?;
/// // The missing position at time 1 is estimated from both sides.
/// assert!(f64::abs(run.estimates[1].mean()[0] - 1.0) < 0.3);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn smooth_sequence<T, N, M, F, P, H>(
    filter: &mut F,
    process: &P,
    inputs: &[P::Input],
    dt: T,
    measurement: &H,
    measurements: &[Option<OVector<T, M>>],
) -> core::result::Result<Sequence<T, N, M>, SmootherError>
where
    T: Real,
    N: Dim,
    M: Dim,
    F: PredictCross<T, N, P> + Update<T, N, M, H> + Rollback,
    P: ProcessInput<T, N> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    smoothed(filter, process, inputs, dt, measurement, measurements, None)
}

/// [`smooth_sequence`], and the lag-one smoothed cross-covariances Pₖ₊₁,ₖ|K = Pˢₖ₊₁ Gₖᵀ
/// ([`Rts::smooth_with_cross_covariances`]): entry k of the second vector pairs
/// `estimates[k + 1]` with `estimates[k]`, K entries in all. What the E-step of EM needs:
/// smoothed moments, lag-one cross-covariances and the log-likelihood, from one pass.
///
/// ```
/// use estim_filters::KalmanFilter;
/// use estim_filters::smoother::smooth_sequence_with_cross_covariances;
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
///
/// let process = LinearProcess {
///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
///     input: Matrix2x1::zeros(),
///     noise: Matrix2::identity() * 1e-2,
/// };
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
/// let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// let zs = [Some(Vector1::new(0.1)), None, Some(Vector1::new(2.1))];
/// let (run, cross) =
///     smooth_sequence_with_cross_covariances(&mut kf, &process, &[Vector1::zeros(); 2], 1.0, &sensor, &zs)?;
/// assert_eq!((run.estimates.len(), cross.len()), (3, 2));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[allow(clippy::type_complexity)]
pub fn smooth_sequence_with_cross_covariances<T, N, M, F, P, H>(
    filter: &mut F,
    process: &P,
    inputs: &[P::Input],
    dt: T,
    measurement: &H,
    measurements: &[Option<OVector<T, M>>],
) -> core::result::Result<(Sequence<T, N, M>, Vec<OMatrix<T, N, N>>), SmootherError>
where
    T: Real,
    N: Dim,
    M: Dim,
    F: PredictCross<T, N, P> + Update<T, N, M, H> + Rollback,
    P: ProcessInput<T, N> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let mut cross = Vec::with_capacity(inputs.len());
    let sequence = smoothed(
        filter,
        process,
        inputs,
        dt,
        measurement,
        measurements,
        Some(&mut cross),
    )?;
    Ok((sequence, cross))
}

/// The forward pass of [`filter_sequence`] recorded, then the backward pass (pushing the
/// lag-one cross-covariances into `cross` if given); the filter restored on any error.
fn smoothed<T, N, M, F, P, H>(
    filter: &mut F,
    process: &P,
    inputs: &[P::Input],
    dt: T,
    measurement: &H,
    measurements: &[Option<OVector<T, M>>],
    cross: Option<&mut Vec<OMatrix<T, N, N>>>,
) -> core::result::Result<Sequence<T, N, M>, SmootherError>
where
    T: Real,
    N: Dim,
    M: Dim,
    F: PredictCross<T, N, P> + Update<T, N, M, H> + Rollback,
    P: ProcessInput<T, N> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    restoring_on_error(filter, |filter| {
        let mut rts = Rts::new();
        let predict = |filter: &mut F, input: &P::Input| rts.predict(filter, process, input, dt);
        let mut sequence = run(filter, inputs, dt, measurement, measurements, predict)?;
        sequence.estimates = rts.backward(filter, cross)?;
        Ok(sequence)
    })
}

/// Runs `body` on `filter`; on an error puts back the snapshot it started from
/// ([`Rollback`]), so a failed sequence leaves the filter exactly as it was.
fn restoring_on_error<F: Rollback, R>(
    filter: &mut F,
    body: impl FnOnce(&mut F) -> core::result::Result<R, SmootherError>,
) -> core::result::Result<R, SmootherError> {
    let before = filter.snapshot();
    let result = body(filter);
    if result.is_err() {
        filter.restore(&before);
    }
    result
}

/// The forward pass of [`filter_sequence`], predicting with `predict` (recording for the
/// smoother, or not).
fn run<T, N, M, F, P, H>(
    filter: &mut F,
    inputs: &[P::Input],
    dt: T,
    measurement: &H,
    measurements: &[Option<OVector<T, M>>],
    mut predict: impl FnMut(&mut F, &P::Input) -> Result<()>,
) -> core::result::Result<Sequence<T, N, M>, SmootherError>
where
    T: Real,
    N: Dim,
    M: Dim,
    F: Predict<T, N, P> + Update<T, N, M, H>,
    P: ProcessInput<T, N> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    if measurements.len() != inputs.len() + 1 {
        return Err(SmootherError::at(
            measurements.len().min(inputs.len() + 1),
            Error::DimensionMismatch {
                stage: Stage::Smoothing,
                quantity: Quantity::Measurement,
                expected_rows: inputs.len() + 1,
                expected_cols: 1,
                found_rows: measurements.len(),
                found_cols: 1,
            },
        ));
    }
    if !inputs.is_empty() {
        ensure_time_step(dt).map_err(|error| SmootherError::at(0, error))?;
    }
    let mut sequence = Sequence {
        estimates: Vec::with_capacity(measurements.len()),
        updates: Vec::with_capacity(measurements.len()),
        log_likelihood: T::zero(),
    };
    for (step, z) in measurements.iter().enumerate() {
        let fail = |error| SmootherError::at(step, error);
        let report = match z {
            Some(z) => {
                let report = filter.update(measurement, z).map_err(fail)?;
                if report.outcome == UpdateOutcome::Applied {
                    sequence.log_likelihood += report.log_likelihood;
                }
                Some(report)
            }
            None => None,
        };
        sequence.updates.push(report);
        sequence.estimates.push(Gaussian::new_unchecked(
            filter.state().clone(),
            filter.covariance().clone(),
        ));
        if let Some(input) = inputs.get(step) {
            predict(filter, input).map_err(fail)?;
        }
    }
    Ok(sequence)
}
