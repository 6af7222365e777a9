//! Why a Monte Carlo run failed.

use core::fmt;

use crate::validation::ValidationError;

/// Why a Monte Carlo run failed. `E` is the error type realizations return
/// ([`MonteCarlo::with_error`](super::MonteCarlo::with_error); [`ValidationError`] by default).
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum MonteCarloError<E = ValidationError> {
    /// A realization returned an error, or recorded something invalid (a slot out of range,
    /// a record made twice, a shape different from earlier runs' in the same chunk, a
    /// covariance that is not positive definite). It is the failing run with the smallest
    /// index, on any number of threads.
    Run {
        /// The run index.
        run: usize,
        /// Its seed ([`run_seed`](super::run_seed)).
        seed: u64,
        /// The error.
        error: E,
    },
    /// Runs in different chunks recorded different shapes at the same slot or residual pair.
    Shape {
        /// The [`Error::DimensionMismatch`](estim_core::Error::DimensionMismatch), wrapped.
        error: ValidationError,
    },
    /// A shard index out of range, or shards to merge that are not exactly one experiment's
    /// chunks ([`Setting::Shard`](crate::validation::Setting::Shard)).
    Shards {
        /// The [`ValidationError::InvalidSetting`].
        error: ValidationError,
    },
}

impl MonteCarloError {
    /// The underlying error.
    pub fn error(&self) -> ValidationError {
        match *self {
            MonteCarloError::Run { error, .. }
            | MonteCarloError::Shape { error }
            | MonteCarloError::Shards { error } => error,
        }
    }
}

impl<E: fmt::Display> fmt::Display for MonteCarloError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MonteCarloError::Run { run, seed, error } => {
                write!(f, "Monte Carlo run {run} (seed {seed}) failed: {error}")
            }
            MonteCarloError::Shape { error } => {
                write!(f, "Monte Carlo runs disagree in shape: {error}")
            }
            MonteCarloError::Shards { error } => {
                write!(f, "Monte Carlo shards: {error}")
            }
        }
    }
}

impl<E: std::error::Error + 'static> std::error::Error for MonteCarloError<E> {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            MonteCarloError::Run { error, .. } => Some(error),
            MonteCarloError::Shape { error } | MonteCarloError::Shards { error } => Some(error),
        }
    }
}

impl From<MonteCarloError> for ValidationError {
    fn from(e: MonteCarloError) -> Self {
        e.error()
    }
}
