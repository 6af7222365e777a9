//! Several readings fused with one rollback and one replay.

use estim_core::nalgebra::{DefaultAllocator, Dim};
use estim_core::{Alloc, Error, Quantity, Real, Stage};

use super::super::error::{BatchError, FusionError};
use super::super::history::Event;
use super::super::outcome::Fused;
use super::super::sensors::SensorSet;
use super::super::settings::DuplicatePolicy;
use super::{FusionDriver, substeps};
use crate::traits::{Predict, ProcessInput, Rollback};

/// Where a reading of a batch went.
#[derive(Clone, Copy, Debug)]
pub(super) struct Slot {
    /// Its record (moved on as later readings of the batch are inserted before it).
    pub(super) at: usize,
    pub(super) time: f64,
    pub(super) sensor: usize,
    /// The events after it when it was inserted: what [`FusionDriver::fuse`] reports.
    pub(super) replayed: usize,
    /// [`DuplicatePolicy::KeepFirst`] kept the reading at `at`: this one was not inserted.
    pub(super) ignored: bool,
}

impl<T, N, F, P, S> FusionDriver<T, N, F, P, S>
where
    T: Real,
    N: Dim,
    F: Predict<T, N, P> + Rollback,
    P: ProcessInput<T, N>,
    P::Input: Clone,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    /// Fuses several `(time, reading)` pairs with **one** rollback and **one** replay: the
    /// readings are inserted in the history first, in the order given, then the history is
    /// re-run once from the earliest of them. The result is what
    /// [`fuse`](Self::fuse) called on each in the same order gives, bit for bit: the same
    /// estimate, history, health, [`decisions`](Self::decisions) and
    /// [`log_likelihood`](Self::log_likelihood), each reading checked as `fuse` would check
    /// it after the ones before it (horizon, oldest record kept, duplicates). A GPS fix
    /// fused as a position and a velocity taken at one time costs one replay instead of two.
    ///
    /// Why pairs and not one time: readings of one fix share a time, but a receiver's queue
    /// or a log's block may hold readings of several times, and the caller should not have
    /// to split them. Why an iterator: the readings are moved into the history, none is
    /// cloned, and an array literal is enough.
    ///
    /// Returns one [`Fused`] per reading, in the order given, borrowed from the driver (a
    /// buffer kept between calls: no allocation once it has held the largest batch; a batch
    /// of one reading per sensor never allocates). Each outcome is the decision recorded
    /// after the whole batch, the one [`decisions`](Self::decisions) lists; it is also the
    /// one `fuse` returns, except when a reading given later lands before it in time: then
    /// `fuse` returns a provisional decision that the later reading's replay re-makes, and
    /// this returns the re-made one. `replayed` is what `fuse` reports (the events after
    /// the reading when it was inserted), although only one replay runs. A reading that
    /// [`DuplicatePolicy::KeepFirst`] ignores is `ignored`, with the kept reading's outcome.
    ///
    /// An empty batch is a no-op returning an empty slice, as no `fuse` call at all: a
    /// receiver cycle with nothing new is not an error.
    ///
    /// Errors, **all or nothing**: if any reading is refused, no reading of the batch is
    /// fused and the driver is left exactly as it was before the call (estimate, history,
    /// health). The [`BatchError`] gives the reading's position in the batch and the error
    /// `fuse` would give: [`FusionError::NonFiniteTime`], [`FusionError::UnknownSensor`],
    /// [`FusionError::TooOld`], [`FusionError::Duplicate`], [`FusionError::GapTooLong`], or
    /// [`FusionError::Filter`] when a filter step of the replay fails (then the reading is
    /// the one at the record whose prediction or update failed, or else the last one, in the
    /// order given, placed before that record).
    ///
    /// ```
    /// # use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, U1, U2, Vector1, Vector2};
    /// # use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
    /// # use estim_filters::fusion::{FusionDriver, FusionError, FusionSettings, Innovation, SensorSet, SensorSettings};
    /// # use estim_filters::{Estimator, KalmanFilter, Update};
    /// # #[derive(Clone, Debug)]
    /// # enum Reading { Position(Vector1<f64>), Velocity(Vector1<f64>) }
    /// # struct Cart { position: LinearMeasurement<f64, U2, U1>, velocity: LinearMeasurement<f64, U2, U1> }
    /// # impl<F: Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>> SensorSet<f64, U2, F> for Cart {
    /// #     type Reading = Reading;
    /// #     fn count(&self) -> usize { 2 }
    /// #     fn sensor(&self, r: &Reading) -> usize { match r { Reading::Position(_) => 0, Reading::Velocity(_) => 1 } }
    /// #     fn dimension(&self, _: usize) -> usize { 1 }
    /// #     fn update(&self, filter: &mut F, r: &Reading) -> Result<Innovation<f64>> {
    /// #         match r {
    /// #             Reading::Position(z) => filter.update(&self.position, z).map(|r| Innovation::of(&r)),
    /// #             Reading::Velocity(z) => filter.update(&self.velocity, z).map(|r| Innovation::of(&r)),
    /// #         }
    /// #     }
    /// # }
    /// // A cart (position, velocity) with an accelerometer at 100 Hz and a GPS whose fixes
    /// // (a position and a velocity each) arrive 50 ms after they were taken.
    /// let driver = || {
    ///     let process = LinearProcess { transition: Matrix2::new(1.0, 0.01, 0.0, 1.0), input: Matrix2::new(0.0, 0.0, 0.0, 0.01), noise: Matrix2::identity() * 1e-6 };
    ///     let sensors = Cart {
    ///         position: LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) },
    ///         velocity: LinearMeasurement { observation: Matrix1x2::new(0.0, 1.0), noise: Matrix1::new(0.01) },
    ///     };
    ///     let filter = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
    ///     let settings = FusionSettings { horizon: 0.2, max_step: 0.01, ..FusionSettings::default() };
    ///     FusionDriver::new(filter, process, Vector2::zeros(), sensors, 0.0, settings, SensorSettings::gated(0.999))
    /// };
    /// let (mut one_call, mut one_by_one) = (driver()?, driver()?);
    /// for k in 1..=10 {
    ///     let a = Vector2::new(0.0, 1.0);
    ///     one_call.set_input(0.01 * k as f64, a)?;
    ///     one_by_one.set_input(0.01 * k as f64, a)?;
    /// }
    /// // The fix taken at 0.05 s, fused at 0.10 s: one replay of the 5 later inputs.
    /// let fix = [(0.05, Reading::Position(Vector1::new(0.001))), (0.05, Reading::Velocity(Vector1::new(0.05)))];
    /// let fused = one_call.fuse_all(fix.clone())?;
    /// assert_eq!(fused.len(), 2);
    /// assert!(fused.iter().all(|f| f.outcome.applied()));
    /// for (time, reading) in fix {
    ///     one_by_one.fuse(time, reading)?;
    /// }
    /// assert_eq!(one_call.filter().estimate(), one_by_one.filter().estimate()); // bit for bit
    /// // All or nothing: the second reading is older than the horizon, nothing is fused.
    /// let before = (one_call.filter().estimate(), one_call.history_len());
    /// let late = [(0.09, Reading::Position(Vector1::new(0.004))), (-0.2, Reading::Velocity(Vector1::new(0.09)))];
    /// let refused = one_call.fuse_all(late).unwrap_err();
    /// assert_eq!(refused.index, 1);
    /// assert!(matches!(refused.error, FusionError::TooOld { .. }));
    /// assert_eq!((one_call.filter().estimate(), one_call.history_len()), before);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn fuse_all<I>(&mut self, readings: I) -> Result<&[Fused<T>], BatchError>
    where
        I: IntoIterator<Item = (f64, S::Reading)>,
    {
        self.slots.clear();
        self.fused.clear();
        let len = self.history.len();
        let mut inserted = 0;
        for (index, (time, reading)) in readings.into_iter().enumerate() {
            // The records `fuse` would have trimmed by now (the oldest ones).
            let trimmed = (len + inserted).saturating_sub(self.settings.capacity);
            match self.place(time, reading, trimmed) {
                Ok(slot) => {
                    inserted += usize::from(!slot.ignored);
                    self.slots.push(slot);
                }
                Err(error) => {
                    self.remove_batch();
                    return Err(BatchError { index, error });
                }
            }
        }
        let first = self.slots.iter().filter(|s| !s.ignored).map(|s| s.at).min();
        if let Some(first) = first {
            // Appended only: the live filter is the checkpoint's.
            let run = self.run_indexed(first, first < len);
            // Every measurement record from `first` on has its decision after a run, and the
            // ignored readings' kept records are measurements already decided or re-run.
            let undecided = self
                .slots
                .iter()
                .position(|s| self.history.get(s.at).outcome.is_none());
            let failed = match (run, undecided) {
                (Err((failed, error)), _) => Some((self.failed_reading(failed), error)),
                (Ok(()), Some(index)) => Some((
                    index,
                    FusionError::Filter(Error::NonFinite {
                        stage: Stage::Update,
                        quantity: Quantity::Measurement,
                    }),
                )),
                (Ok(()), None) => None,
            };
            if let Some((index, error)) = failed {
                self.remove_batch();
                // The same events from the same checkpoint: the same (successful) steps.
                let _ = self.run_from(first, true);
                return Err(BatchError { index, error });
            }
        }
        for slot in &self.slots {
            let record = self.history.get(slot.at);
            if let Some(outcome) = record.outcome {
                self.fused.push(Fused {
                    sensor: slot.sensor,
                    time: slot.time,
                    outcome,
                    replayed: slot.replayed,
                    ignored: slot.ignored,
                });
            }
        }
        self.history.trim();
        Ok(&self.fused)
    }

    /// Checks a reading as [`fuse`](Self::fuse) would after the batch's readings so far (the
    /// oldest `trimmed` records gone) and inserts it, without running anything.
    pub(super) fn place(
        &mut self,
        time: f64,
        reading: S::Reading,
        trimmed: usize,
    ) -> Result<Slot, FusionError> {
        if !time.is_finite() {
            return Err(FusionError::NonFiniteTime { time });
        }
        let count = self.sensors.count();
        let sensor = self.sensors.sensor(&reading);
        if sensor >= count {
            return Err(FusionError::UnknownSensor { sensor, count });
        }
        let latest = self.history.latest().time;
        let oldest = self
            .history
            .get(trimmed)
            .time
            .max(latest - self.settings.horizon);
        if time < oldest {
            return Err(FusionError::TooOld { time, oldest });
        }
        let first = (trimmed..self.history.len())
            .find(|&i| self.history.get(i).is_measurement(time, sensor));
        match (first, self.settings.duplicates) {
            (None, _) | (Some(_), DuplicatePolicy::FuseBoth) => {}
            (Some(_), DuplicatePolicy::Refuse) => {
                return Err(FusionError::Duplicate { sensor, time });
            }
            (Some(at), DuplicatePolicy::KeepFirst) => {
                return Ok(Slot {
                    at,
                    time,
                    sensor,
                    replayed: 0,
                    ignored: true,
                });
            }
        }
        let at = self.history.insertion_index(time, sensor);
        if at <= trimmed {
            return Err(FusionError::TooOld { time, oldest });
        }
        if at == self.history.len() {
            substeps(time - latest, &self.settings)?;
        }
        self.history
            .insert(at, time, Event::Measurement { sensor, reading });
        for slot in &mut self.slots {
            if slot.at >= at {
                slot.at += 1;
            }
        }
        Ok(Slot {
            at,
            time,
            sensor,
            replayed: self.history.len() - 1 - at,
            ignored: false,
        })
    }

    /// The reading a replay failure at record `failed` is blamed on: the one at that record,
    /// or the last one (in the order given) placed before it.
    fn failed_reading(&self, failed: usize) -> usize {
        let placed =
            |s: &Slot, before: bool| !s.ignored && (s.at == failed || before && s.at < failed);
        self.slots
            .iter()
            .position(|s| placed(s, false))
            .or_else(|| self.slots.iter().rposition(|s| placed(s, true)))
            .unwrap_or(0)
    }

    /// Removes the batch's inserted records (latest first, so the others keep their places).
    fn remove_batch(&mut self) {
        self.slots.retain(|s| !s.ignored);
        self.slots
            .sort_unstable_by_key(|s| core::cmp::Reverse(s.at));
        for slot in &self.slots {
            self.history.remove(slot.at);
        }
        self.slots.clear();
    }
}
