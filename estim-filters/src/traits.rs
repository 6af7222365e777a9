//! The step traits every filter implements.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{
    Alloc, Gaussian, MeasurementModel, ProcessModel, Real, StateSpace, error::Result,
};

use crate::report::UpdateReport;

/// The read/reset side of any estimator of an `N`-dimensional state. Object safe, so a
/// filter chosen at run time can live in a `Box<dyn Estimator<T, N>>`.
///
/// To box a filter that can also *step*, name the models your program uses in one trait of
/// your own over [`Predict`] and [`Update`] (both object safe for a concrete model type), with
/// a blanket impl; every filter that accepts those models is then one `Box<dyn ...>`:
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, U1, U2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::{Ekf, Estimator, KalmanFilter, Predict, Ukf, Update};
///
/// type Process = LinearProcess<f64, U2, U1>;
/// type Sensor = LinearMeasurement<f64, U2, U1>;
/// /// Any filter of a 2-state cart with a position sensor.
/// trait CartFilter: Predict<f64, U2, Process> + Update<f64, U2, U1, Sensor> {}
/// impl<F: Predict<f64, U2, Process> + Update<f64, U2, U1, Sensor>> CartFilter for F {}
///
/// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
/// let choice = "ukf"; // from a configuration file, say
/// let mut filter: Box<dyn CartFilter> = match choice {
///     "kf" => Box::new(KalmanFilter::new(prior)),
///     "ekf" => Box::new(Ekf::new(prior)),
///     _ => Box::new(Ukf::new(prior)),
/// };
/// let process = LinearProcess {
///     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
///     input: Matrix2x1::zeros(),
///     noise: Matrix2::identity() * 1e-3,
/// };
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.1) };
/// filter.predict(&process, &Vector1::zeros(), 1.0)?;
/// filter.update(&sensor, &Vector1::new(0.3))?;
/// assert!(filter.covariance()[(0, 0)] < 1.0);
/// # Ok::<(), estim_core::Error>(())
/// ```
pub trait Estimator<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The state estimate x̂.
    fn state(&self) -> &OVector<T, N>;

    /// The estimate's covariance P.
    fn covariance(&self) -> &OMatrix<T, N, N>;

    /// Restarts from `prior`, keeping the filter's configuration.
    fn reset(&mut self, prior: Gaussian<T, N>);

    /// The estimate as a Gaussian N(x̂, P) (a copy).
    fn estimate(&self) -> Gaussian<T, N> {
        Gaussian::new_unchecked(self.state().clone(), self.covariance().clone())
    }
}

/// Rollback: everything an estimator's future steps depend on, saved and put back bit-exactly.
///
/// A snapshot holds what the steps change (the estimate, a square-root factor, whatever a
/// cloud of particles or a set of modes needs), not the configuration (propagator, gate,
/// covariance form), which steps never change. After [`restore`](Self::restore) every step
/// gives the same bits it would have given when the snapshot was taken. This, not
/// [`Estimator::reset`], is how the fusion driver replays delayed readings, how the sequence
/// functions undo a failed run and what checkpoints write: `reset` starts from a Gaussian,
/// which would refactorise a square-root factor (losing bits) and could not hold a particle
/// cloud or mode probabilities.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement};
/// use estim_filters::{Estimator, Rollback, SrKalmanFilter, Update};
///
/// let mut filter = SrKalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.1) };
/// let saved = filter.snapshot();
/// let first = filter.update(&sensor, &Vector1::new(0.3))?;
/// let after = filter.factor().clone();
/// filter.restore(&saved); // as if the update never happened, factor and all
/// let again = filter.update(&sensor, &Vector1::new(0.3))?;
/// assert_eq!((filter.factor(), again.log_likelihood), (&after, first.log_likelihood));
/// # Ok::<(), estim_core::Error>(())
/// ```
pub trait Rollback {
    /// What a snapshot holds (cheap to clone relative to a step: a few vectors and matrices).
    type Snapshot: Clone;

    /// A snapshot of the current state of the estimator.
    fn snapshot(&self) -> Self::Snapshot;

    /// Overwrites `snapshot` with the current state, reusing its buffers where the sizes
    /// agree (so a history of snapshots recycled this way allocates nothing with runtime
    /// sizes).
    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        *snapshot = self.snapshot();
    }

    /// Puts back a snapshot taken from this estimator (or from a clone of it).
    fn restore(&mut self, snapshot: &Self::Snapshot);
}

/// The input type a prediction with the model `P` takes (besides Δt): the model's
/// [`ProcessModel::Input`] for every process model (a blanket impl), or what a set of
/// per-mode models (a multiple-model estimator) names as its input.
pub trait ProcessInput<T: Real, N: Dim> {
    /// The input u.
    type Input;
}

impl<T: Real, N: Dim, P: ProcessModel<T, N> + ?Sized> ProcessInput<T, N> for P
where
    DefaultAllocator: Alloc<N>,
{
    type Input = P::Input;
}

/// The time update over a process model `P`. Each filter bounds `P` by what it needs; the
/// trait asks only that `P` name its input ([`ProcessInput`], which every [`ProcessModel`]
/// does), so an estimator whose model is a set of per-mode models, or one that samples,
/// implements it too.
pub trait Predict<T: Real, N: Dim, P: ProcessInput<T, N> + ?Sized>: Estimator<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// Propagates the estimate through x⁺ = f(x, u, Δt) + w.
    ///
    /// On error the filter is left exactly as it was. Δt must be finite and ≥ 0
    /// ([`Parameter::TimeStep`](estim_core::Parameter::TimeStep): a negative step is refused
    /// even when Q ignores Δt). Q must be finite and positive semi-definite (checked each step:
    /// O(n²) for a diagonally dominant Q, one factorisation otherwise, skipped by the Gaussian
    /// filters for a Q equal to the last one they accepted; constant noise can be checked once
    /// when the model is built, see [`estim_core::checked`], which also gives the policy for a
    /// state-dependent Q).
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()>;

    /// Sizes ahead of time every buffer that [`predict`](Self::predict) with this model needs,
    /// by computing one prediction at the current estimate and discarding it: the estimate is
    /// unchanged. With runtime sizes (and models that opt in through
    /// [`InPlace`](estim_core::InPlace)) every later prediction allocates nothing, the first one included; call it once after
    /// construction (and after a [`reset`](Estimator::reset) to another dimension). Static
    /// sizes need no preparation, and filters without runtime buffers do nothing (the
    /// default). Fails as `predict` would, leaving the filter unchanged.
    fn prepare_predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        let _ = (model, input, dt);
        Ok(())
    }
}

/// The measurement update with a measurement model `H` of `M` components. Each filter bounds
/// `H` by what it needs (the trait does not). The model is passed per call, so one filter
/// takes any number of sensors at any rates.
pub trait Update<T: Real, N: Dim, M: Dim, H: ?Sized>: Estimator<T, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Corrects the estimate with measurement `z` = h(x) + v.
    ///
    /// Returns the update report (innovation, its covariance, NIS, log-likelihood); if a gate
    /// is set and the NIS exceeds it, the report says [`Gated`](crate::UpdateOutcome::Gated)
    /// and the estimate is unchanged. On error the filter is left exactly as it was. R must
    /// be finite and positive semi-definite, and S = cov ẑ + R positive definite (checked each
    /// step; see [`estim_core::checked`] for the cost and the policy for a state-dependent R).
    ///
    /// The report is a new value each call; with runtime sizes that is the one allocation of
    /// the step, which [`update_into`](Self::update_into) avoids.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn update(&mut self, model: &H, z: &OVector<T, M>) -> Result<UpdateReport<T, M>> {
        let mut report = UpdateReport::zeros(z.shape_generic().0);
        self.update_into(model, z, &mut report)?;
        Ok(report)
    }

    /// [`update`](Self::update), writing the report into `report` and reusing its buffers
    /// (resized if they do not have z's length; use one report per measurement size). With
    /// runtime sizes and a model that opts in through [`InPlace`](estim_core::InPlace), a
    /// step then allocates nothing. On error the filter is left exactly as it was and `report` is unspecified.
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>;

    /// Sizes ahead of time every buffer that [`update_into`](Self::update_into) with this
    /// model needs, and `report` for its measurement length, by computing one update at the
    /// current estimate with z = h(x̂) and discarding it: the estimate is unchanged (this call
    /// itself allocates). With runtime sizes (and models that opt in through
    /// [`InPlace`](estim_core::InPlace)) every later `update_into` with this model's measurement length allocates nothing, the
    /// first one included; prepare once per sensor. Static sizes need no preparation, and
    /// filters without runtime buffers do nothing (the default). Fails as an update would,
    /// leaving the filter unchanged.
    fn prepare_update(&mut self, model: &H, report: &mut UpdateReport<T, M>) -> Result<()> {
        let _ = (model, report);
        Ok(())
    }
}

/// A filter whose estimate lives on a state space with ⊞/⊟ ([`StateSpace`]): what a
/// smoother's backward pass needs of the filter that ran the forward pass.
pub trait OnStateSpace<T: Real, N: Dim>: Estimator<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The state space type (⊞/⊟ default to + and −: [`Euclidean`](estim_core::Euclidean)).
    type Space: StateSpace<T, N>;

    /// The state space the estimate lives on.
    fn state_space(&self) -> &Self::Space;
}

/// A filter that can be smoothed: its prediction also gives C = cov(xₖ, xₖ₊₁), the
/// covariance of the state before and after the step, which a Rauch–Tung–Striebel smoother
/// records (G = C (P⁻)⁻¹). Every Gaussian filter of the family implements it; the smoother
/// and the sequence functions ([`crate::smoother`]) take any filter that does.
pub trait PredictCross<T: Real, N: Dim, P: ProcessInput<T, N> + ?Sized>:
    Predict<T, N, P> + OnStateSpace<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// [`Predict::predict`] that also returns C = cov(xₖ, xₖ₊₁) (the propagator's
    /// cross-covariance; additive process noise adds none). Allocates its result; on an
    /// error the filter is unchanged.
    fn predict_with_cross_covariance(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<OMatrix<T, N, N>>;
}

/// The time update when the process noise wₖ of this step is correlated with the noise vₖ of
/// the measurement zₖ taken at the start of the step: E[wₖ vₖᵀ] = S (n × m).
///
/// Call it right after updating with zₖ (or instead of predicting, if zₖ was not used), as
/// [`Predict::predict`] is called otherwise. The filter uses the decorrelated process
/// (Simon, *Optimal State Estimation*, §7.1; Anderson & Moore §5.5)
///
/// ```text
/// x⁺ = f(x) + D (zₖ ⊖ h(x)) + w*,   D = S R⁻¹,   Q* = Q − S R⁻¹ Sᵀ,
/// ```
///
/// whose noise w* = w − D v is uncorrelated with vₖ. For linear models this gives exactly the
/// one-step predictor of Boje eq 16, K = (A P Cᵀ + S)(R + C P Cᵀ)⁻¹.
pub trait PredictCorrelated<T, N, M, P, H>: Estimator<T, N>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessModel<T, N>,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    /// Predicts through `process` with noise correlated (cross-covariance `cross`) with the
    /// noise of `measurement`'s reading `z`.
    ///
    /// Errors also when R is not positive definite or Q − S R⁻¹ Sᵀ is not positive
    /// semi-definite (S inconsistent with Q and R). On error the filter is unchanged.
    #[allow(clippy::too_many_arguments)]
    fn predict_correlated(
        &mut self,
        process: &P,
        input: &P::Input,
        dt: T,
        measurement: &H,
        z: &OVector<T, M>,
        cross: &OMatrix<T, N, M>,
    ) -> Result<()>;
}
