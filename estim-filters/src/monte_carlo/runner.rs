//! The runner: the experiment's settings, its chunks of runs (sequential, parallel or in
//! shards) and the merge of their accumulators in chunk order.

use core::fmt;
use core::marker::PhantomData;
use core::ops::Range;

use crate::validation::{Result, Setting, ValidationError};

use super::accumulator::{Accumulator, SlotAcc};
use super::recorder::{Recorder, slot_error};
use super::stats::{EnsembleStats, EstimateStats, InnovationStats, ResidualPairStats, SlotStats};
use super::{MonteCarloError, run_seed};

/// How far a Monte Carlo run has got: reported to the `progress` callback of
/// [`MonteCarlo::run_with_progress`] each time a chunk of runs is merged, in chunk order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Progress {
    /// Realizations finished and merged.
    pub runs_done: usize,
    /// Realizations in all.
    pub runs: usize,
}

impl Progress {
    /// The fraction done, in [0, 1].
    pub fn fraction(&self) -> f64 {
        self.runs_done as f64 / self.runs as f64
    }
}

/// One shard of a Monte Carlo experiment ([`MonteCarlo::run_shard`]): the accumulators of
/// a contiguous range of its chunks, kept apart so that [`MonteCarlo::merge_shards`] merges
/// every chunk in the same order as one run does (bit-identical statistics). With the `serde`
/// feature it serialises, so shards can run as separate processes (module docs).
#[derive(Clone, Debug)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Shard {
    /// (runs, slots, master seed, chunks, residual pairs) of the experiment it belongs to.
    experiment: (usize, usize, u64, usize, Vec<(usize, usize)>),
    /// The index of its first chunk.
    first_chunk: usize,
    /// One accumulator per chunk, in chunk order.
    chunks: Vec<Accumulator>,
}

impl Shard {
    /// The runs this shard covers (saturating at `usize::MAX` for a shard read from a
    /// damaged file: [`MonteCarlo::merge_shards`] refuses those).
    pub fn runs(&self) -> usize {
        self.chunks
            .iter()
            .fold(0, |sum, c| sum.saturating_add(c.runs))
    }
}

/// A Monte Carlo consistency experiment: how many runs, how many time slots, the master seed,
/// the residual pairs, and the chunking that makes results independent of the thread count.
/// `E` is the error type the realizations return ([`with_error`](Self::with_error)). See the
/// [module docs](super).
pub struct MonteCarlo<E = ValidationError> {
    runs: usize,
    slots: usize,
    seed: u64,
    chunks: usize,
    pairs: Vec<(usize, usize)>,
    error: PhantomData<fn() -> E>,
}

// Written out, not derived: a derive would require E: Clone, Debug, PartialEq, and the error
// type is only a marker here.
impl<E> Clone for MonteCarlo<E> {
    fn clone(&self) -> Self {
        Self {
            pairs: self.pairs.clone(),
            error: PhantomData,
            ..*self
        }
    }
}

impl<E> fmt::Debug for MonteCarlo<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MonteCarlo")
            .field("runs", &self.runs)
            .field("slots", &self.slots)
            .field("seed", &self.seed)
            .field("chunks", &self.chunks)
            .field("pairs", &self.pairs)
            .finish()
    }
}

impl<E> PartialEq for MonteCarlo<E> {
    fn eq(&self, other: &Self) -> bool {
        (self.runs, self.slots, self.seed, self.chunks, &self.pairs)
            == (
                other.runs,
                other.slots,
                other.seed,
                other.chunks,
                &other.pairs,
            )
    }
}

impl<E> Eq for MonteCarlo<E> {}

impl MonteCarlo {
    /// The default number of chunks the runs are split into.
    pub const DEFAULT_CHUNKS: usize = 64;

    /// The most chunks [`with_chunks`](Self::with_chunks) accepts: 2¹⁶, far more than threads
    /// or job-array tasks; the chunks' run ranges are laid out before the first run.
    pub const MAX_CHUNKS: usize = 1 << 16;

    /// `runs` ≥ 1 realizations with statistics at `slots` ≥ 1 time slots, master seed 0.
    /// A slot count whose accumulators cannot be allocated is refused ([`Setting::Slot`]).
    pub fn new(runs: usize, slots: usize) -> Result<Self> {
        if runs == 0 {
            return Err(ValidationError::InvalidSetting {
                setting: Setting::RunCount,
                value: 0.0,
            });
        }
        if slots == 0 {
            return Err(slot_error(0));
        }
        // Each chunk in flight holds an accumulator per slot: refuse a count whose accumulators
        // could not even be addressed or reserved (an error, not a "capacity overflow" panic or
        // an allocation abort at the first run).
        let mut probe: Vec<SlotAcc> = Vec::new();
        probe
            .try_reserve_exact(slots)
            .map_err(|_| slot_error(slots))?;
        drop(probe);
        Ok(Self {
            runs,
            slots,
            seed: 0,
            chunks: Self::DEFAULT_CHUNKS,
            pairs: Vec::new(),
            error: PhantomData,
        })
    }
}

impl<E> MonteCarlo<E> {
    /// The same experiment with realizations that return `Result<(), E2>`: your own error
    /// type, which must take the recorder's errors (`From<ValidationError>`, so `?` works on
    /// them); a failure comes back as [`MonteCarloError::Run`] with your error in it.
    ///
    /// ```
    /// use estim_filters::monte_carlo::{MonteCarlo, MonteCarloError};
    /// use estim_filters::ValidationError;
    ///
    /// #[derive(Debug, PartialEq)]
    /// enum SimError { Diverged(f64), Recording(ValidationError) }
    /// impl From<ValidationError> for SimError {
    ///     fn from(e: ValidationError) -> Self { SimError::Recording(e) }
    /// }
    ///
    /// let mc = MonteCarlo::new(10, 1)?.with_error::<SimError>();
    /// let result = mc.run_sequential(|run, _seed, _rec| {
    ///     if run == 3 { Err(SimError::Diverged(1e9)) } else { Ok(()) }
    /// });
    /// assert!(matches!(
    ///     result,
    ///     Err(MonteCarloError::Run { run: 3, error: SimError::Diverged(_), .. })
    /// ));
    /// # Ok::<(), ValidationError>(())
    /// ```
    pub fn with_error<E2: From<ValidationError>>(self) -> MonteCarlo<E2> {
        MonteCarlo {
            runs: self.runs,
            slots: self.slots,
            seed: self.seed,
            chunks: self.chunks,
            pairs: self.pairs,
            error: PhantomData,
        }
    }

    /// Sets the master seed from which every run's seed is derived ([`run_seed`]).
    pub fn with_seed(mut self, master_seed: u64) -> Self {
        self.seed = master_seed;
        self
    }

    /// Requests the residual cross-correlation between slots `first` and `second` (distinct,
    /// both < slots). Lu's check uses the innovations at t = 20 s and t = 30 s.
    pub fn with_residual_pair(mut self, first: usize, second: usize) -> Result<Self> {
        for s in [first, second] {
            if s >= self.slots {
                return Err(slot_error(s));
            }
        }
        if first == second {
            return Err(slot_error(second));
        }
        self.pairs.push((first, second));
        Ok(self)
    }

    /// Splits the runs into 1 ≤ `chunks` ≤ [`MAX_CHUNKS`](MonteCarlo::MAX_CHUNKS) contiguous
    /// chunks (default 64; fewer if there are fewer runs), else [`Setting::ChunkCount`]. The
    /// statistics depend on it only through floating-point summation order; more chunks let
    /// more threads work, at (2 × threads + 1) × slots accumulators of memory, and a shard
    /// keeps one set of accumulators per chunk.
    pub fn with_chunks(mut self, chunks: usize) -> Result<Self> {
        if !(1..=MonteCarlo::MAX_CHUNKS).contains(&chunks) {
            return Err(ValidationError::setting(Setting::ChunkCount, chunks));
        }
        self.chunks = chunks;
        Ok(self)
    }

    /// The number of runs N.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// The number of time slots S.
    pub fn slots(&self) -> usize {
        self.slots
    }

    /// The master seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The requested residual pairs.
    pub fn residual_pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// The seed of run `run`: [`run_seed`]`(self.seed(), run)`.
    pub fn run_seed(&self, run: usize) -> u64 {
        run_seed(self.seed, run)
    }

    /// The run ranges of the chunks: chunk c covers runs ⌊c N / K⌋ … ⌊(c+1) N / K⌋ − 1.
    fn chunk_ranges(&self) -> Vec<Range<usize>> {
        let k = self.chunks.min(self.runs);
        let bound = |c: usize| ((c as u128 * self.runs as u128) / k as u128) as usize;
        (0..k).map(|c| bound(c)..bound(c + 1)).collect()
    }

    fn run_chunk<F>(
        &self,
        range: Range<usize>,
        f: &mut F,
    ) -> Result<Accumulator, MonteCarloError<E>>
    where
        F: FnMut(usize, u64, &mut Recorder) -> Result<(), E>,
        E: From<ValidationError>,
    {
        let mut recorder = Recorder::new(self.slots, &self.pairs);
        for run in range {
            let seed = self.run_seed(run);
            recorder.begin(run, seed);
            f(run, seed, &mut recorder)
                .and_then(|()| recorder.end_run().map_err(E::from))
                .map_err(|error| MonteCarloError::Run { run, seed, error })?;
            recorder.acc.runs += 1;
        }
        Ok(recorder.acc)
    }

    /// The experiment's identity, as a shard records it.
    fn identity(&self) -> (usize, usize, u64, usize, Vec<(usize, usize)>) {
        (
            self.runs,
            self.slots,
            self.seed,
            self.chunks.min(self.runs),
            self.pairs.clone(),
        )
    }

    /// Runs shard `shard` of `shards` ≥ 1 on this thread: the chunks ⌊s K/S⌋ … ⌊(s+1) K/S⌋ − 1
    /// of the K chunks ([`with_chunks`](Self::with_chunks)), i.e. a contiguous range of run
    /// indices and seeds. [`merge_shards`](Self::merge_shards) over all S shards equals
    /// [`run`](Self::run) bit for bit. Shards are independent: run them in separate
    /// processes or on separate machines (module docs: *Shards*), with the same experiment
    /// (runs, slots, seed, chunks, pairs). With S > K some shards are empty.
    ///
    /// Errors: `shard` ≥ `shards` ([`MonteCarloError::Shards`]); the realizations' errors as in
    /// [`run_sequential`](Self::run_sequential).
    pub fn run_shard<F>(
        &self,
        shard: usize,
        shards: usize,
        mut simulate: F,
    ) -> Result<Shard, MonteCarloError<E>>
    where
        F: FnMut(usize, u64, &mut Recorder) -> Result<(), E>,
        E: From<ValidationError>,
    {
        if shard >= shards {
            return Err(MonteCarloError::Shards {
                error: ValidationError::setting(Setting::Shard, shard),
            });
        }
        let ranges = self.chunk_ranges();
        let k = ranges.len() as u128;
        let bound = |s: usize| ((s as u128 * k) / shards as u128) as usize;
        let (first, last) = (bound(shard), bound(shard + 1));
        let mut chunks = Vec::with_capacity(last - first);
        for range in &ranges[first..last] {
            chunks.push(self.run_chunk(range.clone(), &mut simulate)?);
        }
        Ok(Shard {
            experiment: self.identity(),
            first_chunk: first,
            chunks,
        })
    }

    /// The ensemble statistics of all the shards of this experiment, in any order: every
    /// chunk merged in chunk order, as [`run`](Self::run) does, so the result is bit-identical
    /// to one run.
    ///
    /// ```
    /// use estim_filters::monte_carlo::MonteCarlo;
    /// use estim_core::nalgebra::{Matrix1, Vector1};
    ///
    /// let mc = MonteCarlo::new(100, 1)?.with_seed(3);
    /// let realization = |_run: usize, seed: u64, rec: &mut estim_filters::Recorder| {
    ///     let x = Vector1::new((seed % 1000) as f64 / 1000.0 - 0.5);
    ///     rec.record_estimate(0, &x, &(x * 0.5), &Matrix1::new(1.0 / 48.0))
    /// };
    /// // Three shards, e.g. three processes of a job array, merged afterwards.
    /// let shards = (0..3)
    ///     .map(|s| mc.run_shard(s, 3, realization))
    ///     .collect::<Result<Vec<_>, _>>()?;
    /// assert_eq!(mc.merge_shards(shards)?, mc.run(realization)?);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// Errors: a shard of another experiment, a chunk missing or given twice, accumulators of
    /// the wrong size or with counts their chunk's runs cannot have produced
    /// ([`MonteCarloError::Shards`]); shapes that differ between shards
    /// ([`MonteCarloError::Shape`]).
    pub fn merge_shards(
        &self,
        shards: impl IntoIterator<Item = Shard>,
    ) -> Result<EnsembleStats, MonteCarloError<E>> {
        let invalid = |value: usize| MonteCarloError::Shards {
            error: ValidationError::setting(Setting::Shard, value),
        };
        let identity = self.identity();
        let ranges = self.chunk_ranges();
        let mut shards: Vec<Shard> = shards.into_iter().collect();
        shards.sort_by_key(|s| s.first_chunk);
        let mut total = Accumulator::new(self.slots, self.pairs.len());
        let mut next = 0;
        for shard in &shards {
            if shard.experiment != identity || shard.first_chunk != next {
                return Err(invalid(shard.first_chunk));
            }
            for chunk in &shard.chunks {
                let runs = ranges.get(next).map(|r| r.len());
                let fits = |runs| {
                    chunk.well_formed(runs, self.slots, self.pairs.len()) && total.dof_fit(chunk)
                };
                if !runs.is_some_and(fits) {
                    return Err(invalid(next));
                }
                Self::merge_into(&mut total, chunk)?;
                next += 1;
            }
        }
        if next != identity.3 {
            return Err(invalid(next));
        }
        Ok(self.finish(&total))
    }

    fn merge_into(total: &mut Accumulator, chunk: &Accumulator) -> Result<(), MonteCarloError<E>> {
        total
            .merge(chunk)
            .map_err(|error| MonteCarloError::Shape { error })
    }

    /// Runs every realization on this thread: `simulate(run, seed, recorder)` for run = 0 … N−1.
    /// `simulate` may keep state between runs (`FnMut`: a reused buffer, a counter), but the
    /// statistics stay reproducible only if each run depends on its seed alone.
    ///
    /// Returns the first failure in run order, or the ensemble statistics.
    pub fn run_sequential<F>(&self, simulate: F) -> Result<EnsembleStats, MonteCarloError<E>>
    where
        F: FnMut(usize, u64, &mut Recorder) -> Result<(), E>,
        E: From<ValidationError>,
    {
        self.run_sequential_with_progress(simulate, |_| {})
    }

    /// [`run_sequential`](Self::run_sequential), calling `progress` after each chunk of runs
    /// (as [`run_with_progress`](Self::run_with_progress) does).
    pub fn run_sequential_with_progress<F>(
        &self,
        mut simulate: F,
        mut progress: impl FnMut(Progress),
    ) -> Result<EnsembleStats, MonteCarloError<E>>
    where
        F: FnMut(usize, u64, &mut Recorder) -> Result<(), E>,
        E: From<ValidationError>,
    {
        let mut total = Accumulator::new(self.slots, self.pairs.len());
        for range in self.chunk_ranges() {
            let runs_done = range.end;
            let chunk = self.run_chunk(range, &mut simulate)?;
            Self::merge_into(&mut total, &chunk)?;
            progress(Progress {
                runs_done,
                runs: self.runs,
            });
        }
        Ok(self.finish(&total))
    }

    /// Runs the realizations on rayon's current thread pool (install a pool to choose the
    /// number of threads). Bit-identical to [`run_sequential`](Self::run_sequential): the
    /// chunks are merged in the same order. Chunks run in waves of 2 × threads, which bounds
    /// the memory.
    #[cfg(feature = "parallel")]
    pub fn run_parallel<F>(&self, simulate: F) -> Result<EnsembleStats, MonteCarloError<E>>
    where
        F: Fn(usize, u64, &mut Recorder) -> Result<(), E> + Sync,
        E: From<ValidationError> + Send,
    {
        self.run_parallel_with_progress(simulate, |_| {})
    }

    #[cfg(feature = "parallel")]
    fn run_parallel_with_progress<F>(
        &self,
        simulate: F,
        mut progress: impl FnMut(Progress),
    ) -> Result<EnsembleStats, MonteCarloError<E>>
    where
        F: Fn(usize, u64, &mut Recorder) -> Result<(), E> + Sync,
        E: From<ValidationError> + Send,
    {
        use rayon::prelude::*;
        let wave = 2 * rayon::current_num_threads().max(1);
        let ranges = self.chunk_ranges();
        let mut total = Accumulator::new(self.slots, self.pairs.len());
        for group in ranges.chunks(wave) {
            let chunks: Vec<Result<Accumulator, MonteCarloError<E>>> = group
                .par_iter()
                .map(|range| self.run_chunk(range.clone(), &mut &simulate))
                .collect();
            for (range, chunk) in group.iter().zip(chunks) {
                Self::merge_into(&mut total, &chunk?)?;
                progress(Progress {
                    runs_done: range.end,
                    runs: self.runs,
                });
            }
        }
        Ok(self.finish(&total))
    }

    /// `run_parallel` when the `parallel` feature is on (off by default, in this crate and in
    /// the `estim` facade), else [`run_sequential`](Self::run_sequential). Both
    /// give the same bits; the `Sync` bound is required either way so that code compiles with
    /// and without the feature.
    pub fn run<F>(&self, simulate: F) -> Result<EnsembleStats, MonteCarloError<E>>
    where
        F: Fn(usize, u64, &mut Recorder) -> Result<(), E> + Sync,
        E: From<ValidationError> + Send,
    {
        self.run_with_progress(simulate, |_| {})
    }

    /// [`run`](Self::run), calling `progress` on this thread after each chunk of runs is
    /// merged (64 times by default, [`with_chunks`](Self::with_chunks)), in run order: for a
    /// progress bar or a log line in runs of minutes. It sees only counts, so it cannot change
    /// the statistics.
    ///
    /// ```
    /// use estim_filters::monte_carlo::{MonteCarlo, Progress};
    ///
    /// let mc = MonteCarlo::new(1000, 1)?.with_chunks(4)?;
    /// let mut seen = Vec::new();
    /// mc.run_with_progress(|_, _, _| Ok(()), |p: Progress| seen.push(p.runs_done))?;
    /// assert_eq!(seen, [250, 500, 750, 1000]);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn run_with_progress<F>(
        &self,
        simulate: F,
        progress: impl FnMut(Progress),
    ) -> Result<EnsembleStats, MonteCarloError<E>>
    where
        F: Fn(usize, u64, &mut Recorder) -> Result<(), E> + Sync,
        E: From<ValidationError> + Send,
    {
        #[cfg(feature = "parallel")]
        {
            self.run_parallel_with_progress(simulate, progress)
        }
        #[cfg(not(feature = "parallel"))]
        {
            self.run_sequential_with_progress(simulate, progress)
        }
    }

    fn finish(&self, total: &Accumulator) -> EnsembleStats {
        let slots = total
            .slots
            .iter()
            .enumerate()
            .map(|(slot, acc)| SlotStats {
                slot,
                estimate: (acc.count > 0).then(|| EstimateStats::from_acc(acc)),
                innovation: (acc.nis_count > 0).then(|| InnovationStats {
                    samples: acc.nis_count,
                    degrees_of_freedom: acc.nis_dof,
                    mean_nis: acc.sum_nis / acc.nis_count as f64,
                    mean_log_likelihood: acc.sum_ll / acc.nis_count as f64,
                }),
            })
            .collect();
        let residual_pairs = self
            .pairs
            .iter()
            .zip(&total.pairs)
            .map(|(&(first, second), acc)| ResidualPairStats::from_acc(first, second, acc))
            .collect();
        EnsembleStats {
            runs: self.runs,
            slots,
            residual_pairs,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunk_ranges_cover_every_run_once() {
        for (runs, chunks) in [(1, 64), (10, 64), (64, 64), (1000, 64), (1001, 7)] {
            let mc = MonteCarlo::new(runs, 1)
                .unwrap()
                .with_chunks(chunks)
                .unwrap();
            let ranges = mc.chunk_ranges();
            assert_eq!(ranges.len(), chunks.min(runs));
            assert_eq!(ranges[0].start, 0);
            assert_eq!(ranges.last().unwrap().end, runs);
            assert!(ranges.windows(2).all(|w| w[0].end == w[1].start));
            assert!(ranges.iter().all(|r| !r.is_empty()));
        }
    }
}
