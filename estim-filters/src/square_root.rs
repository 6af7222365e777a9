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
//! Θ is orthogonal, built from Givens rotations that lower-triangularise the array (the
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
//! gives L, K̄ = P_xz L⁻ᵀ and S⁺ = (P⁻ − K S_zz Kᵀ)^{1/2} by rotations alone, as robust as the
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
//! same typed errors as [`GaussianFilter`](crate::GaussianFilter). Every step computes its result aside and
//! commits it only when all checks pass, so on an error the filter is bit-identical to before.
//!
//! # Cost and allocation
//!
//! The covariance P = S Sᵀ is **cached**: formed once per committed step (n³/2
//! multiply-adds), so [`Estimator::covariance`] is a plain reference. Static sizes allocate
//! nothing. Runtime sizes allocate their pre-array and factor buffers at each step (no
//! workspace is kept yet) and use the same slice kernels, not faer. Costs against the Joseph
//! form: BENCHMARKS.md, "Square-root filters".
//!
//! The state is a vector (ℝⁿ, ⊞ = +); states with angles or attitudes need the full-P
//! [`GaussianFilter::with_state_space`](crate::GaussianFilter::with_state_space).
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

mod triangular;

use estim_core::checks::{all_finite, ensure_finite, ensure_nonnegative_diagonal, ensure_shape};
use estim_core::kernel::{self, Accum};
use estim_core::linalg::{mirror_lower_checked, psd_factor};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::propagate::{Affine, Linearized, Unscented};
use estim_core::scalar::real;
use estim_core::{
    Alloc, Differentiable, Error, Gaussian, LinearMeasurementModel, LinearProcessModel,
    MeasurementJacobian, MeasurementModel, Observation, Parameter, ProcessJacobian, ProcessModel,
    Quantity, Real, SigmaScratch, Stage, Transition, VectorFunction, error::Result,
};

use crate::gaussian_filter::ensure_time_step;
use crate::report::{UpdateOutcome, UpdateReport};
use crate::traits::{Estimator, Predict, Update};
use crate::update::{Gate, UpdateSettings, log_det_from_cholesky};
use triangular::{Block, lower_triangularize, rank_one_downdate};

/// A Gaussian filter that carries the covariance as a lower-triangular factor S, P = S Sᵀ
/// (module docs: [`square_root`](self)). `Pr` names the propagation: [`Affine`]
/// ([`SrKalmanFilter`]), [`Linearized`] ([`SrEkf`]) or [`Unscented`] ([`SrUkf`]).
///
/// It implements [`Estimator`], [`Predict`] and [`Update`] for the same models as the
/// full-covariance filter of the same name, so it drops into code written for those.
#[derive(Clone, Debug, PartialEq)]
pub struct SquareRootFilter<T: Real, N: Dim, Pr>
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
    settings: UpdateSettings<T>,
}

/// The square-root linear Kalman filter: [`KalmanFilter`](crate::KalmanFilter)'s equations,
/// propagated as S (array form, module docs). Requirements on the model:
/// [`LinearProcessModel`], [`LinearMeasurementModel`].
pub type SrKalmanFilter<T, N> = SquareRootFilter<T, N, Affine>;

/// The square-root extended Kalman filter: [`Ekf`](crate::Ekf) with the array form.
/// Requirements on the model: Jacobians ([`ProcessJacobian`], [`MeasurementJacobian`]).
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
            settings: UpdateSettings::new(),
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

    /// Makes (x̂, S) the estimate, with P = S Sᵀ.
    fn commit(&mut self, state: OVector<T, N>, factor: OMatrix<T, N, N>) {
        self.covariance = outer(&factor);
        self.state = state;
        self.factor = factor;
    }
}

impl<T: Real, N: Dim, Pr> Estimator<T, N> for SquareRootFilter<T, N, Pr>
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
    let n = s.shape_generic().0;
    let mut p = OMatrix::zeros_generic(n, n);
    kernel::mul_tr_lower(&mut p, Accum::Replace, T::one(), s, s);
    mirror_lower_checked(&mut p);
    p
}

/// A lower-triangular factor of the covariance `c` and whether it exists: [`psd_factor`]
/// (which may return a pivoted, non-triangular root for a singular C) made triangular by
/// rotations.
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

/// A square root of the noise covariance `q` (m × m): its shape, non-negative diagonal and
/// finiteness checked, then [`psd_factor`] (semi-definite allowed; an indefinite `q` is
/// `NotPositiveSemiDefinite` naming `quantity`).
fn noise_factor<T: Real, M: Dim>(
    q: &OMatrix<T, M, M>,
    m: usize,
    stage: Stage,
    quantity: Quantity,
) -> Result<OMatrix<T, M, M>>
where
    DefaultAllocator: Alloc<M>,
{
    ensure_shape(q, m, m, stage, quantity)?;
    if !all_finite(q) {
        return Err(Error::NonFinite { stage, quantity });
    }
    ensure_nonnegative_diagonal(q, stage, quantity)?;
    psd_factor(q, stage).map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
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

/// A new estimate (x̂, S), not yet committed.
type Estimate<T, N> = (OVector<T, N>, OMatrix<T, N, N>);

// ---------------------------------------------------------------------------------------
// Linear and linearised steps (KF, EKF).

/// x̂⁻ = f(x̂), S⁻ from [F S | S_Q]: the predicted state and factor.
fn linearized_predict<T, N, G>(
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    f: &G,
    q: &OMatrix<T, N, N>,
) -> Result<Estimate<T, N>>
where
    T: Real,
    N: Dim,
    G: Differentiable<T, N, N>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n_dim = state.shape_generic().0;
    let n = n_dim.value();
    let mut sq = noise_factor(q, n, stage, Quantity::ProcessNoise)?;
    let mut mean = OVector::zeros_generic(n_dim, U1);
    f.eval_into(state, &mut mean);
    ensure_shape(&mean, n, 1, stage, Quantity::FunctionValue)?;
    finite(&mean, stage, Quantity::Mean)?;
    let mut jacobian = OMatrix::zeros_generic(n_dim, n_dim);
    f.jacobian_into(state, &mut jacobian);
    ensure_shape(&jacobian, n, n, stage, Quantity::Jacobian)?;
    finite(&jacobian, stage, Quantity::Jacobian)?;
    let mut fs = OMatrix::zeros_generic(n_dim, n_dim);
    kernel::mul(&mut fs, Accum::Replace, T::one(), &jacobian, factor);
    lower_triangularize(
        n,
        0,
        &mut [
            Block::new(fs.as_mut_slice(), &mut [], n),
            Block::new(sq.as_mut_slice(), &mut [], n),
        ],
    );
    finite(&fs, stage, Quantity::Covariance)?;
    Ok((mean, fs))
}

/// The array-form update: ẑ = h(x̂), H = ∂h/∂x, and from the pre-array [[S_R, H S], [0, S]]
/// the factor L of S_zz, K̄ = P Hᵀ L⁻ᵀ and S⁺; then the shared tail.
fn linearized_update<T, N, M, H>(
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    model: &H,
    z: &OVector<T, M>,
    settings: &UpdateSettings<T>,
    report: &mut UpdateReport<T, M>,
) -> Result<Option<Estimate<T, N>>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let (n_dim, m_dim) = (state.shape_generic().0, z.shape_generic().0);
    let (n, m) = (n_dim.value(), m_dim.value());
    let h = Observation::new(model);
    let mut predicted = OVector::zeros_generic(m_dim, U1);
    h.eval_into(state, &mut predicted);
    ensure_shape(&predicted, m, 1, stage, Quantity::Measurement)?;
    let mut r = OMatrix::zeros_generic(m_dim, m_dim);
    model.measurement_noise_into(state, &mut r);
    let mut l = noise_factor(&r, m, stage, Quantity::MeasurementNoise)?;
    report.fit(m_dim);
    innovation_into(model, z, &predicted, report)?;
    let mut jacobian = OMatrix::zeros_generic(m_dim, n_dim);
    h.jacobian_into(state, &mut jacobian);
    ensure_shape(&jacobian, m, n, stage, Quantity::Jacobian)?;
    finite(&jacobian, stage, Quantity::Jacobian)?;
    let mut hs = OMatrix::zeros_generic(m_dim, n_dim);
    kernel::mul(&mut hs, Accum::Replace, T::one(), &jacobian, factor);
    let mut kbar: OMatrix<T, N, M> = OMatrix::zeros_generic(n_dim, m_dim);
    let mut posterior = factor.clone();
    lower_triangularize(
        m,
        n,
        &mut [
            Block::new(l.as_mut_slice(), kbar.as_mut_slice(), m),
            Block::new(hs.as_mut_slice(), posterior.as_mut_slice(), n),
        ],
    );
    let Some(whitened) = statistics(&l, settings, report)? else {
        return Ok(None);
    };
    finite(&posterior, stage, Quantity::Covariance)?;
    let mut new_state = state.clone();
    kernel::mul(&mut new_state, Accum::Add, T::one(), &kbar, &whitened);
    finite(&new_state, stage, Quantity::Mean)?;
    Ok(Some((new_state, posterior)))
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

/// The report's statistics from the lower factor `l` of S_zz (`report.innovation` holds ν):
/// S_zz = L Lᵀ, NIS = |L⁻¹ν|², ln p = −½ (NIS + 2 Σ ln Lᵢᵢ + m ln 2π), and the gate. Returns
/// L⁻¹ν if the update applies, `None` if gated. A zero (or non-finite) pivot of L is a
/// singular (non-finite) S_zz.
fn statistics<T: Real, M: Dim>(
    l: &OMatrix<T, M, M>,
    settings: &UpdateSettings<T>,
    report: &mut UpdateReport<T, M>,
) -> Result<Option<OVector<T, M>>>
where
    DefaultAllocator: Alloc<M>,
{
    let stage = Stage::Update;
    let quantity = Quantity::InnovationCovariance;
    finite(l, stage, quantity)?;
    let m = l.nrows();
    if (0..m).any(|i| !(l[(i, i)] > T::zero())) {
        return Err(Error::NotPositiveDefinite { stage, quantity });
    }
    report.innovation_covariance = outer(l);
    let mut whitened = report.innovation.clone();
    kernel::solve_lower_in_place(l, &mut whitened);
    let nis = whitened.norm_squared();
    report.nis = nis;
    report.log_likelihood = -real::<T>(0.5)
        * (nis + log_det_from_cholesky(l) + real::<T>(m as f64 * crate::update::LN_TWO_PI));
    if settings.threshold(m).is_some_and(|g| !(nis <= g)) {
        report.outcome = UpdateOutcome::Gated;
        return Ok(None);
    }
    report.outcome = UpdateOutcome::Applied;
    Ok(Some(whitened))
}

// ---------------------------------------------------------------------------------------
// Unscented steps.

/// The sigma-point deviations of y = g(x) at (x̂, S): g(x̂), Dₚ = [g(x̂ + γSⱼ) ⊖ g(x̂)]ⱼ,
/// Dₘ = [g(x̂ − γSⱼ) ⊖ g(x̂)]ⱼ (m × n each), d̄ = w Σ dᵢ and w = 1/(2c).
struct Deviations<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    value: OVector<T, M>,
    plus: OMatrix<T, M, N>,
    minus: OMatrix<T, M, N>,
    mean: OVector<T, M>,
    weight: T,
}

fn deviations<T, N, M, G>(
    ut: &Unscented<T>,
    x: &OVector<T, N>,
    s: &OMatrix<T, N, N>,
    g: &G,
    m_dim: M,
    stage: Stage,
) -> Result<Deviations<T, N, M>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let n_dim = x.shape_generic().0;
    let (n, m) = (n_dim.value(), m_dim.value());
    let c = ut.alpha() * ut.alpha() * (real::<T>(n as f64) + ut.kappa());
    if !(c > T::zero()) {
        return Err(Error::InvalidParameter {
            parameter: Parameter::UnscentedKappa,
            value: estim_core::nalgebra::try_convert::<T, f64>(ut.kappa()).unwrap_or(f64::NAN),
        });
    }
    let offsets = s * c.sqrt();
    let mut value = OVector::zeros_generic(m_dim, U1);
    g.eval_into(x, &mut value);
    ensure_shape(&value, m, 1, stage, Quantity::FunctionValue)?;
    finite(&value, stage, Quantity::FunctionValue)?;
    let mut plus = OMatrix::zeros_generic(m_dim, n_dim);
    let mut minus = OMatrix::zeros_generic(m_dim, n_dim);
    let mut scratch = SigmaScratch::new(n_dim, m_dim);
    g.eval_sigma_points_into(x, &offsets, &mut plus, &mut minus, &mut scratch)?;
    let weight = T::one() / (real::<T>(2.0) * c);
    let mut mean = OVector::zeros_generic(m_dim, U1);
    let mut y = OVector::zeros_generic(m_dim, U1);
    let mut d = OVector::zeros_generic(m_dim, U1);
    for points in [&mut plus, &mut minus] {
        ensure_shape(points, m, n, stage, Quantity::FunctionValue)?;
        finite(points, stage, Quantity::FunctionValue)?;
        for j in 0..n {
            let column = &mut points.as_mut_slice()[j * m..(j + 1) * m];
            y.as_mut_slice().copy_from_slice(column);
            g.difference_into(&y, &value, &mut d);
            ensure_shape(&d, m, 1, stage, Quantity::FunctionValue)?;
            column.copy_from_slice(d.as_slice());
            mean += &d;
        }
    }
    mean *= weight;
    Ok(Deviations {
        value,
        plus,
        minus,
        mean,
        weight,
    })
}

/// The factor of w Σ dᵢdᵢᵀ + (β − α²) d̄ d̄ᵀ + N N ᵀ into `noise` (the m × m factor N on entry):
/// one triangularisation of [N | √w Dₚ | √w Dₘ | √(β − α²) d̄] when β ≥ α², else of the first
/// three blocks and a downdate by √(α² − β) d̄ (`Err(())` if it fails). Consumes the
/// deviations' columns.
fn deviation_factor<T: Real, N: Dim, M: Dim>(
    ut: &Unscented<T>,
    dev: &mut Deviations<T, N, M>,
    noise: &mut OMatrix<T, M, M>,
) -> core::result::Result<(), ()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (m, n) = dev.plus.shape();
    let root_w = dev.weight.sqrt();
    dev.plus *= root_w;
    dev.minus *= root_w;
    let centre = ut.beta() - ut.alpha() * ut.alpha();
    let mut column = dev.mean.clone();
    column *= centre.abs().sqrt();
    let extra = usize::from(centre > T::zero());
    lower_triangularize(
        m,
        0,
        &mut [
            Block::new(noise.as_mut_slice(), &mut [], m),
            Block::new(dev.plus.as_mut_slice(), &mut [], n),
            Block::new(dev.minus.as_mut_slice(), &mut [], n),
            Block::new(&mut column.as_mut_slice()[..m * extra], &mut [], extra),
        ],
    );
    if centre < T::zero() {
        rank_one_downdate(noise.as_mut_slice(), column.as_mut_slice(), m)?;
    }
    Ok(())
}

/// x̂⁻ = f(x̂) ⊞ d̄ and S⁻ from the sigma-point deviations and S_Q.
fn unscented_predict<T, N, G>(
    ut: &Unscented<T>,
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    f: &G,
    q: &OMatrix<T, N, N>,
) -> Result<Estimate<T, N>>
where
    T: Real,
    N: Dim,
    G: VectorFunction<T, N, N>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n_dim = state.shape_generic().0;
    let mut s = noise_factor(q, n_dim.value(), stage, Quantity::ProcessNoise)?;
    let mut dev = deviations(ut, state, factor, f, n_dim, stage)?;
    let mut mean = state.clone();
    f.output_plus_into(&dev.value, &dev.mean, &mut mean);
    ensure_shape(&mean, n_dim.value(), 1, stage, Quantity::Mean)?;
    finite(&mean, stage, Quantity::Mean)?;
    deviation_factor(ut, &mut dev, &mut s).map_err(|()| Error::NotPositiveSemiDefinite {
        stage,
        quantity: Quantity::Covariance,
    })?;
    finite(&s, stage, Quantity::Covariance)?;
    Ok((mean, s))
}

/// The square-root UKF update in array form (module docs): with Aⱼ = (d₊ⱼ − d₋ⱼ)/2 and
/// Bⱼ = (d₊ⱼ + d₋ⱼ)/2, H̃S = √(2w) A (H̃ = P_xzᵀP⁻¹, the statistical linearisation) and
/// R̃ = R + 2w B Bᵀ + (β − α²) d̄ d̄ᵀ, the pre-array [[S_R̃, H̃S], [0, S]] gives L, K̄ = P_xz L⁻ᵀ and
/// S⁺ at once. R̃'s factor comes from [S_R | √(2w) B | √(β − α²) d̄] inside the array when
/// β ≥ α², else from [S_R | √(2w) B] and a rank-one downdate by √(α² − β) d̄ (its failure is
/// `NotPositiveDefinite`, `InnovationCovariance`).
fn unscented_update<T, N, M, H>(
    ut: &Unscented<T>,
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    model: &H,
    z: &OVector<T, M>,
    settings: &UpdateSettings<T>,
    report: &mut UpdateReport<T, M>,
) -> Result<Option<Estimate<T, N>>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let (n_dim, m_dim) = (state.shape_generic().0, z.shape_generic().0);
    let (n, m) = (n_dim.value(), m_dim.value());
    let h = Observation::new(model);
    let mut r = OMatrix::zeros_generic(m_dim, m_dim);
    model.measurement_noise_into(state, &mut r);
    let mut l = noise_factor(&r, m, stage, Quantity::MeasurementNoise)?;
    let dev = deviations(ut, state, factor, &h, m_dim, stage).map_err(|e| match e {
        Error::DimensionMismatch { .. } => Error::DimensionMismatch {
            stage,
            quantity: Quantity::Measurement,
            expected_rows: model.measure(state).nrows(),
            expected_cols: 1,
            found_rows: m,
            found_cols: 1,
        },
        e => e,
    })?;
    let mut predicted = dev.value.clone();
    h.output_plus_into(&dev.value, &dev.mean, &mut predicted);
    report.fit(m_dim);
    innovation_into(model, z, &predicted, report)?;
    let half_root = (real::<T>(2.0) * dev.weight).sqrt() * real::<T>(0.5);
    let mut odd = dev.plus.clone();
    odd -= &dev.minus;
    odd *= half_root;
    let mut even = dev.plus;
    even += &dev.minus;
    even *= half_root;
    let centre = ut.beta() - ut.alpha() * ut.alpha();
    let mut column = dev.mean;
    column *= centre.abs().sqrt();
    if centre < T::zero() {
        lower_triangularize(
            m,
            0,
            &mut [
                Block::new(l.as_mut_slice(), &mut [], m),
                Block::new(even.as_mut_slice(), &mut [], n),
            ],
        );
        rank_one_downdate(l.as_mut_slice(), column.as_mut_slice(), m).map_err(|()| {
            Error::NotPositiveDefinite {
                stage,
                quantity: Quantity::InnovationCovariance,
            }
        })?;
    }
    let extra = usize::from(centre > T::zero());
    let mut kbar: OMatrix<T, N, M> = OMatrix::zeros_generic(n_dim, m_dim);
    let mut posterior: OMatrix<T, N, N> = OMatrix::zeros_generic(n_dim, n_dim);
    let mut below_centre: OVector<T, N> = OVector::zeros_generic(n_dim, U1);
    let mut prior = factor.clone();
    lower_triangularize(
        m,
        n,
        &mut [
            Block::new(l.as_mut_slice(), kbar.as_mut_slice(), m),
            Block::new(even.as_mut_slice(), posterior.as_mut_slice(), n),
            Block::new(
                &mut column.as_mut_slice()[..m * extra],
                &mut below_centre.as_mut_slice()[..n * extra],
                extra,
            ),
            Block::new(odd.as_mut_slice(), prior.as_mut_slice(), n),
        ],
    );
    let Some(whitened) = statistics(&l, settings, report)? else {
        return Ok(None);
    };
    finite(&posterior, stage, Quantity::Covariance)?;
    let mut new_state = state.clone();
    kernel::mul(&mut new_state, Accum::Add, T::one(), &kbar, &whitened);
    finite(&new_state, stage, Quantity::Mean)?;
    Ok(Some((new_state, posterior)))
}

// ---------------------------------------------------------------------------------------
// The step traits.

impl<T: Real, N: Dim, Pr> SquareRootFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    /// Q(x̂, u, Δt) after the checks every prediction starts with.
    fn process_noise<P: ProcessModel<T, N>>(
        &self,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<OMatrix<T, N, N>> {
        ensure_time_step(dt)?;
        self.ensure_factored(Stage::Prediction)?;
        let n = self.state.shape_generic().0;
        let mut q = OMatrix::zeros_generic(n, n);
        model.process_noise_into(&self.state, input, dt, &mut q);
        Ok(q)
    }

    /// A prediction through a differentiable f (KF, EKF).
    fn predict_linearized<P: ProcessJacobian<T, N>>(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<()> {
        let q = self.process_noise(model, input, dt)?;
        let f = Transition::new(model, input, dt);
        let (x, s) = linearized_predict(&self.state, &self.factor, &f, &q)?;
        self.commit(x, s);
        Ok(())
    }

    /// An update through a differentiable h (KF, EKF).
    fn update_linearized<M: Dim, H: MeasurementJacobian<T, N, M>>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        self.ensure_factored(Stage::Update)?;
        let result =
            linearized_update(&self.state, &self.factor, model, z, &self.settings, report)?;
        if let Some((x, s)) = result {
            self.commit(x, s);
        }
        Ok(())
    }
}

impl<T: Real, N: Dim, P: LinearProcessModel<T, N>> Predict<T, N, P> for SrKalmanFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.predict_linearized(model, input, dt)
    }
}

impl<T: Real, N: Dim, P: ProcessJacobian<T, N>> Predict<T, N, P> for SrEkf<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.predict_linearized(model, input, dt)
    }
}

impl<T: Real, N: Dim, P: ProcessModel<T, N>> Predict<T, N, P> for SrUkf<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        let q = self.process_noise(model, input, dt)?;
        let f = Transition::new(model, input, dt);
        let (x, s) = unscented_predict(&self.propagator, &self.state, &self.factor, &f, &q)?;
        self.commit(x, s);
        Ok(())
    }
}

impl<T, N, M, H> Update<T, N, M, H> for SrKalmanFilter<T, N>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: LinearMeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.update_linearized(model, z, report)
    }
}

impl<T, N, M, H> Update<T, N, M, H> for SrEkf<T, N>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.update_linearized(model, z, report)
    }
}

impl<T, N, M, H> Update<T, N, M, H> for SrUkf<T, N>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.ensure_factored(Stage::Update)?;
        let result = unscented_update(
            &self.propagator,
            &self.state,
            &self.factor,
            model,
            z,
            &self.settings,
            report,
        )?;
        if let Some((x, s)) = result {
            self.commit(x, s);
        }
        Ok(())
    }
}
