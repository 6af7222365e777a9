//! The bootstrap filter's prediction and update, and their step-trait impls.

use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::linalg::inverse_quadratic_form;
use estim_core::nalgebra::{Cholesky, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::{
    Alloc, Error, MeasurementModel, ProcessModel, Quantity, Real, Stage, error::Result, psd_factor,
};

use super::noise::{AdditiveGaussian, ParticleMeasurement, ParticleProcess};
use super::resample::{effective_sample_size, resample_with, to_f64};
use super::rng::{ParticleRng, RESAMPLE};
use super::{ParticleFilter, fill_normals};
use crate::gaussian_filter::ensure_time_step;
use crate::report::{UpdateOutcome, UpdateReport};
use crate::traits::{Predict, Update};

/// A noise matrix remembered with its factor (and, for R, log det(2πR)/2).
type Factored<T, D, Extra> = Option<(OMatrix<T, D, D>, OMatrix<T, D, D>, Extra)>;

/// Buffers of the steps (no state: a step overwrites what it reads).
#[derive(Clone, Debug)]
pub(crate) struct Work<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The propagated cloud, swapped in on success.
    pub(crate) next: OMatrix<T, N, Dyn>,
    /// New log-weights (update) or first-stage log-weights (auxiliary).
    pub(crate) log_w: Vec<T>,
    /// Normalised weights in f64, for resampling.
    pub(crate) weights: Vec<f64>,
    pub(crate) ancestors: Vec<usize>,
    /// The auxiliary filter's first-stage log-densities log ηᵢ.
    pub(crate) log_eta: Vec<T>,
    pub(crate) scratch: Vec<f64>,
    pub(crate) x: OVector<T, N>,
    pub(crate) y: OVector<T, N>,
    pub(crate) normals: OVector<T, N>,
    pub(crate) q: OMatrix<T, N, N>,
    /// The last Q seen and its PSD factor (Q is factorised again only when it changes).
    pub(crate) q_cache: Factored<T, N, ()>,
}

impl<T: Real, N: Dim> Work<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) fn new(n: N, count: usize) -> Self {
        Self {
            next: OMatrix::zeros_generic(n, Dyn(count)),
            log_w: vec![T::zero(); count],
            weights: vec![0.0; count],
            ancestors: (0..count).collect(),
            log_eta: Vec::with_capacity(count),
            scratch: Vec::with_capacity(2 * count),
            x: OVector::zeros_generic(n, U1),
            y: OVector::zeros_generic(n, U1),
            normals: OVector::zeros_generic(n, U1),
            q: OMatrix::zeros_generic(n, n),
            q_cache: None,
        }
    }

    /// Resizes the buffers for dimension n and `count` particles if they differ.
    pub(crate) fn fit(&mut self, n: N, count: usize) {
        if self.next.shape() != (n.value(), count) {
            *self = Self::new(n, count);
        }
    }

    /// Ancestors from the normalised log-weights `log_w` (resampled by `scheme` from the
    /// stream (seed, step, RESAMPLE) if `resample`, else the identity).
    pub(crate) fn ancestors_from(
        &mut self,
        log_w: &[T],
        resample: bool,
        scheme: super::Resampling,
        seed: u64,
        step: u64,
    ) {
        if resample {
            self.weights.clear();
            self.weights
                .extend(log_w.iter().map(|&lw| to_f64(lw).exp()));
            let mut rng = ParticleRng::stream(seed, step, RESAMPLE);
            resample_with(
                scheme,
                &self.weights,
                &mut rng,
                &mut self.ancestors,
                &mut self.scratch,
            );
        } else {
            for (i, a) in self.ancestors.iter_mut().enumerate() {
                *a = i;
            }
        }
    }

    /// Moves particle `x` (copied into `self.x`) with stream (seed, step, j) into column j
    /// of `next`.
    #[inline(always)]
    pub(crate) fn propagate<P: ParticleProcess<T, N> + ?Sized>(
        &mut self,
        process: &P,
        input: &<P::Model as ProcessModel<T, N>>::Input,
        dt: T,
        mut rng: ParticleRng,
        j: usize,
    ) -> Result<()> {
        let Self {
            next,
            x,
            y,
            normals,
            q,
            q_cache,
            ..
        } = self;
        if !process.sample_into(x, input, dt, &mut rng, y) {
            let model = process.model();
            estim_core::in_place::transition_into(model, x, input, dt, y);
            estim_core::in_place::process_noise_into(model, x, input, dt, q);
            let factor = match q_cache {
                Some((cached, factor, ())) if cached == q => factor,
                _ => {
                    let n = x.nrows();
                    ensure_shape(q, n, n, Stage::Prediction, Quantity::ProcessNoise)?;
                    ensure_finite(q, Stage::Prediction, Quantity::ProcessNoise)?;
                    let factor = psd_factor(q, Stage::Prediction).map_err(|_| {
                        Error::NotPositiveSemiDefinite {
                            stage: Stage::Prediction,
                            quantity: Quantity::ProcessNoise,
                        }
                    })?;
                    &mut q_cache.insert((q.clone(), factor, ())).1
                }
            };
            fill_normals(normals, &mut rng);
            y.gemv(T::one(), factor, normals, T::one());
        }
        if y.nrows() != x.nrows() {
            return Err(Error::DimensionMismatch {
                stage: Stage::Prediction,
                quantity: Quantity::FunctionValue,
                expected_rows: x.nrows(),
                expected_cols: 1,
                found_rows: y.nrows(),
                found_cols: 1,
            });
        }
        ensure_finite(y, Stage::Prediction, Quantity::FunctionValue)?;
        next.set_column(j, y);
        Ok(())
    }
}

/// The per-particle measurement log-density and the update report's innovation moments
/// (ν = Σ vᵢ (z ⊖ h(xᵢ)), S = Σ vᵢ (rᵢ − ν)(rᵢ − ν)ᵀ + Σ vᵢ R(xᵢ) for predictive weights vᵢ).
pub(crate) struct Weigher<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    x: OVector<T, N>,
    h: OVector<T, M>,
    r: OVector<T, M>,
    noise: OMatrix<T, M, M>,
    /// The last R, its Cholesky factor L and log det(2πR)/2.
    cache: Factored<T, M, T>,
    solved: OVector<T, M>,
    mean: OVector<T, M>,
    second: OMatrix<T, M, M>,
    noise_mean: OMatrix<T, M, M>,
}

impl<T: Real, N: Dim, M: Dim> Weigher<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) fn new(n: N, m: M) -> Self {
        Self {
            x: OVector::zeros_generic(n, U1),
            h: OVector::zeros_generic(m, U1),
            r: OVector::zeros_generic(m, U1),
            noise: OMatrix::zeros_generic(m, m),
            cache: None,
            solved: OVector::zeros_generic(m, U1),
            mean: OVector::zeros_generic(m, U1),
            second: OMatrix::zeros_generic(m, m),
            noise_mean: OMatrix::zeros_generic(m, m),
        }
    }

    /// log p(z | x) for column `i` of `cloud`, accumulating the innovation moments with
    /// weight `v`. Errors: h(x) of the wrong length, a NaN or +∞ log-density, a non-finite
    /// or (Gaussian path) not positive definite R.
    #[inline(always)]
    pub(crate) fn log_density<H: ParticleMeasurement<T, N, M> + ?Sized>(
        &mut self,
        sensor: &H,
        z: &OVector<T, M>,
        cloud: &OMatrix<T, N, Dyn>,
        i: usize,
        v: T,
    ) -> Result<T> {
        let model = sensor.model();
        self.x.copy_from(&cloud.column(i));
        estim_core::in_place::measure_into(model, &self.x, &mut self.h);
        ensure_shape(
            &self.h,
            z.nrows(),
            1,
            Stage::Update,
            Quantity::FunctionValue,
        )?;
        estim_core::in_place::residual_into(model, z, &self.h, &mut self.r);
        estim_core::in_place::measurement_noise_into(model, &self.x, &mut self.noise);
        let custom = sensor.log_likelihood(z, &self.x);
        let log_g = match custom {
            Some(log_g) => log_g,
            None => {
                let (_, factor, half_log_det) = match &self.cache {
                    Some((cached, ..)) if *cached == self.noise => self.cache.as_ref().unwrap(),
                    _ => {
                        let (m, stage) = (z.nrows(), Stage::Update);
                        ensure_shape(&self.noise, m, m, stage, Quantity::MeasurementNoise)?;
                        ensure_finite(&self.noise, stage, Quantity::MeasurementNoise)?;
                        let not_pd = Error::NotPositiveDefinite {
                            stage: Stage::Update,
                            quantity: Quantity::MeasurementNoise,
                        };
                        let l = Cholesky::new(self.noise.clone()).ok_or(not_pd)?.unpack();
                        let m = estim_core::scalar::real::<T>(z.nrows() as f64);
                        let mut half_log_det = m * T::two_pi().ln() / estim_core::scalar::real(2.0);
                        for k in 0..l.nrows() {
                            half_log_det += l[(k, k)].ln();
                        }
                        if !half_log_det.is_finite() {
                            return Err(not_pd);
                        }
                        self.cache.insert((self.noise.clone(), l, half_log_det))
                    }
                };
                self.solved.copy_from(&self.r);
                factor.solve_lower_triangular_mut(&mut self.solved);
                -self.solved.norm_squared() / estim_core::scalar::real(2.0) - *half_log_det
            }
        };
        #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
        let nan = log_g != log_g;
        if nan || log_g == T::one() / T::zero() {
            return Err(Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Weights,
            });
        }
        if v > T::zero() {
            self.mean.axpy(v, &self.r, T::one());
            self.second.ger(v, &self.r, &self.r, T::one());
            self.noise_mean
                .zip_apply(&self.noise, |acc, r| *acc += v * r);
        }
        Ok(log_g)
    }

    /// Writes the innovation moments accumulated with weights summing to `total` and the
    /// step's log-likelihood `increment` into `report`.
    pub(crate) fn report(&mut self, total: T, increment: T, report: &mut UpdateReport<T, M>) {
        let m = self.mean.shape_generic().0;
        report.fit(m);
        let inv = T::one() / total;
        report.innovation.copy_from(&self.mean);
        report.innovation *= inv;
        let s = &mut report.innovation_covariance;
        s.copy_from(&self.second);
        s.zip_apply(&self.noise_mean, |acc, r| *acc = (*acc + r) * inv);
        s.ger(-T::one(), &report.innovation, &report.innovation, T::one());
        estim_core::checks::symmetrize(s);
        let mut work = s.clone();
        let mut nu = report.innovation.clone();
        report.nis = inverse_quadratic_form(&mut work, &mut nu).unwrap_or(T::one() / T::zero());
        report.log_likelihood = increment;
        report.outcome = UpdateOutcome::Applied;
        report.iterations = None;
    }
}

/// log-sum-exp of `log_w`, or the typed error of a degenerate weight set (a NaN, or every
/// weight zero: no particle explains the measurement).
pub(crate) fn normaliser<T: Real>(log_w: &[T]) -> Result<T> {
    let total = super::log_sum_exp(log_w);
    if total.is_finite() {
        Ok(total)
    } else {
        Err(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Weights,
        })
    }
}

impl<T: Real, N: Dim> ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The bootstrap prediction with any [`ParticleProcess`]: a
    /// [`ProcessModel`] (Gaussian noise from Q) or a [`NonGaussian`](super::NonGaussian)
    /// sampler. Resamples first if the trigger fires. On the Gaussian path Q is evaluated at
    /// each particle (so a state-dependent Q is exact, not taken at the mean) and factorised
    /// again only when it differs from the last one factorised. On error (Δt negative or not
    /// finite, Q not finite or not PSD, f or the sampler giving a non-finite state) the filter
    /// is unchanged.
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix1, Vector1, U1};
    /// use estim_core::rand::Rng;
    /// use estim_core::{Gaussian, ProcessModel};
    /// use estim_filters::particle::{NonGaussian, ParticleFilter, ProcessSampler};
    /// use estim_filters::Estimator;
    ///
    /// /// x⁺ = x + an exponential(1) step: a one-sided random walk.
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
    /// let mut pf = ParticleFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(0.0))?, 1000, 3)?;
    /// pf.predict_with(&NonGaussian(Creep), &(), 1.0)?;
    /// assert!(pf.particles().iter().all(|&x| x > 0.0)); // every step is positive
    /// assert!((pf.state()[0] - 1.0).abs() < 0.15);      // E = 1, standard error 1/√1000
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn predict_with<P: ParticleProcess<T, N> + ?Sized>(
        &mut self,
        process: &P,
        input: &<P::Model as ProcessModel<T, N>>::Input,
        dt: T,
    ) -> Result<()> {
        ensure_time_step(dt)?;
        let count = self.count();
        let ess = effective_sample_size(&self.cloud.log_weights);
        let resample = self.when.fires(ess, count);
        let step = self.cloud.step;
        self.work.ancestors_from(
            &self.cloud.log_weights,
            resample,
            self.scheme,
            self.seed,
            step,
        );
        for j in 0..count {
            let a = self.work.ancestors[j];
            self.work.x.copy_from(&self.cloud.particles.column(a));
            let rng = ParticleRng::stream(self.seed, step, j as u64);
            self.work.propagate(process, input, dt, rng, j)?;
        }
        // Committed: nothing below fails.
        core::mem::swap(&mut self.cloud.particles, &mut self.work.next);
        if resample {
            let uniform = -estim_core::scalar::real::<T>(count as f64).ln();
            self.cloud.log_weights.fill(uniform);
        }
        self.cloud.step = step.wrapping_add(1);
        self.update_moments();
        Ok(())
    }

    /// The bootstrap update with any [`ParticleMeasurement`]: a [`MeasurementModel`]
    /// (weights from N(z ⊖ h(x); 0, R)) or a [`NonGaussian`](super::NonGaussian) likelihood.
    /// The report holds the innovation moments over the predicted cloud (ν = Σ Wᵢ (z ⊖ h(xᵢ)),
    /// S = the weighted covariance of those residuals + Σ Wᵢ R(xᵢ)), the NIS νᵀ S⁻¹ ν (+∞ if S
    /// is singular, possible only with a [`NonGaussian`](super::NonGaussian) model whose R is
    /// singular), and the step's log-likelihood estimate Δℓ = log Σ Wᵢ p(z | xᵢ); the outcome
    /// is always [`Applied`](crate::UpdateOutcome::Applied) (no gate). Runtime-size
    /// measurements allocate their per-update buffers. On error (non-finite z, h(x) of the
    /// wrong length, R not finite or, on the Gaussian path, not positive definite, a NaN or
    /// +∞ log-density, every weight zero) the filter is unchanged.
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix1, Vector1};
    /// use estim_core::{Error, Gaussian, LinearMeasurement, Quantity};
    /// use estim_filters::particle::{AdditiveGaussian, ParticleFilter};
    ///
    /// let model = LinearMeasurement { observation: Matrix1::new(1.0f64), noise: Matrix1::new(1e-4) };
    /// let sensor = AdditiveGaussian(&model); // what `Update::update` passes for any model
    /// let mut pf = ParticleFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?, 500, 1)?;
    /// let report = pf.update_with(&sensor, &Vector1::new(0.5))?;
    /// assert!(report.log_likelihood < 0.0 && pf.effective_sample_size() < 50.0);
    /// // A reading 10⁴ σ away: exp would underflow every weight to 0, the log-weights do not,
    /// // so the cloud survives (on its nearest particles).
    /// assert!(pf.update_with(&sensor, &Vector1::new(100.0)).is_ok());
    /// // A NaN reading is refused and changes nothing.
    /// let before = pf.clone();
    /// let e = pf.update_with(&sensor, &Vector1::new(f64::NAN));
    /// assert!(matches!(e, Err(Error::NonFinite { quantity: Quantity::Measurement, .. })));
    /// assert_eq!(pf, before);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn update_with<M: Dim, H: ParticleMeasurement<T, N, M> + ?Sized>(
        &mut self,
        sensor: &H,
        z: &OVector<T, M>,
    ) -> Result<UpdateReport<T, M>>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        let mut report = UpdateReport::zeros(z.shape_generic().0);
        self.update_into_with(sensor, z, &mut report)?;
        Ok(report)
    }

    /// [`update_with`](Self::update_with) into `report`.
    pub fn update_into_with<M: Dim, H: ParticleMeasurement<T, N, M> + ?Sized>(
        &mut self,
        sensor: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        ensure_finite(z, Stage::Update, Quantity::Measurement)?;
        let (n, _) = self.cloud.mean.shape_generic();
        let mut weigher = Weigher::new(n, z.shape_generic().0);
        let cloud = &self.cloud;
        let log_w = &mut self.work.log_w;
        log_w.clear();
        for (i, &lw) in cloud.log_weights.iter().enumerate() {
            let log_g = weigher.log_density(sensor, z, &cloud.particles, i, lw.exp())?;
            log_w.push(lw + log_g);
        }
        let increment = normaliser(log_w)?;
        // Committed.
        for (lw, &new) in self.cloud.log_weights.iter_mut().zip(log_w.iter()) {
            *lw = new - increment;
        }
        self.cloud.log_likelihood += increment;
        self.update_moments();
        weigher.report(T::one(), increment, report);
        Ok(())
    }
}

impl<T: Real, N: Dim, P: ProcessModel<T, N>> Predict<T, N, P> for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// [`ParticleFilter::predict_with`] with Gaussian process noise N(0, Q).
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.predict_with(&AdditiveGaussian(model), input, dt)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>> Update<T, N, M, H>
    for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// [`ParticleFilter::update_into_with`] with Gaussian measurement noise N(0, R).
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.update_into_with(&AdditiveGaussian(model), z, report)
    }
}
