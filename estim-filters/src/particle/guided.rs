//! Guided proposals (documented on [`Proposal`]).

use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::rand::Rng;
use estim_core::{
    Alloc, Error, MeasurementModel, ProcessModel, Quantity, Real, Stage, error::Result,
};

use super::ParticleFilter;
use super::chunks::{CHUNK, columns, first_error, for_chunks, parallel, with_state};
use super::noise::{AdditiveGaussian, ParticleMeasurement};
use super::resample::ess_of_weights;
use super::rng::ParticleRng;
use super::step::Work;
use super::transition::{GaussianKernel, ParticleTransition, checked_log_density};
use crate::gaussian_filter::ensure_time_step;
use crate::report::UpdateReport;

/// Guided proposals: a particle filter step that draws from a user's q(x⁺ | x, z) instead of
/// the process model.
///
/// With the reading z in hand, each particle moves by the proposal and is reweighted by what
/// the proposal got wrong (Doucet, Godsill & Andrieu 2000; Chopin & Papaspiliopoulos 2020,
/// §10.3.2):
///
/// ```text
/// resample:  if ESS < τN: aⱼ ~ W, log W̄ⱼ = −log N;  else aⱼ = j, log W̄ⱼ = log Wⱼ
/// propose:   xⱼ⁺ ~ q(· | x_aⱼ, u, Δt, z)
/// weight:    log wⱼ = log W̄ⱼ + log p(z | xⱼ⁺) + log p(xⱼ⁺ | x_aⱼ, u, Δt) − log q(xⱼ⁺ | x_aⱼ, u, Δt, z)
/// normalise: Δℓ = log Σ wⱼ,  log Wⱼ ← log wⱼ − Δℓ      (exp Δℓ unbiased for p(z | z₁..ₖ₋₁))
/// ```
///
/// The bootstrap filter is the special case q = p (the transition terms cancel, leaving
/// log p(z | x⁺)). The *locally optimal* proposal q = p(x⁺ | x, z) makes the incremental
/// weight p(z | x) independent of the draw, which minimises the weights' variance given the
/// ancestors; for a linear-Gaussian model it is N(m, Σ) with
/// Σ = (Q⁻¹ + Hᵀ R⁻¹ H)⁻¹, m = Σ (Q⁻¹ F x + Hᵀ R⁻¹ z). A proposal that puts mass where the
/// sensor is sharp helps most when the measurement is informative relative to the process
/// noise (the bootstrap filter's weights then degenerate).
///
/// p(x⁺ | x, u, Δt) is the [`ParticleTransition`] density (Gaussian from Q, which must then be
/// positive definite, or the model's own [`TransitionDensity`](super::TransitionDensity)).
/// The proposal draws from the stream (seed, step, j) of the particle it makes, as the
/// bootstrap prediction does. The proposal pass and the weighing run by chunks of particles
/// like the bootstrap steps (on rayon's pool under the `parallel` feature for large clouds),
/// so a seed gives the same bits on any number of threads; the proposal, the models and the
/// input are therefore `Sync`.
///
/// A proposal q(x⁺ | x, u, Δt, z) for [`ParticleFilter::guided_step`]: draws a successor of
/// `x` knowing the next reading `z`, and says how likely that draw was.
///
/// ```
/// use estim_core::nalgebra::{Vector1, U1};
/// use estim_core::rand::Rng;
/// use estim_core::rand_distr::{Distribution, StandardNormal};
/// use estim_filters::particle::Proposal;
///
/// /// The locally optimal proposal of x⁺ = 0.9 x + w (Q = 0.5), z = x + v (R = 0.1):
/// /// N(m, σ²) with σ² = 1/(1/Q + 1/R), m = σ² (0.9 x / Q + z / R).
/// struct Optimal;
/// impl Proposal<f64, U1, U1> for Optimal {
///     type Input = ();
///     fn propose<R: Rng + ?Sized>(&self, x: &Vector1<f64>, _: &(), _: f64, z: &Vector1<f64>, rng: &mut R) -> (Vector1<f64>, f64) {
///         let var = 1.0 / (1.0 / 0.5 + 1.0 / 0.1);
///         let mean = var * (0.9 * x[0] / 0.5 + z[0] / 0.1);
///         let e: f64 = StandardNormal.sample(rng);
///         let log_q = -0.5 * e * e - 0.5 * (2.0 * std::f64::consts::PI * var).ln();
///         (Vector1::new(mean + var.sqrt() * e), log_q)
///     }
/// }
/// let mut rng = estim_filters::particle::ParticleRng::stream(1, 1, 0);
/// let (draw, log_q) = Optimal.propose(&Vector1::new(0.0), &(), 1.0, &Vector1::new(1.0), &mut rng);
/// assert!(draw[0].is_finite() && log_q.is_finite());
/// ```
pub trait Proposal<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The process input u (the process model's).
    type Input;

    /// One draw x⁺ ~ q(· | x, u, Δt, z) and its log-density log q(x⁺ | x, u, Δt, z), which
    /// must be finite (the proposal drew it).
    fn propose<R: Rng + ?Sized>(
        &self,
        x: &OVector<T, N>,
        u: &Self::Input,
        dt: T,
        z: &OVector<T, M>,
        rng: &mut R,
    ) -> (OVector<T, N>, T);
}

impl<T: Real, N: Dim> ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// One predict-and-update step with the guided proposal `proposal` (see
    /// [`Proposal`]): particles move by q, weights are W̄ p(z | x⁺) p(x⁺ | x) / q(x⁺ | x, z).
    /// `process` gives the transition density (Gaussian from its f and Q, which must be
    /// positive definite), `sensor` the likelihood N(z ⊖ h(x); 0, R). The report
    /// holds the innovation moments of the proposed cloud weighted by W̄ p / q and the
    /// step's log-likelihood Δℓ.
    ///
    /// Errors (the filter unchanged): Δt negative or not finite; z not finite; a proposal
    /// draw of the wrong length or not finite, or a log q that is not finite
    /// ([`Quantity::Weights`]); a transition without density (singular Q:
    /// [`Error::NotPositiveDefinite`]); the update's errors (every weight zero, R not positive
    /// definite, ...).
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix1, Vector1, U1};
    /// use estim_core::rand::Rng;
    /// use estim_core::rand_distr::{Distribution, StandardNormal};
    /// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
    /// use estim_filters::particle::{ParticleFilter, Proposal};
    /// use estim_filters::{Estimator, KalmanFilter, Predict, Update};
    ///
    /// struct Optimal; // N(m, σ²), σ² = 1/(1/Q + 1/R), m = σ² (0.9 x / Q + z / R)
    /// impl Proposal<f64, U1, U1> for Optimal {
    ///     type Input = ();
    ///     fn propose<R: Rng + ?Sized>(&self, x: &Vector1<f64>, _: &(), _: f64, z: &Vector1<f64>, rng: &mut R) -> (Vector1<f64>, f64) {
    ///         let var = 1.0 / (1.0 / 0.5 + 1.0 / 0.1);
    ///         let mean = var * (0.9 * x[0] / 0.5 + z[0] / 0.1);
    ///         let e: f64 = StandardNormal.sample(rng);
    ///         (Vector1::new(mean + var.sqrt() * e), -0.5 * e * e - 0.5 * (2.0 * std::f64::consts::PI * var).ln())
    ///     }
    /// }
    /// let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
    /// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.1) };
    /// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
    /// let mut pf = ParticleFilter::new(prior.clone(), 500, 2)?;
    /// let mut kf = KalmanFilter::new(prior);
    /// for z in [0.4, -0.3, 1.1] {
    ///     pf.guided_step(&process, &Optimal, &(), 1.0, &sensor, &Vector1::new(z))?;
    ///     kf.predict(&process, &(), 1.0)?;
    ///     kf.update(&sensor, &Vector1::new(z))?;
    /// }
    /// // Posterior sd ≈ 0.3; 500 particles give the mean to ≈ 0.015.
    /// assert!((pf.state()[0] - kf.state()[0]).abs() < 0.07);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn guided_step<P, Q, M, H>(
        &mut self,
        process: &P,
        proposal: &Q,
        input: &P::Input,
        dt: T,
        sensor: &H,
        z: &OVector<T, M>,
    ) -> Result<UpdateReport<T, M>>
    where
        P: ProcessModel<T, N> + Sync + ?Sized,
        P::Input: Sync,
        Q: Proposal<T, N, M, Input = P::Input> + Sync + ?Sized,
        M: Dim,
        H: MeasurementModel<T, N, M> + Sync + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        self.guided_step_with(
            &AdditiveGaussian(process),
            proposal,
            input,
            dt,
            &AdditiveGaussian(sensor),
            z,
        )
    }

    /// [`guided_step`](Self::guided_step) with any [`ParticleTransition`] (e.g. a
    /// [`NonGaussian`](super::NonGaussian) model with its own
    /// [`TransitionDensity`](super::TransitionDensity)) and any [`ParticleMeasurement`].
    pub fn guided_step_with<P, Q, M, H>(
        &mut self,
        process: &P,
        proposal: &Q,
        input: &<P::Model as ProcessModel<T, N>>::Input,
        dt: T,
        sensor: &H,
        z: &OVector<T, M>,
    ) -> Result<UpdateReport<T, M>>
    where
        P: ParticleTransition<T, N> + Sync + ?Sized,
        <P::Model as ProcessModel<T, N>>::Input: Sync,
        Q: Proposal<T, N, M, Input = <P::Model as ProcessModel<T, N>>::Input> + Sync + ?Sized,
        M: Dim,
        H: ParticleMeasurement<T, N, M> + Sync + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        ensure_time_step(dt)?;
        ensure_finite(z, Stage::Update, Quantity::Measurement)?;
        let count = self.count();
        let (n, _) = self.cloud.mean.shape_generic();
        let m = z.shape_generic().0;
        let (seed, step) = (self.seed, self.cloud.step);
        let resample = self
            .when
            .fires(|| ess_of_weights(&self.cloud.weights), count);
        let cloud = &self.cloud;
        let work = &mut self.work;
        Work::<T, N>::ancestors_from(
            &mut work.ancestors,
            &mut work.scratch,
            &cloud.weights,
            resample,
            self.scheme,
            seed,
            step,
        )?;
        let uniform = -estim_core::scalar::real::<T>(count as f64).ln();
        // First pass, by chunks: propose into `next`; log W̄ⱼ + log p(x⁺ | x) − log q into
        // `log_eta`.
        let (nn, particles, zs) = (n.value(), cloud.particles.as_slice(), z.as_slice());
        let (ancestors, log_weights) = (&work.ancestors, &cloud.log_weights);
        work.log_eta.resize(count, T::zero());
        let mut placeholder = Vec::new();
        let out = columns(work.next.as_mut_slice(), &mut placeholder, nn, count);
        for_chunks(
            parallel(count),
            &mut work.chunks,
            out,
            n.value().max(1) * CHUNK,
            &mut work.log_eta,
            CHUNK,
            |c, w, out, eta| {
                w.error = with_state(&mut w.state, n, |s| {
                    // The reading and the last Gaussian kernel, per chunk (a generic-size
                    // buffer cannot be shared between threads).
                    let z = OVector::<T, M>::from_column_slice_generic(m, U1, zs);
                    let mut kernel: Option<GaussianKernel<T, N>> = None;
                    let stage = Stage::Prediction;
                    for (k, (column, eta)) in
                        out.chunks_exact_mut(n.value().max(1)).zip(eta).enumerate()
                    {
                        let j = c * CHUNK + k;
                        let a = ancestors[j];
                        s.x.copy_from_slice(&particles[a * nn..(a + 1) * nn]);
                        let mut rng = ParticleRng::stream(seed, step, j as u64);
                        let (next, log_q) = proposal.propose(&s.x, input, dt, &z, &mut rng);
                        let checked = ensure_shape(&next, nn, 1, stage, Quantity::FunctionValue)
                            .and_then(|()| ensure_finite(&next, stage, Quantity::FunctionValue));
                        if let Err(e) = checked {
                            return Some(e);
                        }
                        if !log_q.is_finite() {
                            return Some(Error::NonFinite {
                                stage,
                                quantity: Quantity::Weights,
                            });
                        }
                        let log_p = if process.has_own_density() {
                            let value = process
                                .log_transition(&next, &s.x, input, dt)
                                .unwrap_or(T::zero());
                            checked_log_density(value, stage)
                        } else {
                            GaussianKernel::at(
                                process.model(),
                                &s.x,
                                input,
                                dt,
                                kernel.as_ref(),
                                stage,
                            )
                            .map(|fresh| kernel.insert(fresh).log_density(&next, &mut s.y))
                        };
                        let log_p = match log_p {
                            Ok(log_p) => log_p,
                            Err(e) => return Some(e),
                        };
                        let prior = if resample { uniform } else { log_weights[j] };
                        *eta = prior + log_p - log_q;
                        for (o, &x) in column.iter_mut().zip(next.iter()) {
                            *o = x;
                        }
                    }
                    None
                });
            },
        );
        first_error(work.chunks.iter_mut())?;
        // Second pass: the likelihood, with predictive weights ∝ W̄ p / q for the report.
        let log_eta = core::mem::take(&mut work.log_eta);
        let max = log_eta
            .iter()
            .fold(-T::one() / T::zero(), |m, &v| if v > m { v } else { m });
        let next = core::mem::replace(&mut work.next, OMatrix::zeros_generic(n, Dyn(0)));
        let mut log_w = core::mem::take(&mut work.log_w);
        log_w.resize(count, T::zero());
        let weighed = work.weigh(sensor, z, &next, &mut log_w, |j| {
            let log_v = log_eta[j];
            let v = if max.is_finite() {
                (log_v - max).exp()
            } else {
                T::zero()
            };
            (v, log_v)
        });
        work.next = next;
        work.log_w = log_w;
        work.log_eta = log_eta;
        let increment = weighed?;
        // Committed.
        let mut report = UpdateReport::zeros(m);
        work.report(m, increment, &mut report);
        core::mem::swap(&mut self.cloud.particles, &mut work.next);
        work.normalise(
            increment,
            &mut self.cloud.log_weights,
            &mut self.cloud.weights,
        );
        self.cloud.step = step.wrapping_add(1);
        self.cloud.log_likelihood += increment;
        self.update_moments();
        Ok(report)
    }
}
