//! The bootstrap filter's prediction and update, and their step-trait impls.

use core::marker::PhantomData;

use estim_core::alloc::{DimAlloc, SizeFamily};
use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::linalg::inverse_quadratic_form;
use estim_core::nalgebra::{
    Cholesky, DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1,
};
use estim_core::{
    Alloc, Error, MeasurementModel, ProcessModel, Quantity, Real, Stage, error::Result, psd_factor,
};

use super::chunks::{
    CHUNK, ChunkWork, Factored, StateScratch, chunk_count, columns, dmatrix, dvector, first_error,
    for_chunks, for_chunks1, for_states, lse_combine, lse_partial, parallel, range, with_state,
};
use super::noise::{AdditiveGaussian, ParticleMeasurement, ParticleProcess};
use super::resample::{ess_of_weights, resample_with, to_f64};
use super::rng::{ParticleRng, RESAMPLE};
use super::{ParticleFilter, fill_normals};
use crate::gaussian_filter::ensure_time_step;
use crate::report::{UpdateOutcome, UpdateReport};
use crate::traits::{Predict, Update};

/// Buffers of the steps (no state: a step overwrites what it reads). Everything kept per
/// chunk is of runtime size (see [`ChunkWork`]), so the chunks can run on rayon's threads.
#[derive(Clone, Debug)]
pub(crate) struct Work<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The propagated cloud, swapped in on success.
    pub(crate) next: OMatrix<T, N, Dyn>,
    /// New log-weights (update) or first-stage log-weights (auxiliary).
    pub(crate) log_w: Vec<T>,
    /// The auxiliary filter's first-stage weights in f64, for resampling.
    pub(crate) weights: Vec<f64>,
    pub(crate) ancestors: Vec<usize>,
    /// The auxiliary filter's first-stage log-densities log ηᵢ.
    pub(crate) log_eta: Vec<T>,
    pub(crate) scratch: Vec<f64>,
    /// One scratch and partial-sum set per chunk of particles.
    pub(crate) chunks: Vec<ChunkWork<T>>,
    /// One measurement scratch per chunk (used as such for runtime-size measurements).
    pub(crate) sensors: Vec<SensorScratch<T, Dyn>>,
    /// The report's S and ν, copied for the NIS solve.
    nis_s: DMatrix<T>,
    nis_nu: DVector<T>,
}

impl<T: Real, N: Dim> Work<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) fn new(n: N, count: usize) -> Self {
        let chunks = chunk_count(count);
        Self {
            next: OMatrix::zeros_generic(n, Dyn(count)),
            log_w: vec![T::zero(); count],
            weights: vec![0.0; count],
            ancestors: (0..count).collect(),
            log_eta: vec![T::zero(); count],
            scratch: Vec::with_capacity(2 * count),
            chunks: (0..chunks).map(|_| ChunkWork::new(n.value())).collect(),
            sensors: (0..chunks)
                .map(|_| SensorScratch::<T, Dyn>::new(Dyn(0)))
                .collect(),
            nis_s: dmatrix(0, 0),
            nis_nu: dvector(0),
        }
    }

    /// Resizes the buffers for dimension n and `count` particles if they differ.
    pub(crate) fn fit(&mut self, n: N, count: usize) {
        if self.next.shape() != (n.value(), count) {
            *self = Self::new(n, count);
        }
    }

    /// Ancestors from the normalised weights `weights` (resampled by `scheme` from the stream
    /// (seed, step, RESAMPLE) if `resample`, else the identity).
    /// Errors: those of [`resample`](super::resample) (never for a filter's own weights).
    pub(crate) fn ancestors_from(
        ancestors: &mut [usize],
        scratch: &mut Vec<f64>,
        weights: &[f64],
        resample: bool,
        scheme: super::Resampling,
        seed: u64,
        step: u64,
    ) -> Result<()> {
        if resample {
            let mut rng = ParticleRng::stream(seed, step, RESAMPLE);
            resample_with(scheme, weights, &mut rng, ancestors, scratch)
        } else {
            for (i, a) in ancestors.iter_mut().enumerate() {
                *a = i;
            }
            Ok(())
        }
    }

    /// Propagates the particles `ancestors[j]` of `particles` into column j of `next`, with
    /// the streams (seed, step, j), by chunks. Errors: the first failing particle's (in
    /// particle order), `next` then partly written.
    pub(crate) fn propagate_all<P: ParticleProcess<T, N> + Sync + ?Sized>(
        &mut self,
        particles: &OMatrix<T, N, Dyn>,
        process: &P,
        input: &<P::Model as ProcessModel<T, N>>::Input,
        dt: T,
        seed: u64,
        step: u64,
    ) -> Result<()>
    where
        <P::Model as ProcessModel<T, N>>::Input: Sync,
    {
        let (n, _) = particles.shape_generic();
        let count = particles.ncols();
        let ancestors = &self.ancestors;
        let particles = particles.as_slice();
        let mut placeholder = Vec::new();
        let out = columns(self.next.as_mut_slice(), &mut placeholder, n.value(), count);
        for_chunks1(
            parallel(count),
            &mut self.chunks,
            out,
            n.value().max(1) * CHUNK,
            |c, w, out| {
                let range = range(c, count);
                let ancestors = &ancestors[range.clone()];
                w.error = with_state(&mut w.state, n, |s| {
                    let chunk = Chunk {
                        first: range.start,
                        seed,
                        step,
                    };
                    propagate_chunk(s, chunk, ancestors, particles, out, process, input, dt)
                });
            },
        );
        first_error(self.chunks.iter_mut())
    }

    /// The weighing pass over `cloud`, by chunks: `log_w[i] = baseᵢ + log p(z | xᵢ)` with
    /// (vᵢ, baseᵢ) = `prior(i)`, vᵢ the predictive weight of the report's moments (added to
    /// each chunk's partial sums). Returns the log-sum-exp of the new values. Errors: the
    /// first failing particle's (in particle order), or the typed error of a degenerate weight
    /// set (every new value −∞: no particle explains the measurement).
    pub(crate) fn weigh<M, H, F>(
        &mut self,
        sensor: &H,
        z: &OVector<T, M>,
        cloud: &OMatrix<T, N, Dyn>,
        log_w: &mut [T],
        prior: F,
    ) -> Result<T>
    where
        M: Dim,
        H: ParticleMeasurement<T, N, M> + Sync + ?Sized,
        F: Fn(usize) -> (T, T) + Sync,
        DefaultAllocator: Alloc<N, M>,
    {
        let (n, _) = cloud.shape_generic();
        let m = z.shape_generic().0;
        let count = log_w.len();
        let (nn, cloud, z) = (n.value(), cloud.as_slice(), z.as_slice());
        let mut sensors = core::mem::take(&mut self.sensors);
        sensors.resize_with(self.chunks.len(), || SensorScratch::<T, Dyn>::new(Dyn(0)));
        for_chunks(
            parallel(count),
            &mut self.chunks,
            log_w,
            CHUNK,
            &mut sensors,
            1,
            |c, w, out, kept| {
                let mm = m.value();
                w.sums.clear();
                w.sums.resize(mm * (1 + 2 * mm), T::zero());
                w.total_v = T::zero();
                let ChunkWork {
                    state,
                    sums,
                    total_v,
                    ..
                } = w;
                let (innovation, rest) = sums.split_at_mut(mm);
                let (second, noise) = rest.split_at_mut(mm * mm);
                let mut sums = Sums {
                    m: mm,
                    innovation,
                    second,
                    noise,
                    total_v,
                };
                let first = c * CHUNK;
                let cloud = &cloud[first * nn..(first + out.len()) * nn];
                let error = with_state(state, n, |s| {
                    with_sensor::<T, M, _>(&mut kept[0], m, |ms| {
                        ms.z.as_mut_slice().copy_from_slice(z);
                        weigh_chunk::<T, N, M, H, F>(
                            s, ms, sensor, first, cloud, out, &prior, &mut sums,
                        )
                    })
                });
                w.error = error;
                w.lse = lse_partial(out, &mut w.terms);
            },
        );
        self.sensors = sensors;
        first_error(self.chunks.iter_mut())?;
        let total = lse_combine(self.chunks.iter().map(|w| w.lse));
        if total.is_finite() {
            Ok(total)
        } else {
            Err(Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Weights,
            })
        }
    }

    /// Writes the innovation moments accumulated by the last [`weigh`](Self::weigh) (chunk
    /// partials added in order, normalised by their total Σ vᵢ) and the step's log-likelihood
    /// `increment` into `report`: ν = Σ vᵢ rᵢ / Σ vᵢ, S = (Σ vᵢ rᵢ rᵢᵀ + Σ vᵢ Rᵢ)/Σ vᵢ − ν νᵀ,
    /// NIS = νᵀ S⁻¹ ν (+∞ if S is singular).
    pub(crate) fn report<M: Dim>(&mut self, m: M, increment: T, report: &mut UpdateReport<T, M>)
    where
        DefaultAllocator: Alloc<N, M>,
    {
        report.fit(m);
        let mm = m.value();
        let s = &mut report.innovation_covariance;
        report.innovation.fill(T::zero());
        s.fill(T::zero());
        let mut total = T::zero();
        for w in &self.chunks {
            let (innovation, rest) = w.sums.split_at(mm);
            let (second, noise) = rest.split_at(mm * mm);
            for (a, &b) in report.innovation.iter_mut().zip(innovation) {
                *a += b;
            }
            for ((a, &b), &r) in s.iter_mut().zip(second).zip(noise) {
                *a += b + r;
            }
            total += w.total_v;
        }
        let inv = T::one() / total;
        report.innovation *= inv;
        *s *= inv;
        s.ger(-T::one(), &report.innovation, &report.innovation, T::one());
        estim_core::checks::symmetrize(s);
        let nis = if M::try_to_usize().is_some() {
            // Static: copies on the stack.
            inverse_quadratic_form(&mut s.clone_owned(), &mut report.innovation.clone_owned())
        } else {
            if self.nis_nu.nrows() != mm {
                self.nis_s = dmatrix(mm, mm);
                self.nis_nu = dvector(mm);
            }
            for (a, &b) in self.nis_s.iter_mut().zip(s.iter()) {
                *a = b;
            }
            for (a, &b) in self.nis_nu.iter_mut().zip(report.innovation.iter()) {
                *a = b;
            }
            inverse_quadratic_form(&mut self.nis_s, &mut self.nis_nu)
        };
        report.nis = nis.unwrap_or(T::one() / T::zero());
        report.log_likelihood = increment;
        report.outcome = UpdateOutcome::Applied;
        report.iterations = None;
    }

    /// The log-sum-exp of `values` by chunks (see [`lse_combine`]), or the typed error of a
    /// degenerate weight set (every value −∞).
    pub(crate) fn normaliser(&mut self, values: &[T]) -> Result<T> {
        let count = values.len();
        for_states(parallel(count), &mut self.chunks, |c, w| {
            w.lse = lse_partial(&values[range(c, count)], &mut w.terms);
        });
        let total = lse_combine(self.chunks.iter().map(|w| w.lse));
        if total.is_finite() {
            Ok(total)
        } else {
            Err(Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Weights,
            })
        }
    }

    /// log Wᵢ = vᵢ − `total` into `log_weights` and Wᵢ = eᵢ exp(mₐ − `total`) (in f64) into
    /// `weights`, by chunks, where vᵢ = `self.log_w[i]` and eᵢ = exp(vᵢ − mₐ), mₐ are the terms
    /// and chunk maxima that the log-sum-exp of those values (the last [`weigh`](Self::weigh)
    /// or [`normaliser`](Self::normaliser), `total`) left: one `exp` per particle for the
    /// normaliser and the weights together. Wᵢ equals exp(log Wᵢ) to a few ulps; it underflows
    /// to 0 only where exp(log Wᵢ) would be below the smallest normal f64 (the log-weights
    /// keep such particles alive).
    pub(crate) fn normalise(&mut self, total: T, log_weights: &mut [T], weights: &mut [f64]) {
        let log_w = &self.log_w;
        let count = log_w.len();
        for_chunks(
            parallel(count),
            &mut self.chunks,
            log_weights,
            CHUNK,
            weights,
            CHUNK,
            |c, w, lw, wt| {
                let values = &log_w[c * CHUNK..];
                let scale = to_f64(w.lse.0 - total).exp();
                for ((lw, wt), (&v, &e)) in lw.iter_mut().zip(wt).zip(values.iter().zip(&w.terms)) {
                    *lw = v - total;
                    *wt = e * scale;
                }
            },
        );
    }

    /// Wᵢ = eᵢ exp(mₐ − `total`) into `self.weights` from the terms of the last
    /// [`normaliser`](Self::normaliser) pass, whose result is `total` (see
    /// [`normalise`](Self::normalise)).
    pub(crate) fn weights_from_terms(&mut self, total: T) {
        self.weights.clear();
        for w in &self.chunks {
            let scale = to_f64(w.lse.0 - total).exp();
            self.weights.extend(w.terms.iter().map(|&e| e * scale));
        }
    }
}

/// Which particles a chunk holds and the names of their streams: particle `first + k` draws
/// from (seed, step, first + k).
#[derive(Clone, Copy)]
struct Chunk {
    first: usize,
    seed: u64,
    step: u64,
}

/// Propagates one chunk: particle `ancestors[k]` of `particles` (n per particle, one after
/// another) into the k-th n-slice of `out`. The first error in particle order, if any (`out`
/// then partly written).
///
/// Not inlined on purpose: as a function of its own, its reference arguments are known not to
/// alias one another, so what depends only on the input (e.g. a cos(ω k) term of f) is
/// computed once per chunk rather than once per particle, as a hand-written loop gets it.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn propagate_chunk<T: Real, N: Dim, P: ParticleProcess<T, N> + ?Sized>(
    s: &mut StateScratch<T, N>,
    chunk: Chunk,
    ancestors: &[usize],
    particles: &[T],
    out: &mut [T],
    process: &P,
    input: &<P::Model as ProcessModel<T, N>>::Input,
    dt: T,
) -> Option<Error>
where
    DefaultAllocator: Alloc<N>,
{
    let nn = s.x.nrows();
    if nn == 0 {
        // A zero-dimensional state: nothing to copy, but the process still runs (its errors
        // are reported). A loop of its own keeps the zip below the tight indexed loop.
        for k in 0..ancestors.len() {
            let rng = ParticleRng::stream(chunk.seed, chunk.step, (chunk.first + k) as u64);
            if let Err(e) = propagate(s, process, input, dt, rng) {
                return Some(e);
            }
        }
        return None;
    }
    for ((k, &a), column) in ancestors.iter().enumerate().zip(out.chunks_exact_mut(nn)) {
        s.x.as_mut_slice()
            .copy_from_slice(&particles[a * nn..(a + 1) * nn]);
        let rng = ParticleRng::stream(chunk.seed, chunk.step, (chunk.first + k) as u64);
        if let Err(e) = propagate(s, process, input, dt, rng) {
            return Some(e);
        }
        column.copy_from_slice(s.y.as_slice());
    }
    None
}

/// y ← y + L e for L n × n column-major: column by column, yᵣ ← Lᵣⱼ eⱼ + yᵣ, the operations
/// (and so the bits) of nalgebra's `gemv(1, L, e, 1)` without its generic shape checks.
#[cfg_attr(not(debug_assertions), inline(always))]
fn add_product<T: Real>(y: &mut [T], l: &[T], e: &[T]) {
    let n = y.len();
    if n == 0 {
        return;
    }
    for (column, &ej) in l.chunks_exact(n).zip(e) {
        for (yr, &lr) in y.iter_mut().zip(column) {
            *yr = lr * ej + *yr;
        }
    }
}

/// Solves L x = b in place for L m × m lower triangular, column-major, with a nonzero
/// diagonal: the operations (and so the bits) of nalgebra's `solve_lower_triangular_mut`
/// (xᵢ = bᵢ / Lᵢᵢ, then bᵣ ← −xᵢ Lᵣᵢ + bᵣ below) without its generic shape checks. Stops at a
/// zero diagonal entry, as nalgebra's does.
#[cfg_attr(not(debug_assertions), inline(always))]
fn solve_lower_in_place<T: Real>(l: &[T], b: &mut [T]) {
    let m = b.len();
    for i in 0..m {
        let column = &l[i * m..(i + 1) * m];
        let diag = column[i];
        if diag == T::zero() {
            return;
        }
        let coeff = b[i] / diag;
        b[i] = coeff;
        for (br, &lr) in b[i + 1..].iter_mut().zip(&column[i + 1..]) {
            *br = -coeff * lr + *br;
        }
    }
}

/// Weighs one chunk: `out[k] = baseₖ + log p(z | xₖ)` for the particles of `cloud` (n per
/// particle, one after another; particle index `first + k`), with (vₖ, baseₖ) =
/// `prior(first + k)`, vₖ added to `sums`. The first error in particle order, if any.
///
/// Not inlined on purpose (see [`propagate_chunk`]).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn weigh_chunk<T, N, M, H, F>(
    s: &mut StateScratch<T, N>,
    ms: &mut SensorScratch<T, M>,
    sensor: &H,
    first: usize,
    cloud: &[T],
    out: &mut [T],
    prior: &F,
    sums: &mut Sums<'_, T>,
) -> Option<Error>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: ParticleMeasurement<T, N, M> + ?Sized,
    F: Fn(usize) -> (T, T),
    DefaultAllocator: Alloc<N, M>,
{
    let nn = s.x.nrows();
    let mut weigh = |k: usize, o: &mut T, x: &[T]| {
        let (v, base) = prior(first + k);
        s.x.as_mut_slice().copy_from_slice(x);
        log_density::<T, N, M, H>(ms, sensor, &s.x, v, sums).map(|log_g| *o = base + log_g)
    };
    let weighed = if nn == 0 {
        // A zero-dimensional state: every particle is empty.
        out.iter_mut()
            .enumerate()
            .try_for_each(|(k, o)| weigh(k, o, &[]))
    } else {
        out.iter_mut()
            .enumerate()
            .zip(cloud.chunks_exact(nn))
            .try_for_each(|((k, o), x)| weigh(k, o, x))
    };
    weighed.err()
}

/// Moves particle `s.x` with stream `rng` into `s.y`.
#[cfg_attr(not(debug_assertions), inline(always))]
fn propagate<T: Real, N: Dim, P: ParticleProcess<T, N> + ?Sized>(
    s: &mut StateScratch<T, N>,
    process: &P,
    input: &<P::Model as ProcessModel<T, N>>::Input,
    dt: T,
    mut rng: ParticleRng,
) -> Result<()>
where
    DefaultAllocator: Alloc<N>,
{
    let StateScratch {
        x,
        y,
        normals,
        q,
        q_cache,
    } = s;
    if !process.sample_into(x, input, dt, &mut rng, y) {
        let model = process.model();
        estim_core::model::transition_into(model, x, input, dt, y);
        estim_core::model::process_noise_into(model, x, input, dt, q);
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
        if y.nrows() == x.nrows() {
            fill_normals(normals, &mut rng);
            add_product(y.as_mut_slice(), factor.as_slice(), normals.as_slice());
        }
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
    ensure_finite(y, Stage::Prediction, Quantity::FunctionValue)
}

/// The measurement scratch of a chunk: h(x), the residual, R, the last R with its Cholesky
/// factor and log det(2πR)/2, and a solve buffer.
#[derive(Clone, Debug)]
pub(crate) struct SensorScratch<T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    /// A copy of the reading z.
    z: OVector<T, M>,
    x_h: OVector<T, M>,
    r: OVector<T, M>,
    noise: OMatrix<T, M, M>,
    cache: Factored<T, M, T>,
    solved: OVector<T, M>,
}

impl<T: Real, M: Dim> SensorScratch<T, M>
where
    DefaultAllocator: Alloc<M>,
{
    fn new(m: M) -> Self {
        Self {
            z: OVector::zeros_generic(m, U1),
            x_h: OVector::zeros_generic(m, U1),
            r: OVector::zeros_generic(m, U1),
            noise: OMatrix::zeros_generic(m, m),
            cache: None,
            solved: OVector::zeros_generic(m, U1),
        }
    }

    /// Whether every buffer has dimension m (a model's default `_into` method may reshape a
    /// runtime-size buffer on a failed update).
    fn fits(&self, m: usize) -> bool {
        self.z.nrows() == m
            && self.x_h.nrows() == m
            && self.r.nrows() == m
            && self.solved.nrows() == m
            && self.noise.shape() == (m, m)
    }
}

/// [`SensorScratch`] as a function of the measurement dimension.
struct SensorFamily<T>(PhantomData<T>);

impl<T: Real> SizeFamily<Dyn> for SensorFamily<T> {
    type Of<Z: Dim>
        = SensorScratch<T, Z>
    where
        DefaultAllocator: Alloc<Z, Dyn>;
}

/// Runs `f` with measurement scratch of dimension m: `kept` when M is `Dyn`, a fresh one on
/// the stack when M is static.
#[cfg_attr(not(debug_assertions), inline(always))]
fn with_sensor<T: Real, M: Dim, R>(
    kept: &mut SensorScratch<T, Dyn>,
    m: M,
    f: impl FnOnce(&mut SensorScratch<T, M>) -> R,
) -> R
where
    DefaultAllocator: Alloc<M>,
{
    if M::try_to_usize().is_some() {
        return f(&mut SensorScratch::new(m));
    }
    if !kept.fits(m.value()) {
        *kept = SensorScratch::<T, Dyn>::new(Dyn(m.value()));
    }
    match <DefaultAllocator as DimAlloc<M>>::runtime_sized::<Dyn, SensorFamily<T>>(kept) {
        Some(kept) => f(kept),
        None => f(&mut SensorScratch::new(m)),
    }
}

/// A chunk's innovation-moment sums: Σ vᵢ rᵢ, Σ vᵢ rᵢ rᵢᵀ and Σ vᵢ Rᵢ flat (see
/// [`ChunkWork::sums`]), and Σ vᵢ.
struct Sums<'a, T: Real> {
    m: usize,
    innovation: &'a mut [T],
    second: &'a mut [T],
    noise: &'a mut [T],
    total_v: &'a mut T,
}

/// log p(z | x) for the particle `x`, adding its residual and R with weight `v` (if positive) to
/// `sums`. Errors: h(x) or its residual of the wrong length, a NaN or +∞ log-density (a bug in the
/// model, e.g. h(x) NaN: [`Quantity::FunctionValue`], told apart from the [`Quantity::Weights`] of
/// a measurement no particle explains), a non-finite or (Gaussian path) not positive definite R.
#[cfg_attr(not(debug_assertions), inline(always))]
fn log_density<T, N, M, H>(
    ms: &mut SensorScratch<T, M>,
    sensor: &H,
    x: &OVector<T, N>,
    v: T,
    sums: &mut Sums<'_, T>,
) -> Result<T>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: ParticleMeasurement<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let model = sensor.model();
    let z = &ms.z;
    estim_core::model::measure_into(model, x, &mut ms.x_h);
    ensure_shape(
        &ms.x_h,
        z.nrows(),
        1,
        Stage::Update,
        Quantity::FunctionValue,
    )?;
    model.residual_into(z, &ms.x_h, &mut ms.r);
    ensure_shape(&ms.r, z.nrows(), 1, Stage::Update, Quantity::Innovation)?;
    estim_core::model::measurement_noise_into(model, x, &mut ms.noise);
    let log_g = match sensor.log_likelihood(z, x) {
        Some(log_g) => log_g,
        None => {
            let (_, factor, half_log_det) = match &ms.cache {
                Some((cached, ..)) if *cached == ms.noise => ms.cache.as_ref().unwrap(),
                _ => {
                    let (m, stage) = (z.nrows(), Stage::Update);
                    ensure_shape(&ms.noise, m, m, stage, Quantity::MeasurementNoise)?;
                    ensure_finite(&ms.noise, stage, Quantity::MeasurementNoise)?;
                    let not_pd = Error::NotPositiveDefinite {
                        stage: Stage::Update,
                        quantity: Quantity::MeasurementNoise,
                    };
                    let l = Cholesky::new(ms.noise.clone()).ok_or(not_pd)?.unpack();
                    let m = estim_core::scalar::real::<T>(z.nrows() as f64);
                    let mut half_log_det = m * T::two_pi().ln() / estim_core::scalar::real(2.0);
                    for k in 0..l.nrows() {
                        half_log_det += l[(k, k)].ln();
                    }
                    if !half_log_det.is_finite() {
                        return Err(not_pd);
                    }
                    ms.cache.insert((ms.noise.clone(), l, half_log_det))
                }
            };
            ms.solved.copy_from(&ms.r);
            solve_lower_in_place(factor.as_slice(), ms.solved.as_mut_slice());
            -ms.solved.norm_squared() / estim_core::scalar::real(2.0) - *half_log_det
        }
    };
    #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
    let nan = log_g != log_g;
    if nan || log_g == T::one() / T::zero() {
        return Err(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::FunctionValue,
        });
    }
    if v > T::zero() {
        let m = sums.m;
        let (innovation, second, noise) =
            (&mut *sums.innovation, &mut *sums.second, &mut *sums.noise);
        for (a, &r) in innovation.iter_mut().zip(ms.r.iter()) {
            *a += v * r;
        }
        for col in 0..m {
            let vr = v * ms.r[col];
            for row in 0..m {
                second[col * m + row] += vr * ms.r[row];
                noise[col * m + row] += v * ms.noise[(row, col)];
            }
        }
        *sums.total_v += v;
    }
    Ok(log_g)
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
    pub fn predict_with<P: ParticleProcess<T, N> + Sync + ?Sized>(
        &mut self,
        process: &P,
        input: &<P::Model as ProcessModel<T, N>>::Input,
        dt: T,
    ) -> Result<()>
    where
        <P::Model as ProcessModel<T, N>>::Input: Sync,
    {
        ensure_time_step(dt)?;
        let count = self.count();
        let weights = &self.cloud.weights;
        let resample = self.when.fires(|| ess_of_weights(weights), count);
        let step = self.cloud.step;
        let work = &mut self.work;
        Work::<T, N>::ancestors_from(
            &mut work.ancestors,
            &mut work.scratch,
            &self.cloud.weights,
            resample,
            self.scheme,
            self.seed,
            step,
        )?;
        work.propagate_all(&self.cloud.particles, process, input, dt, self.seed, step)?;
        // Committed: nothing below fails.
        core::mem::swap(&mut self.cloud.particles, &mut self.work.next);
        if resample {
            self.cloud.set_uniform();
        }
        self.cloud.step = step.wrapping_add(1);
        // Equal weights after resampling: the first particle is the first of the largest.
        self.update_moments_about(resample.then_some(0));
        Ok(())
    }

    /// The bootstrap update with any [`ParticleMeasurement`]: a [`MeasurementModel`]
    /// (weights from N(z ⊖ h(x); 0, R)) or a [`NonGaussian`](super::NonGaussian) likelihood.
    /// The report holds the innovation moments over the predicted cloud (ν = Σ Wᵢ (z ⊖ h(xᵢ)),
    /// S = the weighted covariance of those residuals + Σ Wᵢ R(xᵢ)), the NIS νᵀ S⁻¹ ν (+∞ if S
    /// is singular, possible only with a [`NonGaussian`](super::NonGaussian) model whose R is
    /// singular), and the step's log-likelihood estimate Δℓ = log Σ Wᵢ p(z | xᵢ); the outcome
    /// is always [`Applied`](crate::UpdateOutcome::Applied) (no gate). Runtime-size
    /// measurements size their per-chunk buffers at the first update with that length (and
    /// when R changes), then allocate nothing. On error (non-finite z, h(x) of the
    /// wrong length, a residual z ⊖ h(x) of the wrong length ([`Quantity::Innovation`]), R not
    /// finite or, on the Gaussian path, not positive definite, a NaN or
    /// +∞ log-density — h(x) NaN included — with [`Quantity::FunctionValue`], every weight
    /// zero — a reading no particle explains — with [`Quantity::Weights`]) the filter is
    /// unchanged.
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
    pub fn update_with<M: Dim, H: ParticleMeasurement<T, N, M> + Sync + ?Sized>(
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
    pub fn update_into_with<M: Dim, H: ParticleMeasurement<T, N, M> + Sync + ?Sized>(
        &mut self,
        sensor: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        ensure_finite(z, Stage::Update, Quantity::Measurement)?;
        let count = self.count();
        let cloud = &mut self.cloud;
        let work = &mut self.work;
        let (log_weights, weights) = (&cloud.log_weights, &cloud.weights);
        let mut log_w = core::mem::take(&mut work.log_w);
        log_w.resize(count, T::zero());
        let weighed = work.weigh(sensor, z, &cloud.particles, &mut log_w, |i| {
            (estim_core::scalar::real(weights[i]), log_weights[i])
        });
        work.log_w = log_w;
        let increment = weighed?;
        // Committed.
        work.report(z.shape_generic().0, increment, report);
        work.normalise(increment, &mut cloud.log_weights, &mut cloud.weights);
        cloud.log_likelihood += increment;
        self.update_moments();
        Ok(())
    }
}

impl<T: Real, N: Dim, P: ProcessModel<T, N> + Sync> Predict<T, N, P> for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
    P::Input: Sync,
{
    /// [`ParticleFilter::predict_with`] with Gaussian process noise N(0, Q).
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.predict_with(&AdditiveGaussian(model), input, dt)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M> + Sync> Update<T, N, M, H>
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
