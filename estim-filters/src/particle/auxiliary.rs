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

use estim_core::checks::ensure_finite;
use estim_core::nalgebra::{DefaultAllocator, Dim, OVector};
use estim_core::{Alloc, ProcessModel, Quantity, Real, Stage, error::Result};

use super::ParticleFilter;
use super::noise::{AdditiveGaussian, ParticleMeasurement, ParticleProcess};
use super::rng::ParticleRng;
use super::step::{Weigher, normaliser};
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
        P: ProcessModel<T, N> + ?Sized,
        M: Dim,
        H: MeasurementModel<T, N, M> + ?Sized,
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
        P: ParticleProcess<T, N> + ?Sized,
        M: Dim,
        H: ParticleMeasurement<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        ensure_time_step(dt)?;
        ensure_finite(z, Stage::Update, Quantity::Measurement)?;
        let count = self.count();
        let (n, _) = self.cloud.mean.shape_generic();
        let step = self.cloud.step;
        let mut look_ahead = Weigher::new(n, z.shape_generic().0);
        let work = &mut self.work;
        // First stage: μᵢ into `next`, log ηᵢ into `log_eta`, log λᵢ into `log_w`.
        work.log_eta.clear();
        work.log_w.clear();
        for (i, &lw) in self.cloud.log_weights.iter().enumerate() {
            work.x.copy_from(&self.cloud.particles.column(i));
            estim_core::in_place::transition_into(process.model(), &work.x, input, dt, &mut work.y);
            ensure_finite(&work.y, Stage::Prediction, Quantity::FunctionValue)?;
            work.next.set_column(i, &work.y);
            let log_eta = look_ahead.log_density(sensor, z, &work.next, i, T::zero())?;
            work.log_eta.push(log_eta);
            work.log_w.push(lw + log_eta);
        }
        let first = normaliser(&work.log_w)?;
        for lw in &mut work.log_w {
            *lw -= first;
        }
        let first_stage = core::mem::take(&mut work.log_w);
        work.ancestors_from(&first_stage, true, self.scheme, self.seed, step);
        work.log_w = first_stage;
        // Propagate the chosen particles.
        for j in 0..count {
            let a = work.ancestors[j];
            work.x.copy_from(&self.cloud.particles.column(a));
            let rng = ParticleRng::stream(self.seed, step, j as u64);
            work.propagate(process, input, dt, rng, j)?;
        }
        // Second stage; predictive weights ∝ 1/η_aⱼ for the report's moments.
        let max_inverse = work
            .ancestors
            .iter()
            .map(|&a| -work.log_eta[a])
            .fold(-T::one() / T::zero(), |m, v| if v > m { v } else { m });
        let mut weigher = Weigher::new(n, z.shape_generic().0);
        let mut predictive_total = T::zero();
        work.log_w.clear();
        for j in 0..count {
            let log_eta = work.log_eta[work.ancestors[j]];
            let v = (-log_eta - max_inverse).exp();
            predictive_total += v;
            let log_g = weigher.log_density(sensor, z, &work.next, j, v)?;
            work.log_w.push(log_g - log_eta);
        }
        let second = normaliser(&work.log_w)?;
        let increment = first + second - estim_core::scalar::real::<T>(count as f64).ln();
        // Committed.
        core::mem::swap(&mut self.cloud.particles, &mut self.work.next);
        for (lw, &new) in self
            .cloud
            .log_weights
            .iter_mut()
            .zip(self.work.log_w.iter())
        {
            *lw = new - second;
        }
        self.cloud.step = step.wrapping_add(1);
        self.cloud.log_likelihood += increment;
        self.update_moments();
        weigher.report(predictive_total, increment, report);
        Ok(())
    }
}
