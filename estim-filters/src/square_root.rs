//! Square-root filters: the covariance carried as its Cholesky factor, P = S Sᵀ.
//!
//! Every step updates S by orthogonal transformations of a *pre-array* (never by forming and
//! refactorising P), so the P = S Sᵀ the filter reports is positive semi-definite by
//! construction, and the factor needs only half the digits P would: its condition number is
//! √κ(P). That is what lets `f32` survive problems where every full-P form fails
//! (BENCHMARKS.md, "f32 survival"; `cargo run --release --example f32_survival`).
//!
//! | filter | predict | update | model needs |
//! |---|---|---|---|
//! | [`SrKalmanFilter`] | [F S, S_Q] → [S⁻, 0] | array form (below) | linear models |
//! | [`SrEkf`] | as the KF, F = ∂f/∂x at x̂ | array form, H = ∂h/∂x at x̂⁻ | Jacobians |
//! | [`SrUkf`] | sigma-point deviations, then a rank-one update/downdate | array form with the statistical linearisation | values |
//!
//! ```text
//! predict (KF/EKF):  [F S | S_Q] Θ = [S⁻ | 0]                          (S_Q S_Qᵀ = Q)
//! update  (KF/EKF):  [S_R  H S⁻] Θ = [L   0 ]     L Lᵀ = H P⁻ Hᵀ + R = S_zz
//!                    [0    S⁻  ]     [K̄   S⁺]     K̄ = P⁻ Hᵀ L⁻ᵀ,  K = K̄ L⁻¹
//!                    x̂⁺ = x̂⁻ + K̄ (L⁻¹ ν),   NIS = |L⁻¹ ν|²,   ln det S_zz = 2 Σ ln Lᵢᵢ
//! ```
//!
//! Θ is orthogonal, built from Householder reflections (Givens rotations for arrays of more
//! than 16 rows, where they measured faster) that lower-triangularise the array (the
//! transposed R factor of a QR factorisation of its transpose; multiplying the identities out,
//! the (2, 2) block gives S⁺S⁺ᵀ = P⁻ − K̄K̄ᵀ = P⁻ − K S_zz Kᵀ, the Kalman posterior: Kaminski,
//! Bryson & Schmidt 1971; Grewal & Andrews, *Kalman Filtering*, §6.5; the "array algorithms" of
//! Kailath, Sayed & Hassibi, *Linear Estimation*, §12).
//!
//! The square-root UKF is Van der Merwe & Wan (2001, *The square-root unscented Kalman filter
//! for state and parameter estimation*, ICASSP), with the sigma points χ = x̂, x̂ ± γ Sⱼ
//! (γ = √c, c = α²(n + κ)), weights w = 1/(2c), and the deviations dᵢ = g(χᵢ) ⊖ g(x̂) taken from
//! the centre point, as [`Unscented`] does (so the centre weight, ≈ −10⁶ for α = 10⁻³, never
//! multiplies anything):
//!
//! ```text
//! ȳ = g(x̂) + d̄,   d̄ = w Σᵢ dᵢ
//! S_y = triangular factor of [S_noise | √w D₊ | √w D₋ | √(β − α²) d̄]    if β ≥ α²
//!       ... of [S_noise | √w D₊ | √w D₋], then a rank-one downdate by √(α² − β) d̄   if β < α²
//! ```
//!
//! which is cov(y) = w Σ dᵢdᵢᵀ + (β − α²) d̄ d̄ᵀ + noise, algebraically the paper's
//! Σ Wᵢ (Yᵢ − ȳ)(Yᵢ − ȳ)ᵀ with its W₀ᶜ.
//!
//! **The update is in array form, not by downdates.** Van der Merwe & Wan remove U Uᵀ
//! (U = P_xz L⁻ᵀ = K S_zz^{1/2}) from S by m rank-one Cholesky downdates. Each downdate
//! computes lₖₖ² − vₖ², which cancels catastrophically when the measurement is much better
//! than the prior: with R = 10⁻¹² and P = 10⁶ the posterior variance is 10⁻¹⁸ of the prior,
//! below ε even in `f64`, and that form fails (measured with it: the first update with
//! R = 10⁻¹² I failed in f32 from P = 10⁶ I and in f64 from P = I). Here instead, split the
//! deviations into odd and even parts, Aⱼ = (d₊ⱼ − d₋ⱼ)/2 and Bⱼ = (d₊ⱼ + d₋ⱼ)/2. Then
//! P_xz = S (√(2w) A)ᵀ exactly (χ±ⱼ − x̂ = ±γSⱼ, w γ² · 2 = 1), so H̃ S = √(2w) A with
//! H̃ = P_xzᵀ P⁻¹ the statistical linearisation, and w Σ dᵢdᵢᵀ = H̃ P H̃ᵀ + 2w B Bᵀ. So
//! S_zz = H̃ P H̃ᵀ + R̃ with R̃ = R + 2w B Bᵀ + (β − α²) d̄ d̄ᵀ, and the KF's pre-array
//!
//! ```text
//! [S_R   √(2w) B   √(β − α²) d̄   √(2w) A] Θ = [L  0  0  0]
//! [0     0         0              S     ]     [K̄  S⁺ 0  0]
//! ```
//!
//! gives L, K̄ = P_xz L⁻ᵀ and S⁺ = (P⁻ − K S_zz Kᵀ)^{1/2} by reflections alone, as robust as the
//! KF's (the paper's downdates and this are the same posterior in exact arithmetic). When
//! β < α² (the cubature rule, α = 1, β = 0: [`Unscented::cubature`]; Julier's set) the centre
//! column cannot be in the array: R̃'s factor is then the triangular factor of
//! [S_R | √(2w) B] downdated by √(α² − β) d̄ (a checked rank-one downdate: failure is reported, never NaN). If
//! that downdate fails, R̃ is indefinite (a sigma-point rule with a negative centre weight
//! can give a measurement covariance smaller than R; the full-P UKF then returns a posterior
//! with a negative variance), and the update is [`Error::NotPositiveDefinite`] with quantity
//! `InnovationCovariance`, the filter unchanged. The prediction's centre downdate failing is
//! [`Error::NotPositiveSemiDefinite`] (quantity `Covariance`).
//!
//! # What every step checks
//!
//! Q and R are factorised each step ([`psd_factor`]: semi-definite allowed), which is also
//! the check of their positive semi-definiteness (the full-P forms run the same rule as a
//! separate test, `estim_core::checked`): an indefinite Q or R is [`Error::NotPositiveSemiDefinite`] (quantity `ProcessNoise` or
//! `MeasurementNoise`), a non-finite one [`Error::NonFinite`]. A non-finite measurement, a
//! negative or non-finite Δt, a singular innovation covariance, a non-finite result: the
//! same typed errors as [`GaussianFilter`](crate::GaussianFilter). The new P = S Sᵀ is checked
//! as the full-P forms check theirs: a finite factor whose P overflows (S = 10²⁰⁰ I, P = ∞ in
//! `f64`) is [`Error::NonFinite`] (quantity `Covariance`), never an `Ok` with an infinite P.
//! Every step computes its result aside and commits it only when all checks pass, so on an
//! error the filter is bit-identical to before.
//!
//! # What to expect from each form
//!
//! Measured by an outside fuzz campaign (issue 41, f64 runs of 10⁶ steps, f32 of 10⁵):
//!
//! - **R ≪ P** (R = 10⁻¹²): every full-P form refuses the first update (a typed error); the
//!   SR-KF survives in `f64` and `f32`, where its NEES reaches 10¹⁵: the state's resolution,
//!   not a broken P (the `f32_survival` example).
//! - **The SR-UKF there** keeps P semi-definite but loses rank: P becomes singular (never
//!   indefinite) at step 41 285 in `f64`, at step 3–4 in `f32`.
//! - **A nearly unobservable `f32` problem**: the full-P UKF with α = 10⁻³ loses definiteness
//!   at step 519 (Standard form) and 2 781 (Joseph); its square-root form never does; with
//!   the `f32` default α = 0.5 the SR-UKF's P turns singular at step 682.
//!
//! So a square-root form never returns an indefinite P, and the SR-KF/SR-EKF keep running where
//! the full-P forms stop; the SR-UKF can lose rank in long or `f32` runs (a singular P, not an
//! error). A step that cannot be computed is a typed error, never an `Ok` with a bad P.
//!
//! # Cost and allocation
//!
//! The covariance P = S Sᵀ is **cached**: formed once per committed step (n³/2
//! multiply-adds), so [`Estimator::covariance`] is a plain reference. Every step works in a
//! [`FactorScratch`] of the pre-array blocks and the new estimate, which the filter swaps in
//! on success. Static sizes keep it on the stack and allocate nothing. Runtime sizes keep one
//! per shape in the filter, sized by the first step with that shape (or by
//! [`prepare_predict`](Predict::prepare_predict) and [`prepare_update`](Update::prepare_update)),
//! so every later step allocates nothing, with models that opt in through
//! [`InPlace`](estim_core::InPlace) (`tests/it/no_alloc_dynamic.rs`; the cross-covariance of
//! [`PredictCross`] still allocates). They use the same slice kernels as static sizes, not
//! faer. Costs against the Joseph form: BENCHMARKS.md, "Square-root filters".
//!
//! The state is a vector (ℝⁿ, ⊞ = +) by default; states with angles or attitudes take a
//! [`StateSpace`] with [`with_state_space`](SquareRootFilter::with_state_space), as the full-P
//! filters do: the SR-UKF forms its sigma points x̂ ⊞ δ and deviations with ⊟ (estim-core's
//! sigma-point generator, the UKF's), and every update corrects x̂ ⊞ K ν. The factor S lives
//! in the tangent space at x̂, as P does for the full-P filters.
//!
//! ```
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//! use estim_filters::{Estimator, KalmanFilter, Predict, SrKalmanFilter, Update};
//!
//! let process = LinearProcess { transition: Matrix2::new(1.0, 0.1, 0.0, 1.0), input: Matrix2x1::new(0.005, 0.1), noise: Matrix2::identity() * 1e-4 };
//! let position = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
//!
//! let mut sr = SrKalmanFilter::new(prior.clone());     // was: KalmanFilter::new(prior)
//! let mut kf = KalmanFilter::new(prior);
//! for filter in [&mut sr as &mut dyn Cart, &mut kf] {
//!     filter.predict(&process, &Vector1::new(1.0), 0.1)?;
//!     filter.update(&position, &Vector1::new(0.02))?;
//! }
//! assert!((sr.covariance() - kf.covariance()).abs().max() < 1e-15);
//! let s = sr.factor(); // lower triangular, S Sᵀ = P
//! assert!((s * s.transpose() - sr.covariance()).abs().max() < 1e-15 && s[(0, 1)] == 0.0);
//! # trait Cart: Predict<f64, estim_core::nalgebra::U2, LinearProcess<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1>> + Update<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1, LinearMeasurement<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1>> {}
//! # impl<F: Predict<f64, estim_core::nalgebra::U2, LinearProcess<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1>> + Update<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1, LinearMeasurement<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1>>> Cart for F {}
//! # Ok::<(), estim_core::Error>(())
//! ```

mod linearized;
mod propagator;
mod scratch;
mod steps;
mod triangular;
mod unscented;

pub use propagator::{FactorPredict, FactorUpdate};
pub use scratch::FactorScratch;

use estim_core::checks::{
    all_finite, ensure_finite, ensure_nonnegative_diagonal, ensure_shape, finite_or_error,
};
use estim_core::kernel::{self, Accum};
use estim_core::linalg::{mirror_lower_checked, psd_factor, psd_factor_exact_into};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::propagate::{Affine, Linearized, Unscented};
use estim_core::{
    Alloc, Error, Euclidean, Gaussian, MeasurementModel, ProcessModel, Quantity, Real, Stage,
    StateSpace, error::Result,
};

use crate::gaussian_filter::{Step, ensure_time_step};
use crate::report::UpdateReport;
use crate::snapshot::{EstimateSnapshot, FactorSnapshot, copy_matrix};
use crate::traits::{Estimator, OnStateSpace, Predict, PredictCross, Rollback, Update};
use crate::update::{Gate, UpdateSettings, report_statistics};
use scratch::FactorCache;
use triangular::{Block, lower_triangularize};

/// A Gaussian filter that carries the covariance as a lower-triangular factor S, P = S Sᵀ
/// (module docs: [`square_root`](self)). `Pr` names the propagation: [`Affine`]
/// ([`SrKalmanFilter`]), [`Linearized`] ([`SrEkf`]) or [`Unscented`] ([`SrUkf`]).
///
/// It implements [`Estimator`], [`Predict`] and [`Update`] for the same models as the
/// full-covariance filter of the same name, so it drops into code written for those.
#[derive(Debug)]
pub struct SquareRootFilter<T: Real, N: Dim, Pr, S = Euclidean>
where
    DefaultAllocator: Alloc<N>,
{
    state: OVector<T, N>,
    /// S, lower triangular with a non-negative diagonal.
    factor: OMatrix<T, N, N>,
    /// S Sᵀ, formed at each commit.
    covariance: OMatrix<T, N, N>,
    /// `false` when the prior's covariance could not be factorised: every step then fails.
    factored: bool,
    propagator: Pr,
    /// The state space: sigma points x̂ ⊞ δ, deviations ⊟, correction x̂ ⊞ K ν.
    space: S,
    settings: UpdateSettings<T>,
    /// The steps' buffers for runtime sizes (not state: not cloned, not compared).
    scratch: FactorCache<T>,
}

/// A clone starts with an empty scratch cache (its first `Dyn` steps size their own).
impl<T: Real, N: Dim, Pr: Clone, S: Clone> Clone for SquareRootFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    fn clone(&self) -> Self {
        Self {
            state: self.state.clone(),
            factor: self.factor.clone(),
            covariance: self.covariance.clone(),
            factored: self.factored,
            propagator: self.propagator.clone(),
            space: self.space.clone(),
            settings: self.settings,
            scratch: FactorCache::default(),
        }
    }
}

/// Equal estimate, factor, propagator, state space and settings (the scratch is not compared).
impl<T: Real, N: Dim, Pr: PartialEq, S: PartialEq> PartialEq for SquareRootFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    fn eq(&self, other: &Self) -> bool {
        self.state == other.state
            && self.factor == other.factor
            && self.covariance == other.covariance
            && self.factored == other.factored
            && self.propagator == other.propagator
            && self.space == other.space
            && self.settings == other.settings
    }
}

/// The square-root linear Kalman filter: [`KalmanFilter`](crate::KalmanFilter)'s equations,
/// propagated as S (array form, module docs). Requirements on the model:
/// [`LinearProcessModel`](estim_core::LinearProcessModel),
/// [`LinearMeasurementModel`](estim_core::LinearMeasurementModel).
pub type SrKalmanFilter<T, N> = SquareRootFilter<T, N, Affine>;

/// The square-root extended Kalman filter: [`Ekf`](crate::Ekf) with the array form.
/// Requirements on the model: Jacobians ([`ProcessJacobian`](estim_core::ProcessJacobian),
/// [`MeasurementJacobian`](estim_core::MeasurementJacobian)).
pub type SrEkf<T, N> = SquareRootFilter<T, N, Linearized>;

/// The square-root unscented Kalman filter (Van der Merwe & Wan 2001) with the scaled sigma
/// points of [`Unscented`] (its defaults, as [`Ukf`](crate::Ukf)). Requirements on the model:
/// values only ([`ProcessModel`], [`MeasurementModel`]).
pub type SrUkf<T, N> = SquareRootFilter<T, N, Unscented<T>>;

impl<T: Real, N: Dim, Pr: Default> SquareRootFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    /// A filter starting from `prior`, with the propagator's default settings.
    ///
    /// The prior's covariance is factorised here ([`psd_factor`], then made lower
    /// triangular). A covariance that cannot be (possible only for a Gaussian made with
    /// `Gaussian::new_unchecked`) gives a filter whose every step fails with
    /// [`Error::NotPositiveSemiDefinite`] (quantity `Covariance`); [`try_new`](Self::try_new)
    /// reports it here instead.
    pub fn new(prior: Gaussian<T, N>) -> Self {
        Self::with_propagator(prior, Pr::default())
    }

    /// [`new`](Self::new), failing when the prior's covariance cannot be factorised.
    ///
    /// ```
    /// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
    /// use estim_filters::SrEkf;
    ///
    /// let bad = Gaussian::new_unchecked(Vector2::zeros(), Matrix2::new(1.0, 0.0, 0.0, -1.0));
    /// assert!(SrEkf::try_new(bad).is_err());
    /// ```
    pub fn try_new(prior: Gaussian<T, N>) -> Result<Self> {
        let filter = Self::new(prior);
        filter.ensure_factored(Stage::Construction)?;
        Ok(filter)
    }
}

impl<T: Real, N: Dim, Pr> SquareRootFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    /// A filter starting from `prior` that propagates with `propagator` (e.g.
    /// [`Unscented::cubature`] for the square-root cubature filter).
    ///
    /// ```
    /// use estim_core::{Gaussian, Unscented, nalgebra::{Matrix2, Vector2}};
    /// use estim_filters::{Estimator, SrUkf};
    ///
    /// let prior = Gaussian::new(Vector2::zeros(), Matrix2::new(4.0, 2.0, 2.0, 2.0))?;
    /// let ckf = SrUkf::with_propagator(prior, Unscented::cubature());
    /// assert_eq!(ckf.factor()[(0, 0)], 2.0); // √4
    /// assert_eq!(ckf.covariance(), &Matrix2::new(4.0, 2.0, 2.0, 2.0));
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn with_propagator(prior: Gaussian<T, N>, propagator: Pr) -> Self {
        let (state, covariance) = prior.into_parts();
        let (factor, factored) = lower_factor(&covariance);
        let covariance = if factored { outer(&factor) } else { covariance };
        Self {
            state,
            factor,
            covariance,
            factored,
            propagator,
            space: Euclidean,
            settings: UpdateSettings::new(),
            scratch: FactorCache::default(),
        }
    }

    /// A filter whose estimate is x̂ = `state` and S = `factor` exactly as given (no
    /// refactorisation; how a checkpoint resumes bit for bit). S must be square of x̂'s
    /// length, finite, lower triangular with a non-negative diagonal, and S Sᵀ finite.
    #[cfg(feature = "serde")]
    pub(crate) fn from_factor(
        state: OVector<T, N>,
        factor: OMatrix<T, N, N>,
        propagator: Pr,
    ) -> Result<Self> {
        let (stage, n) = (Stage::Construction, state.nrows());
        ensure_shape(&factor, n, n, stage, Quantity::Covariance)?;
        ensure_finite(&state, stage, Quantity::Mean)?;
        ensure_finite(&factor, stage, Quantity::Covariance)?;
        let triangular = (0..n).all(|j| factor[(j, j)] >= T::zero())
            && (0..n).all(|j| (0..j).all(|i| factor[(i, j)] == T::zero()));
        if !triangular {
            return Err(Error::NotPositiveSemiDefinite {
                stage,
                quantity: Quantity::Covariance,
            });
        }
        let (covariance, finite) = outer_checked(&factor);
        finite_or_error(finite, stage, Quantity::Covariance)?;
        Ok(Self {
            state,
            factor,
            covariance,
            factored: true,
            propagator,
            space: Euclidean,
            settings: UpdateSettings::new(),
            scratch: FactorCache::default(),
        })
    }
}

impl<T: Real, N: Dim, Pr, S> SquareRootFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    /// The same filter on the state space `space`: the SR-UKF's sigma points x̂ ⊞ δ and
    /// deviations ⊟, and every update's correction x̂⁺ = x̂ ⊞ K ν (Hertzberg et al. 2013), as
    /// [`GaussianFilter::with_state_space`](crate::GaussianFilter::with_state_space) does.
    ///
    /// ```
    /// use estim_core::{Gaussian, WrappedAngles, nalgebra::{Matrix1, Vector1}};
    /// use estim_core::LinearMeasurement;
    /// use estim_filters::{Estimator, SrEkf, Update};
    ///
    /// let prior = Gaussian::new(Vector1::new(3.1), Matrix1::new(0.1))?;
    /// let mut ekf = SrEkf::new(prior).with_state_space(WrappedAngles::new([0]));
    /// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.1) };
    /// ekf.update(&sensor, &Vector1::new(3.3))?; // x̂ = 3.1 ⊞ 0.1 = 3.2 − 2π
    /// assert!((ekf.state()[0] - (3.2 - std::f64::consts::TAU)).abs() < 1e-12);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn with_state_space<S2: StateSpace<T, N>>(
        self,
        space: S2,
    ) -> SquareRootFilter<T, N, Pr, S2> {
        SquareRootFilter {
            state: self.state,
            factor: self.factor,
            covariance: self.covariance,
            factored: self.factored,
            propagator: self.propagator,
            space,
            settings: self.settings,
            scratch: self.scratch,
        }
    }

    /// Rejects (and reports as [`Gated`](crate::UpdateOutcome::Gated)) the measurements `gate`
    /// says, as [`GaussianFilter::with_gate`](crate::GaussianFilter::with_gate) does.
    ///
    /// ```
    /// use estim_core::{Gaussian, LinearMeasurement, nalgebra::{Matrix1, Vector1}};
    /// use estim_filters::{SrKalmanFilter, Update, UpdateOutcome};
    ///
    /// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
    /// let mut kf = SrKalmanFilter::new(prior).with_gate(9.0)?;
    /// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
    /// // NIS = 10²/2 = 50 > 9: rejected.
    /// assert_eq!(kf.update(&sensor, &Vector1::new(10.0))?.outcome, UpdateOutcome::Gated);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn with_gate(mut self, gate: impl Into<Gate<T>>) -> Result<Self> {
        self.settings = self.settings.with_gate(gate.into())?;
        Ok(self)
    }

    /// The gate, if any.
    pub fn gate(&self) -> Option<Gate<T>> {
        self.settings.gate
    }

    /// The propagator.
    pub fn propagator(&self) -> &Pr {
        &self.propagator
    }

    /// The factor S: lower triangular with a non-negative diagonal, S Sᵀ = P.
    pub fn factor(&self) -> &OMatrix<T, N, N> {
        &self.factor
    }

    /// Replaces the state x̂, keeping the factor S as it is: the reset of a closed-loop
    /// error-state filter (after feeding the estimated error into the nominal solution,
    /// x̂ ← 0 with P unchanged). [`Estimator::reset`] would factorise S Sᵀ again, which in
    /// `f32` can lose the small directions the factor still holds.
    ///
    /// A `state` of the wrong length (runtime sizes) is
    /// [`Error::DimensionMismatch`], one with NaN or ±∞ is [`Error::NonFinite`] (quantity
    /// `Mean`); either leaves the filter unchanged.
    ///
    /// ```
    /// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
    /// use estim_filters::{Estimator, SrKalmanFilter};
    ///
    /// let prior = Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::new(4.0, 2.0, 2.0, 2.0))?;
    /// let mut kf = SrKalmanFilter::new(prior);
    /// let factor = *kf.factor();
    /// kf.set_state(Vector2::zeros())?;
    /// assert_eq!(kf.state(), &Vector2::zeros());
    /// assert_eq!(kf.factor(), &factor);
    /// assert!(kf.set_state(Vector2::new(f64::NAN, 0.0)).is_err());
    /// assert_eq!(kf.state(), &Vector2::zeros());
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn set_state(&mut self, state: OVector<T, N>) -> Result<()> {
        let n = self.state.nrows();
        ensure_shape(&state, n, 1, Stage::Construction, Quantity::Mean)?;
        ensure_finite(&state, Stage::Construction, Quantity::Mean)?;
        self.state = state;
        Ok(())
    }

    fn ensure_factored(&self, stage: Stage) -> Result<()> {
        if self.factored {
            Ok(())
        } else {
            Err(Error::NotPositiveSemiDefinite {
                stage,
                quantity: Quantity::Covariance,
            })
        }
    }
}

/// Makes the estimate in `scratch` (x̂ in `state`, S in `factor`) the filter's, with P = S Sᵀ
/// formed in `scratch.covariance`, if P passes the checks the full-P filters make of theirs:
/// finite (a finite S can still overflow in P: S = 10²⁰⁰ I gives P = 10⁴⁰⁰ I = ∞ in f64; issue
/// 41) and, as there, no negative variance (which Pᵢᵢ = Σₖ Sᵢₖ² cannot have once finite, but
/// the rule is the same for every filter). Otherwise `NonFinite` (`NotPositiveSemiDefinite`)
/// for `stage`'s `Covariance`, and the filter is unchanged. Commits by swapping buffers (no
/// copy for runtime sizes); the scratch then holds the old estimate.
#[cfg_attr(not(debug_assertions), inline(always))]
fn commit<T: Real, N: Dim, M: Dim>(
    stage: Stage,
    state: &mut OVector<T, N>,
    factor: &mut OMatrix<T, N, N>,
    covariance: &mut OMatrix<T, N, N>,
    scratch: &mut FactorScratch<T, N, M>,
) -> Result<()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let quantity = Quantity::Covariance;
    let finite = outer_into(&scratch.factor, &mut scratch.covariance);
    finite_or_error(finite, stage, quantity)?;
    ensure_nonnegative_diagonal(&scratch.covariance, stage, quantity)?;
    core::mem::swap(covariance, &mut scratch.covariance);
    core::mem::swap(state, &mut scratch.state);
    core::mem::swap(factor, &mut scratch.factor);
    Ok(())
}

/// x̂, S and the P formed from it, copied as they are: a restore does not refactorise.
impl<T: Real, N: Dim, Pr, S> Rollback for SquareRootFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = FactorSnapshot<T, N>;

    fn snapshot(&self) -> FactorSnapshot<T, N> {
        FactorSnapshot {
            estimate: EstimateSnapshot {
                state: self.state.clone(),
                covariance: self.covariance.clone(),
            },
            factor: self.factor.clone(),
            factored: self.factored,
        }
    }

    fn snapshot_into(&self, snapshot: &mut FactorSnapshot<T, N>) {
        snapshot.estimate.copy_from(&self.state, &self.covariance);
        copy_matrix(&mut snapshot.factor, &self.factor);
        snapshot.factored = self.factored;
    }

    fn restore(&mut self, snapshot: &FactorSnapshot<T, N>) {
        copy_matrix(&mut self.state, &snapshot.estimate.state);
        copy_matrix(&mut self.covariance, &snapshot.estimate.covariance);
        copy_matrix(&mut self.factor, &snapshot.factor);
        self.factored = snapshot.factored;
    }
}

impl<T: Real, N: Dim, Pr, S> Estimator<T, N> for SquareRootFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    fn state(&self) -> &OVector<T, N> {
        &self.state
    }

    /// S Sᵀ, cached (formed at each committed step).
    fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.covariance
    }

    fn reset(&mut self, prior: Gaussian<T, N>) {
        let (state, covariance) = prior.into_parts();
        let (factor, factored) = lower_factor(&covariance);
        self.covariance = if factored { outer(&factor) } else { covariance };
        self.state = state;
        self.factor = factor;
        self.factored = factored;
    }
}

/// S Sᵀ, exactly symmetric (lower triangle mirrored).
fn outer<T: Real, N: Dim>(s: &OMatrix<T, N, N>) -> OMatrix<T, N, N>
where
    DefaultAllocator: Alloc<N>,
{
    outer_checked(s).0
}

/// S Sᵀ as [`outer`], and whether it is finite.
fn outer_checked<T: Real, N: Dim>(s: &OMatrix<T, N, N>) -> (OMatrix<T, N, N>, bool)
where
    DefaultAllocator: Alloc<N>,
{
    let n = s.shape_generic().0;
    let mut p = OMatrix::zeros_generic(n, n);
    let finite = outer_into(s, &mut p);
    (p, finite)
}

/// S Sᵀ into `p` (of S's shape), exactly symmetric, and whether it is finite.
#[cfg_attr(not(debug_assertions), inline(always))]
fn outer_into<T: Real, N: Dim>(s: &OMatrix<T, N, N>, p: &mut OMatrix<T, N, N>) -> bool
where
    DefaultAllocator: Alloc<N>,
{
    kernel::mul_tr_lower(p, Accum::Replace, T::one(), s, s);
    mirror_lower_checked(p)
}

/// A lower-triangular factor of the covariance `c` and whether it exists: [`psd_factor`]
/// (which may return a pivoted, non-triangular root for a singular C) made triangular by
/// reflections.
fn lower_factor<T: Real, N: Dim>(c: &OMatrix<T, N, N>) -> (OMatrix<T, N, N>, bool)
where
    DefaultAllocator: Alloc<N>,
{
    match psd_factor(c, Stage::Construction) {
        Ok(mut s) => {
            let n = s.nrows();
            lower_triangularize(n, 0, &mut [Block::new(s.as_mut_slice(), &mut [], n)]);
            (s, true)
        }
        Err(_) => (c.clone(), false),
    }
}

/// A square root of the noise covariance `q` (m × m) into `root`: its shape, non-negative
/// diagonal and finiteness checked, then [`psd_factor`]'s factor
/// ([`psd_factor_exact_into`]: semi-definite allowed; an indefinite `q` is
/// `NotPositiveSemiDefinite` naming `quantity`).
#[cfg_attr(not(debug_assertions), inline(always))]
fn noise_factor<T: Real, M: Dim>(
    q: &OMatrix<T, M, M>,
    root: &mut OMatrix<T, M, M>,
    m: usize,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Alloc<M>,
{
    ensure_shape(q, m, m, stage, quantity)?;
    if !all_finite(q) {
        return Err(Error::NonFinite { stage, quantity });
    }
    ensure_nonnegative_diagonal(q, stage, quantity)?;
    psd_factor_exact_into(q, root, stage)
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
}

/// `Ok` if `x` is finite, else `NonFinite` naming `quantity`.
fn finite<T: Real, R: Dim, C: Dim>(
    x: &OMatrix<T, R, C>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: estim_core::nalgebra::allocator::Allocator<R, C>,
{
    if all_finite(x) {
        Ok(())
    } else {
        Err(Error::NonFinite { stage, quantity })
    }
}

/// ν = z ⊖ ẑ into the report, checked finite (a non-finite z is `NonFinite`, `Measurement`).
fn innovation_into<T, N, M, H>(
    model: &H,
    z: &OVector<T, M>,
    predicted: &OVector<T, M>,
    report: &mut UpdateReport<T, M>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    if !all_finite(z) {
        return Err(Error::NonFinite {
            stage,
            quantity: Quantity::Measurement,
        });
    }
    finite(predicted, stage, Quantity::FunctionValue)?;
    model.residual_into(z, predicted, &mut report.innovation);
    ensure_shape(
        &report.innovation,
        z.nrows(),
        1,
        stage,
        Quantity::Innovation,
    )?;
    finite(&report.innovation, stage, Quantity::Innovation)
}

/// The tail both array-form updates share: from the lower factor L of S_zz in
/// `scratch.root`, the whitened gain K̄ = P_xz L⁻ᵀ in `scratch.gain` and the posterior factor
/// in `scratch.factor` (`report.innovation` holds ν), the report's statistics (S_zz = L Lᵀ;
/// NIS, log-likelihood and gate as every update forms them) and, unless gated (`Ok(false)`),
/// x̂⁺ = x̂ ⊞ K̄ L⁻¹ν into `scratch.state` (`Ok(true)`). A zero (or non-finite) pivot of L is a
/// singular (non-finite) S_zz; a non-finite posterior is an error. Inlined into both updates:
/// a call of its own added 48 bytes to the SR-UKF 6/4 firmware step's peak stack.
#[cfg_attr(not(debug_assertions), inline(always))]
fn finish_update<T: Real, N: Dim, M: Dim, S: StateSpace<T, N>>(
    space: &S,
    state: &OVector<T, N>,
    threshold: Option<T>,
    scratch: &mut FactorScratch<T, N, M>,
    report: &mut UpdateReport<T, M>,
) -> Result<bool>
where
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let quantity = Quantity::InnovationCovariance;
    let FactorScratch {
        state: new_state,
        factor: posterior,
        root: l,
        gain: kbar,
        whitened,
        step: delta,
        ..
    } = scratch;
    finite(l, stage, quantity)?;
    let m = l.nrows();
    if (0..m).any(|i| !(l[(i, i)] > T::zero())) {
        return Err(Error::NotPositiveDefinite { stage, quantity });
    }
    outer_into(l, &mut report.innovation_covariance);
    kernel::copy(whitened, &report.innovation);
    kernel::solve_lower_in_place(l, whitened);
    let nis = whitened.norm_squared();
    if !report_statistics(l, nis, threshold, report) {
        return Ok(false);
    }
    finite(posterior, stage, Quantity::Covariance)?;
    if S::VECTOR {
        kernel::copy(new_state, state);
        kernel::mul(new_state, Accum::Add, T::one(), kbar, whitened);
    } else {
        // x̂⁺ = x̂ ⊞ K̄ L⁻¹ν.
        kernel::mul(delta, Accum::Replace, T::one(), kbar, whitened);
        space.plus_into(state, delta, new_state);
        ensure_shape(new_state, state.nrows(), 1, stage, Quantity::Mean)?;
    }
    finite(new_state, stage, Quantity::Mean)?;
    Ok(true)
}
