//! Validate once: linear models whose noise covariances are checked when the model is built.
//!
//! A filter step checks the noise it is given (shape, finiteness, positive
//! semi-definiteness, see the table). For constant matrices the full check can be done once
//! instead, with an error at construction rather than at some later step:
//! [`LinearProcess::try_new`] and [`LinearMeasurement::try_new`] verify that Q (resp. R) is
//! finite, symmetric (within √ε of its largest entry) and positive **semi**-definite, by one
//! factorisation, and return the model. Its fields stay public: a model changed after it was
//! built gets the per-step checks of any model (the table below; those run for every model
//! anyway, so no step relies on the construction check), which do not refuse an asymmetric Q
//! or R but use its symmetric part: check a changed model again with [`check_noise`].
//!
//! **Why semi-definite.** The factorisation is [`psd_factor`] (a Cholesky
//! factorisation that accepts zero pivots within 16 n ε max Qᵢᵢ, with diagonal pivoting as a
//! fallback), not a plain Cholesky: a singular Q is common and legitimate (a constant bias
//! with no process noise, a position driven only through its velocity), and so is a zero
//! variance in R for a component that is measured exactly, as long as S = H P Hᵀ + R stays
//! positive definite (checked at every update). A pivot below −16 n ε max Qᵢᵢ is refused, and so
//! is a zero-variance direction whose covariances exceed √(16 n ε) max Qᵢᵢ (about).
//!
//! # What is caught, and when
//!
//! | noise | at construction | at every step |
//! |---|---|---|
//! | linear models built by `try_new` | shape, NaN/∞, asymmetry, any negative eigenvalue (one factorisation) | the checks below, which cannot fail for an unchanged model |
//! | any model (Q(x, u, Δt), R(x) evaluated per step) | — | shape; NaN/∞ ([`NonFinite`](crate::Error::NonFinite)); (Q + Qᵀ)/2 not semi-definite by [`psd_factor`]'s rule (a pivot below −τ = −16 n ε max Qᵢᵢ, or a zero-variance direction whose covariances exceed √(τ max Qᵢᵢ) + τ: [`ensure_semidefinite_noise`](crate::checks::ensure_semidefinite_noise)), a positive diagonal notwithstanding ([`NotPositiveSemiDefinite`](crate::Error::NotPositiveSemiDefinite) naming the noise); for R, also S = cov(ẑ) + R not positive definite ([`NotPositiveDefinite`](crate::Error::NotPositiveDefinite), from the Cholesky factorisation the update does anyway) |
//!
//! **Policy for state-dependent noise**: an indefinite Q(x) or R(x) is an error of the step
//! (typed as above), never a silently indefinite P, and like every error it leaves the filter
//! unchanged. The per-step test costs O(n²)
//! comparisons when the matrix is diagonally dominant (Gershgorin; every diagonal noise)
//! and one factorisation otherwise (e.g. a rank-one Γ W Γᵀ), in a buffer the step has free
//! at that point (nothing allocated). The Gaussian filters remember the last Q a committed
//! prediction checked and skip the test for a Q equal to it entry for entry (n² comparisons:
//! a constant Q, checked or not, is tested once; Lu's Monte Carlo, a rank-one Q every step,
//! went from 1.4× to 1.04× its time without the test, BENCHMARKS.md). R is tested at every
//! update (its size varies with the sensor). Not refused per step: an asymmetric Q or R, of which
//! the filters use the symmetric part (Q + Qᵀ)/2 (`try_new` refuses it).
//! The square-root filters factorise Q and R every step anyway ([`psd_factor`]) and refuse an
//! indefinite one there.
//!
//! ```
//! use estim_core::nalgebra::{Matrix2, Matrix2x1};
//! use estim_core::{Error, LinearMeasurement, LinearProcess, Quantity, Stage};
//!
//! // A bias with no process noise: Q singular, accepted.
//! let f = Matrix2::new(1.0, 0.1, 0.0, 1.0);
//! let q = Matrix2::new(1e-3, 0.0, 0.0, 0.0);
//! let process = LinearProcess::try_new(f, Matrix2x1::zeros(), q)?;
//! assert_eq!(process.noise, q);
//! // Indefinite with a positive diagonal: refused when built, not at some later step.
//! let r = Matrix2::new(1.0, 2.0, 2.0, 1.0);
//! assert_eq!(
//!     LinearMeasurement::try_new(Matrix2::identity(), r).unwrap_err(),
//!     Error::NotPositiveSemiDefinite {
//!         stage: Stage::Construction,
//!         quantity: Quantity::MeasurementNoise
//!     }
//! );
//! # Ok::<(), Error>(())
//! ```

use nalgebra::{DefaultAllocator, Dim, OMatrix};

use crate::alloc::Alloc;
use crate::checks::{ensure_finite, ensure_shape, ensure_symmetric};
use crate::error::{Error, Quantity, Result, Stage};
use crate::linalg::psd_factor;
use crate::linear::{LinearMeasurement, LinearProcess};
use crate::scalar::Real;

/// `Ok(())` if the noise covariance `noise` (Q or R, named by `quantity`) is square, finite,
/// symmetric within √ε · max|nᵢⱼ| and positive semi-definite (no pivot of its factorisation
/// below −16 n ε max nᵢᵢ), checked in that order at [`Stage::Construction`]; else the
/// [`Error`] of the first failed check: [`DimensionMismatch`](Error::DimensionMismatch),
/// [`NonFinite`](Error::NonFinite), [`NotSymmetric`](Error::NotSymmetric) or
/// [`NotPositiveSemiDefinite`](Error::NotPositiveSemiDefinite). One factorisation, O(n³).
///
/// ```
/// use estim_core::{Quantity, checked::check_noise, nalgebra::Matrix2};
/// assert!(check_noise(&Matrix2::new(1.0, 1.0, 1.0, 1.0), Quantity::ProcessNoise).is_ok());
/// assert!(check_noise(&Matrix2::new(1.0, 0.0, 0.5, 1.0), Quantity::ProcessNoise).is_err());
/// ```
pub fn check_noise<T: Real, D: Dim>(noise: &OMatrix<T, D, D>, quantity: Quantity) -> Result<()>
where
    DefaultAllocator: Alloc<D>,
{
    let stage = Stage::Construction;
    let n = noise.nrows();
    ensure_shape(noise, n, n, stage, quantity)?;
    ensure_finite(noise, stage, quantity)?;
    ensure_symmetric(noise, stage, quantity)?;
    psd_factor(noise, stage)
        .map(|_| ())
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
}

impl<T: Real, N: Dim, U: Dim> LinearProcess<T, N, U>
where
    DefaultAllocator: Alloc<N, U>,
{
    /// x⁺ = F x + B u + w, w ~ N(0, Q), checked once: F (n × n) and B (n × p) of matching
    /// shapes and finite (reported as [`Quantity::Jacobian`]), Q by [`check_noise`]
    /// ([`Quantity::ProcessNoise`]), all at [`Stage::Construction`].
    ///
    /// ```
    /// use estim_core::{Error, LinearProcess, Quantity, Stage};
    /// use estim_core::nalgebra::{Matrix2, Matrix2x1};
    /// let f = Matrix2::identity();
    /// let bad = Matrix2::new(1.0, 0.0, 0.0, f64::NAN);
    /// assert_eq!(
    ///     LinearProcess::try_new(f, Matrix2x1::zeros(), bad).unwrap_err(),
    ///     Error::NonFinite { stage: Stage::Construction, quantity: Quantity::ProcessNoise }
    /// );
    /// ```
    pub fn try_new(
        transition: OMatrix<T, N, N>,
        input: OMatrix<T, N, U>,
        noise: OMatrix<T, N, N>,
    ) -> Result<Self> {
        let stage = Stage::Construction;
        let n = transition.nrows();
        ensure_shape(&transition, n, n, stage, Quantity::Jacobian)?;
        ensure_shape(&input, n, input.ncols(), stage, Quantity::Jacobian)?;
        ensure_shape(&noise, n, n, stage, Quantity::ProcessNoise)?;
        ensure_finite(&transition, stage, Quantity::Jacobian)?;
        ensure_finite(&input, stage, Quantity::Jacobian)?;
        check_noise(&noise, Quantity::ProcessNoise)?;
        Ok(Self {
            transition,
            input,
            noise,
        })
    }
}

impl<T: Real, N: Dim, M: Dim> LinearMeasurement<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// z = H x + v, v ~ N(0, R), checked once: H (m × n) finite (reported as
    /// [`Quantity::Jacobian`]), R (m × m) by [`check_noise`] ([`Quantity::MeasurementNoise`]),
    /// at [`Stage::Construction`]. A singular R is accepted (S = H P Hᵀ + R is factorised, and
    /// must be positive definite, at every update).
    ///
    /// ```
    /// use estim_core::{Error, LinearMeasurement, Quantity, Stage};
    /// use estim_core::nalgebra::Matrix2;
    /// let r = Matrix2::new(1.0, 0.3, 0.0, 1.0); // not symmetric
    /// assert!(matches!(
    ///     LinearMeasurement::try_new(Matrix2::identity(), r),
    ///     Err(Error::NotSymmetric { quantity: Quantity::MeasurementNoise, .. })
    /// ));
    /// ```
    pub fn try_new(observation: OMatrix<T, M, N>, noise: OMatrix<T, M, M>) -> Result<Self> {
        let stage = Stage::Construction;
        let m = observation.nrows();
        ensure_shape(&noise, m, m, stage, Quantity::MeasurementNoise)?;
        ensure_finite(&observation, stage, Quantity::Jacobian)?;
        check_noise(&noise, Quantity::MeasurementNoise)?;
        Ok(Self { observation, noise })
    }
}
