//! The errors of the validation tooling: the [consistency](crate::consistency) statistics and
//! the [Monte Carlo](crate::monte_carlo) runner.
//!
//! Their own settings (a time slot, a correlation lag, a number of work chunks or runs, a
//! confidence level, degrees of freedom) are checked here and reported as
//! [`ValidationError::InvalidSetting`]; data failures (shapes, non-finite values, a covariance
//! that is not positive definite, at [`Stage::ConsistencyCheck`](estim_core::Stage)) are an
//! [`estim_core::Error`], wrapped. A realization's own filter errors convert with `?`.
//!
//! ```
//! use estim_filters::monte_carlo::MonteCarlo;
//! use estim_filters::validation::{Setting, ValidationError};
//!
//! let e = MonteCarlo::new(10, 5).unwrap().with_chunks(0).unwrap_err();
//! assert_eq!(e, ValidationError::InvalidSetting { setting: Setting::ChunkCount, value: 0.0 });
//! ```

use core::fmt;

/// A setting of the validation tooling that was out of range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Setting {
    /// A time-slot index of a Monte Carlo runner (below the number of slots; a pair of
    /// residual slots must differ).
    Slot,
    /// A correlation lag (at least 1, and below the number of samples).
    Lag,
    /// A number of work chunks (at least 1).
    ChunkCount,
    /// A Monte Carlo shard: its index (below the shard count, which is at least 1), or a set of
    /// shards to merge that is not exactly one experiment's, each chunk once.
    Shard,
    /// A number of Monte Carlo runs or of averaged terms (at least 1).
    RunCount,
    /// A confidence level (strictly between 0 and 1).
    Confidence,
    /// Degrees of freedom of a reference distribution (at least 1).
    DegreesOfFreedom,
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Setting::Slot => "slot",
            Setting::Lag => "lag",
            Setting::ChunkCount => "chunk count",
            Setting::Shard => "shard",
            Setting::RunCount => "run count",
            Setting::Confidence => "confidence",
            Setting::DegreesOfFreedom => "degrees of freedom",
        })
    }
}

/// Every error the validation tooling returns.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ValidationError {
    /// A setting of the tooling was out of range.
    #[error("invalid {setting}: {value}")]
    InvalidSetting {
        /// Which.
        setting: Setting,
        /// The value given.
        value: f64,
    },
    /// A Monte Carlo realization recorded the same kind of statistic at one slot twice
    /// ([`Recorder`](crate::Recorder): at most one estimate, one innovation and one residual
    /// per slot and run).
    #[error("slot {slot} recorded twice in one run")]
    RecordedTwice {
        /// The slot.
        slot: usize,
    },
    /// An estimation error: a filter step, a shape, a non-finite value, a covariance that is
    /// not positive definite, a statistical parameter.
    #[error(transparent)]
    Estimation(#[from] estim_core::Error),
}

impl ValidationError {
    /// An invalid `setting` of value `value`.
    pub(crate) fn setting(setting: Setting, value: usize) -> Self {
        ValidationError::InvalidSetting {
            setting,
            value: value as f64,
        }
    }
}

/// Shorthand for `Result<T, ValidationError>`.
pub type Result<T, E = ValidationError> = core::result::Result<T, E>;
