//! The Kalman family as one filter parameterised by its moment propagator.

use estim_core::checks::{
    all_finite, ensure_nonnegative_diagonal, ensure_semidefinite_noise, ensure_shape,
};
use estim_core::kernel;
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::propagate::{
    Affine, Linearized, MomentPropagator, Outputs, PropagatorWorkspace, SecondOrder,
    SecondOrderGaussian, Unscented,
};
use estim_core::{
    AffineFunction, Alloc, Error, Euclidean, Gaussian, LinearMeasurementModel, LinearProcessModel,
    MeasurementModel, Observation, Parameter, ProcessModel, Quantity, Real, Stage, StateSpace,
    Transition, VectorFunction, error::Result,
};

use crate::correlated::Decorrelated;
use crate::report::UpdateReport;
use crate::scratch::{PredictScratch, ScratchCache, UpdateScratch};
use crate::snapshot::{EstimateSnapshot, copy_matrix};
use crate::traits::{
    Estimator, OnStateSpace, Predict, PredictCorrelated, PredictCross, Rollback, Update,
};
use crate::update::{self, CovarianceUpdate, Gate, UpdateSettings};

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
/// Every step computes the new estimate aside and commits it only when all checks pass, so an
/// error leaves the filter unchanged.
///
/// The state lives in the state space `S` ([`Euclidean`] by default): sigma points are
/// μ ⊞ δ, the update is x̂⁺ = x̂ ⊞ K ν, and deviations of predicted states are x ⊟ x̂ (Hertzberg
/// et al. 2013). For a state with angles give it a [`StateSpace`] that wraps them, with
/// [`with_state_space`](Self::with_state_space).
///
/// # Static or dynamic sizes
///
/// The same code runs on nalgebra's static sizes (`SVector<f64, 6>`, on the stack) and runtime
/// sizes (`DVector<f64>`); switching is changing the types. Static sizes allocate nothing. With
/// runtime sizes the heavy kernels (products, Cholesky, triangular solves) run on faer (and
/// our own SIMD kernel for a matrix times a vector) in
/// buffers the filter keeps, sized by [`prepare_predict`](Predict::prepare_predict) and
/// [`prepare_update`](Update::prepare_update) (once per sensor) right after construction, or
/// else by the first prediction and the first update with each measurement length; after that
/// no step allocates, given models that opt in through [`InPlace`](estim_core::InPlace) (as
/// [`LinearProcess`](estim_core::LinearProcess) and
/// [`LinearMeasurement`](estim_core::LinearMeasurement) do) and
/// [`update_into`](Update::update_into) with a reused report. Which to pick, measured
/// (BENCHMARKS.md, "Static or dynamic"): static sizes for the small states of the papers
/// (n ≤ 6; no heap; 1.6–1.9× faster there); from n = 12 both run the same kernels and are
/// within 10 % of each other (static ahead at 12–16, runtime sizes up to 10 % ahead at 50).
#[derive(Debug)]
pub struct GaussianFilter<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S = Euclidean>
where
    DefaultAllocator: Alloc<N>,
{
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
    propagator: Pr,
    space: S,
    settings: UpdateSettings<T>,
    scratch: ScratchCache<T, Pr>,
    accepted_noise: AcceptedNoise<T, N>,
}

/// A copy of the estimate, the state space, the settings and the remembered Q; the
/// runtime-size buffers are not copied (the clone sizes its own on first use).
impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T> + Clone, S: Clone> Clone
    for GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    fn clone(&self) -> Self {
        Self {
            state: self.state.clone(),
            covariance: self.covariance.clone(),
            propagator: self.propagator.clone(),
            space: self.space.clone(),
            settings: self.settings,
            scratch: ScratchCache::default(),
            accepted_noise: self.accepted_noise.clone(),
        }
    }
}

/// Equal estimates, propagators, state spaces and settings (the runtime-size buffers and the
/// remembered process noise are not compared).
impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T> + PartialEq, S: PartialEq> PartialEq
    for GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    fn eq(&self, other: &Self) -> bool {
        self.state == other.state
            && self.covariance == other.covariance
            && self.propagator == other.propagator
            && self.space == other.space
            && self.settings == other.settings
    }
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
/// scaled sigma points of [`Unscented`] (default β = 2, κ = 0 and α = 10⁻³ in `f64`, 0.5 in
/// `f32`, where α = 10⁻³ would cost the mean all its precision; use
/// [`GaussianFilter::with_propagator`] for others, e.g. [`Unscented::cubature`] for the
/// cubature Kalman filter). Requirements on the model: values only.
pub type Ukf<T, N> = GaussianFilter<T, N, Unscented<T>>;

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T> + Default> GaussianFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    /// A filter starting from `prior`, with the propagator's default settings.
    pub fn new(prior: Gaussian<T, N>) -> Self {
        Self::with_propagator(prior, Pr::default())
    }
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>> GaussianFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
{
    /// A filter starting from `prior` that propagates moments with `propagator`.
    pub fn with_propagator(prior: Gaussian<T, N>, propagator: Pr) -> Self {
        let (state, covariance) = prior.into_parts();
        Self {
            accepted_noise: AcceptedNoise::like(&covariance),
            state,
            covariance,
            propagator,
            space: Euclidean,
            settings: UpdateSettings::new(),
            scratch: ScratchCache::default(),
        }
    }
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S> GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    /// The same filter on the state space `space`: sigma points μ ⊞ δ, update x̂ ⊞ K ν,
    /// deviations of predicted states x ⊟ x̂. The models are unchanged; a measurement of an
    /// angle also wraps its residual.
    ///
    /// ```
    /// use core::f64::consts::PI;
    /// use estim_core::nalgebra::{Const, Matrix1, Vector1};
    /// use estim_core::{Gaussian, StateSpace, wrap_angle};
    /// use estim_filters::{Estimator, Ukf};
    ///
    /// /// A heading in (−π, π].
    /// #[derive(Clone, Debug, PartialEq)]
    /// struct Heading;
    /// impl StateSpace<f64, Const<1>> for Heading {
    ///     fn plus_into(&self, x: &Vector1<f64>, d: &Vector1<f64>, out: &mut Vector1<f64>) {
    ///         out[0] = wrap_angle(x[0] + d[0]);
    ///     }
    ///     fn minus_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
    ///         out[0] = wrap_angle(a[0] - b[0]);
    ///     }
    /// }
    /// let prior = Gaussian::new(Vector1::new(PI - 0.01), Matrix1::new(0.1))?;
    /// let filter = Ukf::new(prior).with_state_space(Heading);
    /// assert_eq!(filter.state()[0], PI - 0.01);
    /// assert_eq!(filter.state_space(), &Heading);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn with_state_space<S2: StateSpace<T, N>>(self, space: S2) -> GaussianFilter<T, N, Pr, S2> {
        GaussianFilter {
            state: self.state,
            covariance: self.covariance,
            propagator: self.propagator,
            space,
            settings: self.settings,
            scratch: self.scratch,
            accepted_noise: self.accepted_noise,
        }
    }

    /// The state space.
    pub fn state_space(&self) -> &S {
        &self.space
    }

    /// Uses `form` for the covariance update (default: Joseph).
    pub fn with_covariance_update(mut self, form: CovarianceUpdate) -> Self {
        self.settings.form = form;
        self
    }

    /// Rejects (and reports as [`Gated`](crate::UpdateOutcome::Gated)) the measurements `gate`
    /// says: a NIS threshold ([`Gate::Nis`]) or a probability ([`Gate::Probability`], the χ²
    /// quantile for each measurement's dimension). A threshold must be finite and > 0, a
    /// probability in (0, 1) ([`Error::InvalidParameter`](estim_core::Error)).
    pub fn with_gate(mut self, gate: impl Into<Gate<T>>) -> Result<Self> {
        self.settings = self.settings.with_gate(gate.into())?;
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

    /// The gate, if any.
    pub fn gate(&self) -> Option<Gate<T>> {
        self.settings.gate
    }
    /// The estimate (to update in place) and the update settings, for filters built on this
    /// one (the iterated EKF).
    #[allow(clippy::type_complexity)]
    pub(crate) fn estimate_mut(
        &mut self,
    ) -> (&mut OVector<T, N>, &mut OMatrix<T, N, N>, UpdateSettings<T>) {
        (&mut self.state, &mut self.covariance, self.settings)
    }
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S> Estimator<T, N> for GaussianFilter<T, N, Pr, S>
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
        let n = self.state.nrows();
        (self.state, self.covariance) = prior.into_parts();
        if self.state.nrows() != n {
            self.scratch.clear();
            self.accepted_noise = AcceptedNoise::like(&self.covariance);
        }
    }
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S> Rollback for GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = EstimateSnapshot<T, N>;

    fn snapshot(&self) -> EstimateSnapshot<T, N> {
        EstimateSnapshot {
            state: self.state.clone(),
            covariance: self.covariance.clone(),
        }
    }

    fn snapshot_into(&self, snapshot: &mut EstimateSnapshot<T, N>) {
        snapshot.copy_from(&self.state, &self.covariance);
    }

    fn restore(&mut self, snapshot: &EstimateSnapshot<T, N>) {
        let n = self.state.nrows();
        copy_matrix(&mut self.state, &snapshot.state);
        copy_matrix(&mut self.covariance, &snapshot.covariance);
        if self.state.nrows() != n {
            self.scratch.clear();
            self.accepted_noise = AcceptedNoise::like(&self.covariance);
        }
    }
}

/// One prediction through `g` plus additive noise (`fill_noise` writes Q(x̂) into its buffer),
/// computed in the step's scratch (a local for static sizes, the filter's cached one for `Dyn`)
/// and committed only if every check passes; the cross-covariance cov(x, g(x)) into `cross`
/// if given (the smoother's prediction: the same path). Q is checked positive semi-definite unless it
/// equals `accepted`, the last Q a committed prediction checked (which it then becomes).
#[cfg_attr(not(debug_assertions), inline(always))]
#[allow(clippy::too_many_arguments)]
fn predict_step<T, N, Pr, G>(
    propagator: &Pr,
    cache: &mut ScratchCache<T, Pr>,
    state: &mut OVector<T, N>,
    covariance: &mut OMatrix<T, N, N>,
    accepted: &mut AcceptedNoise<T, N>,
    g: &G,
    fill_noise: impl FnOnce(&OVector<T, N>, &mut OMatrix<T, N, N>),
    cross: Option<&mut OMatrix<T, N, N>>,
    step: Step,
) -> Result<()>
where
    T: Real,
    N: Dim,
    G: VectorFunction<T, N, N>,
    Pr: MomentPropagator<T, N, N, G>,
    DefaultAllocator: Alloc<N>,
{
    let n = state.shape_generic().0;
    // Chosen here rather than through a closure over the whole step: a local the compiler
    // sees whole stays in registers for small static sizes (issue #6: the 3/2 KF step 85 → 67 ns).
    let mut local;
    let (work, cached) = match cache.predict(n) {
        Some(work) => (work, true),
        None => {
            local = PredictScratch::new(n);
            (&mut local, false)
        }
    };
    fill_noise(state, &mut work.noise);
    let known = accepted.holds(&work.noise);
    let result = predicted(propagator, state, covariance, g, work, known, cross);
    match result {
        Ok(()) if step == Step::Apply => {
            if !known {
                accepted.remember(&work.noise);
            }
            commit(state, covariance, &mut work.state, &mut work.covariance)
        }
        Ok(()) => {}
        Err(_) if cached => cache.discard_predict(),
        Err(_) => {}
    }
    result
}

/// The last process noise Q a committed prediction found positive semi-definite (n × n zeros
/// at first, which are): a prediction whose Q equals it entry for entry skips the check.
#[derive(Clone, Debug)]
struct AcceptedNoise<T: Real, N: Dim>(OMatrix<T, N, N>)
where
    DefaultAllocator: Alloc<N>;

impl<T: Real, N: Dim> AcceptedNoise<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// Zeros of `covariance`'s shape.
    fn like(covariance: &OMatrix<T, N, N>) -> Self {
        let (rows, cols) = covariance.shape_generic();
        Self(OMatrix::zeros_generic(rows, cols))
    }

    /// Whether `q` is the accepted Q: the same shape and equal entries (−0 = +0; NaN equals
    /// nothing), without early exit (a branch-free pass the compiler vectorises).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn holds(&self, q: &OMatrix<T, N, N>) -> bool {
        self.0.shape() == q.shape()
            && (self.0.as_slice().iter())
                .zip(q.as_slice())
                .fold(true, |same, (x, y)| same & (x == y))
    }

    /// Remembers `q`, of the accepted Q's shape, which a committed prediction has just checked.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn remember(&mut self, q: &OMatrix<T, N, N>) {
        kernel::copy(&mut self.0, q);
    }
}

/// Whether a step commits its result or only sizes the buffers it works in (`prepare_*`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Step {
    /// Commit the new estimate (if every check passes).
    Apply,
    /// Compute it and discard it.
    Prepare,
}

/// The predicted estimate into `scratch.state` and `scratch.covariance`, with Q already in
/// `scratch.noise` (and `known` if it equals a Q already checked).
#[cfg_attr(not(debug_assertions), inline(always))]
fn predicted<T, N, Pr, G>(
    propagator: &Pr,
    state: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    g: &G,
    scratch: &mut PredictScratch<T, N, Pr>,
    known: bool,
    cross: Option<&mut OMatrix<T, N, N>>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    G: VectorFunction<T, N, N>,
    Pr: MomentPropagator<T, N, N, G>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n = state.nrows();
    let PredictScratch {
        propagation,
        state: mean,
        covariance: p,
        noise: q,
    } = scratch;
    if !known {
        ensure_process_noise(q, p, n)?;
    }
    // The propagator checks its own outputs; Q is checked through P⁻ = cov f + Q, and only on
    // failure is it examined to name the culprit.
    let mut out = Outputs::mean_covariance(mean, p).with_noise(q);
    out.cross_covariance = cross;
    propagator
        .propagate_into(state, covariance, g, out, propagation)
        .map_err(|e| match e {
            Error::NonFinite {
                quantity: Quantity::Covariance,
                ..
            } if !all_finite(q) => Error::NonFinite {
                stage,
                quantity: Quantity::ProcessNoise,
            },
            e => e,
        })?;
    ensure_predicted_covariance(p)
}

/// Q before a prediction: its shape, and positive semi-definite (an indefinite Q, even with a
/// positive diagonal, can make P⁻ indefinite without any other check failing):
/// [`ensure_semidefinite_noise`], O(n²) without a factorisation when Q is diagonally dominant
/// (every diagonal Q), else one factorisation in `work` (an n × n buffer free at this point).
#[cfg_attr(not(debug_assertions), inline(always))]
fn ensure_process_noise<T: Real, N: Dim>(
    q: &OMatrix<T, N, N>,
    work: &mut OMatrix<T, N, N>,
    n: usize,
) -> Result<()>
where
    DefaultAllocator: Alloc<N>,
{
    let (stage, quantity) = (Stage::Prediction, Quantity::ProcessNoise);
    ensure_shape(q, n, n, stage, quantity)?;
    ensure_semidefinite_noise(q, work, stage, quantity)
}

/// P⁻ after a prediction: a prior accepted as PSD within its rounding tolerance (a variance of
/// −10⁻³⁰⁰) and a finite but huge transition (10³⁰⁰) gave P⁻ a variance of −10³⁰⁰ as `Ok`
/// (found by the fuzz test, tests/it/fuzz.rs). The diagonal costs O(n) to check.
#[cfg_attr(not(debug_assertions), inline(always))]
fn ensure_predicted_covariance<T: Real, N: Dim>(p: &OMatrix<T, N, N>) -> Result<()>
where
    DefaultAllocator: Alloc<N>,
{
    ensure_nonnegative_diagonal(p, Stage::Prediction, Quantity::Covariance)
}

/// Makes `scratch`'s estimate the filter's, swapping buffers (no copy for runtime sizes).
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn commit<T: Real, N: Dim>(
    state: &mut OVector<T, N>,
    covariance: &mut OMatrix<T, N, N>,
    new_state: &mut OVector<T, N>,
    new_covariance: &mut OMatrix<T, N, N>,
) where
    DefaultAllocator: Alloc<N>,
{
    core::mem::swap(state, new_state);
    core::mem::swap(covariance, new_covariance);
}

/// Δt must be finite and ≥ 0: a negative step is a timestamp bug far more often than a wish
/// to predict backwards (which a process noise Q(Δt) cannot express; use a smoother), so it is
/// an error even for models whose Q ignores Δt.
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn ensure_time_step<T: Real>(dt: T) -> Result<()> {
    if !dt.is_finite() {
        Err(Error::NonFinite {
            stage: Stage::Prediction,
            quantity: Quantity::TimeStep,
        })
    } else if dt < T::zero() {
        Err(Error::InvalidParameter {
            parameter: Parameter::TimeStep,
            value: estim_core::nalgebra::try_convert::<T, f64>(dt).unwrap_or(f64::NAN),
        })
    } else {
        Ok(())
    }
}

impl<T, N, Pr, P, S> Predict<T, N, P> for GaussianFilter<T, N, Pr, S>
where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N>,
    S: StateSpace<T, N>,
    Pr: for<'a> MomentPropagator<T, N, N, Transition<'a, P, P::Input, T, S>>,
    DefaultAllocator: Alloc<N>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.process_step(model, input, dt, None, Step::Apply)
    }

    fn prepare_predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.process_step(model, input, dt, None, Step::Prepare)
    }
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S: StateSpace<T, N>> GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    /// A prediction through `model` (or its preparation).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn process_step<P>(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
        cross: Option<&mut OMatrix<T, N, N>>,
        step: Step,
    ) -> Result<()>
    where
        P: ProcessModel<T, N>,
        Pr: for<'a> MomentPropagator<T, N, N, Transition<'a, P, P::Input, T, S>>,
    {
        ensure_time_step(dt)?;
        let Self {
            state,
            covariance,
            propagator,
            space,
            scratch,
            accepted_noise,
            ..
        } = self;
        let map = Transition::on(&*space, model, input, dt);
        let noise = |x: &OVector<T, N>, q: &mut OMatrix<T, N, N>| {
            estim_core::model::process_noise_into(model, x, input, dt, q)
        };
        predict_step(
            propagator,
            scratch,
            state,
            covariance,
            accepted_noise,
            &map,
            noise,
            cross,
            step,
        )
    }
}

/// The state space the filter was given ([`with_state_space`](GaussianFilter::with_state_space)).
impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S: StateSpace<T, N>> OnStateSpace<T, N>
    for GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    type Space = S;

    fn state_space(&self) -> &S {
        &self.space
    }
}

/// The prediction's own path, with the propagator's cross-covariance written out:
///
/// ```
/// use estim_filters::{Ekf, PredictCross};
/// use estim_core::{Gaussian, LinearProcess};
/// use estim_core::nalgebra::{Matrix2, Matrix2x1, Vector1, Vector2};
///
/// let f = Matrix2::new(1.0, 0.1, 0.0, 1.0);
/// let process = LinearProcess { transition: f, input: Matrix2x1::zeros(), noise: Matrix2::identity() * 0.01 };
/// let mut ekf = Ekf::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// let c = ekf.predict_with_cross_covariance(&process, &Vector1::zeros(), 0.1)?;
/// assert!((c - f.transpose()).abs().max() < 1e-15); // cov(x, F x) = P Fᵀ with P = I
/// # Ok::<(), estim_core::Error>(())
/// ```
impl<T, N, Pr, P, S> PredictCross<T, N, P> for GaussianFilter<T, N, Pr, S>
where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N>,
    S: StateSpace<T, N>,
    Pr: for<'a> MomentPropagator<T, N, N, Transition<'a, P, P::Input, T, S>>,
    DefaultAllocator: Alloc<N>,
{
    fn predict_with_cross_covariance(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<OMatrix<T, N, N>> {
        let n = self.state.shape_generic().0;
        let mut cross = OMatrix::zeros_generic(n, n);
        self.process_step(model, input, dt, Some(&mut cross), Step::Apply)?;
        Ok(cross)
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
    /// Runs through the same prediction code (vector states only: the filter's state space is
    /// [`Euclidean`]); building the decorrelated map allocates for
    /// runtime sizes (it solves with R once per call).
    #[cfg_attr(not(debug_assertions), inline(always))]
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
        let Self {
            state,
            covariance,
            propagator,
            scratch,
            accepted_noise,
            ..
        } = self;
        let (map, q_star) = Decorrelated::new(process, input, dt, measurement, z, cross, state)?;
        let noise = |_: &OVector<T, N>, q: &mut OMatrix<T, N, N>| *q = q_star;
        predict_step(
            propagator,
            scratch,
            state,
            covariance,
            accepted_noise,
            &map,
            noise,
            None,
            Step::Apply,
        )
    }
}

/// The measurement update of any filter whose predicted-measurement moments come from
/// `propagator` at (`state`, `covariance`) on the state space `space`: the report goes to
/// `report`, the posterior to `scratch.state` and `scratch.covariance` (uncommitted);
/// `Ok(false)` if gated.
#[cfg_attr(not(debug_assertions), inline(always))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn measurement_update<T, N, M, Pr, H, S>(
    propagator: &Pr,
    space: &S,
    state: &OVector<T, N>,
    covariance: &OMatrix<T, N, N>,
    model: &H,
    z: &OVector<T, M>,
    settings: UpdateSettings<T>,
    scratch: &mut UpdateScratch<T, N, M, Pr>,
    report: &mut UpdateReport<T, M>,
) -> Result<bool>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    S: StateSpace<T, N>,
    Pr: for<'a> MomentPropagator<T, N, M, Observation<'a, H, S>>,
    DefaultAllocator: Alloc<N, M>,
{
    let m = z.nrows();
    propagator
        .propagate_into(
            state,
            covariance,
            &Observation::on(space, model),
            Outputs::moments(&mut scratch.predicted),
            &mut scratch.propagation,
        )
        .map_err(|e| measurement_length_error(e, m))?;
    report.fit(z.shape_generic().0);
    model.residual_into(z, &scratch.predicted.mean, &mut report.innovation);
    estim_core::model::measurement_noise_into(model, state, &mut scratch.noise);
    update::apply(space, state, covariance, scratch, report, settings)
}

/// The buffers are sized from z, so a model whose h(x) has another length fails in the
/// propagation, whose first check is h(x̂)'s length: that is z having the wrong length for the
/// model, and is reported so.
fn measurement_length_error(e: Error, z_len: usize) -> Error {
    match e {
        Error::DimensionMismatch {
            stage: Stage::Propagation,
            quantity: Quantity::FunctionValue,
            expected_rows,
            found_rows,
            found_cols: 1,
            ..
        } if expected_rows == z_len => Error::DimensionMismatch {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
            expected_rows: found_rows,
            expected_cols: 1,
            found_rows: z_len,
            found_cols: 1,
        },
        e => e,
    }
}

impl<T, N, M, Pr, H, S> Update<T, N, M, H> for GaussianFilter<T, N, Pr, S>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    S: StateSpace<T, N>,
    Pr: for<'a> MomentPropagator<T, N, M, Observation<'a, H, S>>,
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.measurement_step(model, z, report, Step::Apply)
    }

    fn prepare_update(&mut self, model: &H, report: &mut UpdateReport<T, M>) -> Result<()> {
        let z = model.measure(&self.state);
        self.measurement_step(model, &z, report, Step::Prepare)
    }
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S: StateSpace<T, N>> GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    /// P ← γ⁻¹P: the fading-memory filter's inflation before its update, each entry divided
    /// (the caller keeps a snapshot to undo it).
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn inflate_covariance(&mut self, gamma: T) {
        self.covariance /= gamma;
    }

    /// An update with `model` and `z` (or its preparation).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn measurement_step<M, H>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
        step: Step,
    ) -> Result<()>
    where
        M: Dim,
        H: MeasurementModel<T, N, M>,
        Pr: for<'a> MomentPropagator<T, N, M, Observation<'a, H, S>>,
        DefaultAllocator: Alloc<N, M>,
    {
        let Self {
            state,
            covariance,
            propagator,
            space,
            settings,
            scratch,
            ..
        } = self;
        update_step(
            propagator, space, scratch, state, covariance, model, z, *settings, report, step,
        )
    }
}

/// One measurement update, computed in the step's scratch (a local for static sizes, the
/// filter's cached one for `Dyn`) and committed only if applied.
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn update_step<T, N, M, Pr, H, S>(
    propagator: &Pr,
    space: &S,
    cache: &mut ScratchCache<T, Pr>,
    state: &mut OVector<T, N>,
    covariance: &mut OMatrix<T, N, N>,
    model: &H,
    z: &OVector<T, M>,
    settings: UpdateSettings<T>,
    report: &mut UpdateReport<T, M>,
    step: Step,
) -> Result<()>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    S: StateSpace<T, N>,
    Pr: for<'a> MomentPropagator<T, N, M, Observation<'a, H, S>>,
    DefaultAllocator: Alloc<N, M>,
{
    let (n, m) = (state.shape_generic().0, z.shape_generic().0);
    let mut local;
    let (work, slot) = match cache.update(n, m) {
        Some((work, slot)) => (work, Some(slot)),
        None => {
            local = UpdateScratch::new(n, m);
            (&mut local, None)
        }
    };
    let result = measurement_update(
        propagator, space, state, covariance, model, z, settings, work, report,
    );
    match result {
        Ok(true) if step == Step::Apply => {
            commit(state, covariance, &mut work.state, &mut work.covariance)
        }
        Ok(_) => {}
        Err(_) => {
            if let Some(slot) = slot {
                cache.discard_update(slot);
            }
        }
    }
    result.map(|_| ())
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
