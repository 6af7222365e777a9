//! The auxiliary particle filter (Pitt & Shephard 1999), as a combined predict-and-update step.
//!
//! With the next reading z in hand, particles are chosen by how well their noise-free
//! prediction μᵢ = f(xᵢ, u, Δt) explains it, then propagated and corrected for that choice
//! (Chopin & Papaspiliopoulos 2020, §10.3.3; Johansen & Doucet 2008):
//!
//! ```text
//! first stage:   log ηᵢ = log p(z | μᵢ),   log λᵢ = log Wᵢ + log ηᵢ,   L₁ = log Σ λᵢ
//! resample:      aⱼ ~ λ (always; the filter's scheme)
//! propagate:     xⱼ ~ p(· | x_aⱼ, u, Δt)
//! second stage:  log wⱼ = log p(z | xⱼ) − log η_aⱼ,   L₂ = log Σ wⱼ
//! likelihood:    Δℓ = L₁ + L₂ − log N        (exp Δℓ unbiased for p(z | z₁..ₖ₋₁))
//! ```
//!
//! p(z | ·) is the same density the bootstrap update uses (Gaussian from R, or a
//! [`NonGaussian`](super::NonGaussian) model's likelihood). ηᵢ must be positive wherever the
//! children of xᵢ can explain z (true for a Gaussian R); a particle with ηᵢ = 0 has no children.

use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector};
use estim_core::{Alloc, ProcessModel, Quantity, Real, Stage, error::Result};

use super::ParticleFilter;
use super::chunks::{CHUNK, columns, first_error, for_chunks1, parallel, with_state};
use super::noise::{AdditiveGaussian, ParticleMeasurement, ParticleProcess};
use super::step::Work;
use crate::gaussian_filter::ensure_time_step;
use crate::report::UpdateReport;
use estim_core::MeasurementModel;

impl<T: Real, N: Dim> ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// One auxiliary-particle-filter step with Gaussian noise from the models' Q and R:
    /// predicts through `process` and updates with `sensor`'s reading `z` (see the
    /// [module documentation](crate::particle) and Pitt & Shephard 1999 for the math). The report's innovation moments are those
    /// of the predictive cloud (the propagated particles reweighted by 1/η_aⱼ), its
    /// log-likelihood Δℓ. On error (as for a prediction or an update) the filter is unchanged.
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix1, Vector1};
    /// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
    /// use estim_filters::particle::ParticleFilter;
    /// use estim_filters::{Estimator, KalmanFilter, Predict, Update};
    ///
    /// let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
    /// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.1) };
    /// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
    /// let mut apf = ParticleFilter::new(prior.clone(), 2000, 5)?;
    /// let mut kf = KalmanFilter::new(prior);
    /// for z in [0.4, -0.3, 1.1] {
    ///     apf.auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(z))?;
    ///     kf.predict(&process, &(), 1.0)?;
    ///     kf.update(&sensor, &Vector1::new(z))?;
    /// }
    /// // Posterior sd ≈ 0.3; 2000 particles give the mean to ≈ 0.01.
    /// assert!((apf.state()[0] - kf.state()[0]).abs() < 0.05);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn auxiliary_step<P, M, H>(
        &mut self,
        process: &P,
        input: &P::Input,
        dt: T,
        sensor: &H,
        z: &OVector<T, M>,
    ) -> Result<UpdateReport<T, M>>
    where
        P: ProcessModel<T, N> + Sync + ?Sized,
        P::Input: Sync,
        M: Dim,
        H: MeasurementModel<T, N, M> + Sync + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        let mut report = UpdateReport::zeros(z.shape_generic().0);
        self.auxiliary_step_with(
            &AdditiveGaussian(process),
            input,
            dt,
            &AdditiveGaussian(sensor),
            z,
            &mut report,
        )?;
        Ok(report)
    }

    /// [`auxiliary_step`](Self::auxiliary_step) with any [`ParticleProcess`] and
    /// [`ParticleMeasurement`] (e.g. [`NonGaussian`](super::NonGaussian) models), into
    /// `report`. The look-ahead point is the process model's
    /// [`transition`](ProcessModel::transition).
    pub fn auxiliary_step_with<P, M, H>(
        &mut self,
        process: &P,
        input: &<P::Model as ProcessModel<T, N>>::Input,
        dt: T,
        sensor: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        P: ParticleProcess<T, N> + Sync + ?Sized,
        <P::Model as ProcessModel<T, N>>::Input: Sync,
        M: Dim,
        H: ParticleMeasurement<T, N, M> + Sync + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        ensure_time_step(dt)?;
        ensure_finite(z, Stage::Update, Quantity::Measurement)?;
        let count = self.count();
        let (n, _) = self.cloud.mean.shape_generic();
        let (seed, step) = (self.seed, self.cloud.step);
        let cloud = &self.cloud;
        let work = &mut self.work;
        // First stage: μᵢ into `next`, log ηᵢ into `log_eta`.
        let (nn, particles) = (n.value(), cloud.particles.as_slice());
        let mut placeholder = Vec::new();
        let out = columns(work.next.as_mut_slice(), &mut placeholder, nn, count);
        for_chunks1(
            parallel(count),
            &mut work.chunks,
            out,
            n.value().max(1) * CHUNK,
            |c, w, out| {
                w.error = with_state(&mut w.state, n, |s| {
                    for (k, column) in out.chunks_exact_mut(n.value().max(1)).enumerate() {
                        let i = c * CHUNK + k;
                        s.x.copy_from_slice(&particles[i * nn..(i + 1) * nn]);
                        estim_core::model::transition_into(
                            process.model(),
                            &s.x,
                            input,
                            dt,
                            &mut s.y,
                        );
                        let (stage, quantity) = (Stage::Prediction, Quantity::FunctionValue);
                        let checked = ensure_shape(&s.y, s.x.nrows(), 1, stage, quantity)
                            .and_then(|()| ensure_finite(&s.y, stage, quantity));
                        if let Err(e) = checked {
                            return Some(e);
                        }
                        for (o, &y) in column.iter_mut().zip(s.y.iter()) {
                            *o = y;
                        }
                    }
                    None
                });
            },
        );
        first_error(work.chunks.iter_mut())?;
        let next = core::mem::replace(&mut work.next, OMatrix::zeros_generic(n, Dyn(0)));
        let mut log_eta = core::mem::take(&mut work.log_eta);
        log_eta.resize(count, T::zero());
        let first_stage = work.weigh(sensor, z, &next, &mut log_eta, |_| (T::zero(), T::zero()));
        work.next = next;
        work.log_eta = log_eta;
        first_stage?;
        // log λᵢ = log Wᵢ + log ηᵢ; L₁ = log Σ λᵢ; resampling weights λᵢ / Σ λ.
        let mut log_w = core::mem::take(&mut work.log_w);
        log_w.clear();
        log_w.extend(
            cloud
                .log_weights
                .iter()
                .zip(&work.log_eta)
                .map(|(&lw, &eta)| lw + eta),
        );
        let first = work.normaliser(&log_w);
        work.log_w = log_w;
        let first = first?;
        work.weights_from_terms(first);
        Work::<T, N>::ancestors_from(
            &mut work.ancestors,
            &mut work.scratch,
            &work.weights,
            true,
            self.scheme,
            seed,
            step,
        )?;
        // Propagate the chosen particles.
        work.propagate_all(&cloud.particles, process, input, dt, seed, step)?;
        // Second stage; predictive weights ∝ 1/η_aⱼ for the report's moments.
        let ancestors = core::mem::take(&mut work.ancestors);
        let log_eta = core::mem::take(&mut work.log_eta);
        let max_inverse = ancestors
            .iter()
            .map(|&a| -log_eta[a])
            .fold(-T::one() / T::zero(), |m, v| if v > m { v } else { m });
        let next = core::mem::replace(&mut work.next, OMatrix::zeros_generic(n, Dyn(0)));
        let mut log_w = core::mem::take(&mut work.log_w);
        let second = work.weigh(sensor, z, &next, &mut log_w, |j| {
            let log_eta = log_eta[ancestors[j]];
            ((-log_eta - max_inverse).exp(), -log_eta)
        });
        work.next = next;
        work.log_w = log_w;
        work.ancestors = ancestors;
        work.log_eta = log_eta;
        let second = second?;
        let increment = first + second - estim_core::scalar::real::<T>(count as f64).ln();
        // Committed.
        work.report(z.shape_generic().0, increment, report);
        core::mem::swap(&mut self.cloud.particles, &mut work.next);
        work.normalise(second, &mut self.cloud.log_weights, &mut self.cloud.weights);
        self.cloud.step = step.wrapping_add(1);
        self.cloud.log_likelihood += increment;
        self.update_moments();
        Ok(())
    }
}
