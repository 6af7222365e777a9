//! The particle loops in fixed chunks: the unit of parallel work and of the reduction order.
//!
//! Every per-particle loop (propagation, weighing, normalisation, moments) runs over chunks
//! of [`CHUNK`] consecutive particles, each chunk with its own scratch and partial sums. The
//! partial sums are combined in chunk order, whatever thread ran a chunk and whenever it
//! finished; with the counter-based random streams (one per particle), a step gives the same
//! bits serially, on any number of rayon threads, and on every run. Under the `parallel`
//! feature the chunks run on rayon's current pool when the filter has at least
//! [`PARALLEL_MIN`] particles and the pool more than one thread; below that they run in order
//! on the calling thread (the same bits, without the fork-join cost).
//!
//! A log-sum-exp over chunks: chunk c holds mₐ = max of its values and sₐ = Σ exp(vᵢ − mₐ);
//! then m = maxₐ mₐ and log Σ exp(vᵢ) = m + log Σₐ sₐ exp(mₐ − m), the sum in chunk order.
//! The chunk keeps its terms eᵢ = exp(vᵢ − mₐ), so the normalised weights are
//! Wᵢ = eᵢ exp(mₐ − log Σ exp(v)) with one `exp` per chunk, not a second one per particle.

use core::marker::PhantomData;

use estim_core::alloc::{DimAlloc, SizeFamily};
use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::{Alloc, Error, Real};

use super::resample::to_f64;

/// A noise matrix remembered with its factor (and, for R, log det(2πR)/2).
pub(crate) type Factored<T, D, Extra> = Option<(OMatrix<T, D, D>, OMatrix<T, D, D>, Extra)>;

/// Particles per chunk. The bits of a step depend on it (the order of the partial sums), so
/// it is a constant, not a tuning knob.
pub(crate) const CHUNK: usize = 512;

/// The smallest particle count whose loops run on rayon's pool (feature `parallel`): below it
/// the fork-join overhead (five loops a step, and the serial resampling) outweighs the work
/// (≈ 0.03–0.04 µs of CPU per particle-step for a 1-D model). Measured on a 2-core machine
/// (growth model, 1 and 2 threads alternating, medians of wall-clock, 2 threads / 1 thread):
///
/// | N | 1024 | 2048 | 4096 | 8192 | 16384 | 32768 | 65536 |
/// |---|---:|---:|---:|---:|---:|---:|---:|
/// | idle (load < 1.3, 7 runs) | 1.71 | 1.42 | 1.11 | 1.14 | 1.06 | 0.86 | 0.79 |
/// | shared (load 3.6–5.5, 6 runs) | 1.80 | 1.48 | 1.13 | 1.01 | 1.03 | 1.01 | 0.89 |
///
/// so the pool is used from 32768 particles, the first count where the second thread pays on
/// the idle machine and does not cost on the busy one. Serial and parallel runs give the same
/// bits.
pub const PARALLEL_MIN: usize = 32768;

/// Whether the loops over `count` particles run on rayon's pool.
#[inline]
pub(crate) fn parallel(count: usize) -> bool {
    #[cfg(feature = "parallel")]
    {
        count >= PARALLEL_MIN && rayon::current_num_threads() > 1
    }
    #[cfg(not(feature = "parallel"))]
    {
        let _ = count;
        false
    }
}

/// The number of chunks of `count` particles.
#[inline]
pub(crate) fn chunk_count(count: usize) -> usize {
    count.div_ceil(CHUNK)
}

/// The index range of chunk `c` of `count` particles.
#[inline]
pub(crate) fn range(c: usize, count: usize) -> core::ops::Range<usize> {
    c * CHUNK..((c + 1) * CHUNK).min(count)
}

/// The buffer of the particles' columns for [`for_chunks`]: `values` (n per particle), or
/// for a zero-dimensional state, whose particles are empty, `placeholder` filled with one
/// unused value per particle. With columns of width n.max(1) the per-chunk loops (zipped with
/// `chunks_exact_mut`) then run once per particle as for any other state. The placeholder
/// allocates only then.
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn columns<'a, T: Real>(
    values: &'a mut [T],
    placeholder: &'a mut Vec<T>,
    n: usize,
    count: usize,
) -> &'a mut [T] {
    if n > 0 {
        return values;
    }
    placeholder.clear();
    placeholder.resize(count, T::zero());
    placeholder.as_mut_slice()
}

/// Runs `f(c, states[c], a_c, b_c)` for every chunk c, where a_c and b_c are the c-th pieces
/// of `a` (width `wa`) and `b` (width `wb`): on rayon's pool if `par`, else in order.
/// `states` has one entry per chunk; `a` and `b` have at least as many pieces.
pub(crate) fn for_chunks<S, A, B, F>(
    par: bool,
    states: &mut [S],
    a: &mut [A],
    wa: usize,
    b: &mut [B],
    wb: usize,
    f: F,
) where
    S: Send,
    A: Send,
    B: Send,
    F: Fn(usize, &mut S, &mut [A], &mut [B]) + Sync,
{
    let (wa, wb) = (wa.max(1), wb.max(1));
    #[cfg(feature = "parallel")]
    if par {
        use rayon::prelude::*;
        states
            .par_iter_mut()
            .zip(a.par_chunks_mut(wa))
            .zip(b.par_chunks_mut(wb))
            .enumerate()
            .for_each(|(c, ((s, a), b))| f(c, s, a, b));
        return;
    }
    let _ = par;
    for (c, ((s, a), b)) in states
        .iter_mut()
        .zip(a.chunks_mut(wa))
        .zip(b.chunks_mut(wb))
        .enumerate()
    {
        f(c, s, a, b);
    }
}

/// [`for_chunks`] with one output.
pub(crate) fn for_chunks1<S, A, F>(par: bool, states: &mut [S], a: &mut [A], wa: usize, f: F)
where
    S: Send,
    A: Send,
    F: Fn(usize, &mut S, &mut [A]) + Sync,
{
    // A vector of a zero-sized type never allocates.
    let mut units = vec![(); states.len()];
    for_chunks(par, states, a, wa, &mut units, 1, |c, s, a, _| f(c, s, a));
}

/// [`for_chunks`] with no output.
pub(crate) fn for_states<S, F>(par: bool, states: &mut [S], f: F)
where
    S: Send,
    F: Fn(usize, &mut S) + Sync,
{
    let mut units = vec![(); states.len()];
    for_chunks1(par, states, &mut units, 1, |c, s, _| f(c, s));
}

/// A chunk's log-sum-exp partial: (mₐ, sₐ) with sₐ = Σ eᵢ, eᵢ = exp(vᵢ − mₐ) (in f64, then
/// sₐ rounded to T), the terms eᵢ written to `terms` (for the normalised weights, see
/// [`Work::normalise`](super::step::Work::normalise)); (−∞, 0) and zero terms if every value
/// is −∞ or the chunk is empty. The values are never NaN (the callers reject NaN first).
/// `terms` is reserved for [`CHUNK`] values at construction, so this allocates nothing.
#[inline]
pub(crate) fn lse_partial<T: Real>(values: &[T], terms: &mut Vec<f64>) -> (T, T) {
    let mut max = -T::one() / T::zero();
    for &v in values {
        if v > max {
            max = v;
        }
    }
    terms.clear();
    if !max.is_finite() {
        terms.resize(values.len(), 0.0);
        return (max, T::zero());
    }
    let mut sum = 0.0;
    terms.extend(values.iter().map(|&v| {
        let e = to_f64(v - max).exp();
        sum += e;
        e
    }));
    (max, estim_core::scalar::real(sum))
}

/// Combines the partials in order: log Σ exp(vᵢ) = m + log Σₐ sₐ exp(mₐ − m).
pub(crate) fn lse_combine<T: Real>(partials: impl Iterator<Item = (T, T)> + Clone) -> T {
    let max = partials
        .clone()
        .fold(-T::one() / T::zero(), |m, (c, _)| if c > m { c } else { m });
    if !max.is_finite() {
        return max;
    }
    let mut sum = T::zero();
    for (m, s) in partials {
        if m.is_finite() {
            sum += s * (m - max).exp();
        }
    }
    max + sum.ln()
}

/// The measurement dimension up to which the chunks' innovation sums are reserved up front.
pub(crate) const RESERVED_M: usize = 6;

/// The propagation scratch of a chunk for states of dimension N.
#[derive(Clone, Debug)]
pub(crate) struct StateScratch<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) x: OVector<T, N>,
    pub(crate) y: OVector<T, N>,
    pub(crate) normals: OVector<T, N>,
    pub(crate) q: OMatrix<T, N, N>,
    /// The last Q seen and its PSD factor (Q is factorised again only when it changes).
    pub(crate) q_cache: Factored<T, N, ()>,
}

impl<T: Real, N: Dim> StateScratch<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) fn new(n: N) -> Self {
        Self {
            x: OVector::zeros_generic(n, U1),
            y: OVector::zeros_generic(n, U1),
            normals: OVector::zeros_generic(n, U1),
            q: OMatrix::zeros_generic(n, n),
            q_cache: None,
        }
    }

    /// Whether every buffer has dimension n (a model's default `_into` method may reshape a
    /// runtime-size buffer on a failed step).
    fn fits(&self, n: usize) -> bool {
        self.x.nrows() == n
            && self.y.nrows() == n
            && self.normals.nrows() == n
            && self.q.shape() == (n, n)
    }
}

/// [`StateScratch`] as a function of the state dimension, for [`DimAlloc::runtime_sized`].
struct StateFamily<T>(PhantomData<T>);

impl<T: Real> SizeFamily<Dyn> for StateFamily<T> {
    type Of<Z: Dim>
        = StateScratch<T, Z>
    where
        DefaultAllocator: Alloc<Z, Dyn>;
}

/// What one chunk keeps between steps (all of runtime size, so it can be sent to rayon's
/// threads whatever the filter's dimensions): the state scratch of a `Dyn` filter (a static
/// filter uses scratch on the stack instead), the partial sums of the last pass and its first
/// error.
#[derive(Clone, Debug)]
pub(crate) struct ChunkWork<T: Real> {
    /// The state scratch, used as such when the filter's dimension is `Dyn`.
    pub(crate) state: StateScratch<T, Dyn>,
    /// The chunk's part of Σ Wᵢ xᵢ, then of Σ Wᵢ (xᵢ − x̂)(xᵢ − x̂)ᵀ.
    pub(crate) mean: DVector<T>,
    pub(crate) covariance: DMatrix<T>,
    /// The chunk's part of the update report's innovation moments for m measurement
    /// components, flat: Σ vᵢ rᵢ (m), Σ vᵢ rᵢ rᵢᵀ (m², column-major), Σ vᵢ R(xᵢ) (m²); room
    /// for m ≤ [`RESERVED_M`] is reserved at construction, so static-size updates do not
    /// allocate.
    pub(crate) sums: Vec<T>,
    /// The chunk's Σ vᵢ.
    pub(crate) total_v: T,
    /// The chunk's log-sum-exp partial (see [`lse_partial`]).
    pub(crate) lse: (T, T),
    /// The terms eᵢ = exp(vᵢ − mₐ) of that partial (see [`lse_partial`]).
    pub(crate) terms: Vec<f64>,
    /// The first error of the chunk's loop, in particle order.
    pub(crate) error: Option<Error>,
}

impl<T: Real> ChunkWork<T> {
    pub(crate) fn new(n: usize) -> Self {
        Self {
            state: StateScratch::new(Dyn(n)),
            mean: dvector(n),
            covariance: dmatrix(n, n),
            sums: Vec::with_capacity(RESERVED_M * (1 + 2 * RESERVED_M)),
            total_v: T::zero(),
            lse: (T::zero(), T::zero()),
            terms: Vec::with_capacity(CHUNK),
            error: None,
        }
    }
}

/// Runs `f` with state scratch of dimension n: `kept` when N is `Dyn`, a fresh one on the
/// stack when N is static.
#[cfg_attr(not(debug_assertions), inline(always))]
pub(crate) fn with_state<T: Real, N: Dim, R>(
    kept: &mut StateScratch<T, Dyn>,
    n: N,
    f: impl FnOnce(&mut StateScratch<T, N>) -> R,
) -> R
where
    DefaultAllocator: Alloc<N>,
{
    if N::try_to_usize().is_some() {
        return f(&mut StateScratch::new(n));
    }
    if !kept.fits(n.value()) {
        *kept = StateScratch::<T, Dyn>::new(Dyn(n.value()));
    }
    match <DefaultAllocator as DimAlloc<N>>::runtime_sized::<Dyn, StateFamily<T>>(kept) {
        Some(kept) => f(kept),
        None => f(&mut StateScratch::new(n)),
    }
}

/// A zero vector of runtime length n (outside any generic allocator bound, which would
/// shadow nalgebra's `Dyn` impls).
pub(crate) fn dvector<T: Real>(n: usize) -> DVector<T> {
    DVector::zeros(n)
}

/// A zero matrix of runtime shape r × c.
pub(crate) fn dmatrix<T: Real>(r: usize, c: usize) -> DMatrix<T> {
    DMatrix::zeros(r, c)
}

/// The first error in chunk order, if any (clearing every chunk's).
pub(crate) fn first_error<'a, T: Real + 'a>(
    chunks: impl Iterator<Item = &'a mut ChunkWork<T>>,
) -> Result<(), Error> {
    let mut first = None;
    for w in chunks {
        if let Some(e) = w.error.take() {
            first.get_or_insert(e);
        }
    }
    first.map_or(Ok(()), Err)
}

/// One chunk's Σ Wᵢ dᵢ into `first` and Σ Wᵢ dᵢ dᵢᵀ into `second` (column-major), dᵢ = xᵢ − s,
/// for particles of dimension D (`x` holds them one after another).
#[cfg_attr(not(debug_assertions), inline(always))]
fn chunk_moments<T: Real, const D: usize>(
    x: &[T],
    weights: &[f64],
    shift: &[T],
    first: &mut [T],
    second: &mut [T],
) {
    let shift: [T; D] = core::array::from_fn(|r| shift[r]);
    let mut m1 = [T::zero(); D];
    let mut m2 = [[T::zero(); D]; D];
    for (x, &wi) in x.chunks_exact(D).zip(weights) {
        let wi = estim_core::scalar::real::<T>(wi);
        let d: [T; D] = core::array::from_fn(|r| x[r] - shift[r]);
        for c in 0..D {
            let wd = wi * d[c];
            m1[c] += wd;
            for r in 0..D {
                m2[c][r] += wd * d[r];
            }
        }
    }
    first.copy_from_slice(&m1);
    for (column, m) in second.chunks_exact_mut(D).zip(&m2) {
        column.copy_from_slice(m);
    }
}

/// The weighted moments x̂ = Σ Wᵢ xᵢ and P = Σ Wᵢ (xᵢ − x̂)(xᵢ − x̂)ᵀ of `particles` with
/// weights `weights` (Σ Wᵢ = 1), in one pass by chunks, the partial sums added in chunk order.
/// Each chunk sums dᵢ = xᵢ − s and Wᵢ dᵢ dᵢᵀ about a shift s, the particle of largest
/// weight (inside the cloud's bulk, so the correction below loses no precision); then
/// x̂ = s + Σ Wᵢ dᵢ and P = Σ Wᵢ dᵢ dᵢᵀ − (x̂ − s)(x̂ − s)ᵀ.
///
/// `heaviest`, if known to the caller, is that particle (the first of the largest weight, as
/// the scan here finds it).
pub(crate) fn moments<T: Real, N: Dim>(
    chunks: &mut [ChunkWork<T>],
    particles: &OMatrix<T, N, Dyn>,
    weights: &[f64],
    heaviest: Option<usize>,
    mean: &mut OVector<T, N>,
    covariance: &mut OMatrix<T, N, N>,
) where
    DefaultAllocator: Alloc<N>,
{
    let count = weights.len();
    let n = particles.nrows();
    let particles = particles.as_slice();
    let heaviest = heaviest.unwrap_or_else(|| {
        weights
            .iter()
            .enumerate()
            .fold(
                (0, f64::NEG_INFINITY),
                |(a, m), (i, &w)| if w > m { (i, w) } else { (a, m) },
            )
            .0
    });
    let shift = &particles[heaviest * n..(heaviest + 1) * n];
    for_states(parallel(count), chunks, |c, w| {
        if w.mean.nrows() != n || w.covariance.nrows() != n {
            w.mean = dvector(n);
            w.covariance = dmatrix(n, n);
        }
        let first = w.mean.as_mut_slice();
        let second = w.covariance.as_mut_slice();
        first.fill(T::zero());
        second.fill(T::zero());
        let (range, w) = (range(c, count), &weights[c * CHUNK..]);
        let x = &particles[range.start * n..range.end * n];
        // The loops unrolled for the common small dimensions.
        match n {
            // A zero-dimensional state has empty moments.
            0 => {}
            1 => chunk_moments::<T, 1>(x, w, shift, first, second),
            2 => chunk_moments::<T, 2>(x, w, shift, first, second),
            3 => chunk_moments::<T, 3>(x, w, shift, first, second),
            4 => chunk_moments::<T, 4>(x, w, shift, first, second),
            6 => chunk_moments::<T, 6>(x, w, shift, first, second),
            _ => {
                for (x, &wi) in x.chunks_exact(n).zip(w) {
                    let wi = estim_core::scalar::real::<T>(wi);
                    for (col, column) in second.chunks_exact_mut(n).enumerate() {
                        let wd = wi * (x[col] - shift[col]);
                        first[col] += wd;
                        for ((p, &xr), &sr) in column.iter_mut().zip(x).zip(shift) {
                            *p += wd * (xr - sr);
                        }
                    }
                }
            }
        }
    });
    mean.fill(T::zero());
    covariance.fill(T::zero());
    for w in chunks.iter() {
        for (m, &p) in mean.iter_mut().zip(w.mean.iter()) {
            *m += p;
        }
        for (p, &q) in covariance.iter_mut().zip(w.covariance.iter()) {
            *p += q;
        }
    }
    // P = Σ W d dᵀ − m₁ m₁ᵀ with m₁ = x̂ − s, then x̂ = s + m₁.
    covariance.ger(-T::one(), mean, mean, T::one());
    for (m, &s) in mean.iter_mut().zip(shift) {
        *m += s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunked_log_sum_exp_matches_the_direct_one() {
        let values: Vec<f64> = (0..1500).map(|i| -0.01 * i as f64).collect();
        let direct = super::super::log_sum_exp(&values);
        let mut terms = vec![vec![]; 3];
        let parts: Vec<_> = values
            .chunks(CHUNK)
            .zip(&mut terms)
            .map(|(v, t)| lse_partial(v, t))
            .collect();
        let chunked = lse_combine(parts.iter().copied());
        // The same sum regrouped into 3 chunks: equal to a few ulps of a value of order 5.
        assert!((chunked - direct).abs() < 1e-13, "{chunked} vs {direct}");
        // The terms times exp(mₐ − total) are the normalised weights exp(vᵢ − total), to a
        // few ulps: each exp argument is rounded (relative error of the exp ≤ ε |argument|),
        // then the exps and the product (3 ε); 4 times that bound leaves margin.
        for ((v, t), (m, _)) in values.chunks(CHUNK).zip(&terms).zip(&parts) {
            let scale = (m - chunked).exp();
            for (&v, &e) in v.iter().zip(t) {
                let w = (v - chunked).exp();
                let bound = 4.0 * f64::EPSILON * (3.0 + (v - chunked).abs() + (m - chunked).abs());
                assert!((e * scale - w).abs() <= bound * w, "{} vs {w}", e * scale);
            }
        }
        let dead = [f64::NEG_INFINITY; 4];
        let mut t = vec![1.0];
        assert_eq!(
            lse_combine([lse_partial(&dead, &mut t)].into_iter()),
            f64::NEG_INFINITY
        );
        assert_eq!(t, [0.0; 4]);
    }
}
