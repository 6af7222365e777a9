//! The Gaussian-sum filter (documented on [`GaussianSum`]).

use estim_core::kernel::{self, CholeskyScratch};
use estim_core::nalgebra::{DVector, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Error, Gaussian, Parameter, Quantity, Real, Stage, error::Result};

use super::mixture::{self, mixture_into};
use crate::report::UpdateReport;
use crate::traits::{Estimator, Predict, ProcessInput, Rollback, Update};

/// A `DVector` of `values` (here, not in the impls, whose `DefaultAllocator` bounds hide
/// nalgebra's constructors for `Dyn`).
fn vector<T: Real>(values: Vec<T>) -> DVector<T> {
    DVector::from_vec(values)
}

/// A Gaussian-sum filter over components of the filter type `F`.
///
/// The Gaussian-sum filter (Sorenson & Alspach 1971; Alspach & Sorenson 1972): a weighted
/// sum of Gaussians, each carried by a filter of the family, with the number of components
/// bounded by Runnalls' merging.
///
/// ```text
/// p(x) ≈ Σᵢ wᵢ N(x; x̂ᵢ, Pᵢ)                       (each component a filter)
/// predict:        each component through the model (weights unchanged)
/// mixture noise:  w ~ Σₗ αₗ N(0, Qₗ): component i through model l, weight wᵢ αₗ (K·L of them)
/// update:         each component updates; wᵢ ← wᵢ exp(ℓᵢ) / Σⱼ wⱼ exp(ℓⱼ)   (in logs)
/// reduce:         while more than `max_components`, merge the pair with the least Runnalls
///                 cost B(i, j) = ½ [(wᵢ + wⱼ) ln|Pᵢⱼ| − wᵢ ln|Pᵢ| − wⱼ ln|Pⱼ|], an upper
///                 bound on the Kullback–Leibler discrimination the merge adds (Runnalls 2007),
///                 into its moments: w = wᵢ + wⱼ, x̂ = (wᵢx̂ᵢ + wⱼx̂ⱼ)/w,
///                 Pᵢⱼ = (wᵢPᵢ + wⱼPⱼ)/w + (wᵢwⱼ/w²)(x̂ᵢ − x̂ⱼ)(x̂ᵢ − x̂ⱼ)ᵀ
/// estimate:       the mixture's moments
/// ```
///
/// Without mixture noise and without merging the filter is exact for a linear model with a
/// mixture prior (each component is the Kalman filter of its prior, the weights Bayes'
/// rule); with mixture noise the number of components grows as Lᵏ and merging is the
/// approximation (measured in `tests/sampling/gaussian_sum.rs` against the enumeration).
/// Every step is atomic: on an error every component and weight is as before. It implements
/// the step traits and [`Rollback`] (a clone of every component and weight); with the `serde`
/// feature it checkpoints (its components, weights and bound) and resumes bit for bit.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::imm::GaussianSum;
/// use estim_filters::{Estimator, KalmanFilter};
///
/// // Is the cart at 0 or at 10? A two-component prior, then position measurements.
/// let model = LinearProcess::without_input(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity() * 1e-3);
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
/// let at = |p: f64| KalmanFilter::new(Gaussian::new(Vector2::new(p, 0.0), Matrix2::identity()).unwrap());
/// let mut gsf = GaussianSum::new(vec![(0.5, at(0.0)), (0.5, at(10.0))], 2)?;
/// for z in [9.8, 10.1, 10.0] {
///     gsf.predict(&model, &(), 1.0)?;
///     gsf.update(&sensor, &Vector1::new(z))?;
/// }
/// assert!(gsf.weights()[1] > 0.999);
/// assert!((gsf.state()[0] - 10.0).abs() < 0.5);
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct GaussianSum<T: Real, N: Dim, F>
where
    DefaultAllocator: Alloc<N>,
{
    pub(super) components: Vec<F>,
    pub(super) weights: DVector<T>,
    pub(super) max_components: usize,
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim, F: Estimator<T, N> + Clone> GaussianSum<T, N, F>
where
    DefaultAllocator: Alloc<N>,
{
    /// A Gaussian sum of the weighted `components` (weights in [0, 1] summing to 1, each
    /// component's filter holding its Gaussian), reduced to at most `max_components` after
    /// every step that grows it (and here).
    ///
    /// Errors: no component, or components of different state sizes
    /// ([`Error::DimensionMismatch`]); weights not finite ([`Error::NonFinite`]), outside
    /// [0, 1] or not summing to 1 ([`Error::InvalidParameter`],
    /// [`ModeProbability`](Parameter::ModeProbability)); `max_components = 0`
    /// ([`Error::InvalidParameter`], [`ModeProbability`](Parameter::ModeProbability) with
    /// value 0); a covariance that is not positive definite when merging
    /// ([`Error::NotPositiveDefinite`]).
    pub fn new(components: Vec<(T, F)>, max_components: usize) -> Result<Self> {
        let m = components.len();
        let Some((_, first)) = components.first() else {
            return Err(Error::DimensionMismatch {
                stage: Stage::Construction,
                quantity: Quantity::ModeProbabilities,
                expected_rows: 1,
                expected_cols: 1,
                found_rows: 0,
                found_cols: 1,
            });
        };
        let (rows, cols) = first.state().shape_generic();
        if let Some((_, bad)) = components
            .iter()
            .find(|(_, f)| f.state().nrows() != rows.value())
        {
            return Err(Error::DimensionMismatch {
                stage: Stage::Construction,
                quantity: Quantity::Mean,
                expected_rows: rows.value(),
                expected_cols: 1,
                found_rows: bad.state().nrows(),
                found_cols: 1,
            });
        }
        if max_components == 0 {
            return Err(Error::InvalidParameter {
                parameter: Parameter::ModeProbability,
                value: 0.0,
            });
        }
        let weights = vector(components.iter().map(|(w, _)| *w).collect());
        mixture::check_probabilities(&weights, m)?;
        let mut sum = Self {
            components: components.into_iter().map(|(_, f)| f).collect(),
            weights,
            max_components,
            state: OVector::zeros_generic(rows, cols),
            covariance: OMatrix::zeros_generic(rows, rows),
        };
        sum.reduce()?;
        sum.combine();
        Ok(sum)
    }

    /// The component weights.
    pub fn weights(&self) -> &DVector<T> {
        &self.weights
    }

    /// The component filters.
    pub fn components(&self) -> &[F] {
        &self.components
    }

    /// The bound on the number of components.
    pub fn max_components(&self) -> usize {
        self.max_components
    }

    pub(super) fn combine(&mut self) {
        let mut spread = self.state.clone();
        let parts = (self.weights.iter().zip(&self.components))
            .map(|(&w, f)| (w, f.state(), f.covariance()));
        mixture_into(parts, &mut self.state, &mut self.covariance, &mut spread);
    }

    /// ln |P| by Cholesky.
    fn log_det(p: &OMatrix<T, N, N>, scratch: &mut CholeskyScratch) -> Result<T> {
        let mut factor = p.clone();
        if !kernel::cholesky_in_place(&mut factor, scratch) {
            return Err(Error::NotPositiveDefinite {
                stage: Stage::Prediction,
                quantity: Quantity::Covariance,
            });
        }
        let n = p.nrows();
        let half = (0..n).fold(T::zero(), |acc, i| acc + factor[(i, i)].ln());
        Ok(half + half)
    }

    /// The moments of merging components i and j (module docs).
    fn merged(&self, i: usize, j: usize) -> (T, OVector<T, N>, OMatrix<T, N, N>) {
        let (wi, wj) = (self.weights[i], self.weights[j]);
        let w = wi + wj;
        let (fi, fj) = (&self.components[i], &self.components[j]);
        let (a, b) = (wi / w, wj / w);
        let x = fi.state() * a + fj.state() * b;
        let d = fi.state() - fj.state();
        let p = fi.covariance() * a + fj.covariance() * b + &d * d.transpose() * (a * b);
        (w, x, p)
    }

    /// Merges the cheapest pair (Runnalls' cost) until at most `max_components` remain.
    fn reduce(&mut self) -> Result<()> {
        let mut scratch = CholeskyScratch::default();
        let half = T::one() / (T::one() + T::one());
        while self.components.len() > self.max_components {
            let k = self.components.len();
            let dets: Vec<T> = (self.components.iter())
                .map(|f| Self::log_det(f.covariance(), &mut scratch))
                .collect::<Result<_>>()?;
            let mut best: Option<(T, usize, usize)> = None;
            for i in 0..k {
                for j in i + 1..k {
                    let (w, _, p) = self.merged(i, j);
                    let cost = half
                        * (w * Self::log_det(&p, &mut scratch)?
                            - self.weights[i] * dets[i]
                            - self.weights[j] * dets[j]);
                    if best.is_none_or(|(c, _, _)| cost < c) {
                        best = Some((cost, i, j));
                    }
                }
            }
            let (_, i, j) = best.expect("at least two components");
            let (w, x, p) = self.merged(i, j);
            self.components[i].reset(Gaussian::new_unchecked(x, p));
            self.weights[i] = w;
            self.components.remove(j);
            let kept = (0..k).filter(|&l| l != j).map(|l| self.weights[l]);
            self.weights = vector(kept.collect());
        }
        Ok(())
    }

    /// Every component predicts through `model`; weights unchanged. On an error nothing
    /// changes.
    pub fn predict<P>(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()>
    where
        P: ProcessInput<T, N> + ?Sized,
        F: Predict<T, N, P>,
    {
        let mut next = self.components.clone();
        for f in &mut next {
            f.predict(model, input, dt)?;
        }
        self.components = next;
        self.combine();
        Ok(())
    }

    /// Prediction with mixture process noise Σₗ αₗ N(0, Qₗ), given as the weighted models
    /// `(αₗ, model with Qₗ)` (the αₗ in [0, 1] summing to 1): component i through model l
    /// with weight wᵢ αₗ, then merged down to `max_components`. On an error nothing changes.
    ///
    /// Errors: no model, or weights αₗ as in [`new`](Self::new); a component's prediction
    /// error; a covariance that is not positive definite when merging.
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix2, Vector2};
    /// use estim_core::{Gaussian, LinearProcess};
    /// use estim_filters::imm::GaussianSum;
    /// use estim_filters::KalmanFilter;
    ///
    /// // Heavy-tailed process noise: mostly quiet, sometimes a kick.
    /// let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
    /// let noise = [
    ///     (0.9, LinearProcess::without_input(f, Matrix2::identity() * 1e-3)),
    ///     (0.1, LinearProcess::without_input(f, Matrix2::identity() * 1.0)),
    /// ];
    /// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
    /// let mut gsf = GaussianSum::new(vec![(1.0, KalmanFilter::new(prior))], 3)?;
    /// for _ in 0..4 {
    ///     gsf.predict_mixture(&noise, &(), 1.0)?; // 3 components × 2, merged back to 3
    ///     assert!(gsf.components().len() <= 3);
    /// }
    /// assert!(f64::abs(gsf.weights().sum() - 1.0) < 1e-12);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn predict_mixture<P>(&mut self, models: &[(T, P)], input: &P::Input, dt: T) -> Result<()>
    where
        P: ProcessInput<T, N>,
        F: Predict<T, N, P>,
    {
        let alphas = vector(models.iter().map(|(a, _)| *a).collect());
        if models.is_empty() {
            return Err(Error::DimensionMismatch {
                stage: Stage::Prediction,
                quantity: Quantity::ModeProbabilities,
                expected_rows: 1,
                expected_cols: 1,
                found_rows: 0,
                found_cols: 1,
            });
        }
        mixture::check_probabilities(&alphas, models.len())?;
        let before = (self.components.clone(), self.weights.clone());
        let k = self.components.len();
        let mut components = Vec::with_capacity(k * models.len());
        let mut weights = Vec::with_capacity(k * models.len());
        for (f, &w) in self.components.iter().zip(self.weights.iter()) {
            for (alpha, model) in models {
                if w * *alpha == T::zero() {
                    continue;
                }
                let mut g = f.clone();
                g.predict(model, input, dt)?;
                components.push(g);
                weights.push(w * *alpha);
            }
        }
        let total = weights.iter().fold(T::zero(), |a, &w| a + w);
        self.components = components;
        self.weights = vector(weights.into_iter().map(|w| w / total).collect());
        if let Err(e) = self.reduce() {
            (self.components, self.weights) = before;
            return Err(e);
        }
        self.combine();
        Ok(())
    }

    /// Every component updates with `model` and `z`; the weights by Bayes' rule on their
    /// log-likelihoods; the report is the mixture's (as the IMM's). On an error nothing
    /// changes.
    pub fn update<M: Dim, H: ?Sized>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
    ) -> Result<UpdateReport<T, M>>
    where
        F: Update<T, N, M, H>,
        DefaultAllocator: Alloc<N, M>,
    {
        let mut report = UpdateReport::zeros(z.shape_generic().0);
        let mut updated = self.components.clone();
        let mut weights = self.weights.clone();
        let mut log_likelihoods = self.weights.clone();
        let applied = mixture::update_weighted::<T, M>(
            z.shape_generic().0,
            &self.weights,
            &mut weights,
            &mut log_likelihoods,
            &mut report,
            |i, report| updated[i].update_into(model, z, report),
        )?;
        if applied {
            self.components = updated;
            self.weights = weights;
            self.combine();
        }
        Ok(report)
    }
}

/// The mixture's moments; [`reset`](Estimator::reset) makes it one component at `prior`.
impl<T: Real, N: Dim, F: Estimator<T, N> + Clone> Estimator<T, N> for GaussianSum<T, N, F>
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
        self.components.truncate(1);
        self.components[0].reset(prior.clone());
        self.weights = vector(vec![T::one()]);
        (self.state, self.covariance) = prior.into_parts();
    }
}

/// [`GaussianSum::predict`].
impl<T, N, F, P> Predict<T, N, P> for GaussianSum<T, N, F>
where
    T: Real,
    N: Dim,
    P: ProcessInput<T, N> + ?Sized,
    F: Estimator<T, N> + Clone + Predict<T, N, P>,
    DefaultAllocator: Alloc<N>,
{
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        GaussianSum::predict(self, model, input, dt)
    }
}

/// [`GaussianSum::update`].
impl<T, N, M, F, H> Update<T, N, M, H> for GaussianSum<T, N, F>
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
        *report = GaussianSum::update(self, model, z)?;
        Ok(())
    }
}

/// A clone of the components, weights and combined estimate (their number changes with
/// merging).
impl<T: Real, N: Dim, F: Estimator<T, N> + Clone> Rollback for GaussianSum<T, N, F>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = Self;

    fn snapshot(&self) -> Self {
        self.clone()
    }

    fn restore(&mut self, snapshot: &Self) {
        self.clone_from(snapshot);
    }
}
