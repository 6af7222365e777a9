//! The transition log-density (design documented on [`log_transition_density`]).

use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::nalgebra::{Cholesky, DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::{Alloc, Error, ProcessModel, Quantity, Real, Stage, error::Result};

use super::noise::{AdditiveGaussian, NonGaussian, ParticleProcess, ProcessSampler};

/// Opt-in: a process that evaluates its own transition log-density log p(x⁺ | x, u, Δt), for
/// a process whose noise is not additive Gaussian (or lives on a manifold). Pair it with
/// [`ProcessSampler`] and use the model as [`NonGaussian(model)`](NonGaussian): the density
/// must be the one of the sampler's draws.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::rand::Rng;
/// use estim_core::ProcessModel;
/// use estim_filters::particle::{ProcessSampler, TransitionDensity};
///
/// /// x⁺ = x + an exponential(1) step.
/// struct Creep;
/// impl ProcessModel<f64, U1> for Creep {
///     type Input = ();
///     fn transition(&self, x: &Vector1<f64>, _: &(), _: f64) -> Vector1<f64> { x.add_scalar(1.0) }
///     fn process_noise(&self, _: &Vector1<f64>, _: &(), _: f64) -> Matrix1<f64> { Matrix1::new(1.0) }
/// }
/// impl ProcessSampler<f64, U1> for Creep {
///     fn sample_transition<R: Rng + ?Sized>(&self, x: &Vector1<f64>, _: &(), _: f64, rng: &mut R) -> Vector1<f64> {
///         x.add_scalar(-(1.0 - rng.random::<f64>()).ln())
///     }
/// }
/// impl TransitionDensity<f64, U1> for Creep {
///     fn log_transition_density(&self, next: &Vector1<f64>, x: &Vector1<f64>, _: &(), _: f64) -> f64 {
///         let step = next[0] - x[0];
///         if step >= 0.0 { -step } else { f64::NEG_INFINITY }
///     }
/// }
/// assert_eq!(Creep.log_transition_density(&Vector1::new(0.5), &Vector1::new(1.0), &(), 1.0), f64::NEG_INFINITY);
/// ```
pub trait TransitionDensity<T: Real, N: Dim>: ProcessModel<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// log p(x⁺ = `next` | x, u, Δt); −∞ where the move is impossible. Must not be NaN or +∞.
    fn log_transition_density(
        &self,
        next: &OVector<T, N>,
        x: &OVector<T, N>,
        u: &Self::Input,
        dt: T,
    ) -> T;
}

/// How a particle algorithm evaluates log p(x⁺ | x, u, Δt): the Gaussian density of
/// N(f(x, u, Δt), Q(x, u, Δt)) for [`AdditiveGaussian`], the model's own
/// [`TransitionDensity`] for [`NonGaussian`].
pub trait ParticleTransition<T: Real, N: Dim>: ParticleProcess<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// log p(x⁺ | x, u, Δt) if the model evaluates it itself; `None` (the default) for the
    /// Gaussian path.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn log_transition(
        &self,
        next: &OVector<T, N>,
        x: &OVector<T, N>,
        u: &<Self::Model as ProcessModel<T, N>>::Input,
        dt: T,
    ) -> Option<T> {
        let _ = (next, x, u, dt);
        None
    }

    /// Whether [`log_transition`](Self::log_transition) answers (`false`: the Gaussian path).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn has_own_density(&self) -> bool {
        false
    }
}

impl<T: Real, N: Dim, P: ProcessModel<T, N> + ?Sized> ParticleTransition<T, N>
    for AdditiveGaussian<'_, P>
where
    DefaultAllocator: Alloc<N>,
{
}

impl<T: Real, N: Dim, P: ProcessSampler<T, N> + TransitionDensity<T, N>> ParticleTransition<T, N>
    for NonGaussian<P>
where
    DefaultAllocator: Alloc<N>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn log_transition(
        &self,
        next: &OVector<T, N>,
        x: &OVector<T, N>,
        u: &P::Input,
        dt: T,
    ) -> Option<T> {
        Some(self.0.log_transition_density(next, x, u, dt))
    }

    #[cfg_attr(not(debug_assertions), inline(always))]
    fn has_own_density(&self) -> bool {
        true
    }
}

/// A Gaussian N(μ, Q) prepared for repeated log-density evaluations: its mean, the Cholesky
/// factor L of Q and n/2 log 2π + Σ log Lₖₖ.
#[derive(Clone, Debug)]
pub(crate) struct GaussianKernel<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) mean: OVector<T, N>,
    pub(crate) noise: OMatrix<T, N, N>,
    pub(crate) factor: OMatrix<T, N, N>,
    pub(crate) half_log_det: T,
}

impl<T: Real, N: Dim> GaussianKernel<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The kernel N(f(x, u, Δt), Q(x, u, Δt)), reusing `previous`'s factor when Q is the same.
    /// Errors (at `stage`): f(x) or Q of the wrong shape or not finite; Q not positive
    /// definite (singular: no density).
    pub(crate) fn at<P: ProcessModel<T, N> + ?Sized>(
        model: &P,
        x: &OVector<T, N>,
        u: &P::Input,
        dt: T,
        previous: Option<&Self>,
        stage: Stage,
    ) -> Result<Self> {
        let n = x.nrows();
        let mean = model.transition(x, u, dt);
        ensure_shape(&mean, n, 1, stage, Quantity::FunctionValue)?;
        ensure_finite(&mean, stage, Quantity::FunctionValue)?;
        let noise = model.process_noise(x, u, dt);
        if let Some(previous) = previous.filter(|p| p.noise == noise) {
            return Ok(Self {
                mean,
                noise,
                factor: previous.factor.clone(),
                half_log_det: previous.half_log_det,
            });
        }
        ensure_shape(&noise, n, n, stage, Quantity::ProcessNoise)?;
        ensure_finite(&noise, stage, Quantity::ProcessNoise)?;
        let singular = Error::NotPositiveDefinite {
            stage,
            quantity: Quantity::ProcessNoise,
        };
        let factor = Cholesky::new(noise.clone()).ok_or(singular)?.unpack();
        let mut half_log_det =
            estim_core::scalar::real::<T>(n as f64) * T::two_pi().ln() / (T::one() + T::one());
        for k in 0..n {
            half_log_det += factor[(k, k)].ln();
        }
        if !half_log_det.is_finite() {
            return Err(singular);
        }
        Ok(Self {
            mean,
            noise,
            factor,
            half_log_det,
        })
    }

    /// log N(`next`; μ, Q), with `work` as the residual buffer.
    #[inline]
    pub(crate) fn log_density(&self, next: &OVector<T, N>, work: &mut OVector<T, N>) -> T {
        work.copy_from(next);
        *work -= &self.mean;
        self.factor.solve_lower_triangular_mut(work);
        -work.norm_squared() / (T::one() + T::one()) - self.half_log_det
    }
}

/// Checks a model's own log-density: NaN or +∞ is a typed error, a bug in the model
/// ([`Quantity::FunctionValue`]).
pub(crate) fn checked_log_density<T: Real>(value: T, stage: Stage) -> Result<T> {
    #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
    let nan = value != value;
    if nan || value == T::one() / T::zero() {
        Err(Error::NonFinite {
            stage,
            quantity: Quantity::FunctionValue,
        })
    } else {
        Ok(value)
    }
}

/// The transition log-density log p(x⁺ | x, u, Δt), which the backward pass of a particle
/// smoother and a guided proposal's importance weight need.
///
/// **Design.** A [`ProcessModel`] written for the Kalman filters gives f and Q; a particle
/// filter draws x⁺ = f(x, u, Δt) + L ε with L Lᵀ = Q through a PSD factor, so a singular Q is
/// fine for *sampling*. The density of that draw is
///
/// ```text
/// log p(x⁺ | x, u, Δt) = −½ rᵀ Q⁻¹ r − ½ log det(2π Q),   r = x⁺ − f(x, u, Δt)
///                      = −½ |L⁻¹ r|² − n/2 log 2π − Σₖ log Lₖₖ     (Q = L Lᵀ, Cholesky)
/// ```
///
/// - r is the plain difference x⁺ − f: it is the difference the filter's sampler added the
///   noise with, so the density is the one of the draws the forward pass made (a wrapped angle
///   would need a wrapped density, which the model then states itself, below).
/// - A singular Q (a state that is a deterministic function of the previous one, e.g. the
///   position of a constant-velocity model with noise on the velocity only) has **no
///   density**: the transition law is concentrated on a subspace and every other particle's
///   backward weight is 0 whatever the numbers say. That is a typed error,
///   [`Error::NotPositiveDefinite`] with [`Quantity::ProcessNoise`] (at the stage of the
///   algorithm that asked), never NaN or a silently regularised Q. Such a model is smoothed by
///   making its noise non-degenerate, or by stating a density of its own.
/// - A non-Gaussian process opts in with [`TransitionDensity`], beside
///   [`ProcessSampler`](super::ProcessSampler): used as [`NonGaussian(model)`](super::NonGaussian)
///   it supplies both the draws and their density, and the two must agree (the smoother's
///   correctness rests on it).
///
/// The dispatch trait [`ParticleTransition`] is implemented by the same two wrappers as
/// [`ParticleProcess`]: [`AdditiveGaussian`] (the Gaussian density above, with Q evaluated at
/// the conditioning state x, so a state-dependent Q is exact) and [`NonGaussian`].
///
/// log p(x⁺ | x, u, Δt) through any [`ParticleTransition`]: the model's own density, or the
/// Gaussian N(f(x, u, Δt), Q(x, u, Δt)) evaluated by the Cholesky factor of Q
/// (above). One evaluation; the smoother and the proposals use a cached form.
///
/// Errors (at `stage`): a singular or indefinite Q ([`Error::NotPositiveDefinite`] with
/// [`Quantity::ProcessNoise`]: that transition has no density); f(x) or Q of the wrong shape or
/// not finite; a model density that is NaN or +∞ ([`Quantity::FunctionValue`]).
///
/// ```
/// use estim_core::nalgebra::{Matrix2, Vector2};
/// use estim_core::{Error, LinearProcess, Quantity, Stage};
/// use estim_filters::particle::{AdditiveGaussian, log_transition_density};
///
/// let walk = LinearProcess::without_input(Matrix2::identity(), Matrix2::new(4.0, 0.0, 0.0, 1.0));
/// let (x, next) = (Vector2::new(0.0, 0.0), Vector2::new(2.0, 1.0));
/// let log_p = log_transition_density(&AdditiveGaussian(&walk), &next, &x, &(), 1.0, Stage::Smoothing)?;
/// // Two unit-variance standardised residuals: −½(1 + 1) − log 2π − log 2.
/// let expected = -1.0 - (2.0 * std::f64::consts::PI).ln() - 2f64.ln();
/// assert!((log_p - expected).abs() < 1e-12);
///
/// // Noise on the second component only: no density, a typed error.
/// let degenerate = LinearProcess::without_input(Matrix2::identity(), Matrix2::new(0.0, 0.0, 0.0, 1.0));
/// assert_eq!(
///     log_transition_density(&AdditiveGaussian(&degenerate), &next, &x, &(), 1.0, Stage::Smoothing),
///     Err(Error::NotPositiveDefinite { stage: Stage::Smoothing, quantity: Quantity::ProcessNoise })
/// );
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn log_transition_density<T: Real, N: Dim, P: ParticleTransition<T, N> + ?Sized>(
    process: &P,
    next: &OVector<T, N>,
    x: &OVector<T, N>,
    u: &<P::Model as ProcessModel<T, N>>::Input,
    dt: T,
    stage: Stage,
) -> Result<T>
where
    DefaultAllocator: Alloc<N>,
{
    ensure_shape(next, x.nrows(), 1, stage, Quantity::Mean)?;
    if let Some(value) = process.log_transition(next, x, u, dt) {
        return checked_log_density(value, stage);
    }
    let kernel = GaussianKernel::at(process.model(), x, u, dt, None, stage)?;
    let mut work = OVector::zeros_generic(x.shape_generic().0, U1);
    Ok(kernel.log_density(next, &mut work))
}
