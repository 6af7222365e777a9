//! A particle filter whose step traits use each model's own noise.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Gaussian, Real, error::Result};

use super::ParticleFilter;
use super::noise::{MeasurementLikelihood, Own, ProcessSampler};
use crate::report::UpdateReport;
use crate::traits::{Estimator, Predict, Rollback, Update};

/// A [`ParticleFilter`] whose [`Predict`] takes any [`ProcessSampler`] and whose [`Update`]
/// takes any [`MeasurementLikelihood`]: the way non-Gaussian models reach the code written
/// against the step traits (the fusion driver, the batch functions).
///
/// Why a second type: the plain filter's step impls cover every model with Gaussian noise, and
/// an impl for a wrapped model beside them would overlap in Rust's coherence rules (see
/// [`NonGaussian`](super::NonGaussian)); a different filter type does not. Every model used
/// with it implements the opt-in traits (a Gaussian one in a few lines, drawing N(0, Q) or
/// evaluating N(h(x), R)); [`inner`](Self::inner) gives the plain filter for the rest.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::rand::Rng;
/// use estim_core::{Gaussian, MeasurementModel, ProcessModel};
/// use estim_filters::particle::{MeasurementLikelihood, NonGaussianFilter, ParticleFilter, ProcessSampler};
/// use estim_filters::{Estimator, Predict, Update};
///
/// /// A walk with uniform steps on [−1, 1], read by a sensor with uniform error on [−½, ½].
/// struct Walk;
/// impl ProcessModel<f64, U1> for Walk {
///     type Input = ();
///     fn transition(&self, x: &Vector1<f64>, _: &(), _: f64) -> Vector1<f64> { *x }
///     fn process_noise(&self, _: &Vector1<f64>, _: &(), _: f64) -> Matrix1<f64> { Matrix1::new(1.0 / 3.0) }
/// }
/// impl ProcessSampler<f64, U1> for Walk {
///     fn sample_transition<R: Rng + ?Sized>(&self, x: &Vector1<f64>, _: &(), _: f64, rng: &mut R) -> Vector1<f64> {
///         x.add_scalar(rng.random_range(-1.0..1.0))
///     }
/// }
/// struct Ruler;
/// impl MeasurementModel<f64, U1, U1> for Ruler {
///     fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> { *x }
///     fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> { Matrix1::new(1.0 / 12.0) }
/// }
/// impl MeasurementLikelihood<f64, U1, U1> for Ruler {
///     fn log_likelihood(&self, z: &Vector1<f64>, x: &Vector1<f64>) -> f64 {
///         if (z[0] - x[0]).abs() <= 0.5 { 0.0 } else { f64::NEG_INFINITY }
///     }
/// }
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(0.01))?;
/// let mut pf = NonGaussianFilter::new(ParticleFilter::new(prior, 1000, 2)?);
/// pf.predict(&Walk, &(), 1.0)?;
/// pf.update(&Ruler, &Vector1::new(0.9))?;
/// // Nearly uniform on [0.4, 1] (the step's reach from x₀ ≈ 0, within ½ of the reading):
/// // mean ≈ 0.7, and 1000 particles give it to ≈ 0.01.
/// assert!((pf.state()[0] - 0.7).abs() < 0.05);
/// // Every particle with weight lies within ½ of the reading.
/// let cloud = pf.inner();
/// for (x, &lw) in cloud.particles().iter().zip(cloud.log_weights()) {
///     assert!(lw == f64::NEG_INFINITY || (x - 0.9).abs() <= 0.5);
/// }
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct NonGaussianFilter<T: Real, N: Dim>(ParticleFilter<T, N>)
where
    DefaultAllocator: Alloc<N>;

impl<T: Real, N: Dim> NonGaussianFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// `filter`, stepped with the models' own noise.
    pub fn new(filter: ParticleFilter<T, N>) -> Self {
        Self(filter)
    }

    /// The particle filter (its cloud, weights, likelihood, and Gaussian-noise steps).
    pub fn inner(&self) -> &ParticleFilter<T, N> {
        &self.0
    }

    /// The particle filter, mutably.
    pub fn inner_mut(&mut self) -> &mut ParticleFilter<T, N> {
        &mut self.0
    }

    /// The particle filter, unwrapped.
    pub fn into_inner(self) -> ParticleFilter<T, N> {
        self.0
    }
}

impl<T: Real, N: Dim> Estimator<T, N> for NonGaussianFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn state(&self) -> &OVector<T, N> {
        self.0.state()
    }

    fn covariance(&self) -> &OMatrix<T, N, N> {
        self.0.covariance()
    }

    fn reset(&mut self, prior: Gaussian<T, N>) {
        self.0.reset(prior);
    }
}

impl<T: Real, N: Dim> Rollback for NonGaussianFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = <ParticleFilter<T, N> as Rollback>::Snapshot;

    fn snapshot(&self) -> Self::Snapshot {
        self.0.snapshot()
    }

    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        self.0.snapshot_into(snapshot);
    }

    fn restore(&mut self, snapshot: &Self::Snapshot) {
        self.0.restore(snapshot);
    }
}

impl<T: Real, N: Dim, P: ProcessSampler<T, N> + Sync> Predict<T, N, P> for NonGaussianFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
    P::Input: Sync,
{
    /// [`ParticleFilter::predict_with`] drawing from the model's sampler.
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.0.predict_with(&Own(model), input, dt)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementLikelihood<T, N, M> + Sync> Update<T, N, M, H>
    for NonGaussianFilter<T, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// [`ParticleFilter::update_into_with`] weighting by the model's likelihood.
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.0.update_into_with(&Own(model), z, report)
    }
}
