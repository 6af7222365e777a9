//! The driver's run smoothed: the Rauch–Tung–Striebel backward pass over its history.

use estim_core::nalgebra::{DefaultAllocator, Dim, convert};
use estim_core::{Alloc, Real};

use super::super::history::Event;
use super::super::sensors::SensorSet;
use super::super::settings::InputConvention;
use super::{FusionDriver, substeps};
use crate::smoother::{Rts, SmootherError, Track};
use crate::traits::{PredictCross, ProcessInput, Rollback};

impl<T, N, F, P, S> FusionDriver<T, N, F, P, S>
where
    T: Real,
    N: Dim,
    F: PredictCross<T, N, P> + Rollback,
    P: ProcessInput<T, N>,
    S: SensorSet<T, N, F>,
    DefaultAllocator: Alloc<N>,
{
    /// The run smoothed over the history kept ([`FusionSettings::capacity`] records, from
    /// [`oldest_time`](Self::oldest_time)'s record on), in time order, each late reading where
    /// it was taken: the estimates at the times of the events (and of the sub-steps, if
    /// [`FusionSettings::max_step`] cuts the gaps), given every reading up to the latest.
    ///
    /// How: the history already holds the filter after every event (the checkpoints the
    /// replays start from). For each gap between events the filter is put back to the
    /// checkpoint before it and predicted across it with [`Rts::predict`] (recording the
    /// prediction and its cross-covariance); the filtered estimates are the checkpoints, so
    /// the decisions (accepted, rejected, reset) are the run's own, nothing is re-decided.
    /// The backward pass is then [`Rts`]'s. The filter is put back to its latest checkpoint,
    /// bit for bit, success or not: the driver is unchanged. To smooth a whole log, size
    /// [`FusionSettings::capacity`] to its number of events (at most
    /// [`FusionSettings::MAX_CAPACITY`]) or smooth in windows.
    ///
    /// Errors: the backward pass's ([`SmootherError`], its `step` indexing the returned
    /// track); a prediction that fails when re-run ([`SmootherError::error`], `step` the
    /// estimate it started from).
    ///
    /// [`FusionSettings::capacity`]: super::super::FusionSettings::capacity
    /// [`FusionSettings::max_step`]: super::super::FusionSettings::max_step
    /// [`FusionSettings::MAX_CAPACITY`]: super::super::FusionSettings::MAX_CAPACITY
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
    /// driver.fuse(0.2, Vector1::new(1.0))?;
    /// driver.fuse(0.6, Vector1::new(1.2))?;
    /// driver.fuse(0.4, Vector1::new(1.1))?; // late: smoothed where it was taken
    /// let track = driver.smooth()?;
    /// assert_eq!(track.times, [0.0, 0.2, 0.4, 0.6]);
    /// // The start is now informed by all three readings.
    /// assert!(track.estimates[0].covariance()[(0, 0)] < 0.2);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn smooth(&mut self) -> Result<Track<T, N>, SmootherError> {
        let mut rts = Rts::new().starting_at(self.history.oldest().time);
        let result = self.record_history(&mut rts);
        self.filter.restore(&self.history.latest().snapshot);
        result?;
        rts.set_clock(self.history.latest().time);
        rts.smooth_with_times(&self.filter)
    }

    /// Re-predicts every gap of the history from the checkpoint before it into `rts`.
    fn record_history(&mut self, rts: &mut Rts<T, N>) -> Result<(), SmootherError> {
        let Self {
            filter,
            process,
            settings,
            convention,
            history,
            ..
        } = self;
        let len = history.len();
        let preceding = *convention == InputConvention::Preceding;
        // Preceding inputs: the first input record at or after j (`len`: none).
        let mut next = 0;
        for j in 1..len {
            let (previous, record) = (history.get(j - 1), history.get(j));
            let gap = record.time - previous.time;
            if preceding && next < j {
                next = (j..len)
                    .find(|&k| matches!(history.get(k).event, Event::Input(_)))
                    .unwrap_or(len);
            }
            // Never fails here: every gap of the history passed this check when it was added.
            let n = substeps(gap, settings).unwrap_or(0);
            if n == 0 {
                continue;
            }
            let input = match (preceding && next < len).then(|| &history.get(next).event) {
                Some(Event::Input(u)) => u,
                _ => &previous.input,
            };
            filter.restore(&previous.snapshot);
            let h = gap / n as f64;
            let dt: T = convert(h);
            for i in 0..n {
                let step = rts.len();
                rts.set_clock(previous.time + h * i as f64);
                rts.predict(filter, process, input, dt)
                    .map_err(|error| SmootherError::at(step, error))?;
            }
        }
        Ok(())
    }
}
