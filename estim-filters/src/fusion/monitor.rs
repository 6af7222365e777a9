//! Per-sensor health: the windowed NIS χ² fault monitor, the rejection run, the counters.
//!
//! The state lives in plain buffers sized at construction and is copied into every history
//! record ([`Health::copy_from`], no allocation), so a replay restores the health a sensor had
//! at the checkpoint and re-makes every later decision exactly as a time-ordered delivery
//! would have.

use estim_core::Real;

/// Whether a sensor's measurements are used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SensorStatus {
    /// Its measurements are judged by the gate and applied when they pass.
    Admitted,
    /// Its fault monitor fired: its measurements are not applied until it recovers.
    Excluded,
}

/// A sensor's counters and state (a copy).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorHealth<T> {
    /// Admitted or excluded.
    pub status: SensorStatus,
    /// Measurements accepted.
    pub accepted: u64,
    /// Measurements rejected by the gate.
    pub rejected: u64,
    /// Resets made from this sensor.
    pub resets: u64,
    /// Measurements not applied because the sensor was excluded (the one that raised the fault
    /// included).
    pub excluded: u64,
    /// Times the sensor was declared faulty.
    pub faults: u64,
    /// Times it was readmitted.
    pub readmissions: u64,
    /// The current run of consecutive rejections.
    pub consecutive_rejections: usize,
    /// The sum of the clipped NIS in the monitor's window (0 without a monitor).
    pub window_sum: T,
    /// The number of values in the window.
    pub window_len: usize,
    /// The NIS of the latest measurement (0 before any).
    pub last_nis: T,
}

/// The last W values, oldest overwritten first.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Window<T> {
    values: Vec<T>,
    next: usize,
    len: usize,
}

impl<T: Real> Window<T> {
    fn new(size: usize) -> Self {
        Self {
            values: vec![T::zero(); size],
            next: 0,
            len: 0,
        }
    }

    pub(crate) fn push(&mut self, v: T) {
        if self.values.is_empty() {
            return;
        }
        self.values[self.next] = v;
        self.next = (self.next + 1) % self.values.len();
        self.len = (self.len + 1).min(self.values.len());
    }

    pub(crate) fn sum(&self) -> T {
        self.values[..self.len]
            .iter()
            .fold(T::zero(), |s, &v| s + v)
    }

    pub(crate) fn len(&self) -> usize {
        self.len
    }

    pub(crate) fn is_full(&self) -> bool {
        self.len == self.values.len()
    }

    pub(crate) fn clear(&mut self) {
        self.next = 0;
        self.len = 0;
    }

    fn copy_from(&mut self, other: &Self) {
        self.values.copy_from_slice(&other.values);
        self.next = other.next;
        self.len = other.len;
    }
}

/// One sensor's decision state.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SensorState<T> {
    pub window: Window<T>,
    pub excluded: bool,
    pub since_exclusion: usize,
    pub run: usize,
    /// The driver-wide accepted count when the current rejection run began.
    pub run_start_accepted: u64,
    pub health: SensorHealth<T>,
}

impl<T: Real> SensorState<T> {
    fn new(window: usize) -> Self {
        Self {
            window: Window::new(window),
            excluded: false,
            since_exclusion: 0,
            run: 0,
            run_start_accepted: 0,
            health: SensorHealth {
                status: SensorStatus::Admitted,
                accepted: 0,
                rejected: 0,
                resets: 0,
                excluded: 0,
                faults: 0,
                readmissions: 0,
                consecutive_rejections: 0,
                window_sum: T::zero(),
                window_len: 0,
                last_nis: T::zero(),
            },
        }
    }

    /// The public summary, brought up to date.
    pub(crate) fn summary(&self) -> SensorHealth<T> {
        SensorHealth {
            status: if self.excluded {
                SensorStatus::Excluded
            } else {
                SensorStatus::Admitted
            },
            consecutive_rejections: self.run,
            window_sum: self.window.sum(),
            window_len: self.window.len(),
            ..self.health
        }
    }

    fn copy_from(&mut self, other: &Self) {
        self.window.copy_from(&other.window);
        self.excluded = other.excluded;
        self.since_exclusion = other.since_exclusion;
        self.run = other.run;
        self.run_start_accepted = other.run_start_accepted;
        self.health = other.health;
    }
}

/// The health of every sensor, the driver-wide count of accepted measurements and the sum
/// of their log-likelihoods (checkpointed with the rest, so a replay re-makes the sum too).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Health<T> {
    pub sensors: Vec<SensorState<T>>,
    pub accepted: u64,
    pub log_likelihood: T,
}

impl<T: Real> Health<T> {
    /// Fresh state for sensors with these monitor windows (0: no monitor).
    pub(crate) fn new(windows: impl Iterator<Item = usize>) -> Self {
        Self {
            sensors: windows.map(SensorState::new).collect(),
            accepted: 0,
            log_likelihood: T::zero(),
        }
    }

    /// Copies `other` (same sensors, same windows) without allocating.
    pub(crate) fn copy_from(&mut self, other: &Self) {
        for (a, b) in self.sensors.iter_mut().zip(&other.sensors) {
            a.copy_from(b);
        }
        self.accepted = other.accepted;
        self.log_likelihood = other.log_likelihood;
    }
}
