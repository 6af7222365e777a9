//! Noise identification: learning Q and R (and the prior, F, H) from recorded data.
//!
//! Three routes, one concept each:
//!
//! | module | what | models | what it gives |
//! |---|---|---|---|
//! | [`em`] | expectation–maximisation (Shumway & Stoffer 1982) | linear-Gaussian, time invariant | Q, R, x₀, P₀, F, H under structure constraints; the log-likelihood of every iteration |
//! | `likelihood` (feature `likelihood`) | maximum likelihood by L-BFGS (argmin) | any filter of the family (KF, EKF, UKF, second-order EKF) | the parameters of a user-chosen parameterisation and their Hessian-based standard errors |
//! | [`adaptive`] | innovation-based covariance matching (Mehra 1972; Mohamed & Schwarz 1999) | any filter, online | R̂ after every update, with a forgetting window |
//!
//! EM is the batch route for linear models: every iteration is one smoother pass and a
//! closed-form M-step, and the likelihood never decreases; it does not give standard errors.
//! Maximum likelihood works for nonlinear models and gives standard errors, at the price of a
//! few dozen filter passes per parameter. Covariance matching is an online heuristic for when the
//! noise drifts; it has no likelihood guarantee and its failure modes are documented in its
//! module.
//!
//! All three report failures as a [`NoiseIdError`]: data failures (every measurement missing,
//! non-finite data), settings out of range (an iteration cap of 0, a NaN tolerance, a window
//! below 1), structure constraints that make the problem unidentifiable, and the filter errors
//! of the passes they run, with the sequence they happened in.
//!
//! # References
//!
//! - R. H. Shumway, D. S. Stoffer, *An approach to time series smoothing and forecasting using
//!   the EM algorithm*, J. Time Series Analysis 3(4), 1982.
//! - S. Särkkä, *Bayesian Filtering and Smoothing*, Cambridge, 2013, §12.
//! - R. K. Mehra, *Approaches to adaptive filtering*, IEEE T-AC 17(5), 1972.
//! - A. H. Mohamed, K. P. Schwarz, *Adaptive Kalman filtering for INS/GPS*, J. Geodesy 73, 1999.

use core::fmt;

use estim_core::checks::all_finite;
use estim_core::nalgebra::{DefaultAllocator, Dim, OVector};
use estim_core::{Alloc, Error, Quantity, Real};

use crate::smoother::SmootherError;

pub mod adaptive;
pub mod em;
#[cfg(feature = "likelihood")]
pub mod likelihood;

pub use adaptive::{MeasurementNoiseMatching, WithNoise};
pub use em::{
    CovarianceStructure, EmEstimate, EmSettings, LinearGaussian, MatrixStructure, Record,
};
#[cfg(feature = "likelihood")]
pub use likelihood::{MaximumLikelihood, MlEstimate};

/// A setting of a noise-identification algorithm that was out of range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Setting {
    /// An iteration cap (at least 1).
    MaxIterations,
    /// A convergence tolerance (finite and ≥ 0).
    Tolerance,
    /// A forgetting window (finite and ≥ 1 sample).
    Window,
    /// A variance floor (finite and > 0).
    Floor,
    /// A finite-difference step (finite and > 0).
    StepSize,
    /// An initial parameter value (finite).
    InitialParameter,
    /// An L-BFGS memory (at least 1).
    Memory,
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Setting::MaxIterations => "iteration cap",
            Setting::Tolerance => "tolerance",
            Setting::Window => "forgetting window",
            Setting::Floor => "variance floor",
            Setting::StepSize => "finite-difference step",
            Setting::InitialParameter => "initial parameter",
            Setting::Memory => "L-BFGS memory",
        })
    }
}

/// Why a structure constraint leaves the problem unidentifiable.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Unidentifiable {
    /// A scalar-multiple structure `c · S` with a shape `S` that is zero (nothing to scale),
    /// not finite, or not symmetric positive semi-definite.
    DegenerateShape(Quantity),
    /// F and H both free (some entries of each) with a free Q: any invertible change of state
    /// coordinates x → T x gives the same likelihood.
    StateBasis,
    /// H entirely free with a free Q: the scale of the state is not identified
    /// (x → c x, H → H / c, Q → c² Q give the same outputs).
    StateScale,
    /// Q (or F) free but no sequence has a transition (every sequence is one time long).
    NoTransitions,
    /// The Hessian of the log-likelihood at the optimum is not negative definite: the data
    /// do not determine parameter `index` (or a combination of parameters).
    FlatLikelihood {
        /// The first parameter whose direction is flat or upward.
        index: usize,
    },
}

impl fmt::Display for Unidentifiable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Unidentifiable::DegenerateShape(q) => {
                write!(
                    f,
                    "the shape of the scalar-multiple {q} is zero, not finite or not PSD"
                )
            }
            Unidentifiable::StateBasis => {
                f.write_str("F, H and Q all free: the state coordinates are not identified")
            }
            Unidentifiable::StateScale => {
                f.write_str("H entirely free with a free Q: the state scale is not identified")
            }
            Unidentifiable::NoTransitions => {
                f.write_str("Q or F free, but no sequence has a transition")
            }
            Unidentifiable::FlatLikelihood { index } => write!(
                f,
                "the log-likelihood is not strictly concave at the optimum along parameter {index}"
            ),
        }
    }
}

/// Why the optimiser stopped without a usable optimum.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum OptimizerFailure {
    /// The optimiser reported an internal error (a line search that failed outright, a
    /// non-finite step).
    Internal,
    /// The log-likelihood at the point returned is not finite.
    NonFiniteOptimum,
}

impl fmt::Display for OptimizerFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            OptimizerFailure::Internal => "internal optimiser error",
            OptimizerFailure::NonFiniteOptimum => "non-finite log-likelihood at the optimum",
        })
    }
}

/// Every error of the noise-identification algorithms.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NoiseIdError {
    /// No sequence holds a single measurement: nothing to learn from.
    #[error("every measurement is missing")]
    AllMissing,
    /// A recorded measurement is NaN or ±∞.
    #[error("{quantity} of sequence {sequence} at time {step} is not finite")]
    NonFiniteData {
        /// Which sequence (0 = the first).
        sequence: usize,
        /// Which time in it.
        step: usize,
        /// What ([`Quantity::Measurement`]).
        quantity: Quantity,
    },
    /// A recorded input is NaN or ±∞.
    #[error("input of sequence {sequence} at time {step} is not finite")]
    NonFiniteInput {
        /// Which sequence (0 = the first).
        sequence: usize,
        /// Which time in it.
        step: usize,
    },
    /// A sequence whose lengths disagree (`measurements` must have one entry more than
    /// `inputs`), or no sequence at all (`found` 0, `expected` 1).
    #[error("sequence {sequence}: {found} entries where {expected} were expected")]
    SequenceLength {
        /// Which sequence.
        sequence: usize,
        /// The length expected.
        expected: usize,
        /// The length found.
        found: usize,
    },
    /// A setting out of range.
    #[error("{setting} = {value} is out of range")]
    InvalidSetting {
        /// Which setting.
        setting: Setting,
        /// The rejected value, as `f64`.
        value: f64,
    },
    /// The structure constraints (or the data) leave the problem unidentifiable.
    #[error("unidentifiable: {0}")]
    Unidentifiable(Unidentifiable),
    /// A model or prior handed in is invalid (not finite, not symmetric, not PSD).
    #[error("invalid model: {0}")]
    Model(Error),
    /// A filter or smoother pass over sequence `sequence` failed.
    #[error("sequence {sequence}: {error}")]
    Pass {
        /// Which sequence.
        sequence: usize,
        /// The failing step and its error.
        error: SmootherError,
    },
    /// The optimiser failed.
    #[error("optimiser: {0}")]
    Optimizer(OptimizerFailure),
}

/// Checks an iteration cap (≥ 1) and a tolerance (finite, ≥ 0).
pub(crate) fn check_iteration_settings(
    max_iterations: usize,
    tolerance: f64,
) -> Result<(), NoiseIdError> {
    if max_iterations == 0 {
        return Err(NoiseIdError::InvalidSetting {
            setting: Setting::MaxIterations,
            value: 0.0,
        });
    }
    if !(tolerance >= 0.0 && tolerance.is_finite()) {
        return Err(NoiseIdError::InvalidSetting {
            setting: Setting::Tolerance,
            value: tolerance,
        });
    }
    Ok(())
}

/// Checks that every recorded measurement of sequence `sequence` is finite.
pub(crate) fn check_measurements<T: Real, M: Dim>(
    sequence: usize,
    measurements: &[Option<OVector<T, M>>],
) -> Result<(), NoiseIdError>
where
    DefaultAllocator: Alloc<M>,
{
    match measurements
        .iter()
        .position(|z| z.as_ref().is_some_and(|z| !all_finite(z)))
    {
        Some(step) => Err(NoiseIdError::NonFiniteData {
            sequence,
            step,
            quantity: Quantity::Measurement,
        }),
        None => Ok(()),
    }
}
