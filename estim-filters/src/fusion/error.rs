//! What the fusion driver refuses, and why.

use core::fmt;

/// A setting of the fusion driver that was out of range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum FusionSetting {
    /// [`FusionSettings::horizon`](super::FusionSettings::horizon): finite and ≥ 0 seconds.
    Horizon,
    /// [`FusionSettings::capacity`](super::FusionSettings::capacity): at least 2 records.
    Capacity,
    /// [`FusionSettings::max_step`](super::FusionSettings::max_step): > 0 seconds (∞ allowed).
    MaxStep,
    /// [`FusionSettings::max_substeps`](super::FusionSettings::max_substeps): at least 1.
    MaxSubsteps,
    /// The start time: finite.
    StartTime,
    /// A gate probability: strictly between 0 and 1.
    GateProbability,
    /// [`ResetSettings::after_rejections`](super::ResetSettings::after_rejections): at least 1.
    ResetAfter,
    /// A state index of [`ResetSettings::states`](super::ResetSettings::states): below the
    /// state dimension.
    ResetState,
    /// [`ResetSettings::variance`](super::ResetSettings::variance) (finite, > 0) or
    /// `blow_up_variance` (finite, > 0).
    ResetVariance,
    /// [`MonitorSettings::window`](super::MonitorSettings::window): at least 1.
    MonitorWindow,
    /// [`MonitorSettings::false_alarm`](super::MonitorSettings::false_alarm) or
    /// `clip_probability`: strictly between 0 and 1.
    MonitorProbability,
    /// A sensor index given to a settings call: below the number of sensors.
    Sensor,
    /// A sensor's dimension ([`SensorSet::dimension`](super::SensorSet::dimension)): at least 1.
    SensorDimension,
    /// The input convention, changed after events were recorded (value: the number of
    /// records).
    InputConvention,
}

impl fmt::Display for FusionSetting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            FusionSetting::Horizon => "FusionSettings::horizon (finite, >= 0 s)",
            FusionSetting::Capacity => "FusionSettings::capacity (2 ..= MAX_CAPACITY records)",
            FusionSetting::MaxStep => "FusionSettings::max_step (> 0 s; infinity: no sub-steps)",
            FusionSetting::MaxSubsteps => "FusionSettings::max_substeps (at least 1)",
            FusionSetting::StartTime => "start time of FusionDriver::new (finite)",
            FusionSetting::GateProbability => {
                "SensorSettings::gate_probability (strictly between 0 and 1)"
            }
            FusionSetting::ResetAfter => "ResetSettings::after_rejections (at least 1)",
            FusionSetting::ResetState => "ResetSettings::states (an index below the state size)",
            FusionSetting::ResetVariance => {
                "ResetSettings::variance or blow_up_variance (finite, > 0)"
            }
            FusionSetting::MonitorWindow => "MonitorSettings::window (1 ..= MAX_WINDOW)",
            FusionSetting::MonitorProbability => {
                "MonitorSettings::false_alarm or clip_probability (strictly between 0 and 1)"
            }
            FusionSetting::Sensor => "sensor index (below SensorSet::count)",
            FusionSetting::SensorDimension => "SensorSet::dimension (at least 1)",
            FusionSetting::InputConvention => {
                "input convention (call with_input_convention before the first event)"
            }
        })
    }
}

/// Every error of the fusion driver. On any error the driver is left exactly as it was
/// (filter, history, input, health).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FusionError {
    /// A timestamp is NaN or infinite.
    #[error("timestamp {time} is not finite")]
    NonFiniteTime {
        /// The timestamp given.
        time: f64,
    },
    /// A measurement older than the history can replay: before the oldest checkpoint kept, or
    /// more than the horizon before the latest event. It is not fused (fusing it as current
    /// would make the filter inconsistent).
    #[error(
        "measurement at {time} s is older than the history (oldest usable time {oldest} s): \
         raise FusionSettings::horizon, or FusionSettings::capacity if the history filled up"
    )]
    TooOld {
        /// The measurement's timestamp.
        time: f64,
        /// The oldest timestamp the driver can still fuse.
        oldest: f64,
    },
    /// An input or a time mark before the latest event: inputs and marks must come in time
    /// order (only measurements may be late).
    #[error(
        "time {time} s is before the latest event at {latest} s: inputs and time marks must \
         come in time order (only measurements may be late)"
    )]
    NotMonotone {
        /// The time given.
        time: f64,
        /// The latest event's time.
        latest: f64,
    },
    /// The history already holds a measurement of this sensor at this time, and
    /// [`FusionSettings::duplicates`](super::FusionSettings::duplicates) is
    /// [`DuplicatePolicy::Refuse`](super::DuplicatePolicy::Refuse).
    #[error(
        "sensor {sensor} already has a measurement at {time} s (FusionSettings::duplicates \
         is Refuse; FuseBoth or KeepFirst accept it)"
    )]
    Duplicate {
        /// The sensor.
        sensor: usize,
        /// The timestamp.
        time: f64,
    },
    /// The reading names a sensor the set does not have.
    #[error("unknown sensor {sensor}: SensorSet::sensor must be below SensorSet::count = {count}")]
    UnknownSensor {
        /// The sensor index the reading gave.
        sensor: usize,
        /// The number of sensors.
        count: usize,
    },
    /// Predicting over this gap would take more than
    /// [`FusionSettings::max_substeps`](super::FusionSettings::max_substeps) sub-steps.
    #[error(
        "a gap of {gap} s needs more than FusionSettings::max_substeps sub-steps of \
         FusionSettings::max_step = {max_step} s: raise either, or check the timestamp"
    )]
    GapTooLong {
        /// The gap in seconds.
        gap: f64,
        /// The maximum sub-step.
        max_step: f64,
    },
    /// A setting is out of range.
    #[error("invalid {setting}: {value} given")]
    InvalidSetting {
        /// Which.
        setting: FusionSetting,
        /// The value given, as `f64`.
        value: f64,
    },
    /// A filter step failed (non-finite reading, covariance not positive definite, …).
    #[error(transparent)]
    Filter(#[from] estim_core::Error),
}

/// A batch refused by [`FusionDriver::fuse_all`](super::FusionDriver::fuse_all): which
/// reading, and why. The driver is left exactly as it was before the batch (no reading of it
/// is fused).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("reading {index} of the batch was refused")]
pub struct BatchError {
    /// The reading's position in the batch (0-based, in the order given). For a filter step
    /// that failed during the replay: the reading at the record whose step (its prediction
    /// or its update) failed, or else the last reading, in the order given, placed before
    /// that record.
    pub index: usize,
    /// Why: the error [`FusionDriver::fuse`](super::FusionDriver::fuse) gives (also the
    /// error's [`source`](core::error::Error::source)).
    #[source]
    pub error: FusionError,
}

impl FusionError {
    pub(crate) fn setting(setting: FusionSetting, value: f64) -> Self {
        FusionError::InvalidSetting { setting, value }
    }
}
