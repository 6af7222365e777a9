//! The interacting multiple model estimator (IMM; Blom & Bar-Shalom 1988; Bar-Shalom, Li &
//! Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, §11.6.6).
//!
//! The system switches between m modes as a Markov chain, πᵢⱼ = P(mode j at k+1 | mode i at
//! k) (Π row-stochastic), and each mode j has its own process model. One estim filter per mode
//! ([`modes`]: a tuple of filters of any types, or a `Vec`) runs matched to its mode, and the
//! IMM keeps the mode probabilities μ. One cycle, split over the two steps:
//!
//! ```text
//! predict:  c̄ⱼ = Σᵢ πᵢⱼ μᵢ                                      (chain prediction)
//!           μᵢ|ⱼ = πᵢⱼ μᵢ / c̄ⱼ                                  (mixing weights)
//!           x̂⁰ⱼ = Σᵢ μᵢ|ⱼ x̂ᵢ,  P⁰ⱼ = Σᵢ μᵢ|ⱼ (Pᵢ + (x̂ᵢ − x̂⁰ⱼ)(x̂ᵢ − x̂⁰ⱼ)ᵀ)
//!           mode j restarts from N(x̂⁰ⱼ, P⁰ⱼ) and predicts with model j;  μ ← c̄
//! update:   every mode updates with z;  ℓⱼ = its report's log-likelihood
//!           μⱼ ← c̄ⱼ exp(ℓⱼ) / Σₖ c̄ₖ exp(ℓₖ)                    (in logs: no underflow)
//! (a mode with c̄ⱼ = 0, or μⱼ = 0 at an update, is skipped: see below)
//! both:     x̂ = Σⱼ μⱼ x̂ⱼ,  P = Σⱼ μⱼ (Pⱼ + (x̂ⱼ − x̂)(x̂ⱼ − x̂)ᵀ)  (the combined estimate)
//! ```
//!
//! Mixing happens at each prediction (one Markov transition per prediction), so several
//! sensors may update between two predictions, each multiplying in its likelihood. Π is
//! therefore per prediction step: where steps vary in length (the fusion driver predicts in
//! sub-steps of at most `max_step`), give Π for that step, or change it with
//! [`Imm::set_transition`]. The
//! combined estimate ([`Estimator::state`], [`Estimator::covariance`]) and μ
//! ([`Imm::probabilities`]) are current after every step: after a prediction they are the
//! predicted mixture's (weights c̄), after an update the posterior's.
//!
//! A mode whose mixing weights are μⱼ|ⱼ = 1 exactly (nothing flows in from another mode, as
//! with Π = I) keeps its own estimate untouched; so with Π = I the IMM is the static
//! multiple-model bank (model selection by likelihood), and one mode is that filter bit for
//! bit. Otherwise mixing restarts the mode filter from the mixed Gaussian with
//! [`Estimator::reset`]; a square-root filter refactorises P⁰ⱼ there, which costs it nothing it
//! had: mixing makes a new Gaussian anyway.
//!
//! A mode with zero probability (c̄ⱼ = 0 at a prediction, μⱼ = 0 at an update) is neither
//! predicted nor updated: its weight in every mixture is 0, so its filter keeps its last
//! estimate (stale, and read by [`Imm::mode_estimate`] as such) and cannot fail the step, say
//! by diverging under a model that no longer fits. Once c̄ⱼ > 0 again, the probability flows
//! in from other modes, and mixing restarts the mode from their mixture.
//!
//! The IMM implements the step traits and the contract: [`Predict`] over a set of per-mode
//! models the user names ([`ModeModels`]), [`Update`] with any measurement model every mode
//! accepts, and [`Rollback`] (every mode's snapshot plus μ), so it goes into the fusion driver
//! (a late measurement rolls μ back too), the Monte Carlo runner and the sequence functions;
//! with the `serde` feature it checkpoints and resumes bit for bit.
//!
//! Modes of different state sizes (a constant-velocity mode inside a constant-acceleration
//! state, say) mix and combine in a common state through maps the user gives: see [`embed`]
//! ([`EmbeddedModes`] of [`Embedded`] filters, each with its [`StateMap`]).
//!
//! The IMM is an approximation: it merges the mᵏ mode histories into m Gaussians at each step
//! (the exact posterior is a mixture of mᵏ). The tests (`tests/sampling/imm.rs`) measure that error
//! against the enumeration of every mode sequence.
//!
//! # Failures
//!
//! Every step is atomic: on an error (a mode's step fails, a measurement impossible under
//! every mode, NaN log-likelihoods) every mode filter, μ and the combined estimate are as
//! before the step. A measurement every mode gates is reported as gated and changes nothing;
//! when only some modes gate, those keep their estimate and all modes' likelihoods (computed
//! before the gate) still weigh μ.
//!
//! ```
//! use estim_core::nalgebra::{DMatrix, DVector, Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_filters::imm::Imm;
//! use estim_filters::{Estimator, KalmanFilter, Ukf};
//!
//! // A cart either coasting (little process noise) or manoeuvring (much more).
//! let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
//! let coast = LinearProcess::without_input(f, Matrix2::identity() * 1e-4);
//! let manoeuvre = LinearProcess::without_input(f, Matrix2::identity() * 1e-1);
//! let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
//!
//! let modes = (KalmanFilter::new(prior.clone()), Ukf::new(prior));
//! let pi = DMatrix::from_row_slice(2, 2, &[0.95, 0.05, 0.10, 0.90]);
//! let mut imm = Imm::new(modes, pi, DVector::from_vec(vec![0.5, 0.5]))?;
//! for k in 0..10 {
//!     imm.predict_modes(&(coast.clone(), manoeuvre.clone()), &(), 1.0)?;
//!     let z = if k < 5 { 0.0 } else { (k as f64 - 4.0).powi(2) }; // then it accelerates
//!     imm.update_modes(&sensor, &Vector1::new(z))?;
//! }
//! assert!(imm.probabilities()[1] > 0.9); // the manoeuvring mode explains the data
//! assert!(imm.covariance()[(0, 0)] > 0.0);
//! # Ok::<(), estim_core::Error>(())
//! ```

#[cfg(feature = "serde")]
mod checkpoint;
pub mod embed;
mod gaussian_sum;
mod gpb2;
mod mixture;
pub mod modes;
pub mod smoother;

use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Error, Gaussian, Quantity, Real, Stage, error::Result};

pub use embed::{Embedded, EmbeddedModes, LiftedMeasurement, StateMap};
pub use gaussian_sum::GaussianSum;
pub use gpb2::{Gpb2, Gpb2Snapshot};
pub use modes::{ModeModels, Modes, PredictModes, UpdateModes};
pub use smoother::{ImmSmoother, PredictCrossModes, Prediction, SmoothedModes};

use crate::report::UpdateReport;
use crate::snapshot::copy_matrix;
use crate::traits::{Estimator, Predict, ProcessInput, Rollback, Update};
use mixture::mixture_into;

/// The interacting multiple model estimator over the mode filters `F` (see the [module
/// docs](self)).
#[derive(Clone, Debug)]
pub struct Imm<T: Real, N: Dim, F: Modes<T, N>>
where
    DefaultAllocator: Alloc<N>,
{
    modes: F,
    transition: DMatrix<T>,
    mixing: Mixing,
    probabilities: DVector<T>,
    /// μ₀ as given to `new`, kept only to be written in a checkpoint.
    #[cfg(feature = "serde")]
    initial: DVector<T>,
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
    work: Work<T, N, F::Snapshot>,
}

/// Where each mode restarts from at a prediction.
///
/// ```text
/// Interacting (IMM):  mode j from Σᵢ μᵢ|ⱼ N(x̂ᵢ, Pᵢ),  μᵢ|ⱼ = πᵢⱼ μᵢ / c̄ⱼ   (m mixtures)
/// Gpb1:               mode j from Σᵢ μᵢ N(x̂ᵢ, Pᵢ) = N(x̂, P), the combined estimate (one)
/// ```
///
/// GPB1 (the first-order generalised pseudo-Bayesian estimator, Bar-Shalom, Li &
/// Kirubarajan §11.6.4) forgets which mode each hypothesis came from at every step; the IMM
/// keeps that per destination mode at the same cost in filter steps. They coincide when
/// every row of Π is the same (the next mode independent of the current one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Mixing {
    /// The interacting multiple model mixing (the default).
    #[default]
    Interacting,
    /// Every mode restarts from the combined estimate (GPB1).
    Gpb1,
}

/// A mean and covariance.
type Moments<T, N> = (OVector<T, N>, OMatrix<T, N, N>);

/// Buffers of a step, sized at construction (m mixed Gaussians, m probabilities and the undo
/// snapshot): they hold nothing between steps.
#[derive(Clone, Debug)]
struct Work<T: Real, N: Dim, S>
where
    DefaultAllocator: Alloc<N>,
{
    predicted: DVector<T>,
    log_weights: DVector<T>,
    mixed: Vec<Moments<T, N>>,
    mixing: Vec<bool>,
    spread: OVector<T, N>,
    undo: S,
}

/// What an [`Imm`] step changes: every mode filter's snapshot, μ and the combined estimate.
/// Read-only: take it with [`Rollback::snapshot`], give it to [`Rollback::restore`] (which
/// trusts it, so it cannot be edited into a μ of another length).
///
/// ```
/// use estim_core::nalgebra::{DMatrix, DVector, Matrix2, Vector2};
/// use estim_core::Gaussian;
/// use estim_filters::imm::Imm;
/// use estim_filters::{KalmanFilter, Rollback};
///
/// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
/// let modes = vec![KalmanFilter::new(prior.clone()), KalmanFilter::new(prior)];
/// let imm = Imm::new(modes, DMatrix::identity(2, 2), DVector::from_vec(vec![0.25, 0.75]))?;
/// let saved = imm.snapshot();
/// assert_eq!(saved.probabilities(), imm.probabilities());
/// assert_eq!(saved.modes().len(), 2);
/// assert_eq!(saved.state(), &Vector2::zeros());
/// assert_eq!(saved.covariance(), &Matrix2::identity());
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ImmSnapshot<T: Real, N: Dim, S>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) modes: S,
    pub(crate) probabilities: DVector<T>,
    pub(crate) state: OVector<T, N>,
    pub(crate) covariance: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim, S> ImmSnapshot<T, N, S>
where
    DefaultAllocator: Alloc<N>,
{
    /// The mode filters' snapshot.
    pub fn modes(&self) -> &S {
        &self.modes
    }

    /// The mode probabilities μ saved.
    pub fn probabilities(&self) -> &DVector<T> {
        &self.probabilities
    }

    /// The combined mean x̂ = Σⱼ μⱼ x̂ⱼ saved.
    pub fn state(&self) -> &OVector<T, N> {
        &self.state
    }

    /// The combined covariance P = Σⱼ μⱼ (Pⱼ + (x̂ⱼ − x̂)(x̂ⱼ − x̂)ᵀ) saved.
    pub fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.covariance
    }
}

impl<T: Real, N: Dim, F: Modes<T, N>> Imm<T, N, F>
where
    DefaultAllocator: Alloc<N>,
{
    /// An IMM over `modes` with the Markov transition matrix `transition` (Π, m × m,
    /// πᵢⱼ = P(mode j next | mode i now)) and the initial mode probabilities `probabilities`
    /// (μ₀, m entries). The combined estimate starts as the mixture of the modes' estimates.
    ///
    /// Errors: Π or μ₀ of the wrong size ([`Error::DimensionMismatch`], quantity
    /// [`TransitionMatrix`](Quantity::TransitionMatrix) or
    /// [`ModeProbabilities`](Quantity::ModeProbabilities)), not finite ([`Error::NonFinite`]),
    /// an entry outside [0, 1] or a row (μ₀) not summing to 1 within 64 m ulps
    /// ([`Error::InvalidParameter`] with
    /// [`TransitionProbability`](estim_core::Parameter::TransitionProbability) or
    /// [`ModeProbability`](estim_core::Parameter::ModeProbability)); no mode, or modes of
    /// different state sizes ([`Error::DimensionMismatch`], quantity
    /// [`Mean`](Quantity::Mean)).
    ///
    /// ```
    /// use estim_core::nalgebra::{DMatrix, DVector, Matrix2, Vector2};
    /// use estim_core::{Error, Gaussian, Parameter};
    /// use estim_filters::imm::Imm;
    /// use estim_filters::{Ekf, Estimator};
    ///
    /// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
    /// let modes = vec![Ekf::new(prior.clone()), Ekf::new(prior.clone()), Ekf::new(prior)];
    /// let uniform = DVector::from_element(3, 1.0 / 3.0);
    /// let not_stochastic = DMatrix::from_element(3, 3, 0.5);
    /// assert!(matches!(
    ///     Imm::new(modes.clone(), not_stochastic, uniform.clone()),
    ///     Err(Error::InvalidParameter { parameter: Parameter::TransitionProbability, .. })
    /// ));
    /// let imm = Imm::new(modes, DMatrix::identity(3, 3), uniform)?;
    /// assert_eq!(imm.state(), &Vector2::zeros());
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn new(modes: F, transition: DMatrix<T>, probabilities: DVector<T>) -> Result<Self> {
        let m = modes.count();
        if m == 0 {
            return Err(Error::DimensionMismatch {
                stage: Stage::Construction,
                quantity: Quantity::ModeProbabilities,
                expected_rows: 1,
                expected_cols: 1,
                found_rows: 0,
                found_cols: 1,
            });
        }
        let (rows, cols) = modes.mode(0).state().shape_generic();
        if let Some(bad) = (0..m).find(|&i| modes.mode(i).state().nrows() != rows.value()) {
            return Err(Error::DimensionMismatch {
                stage: Stage::Construction,
                quantity: Quantity::Mean,
                expected_rows: rows.value(),
                expected_cols: 1,
                found_rows: modes.mode(bad).state().nrows(),
                found_cols: 1,
            });
        }
        mixture::check_transition(&transition, m, Stage::Construction)?;
        mixture::check_probabilities(&probabilities, m)?;
        let zeros = OVector::zeros_generic(rows, cols);
        let mut imm = Self {
            work: Work {
                predicted: probabilities.clone(),
                log_weights: probabilities.clone(),
                mixed: (0..m)
                    .map(|_| (zeros.clone(), OMatrix::zeros_generic(rows, rows)))
                    .collect(),
                mixing: vec![false; m],
                spread: zeros.clone(),
                undo: modes.snapshot(),
            },
            state: zeros,
            covariance: OMatrix::zeros_generic(rows, rows),
            #[cfg(feature = "serde")]
            initial: probabilities.clone(),
            probabilities,
            transition,
            mixing: Mixing::Interacting,
            modes,
        };
        imm.combine();
        Ok(imm)
    }

    /// The static multiple-model bank: Π = I, so no mode ever switches, nothing is mixed and
    /// each mode filter runs exactly as it would alone; μ is then the posterior probability
    /// of each model given the data (Magill 1965), model selection by likelihood.
    ///
    /// ```
    /// use estim_core::nalgebra::{DVector, Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
    /// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
    /// use estim_filters::imm::Imm;
    /// use estim_filters::KalmanFilter;
    ///
    /// // Is the cart moving (constant velocity) or parked (the velocity held at 0)?
    /// let moving = LinearProcess::without_input(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity() * 1e-4);
    /// let parked = LinearProcess::without_input(Matrix2::new(1.0, 0.0, 0.0, 0.0), Matrix2::identity() * 1e-4);
    /// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) };
    /// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
    /// let modes = (KalmanFilter::new(prior.clone()), KalmanFilter::new(prior));
    /// let mut bank = Imm::static_bank(modes, DVector::from_element(2, 0.5))?;
    /// for k in 1..=10 {
    ///     bank.predict_modes(&(moving.clone(), parked.clone()), &(), 1.0)?;
    ///     bank.update_modes(&sensor, &Vector1::new(0.5 * k as f64))?;
    /// }
    /// assert!(bank.probabilities()[0] > 0.999);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn static_bank(modes: F, probabilities: DVector<T>) -> Result<Self> {
        let m = modes.count();
        Self::new(modes, DMatrix::identity(m, m), probabilities)
    }

    /// The same estimator with the mixing `mixing` ([`Mixing::Gpb1`] for GPB1).
    ///
    /// ```
    /// use estim_core::nalgebra::{DMatrix, DVector, Matrix2, Vector2};
    /// use estim_core::Gaussian;
    /// use estim_filters::imm::{Imm, Mixing};
    /// use estim_filters::KalmanFilter;
    ///
    /// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
    /// let modes = (KalmanFilter::new(prior.clone()), KalmanFilter::new(prior));
    /// let pi = DMatrix::from_row_slice(2, 2, &[0.9, 0.1, 0.1, 0.9]);
    /// let gpb1 = Imm::new(modes, pi, DVector::from_element(2, 0.5))?.with_mixing(Mixing::Gpb1);
    /// assert_eq!(gpb1.mixing(), Mixing::Gpb1);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn with_mixing(mut self, mixing: Mixing) -> Self {
        self.mixing = mixing;
        self
    }

    /// The mixing.
    pub fn mixing(&self) -> Mixing {
        self.mixing
    }

    /// The mode filters.
    pub fn modes(&self) -> &F {
        &self.modes
    }

    /// The mode filters, given back.
    pub fn into_modes(self) -> F {
        self.modes
    }

    /// The mode probabilities μ (after a prediction the predicted ones, c̄ = Πᵀ μ; after an
    /// update the posterior ones).
    pub fn probabilities(&self) -> &DVector<T> {
        &self.probabilities
    }

    /// The Markov transition matrix Π.
    pub fn transition(&self) -> &DMatrix<T> {
        &self.transition
    }

    /// Replaces Π (for a step of another length, say); checked as in [`new`](Self::new),
    /// unchanged on an error.
    pub fn set_transition(&mut self, transition: DMatrix<T>) -> Result<()> {
        mixture::check_transition(&transition, self.modes.count(), Stage::Construction)?;
        self.transition = transition;
        Ok(())
    }

    /// Mode `i`'s estimate, as its filter holds it.
    ///
    /// # Panics
    /// If `i` is not a mode.
    #[track_caller]
    pub fn mode_estimate(&self, i: usize) -> Gaussian<T, N> {
        self.modes.mode(i).estimate()
    }

    /// The combined estimate from the modes and μ.
    fn combine(&mut self) {
        let Self {
            modes,
            probabilities,
            state,
            covariance,
            work,
            ..
        } = self;
        let modes = &*modes;
        let components = (0..modes.count()).map(|j| {
            let mode = modes.mode(j);
            (probabilities[j], mode.state(), mode.covariance())
        });
        mixture_into(components, state, covariance, &mut work.spread);
    }

    /// The mixed starting Gaussian of every mode into `work.mixed`, with `work.mixing[j]`
    /// false for a mode with nothing to mix (μⱼ|ⱼ = 1 exactly, or c̄ⱼ = 0), and c̄ in
    /// `work.predicted`.
    fn mix(&mut self) {
        let Self {
            modes,
            transition: pi,
            mixing,
            probabilities: mu,
            state,
            covariance,
            work,
            ..
        } = self;
        mixture::predict_probabilities(pi, mu, &mut work.predicted);
        let modes = &*modes;
        let m = modes.count();
        for j in 0..m {
            let c = work.predicted[j];
            if *mixing == Mixing::Gpb1 {
                // The combined estimate is that mode's own when μⱼ = 1 (copied bit for bit).
                work.mixing[j] = mu[j] != T::one();
                let (x, p) = &mut work.mixed[j];
                x.copy_from(state);
                p.copy_from(covariance);
                continue;
            }
            let own = (0..m).all(|i| i == j || pi[(i, j)] * mu[i] == T::zero());
            work.mixing[j] = c > T::zero() && !own;
            if !work.mixing[j] {
                continue;
            }
            let components = (0..m).map(|i| {
                let mode = modes.mode(i);
                (pi[(i, j)] * mu[i] / c, mode.state(), mode.covariance())
            });
            let (x, p) = &mut work.mixed[j];
            mixture_into(components, x, p, &mut work.spread);
        }
    }

    /// One IMM prediction (see the [module docs](self)): mixing, then mode j predicts through
    /// its model in `models` (the tuple `(P0, P1, …)` for a tuple of modes, a slice for a
    /// `Vec`), then μ ← c̄ = Πᵀ μ (divided by its sum, which rounding in Π may move off 1 by
    /// a few ulps) and the combined estimate is the predicted mixture's. On an
    /// error (any mode's prediction, or fewer models than modes in a `Vec` mode set:
    /// [`Error::DimensionMismatch`], quantity [`ModeProbabilities`](Quantity::ModeProbabilities))
    /// every mode, μ and the estimate are as before.
    pub fn predict_modes<P: ?Sized>(&mut self, models: &P, input: &F::Input, dt: T) -> Result<()>
    where
        F: PredictModes<T, N, P>,
    {
        self.mix();
        self.modes.snapshot_into(&mut self.work.undo);
        for j in 0..self.modes.count() {
            if self.work.predicted[j] == T::zero() {
                continue; // No weight: left as it is (re-seeded by mixing once c̄ⱼ > 0).
            }
            if self.work.mixing[j] {
                let (x, p) = &self.work.mixed[j];
                let mixed = Gaussian::new_unchecked(x.clone(), p.clone());
                self.modes.reset_mode(j, mixed);
            }
            if let Err(e) = self.modes.predict_mode(j, models, input, dt) {
                self.modes.restore(&self.work.undo);
                return Err(e);
            }
        }
        // c̄ / Σ c̄: Π's rows sum to 1 only within the rounding `new` accepts, so without this
        // Σ μ would drift from 1 over predictions without an update (and a checkpoint of the
        // IMM would no longer read back). Σ c̄ > 0: μ sums to 1 and Π is row-stochastic.
        let total = self.work.predicted.sum();
        self.probabilities.copy_from(&self.work.predicted);
        self.probabilities /= total;
        self.combine();
        Ok(())
    }

    /// [`update_modes_into`](Self::update_modes_into) with a new report.
    pub fn update_modes<M: Dim, H: ?Sized>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
    ) -> Result<UpdateReport<T, M>>
    where
        F: UpdateModes<T, N, M, H>,
        DefaultAllocator: Alloc<N, M>,
    {
        let mut report = UpdateReport::zeros(z.shape_generic().0);
        self.update_modes_into(model, z, &mut report)?;
        Ok(report)
    }

    /// One IMM update: every mode with μⱼ > 0 updates with `model` and `z`, μ by Bayes' rule on their
    /// log-likelihoods, then the combined estimate is the posterior mixture's.
    ///
    /// The report is the mixture's: ν̄ = Σ c̄ⱼ νⱼ (= z − ẑ for ẑ the mixture's predicted
    /// measurement), S̄ = Σ c̄ⱼ (Sⱼ + (νⱼ − ν̄)(νⱼ − ν̄)ᵀ), NIS = ν̄ᵀ S̄⁻¹ ν̄ (of the
    /// moment-matched Gaussian), and the exact log-likelihood of z under the predicted
    /// mixture, ln Σⱼ c̄ⱼ exp(ℓⱼ). `Gated` when every mode gated it (nothing changes then).
    ///
    /// Errors (everything as before): any mode's update error; a NaN log-likelihood (of a
    /// mode with μⱼ > 0: the others are not updated), or z
    /// impossible under every mode with c̄ⱼ > 0 ([`Error::NonFinite`],
    /// [`ModeProbabilities`](Quantity::ModeProbabilities)).
    pub fn update_modes_into<M: Dim, H: ?Sized>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        F: UpdateModes<T, N, M, H>,
        DefaultAllocator: Alloc<N, M>,
    {
        self.modes.snapshot_into(&mut self.work.undo);
        let result = self.update_all(model, z, report);
        if result.is_err() {
            self.modes.restore(&self.work.undo);
        }
        result
    }

    /// The update's work; the caller restores the modes on an error.
    fn update_all<M: Dim, H: ?Sized>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        F: UpdateModes<T, N, M, H>,
        DefaultAllocator: Alloc<N, M>,
    {
        let Self {
            modes,
            probabilities,
            work,
            ..
        } = self;
        let applied = mixture::update_weighted::<T, M>(
            z.shape_generic().0,
            probabilities,
            &mut work.predicted,
            &mut work.log_weights,
            report,
            |j, report| modes.update_mode(j, model, z, report),
        )?;
        if applied {
            core::mem::swap(&mut self.probabilities, &mut self.work.predicted);
            self.combine();
        }
        Ok(())
    }
}

/// The combined estimate; [`reset`](Estimator::reset) restarts every mode from the prior and
/// keeps μ: a reset re-initialises the state (the fusion driver's covariance reset gives it
/// the combined Gaussian with inflated variances), not the belief in the modes. (μ₀ as given
/// at construction is kept in [`Imm`]'s checkpoint; [`Gpb2`] resets the same way.)
impl<T: Real, N: Dim, F: Modes<T, N>> Estimator<T, N> for Imm<T, N, F>
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
        for j in 0..self.modes.count() {
            self.modes.reset_mode(j, prior.clone());
        }
        let (n, _) = prior.mean().shape_generic();
        if self.work.spread.nrows() != n.value() {
            let zeros = OVector::zeros_generic(n, estim_core::nalgebra::U1);
            for (x, p) in &mut self.work.mixed {
                *x = zeros.clone();
                *p = OMatrix::zeros_generic(n, n);
            }
            self.work.spread = zeros.clone();
            self.state = zeros;
            self.covariance = OMatrix::zeros_generic(n, n);
        }
        self.combine();
    }
}

/// Every mode filter's snapshot, μ and the combined estimate: a restore puts back the factor
/// of a square-root mode too, so every later step gives the same bits.
impl<T: Real, N: Dim, F: Modes<T, N>> Rollback for Imm<T, N, F>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = ImmSnapshot<T, N, F::Snapshot>;

    fn snapshot(&self) -> Self::Snapshot {
        ImmSnapshot {
            modes: self.modes.snapshot(),
            probabilities: self.probabilities.clone(),
            state: self.state.clone(),
            covariance: self.covariance.clone(),
        }
    }

    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        self.modes.snapshot_into(&mut snapshot.modes);
        copy_matrix(&mut snapshot.probabilities, &self.probabilities);
        copy_matrix(&mut snapshot.state, &self.state);
        copy_matrix(&mut snapshot.covariance, &self.covariance);
    }

    fn restore(&mut self, snapshot: &Self::Snapshot) {
        self.modes.restore(&snapshot.modes);
        copy_matrix(&mut self.probabilities, &snapshot.probabilities);
        copy_matrix(&mut self.state, &snapshot.state);
        copy_matrix(&mut self.covariance, &snapshot.covariance);
    }
}

/// [`Imm::predict_modes`] with the per-mode models of `model` ([`ModeModels`]).
impl<T, N, F, W> Predict<T, N, W> for Imm<T, N, F>
where
    T: Real,
    N: Dim,
    W: ProcessInput<T, N> + ModeModels + ?Sized,
    F: PredictModes<T, N, W::Models, Input = <W as ProcessInput<T, N>>::Input>,
    DefaultAllocator: Alloc<N>,
{
    fn predict(
        &mut self,
        model: &W,
        input: &<W as ProcessInput<T, N>>::Input,
        dt: T,
    ) -> Result<()> {
        self.predict_modes(model.models(), input, dt)
    }
}

/// [`Imm::update_modes_into`]: every mode updates with `model`.
impl<T, N, M, F, H> Update<T, N, M, H> for Imm<T, N, F>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: ?Sized,
    F: UpdateModes<T, N, M, H>,
    DefaultAllocator: Alloc<N, M>,
{
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.update_modes_into(model, z, report)
    }
}
