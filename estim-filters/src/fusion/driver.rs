//! The fusion driver: time, replay of late measurements, and the decision on each one.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, convert};
use estim_core::{Alloc, Error, Gaussian, Quantity, Real, Stage};

use super::error::{FusionError, FusionSetting};
use super::history::{Event, History, Record};
use super::monitor::{Health, SensorHealth};
use super::outcome::{ExclusionReason, Fused, Innovation, Outcome, ResetReason};
use super::sensors::SensorSet;
use super::settings::{FusionSettings, InputConvention, Resolved, SensorSettings};
use crate::traits::{Estimator, Predict, ProcessInput, Rollback};

mod batch;
mod smooth;

/// A filter `F` of the family, its process model `P` with its input, and the sensors `S`,
/// driven by timestamped events: see the [module docs](super) for what it does and why.
///
/// Requirements: `F` predicts with `P` ([`Predict`]) and can be rolled back ([`Rollback`]:
/// every filter of the family), and `S` updates `F` ([`SensorSet`]); the input is `Clone`
/// (it is recorded). `P` is whatever `F` predicts with: a process model for the single-model
/// filters, a set of per-mode models for a multiple-model estimator.
pub struct FusionDriver<T, N, F, P, S>
where
    T: Real,
    N: Dim,
    F: Predict<T, N, P> + Rollback,
    P: ProcessInput<T, N>,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    filter: F,
    process: P,
    sensors: S,
    settings: FusionSettings,
    convention: InputConvention,
    resolved: Vec<Resolved<T>>,
    input: P::Input,
    health: Health<T>,
    history: History<T, F::Snapshot, P::Input, S::Reading>,
    /// The filter before the update being decided, put back when the decision undoes it.
    prior: F::Snapshot,
    prior_state: OVector<T, N>,
    prior_covariance: OMatrix<T, N, N>,
    /// Where the readings of the current [`fuse_all`](Self::fuse_all) batch went.
    slots: Vec<batch::Slot>,
    /// What [`fuse_all`](Self::fuse_all) returns.
    fused: Vec<Fused<T>>,
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
    /// A driver at time `start` (seconds) whose filter holds the estimate at that time, with
    /// `input` held from then on and every sensor judged by `sensor_settings` (change one with
    /// [`with_sensor_settings`](Self::with_sensor_settings)). Allocates the whole history.
    ///
    /// Errors: [`FusionError::InvalidSetting`] for a setting out of range (including a
    /// non-finite `start`).
    ///
    /// ```
    /// # use estim_core::nalgebra::{Matrix1, U1, Vector1};
    /// # use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
    /// # use estim_filters::fusion::{FusionDriver, FusionError, FusionSettings, Innovation, MonitorSettings, SensorSet, SensorSettings, SensorStatus};
    /// # use estim_filters::{Estimator, KalmanFilter, Update};
    /// # struct One(LinearMeasurement<f64, U1, U1>);
    /// # impl<F: Update<f64, U1, U1, LinearMeasurement<f64, U1, U1>>> SensorSet<f64, U1, F> for One {
    /// #     type Reading = Vector1<f64>;
    /// #     fn count(&self) -> usize { 1 }
    /// #     fn sensor(&self, _: &Vector1<f64>) -> usize { 0 }
    /// #     fn dimension(&self, _: usize) -> usize { 1 }
    /// #     fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> { f.update(&self.0, z).map(|r| Innovation::of(&r)) }
    /// # }
    /// // A speed integrated from an acceleration input, observed directly.
    /// let speed = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::new(0.01), noise: Matrix1::new(1e-6) };
    /// let sensor = One(LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.01) });
    /// let filter = KalmanFilter::new(Gaussian::new(Vector1::zeros(), Matrix1::new(1.0))?);
    /// // Steps of 10 ms: the input matrix is per step.
    /// let settings = FusionSettings { max_step: 0.01, ..FusionSettings::default() };
    /// let mut driver = FusionDriver::new(filter, speed, Vector1::new(0.0), sensor, 0.0, settings, SensorSettings::default())?;
    /// driver.set_input(0.5, Vector1::new(2.0))?; // 2 m/s² from 0.5 s on
    /// driver.advance_to(1.5)?;                     // 100 steps of 10 ms at 2 m/s²
    /// assert!((driver.filter().state()[0] - 2.0).abs() < 1e-9);
    /// assert!(matches!(driver.set_input(1.0, Vector1::new(0.0)), Err(FusionError::NotMonotone { .. })));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn new(
        filter: F,
        process: P,
        input: P::Input,
        sensors: S,
        start: f64,
        settings: FusionSettings,
        sensor_settings: SensorSettings,
    ) -> Result<Self, FusionError> {
        settings.validate()?;
        if !start.is_finite() {
            return Err(FusionError::setting(FusionSetting::StartTime, start));
        }
        let n = filter.state().nrows();
        let resolved = (0..sensors.count())
            .map(|s| sensor_settings.resolve(sensors.dimension(s), n))
            .collect::<Result<Vec<_>, _>>()?;
        let health = Health::new(resolved.iter().map(window_of));
        let start_record = Record {
            time: start,
            event: Event::Start,
            snapshot: filter.snapshot(),
            input: input.clone(),
            health: health.clone(),
            outcome: None,
        };
        let mut history = History::new(start_record, settings.capacity);
        // A batch of one reading per sensor never allocates.
        history.reserve(sensors.count());
        Ok(Self {
            slots: Vec::with_capacity(sensors.count()),
            fused: Vec::with_capacity(sensors.count()),
            prior: filter.snapshot(),
            prior_state: filter.state().clone(),
            prior_covariance: filter.covariance().clone(),
            history,
            filter,
            process,
            sensors,
            settings,
            convention: InputConvention::HoldForward,
            resolved,
            input,
            health,
        })
    }

    /// The same driver with inputs read by `convention` ([`InputConvention`]; the default is
    /// [`InputConvention::HoldForward`]). With [`InputConvention::Preceding`], the input given
    /// to [`new`](Self::new) is held forward until the first sample arrives, and the first
    /// sample covers the time from the start to its timestamp.
    ///
    /// Errors: [`FusionError::InvalidSetting`] ([`FusionSetting::InputConvention`]) once an
    /// event has been recorded: the history would mix the two readings.
    ///
    /// ```
    /// # use estim_core::nalgebra::{Matrix1, U1, Vector1};
    /// # use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
    /// # use estim_filters::fusion::{FusionDriver, FusionSettings, InputConvention, Innovation, SensorSet, SensorSettings};
    /// # use estim_filters::{Estimator, KalmanFilter, Update};
    /// # struct One(LinearMeasurement<f64, U1, U1>);
    /// # impl<F: Update<f64, U1, U1, LinearMeasurement<f64, U1, U1>>> SensorSet<f64, U1, F> for One {
    /// #     type Reading = Vector1<f64>;
    /// #     fn count(&self) -> usize { 1 }
    /// #     fn sensor(&self, _: &Vector1<f64>) -> usize { 0 }
    /// #     fn dimension(&self, _: usize) -> usize { 1 }
    /// #     fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> { f.update(&self.0, z).map(|r| Innovation::of(&r)) }
    /// # }
    /// // A speed integrated from accelerometer samples: each covers the 10 ms before it.
    /// let speed = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::new(0.01), noise: Matrix1::new(1e-6) };
    /// let sensor = One(LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.01) });
    /// let filter = KalmanFilter::new(Gaussian::new(Vector1::zeros(), Matrix1::new(1.0))?);
    /// let settings = FusionSettings { max_step: 0.01, ..FusionSettings::default() };
    /// let mut driver = FusionDriver::new(filter, speed, Vector1::new(0.0), sensor, 0.0, settings, SensorSettings::default())?
    ///     .with_input_convention(InputConvention::Preceding)?;
    /// for k in 1..=100 {
    ///     // 2 m/s² over (0, 0.5 s], then 0.
    ///     let a = if k <= 50 { 2.0 } else { 0.0 };
    ///     driver.set_input(0.01 * k as f64, Vector1::new(a))?;
    /// }
    /// assert!((driver.filter().state()[0] - 1.0).abs() < 1e-9);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn with_input_convention(
        mut self,
        convention: InputConvention,
    ) -> Result<Self, FusionError> {
        if self.history.len() > 1 || !matches!(self.history.latest().event, Event::Start) {
            return Err(FusionError::setting(
                FusionSetting::InputConvention,
                self.history.len() as f64,
            ));
        }
        self.convention = convention;
        Ok(self)
    }

    /// The same driver with `settings` for `sensor`. That sensor's health restarts (counters
    /// zero, window empty, admitted), in the history too.
    ///
    /// Errors: [`FusionError::InvalidSetting`] for a setting out of range or a sensor index
    /// ≥ the number of sensors.
    pub fn with_sensor_settings(
        mut self,
        sensor: usize,
        settings: SensorSettings,
    ) -> Result<Self, FusionError> {
        if sensor >= self.resolved.len() {
            return Err(FusionError::setting(FusionSetting::Sensor, sensor as f64));
        }
        let resolved =
            settings.resolve(self.sensors.dimension(sensor), self.filter.state().nrows())?;
        let fresh = Health::new(core::iter::once(window_of(&resolved)));
        self.health.sensors[sensor] = fresh.sensors[0].clone();
        for record in self.history.all_mut() {
            record.health.sensors[sensor] = fresh.sensors[0].clone();
        }
        self.resolved[sensor] = resolved;
        Ok(self)
    }

    /// Fuses `reading`, taken at `time` seconds, at that time: predicted to from the event
    /// before it, decided ([`Outcome`]), and, if later events were already fused, those are
    /// re-run after it (exactly as if everything had arrived in time order).
    ///
    /// Errors, each leaving the driver exactly as it was: [`FusionError::NonFiniteTime`],
    /// [`FusionError::UnknownSensor`], [`FusionError::TooOld`] (more than the horizon before
    /// the latest event, or before the oldest record kept), [`FusionError::Duplicate`] (this
    /// sensor already has a measurement at this time and [`FusionSettings::duplicates`] is
    /// [`DuplicatePolicy::Refuse`](super::DuplicatePolicy::Refuse); the default fuses both),
    /// [`FusionError::GapTooLong`], and
    /// [`FusionError::Filter`] when a filter step fails (e.g. a non-finite reading).
    ///
    /// ```
    /// # use estim_core::nalgebra::{Matrix1, U1, Vector1};
    /// # use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
    /// # use estim_filters::fusion::{DuplicatePolicy, FusionDriver, FusionError, FusionSettings, Innovation, SensorSet, SensorSettings};
    /// # use estim_filters::{Estimator, KalmanFilter, Update};
    /// # struct One(LinearMeasurement<f64, U1, U1>);
    /// # impl<F: Update<f64, U1, U1, LinearMeasurement<f64, U1, U1>>> SensorSet<f64, U1, F> for One {
    /// #     type Reading = Vector1<f64>;
    /// #     fn count(&self) -> usize { 1 }
    /// #     fn sensor(&self, _: &Vector1<f64>) -> usize { 0 }
    /// #     fn dimension(&self, _: usize) -> usize { 1 }
    /// #     fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> { f.update(&self.0, z).map(|r| Innovation::of(&r)) }
    /// # }
    /// let walk = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(1e-3) };
    /// let sensor = One(LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.1) });
    /// let filter = KalmanFilter::new(Gaussian::new(Vector1::zeros(), Matrix1::new(1.0))?);
    /// let settings = FusionSettings { horizon: 0.3, duplicates: DuplicatePolicy::Refuse, ..FusionSettings::default() };
    /// let mut driver = FusionDriver::new(filter, walk, Vector1::zeros(), sensor, 0.0, settings, SensorSettings::default())?;
    /// driver.fuse(1.0, Vector1::new(0.5))?;
    /// let before = driver.filter().estimate();
    /// // Taken 0.5 s before the latest event, beyond the 0.3 s horizon: refused, nothing changed.
    /// assert!(matches!(driver.fuse(0.5, Vector1::new(0.4)), Err(FusionError::TooOld { .. })));
    /// assert!(matches!(driver.fuse(f64::NAN, Vector1::new(0.4)), Err(FusionError::NonFiniteTime { .. })));
    /// assert!(matches!(driver.fuse(1.0, Vector1::new(0.4)), Err(FusionError::Duplicate { sensor: 0, .. })));
    /// assert_eq!(driver.filter().estimate(), before);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn fuse(&mut self, time: f64, reading: S::Reading) -> Result<Fused<T>, FusionError> {
        // The same checks and insertion as a batch of one (nothing trimmed yet).
        let slot = self.place(time, reading, 0)?;
        let (at, sensor) = (slot.at, slot.sensor);
        // Between calls every recorded measurement has its decision: `None` is unreachable.
        let undecided = FusionError::Filter(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
        });
        if slot.ignored {
            // KeepFirst: the reading already recorded at this time keeps its decision.
            let outcome = self.history.get(at).outcome.ok_or(undecided)?;
            return Ok(Fused {
                sensor,
                time,
                outcome,
                replayed: 0,
                ignored: true,
            });
        }
        if let Err(e) = self.run_from(at, at + 1 < self.history.len()) {
            self.undo(at);
            return Err(e);
        }
        let outcome = self.history.get(at).outcome.ok_or(undecided)?;
        let replayed = self.history.len() - 1 - at;
        self.history.trim();
        Ok(Fused {
            sensor,
            time,
            outcome,
            replayed,
            ignored: false,
        })
    }

    /// A new input at `time`, read by the driver's [`InputConvention`]:
    ///
    /// - [`HoldForward`](InputConvention::HoldForward): predicts to `time` with the input in
    ///   force, then holds `input` from `time` on. `time` ≥ the latest event.
    /// - [`Preceding`](InputConvention::Preceding): `input` covers the interval from the
    ///   previous input's time to `time`: the events after the previous input (measurements
    ///   fused at their time, marks) are re-run with it, and it is held forward after `time`
    ///   until the next one arrives. `time` ≥ the previous input's time (inputs come in time
    ///   order; measurements may be ahead of them) and within the horizon.
    ///
    /// Errors (driver unchanged): [`FusionError::NonFiniteTime`], [`FusionError::NotMonotone`],
    /// [`FusionError::TooOld`] (preceding inputs only), [`FusionError::GapTooLong`],
    /// [`FusionError::Filter`].
    pub fn set_input(&mut self, time: f64, input: P::Input) -> Result<(), FusionError> {
        match self.convention {
            InputConvention::HoldForward => self.append(time, Event::Input(input)),
            InputConvention::Preceding => self.insert_sample(time, input),
        }
    }

    /// [`set_input`](Self::set_input) for [`InputConvention::Preceding`].
    fn insert_sample(&mut self, time: f64, input: P::Input) -> Result<(), FusionError> {
        if !time.is_finite() {
            return Err(FusionError::NonFiniteTime { time });
        }
        let len = self.history.len();
        let previous = (0..len)
            .rev()
            .find(|&i| matches!(self.history.get(i).event, Event::Input(_)));
        if let Some(i) = previous {
            let latest = self.history.get(i).time;
            if time < latest {
                return Err(FusionError::NotMonotone { time, latest });
            }
        }
        let latest = self.history.latest().time;
        let oldest = self
            .history
            .oldest()
            .time
            .max(latest - self.settings.horizon);
        if time < oldest {
            return Err(FusionError::TooOld { time, oldest });
        }
        // After every record at or before `time`: never 0, the oldest record is at or before.
        let mut at = len;
        while at > 0 && self.history.get(at - 1).time > time {
            at -= 1;
        }
        if at == 0 {
            return Err(FusionError::TooOld { time, oldest });
        }
        if at == len {
            substeps(time - latest, &self.settings)?;
        }
        // The events since the previous input were predicted with it held forward; they are
        // re-run with this one.
        let start = previous.map_or(1, |i| i + 1).min(at);
        self.history.insert(at, time, Event::Input(input));
        let restore = start + 1 < self.history.len();
        if let Err(e) = self.run_from(start, restore) {
            self.history.remove(at);
            let _ = self.run_from(start, true);
            return Err(e);
        }
        self.history.trim();
        Ok(())
    }

    /// Predicts to `time` (≥ the latest event) with the input in force: the filter then holds
    /// the estimate at `time`, e.g. the real-time estimate between late measurements. Recorded
    /// like any event (a later replay predicts in the same pieces).
    ///
    /// Errors as [`set_input`](Self::set_input).
    pub fn advance_to(&mut self, time: f64) -> Result<(), FusionError> {
        self.append(time, Event::Mark)
    }

    fn append(&mut self, time: f64, event: Event<P::Input, S::Reading>) -> Result<(), FusionError> {
        if !time.is_finite() {
            return Err(FusionError::NonFiniteTime { time });
        }
        let latest = self.history.latest().time;
        if time < latest {
            return Err(FusionError::NotMonotone { time, latest });
        }
        substeps(time - latest, &self.settings)?;
        let at = self.history.len();
        self.history.insert(at, time, event);
        if let Err(e) = self.run_from(at, false) {
            self.undo(at);
            return Err(e);
        }
        self.history.trim();
        Ok(())
    }

    /// Removes the record inserted at `at` and restores everything from the history (the
    /// records before `at` are untouched; the ones after are re-run as they were).
    fn undo(&mut self, at: usize) {
        self.history.remove(at);
        // The same events from the same checkpoint: the same (successful) steps as before.
        let _ = self.run_from(at, true);
    }

    /// Re-runs the records from `start` on from the checkpoint `start − 1` (restored first if
    /// `restore`; otherwise the live state must be that checkpoint's).
    fn run_from(&mut self, start: usize, restore: bool) -> Result<(), FusionError> {
        self.run_indexed(start, restore).map_err(|(_, e)| e)
    }

    /// [`run_from`](Self::run_from), with the index of the record that failed.
    fn run_indexed(&mut self, start: usize, restore: bool) -> Result<(), (usize, FusionError)> {
        let Self {
            filter,
            process,
            sensors,
            settings,
            convention,
            resolved,
            input,
            health,
            history,
            prior,
            prior_state,
            prior_covariance,
            ..
        } = self;
        let checkpoint = history.get(start - 1);
        if restore {
            filter.restore(&checkpoint.snapshot);
            input.clone_from(&checkpoint.input);
            health.copy_from(&checkpoint.health);
        }
        let mut previous = checkpoint.time;
        let preceding = *convention == InputConvention::Preceding;
        let len = history.len();
        // Preceding inputs: the index of the first input record at or after j (`len`: none,
        // the latest input is held forward), found once per input, not once per record.
        let mut next = 0;
        for j in start..len {
            let time = history.get(j).time;
            if preceding && next < j {
                next = (j..len)
                    .find(|&k| matches!(history.get(k).event, Event::Input(_)))
                    .unwrap_or(len);
            }
            let span_input = match (preceding && next < len).then(|| &history.get(next).event) {
                Some(Event::Input(u)) => u,
                _ => &*input,
            };
            predict_span(filter, process, span_input, time - previous, settings)
                .map_err(|e| (j, e))?;
            let record = history.get_mut(j);
            match &record.event {
                Event::Input(u) => input.clone_from(u),
                Event::Start | Event::Mark => {}
                Event::Measurement { sensor, reading } => {
                    let work = Work {
                        prior: &mut *prior,
                        prior_state: &mut *prior_state,
                        prior_covariance: &mut *prior_covariance,
                    };
                    record.outcome = Some(
                        decide(
                            filter,
                            sensors,
                            reading,
                            *sensor,
                            &resolved[*sensor],
                            health,
                            work,
                        )
                        .map_err(|e| (j, e))?,
                    );
                }
            }
            filter.snapshot_into(&mut record.snapshot);
            record.input.clone_from(input);
            record.health.copy_from(health);
            previous = record.time;
        }
        Ok(())
    }
}

impl<T, N, F, P, S> FusionDriver<T, N, F, P, S>
where
    T: Real,
    N: Dim,
    F: Predict<T, N, P> + Rollback,
    P: ProcessInput<T, N>,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    /// The filter, holding the estimate at [`time`](Self::time).
    pub fn filter(&self) -> &F {
        &self.filter
    }

    /// The process model.
    pub fn process(&self) -> &P {
        &self.process
    }

    /// The sensors.
    pub fn sensors(&self) -> &S {
        &self.sensors
    }

    /// The input in force.
    pub fn input(&self) -> &P::Input {
        &self.input
    }

    /// The time of the latest event (the filter's estimate is at this time) \[s\].
    pub fn time(&self) -> f64 {
        self.history.latest().time
    }

    /// The oldest time a measurement may still have \[s\]: the later of the oldest record kept
    /// and the latest event minus the horizon.
    pub fn oldest_time(&self) -> f64 {
        self.history
            .oldest()
            .time
            .max(self.time() - self.settings.horizon)
    }

    /// The number of records in the history (≤ [`FusionSettings::capacity`]).
    pub fn history_len(&self) -> usize {
        self.history.len()
    }

    /// The settings.
    pub fn settings(&self) -> &FusionSettings {
        &self.settings
    }

    /// The number of sensors.
    pub fn sensor_count(&self) -> usize {
        self.resolved.len()
    }

    /// The gate threshold of `sensor` (the χ²ₘ quantile), if it has a gate.
    ///
    /// # Panics
    ///
    /// If `sensor` ≥ [`sensor_count`](Self::sensor_count).
    #[track_caller]
    pub fn gate(&self, sensor: usize) -> Option<T> {
        self.resolved[sensor].gate
    }

    /// The fault monitor's threshold q and clip c of `sensor`, if it has a monitor.
    ///
    /// # Panics
    ///
    /// If `sensor` ≥ [`sensor_count`](Self::sensor_count).
    #[track_caller]
    pub fn monitor_thresholds(&self, sensor: usize) -> Option<(T, T)> {
        self.resolved[sensor]
            .monitor
            .as_ref()
            .map(|m| (m.threshold, m.clip))
    }

    /// The health of `sensor` after the latest event.
    ///
    /// ```
    /// # use estim_core::nalgebra::{Matrix1, U1, Vector1};
    /// # use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
    /// # use estim_filters::fusion::{FusionDriver, FusionError, FusionSettings, Innovation, MonitorSettings, SensorSet, SensorSettings, SensorStatus};
    /// # use estim_filters::{Estimator, KalmanFilter, Update};
    /// # struct One(LinearMeasurement<f64, U1, U1>);
    /// # impl<F: Update<f64, U1, U1, LinearMeasurement<f64, U1, U1>>> SensorSet<f64, U1, F> for One {
    /// #     type Reading = Vector1<f64>;
    /// #     fn count(&self) -> usize { 1 }
    /// #     fn sensor(&self, _: &Vector1<f64>) -> usize { 0 }
    /// #     fn dimension(&self, _: usize) -> usize { 1 }
    /// #     fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> { f.update(&self.0, z).map(|r| Innovation::of(&r)) }
    /// # }
    /// let walk = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(1e-4) };
    /// let sensor = One(LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.01) });
    /// let filter = KalmanFilter::new(Gaussian::new(Vector1::zeros(), Matrix1::new(0.01))?);
    /// let monitor = MonitorSettings { window: 5, ..MonitorSettings::default() };
    /// let mut driver = FusionDriver::new(filter, walk, Vector1::zeros(), sensor, 0.0, FusionSettings::default(), SensorSettings::default())?
    ///     .with_sensor_settings(0, SensorSettings::gated(0.999).with_monitor(monitor))?;
    /// // The sensor sticks at 5 (50 σ): rejected, then excluded as faulty.
    /// for k in 1..=6 { driver.fuse(0.1 * k as f64, Vector1::new(5.0))?; }
    /// let health = driver.health(0);
    /// assert_eq!(health.status, SensorStatus::Excluded);
    /// assert_eq!(health.faults, 1);
    /// assert!(health.rejected >= 1);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Panics
    ///
    /// If `sensor` ≥ [`sensor_count`](Self::sensor_count).
    #[track_caller]
    pub fn health(&self, sensor: usize) -> SensorHealth<T> {
        self.health.sensors[sensor].summary()
    }

    /// The prediction-error log-likelihood of the run so far, Σ ln N(νᵢ; 0, Sᵢ) over the
    /// accepted measurements ([`Outcome::Accepted`]; rejected, excluded and reset ones add
    /// nothing), each taken at its time (a late one after its replay): the
    /// [`Sequence::log_likelihood`](crate::smoother::Sequence::log_likelihood) of the same
    /// readings in time order, so maximum-likelihood noise identification
    /// ([`noise_id`](crate::noise_id)) works over a driver run. It covers the whole run, not
    /// only the history kept.
    ///
    /// ```
    /// # use estim_core::nalgebra::{Matrix1, U1, Vector1};
    /// # use estim_core::{Gaussian, LinearMeasurement, LinearProcess, error::Result};
    /// # use estim_filters::fusion::{FusionDriver, FusionSettings, Innovation, SensorSet, SensorSettings};
    /// # use estim_filters::{KalmanFilter, Update};
    /// # struct One(LinearMeasurement<f64, U1, U1>);
    /// # impl<F: Update<f64, U1, U1, LinearMeasurement<f64, U1, U1>>> SensorSet<f64, U1, F> for One {
    /// #     type Reading = Vector1<f64>;
    /// #     fn count(&self) -> usize { 1 }
    /// #     fn sensor(&self, _: &Vector1<f64>) -> usize { 0 }
    /// #     fn dimension(&self, _: usize) -> usize { 1 }
    /// #     fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> { f.update(&self.0, z).map(|r| Innovation::of(&r)) }
    /// # }
    /// let walk = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(1e-2) };
    /// let sensor = One(LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.1) });
    /// let filter = KalmanFilter::new(Gaussian::new(Vector1::zeros(), Matrix1::new(1.0))?);
    /// let mut driver = FusionDriver::new(filter, walk, Vector1::zeros(), sensor, 0.0, FusionSettings::default(), SensorSettings::default())?;
    /// let first = driver.fuse(1.0, Vector1::new(0.3))?.outcome.innovation().log_likelihood;
    /// // S = P⁻ + R = 1.01 + 0.1, ν = 0.3.
    /// let expected = -0.5 * (0.3f64.powi(2) / 1.11 + (2.0 * std::f64::consts::PI * 1.11).ln());
    /// assert!((first - expected).abs() < 1e-12);
    /// driver.fuse(2.0, Vector1::new(0.2))?;
    /// assert!(driver.log_likelihood() < first); // a second term, negative here
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn log_likelihood(&self) -> T {
        self.health.log_likelihood
    }

    /// The decisions recorded in the history, oldest first, as `(time, sensor, outcome)`:
    /// after a replay they are the re-made ones.
    pub fn decisions(&self) -> impl Iterator<Item = (f64, usize, Outcome<T>)> + '_ {
        self.history
            .iter()
            .filter_map(|r| match (&r.event, r.outcome) {
                (&Event::Measurement { sensor, .. }, Some(outcome)) => {
                    Some((r.time, sensor, outcome))
                }
                _ => None,
            })
    }
}

fn window_of<T>(resolved: &Resolved<T>) -> usize {
    resolved.monitor.as_ref().map_or(0, |m| m.window)
}

/// The number of equal sub-steps for a gap: ⌈gap / h − 10⁻⁹⌉ (at least 1 for a gap > 0).
fn substeps(gap: f64, settings: &FusionSettings) -> Result<usize, FusionError> {
    if gap <= 0.0 {
        return Ok(0);
    }
    let n = (gap / settings.max_step - 1e-9).ceil().max(1.0);
    if n <= settings.max_substeps as f64 {
        Ok(n as usize)
    } else {
        Err(FusionError::GapTooLong {
            gap,
            max_step: settings.max_step,
        })
    }
}

/// Predicts over `gap` seconds in equal sub-steps.
fn predict_span<T, N, F, P>(
    filter: &mut F,
    process: &P,
    input: &P::Input,
    gap: f64,
    settings: &FusionSettings,
) -> Result<(), FusionError>
where
    T: Real,
    N: Dim,
    F: Predict<T, N, P>,
    P: ProcessInput<T, N>,
    DefaultAllocator: Alloc<N>,
{
    let n = substeps(gap, settings)?;
    if n == 0 {
        return Ok(());
    }
    let dt: T = convert(gap / n as f64);
    for _ in 0..n {
        filter.predict(process, input, dt)?;
    }
    Ok(())
}

/// The driver's buffers for the filter before an update: its snapshot (put back, to the bit,
/// when the decision undoes the update) and its estimate (read, and re-initialised by a
/// covariance reset).
struct Work<'a, T: Real, N: Dim, Sn>
where
    DefaultAllocator: Alloc<N>,
{
    prior: &'a mut Sn,
    prior_state: &'a mut OVector<T, N>,
    prior_covariance: &'a mut OMatrix<T, N, N>,
}

/// The decision on one measurement (see the module docs, "Decisions"). On error the caller
/// restores everything from the history.
fn decide<T, N, F, S>(
    filter: &mut F,
    sensors: &S,
    reading: &S::Reading,
    sensor: usize,
    config: &Resolved<T>,
    health: &mut Health<T>,
    work: Work<'_, T, N, F::Snapshot>,
) -> Result<Outcome<T>, FusionError>
where
    T: Real,
    N: Dim,
    F: Estimator<T, N> + Rollback,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    let Work {
        prior,
        prior_state,
        prior_covariance,
    } = work;
    filter.snapshot_into(prior);
    if config.reset.is_some() {
        prior_state.copy_from(filter.state());
        prior_covariance.copy_from(filter.covariance());
    }
    let innovation: Innovation<T> = sensors.update(filter, reading)?;
    if innovation.dimension != config.dimension {
        return Err(FusionError::Filter(Error::DimensionMismatch {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
            expected_rows: config.dimension,
            expected_cols: 1,
            found_rows: innovation.dimension,
            found_cols: 1,
        }));
    }
    let accepted_total = health.accepted;
    let state = &mut health.sensors[sensor];
    let nis = innovation.nis;
    state.health.last_nis = nis;

    if let Some(monitor) = &config.monitor {
        // `nis <= clip` is false for NaN, which then counts as the clip (evidence of a fault).
        state.window.push(if nis <= monitor.clip {
            nis
        } else {
            monitor.clip
        });
        let window_sum = state.window.sum();
        if state.excluded {
            filter.restore(prior);
            state.since_exclusion += 1;
            state.health.excluded += 1;
            let reason = if state.window.is_full() && window_sum <= monitor.threshold {
                state.excluded = false;
                state.run = 0;
                state.health.readmissions += 1;
                ExclusionReason::Readmitted { window_sum }
            } else {
                ExclusionReason::SensorExcluded {
                    window_sum,
                    since_exclusion: state.since_exclusion,
                }
            };
            return Ok(Outcome::Excluded { innovation, reason });
        }
        if !(window_sum <= monitor.threshold) {
            filter.restore(prior);
            state.excluded = true;
            state.since_exclusion = 0;
            state.window.clear();
            state.run = 0;
            state.health.faults += 1;
            state.health.excluded += 1;
            let reason = ExclusionReason::FaultDetected {
                window_sum,
                threshold: monitor.threshold,
            };
            return Ok(Outcome::Excluded { innovation, reason });
        }
    }

    let gated = !innovation.applied || config.gate.is_some_and(|g| !(nis <= g));
    if let Some(reset) = &config.reset {
        let blow_up = reset.blow_up.and_then(|limit| {
            reset
                .states
                .iter()
                .map(|&i| (i, prior_covariance[(i, i)]))
                .find(|&(_, v)| !(v <= limit))
        });
        let run = if gated { state.run + 1 } else { 0 };
        let run_start = if state.run == 0 {
            accepted_total
        } else {
            state.run_start_accepted
        };
        let reason = match blow_up {
            Some((state, variance)) => Some(ResetReason::CovarianceBlowUp { state, variance }),
            None if gated && run >= reset.after && run_start == accepted_total => {
                Some(ResetReason::RejectionRun { rejections: run })
            }
            None => None,
        };
        if let Some(reason) = reason {
            // The reset states forget their correlations and take the large prior variance;
            // then the measurement is applied to the re-initialised estimate, ungated.
            let n = prior_covariance.nrows();
            for &i in &reset.states {
                for j in 0..n {
                    prior_covariance[(i, j)] = T::zero();
                    prior_covariance[(j, i)] = T::zero();
                }
            }
            for &i in &reset.states {
                prior_covariance[(i, i)] = reset.variance;
            }
            // A re-initialisation from a new Gaussian, not a rollback: `reset` is the contract.
            filter.reset(Gaussian::new_unchecked(
                prior_state.clone(),
                prior_covariance.clone(),
            ));
            sensors.update(filter, reading)?;
            state.run = 0;
            state.window.clear();
            state.health.resets += 1;
            health.accepted += 1;
            return Ok(Outcome::Reset { innovation, reason });
        }
    }
    if gated {
        filter.restore(prior);
        if state.run == 0 {
            state.run_start_accepted = accepted_total;
        }
        state.run += 1;
        state.health.rejected += 1;
        let test_ratio = config.gate.map_or(T::one(), |g| nis / g);
        return Ok(Outcome::Rejected {
            innovation,
            test_ratio,
        });
    }
    state.run = 0;
    state.health.accepted += 1;
    health.accepted += 1;
    health.log_likelihood += innovation.log_likelihood;
    Ok(Outcome::Accepted { innovation })
}
