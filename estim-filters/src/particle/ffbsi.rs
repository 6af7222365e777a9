//! The FFBSi particle smoother (documented on [`Ffbsi`]).

use estim_core::checks::ensure_finite;
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::{Alloc, Error, ProcessModel, Quantity, Real, Stage, error::Result};

use super::noise::{AdditiveGaussian, ParticleProcess};
use super::resample::{log_sum_exp, to_f64};
use super::rng::ParticleRng;
use super::transition::{GaussianKernel, ParticleTransition, checked_log_density};
use super::{ParticleFilter, check_count};
use crate::gaussian_filter::ensure_time_step;

/// One recorded filtering cloud and the transition that leaves it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Record<T: Real, N: Dim, U>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) particles: OMatrix<T, N, Dyn>,
    pub(crate) log_weights: Vec<T>,
    pub(crate) input: U,
    pub(crate) dt: T,
}

/// The forward-filtering backward-simulation particle smoother (FFBSi; Godsill, Doucet &
/// West 2004).
///
/// The forward pass is the user's own loop over a [`ParticleFilter`], with
/// [`Ffbsi::predict`] in place of `predict` (or [`Ffbsi::record`] before any step, e.g. an
/// [`auxiliary_step`](ParticleFilter::auxiliary_step)): each records the filtering cloud
/// {xₖⁱ, Wₖⁱ} of p(xₖ | z₁..ₖ) and the input and Δt of the transition that follows. The
/// backward pass ([`Ffbsi::smooth`]) draws M trajectories x₀..K⁽ʲ⁾ from the particle
/// approximation of the joint smoothing distribution p(x₀..K | z₁..K):
///
/// ```text
/// last:      bₖ ~ Categorical(W_K)                                  (K = the last step)
/// backward:  log w̃ⁱ = log Wₖⁱ + log p(x̃ₖ₊₁ | xₖⁱ, uₖ, Δtₖ),   bₖ ~ Categorical(w̃ / Σ w̃)
///            x̃ₖ = xₖ^bₖ                                             (k = K−1, …, 0)
/// ```
///
/// The backward weights need the transition log-density ([`ParticleTransition`]: Gaussian
/// from the model's f and Q, or the model's own [`TransitionDensity`](super::TransitionDensity);
/// a singular Q is [`Error::NotPositiveDefinite`], see [`log_transition_density`](super::log_transition_density)).
/// The cost is O(M N) density evaluations per step; on the Gaussian path f(xₖⁱ) and the
/// factor of Q are computed once per particle and step, so each of the M N evaluations is a
/// subtraction and a triangular solve.
///
/// Each trajectory j draws from the stream (seed, k, j) at step k ([`ParticleRng`]): the
/// paths do not depend on the order they are computed in, and a seed gives the same bits.
/// Unlike the filter's resampled genealogy, the backward draws re-select ancestors at every
/// step, so the early marginals do not collapse onto a few particles (path degeneracy).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::particle::{Ffbsi, ParticleFilter};
/// use estim_filters::smoother::Rts;
/// use estim_filters::{KalmanFilter, Update};
///
/// let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
/// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let mut pf = ParticleFilter::new(prior.clone(), 1000, 4)?;
/// let mut kf = KalmanFilter::new(prior);
/// let (mut ffbsi, mut rts) = (Ffbsi::new(), Rts::new());
/// for z in [0.4, -0.3, 1.1, 0.8] {
///     ffbsi.predict(&mut pf, &process, &(), 1.0)?;
///     rts.predict(&mut kf, &process, &(), 1.0)?;
///     pf.update(&sensor, &Vector1::new(z))?;
///     kf.update(&sensor, &Vector1::new(z))?;
/// }
/// let paths = ffbsi.smooth(&pf, &process, 500, 9)?;
/// let exact = rts.smooth(&kf)?;
/// assert_eq!(paths.len(), 5);
/// // Smoothed sd ≈ 0.7 at k = 0: 500 paths over 1000 particles give the mean to ≈ 0.04.
/// assert!((paths.mean(0)[0] - exact[0].mean()[0]).abs() < 0.15);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// A forward-filtering backward-simulation particle smoother over a forward pass recorded
/// with [`predict`](Self::predict) or [`record`](Self::record) (above). `U` is the
/// process input type. Memory: one n × N cloud and N log-weights per recorded step. With
/// the `serde` feature the record is a checkpoint (serialise it with the filter; a restored
/// smoother continues and smooths to the same bits).
#[derive(Clone, Debug, PartialEq)]
pub struct Ffbsi<T: Real, N: Dim, U = ()>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) records: Vec<Record<T, N, U>>,
}

impl<T: Real, N: Dim, U> Default for Ffbsi<T, N, U>
where
    DefaultAllocator: Alloc<N>,
{
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real, N: Dim, U> Ffbsi<T, N, U>
where
    DefaultAllocator: Alloc<N>,
{
    /// An empty record.
    pub fn new() -> Self {
        Self {
            records: Vec::new(),
        }
    }

    /// The number of recorded transitions K (a smoothing gives K + 1 states per path).
    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// Whether nothing is recorded.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Forgets the record.
    pub fn clear(&mut self) {
        self.records.clear();
    }

    /// Records `filter`'s cloud as the filtering distribution at step k, followed by a
    /// transition with `input` over `dt` (the step the caller makes next, by any method).
    /// Errors (the record unchanged): Δt negative or not finite; a particle count or state
    /// dimension different from the earlier records'
    /// ([`Error::DimensionMismatch`] with [`Quantity::Weights`] or [`Quantity::Mean`]).
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix1, Vector1};
    /// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
    /// use estim_filters::particle::{Ffbsi, ParticleFilter};
    ///
    /// let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
    /// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.2) };
    /// let mut apf = ParticleFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?, 300, 1)?;
    /// let mut ffbsi = Ffbsi::new();
    /// for z in [0.5, 0.9, 0.2] {
    ///     ffbsi.record(&apf, (), 1.0)?; // then any step: here an auxiliary one
    ///     apf.auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(z))?;
    /// }
    /// let paths = ffbsi.smooth(&apf, &process, 100, 2)?;
    /// assert_eq!((paths.len(), paths.paths()), (4, 100));
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn record(&mut self, filter: &ParticleFilter<T, N>, input: U, dt: T) -> Result<()> {
        ensure_time_step(dt)?;
        if let Some(first) = self.records.first() {
            check_cloud(&first.particles, filter.particles(), Stage::Prediction)?;
        }
        self.records.push(Record {
            particles: filter.particles().clone(),
            log_weights: filter.log_weights().to_vec(),
            input,
            dt,
        });
        Ok(())
    }

    /// Records `filter` (as [`record`](Self::record)) and predicts it through `process` with
    /// Gaussian noise from Q ([`Predict`](crate::Predict)). On error neither the record nor the
    /// filter changes.
    pub fn predict<P>(
        &mut self,
        filter: &mut ParticleFilter<T, N>,
        process: &P,
        input: &U,
        dt: T,
    ) -> Result<()>
    where
        P: ProcessModel<T, N, Input = U> + Sync + ?Sized,
        U: Clone + Sync,
    {
        self.predict_with(filter, &AdditiveGaussian(process), input, dt)
    }

    /// [`predict`](Self::predict) with any [`ParticleProcess`] (e.g. a
    /// [`NonGaussian`](super::NonGaussian) sampler).
    pub fn predict_with<P>(
        &mut self,
        filter: &mut ParticleFilter<T, N>,
        process: &P,
        input: &U,
        dt: T,
    ) -> Result<()>
    where
        P: ParticleProcess<T, N> + Sync + ?Sized,
        P::Model: ProcessModel<T, N, Input = U>,
        U: Clone + Sync,
    {
        self.record(filter, input.clone(), dt)?;
        if let Err(error) = filter.predict_with(process, input, dt) {
            self.records.pop();
            return Err(error);
        }
        Ok(())
    }

    /// M = `paths` trajectories from the smoothing distribution, with Gaussian transition
    /// densities from `process`'s f and Q; `last` is the filter at the final step K (after its
    /// last update). See [`smooth_with`](Self::smooth_with).
    pub fn smooth<P>(
        &self,
        last: &ParticleFilter<T, N>,
        process: &P,
        paths: usize,
        seed: u64,
    ) -> Result<SmoothedPaths<T, N>>
    where
        P: ProcessModel<T, N, Input = U> + ?Sized,
    {
        self.smooth_with(last, &AdditiveGaussian(process), paths, seed)
    }

    /// M = `paths` trajectories x₀..K from the smoothing distribution by backward simulation
    /// (see [`Ffbsi`]) through any [`ParticleTransition`], seeded by `seed`.
    ///
    /// Errors (nothing changes: the record is only read): `paths` = 0, or so many that the
    /// paths could not be allocated ([`SampleCount`](estim_core::Parameter::SampleCount));
    /// `last` of another particle count or dimension ([`Error::DimensionMismatch`]); a
    /// transition without a density (singular Q: [`Error::NotPositiveDefinite`] with
    /// [`Quantity::ProcessNoise`]) or f, Q not finite; a model density NaN or +∞, or a recorded
    /// state from which no particle can reach the drawn successor (every backward weight zero):
    /// [`Error::NonFinite`] with [`Quantity::Weights`]. Every error is at [`Stage::Smoothing`]
    /// except the count checks.
    pub fn smooth_with<P>(
        &self,
        last: &ParticleFilter<T, N>,
        process: &P,
        paths: usize,
        seed: u64,
    ) -> Result<SmoothedPaths<T, N>>
    where
        P: ParticleTransition<T, N> + ?Sized,
        P::Model: ProcessModel<T, N, Input = U>,
    {
        // One n × paths matrix per recorded step and the last.
        let per_path = (self.records.len() + 1).saturating_mul(last.particles().nrows());
        check_count::<T>(paths, per_path)?;
        if let Some(first) = self.records.first() {
            check_cloud(&first.particles, last.particles(), Stage::Smoothing)?;
        }
        let steps = self.records.len();
        let (n, _) = last.particles().shape_generic();
        let count = last.count();
        let mut out: Vec<OMatrix<T, N, Dyn>> = (0..=steps)
            .map(|_| OMatrix::zeros_generic(n, Dyn(paths)))
            .collect();
        // The last step: bⱼ ~ W_K by inversion of the cumulative weights.
        let mut cumulative = Vec::with_capacity(count);
        let mut total = 0.0;
        for &lw in last.log_weights() {
            total += to_f64(lw).exp();
            cumulative.push(total);
        }
        for j in 0..paths {
            let u = ParticleRng::stream(seed, steps as u64, j as u64).uniform() * total;
            let b = cumulative.partition_point(|&c| c < u).min(count - 1);
            out[steps].set_column(j, &last.particles().column(b));
        }
        let mut x = OVector::zeros_generic(n, U1);
        let mut next = OVector::zeros_generic(n, U1);
        let mut work = OVector::zeros_generic(n, U1);
        let mut kernels: Vec<GaussianKernel<T, N>> = Vec::with_capacity(count);
        let mut log_w = Vec::with_capacity(count);
        let stage = Stage::Smoothing;
        for k in (0..steps).rev() {
            let record = &self.records[k];
            let own = process.has_own_density();
            if !own {
                kernels.clear();
                for i in 0..count {
                    x.copy_from(&record.particles.column(i));
                    let kernel = GaussianKernel::at(
                        process.model(),
                        &x,
                        &record.input,
                        record.dt,
                        kernels.last(),
                        stage,
                    )?;
                    kernels.push(kernel);
                }
            }
            let (done, todo) = out.split_at_mut(k + 1);
            let (current, following) = (&mut done[k], &todo[0]);
            for j in 0..paths {
                next.copy_from(&following.column(j));
                log_w.clear();
                for i in 0..count {
                    let log_p = if own {
                        x.copy_from(&record.particles.column(i));
                        let value = process
                            .log_transition(&next, &x, &record.input, record.dt)
                            .unwrap_or(T::zero());
                        checked_log_density(value, stage)?
                    } else {
                        kernels[i].log_density(&next, &mut work)
                    };
                    log_w.push(record.log_weights[i] + log_p);
                }
                let norm = log_sum_exp(&log_w);
                if !norm.is_finite() {
                    return Err(Error::NonFinite {
                        stage,
                        quantity: Quantity::Weights,
                    });
                }
                let u = ParticleRng::stream(seed, k as u64, j as u64).uniform();
                let b = draw(&log_w, norm, u);
                current.set_column(j, &record.particles.column(b));
            }
        }
        for states in &out {
            ensure_finite(states, stage, Quantity::Mean)?;
        }
        Ok(SmoothedPaths { states: out })
    }
}

/// The index whose cumulative normalised weight first reaches `u` ∈ (0, 1) (the last
/// positive-weight index if round-off leaves the total short of `u`).
fn draw<T: Real>(log_w: &[T], norm: T, u: f64) -> usize {
    let mut cumulative = 0.0;
    let mut last_positive = 0;
    for (i, &lw) in log_w.iter().enumerate() {
        let w = to_f64(lw - norm).exp();
        if w > 0.0 {
            last_positive = i;
            cumulative += w;
            if cumulative >= u {
                return i;
            }
        }
    }
    last_positive
}

/// `found` has `expected`'s shape (the same state dimension and particle count).
pub(crate) fn check_cloud<T: Real, N: Dim>(
    expected: &OMatrix<T, N, Dyn>,
    found: &OMatrix<T, N, Dyn>,
    stage: Stage,
) -> Result<()>
where
    DefaultAllocator: Alloc<N>,
{
    if expected.shape() == found.shape() {
        return Ok(());
    }
    let quantity = if expected.nrows() == found.nrows() {
        Quantity::Weights
    } else {
        Quantity::Mean
    };
    Err(Error::DimensionMismatch {
        stage,
        quantity,
        expected_rows: expected.nrows(),
        expected_cols: expected.ncols(),
        found_rows: found.nrows(),
        found_cols: found.ncols(),
    })
}

/// M smoothed trajectories x₀..K⁽ʲ⁾ (equally weighted draws from the particle approximation
/// of p(x₀..K | z₁..K)), stored per step as an n × M matrix with one column per trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothedPaths<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    states: Vec<OMatrix<T, N, Dyn>>,
}

impl<T: Real, N: Dim> SmoothedPaths<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The number of steps K + 1.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// Whether there are no steps (never, for a smoother's output).
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// The number of trajectories M.
    pub fn paths(&self) -> usize {
        self.states.first().map_or(0, |s| s.ncols())
    }

    /// The states at step k, one column per trajectory (n × M).
    ///
    /// # Panics
    /// If k > K.
    #[track_caller]
    pub fn at(&self, k: usize) -> &OMatrix<T, N, Dyn> {
        &self.states[k]
    }

    /// The smoothed mean at step k: x̄ₖ = (1/M) Σⱼ xₖ⁽ʲ⁾.
    ///
    /// # Panics
    /// If k > K.
    #[track_caller]
    pub fn mean(&self, k: usize) -> OVector<T, N> {
        let states = &self.states[k];
        let scale = T::one() / estim_core::scalar::real::<T>(states.ncols() as f64);
        let mut mean = OVector::zeros_generic(states.shape_generic().0, U1);
        for column in states.column_iter() {
            mean.axpy(scale, &column, T::one());
        }
        mean
    }

    /// The smoothed covariance at step k: (1/M) Σⱼ (xₖ⁽ʲ⁾ − x̄ₖ)(xₖ⁽ʲ⁾ − x̄ₖ)ᵀ (the moments of
    /// the equally weighted trajectories, as the filter's moments are of its weighted cloud).
    ///
    /// # Panics
    /// If k > K.
    #[track_caller]
    pub fn covariance(&self, k: usize) -> OMatrix<T, N, N> {
        let states = &self.states[k];
        let mean = self.mean(k);
        let scale = T::one() / estim_core::scalar::real::<T>(states.ncols() as f64);
        let (n, _) = states.shape_generic();
        let mut covariance = OMatrix::zeros_generic(n, n);
        let mut d = OVector::zeros_generic(n, U1);
        for column in states.column_iter() {
            d.copy_from(&column);
            d -= &mean;
            covariance.ger(scale, &d, &d, T::one());
        }
        covariance
    }
}
