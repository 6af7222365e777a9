//! Which noise a particle filter uses: Gaussian from the model's Q and R by default, or the
//! model's own sampler and likelihood when wrapped in [`NonGaussian`].
//!
//! Rust has no specialisation, and a blanket impl over every `ProcessModel<T, N>` cannot sit
//! beside an impl for a wrapper type (a downstream crate could implement `ProcessModel<T, N>`
//! for the wrapper with its own scalar `T`, and rustc rejects the pair). So the choice is made
//! by two wrapper types, each implementing the dispatch traits [`ParticleProcess`] /
//! [`ParticleMeasurement`]: [`AdditiveGaussian`] for every model (what the step traits
//! [`Predict`](crate::Predict) and [`Update`](crate::Update) use, so any model written for the
//! Kalman filters runs unchanged) and [`NonGaussian`] for a model with the opt-in capability
//! [`ProcessSampler`] / [`MeasurementLikelihood`] (through
//! [`ParticleFilter::predict_with`](super::ParticleFilter::predict_with) and
//! [`update_with`](super::ParticleFilter::update_with), or through the step traits of
//! [`NonGaussianFilter`](super::NonGaussianFilter), a second filter type for which the step
//! impls over the opt-in traits do not overlap). The opt-in traits extend the model
//! traits, so one model runs in a UKF (with its Gaussian approximation Q, R) and in a particle
//! filter with its true noise; the wrapper at the call site is the only difference.

use estim_core::nalgebra::{DefaultAllocator, Dim, OVector};
use estim_core::rand::Rng;
use estim_core::{Alloc, MeasurementModel, ProcessModel, Real};

use super::rng::ParticleRng;

/// Opt-in: a process whose noise is not additive Gaussian. Draws x⁺ ~ p(x⁺ | x, u, Δt).
///
/// [`transition`](ProcessModel::transition) stays the noise-free prediction f(x, u, Δt) (the
/// auxiliary filter's look-ahead point) and [`process_noise`](ProcessModel::process_noise) its
/// Gaussian approximation for the Kalman filters. Use it in a particle filter as
/// [`NonGaussian(model)`](NonGaussian).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::rand::Rng;
/// use estim_core::rand_distr::{Distribution, StudentT};
/// use estim_core::ProcessModel;
/// use estim_filters::particle::ProcessSampler;
///
/// /// A random walk with Student-t (ν = 3) steps of scale s.
/// struct HeavyWalk { s: f64 }
/// impl ProcessModel<f64, U1> for HeavyWalk {
///     type Input = ();
///     fn transition(&self, x: &Vector1<f64>, _: &(), _: f64) -> Vector1<f64> { *x }
///     fn process_noise(&self, _: &Vector1<f64>, _: &(), _: f64) -> Matrix1<f64> {
///         Matrix1::new(3.0 * self.s * self.s) // the t variance ν/(ν − 2) s²
///     }
/// }
/// impl ProcessSampler<f64, U1> for HeavyWalk {
///     fn sample_transition<R: Rng + ?Sized>(&self, x: &Vector1<f64>, _: &(), _: f64, rng: &mut R) -> Vector1<f64> {
///         x + Vector1::new(self.s * StudentT::new(3.0).unwrap().sample(rng))
///     }
/// }
/// # let _ = HeavyWalk { s: 1.0 };
/// ```
pub trait ProcessSampler<T: Real, N: Dim>: ProcessModel<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// One draw x⁺ ~ p(· | x, u, Δt).
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        x: &OVector<T, N>,
        u: &Self::Input,
        dt: T,
        rng: &mut R,
    ) -> OVector<T, N>;
}

/// Opt-in: a sensor whose noise is not Gaussian. Evaluates log p(z | x).
///
/// [`measure`](MeasurementModel::measure), [`residual_into`](MeasurementModel::residual_into) and
/// [`measurement_noise`](MeasurementModel::measurement_noise) (the noise's covariance) still
/// give the update report's innovation moments and the Kalman filters' approximation. Use it
/// in a particle filter as [`NonGaussian(model)`](NonGaussian).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::MeasurementModel;
/// use estim_filters::particle::MeasurementLikelihood;
///
/// /// z = x + v with v uniform on [−a, a]: a bounded (quantised) sensor.
/// struct Quantised { a: f64 }
/// impl MeasurementModel<f64, U1, U1> for Quantised {
///     fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> { *x }
///     fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> { Matrix1::new(self.a * self.a / 3.0) }
/// }
/// impl MeasurementLikelihood<f64, U1, U1> for Quantised {
///     fn log_likelihood(&self, z: &Vector1<f64>, x: &Vector1<f64>) -> f64 {
///         if (z[0] - x[0]).abs() <= self.a { -(2.0 * self.a).ln() } else { f64::NEG_INFINITY }
///     }
/// }
/// assert_eq!(Quantised { a: 0.5 }.log_likelihood(&Vector1::new(2.0), &Vector1::new(1.0)), f64::NEG_INFINITY);
/// ```
pub trait MeasurementLikelihood<T: Real, N: Dim, M: Dim>: MeasurementModel<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// log p(z | x); −∞ where the reading is impossible from x. Must not be NaN or +∞.
    fn log_likelihood(&self, z: &OVector<T, M>, x: &OVector<T, N>) -> T;
}

/// A model whose own sampler ([`ProcessSampler`]) or likelihood ([`MeasurementLikelihood`]) a
/// particle filter uses instead of the Gaussian noise N(0, Q) or N(h(x), R).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::{Gaussian, LinearProcess, MeasurementModel};
/// use estim_filters::particle::{MeasurementLikelihood, NonGaussian, ParticleFilter};
/// use estim_filters::{Estimator, Predict};
///
/// struct Quantised;
/// impl MeasurementModel<f64, U1, U1> for Quantised {
///     fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> { *x }
///     fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> { Matrix1::new(0.25 / 3.0) }
/// }
/// impl MeasurementLikelihood<f64, U1, U1> for Quantised {
///     fn log_likelihood(&self, z: &Vector1<f64>, x: &Vector1<f64>) -> f64 {
///         if (z[0] - x[0]).abs() <= 0.5 { 0.0 } else { f64::NEG_INFINITY }
///     }
/// }
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(4.0))?;
/// let mut pf = ParticleFilter::new(prior, 500, 1)?;
/// pf.update_with(&NonGaussian(Quantised), &Vector1::new(1.2))?;
/// // Every surviving particle lies within 0.5 of the reading.
/// assert!((pf.state()[0] - 1.1).abs() < 0.2);
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NonGaussian<M>(pub M);

/// How a particle filter moves a particle: [`AdditiveGaussian`] over any [`ProcessModel`]
/// (x⁺ = f(x, u, Δt) + w, w ~ N(0, Q) drawn through a PSD factor of Q, so a singular Q works)
/// or [`NonGaussian<P>`] with `P:` [`ProcessSampler`].
pub trait ParticleProcess<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The underlying model (f and Q).
    type Model: ProcessModel<T, N> + ?Sized;

    /// The model.
    fn model(&self) -> &Self::Model;

    /// Writes a draw of x⁺ into `out` and returns `true` if the model samples itself; `false`
    /// (the default) for the Gaussian path.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn sample_into(
        &self,
        x: &OVector<T, N>,
        u: &<Self::Model as ProcessModel<T, N>>::Input,
        dt: T,
        rng: &mut ParticleRng,
        out: &mut OVector<T, N>,
    ) -> bool {
        let _ = (x, u, dt, rng, out);
        false
    }
}

/// A model used with Gaussian noise in a particle filter (the default path: the step traits
/// wrap every model in it).
#[derive(Clone, Copy, Debug)]
pub struct AdditiveGaussian<'a, M: ?Sized>(pub &'a M);

impl<T: Real, N: Dim, P: ProcessModel<T, N> + ?Sized> ParticleProcess<T, N>
    for AdditiveGaussian<'_, P>
where
    DefaultAllocator: Alloc<N>,
{
    type Model = P;

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn model(&self) -> &P {
        self.0
    }
}

impl<T: Real, N: Dim, P: ProcessSampler<T, N>> ParticleProcess<T, N> for NonGaussian<P>
where
    DefaultAllocator: Alloc<N>,
{
    type Model = P;

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn model(&self) -> &P {
        &self.0
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn sample_into(
        &self,
        x: &OVector<T, N>,
        u: &P::Input,
        dt: T,
        rng: &mut ParticleRng,
        out: &mut OVector<T, N>,
    ) -> bool {
        *out = self.0.sample_transition(x, u, dt, rng);
        true
    }
}

/// How a particle filter weights a particle: [`AdditiveGaussian`] over any
/// [`MeasurementModel`] (log N(z ⊖ h(x); 0, R(x)), with the model's residual ⊖ so angles wrap)
/// or [`NonGaussian<H>`] with `H:` [`MeasurementLikelihood`].
pub trait ParticleMeasurement<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The underlying model (h, R and the residual).
    type Model: MeasurementModel<T, N, M> + ?Sized;

    /// The model.
    fn model(&self) -> &Self::Model;

    /// log p(z | x) if the model evaluates it itself; `None` (the default) for the Gaussian
    /// path.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn log_likelihood(&self, z: &OVector<T, M>, x: &OVector<T, N>) -> Option<T> {
        let _ = (z, x);
        None
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M> + ?Sized> ParticleMeasurement<T, N, M>
    for AdditiveGaussian<'_, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    type Model = H;

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn model(&self) -> &H {
        self.0
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementLikelihood<T, N, M>> ParticleMeasurement<T, N, M>
    for NonGaussian<H>
where
    DefaultAllocator: Alloc<N, M>,
{
    type Model = H;

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn model(&self) -> &H {
        &self.0
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn log_likelihood(&self, z: &OVector<T, M>, x: &OVector<T, N>) -> Option<T> {
        Some(self.0.log_likelihood(z, x))
    }
}

/// A borrowed model with its own noise (what [`NonGaussianFilter`](super::NonGaussianFilter)'s
/// step impls pass on).
pub(crate) struct Own<'a, M: ?Sized>(pub(crate) &'a M);

impl<T: Real, N: Dim, P: ProcessSampler<T, N> + ?Sized> ParticleProcess<T, N> for Own<'_, P>
where
    DefaultAllocator: Alloc<N>,
{
    type Model = P;

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn model(&self) -> &P {
        self.0
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn sample_into(
        &self,
        x: &OVector<T, N>,
        u: &P::Input,
        dt: T,
        rng: &mut ParticleRng,
        out: &mut OVector<T, N>,
    ) -> bool {
        *out = self.0.sample_transition(x, u, dt, rng);
        true
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementLikelihood<T, N, M> + ?Sized>
    ParticleMeasurement<T, N, M> for Own<'_, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    type Model = H;

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn model(&self) -> &H {
        self.0
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn log_likelihood(&self, z: &OVector<T, M>, x: &OVector<T, N>) -> Option<T> {
        Some(self.0.log_likelihood(z, x))
    }
}
