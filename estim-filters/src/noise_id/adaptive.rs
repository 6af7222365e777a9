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
//! returns R̂ as its noise and forwards everything else, so it works with every filter and
//! every capability: Jacobians, Hessians, sigma points), update the filter with it, and feed the
//! report back with [`observe`](MeasurementNoiseMatching::observe):
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

use estim_core::checks::{all_finite, ensure_finite, ensure_symmetric, symmetrize};
use estim_core::nalgebra::{DMatrix, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{
    Alloc, Error, LinearMeasurementModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, Quantity, Real, Stage, function::SigmaScratch,
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
    /// Errors: [`NoiseIdError::InvalidSetting`] for the window or floor; [`NoiseIdError::Model`]
    /// if `initial` is not finite or not symmetric.
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
        let mut this = Self {
            window,
            floor,
            statistic: initial.clone(),
            estimate: initial,
            samples: 0,
            clipped: 0,
        };
        this.project();
        Ok(this)
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

    /// `inner` with R̂ as its measurement noise, everything else forwarded.
    pub fn model<'a, H>(&'a self, inner: &'a H) -> WithNoise<'a, H, T, M> {
        WithNoise {
            inner,
            noise: &self.estimate,
        }
    }

    /// Uses the report of an update made with [`model`](Self::model) (so with R̂ as the
    /// noise). Returns whether it was used (`false` for a gated update).
    ///
    /// Errors: [`NoiseIdError::Model`] with [`Error::NonFinite`] for a non-finite report, or
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
        self.statistic = &self.statistic * (T::one() - alpha) + sample * alpha;
        symmetrize(&mut self.statistic);
        self.samples += 1;
        self.project();
        Ok(true)
    }

    /// R̂ ← C with its eigenvalues raised to at least the floor.
    fn project(&mut self) {
        let m = self.statistic.nrows();
        let dynamic = DMatrix::from_iterator(m, m, self.statistic.iter().copied());
        let mut eigen = dynamic.symmetric_eigen();
        self.clipped = 0;
        for v in eigen.eigenvalues.iter_mut() {
            if *v < self.floor {
                *v = self.floor;
                self.clipped += 1;
            }
        }
        if self.clipped == 0 {
            self.estimate.copy_from(&self.statistic);
            return;
        }
        let projected = eigen.recompose();
        self.estimate = OMatrix::from_iterator_generic(
            self.statistic.shape_generic().0,
            self.statistic.shape_generic().1,
            projected.iter().copied(),
        );
        symmetrize(&mut self.estimate);
    }
}

/// A measurement model with its noise replaced by a given matrix (the adaptive estimate):
/// [`MeasurementNoiseMatching::model`]. Every other method forwards to the inner model, so
/// it has every capability the inner model has.
#[derive(Clone, Copy, Debug)]
pub struct WithNoise<'a, H, T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    inner: &'a H,
    noise: &'a OMatrix<T, M, M>,
}

impl<H, T: Real, N: Dim, M: Dim> MeasurementModel<T, N, M> for WithNoise<'_, H, T, M>
where
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.inner.measure(x)
    }

    fn measurement_noise(&self, _: &OVector<T, N>) -> OMatrix<T, M, M> {
        self.noise.clone()
    }

    fn residual(&self, a: &OVector<T, M>, b: &OVector<T, M>) -> OVector<T, M> {
        self.inner.residual(a, b)
    }

    fn measure_into(&self, x: &OVector<T, N>, out: &mut OVector<T, M>) {
        self.inner.measure_into(x, out);
    }

    fn measurement_noise_into(&self, _: &OVector<T, N>, out: &mut OMatrix<T, M, M>) {
        if out.shape() == self.noise.shape() {
            out.copy_from(self.noise);
        } else {
            *out = self.noise.clone();
        }
    }

    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.inner.residual_into(a, b, out);
    }

    fn measure_sigma_points_into(
        &self,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        plus: &mut OMatrix<T, M, N>,
        minus: &mut OMatrix<T, M, N>,
        scratch: &mut SigmaScratch<T, N, M>,
    ) -> estim_core::error::Result<()> {
        self.inner
            .measure_sigma_points_into(mean, offsets, plus, minus, scratch)
    }
}

impl<H, T: Real, N: Dim, M: Dim> MeasurementJacobian<T, N, M> for WithNoise<'_, H, T, M>
where
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.inner.measurement_jacobian(x)
    }

    fn measurement_jacobian_into(&self, x: &OVector<T, N>, out: &mut OMatrix<T, M, N>) {
        self.inner.measurement_jacobian_into(x, out);
    }
}

impl<H, T: Real, N: Dim, M: Dim> MeasurementHessian<T, N, M> for WithNoise<'_, H, T, M>
where
    H: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.inner.measurement_hessian(x, k)
    }

    fn measurement_hessian_into(
        &self,
        x: &OVector<T, N>,
        k: usize,
        out: &mut OMatrix<T, N, N>,
    ) -> bool {
        self.inner.measurement_hessian_into(x, k, out)
    }
}

impl<H, T: Real, N: Dim, M: Dim> LinearMeasurementModel<T, N, M> for WithNoise<'_, H, T, M>
where
    H: LinearMeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
}
