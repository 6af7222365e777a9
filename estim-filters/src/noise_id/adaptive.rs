//! Online measurement-noise estimation by innovation-based covariance matching
//! (Mehra 1972; Mohamed & Schwarz 1999), usable with every filter.
//!
//! A consistent filter's innovations νₖ = zₖ ⊖ ẑₖ have covariance Sₖ = Ĉₖ + Rₖ, with
//! Ĉₖ = cov(ẑₖ) (H P⁻ Hᵀ for a linear model) the part the filter predicts from its state.
//! So Rₖ = E[νₖ νₖᵀ] − Ĉₖ, and every update gives one unbiased sample of R:
//!
//! ```text
//! dₖ = νₖ νₖᵀ − (Sₖ − R̂ₖ)        (Sₖ and νₖ from the update report; R̂ₖ the noise it used)
//! Cₖ = (1 − αₖ) Cₖ₋₁ + αₖ dₖ,    αₖ = max(1/k, 1/L)
//! R̂ₖ₊₁ = Cₖ projected on {R symmetric : eigenvalues ≥ floor}
//! ```
//!
//! **Forgetting window.** αₖ = 1/k for the first L updates (the running mean, so the start
//! value is forgotten after the first sample), then 1/L: an exponentially weighted mean whose
//! weights sum to one, with an effective memory of L updates (weight 1/L on the newest, half
//! the weight gone after L ln 2 updates). A stationary R is then estimated with a standard
//! deviation of about √(Var d / (2L − 1)) per entry (for a scalar, Var d = 2 S², so
//! σ(R̂) ≈ S / √L); a step change in R is followed with time constant L updates. Larger L: less
//! noise, slower tracking.
//!
//! **Failure modes.**
//! - *Indefinite R̂.* When the filter's predicted output covariance Ĉ exceeds the windowed
//!   innovation covariance (a short window, a filter that is too pessimistic, Q too large,
//!   a run of small innovations), C has eigenvalues below zero and is not a covariance. Then
//!   R̂ is C with every eigenvalue below `floor` raised to `floor` (the nearest matrix with that
//!   spectrum bound in the Frobenius norm); the statistic C itself keeps the raw samples, so the
//!   estimate stays unbiased over the window and recovers when the innovations do.
//!   [`clipped`](MeasurementNoiseMatching::clipped) says how many eigenvalues were raised at
//!   the last update.
//! - *Q and R are not separable online from innovations alone*: if Q is wrong, the excess
//!   innovation covariance is attributed to R. Estimate R this way only when Q is trusted
//!   (or use [`em`](super::em) / maximum likelihood in batch).
//! - *Feedback.* R̂ enters the next update, so P and hence Ĉ depend on earlier estimates; with
//!   a short window the loop can chatter. L of several tens of updates avoids it in practice.
//! - Gated updates (outliers rejected by the filter's gate) are not used: their innovations are
//!   by definition not from the model.
//!
//! Use: wrap the measurement model with [`model`](MeasurementNoiseMatching::model) (it
//! returns R̂ as its noise and forwards its value, residual and derivatives, so it works with
//! every filter the model does: Jacobians, Hessians, sigma points; not its allocation-free
//! route, see [`WithNoise`]), update the filter with it, and feed the report back with
//! [`observe`](MeasurementNoiseMatching::observe):
//!
//! ```
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_core::nalgebra::{Matrix1, Vector1};
//! use estim_core::rand::{SeedableRng, rngs::StdRng};
//! use estim_core::rand_distr::{Distribution, Normal};
//! use estim_filters::noise_id::MeasurementNoiseMatching;
//! use estim_filters::{Predict, Ukf, Update};
//!
//! // A random walk (Q = 0.01) seen through noise of variance 0.5; the filter starts with R = 2.
//! let process = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(0.01) };
//! let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(2.0) };
//! let mut adaptive = MeasurementNoiseMatching::new(sensor.noise, 100.0, 1e-6)?;
//! let mut ukf = Ukf::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?);
//! let (mut rng, mut x) = (StdRng::seed_from_u64(7), 0.0);
//! let (walk, noise) = (Normal::new(0.0, 0.1)?, Normal::new(0.0, 0.5f64.sqrt())?);
//! for _ in 0..3000 {
//!     x += walk.sample(&mut rng);
//!     ukf.predict(&process, &Vector1::zeros(), 1.0)?;
//!     let report = ukf.update(&adaptive.model(&sensor), &Vector1::new(x + noise.sample(&mut rng)))?;
//!     adaptive.observe(&report)?;
//! }
//! // σ(R̂) ≈ S / √L ≈ 0.6 / 10 = 0.06.
//! assert!((adaptive.noise()[(0, 0)] - 0.5).abs() < 0.25);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use estim_core::checks::{all_finite, ensure_finite, ensure_symmetric};
use estim_core::linalg::symmetric_map;
use estim_core::nalgebra::{DMatrix, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::scalar::real;
use estim_core::{
    Alloc, Error, LinearMeasurementModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, Quantity, Real, Stage,
};

use super::{NoiseIdError, Setting};
use crate::report::UpdateReport;

/// Covariance matching of the measurement noise R over a forgetting window (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct MeasurementNoiseMatching<T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    window: T,
    floor: T,
    statistic: OMatrix<T, M, M>,
    estimate: OMatrix<T, M, M>,
    samples: usize,
    clipped: usize,
}

impl<T: Real, M: Dim> MeasurementNoiseMatching<T, M>
where
    DefaultAllocator: Alloc<M>,
{
    /// Starts from `initial` (the R the filter would use without adaptation; forgotten after
    /// the first update), with forgetting window `window` = L updates (finite, ≥ 1) and
    /// eigenvalue floor `floor` (finite, > 0; the smallest variance R̂ may have).
    ///
    /// `initial` needs to be symmetric only within `ensure_symmetric`'s tolerance; the start
    /// statistic is its symmetric part (R₀ + R₀ᵀ)/2, formed entry pair by entry pair, so R̂ is
    /// exactly symmetric from the start.
    ///
    /// Errors: [`NoiseIdError::InvalidSetting`] for the window or floor; [`NoiseIdError::Model`]
    /// if `initial` is not finite, not square (runtime sizes) or not symmetric, or with [`Error::NonFinite`] (quantity
    /// `MeasurementNoise`) if R̂ would overflow although `initial` is finite (entries near the
    /// largest finite number, whose eigenvalues exceed it: the projection could not be formed).
    ///
    /// ```
    /// use estim_core::nalgebra::Matrix2;
    /// use estim_filters::noise_id::MeasurementNoiseMatching;
    ///
    /// let m = f64::MAX; // eigenvalues 2·MAX = ∞ and 0
    /// assert!(MeasurementNoiseMatching::new(Matrix2::new(m, -m, -m, m), 10.0, 1e-6).is_err());
    /// ```
    pub fn new(initial: OMatrix<T, M, M>, window: T, floor: T) -> Result<Self, NoiseIdError> {
        let as_f64 = |v: T| v.to_subset().unwrap_or(f64::NAN);
        if !(window >= T::one() && window.is_finite()) {
            return Err(NoiseIdError::InvalidSetting {
                setting: Setting::Window,
                value: as_f64(window),
            });
        }
        if !(floor > T::zero() && floor.is_finite()) {
            return Err(NoiseIdError::InvalidSetting {
                setting: Setting::Floor,
                value: as_f64(floor),
            });
        }
        ensure_finite(&initial, Stage::Construction, Quantity::MeasurementNoise)
            .and_then(|()| {
                ensure_symmetric(&initial, Stage::Construction, Quantity::MeasurementNoise)
            })
            .map_err(NoiseIdError::Model)?;
        let mut statistic = initial;
        let half = real::<T>(0.5);
        // Halves of finite numbers cannot overflow (a sum could); an exactly symmetric pair
        // is kept as it is.
        symmetric_map(
            statistic.nrows(),
            statistic.as_mut_slice(),
            [],
            |a, [], b, []| {
                if a == b { a } else { a * half + b * half }
            },
        );
        let (estimate, clipped) =
            projected(&statistic, floor).ok_or_else(|| overflow(Stage::Construction))?;
        Ok(Self {
            window,
            floor,
            statistic,
            estimate,
            samples: 0,
            clipped,
        })
    }

    /// The current estimate R̂ (symmetric, eigenvalues ≥ floor).
    pub fn noise(&self) -> &OMatrix<T, M, M> {
        &self.estimate
    }

    /// The raw windowed statistic C (may be indefinite: module docs).
    pub fn statistic(&self) -> &OMatrix<T, M, M> {
        &self.statistic
    }

    /// The number of updates used so far.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// How many eigenvalues of C were raised to the floor to form the current R̂ (0 when C was
    /// a valid covariance).
    pub fn clipped(&self) -> usize {
        self.clipped
    }

    /// `inner` with R̂ as its measurement noise, its value, residual and derivatives forwarded
    /// ([`WithNoise`]).
    pub fn model<'a, H>(&'a self, inner: &'a H) -> WithNoise<'a, H, T, M> {
        WithNoise {
            inner,
            noise: &self.estimate,
        }
    }

    /// Uses the report of an update made with [`model`](Self::model) (so with R̂ as the
    /// noise). Returns whether it was used (`false` for a gated update).
    ///
    /// Errors: [`NoiseIdError::Model`] with [`Error::NonFinite`] for a non-finite report
    /// (quantity `Innovation`) or a finite one that would make R̂ overflow (quantity
    /// `MeasurementNoise`: e.g. ν = (10¹⁵⁴, −10¹⁵⁴), whose ν νᵀ has eigenvalue 2·10³⁰⁸), or
    /// [`Error::DimensionMismatch`] for a report of another size; the estimator is then
    /// unchanged.
    pub fn observe(&mut self, report: &UpdateReport<T, M>) -> Result<bool, NoiseIdError> {
        let used = self.estimate.clone();
        self.observe_with(report, &used)
    }

    /// [`observe`](Self::observe) for an update made with noise `used` instead of R̂ (e.g. a
    /// model whose R is set by hand from [`noise`](Self::noise)).
    pub fn observe_with(
        &mut self,
        report: &UpdateReport<T, M>,
        used: &OMatrix<T, M, M>,
    ) -> Result<bool, NoiseIdError> {
        let m = self.estimate.nrows();
        let check = |rows: usize, cols: usize, found: (usize, usize), quantity| {
            let (found_rows, found_cols) = found;
            if (found_rows, found_cols) == (rows, cols) {
                Ok(())
            } else {
                Err(NoiseIdError::Model(Error::DimensionMismatch {
                    stage: Stage::Update,
                    quantity,
                    expected_rows: rows,
                    expected_cols: cols,
                    found_rows,
                    found_cols,
                }))
            }
        };
        check(m, 1, report.innovation.shape(), Quantity::Innovation)?;
        check(
            m,
            m,
            report.innovation_covariance.shape(),
            Quantity::InnovationCovariance,
        )?;
        check(m, m, used.shape(), Quantity::MeasurementNoise)?;
        if !report.applied() {
            return Ok(false);
        }
        let nu = &report.innovation;
        // dₖ = ν νᵀ − (S − R_used).
        let sample = nu * nu.transpose() - &report.innovation_covariance + used;
        if !(all_finite(&sample) && all_finite(nu)) {
            return Err(NoiseIdError::Model(Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Innovation,
            }));
        }
        let k = T::from_usize(self.samples + 1).unwrap_or(self.window);
        let alpha = (T::one() / k).max(T::one() / self.window);
        // C ← (1 − α) C + α sym(d), each entry pair formed once (C is exactly symmetric, and
        // so stays; sym(d) = (d + dᵀ)/2 as halves, which cannot overflow), aside until R̂ is.
        let (keep, half) = (T::one() - alpha, real::<T>(0.5));
        let mut statistic = self.statistic.clone();
        let finite = symmetric_map(
            statistic.nrows(),
            statistic.as_mut_slice(),
            [sample.as_slice()],
            |c, [d], _, [dt]| {
                let d = if d == dt { d } else { d * half + dt * half };
                keep * c + alpha * d
            },
        );
        if !finite {
            return Err(overflow(Stage::Update));
        }
        let (estimate, clipped) =
            projected(&statistic, self.floor).ok_or_else(|| overflow(Stage::Update))?;
        self.statistic = statistic;
        self.estimate = estimate;
        self.clipped = clipped;
        self.samples += 1;
        Ok(true)
    }
}

/// The error of an R̂ that would overflow.
fn overflow(stage: Stage) -> NoiseIdError {
    NoiseIdError::Model(Error::NonFinite {
        stage,
        quantity: Quantity::MeasurementNoise,
    })
}

/// R̂ = C with its eigenvalues raised to at least `floor`, and how many were raised; `None`
/// if C's eigenvalues or R̂ are not finite (C exactly symmetric and finite, but with entries
/// so large that its spectrum overflows). With nothing raised R̂ is C itself; otherwise
/// R̂ = V Λ Vᵀ is formed entry pair by entry pair, R̂ᵢⱼ = R̂ⱼᵢ = Σₖ vᵢₖ λₖ vⱼₖ, so it is
/// exactly symmetric by construction.
fn projected<T: Real, M: Dim>(
    statistic: &OMatrix<T, M, M>,
    floor: T,
) -> Option<(OMatrix<T, M, M>, usize)>
where
    DefaultAllocator: Alloc<M>,
{
    let m = statistic.nrows();
    let dynamic = DMatrix::from_iterator(m, m, statistic.iter().copied());
    let mut eigen = dynamic.symmetric_eigen();
    if !all_finite(&eigen.eigenvalues) {
        return None;
    }
    let mut clipped = 0;
    for v in eigen.eigenvalues.iter_mut() {
        if *v < floor {
            *v = floor;
            clipped += 1;
        }
    }
    let mut estimate = statistic.clone();
    if clipped == 0 {
        return Some((estimate, 0));
    }
    let (vectors, values) = (&eigen.eigenvectors, &eigen.eigenvalues);
    let mut finite = true;
    for j in 0..m {
        for i in j..m {
            let v = (0..m).fold(T::zero(), |sum, k| {
                sum + vectors[(i, k)] * values[k] * vectors[(j, k)]
            });
            estimate[(i, j)] = v;
            estimate[(j, i)] = v;
            finite &= v.is_finite();
        }
    }
    finite.then_some((estimate, clipped))
}

/// A measurement model with its noise replaced by a given matrix (the adaptive estimate):
/// [`MeasurementNoiseMatching::model`]. Every other method forwards to the inner model, so
/// it has the inner model's values, derivatives and linearity. Not its allocation-free
/// [`InPlace`](estim_core::InPlace) route: on runtime sizes an update with it allocates its
/// value, noise and Jacobian, as [`MeasurementNoiseMatching::observe`] allocates at every
/// update anyway (R̂'s eigendecomposition).
#[derive(Clone, Copy, Debug)]
pub struct WithNoise<'a, H, T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    inner: &'a H,
    noise: &'a OMatrix<T, M, M>,
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>> MeasurementModel<T, N, M>
    for WithNoise<'_, H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.inner.measure(x)
    }

    fn measurement_noise(&self, _: &OVector<T, N>) -> OMatrix<T, M, M> {
        self.noise.clone()
    }

    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.inner.residual_into(a, b, out);
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementJacobian<T, N, M>> MeasurementJacobian<T, N, M>
    for WithNoise<'_, H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.inner.measurement_jacobian(x)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementHessian<T, N, M>> MeasurementHessian<T, N, M>
    for WithNoise<'_, H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.inner.measurement_hessian(x, k)
    }
}

impl<T: Real, N: Dim, M: Dim, H: LinearMeasurementModel<T, N, M>> LinearMeasurementModel<T, N, M>
    for WithNoise<'_, H, T, M>
where
    DefaultAllocator: Alloc<N, M>,
{
}
