//! The second-order generalised pseudo-Bayesian estimator (GPB2; Bar-Shalom, Li &
//! Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, §11.6.5).
//!
//! Where the IMM mixes the m mode estimates into m starting points, GPB2 runs one filter per
//! pair (mode i at k, mode j at k+1): m² filters per cycle, merged back to m Gaussians (one
//! per current mode) only at the next prediction:
//!
//! ```text
//! predict:  gᵢ = merge of the components whose mode is i, μᵢ their total weight
//!           component (i, j): mode j's filter from gᵢ, predicted with model j, weight πᵢⱼ μᵢ
//! update:   every component updates with z; weight × exp(ℓ)  (normalised, in logs)
//! both:     μⱼ = Σ of the weights of the components in mode j; the combined estimate is the
//!           mixture of all components
//! ```
//!
//! Merging lazily (at the prediction, not the update) keeps every two-step mode history
//! until then: after two cycles from a common prior GPB2 holds the exact posterior (all m²
//! histories), which the tests check against the enumeration.
//!
//! The modes are a `Vec<F>` of one filter type (each component is a clone of its mode's
//! filter, restarted with [`Estimator::reset`]); every step is atomic. It implements
//! [`Predict`] (over a [`ModeModels`] whose models are a `Vec`), [`Update`] and [`Rollback`].
//!
//! ```
//! use estim_core::nalgebra::{DMatrix, DVector, Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_filters::imm::Gpb2;
//! use estim_filters::{Estimator, KalmanFilter};
//!
//! let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
//! let models = vec![
//!     LinearProcess::without_input(f, Matrix2::identity() * 1e-4),
//!     LinearProcess::without_input(f, Matrix2::identity() * 1e-1),
//! ];
//! let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.01) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
//! let pi = DMatrix::from_row_slice(2, 2, &[0.95, 0.05, 0.10, 0.90]);
//! let modes = vec![KalmanFilter::new(prior.clone()), KalmanFilter::new(prior)];
//! let mut gpb2 = Gpb2::new(modes, pi, DVector::from_element(2, 0.5))?;
//! for k in 0..10 {
//!     gpb2.predict_modes(&models, &(), 1.0)?;
//!     let z = if k < 5 { 0.0 } else { (k as f64 - 4.0).powi(2) };
//!     gpb2.update_modes(&sensor, &Vector1::new(z))?;
//! }
//! assert!(gpb2.probabilities()[1] > 0.9);
//! # Ok::<(), estim_core::Error>(())
//! ```

use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Error, Gaussian, Quantity, Real, Stage, error::Result};

use super::ModeModels;
use super::mixture::{self, mixture_into};
use crate::report::UpdateReport;
use crate::snapshot::copy_matrix;
use crate::traits::{Estimator, Predict, ProcessInput, Rollback, Update};

/// One hypothesis: its current mode, its filter and its weight.
#[derive(Clone, Debug)]
struct Component<T, F> {
    mode: usize,
    filter: F,
    weight: T,
}

/// The GPB2 estimator over a `Vec` of mode filters (see [`imm`](crate::imm)).
#[derive(Clone, Debug)]
pub struct Gpb2<T: Real, N: Dim, F>
where
    DefaultAllocator: Alloc<N>,
{
    bases: Vec<F>,
    components: Vec<Component<T, F>>,
    transition: DMatrix<T>,
    probabilities: DVector<T>,
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim, F: Estimator<T, N> + Clone> Gpb2<T, N, F>
where
    DefaultAllocator: Alloc<N>,
{
    /// GPB2 over `modes` with the transition matrix Π and initial probabilities μ₀, checked
    /// as by [`Imm::new`](super::Imm::new) (the same errors).
    pub fn new(modes: Vec<F>, transition: DMatrix<T>, probabilities: DVector<T>) -> Result<Self> {
        let m = modes.len();
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
        let (rows, cols) = modes[0].state().shape_generic();
        if let Some(bad) = modes.iter().find(|f| f.state().nrows() != rows.value()) {
            return Err(Error::DimensionMismatch {
                stage: Stage::Construction,
                quantity: Quantity::Mean,
                expected_rows: rows.value(),
                expected_cols: 1,
                found_rows: bad.state().nrows(),
                found_cols: 1,
            });
        }
        mixture::check_transition(&transition, m, Stage::Construction)?;
        mixture::check_probabilities(&probabilities, m)?;
        let components = (modes.iter().enumerate())
            .map(|(j, f)| Component {
                mode: j,
                filter: f.clone(),
                weight: probabilities[j],
            })
            .collect();
        let mut gpb2 = Self {
            bases: modes,
            components,
            transition,
            probabilities,
            state: OVector::zeros_generic(rows, cols),
            covariance: OMatrix::zeros_generic(rows, rows),
        };
        gpb2.combine();
        Ok(gpb2)
    }

    /// The mode probabilities μ.
    pub fn probabilities(&self) -> &DVector<T> {
        &self.probabilities
    }

    /// The number of hypotheses held (m after construction, m² after a prediction).
    pub fn hypotheses(&self) -> usize {
        self.components.len()
    }

    fn combine(&mut self) {
        let mut spread = self.state.clone();
        let components =
            (self.components.iter()).map(|c| (c.weight, c.filter.state(), c.filter.covariance()));
        mixture_into(
            components,
            &mut self.state,
            &mut self.covariance,
            &mut spread,
        );
        self.probabilities.fill(T::zero());
        for c in &self.components {
            self.probabilities[c.mode] += c.weight;
        }
    }

    /// One GPB2 prediction: merge per mode, then m² components (i, j), mode j's filter from
    /// the merged gᵢ predicted with `models[j]`, weight πᵢⱼ μᵢ (divided by their sum, which
    /// rounding in Π may move off 1 by a few ulps). On an error nothing changes.
    ///
    /// Errors: fewer models than modes ([`Error::DimensionMismatch`], quantity
    /// [`ModeProbabilities`](Quantity::ModeProbabilities)); any component's prediction error.
    pub fn predict_modes<P>(&mut self, models: &[P], input: &P::Input, dt: T) -> Result<()>
    where
        P: ProcessInput<T, N>,
        F: Predict<T, N, P>,
    {
        let m = self.bases.len();
        if m > 0 {
            super::modes::model_of(models, m - 1, m)?;
        }
        let pi = &self.transition;
        let mut next = Vec::with_capacity(m * m);
        let mut spread = self.state.clone();
        for i in 0..m {
            let mu = self.probabilities[i];
            if mu == T::zero() {
                continue;
            }
            let mut group = self.components.iter().filter(|c| c.mode == i);
            // One component holding all of mode i: it is gᵢ itself (no refactorisation).
            let single = match (group.next(), group.next()) {
                (Some(c), None) => Some(c),
                _ => None,
            };
            let mut merged = (self.state.clone(), self.covariance.clone());
            if single.is_none() {
                let parts = (self.components.iter())
                    .filter(|c| c.mode == i)
                    .map(|c| (c.weight / mu, c.filter.state(), c.filter.covariance()));
                mixture_into(parts, &mut merged.0, &mut merged.1, &mut spread);
            }
            for j in 0..m {
                let weight = pi[(i, j)] * mu;
                if weight == T::zero() {
                    continue;
                }
                let mut filter = match single {
                    Some(c) if c.mode == j => c.filter.clone(),
                    Some(c) => {
                        let mut f = self.bases[j].clone();
                        f.reset(c.filter.estimate());
                        f
                    }
                    None => {
                        let mut f = self.bases[j].clone();
                        f.reset(Gaussian::new_unchecked(merged.0.clone(), merged.1.clone()));
                        f
                    }
                };
                filter.predict(&models[j], input, dt)?;
                next.push(Component {
                    mode: j,
                    filter,
                    weight,
                });
            }
        }
        // Σ πᵢⱼ μᵢ / its sum: Π's rows sum to 1 only within the rounding `new` accepts, so
        // without this Σ μ would drift from 1 over predictions without an update (as the
        // IMM's). The sum is > 0: μ sums to 1 and Π is row-stochastic.
        let total = next.iter().fold(T::zero(), |acc, c| acc + c.weight);
        for c in &mut next {
            c.weight /= total;
        }
        self.components = next;
        self.combine();
        Ok(())
    }

    /// One GPB2 update of every component with `model` and `z`; the report as
    /// [`Imm::update_modes_into`](super::Imm::update_modes_into) gives it (the mixture's, over
    /// the components). On an error nothing changes.
    pub fn update_modes<M: Dim, H: ?Sized>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
    ) -> Result<UpdateReport<T, M>>
    where
        F: Update<T, N, M, H>,
        DefaultAllocator: Alloc<N, M>,
    {
        let mut report = UpdateReport::zeros(z.shape_generic().0);
        self.update_modes_into(model, z, &mut report)?;
        Ok(report)
    }

    /// [`update_modes`](Self::update_modes) into `report`.
    pub fn update_modes_into<M: Dim, H: ?Sized>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        F: Update<T, N, M, H>,
        DefaultAllocator: Alloc<N, M>,
    {
        let mut updated = self.components.clone();
        let k = updated.len();
        let prior = DVector::from_iterator(k, updated.iter().map(|c| c.weight));
        let mut weights = prior.clone();
        let mut log_likelihoods = prior.clone();
        // A component with no weight left (an underflow at an earlier update) is not
        // updated, as in the IMM, so it cannot fail the step; its weight stays 0.
        let applied = mixture::update_weighted::<T, M>(
            z.shape_generic().0,
            &prior,
            &mut weights,
            &mut log_likelihoods,
            report,
            |i, report| updated[i].filter.update_into(model, z, report),
        )?;
        if applied {
            for (c, w) in updated.iter_mut().zip(weights.iter()) {
                c.weight = *w;
            }
            self.components = updated;
            self.combine();
        }
        Ok(())
    }
}

/// The combined estimate: the mixture of every hypothesis. [`reset`](Estimator::reset)
/// restarts from one component per mode at `prior`, with μ as it is (a re-initialisation of
/// the state, as [`Imm`](super::Imm)'s reset).
impl<T: Real, N: Dim, F: Estimator<T, N> + Clone> Estimator<T, N> for Gpb2<T, N, F>
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
        self.components = (self.bases.iter().enumerate())
            .map(|(j, f)| {
                let mut filter = f.clone();
                filter.reset(prior.clone());
                Component {
                    mode: j,
                    filter,
                    weight: self.probabilities[j],
                }
            })
            .collect();
        self.state = prior.mean().clone();
        self.covariance = prior.covariance().clone();
        self.combine();
    }
}

/// What a [`Gpb2`] step changes: every hypothesis (its filter, mode and weight), μ and the
/// combined estimate. Opaque: take it with [`Rollback::snapshot`], give it to
/// [`Rollback::restore`].
#[derive(Clone, Debug)]
pub struct Gpb2Snapshot<T: Real, N: Dim, F>
where
    DefaultAllocator: Alloc<N>,
{
    components: Vec<Component<T, F>>,
    probabilities: DVector<T>,
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
}

/// The hypotheses are cloned whole (their number changes between m and m²).
impl<T: Real, N: Dim, F: Estimator<T, N> + Clone> Rollback for Gpb2<T, N, F>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = Gpb2Snapshot<T, N, F>;

    fn snapshot(&self) -> Self::Snapshot {
        Gpb2Snapshot {
            components: self.components.clone(),
            probabilities: self.probabilities.clone(),
            state: self.state.clone(),
            covariance: self.covariance.clone(),
        }
    }

    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        snapshot.components.clone_from(&self.components);
        copy_matrix(&mut snapshot.probabilities, &self.probabilities);
        copy_matrix(&mut snapshot.state, &self.state);
        copy_matrix(&mut snapshot.covariance, &self.covariance);
    }

    fn restore(&mut self, snapshot: &Self::Snapshot) {
        self.components.clone_from(&snapshot.components);
        copy_matrix(&mut self.probabilities, &snapshot.probabilities);
        copy_matrix(&mut self.state, &snapshot.state);
        copy_matrix(&mut self.covariance, &snapshot.covariance);
    }
}

/// [`Gpb2::predict_modes`] with the per-mode models of `model` (a `Vec`, [`ModeModels`]).
impl<T, N, F, W, P> Predict<T, N, W> for Gpb2<T, N, F>
where
    T: Real,
    N: Dim,
    P: ProcessInput<T, N>,
    W: ModeModels<Models = Vec<P>> + ProcessInput<T, N, Input = P::Input> + ?Sized,
    F: Estimator<T, N> + Clone + Predict<T, N, P>,
    DefaultAllocator: Alloc<N>,
{
    fn predict(&mut self, model: &W, input: &P::Input, dt: T) -> Result<()> {
        self.predict_modes(model.models(), input, dt)
    }
}

/// [`Gpb2::update_modes_into`].
impl<T, N, M, F, H> Update<T, N, M, H> for Gpb2<T, N, F>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: ?Sized,
    F: Estimator<T, N> + Clone + Update<T, N, M, H>,
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
