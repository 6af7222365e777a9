//! The error type shared by every estim crate.
//!
//! Errors are data failures: a covariance that is not positive (semi-)definite, a non-finite
//! number, an input of the wrong length, a parameter out of range. Each variant says *where*
//! ([`Stage`]) and *what* ([`Quantity`] or [`Parameter`]); none carries a formatted string.
//! Shape misuse that only a programmer can cause (e.g. mixing a 3-state filter with a 4-state
//! static model) is a compile error for static sizes.

use core::fmt;

/// The step of an algorithm at which an error happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Stage {
    /// Building a value (a Gaussian, a propagator, a filter).
    Construction,
    /// Propagating moments through a function.
    Propagation,
    /// A filter's time update.
    Prediction,
    /// A filter's measurement update.
    Update,
    /// A smoother's backward pass.
    Smoothing,
    /// Checking derivatives by finite differences.
    DerivativeCheck,
    /// Computing consistency statistics (NEES, NIS, whiteness, Monte Carlo ensembles).
    ConsistencyCheck,
}

/// The quantity that failed a check.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Quantity {
    /// A mean or state vector.
    Mean,
    /// A covariance matrix.
    Covariance,
    /// A cross-covariance matrix.
    CrossCovariance,
    /// A function value y = g(x).
    FunctionValue,
    /// A Jacobian ∂g/∂x.
    Jacobian,
    /// The Hessian of one output component.
    Hessian,
    /// Process noise Q.
    ProcessNoise,
    /// Measurement noise R.
    MeasurementNoise,
    /// Process–measurement noise cross-covariance S.
    NoiseCrossCovariance,
    /// A measurement vector z.
    Measurement,
    /// The innovation covariance S = H P Hᵀ + R.
    InnovationCovariance,
    /// A filter gain.
    Gain,
    /// A time step Δt.
    TimeStep,
    /// A filter innovation ν = z ⊖ ẑ.
    Innovation,
    /// A residual recorded for a consistency check.
    Residual,
    /// The mode probabilities μ of a multiple-model estimator.
    ModeProbabilities,
    /// The Markov transition matrix Π of a multiple-model estimator.
    TransitionMatrix,
    /// A particle filter's (log-)weights: a NaN weight, or all weights zero (a measurement
    /// that no particle explains).
    Weights,
    /// The map between a multiple-model estimator's mode state and its common state (the
    /// mode's components' places in the common state, and the default mean and variance of
    /// the components the mode lacks).
    StateMap,
}

/// A parameter that failed validation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Parameter {
    /// Unscented spread α (must be finite and > 0).
    UnscentedAlpha,
    /// Unscented β (must be finite, with α²κ + nβ ≥ 0 for the state dimension n; see
    /// [`Unscented`](crate::Unscented#accepted-parameters)).
    UnscentedBeta,
    /// Unscented κ (must be finite, with n + κ > 0 and α²κ + nβ ≥ 0 for the state
    /// dimension n).
    UnscentedKappa,
    /// Number of Monte Carlo samples (at least 2).
    SampleCount,
    /// A particle weight (must be ≥ 0; the weights need not sum to 1).
    Weight,
    /// Forgetting factor γ of a fading-memory estimator (0 < γ ≤ 1).
    ForgettingFactor,
    /// A gating threshold (must be finite and > 0).
    GateThreshold,
    /// A gate's probability (must be in (0, 1)).
    GateProbability,
    /// A finite-difference step (must be finite and > 0).
    StepSize,
    /// A prediction's time step Δt (must be ≥ 0: a filter predicts forward; backward
    /// estimates come from a smoother).
    TimeStep,
    /// A simulated or analysed duration in seconds (must be finite, ≥ 0, and short enough that
    /// its step count stays under the documented maximum).
    Duration,
    /// A number of steps or iterations (at most a documented maximum, so memory and run time
    /// stay bounded).
    StepCount,
    /// A sampling or fix period in seconds (must be finite and > 0).
    Period,
    /// A number of Monte Carlo runs (at least 1, at most a documented maximum).
    RunCount,
    /// A convergence tolerance (must be finite and ≥ 0).
    Tolerance,
    /// An entry or a row sum of a Markov transition matrix Π (entries in [0, 1], every row
    /// summing to 1: row-stochastic).
    TransitionProbability,
    /// A mode probability or their sum (each in [0, 1], summing to 1).
    ModeProbability,
}

/// Every error an estim algorithm returns.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A quantity contains NaN or ±∞.
    #[error("{quantity} is not finite ({stage})")]
    NonFinite {
        /// Where.
        stage: Stage,
        /// What.
        quantity: Quantity,
    },
    /// A matrix that must be symmetric is not, beyond the tolerance.
    #[error(
        "{quantity} is not symmetric ({stage}): entries ({row}, {col}) and ({col}, {row}) differ"
    )]
    NotSymmetric {
        /// Where.
        stage: Stage,
        /// What.
        quantity: Quantity,
        /// Row of the worst pair.
        row: usize,
        /// Column of the worst pair.
        col: usize,
    },
    /// A matrix that must be positive semi-definite has a clearly negative direction.
    #[error("{quantity} is not positive semi-definite ({stage})")]
    NotPositiveSemiDefinite {
        /// Where.
        stage: Stage,
        /// What.
        quantity: Quantity,
    },
    /// A matrix that must be positive definite (to be factorised) is not.
    #[error("{quantity} is not positive definite ({stage})")]
    NotPositiveDefinite {
        /// Where.
        stage: Stage,
        /// What.
        quantity: Quantity,
    },
    /// A runtime-sized vector or matrix has the wrong shape.
    #[error(
        "{quantity} has shape {found_rows}×{found_cols}, expected {expected_rows}×{expected_cols} ({stage})"
    )]
    DimensionMismatch {
        /// Where.
        stage: Stage,
        /// What.
        quantity: Quantity,
        /// Expected rows.
        expected_rows: usize,
        /// Expected columns.
        expected_cols: usize,
        /// Actual rows.
        found_rows: usize,
        /// Actual columns.
        found_cols: usize,
    },
    /// A parameter is out of its valid range.
    #[error("parameter {parameter} = {value} is out of range")]
    InvalidParameter {
        /// Which parameter.
        parameter: Parameter,
        /// The rejected value, as `f64`.
        value: f64,
    },
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stage::Construction => "construction",
            Stage::Propagation => "moment propagation",
            Stage::Prediction => "prediction",
            Stage::Update => "update",
            Stage::Smoothing => "smoothing",
            Stage::DerivativeCheck => "derivative check",
            Stage::ConsistencyCheck => "consistency check",
        })
    }
}

impl fmt::Display for Quantity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Quantity::Mean => "mean",
            Quantity::Covariance => "covariance",
            Quantity::CrossCovariance => "cross-covariance",
            Quantity::FunctionValue => "function value",
            Quantity::Jacobian => "Jacobian",
            Quantity::Hessian => "Hessian",
            Quantity::ProcessNoise => "process noise Q",
            Quantity::MeasurementNoise => "measurement noise R",
            Quantity::NoiseCrossCovariance => "noise cross-covariance S",
            Quantity::Measurement => "measurement",
            Quantity::InnovationCovariance => "innovation covariance",
            Quantity::Gain => "gain",
            Quantity::TimeStep => "time step",
            Quantity::Innovation => "innovation",
            Quantity::Residual => "residual",
            Quantity::ModeProbabilities => "mode probabilities",
            Quantity::TransitionMatrix => "transition matrix",
            Quantity::Weights => "particle weights",
            Quantity::StateMap => "mode state map",
        })
    }
}

impl fmt::Display for Parameter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Parameter::UnscentedAlpha => "unscented alpha",
            Parameter::UnscentedBeta => "unscented beta",
            Parameter::UnscentedKappa => "unscented kappa",
            Parameter::SampleCount => "sample count",
            Parameter::Weight => "particle weight",
            Parameter::ForgettingFactor => "forgetting factor",
            Parameter::GateThreshold => "gate threshold",
            Parameter::GateProbability => "gate probability",
            Parameter::StepSize => "step size",
            Parameter::TimeStep => "time step",
            Parameter::Duration => "duration",
            Parameter::StepCount => "step count",
            Parameter::Period => "period",
            Parameter::RunCount => "run count",
            Parameter::Tolerance => "tolerance",
            Parameter::TransitionProbability => "transition probability",
            Parameter::ModeProbability => "mode probability",
        })
    }
}

/// Shorthand for `Result<T, estim_core::Error>`.
pub type Result<T, E = Error> = core::result::Result<T, E>;
