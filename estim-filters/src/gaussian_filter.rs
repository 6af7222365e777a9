//! The Kalman family as one filter parameterised by its moment propagator.

use estim_core::linalg::{all_finite, ensure_shape, symmetrize};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::propagate::{
    Affine, Linearized, MomentPropagator, SecondOrder, SecondOrderGaussian, Unscented,
};
use estim_core::{
    AffineFunction, Alloc, Error, Gaussian, LinearMeasurementModel, LinearProcessModel,
    MeasurementModel, Observation, ProcessModel, Quantity, Real, Stage, Transition, error::Result,
};

use crate::correlated::Decorrelated;
use crate::report::UpdateReport;
use crate::traits::{Estimator, Predict, PredictCorrelated, Update};
use crate::update::{self, CovarianceUpdate, UpdateSettings};

/// A Gaussian filter: the estimate is N(x̂, P), and both steps ask the propagator `Pr` for the
/// moments of a function of it.
///
/// ```text
/// predict:  (x̂⁻, cov f)  = moments of f(x, u, Δt) for x ~ N(x̂, P);   P⁻ = cov f + Q(x̂, u, Δt)
/// update:   (ẑ, cov h, Pₓᵤ) = moments of h(x);  then the shared Kalman update (see [`update`])
/// ```
///
/// The aliases name the classic filters: [`KalmanFilter`], [`Ekf`], [`SecondOrderEkf`],
/// [`GaussianSecondOrderEkf`], [`Ukf`]. Each requires of the model exactly what its propagator
/// requires of a function; a model lacking it is a compile error.
///
/// Static sizes allocate nothing per step. Every step computes the new estimate aside and
/// commits it only when all checks pass, so an error leaves the filter unchanged.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianFilter<T: Real, N: Dim, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
    propagator: Pr,
    settings: UpdateSettings<T>,
}

/// The linear Kalman filter (Kalman 1960): exact for linear models and accepts only those
/// ([`LinearProcessModel`], [`LinearMeasurementModel`]).
///
/// Predict: x̂⁻ = F x̂ + B u, P⁻ = F P Fᵀ + Q. Update: S = H P Hᵀ + R, K = P Hᵀ S⁻¹,
/// x̂ = x̂⁻ + K (z − H x̂⁻), Joseph covariance update.
pub type KalmanFilter<T, N> = GaussianFilter<T, N, Affine>;

/// The extended Kalman filter: the Kalman equations with F = ∂f/∂x and H = ∂h/∂x at the
/// estimate (Jazwinski 1970, §8.3). Requirements on the model: Jacobians
/// ([`ProcessJacobian`](estim_core::ProcessJacobian),
/// [`MeasurementJacobian`](estim_core::MeasurementJacobian)).
pub type Ekf<T, N> = GaussianFilter<T, N, Linearized>;

/// The truncated second-order filter (Athans, Wishner & Bertolini 1968; Gelb 1974 §6.1):
/// the EKF with the Hessian bias correction ½ Σᵢⱼ (Hₖ ∘ P)ᵢⱼ in the predicted state and the
/// predicted measurement (Papoulis' mean, Boje eq 7). Requirements on the model: Hessians
/// ([`ProcessHessian`](estim_core::ProcessHessian),
/// [`MeasurementHessian`](estim_core::MeasurementHessian)).
pub type SecondOrderEkf<T, N> = GaussianFilter<T, N, SecondOrder>;

/// The Gaussian second-order filter: [`SecondOrderEkf`] plus the covariance terms
/// ½ tr(Hₖ P Hₗ P) that Gaussian fourth moments give. Requirements: Hessians.
pub type GaussianSecondOrderEkf<T, N> = GaussianFilter<T, N, SecondOrderGaussian>;

/// The unscented Kalman filter (Julier & Uhlmann 1997; Wan & van der Merwe 2000), with the
/// scaled sigma points of [`Unscented`] (default α = 10⁻³, β = 2, κ = 0; use
/// [`GaussianFilter::with_propagator`] for others, e.g. [`Unscented::cubature`] for the
/// cubature Kalman filter). Requirements on the model: values only.
pub type Ukf<T, N> = GaussianFilter<T, N, Unscented<T>>;

impl<T: Real, N: Dim, Pr: Default> GaussianFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    /// A filter starting from `prior`, with the propagator's default settings.
    pub fn new(prior: Gaussian<T, N>) -> Self {
        Self::with_propagator(prior, Pr::default())
    }
}

impl<T: Real, N: Dim, Pr> GaussianFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    /// A filter starting from `prior` that propagates moments with `propagator`.
    pub fn with_propagator(prior: Gaussian<T, N>, propagator: Pr) -> Self {
        let (state, covariance) = prior.into_parts();
        Self {
            state,
            covariance,
            propagator,
            settings: UpdateSettings::new(),
        }
    }

    /// Uses `form` for the covariance update (default: Joseph).
    pub fn with_covariance_update(mut self, form: CovarianceUpdate) -> Self {
        self.settings.form = form;
        self
    }

    /// Rejects (and reports as [`Gated`](crate::UpdateOutcome::Gated)) any measurement whose
    /// NIS exceeds `threshold`, e.g. the 99% χ² quantile for the measurement's dimension.
    /// `threshold` must be finite and > 0.
    pub fn with_gate(mut self, threshold: T) -> Result<Self> {
        self.settings = self.settings.with_gate(threshold)?;
        Ok(self)
    }

    /// The moment propagator.
    pub fn propagator(&self) -> &Pr {
        &self.propagator
    }

    /// The covariance update form.
    pub fn covariance_update(&self) -> CovarianceUpdate {
        self.settings.form
    }

    /// The gate threshold, if any.
    pub fn gate(&self) -> Option<T> {
        self.settings.gate
    }
}

impl<T: Real, N: Dim, Pr> Estimator<T, N> for GaussianFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    fn state(&self) -> &OVector<T, N> {
        &self.state
    }

    fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.covariance
    }

    fn reset(&mut self, prior: Gaussian<T, N>) {
        (self.state, self.covariance) = prior.into_parts();
    }
}

/// Moments of `g` plus additive noise `q`: the predicted estimate, not yet committed.
#[inline(always)]
pub(crate) fn predicted<T, N, Pr, G>(
    propagator: &Pr,
    state: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    g: &G,
    q: OMatrix<T, N, N>,
) -> Result<update::Estimate<T, N>>
where
    T: Real,
    N: Dim,
    Pr: MomentPropagator<T, N, N, G>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n = state.nrows();
    ensure_shape(&q, n, n, stage, Quantity::ProcessNoise)?;
    // The propagator checks its own outputs; Q is checked through P⁻ = cov f + Q, and only on
    // failure is it examined to name the culprit.
    let (mean, predicted_covariance) =
        propagator.propagate_mean_covariance(state, covariance, g)?;
    ensure_shape(&mean, n, 1, stage, Quantity::Mean)?;
    let mut p = predicted_covariance + &q;
    symmetrize(&mut p);
    if !all_finite(&p) {
        let quantity = if all_finite(&q) {
            Quantity::Covariance
        } else {
            Quantity::ProcessNoise
        };
        return Err(Error::NonFinite { stage, quantity });
    }
    Ok((mean, p))
}

#[inline(always)]
pub(crate) fn ensure_time_step<T: Real>(dt: T) -> Result<()> {
    if dt.is_finite() {
        Ok(())
    } else {
        Err(Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::TimeStep,
        })
    }
}

impl<T, N, Pr, P> Predict<T, N, P> for GaussianFilter<T, N, Pr>
where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N>,
    Pr: for<'a> MomentPropagator<T, N, N, Transition<'a, P, P::Input, T>>,
    DefaultAllocator: Alloc<N>,
{
    #[inline(always)]
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        ensure_time_step(dt)?;
        let q = model.process_noise(&self.state, input, dt);
        let map = Transition::new(model, input, dt);
        let (x, p) = predicted(&self.propagator, &self.state, &self.covariance, &map, q)?;
        self.state = x;
        self.covariance = p;
        Ok(())
    }
}

impl<T, N, M, Pr, P, H> PredictCorrelated<T, N, M, P, H> for GaussianFilter<T, N, Pr>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessModel<T, N>,
    H: MeasurementModel<T, N, M>,
    Pr: for<'a> MomentPropagator<T, N, N, Decorrelated<'a, P, P::Input, H, T, N, M>>,
    DefaultAllocator: Alloc<N, M>,
{
    #[inline(always)]
    fn predict_correlated(
        &mut self,
        process: &P,
        input: &P::Input,
        dt: T,
        measurement: &H,
        z: &OVector<T, M>,
        cross: &OMatrix<T, N, M>,
    ) -> Result<()> {
        ensure_time_step(dt)?;
        let (map, q_star) =
            Decorrelated::new(process, input, dt, measurement, z, cross, &self.state)?;
        let (x, p) = predicted(
            &self.propagator,
            &self.state,
            &self.covariance,
            &map,
            q_star,
        )?;
        self.state = x;
        self.covariance = p;
        Ok(())
    }
}

/// The measurement update of any filter whose predicted-measurement moments come from
/// `propagator` at (`state`, `covariance`): returns the uncommitted posterior.
#[inline(always)]
pub(crate) fn measurement_update<T, N, M, Pr, H>(
    propagator: &Pr,
    state: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    model: &H,
    z: &OVector<T, M>,
    settings: UpdateSettings<T>,
) -> Result<update::Posterior<T, N, M>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    Pr: for<'a> MomentPropagator<T, N, M, Observation<'a, H>>,
    DefaultAllocator: Alloc<N, M>,
{
    let predicted = propagator.propagate(state, covariance, &Observation::new(model))?;
    ensure_shape(
        z,
        predicted.mean.nrows(),
        1,
        Stage::Update,
        Quantity::Measurement,
    )?;
    let innovation = model.residual(z, &predicted.mean);
    let noise = model.measurement_noise(state);
    update::apply(state, covariance, predicted, noise, innovation, settings)
}

impl<T, N, M, Pr, H> Update<T, N, M, H> for GaussianFilter<T, N, Pr>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    Pr: for<'a> MomentPropagator<T, N, M, Observation<'a, H>>,
    DefaultAllocator: Alloc<N, M>,
{
    #[inline(always)]
    fn update(&mut self, model: &H, z: &OVector<T, M>) -> Result<UpdateReport<T, M>> {
        let (posterior, report) = measurement_update(
            &self.propagator,
            &self.state,
            &self.covariance,
            model,
            z,
            self.settings,
        )?;
        if let Some((x, p)) = posterior {
            self.state = x;
            self.covariance = p;
        }
        Ok(report)
    }
}

impl<P, H, T, N, M> AffineFunction<T, N, N> for Decorrelated<'_, P, P::Input, H, T, N, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: LinearProcessModel<T, N>,
    H: LinearMeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
}
