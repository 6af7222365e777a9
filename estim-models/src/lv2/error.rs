//! The error of the fusion routines.

use core::fmt;

/// Why a fusion could not produce an estimate.
///
/// Too few or dependent axes are data conditions, not programming errors (a sensor saturates,
/// a channel drops out), so they are returned, never panicked on. Everything else (non-finite
/// numbers, shape mismatches of runtime-sized inputs, a filter failure) is the framework's
/// [`estim_core::Error`], wrapped.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum FusionError {
    /// Fewer usable axes than unknowns: `usable` axes survived screening, `required` (the
    /// state dimension: 2 in the plane, 3 in space) are needed.
    TooFewAxes {
        /// Axes left after dropping missing, saturated and non-finite readings.
        usable: usize,
        /// Unknowns to estimate.
        required: usize,
    },
    /// Enough axes, but their directions do not span the state space (e.g. the only two
    /// usable axes are parallel): the information matrix Hᵀ R⁻¹ H is singular to working
    /// precision (smallest Cholesky pivot ≤ 10⁴ n ε times its largest diagonal entry).
    DependentAxes {
        /// Axes left after screening.
        usable: usize,
        /// Unknowns to estimate.
        required: usize,
    },
    /// A framework error: bad construction data, a shape mismatch, a non-finite result.
    Core(estim_core::Error),
}

impl fmt::Display for FusionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FusionError::TooFewAxes { usable, required } => write!(
                f,
                "only {usable} usable sensing axes, at least {required} independent ones needed"
            ),
            FusionError::DependentAxes { usable, required } => write!(
                f,
                "the {usable} usable sensing axes do not span the {required}-dimensional state"
            ),
            FusionError::Core(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for FusionError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            FusionError::Core(e) => Some(e),
            _ => None,
        }
    }
}

impl From<estim_core::Error> for FusionError {
    fn from(e: estim_core::Error) -> Self {
        FusionError::Core(e)
    }
}
