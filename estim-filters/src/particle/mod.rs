//! Particle filters (sequential Monte Carlo) over the models the Kalman filters use.
//!
//! A [`ParticleFilter`] represents p(xₖ | z₁..ₖ) by particles xᵢ with normalised log-weights
//! log Wᵢ (Σ Wᵢ = 1), stored as one n × N matrix (a column per particle). Changing filter is
//! changing the constructor: any [`ProcessModel`](estim_core::ProcessModel) /
//! [`MeasurementModel`](estim_core::MeasurementModel) runs with Gaussian noise, and a model
//! wrapped in [`NonGaussian`] uses its own [`ProcessSampler`] / [`MeasurementLikelihood`]
//! ([`NonGaussianFilter`] takes such models through the step traits, for the fusion driver and
//! the batch functions).
//!
//! **Bootstrap (SIR) step** (Gordon, Salmond & Smith 1993; Chopin & Papaspiliopoulos 2020,
//! ch. 10), with resampling before each propagation:
//!
//! ```text
//! predict:  if ESS = 1/Σ Wᵢ² < τN: aᵢ ~ resample(W), log Wᵢ = −log N;  else aᵢ = i
//!           xᵢ ← f(x_aᵢ, u, Δt) + L ε,  L Lᵀ = Q(x_aᵢ, u, Δt),  ε ~ N(0, I)
//! update:   log gᵢ = log N(z ⊖ h(xᵢ); 0, R(xᵢ))
//!           Δℓ = log Σ Wᵢ gᵢ      (log-sum-exp; the step's likelihood estimate)
//!           log Wᵢ ← log Wᵢ + log gᵢ − Δℓ
//! ```
//!
//! Δℓ uses the weights the filter holds (normalised, whatever resampling did), so
//! exp(Σ Δℓ) is an unbiased estimate of p(z₁..ₖ) under adaptive resampling too (Del Moral
//! 2004; the running total is [`ParticleFilter::log_likelihood`]). [`state`](Estimator::state)
//! and [`covariance`](Estimator::covariance) are the weighted moments Σ Wᵢ xᵢ and
//! Σ Wᵢ (xᵢ − x̂)(xᵢ − x̂)ᵀ.
//!
//! The auxiliary particle filter ([`ParticleFilter::auxiliary_step`], Pitt & Shephard 1999)
//! is a combined predict-and-update step on the same cloud:
//!
//! ```text
//! first stage:   log ηᵢ = log p(z | μᵢ), μᵢ = f(xᵢ, u, Δt);  log λᵢ = log Wᵢ + log ηᵢ;  L₁ = log Σ λᵢ
//! resample:      aⱼ ~ λ (always)
//! propagate:     xⱼ ~ p(· | x_aⱼ, u, Δt)
//! second stage:  log wⱼ = log p(z | xⱼ) − log η_aⱼ;  L₂ = log Σ wⱼ
//! likelihood:    Δℓ = L₁ + L₂ − log N        (exp Δℓ unbiased for p(z | z₁..ₖ₋₁))
//! ```
//!
//! With η from R alone, narrower than the true predictive N(h(μ), R + H Q Hᵀ), the weights
//! g/η are heavy-tailed when the sensor is sharp relative to Q: the estimate stays unbiased but
//! its variance grows (seen in the tests at R = Q/5); the bootstrap filter is then the safer
//! choice.
//!
//! Beyond the filter: a user's guided proposal q(x⁺ | x, z) ([`Proposal`],
//! [`ParticleFilter::guided_step`]); the transition log-density those and the smoother need
//! ([`log_transition_density`], with the opt-in [`TransitionDensity`]; a singular Q has none, a
//! typed error); the FFBSi particle smoother ([`Ffbsi`]); the Rao-Blackwellised filter for
//! conditionally linear-Gaussian models ([`RaoBlackwellised`]); Bayesian parameter learning by
//! particle marginal Metropolis-Hastings ([`pmmh`] with [`particle_log_likelihood`]).
//!
//! **Randomness.** All draws come from counter-based streams named by (seed, step, particle)
//! ([`ParticleRng`]): the random state is one step counter, part of every snapshot and
//! checkpoint, and per-particle work does not depend on the visiting order.
//!
//! **Parallel and reproducible.** The per-particle loops run over fixed chunks of particles,
//! each with its own scratch and partial sums (log-sum-exp, moments), combined in chunk
//! order. With the `parallel` feature the chunks of a filter with at least [`PARALLEL_MIN`]
//! particles run on rayon's current pool (install a pool to choose the threads); serial or on
//! any number of threads, a seed gives the same bits. The models and inputs are therefore
//! `Sync` (the bound holds with and without the feature, so code compiles either way). After
//! the first step (which sizes the runtime-size buffers and factorises Q and R), steps with a
//! fixed particle count allocate nothing, for static and runtime (`Dyn`) sizes alike, as
//! long as the model's `_into` methods do not allocate. (The Rao-Blackwellised filter
//! allocates nothing at static sizes; at runtime sizes its per-particle Kalman steps allocate
//! the matrices the conditionally linear model returns.)
//!
//! ```
//! use estim_core::nalgebra::{Matrix1, Vector1};
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_filters::particle::ParticleFilter;
//! use estim_filters::{Estimator, KalmanFilter, Predict, Update};
//!
//! let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
//! let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
//! let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
//! let mut pf = ParticleFilter::new(prior.clone(), 4000, 42)?;
//! let mut kf = KalmanFilter::new(prior);
//! for z in [0.4, -0.3, 1.1] {
//!     pf.predict(&process, &(), 1.0)?;
//!     kf.predict(&process, &(), 1.0)?;
//!     pf.update(&sensor, &Vector1::new(z))?;
//!     kf.update(&sensor, &Vector1::new(z))?;
//! }
//! // The posterior standard deviation is about 0.6; 4000 particles give the mean to ~0.01.
//! assert!((pf.state()[0] - kf.state()[0]).abs() < 0.06);
//! # Ok::<(), estim_core::Error>(())
//! ```

mod auxiliary;
#[cfg(feature = "serde")]
mod checkpoint;
mod chunks;
mod ffbsi;
#[cfg(feature = "serde")]
mod ffbsi_checkpoint;
mod guided;
mod noise;
mod own_noise;
mod pmmh;
mod rbpf;
#[cfg(feature = "serde")]
mod rbpf_checkpoint;
mod rbpf_contract;
mod resample;
mod rng;
mod step;
mod transition;

use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::rand_distr::{Distribution, StandardNormal};
use estim_core::{Alloc, Error, Gaussian, Parameter, Real, error::Result, psd_factor};

pub use chunks::PARALLEL_MIN;
pub use ffbsi::{Ffbsi, SmoothedPaths};
pub use guided::Proposal;
pub use noise::{
    AdditiveGaussian, MeasurementLikelihood, NonGaussian, ParticleMeasurement, ParticleProcess,
    ProcessSampler,
};
pub use own_noise::NonGaussianFilter;
pub use pmmh::{MAX_PMMH_ITERATIONS, PmmhChain, PmmhError, particle_log_likelihood, pmmh};
pub use rbpf::{
    ConditionalMeasurement, ConditionalTransition, ConditionallyLinearMeasurement,
    ConditionallyLinearProcess, RaoBlackwellised, RaoBlackwellisedSnapshot,
};
pub use resample::{ResampleWhen, Resampling, log_sum_exp, resample};
pub use rng::{ParticleRng, RESAMPLE};
pub use transition::{ParticleTransition, TransitionDensity, log_transition_density};

use crate::traits::{Estimator, Rollback};
use resample::{ess_of_weights, to_f64};
use step::Work;

/// A particle filter: bootstrap (SIR) steps through [`Predict`](crate::Predict) and
/// [`Update`](crate::Update), auxiliary steps through
/// [`auxiliary_step`](Self::auxiliary_step). See the [module documentation](self).
#[derive(Clone, Debug)]
pub struct ParticleFilter<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    seed: u64,
    scheme: Resampling,
    when: ResampleWhen,
    cloud: ParticleSnapshot<T, N>,
    work: Work<T, N>,
}

/// Everything a particle filter's steps change: the particles, their log-weights, the random
/// step counter, the weighted moments and the running log-likelihood. Restoring one gives the
/// same bits afterwards as at the time it was taken.
#[derive(Clone, Debug, PartialEq)]
pub struct ParticleSnapshot<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) particles: OMatrix<T, N, Dyn>,
    pub(crate) log_weights: Vec<T>,
    /// Wᵢ in f64, for the ESS, resampling and the moments: exp(log Wᵢ) to a few ulps (an
    /// update derives them from its log-sum-exp terms, one `exp` per particle; see
    /// `Work::normalise`), so checkpoints store them.
    pub(crate) weights: Vec<f64>,
    pub(crate) step: u64,
    pub(crate) mean: OVector<T, N>,
    pub(crate) covariance: OMatrix<T, N, N>,
    pub(crate) log_likelihood: T,
}

impl<T: Real, N: Dim> ParticleSnapshot<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// Copies `other` into `self`, reusing the buffers when the shapes agree.
    fn copy_from(&mut self, other: &Self) {
        if self.particles.shape() == other.particles.shape() {
            self.particles.copy_from(&other.particles);
        } else {
            self.particles = other.particles.clone();
        }
        self.log_weights.clone_from(&other.log_weights);
        self.weights.clone_from(&other.weights);
        self.step = other.step;
        if self.mean.shape() == other.mean.shape() {
            self.mean.copy_from(&other.mean);
            self.covariance.copy_from(&other.covariance);
        } else {
            self.mean = other.mean.clone();
            self.covariance = other.covariance.clone();
        }
        self.log_likelihood = other.log_likelihood;
    }

    /// Wᵢ = exp(log Wᵢ) from the log-weights (for a checkpoint written without weights).
    #[cfg(any(feature = "serde", test))]
    pub(crate) fn refresh_weights(&mut self) {
        self.weights.clear();
        self.weights
            .extend(self.log_weights.iter().map(|&lw| to_f64(lw).exp()));
    }

    /// Equal weights: log Wᵢ = −log N.
    pub(crate) fn set_uniform(&mut self) {
        let uniform = -estim_core::scalar::real::<T>(self.log_weights.len() as f64).ln();
        self.log_weights.fill(uniform);
        self.weights.fill(to_f64(uniform).exp());
    }
}

impl<T: Real, N: Dim> PartialEq for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// Equal configuration and equal state (to the bit, NaN aside); the work buffers are
    /// ignored.
    fn eq(&self, other: &Self) -> bool {
        self.seed == other.seed
            && self.scheme == other.scheme
            && self.when == other.when
            && self.cloud == other.cloud
    }
}

impl<T: Real, N: Dim> ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// `count` particles drawn from `prior` (x = μ + S ε with S Sᵀ = P from
    /// [`psd_factor`], so a singular prior works), equally weighted, with random streams
    /// seeded by `seed`. Systematic resampling when the ESS falls below N/2 (change with
    /// [`with_resampling`](Self::with_resampling) and [`with_trigger`](Self::with_trigger)).
    ///
    /// Errors: `count` = 0, or so large that the particles could not be allocated
    /// ([`Parameter::SampleCount`]); a prior covariance that is not positive semi-definite
    /// (possible only with [`Gaussian::new_unchecked`]).
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix2, Vector2};
    /// use estim_core::Gaussian;
    /// use estim_filters::particle::ParticleFilter;
    /// use estim_filters::Estimator;
    ///
    /// let prior = Gaussian::new(Vector2::new(1.0, -1.0), Matrix2::identity())?;
    /// let pf = ParticleFilter::new(prior.clone(), 2000, 7)?;
    /// assert_eq!(pf.particles().ncols(), 2000);
    /// // The sample mean is within 4 standard errors (1/√2000 = 0.022) of the prior's.
    /// assert!((pf.state() - prior.mean()).abs().max() < 0.09);
    /// assert!(ParticleFilter::new(prior, 0, 7).is_err());
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn new(prior: Gaussian<T, N>, count: usize, seed: u64) -> Result<Self> {
        // The cloud, its resampling buffer and six per-particle vectors.
        check_count::<T>(count, 2 * prior.mean().nrows() + 6)?;
        let factor = psd_factor(prior.covariance(), estim_core::Stage::Construction)?;
        let (n, _) = prior.mean().shape_generic();
        let mut filter = Self {
            seed,
            scheme: Resampling::default(),
            when: ResampleWhen::default(),
            cloud: ParticleSnapshot {
                particles: OMatrix::zeros_generic(n, Dyn(count)),
                log_weights: vec![T::zero(); count],
                weights: vec![0.0; count],
                step: 0,
                mean: prior.mean().clone(),
                covariance: prior.covariance().clone(),
                log_likelihood: T::zero(),
            },
            work: Work::new(n, count),
        };
        filter.draw(&prior, &factor);
        Ok(filter)
    }

    /// The same filter resampling by `scheme`.
    pub fn with_resampling(mut self, scheme: Resampling) -> Self {
        self.scheme = scheme;
        self
    }

    /// The same filter resampling when `when` fires. Errors: an
    /// [`EssBelow`](ResampleWhen::EssBelow) fraction outside (0, 1]
    /// ([`Parameter::Tolerance`]).
    pub fn with_trigger(mut self, when: ResampleWhen) -> Result<Self> {
        check_trigger(when)?;
        self.when = when;
        Ok(self)
    }

    /// The same filter with random streams seeded by `seed` (e.g. one per Monte Carlo run).
    /// The cloud is not redrawn: call [`reset`](Estimator::reset) for that.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// The particles, one per column (n × N).
    pub fn particles(&self) -> &OMatrix<T, N, Dyn> {
        &self.cloud.particles
    }

    /// The normalised log-weights log Wᵢ (log Σ Wᵢ = 0; −∞ for a particle of weight zero).
    pub fn log_weights(&self) -> &[T] {
        &self.cloud.log_weights
    }

    /// The normalised weights Wᵢ = exp(log Wᵢ), written into `out` (resized to N).
    pub fn weights_into(&self, out: &mut Vec<T>) {
        out.clear();
        out.extend(self.cloud.log_weights.iter().map(|&lw| lw.exp()));
    }

    /// The effective sample size 1 / Σ Wᵢ², in [1, N].
    pub fn effective_sample_size(&self) -> T {
        estim_core::scalar::real(ess_of_weights(&self.cloud.weights))
    }

    /// The running log-likelihood estimate log p̂(z₁..ₖ) = Σ Δℓ since construction or the last
    /// [`reset`](Estimator::reset) (its exponential is unbiased for p(z₁..ₖ)).
    pub fn log_likelihood(&self) -> T {
        self.cloud.log_likelihood
    }

    /// The number of particles N.
    pub fn count(&self) -> usize {
        self.cloud.log_weights.len()
    }

    /// The seed of the random streams.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The random step counter: the stream names of the next step are (seed, step, ·).
    pub fn step(&self) -> u64 {
        self.cloud.step
    }

    /// The resampling scheme.
    pub fn resampling(&self) -> Resampling {
        self.scheme
    }

    /// When the filter resamples.
    pub fn trigger(&self) -> ResampleWhen {
        self.when
    }

    /// Draws the cloud from `prior` with factor S (S Sᵀ = P) from the streams (seed, 0, i);
    /// equal weights, step 1, likelihood 0.
    fn draw(&mut self, prior: &Gaussian<T, N>, factor: &OMatrix<T, N, N>) {
        let count = self.count();
        let (n, _) = prior.mean().shape_generic();
        let cloud = &mut self.cloud;
        if cloud.particles.nrows() != n.value() {
            cloud.particles = OMatrix::zeros_generic(n, Dyn(count));
        }
        self.work.fit(n, count);
        let mut normals = OVector::zeros_generic(n, U1);
        for i in 0..count {
            let mut rng = ParticleRng::stream(self.seed, 0, i as u64);
            fill_normals(&mut normals, &mut rng);
            let mut column = cloud.particles.column_mut(i);
            column.copy_from(prior.mean());
            column.gemv(T::one(), factor, &normals, T::one());
        }
        cloud.set_uniform();
        cloud.step = 1;
        cloud.log_likelihood = T::zero();
        self.update_moments();
    }

    /// x̂ = Σ Wᵢ xᵢ and P = Σ Wᵢ (xᵢ − x̂)(xᵢ − x̂)ᵀ from the cloud (by chunks, in a fixed
    /// order).
    fn update_moments(&mut self) {
        self.update_moments_about(None);
    }

    /// [`update_moments`](Self::update_moments) with the particle of largest weight (the first
    /// one if tied) already known, if `heaviest` is given.
    fn update_moments_about(&mut self, heaviest: Option<usize>) {
        let cloud = &mut self.cloud;
        let (n, _) = cloud.particles.shape_generic();
        if cloud.mean.nrows() != n.value() {
            cloud.mean = OVector::zeros_generic(n, U1);
            cloud.covariance = OMatrix::zeros_generic(n, n);
        }
        chunks::moments(
            &mut self.work.chunks,
            &cloud.particles,
            &cloud.weights,
            heaviest,
            &mut cloud.mean,
            &mut cloud.covariance,
        );
    }
}

/// Fills `out` with standard normal draws (in f64, then rounded to T, so f32 and f64 filters
/// see the same normal stream).
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn fill_normals<T: Real, N: Dim>(out: &mut OVector<T, N>, rng: &mut ParticleRng)
where
    DefaultAllocator: Alloc<N>,
{
    for v in out.iter_mut() {
        let z: f64 = StandardNormal.sample(rng);
        *v = estim_core::scalar::real(z);
    }
}

/// An [`EssBelow`](ResampleWhen::EssBelow) fraction must be in (0, 1].
fn check_trigger(when: ResampleWhen) -> Result<()> {
    match when {
        ResampleWhen::EssBelow(f) if !(f > 0.0 && f <= 1.0) => Err(Error::InvalidParameter {
            parameter: Parameter::Tolerance,
            value: f,
        }),
        _ => Ok(()),
    }
}

/// The snapshot is the cloud, its log-weights, the random step counter (so a restore replays
/// the same random bits), the weighted moments and the running log-likelihood; not the
/// configuration (seed, scheme, trigger).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::particle::ParticleFilter;
/// use estim_filters::{Predict, Rollback, Update};
///
/// let process = LinearProcess::without_input(Matrix1::new(1.0f64), Matrix1::new(0.1));
/// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.5) };
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let mut pf = ParticleFilter::new(prior, 100, 3)?;
/// let saved = pf.snapshot();
/// pf.predict(&process, &(), 1.0)?;
/// pf.update(&sensor, &Vector1::new(0.4))?;
/// let first = pf.clone();
/// pf.restore(&saved);
/// pf.predict(&process, &(), 1.0)?;
/// pf.update(&sensor, &Vector1::new(0.4))?;
/// assert_eq!(pf, first); // the same bits, resampling and noise included
/// # Ok::<(), estim_core::Error>(())
/// ```
impl<T: Real, N: Dim> Rollback for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = ParticleSnapshot<T, N>;

    fn snapshot(&self) -> ParticleSnapshot<T, N> {
        self.cloud.clone()
    }

    /// Reuses the snapshot's buffers when the shapes agree.
    fn snapshot_into(&self, snapshot: &mut ParticleSnapshot<T, N>) {
        snapshot.copy_from(&self.cloud);
    }

    fn restore(&mut self, snapshot: &ParticleSnapshot<T, N>) {
        self.cloud.copy_from(snapshot);
        let (n, _) = self.cloud.mean.shape_generic();
        self.work.fit(n, self.count());
    }
}

impl<T: Real, N: Dim> Estimator<T, N> for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn state(&self) -> &OVector<T, N> {
        &self.cloud.mean
    }

    fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.cloud.covariance
    }

    /// Draws a fresh cloud from `prior` exactly as [`ParticleFilter::new`] with this filter's
    /// seed and count would (and zeroes the running log-likelihood). A prior covariance that
    /// is not positive semi-definite (only possible with [`Gaussian::new_unchecked`]) puts
    /// every particle at the prior mean.
    fn reset(&mut self, prior: Gaussian<T, N>) {
        let (n, _) = prior.mean().shape_generic();
        let factor = psd_factor(prior.covariance(), estim_core::Stage::Construction)
            .unwrap_or_else(|_| OMatrix::zeros_generic(n, n));
        self.draw(&prior, &factor);
    }
}

/// `Ok` when `count` ≥ 1 items of `per_item` scalars each could be reserved now: a count that
/// cannot even be addressed, or whose memory the allocator refuses, is an error
/// ([`Parameter::SampleCount`]) instead of a "capacity overflow" panic or an allocation abort.
/// (The probe is released at once; what is then allocated is this much or less.)
pub(crate) fn check_count<T>(count: usize, per_item: usize) -> Result<()> {
    let refused = Error::InvalidParameter {
        parameter: Parameter::SampleCount,
        value: count as f64,
    };
    let len = count.checked_mul(per_item.max(1)).filter(|_| count > 0);
    let mut probe: Vec<T> = Vec::new();
    match len {
        Some(len) if probe.try_reserve_exact(len).is_ok() => Ok(()),
        _ => Err(refused),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moments_of_a_weighted_cloud() {
        let prior = Gaussian::new(
            estim_core::nalgebra::Vector1::new(0.0),
            estim_core::nalgebra::Matrix1::new(1.0),
        )
        .unwrap();
        let mut pf = ParticleFilter::new(prior, 2, 0).unwrap();
        pf.cloud.particles[(0, 0)] = 1.0;
        pf.cloud.particles[(0, 1)] = 3.0;
        pf.cloud.log_weights = vec![0.25f64.ln(), 0.75f64.ln()];
        pf.cloud.refresh_weights();
        pf.update_moments();
        // Mean 0.25 + 2.25 = 2.5; variance 0.25·2.25 + 0.75·0.25 = 0.75.
        assert!((pf.state()[0] - 2.5).abs() < 1e-15);
        assert!((pf.covariance()[(0, 0)] - 0.75).abs() < 1e-15);
        assert!((to_f64(pf.effective_sample_size()) - 1.0 / 0.625).abs() < 1e-12);
    }
}
