//! The Monte Carlo consistency runner: many seeded realizations of a simulation and its filter,
//! summarised per time slot without storing trajectories.
//!
//! These are the four checks of Lu's Monte Carlo validation (*Accelerometer calibration with
//! GPS*, §3.2) — ensemble mean error ≈ 0, ensemble error covariance ≈ the filter's covariance,
//! error orthogonal to the estimate, residuals at two times uncorrelated — plus the averaged
//! NEES and NIS tests of Bar-Shalom, Li & Kirubarajan (2001, §5.4.2), for any model and filter.
//!
//! # Use
//!
//! You write one realization: simulate the truth and measurements from the given seed, run
//! your filter, and record what the statistics need at the time slots you chose up front
//! (0 … S−1: every step, or a few chosen times):
//!
//! - [`Recorder::record_estimate`]`(slot, &truth, x̂, P)` (or [`Recorder::record_filter`]) for
//!   the error statistics, NEES and orthogonality,
//! - [`Recorder::record_innovation`]`(slot, &report)` for the NIS,
//! - [`Recorder::record_residual`]`(slot, &r)` at the two slots of each residual pair
//!   requested with [`MonteCarlo::with_residual_pair`].
//!
//! ```
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//! use estim_filters::monte_carlo::MonteCarlo;
//! use estim_filters::{KalmanFilter, Predict, Update};
//! use rand::{Rng, SeedableRng, rngs::StdRng};
//! use rand_distr::StandardNormal;
//!
//! let process = LinearProcess {
//!     transition: Matrix2::new(1.0, 0.1, 0.0, 1.0),
//!     input: Matrix2x1::zeros(),
//!     noise: Matrix2::new(1e-3, 0.0, 0.0, 1e-3),
//! };
//! let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.04) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
//!
//! let steps = 40;
//! let mc = MonteCarlo::new(200, steps)?.with_seed(7).with_residual_pair(10, 30)?;
//! let stats = mc.run(|_run, seed, rec| {
//!     let mut rng = StdRng::seed_from_u64(seed);
//!     let mut normal = || rng.sample::<f64, _>(StandardNormal);
//!     // The truth starts from the filter's prior (the checks assume it).
//!     let mut x = Vector2::new(normal(), normal());
//!     let mut kf = KalmanFilter::new(prior.clone());
//!     for k in 0..steps {
//!         x = process.transition * x + Vector2::new(normal(), normal()) * 1e-3f64.sqrt();
//!         let z = sensor.observation * x + Vector1::new(0.2 * normal());
//!         kf.predict(&process, &Vector1::new(0.0), 0.1)?;
//!         let report = kf.update(&sensor, &z)?;
//!         rec.record_innovation(k, &report)?; // NIS
//!         rec.record_residual(k, &report.innovation)?; // used at slots 10 and 30
//!         rec.record_filter(k, &x, &kf)?; // error, NEES, orthogonality
//!     }
//!     Ok(())
//! })?;
//! // Each check at 99%: a consistent filter passes all six in ≥ 94% of seeds.
//! let verdict = stats.verdict(0.99)?;
//! println!("{verdict}");
//! assert!(verdict.consistent(), "{verdict}");
//! let last = stats.slots[steps - 1].estimate.as_ref().unwrap();
//! assert!(last.nees_band(0.99)?.contains(last.mean_nees));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Determinism and memory
//!
//! Run `i` gets the seed [`run_seed`]`(master, i)` (SplitMix64), whatever runs before it. The
//! runs are split into a fixed number of contiguous chunks (64 by default, independent of the
//! number of threads); each chunk is accumulated sequentially in run order, and the chunk
//! accumulators are merged in chunk order. The sequential runner does exactly the same, so
//! [`MonteCarlo::run_sequential`] and `MonteCarlo::run_parallel` return bit-identical
//! statistics for the same seed, on any number of threads.
//!
//! Nothing is stored per run or per step: each slot holds running moments (O(n²) numbers for
//! an n-state filter), so memory is O(slots × n²) per chunk in flight, with at most
//! 2 × threads + 1 chunks alive at once — never O(runs × steps). Record trajectories yourself
//! (in the closure) if you want them.
//!
//! # Shards: one experiment over many processes or machines
//!
//! [`MonteCarlo::run_shard`]`(s, S, …)` runs the s-th of S contiguous ranges of chunks;
//! [`MonteCarlo::merge_shards`] merges the S [`Shard`]s chunk by chunk in chunk order, so the
//! result equals one [`run`](MonteCarlo::run) bit for bit, whatever the order the shards
//! finish in. To spread one experiment over the tasks of a job array (Slurm, PBS, a CI
//! matrix, `xargs -P`): with the `serde` feature,
//!
//! 1. every task builds the same `MonteCarlo` (runs, slots, seed, chunks ≥ S, pairs) and runs
//!    its shard, s = the task index (`SLURM_ARRAY_TASK_ID`), writing it out, e.g.
//!    `serde_json::to_writer(file, &mc.run_shard(s, S, simulate)?)`;
//! 2. one last task reads the S files back (`serde_json::from_reader`) and calls
//!    `mc.merge_shards(shards)`, which refuses shards of another experiment or a missing or
//!    repeated chunk.
//!
//! serde_json with its `float_roundtrip` feature (or a binary format) reads back every finite
//! `f64` exactly (the accumulators hold only finite values), so the merged statistics are those
//! of a single run; serde_json's default parser may be an ulp off. A shard holds one accumulator per chunk:
//! O(chunks/S × slots × n²) numbers.
//!
//! Means and covariances are accumulated with Welford's update and merged with Chan, Golub &
//! LeVeque's pairwise formula (a chunk of n_b samples with mean m_b and centred co-moment C_b
//! joins one of n_a: δ = m_b − m_a, m = m_a + δ n_b/n, C = C_a + C_b + δδᵀ n_a n_b/n), so the
//! ensemble covariance does not cancel catastrophically when the estimates are large compared
//! with their spread.

use core::fmt;
use core::marker::PhantomData;
use core::ops::Range;

use estim_core::linalg::{ensure_shape, inverse_quadratic_form};
use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, OMatrix, OVector, SMatrix};
use estim_core::{Alloc, Error, Quantity, Real};

use crate::validation::{Result, Setting, ValidationError};

use crate::consistency::{
    Check, ChiSquareBand, FamilyRule, FamilyTest, Location, STAGE, Verdict,
    cholesky_quadratic_form, dist, to_f64, validate_confidence,
};
use crate::report::UpdateReport;
use crate::traits::Estimator;

/// The seed of run `run` under master seed `master`: the `run`-th output of SplitMix64
/// (Steele, Lea & Flood 2014) seeded with `master`. Use it to replay one run alone.
pub fn run_seed(master: u64, run: usize) -> u64 {
    let mut z = master.wrapping_add(
        (run as u64)
            .wrapping_add(1)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15),
    );
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Why a Monte Carlo run failed. `E` is the error type realizations return
/// ([`MonteCarlo::with_error`]; [`ValidationError`] by default).
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum MonteCarloError<E = ValidationError> {
    /// A realization returned an error, or recorded something invalid (a slot out of range,
    /// a record made twice, a shape different from earlier runs' in the same chunk, a
    /// covariance that is not positive definite). It is the failing run with the smallest
    /// index, on any number of threads.
    Run {
        /// The run index.
        run: usize,
        /// Its seed ([`run_seed`]).
        seed: u64,
        /// The error.
        error: E,
    },
    /// Runs in different chunks recorded different shapes at the same slot or residual pair.
    Shape {
        /// The [`Error::DimensionMismatch`], wrapped.
        error: ValidationError,
    },
    /// A shard index out of range, or shards to merge that are not exactly one experiment's
    /// chunks ([`Setting::Shard`]).
    Shards {
        /// The [`ValidationError::InvalidSetting`].
        error: ValidationError,
    },
}

impl MonteCarloError {
    /// The underlying error.
    pub fn error(&self) -> ValidationError {
        match *self {
            MonteCarloError::Run { error, .. }
            | MonteCarloError::Shape { error }
            | MonteCarloError::Shards { error } => error,
        }
    }
}

impl<E: fmt::Display> fmt::Display for MonteCarloError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MonteCarloError::Run { run, seed, error } => {
                write!(f, "Monte Carlo run {run} (seed {seed}) failed: {error}")
            }
            MonteCarloError::Shape { error } => {
                write!(f, "Monte Carlo runs disagree in shape: {error}")
            }
            MonteCarloError::Shards { error } => {
                write!(f, "Monte Carlo shards: {error}")
            }
        }
    }
}

impl<E: std::error::Error + 'static> std::error::Error for MonteCarloError<E> {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            MonteCarloError::Run { error, .. } => Some(error),
            MonteCarloError::Shape { error } | MonteCarloError::Shards { error } => Some(error),
        }
    }
}

impl From<MonteCarloError> for ValidationError {
    fn from(e: MonteCarloError) -> Self {
        e.error()
    }
}

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
    /// The runs this shard covers.
    pub fn runs(&self) -> usize {
        self.chunks.iter().map(|c| c.runs).sum()
    }
}

/// Running moments of one slot's estimates, in f64, column-major n × n matrices.
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
struct SlotAcc {
    n: usize,
    count: usize,
    mean_e: Vec<f64>,
    mean_x: Vec<f64>,
    /// Σ (e − ē)(e − ē)ᵀ.
    c_ee: Vec<f64>,
    /// Σ (e − ē)(x̂ − x̄)ᵀ.
    c_ex: Vec<f64>,
    /// Σ (x̂ᵢ − x̄ᵢ)².
    m2_x: Vec<f64>,
    sum_p: Vec<f64>,
    sum_nees: f64,
    nis_count: usize,
    nis_dof: usize,
    sum_nis: f64,
    sum_ll: f64,
}

fn mismatch(quantity: Quantity, expected: usize, found: usize) -> ValidationError {
    ValidationError::Estimation(Error::DimensionMismatch {
        stage: STAGE,
        quantity,
        expected_rows: expected,
        expected_cols: 1,
        found_rows: found,
        found_cols: 1,
    })
}

/// An n × n column-major buffer as N columns of N, if it has N² entries.
#[inline(always)]
fn square<const N: usize>(m: &[f64]) -> Option<&[[f64; N]; N]> {
    let (columns, rest) = m.as_chunks::<N>();
    if rest.is_empty() {
        columns.try_into().ok()
    } else {
        None
    }
}

/// [`square`], mutably.
#[inline(always)]
fn square_mut<const N: usize>(m: &mut [f64]) -> Option<&mut [[f64; N]; N]> {
    let (columns, rest) = m.as_chunks_mut::<N>();
    if rest.is_empty() {
        columns.try_into().ok()
    } else {
        None
    }
}

/// The NEES eᵀP⁻¹e of a state of n ≤ 6 components by [`inverse_quadratic_form`] on a
/// fixed-size copy of P (the algorithm of the runtime-size path, unrolled): `Some(None)` if P
/// is not positive definite, `None` if n is not small.
fn small_nees(p: &[f64], e: &[f64], n: usize) -> Option<Option<f64>> {
    fn fixed<const N: usize>(p: &[f64], e: &[f64]) -> Option<Option<f64>> {
        if p.len() != N * N || e.len() != N {
            return None;
        }
        let mut c = SMatrix::<f64, N, N>::zeros();
        c.as_mut_slice().copy_from_slice(p);
        let mut v = SMatrix::<f64, N, 1>::zeros();
        v.as_mut_slice().copy_from_slice(e);
        // |L⁻¹e|² summed in index order, as the runtime-size dot product does below 8 entries
        // (nalgebra's fixed-size one pairs the terms differently at n = 4).
        Some(inverse_quadratic_form(&mut c, &mut v).map(|_| v.iter().fold(0.0, |s, &x| s + x * x)))
    }
    match n {
        1 => fixed::<1>(p, e),
        2 => fixed::<2>(p, e),
        3 => fixed::<3>(p, e),
        4 => fixed::<4>(p, e),
        5 => fixed::<5>(p, e),
        6 => fixed::<6>(p, e),
        _ => None,
    }
}

impl SlotAcc {
    fn ensure_dim(&mut self, n: usize) -> Result<()> {
        if self.count == 0 && self.n == 0 {
            self.n = n;
            self.mean_e = vec![0.0; n];
            self.mean_x = vec![0.0; n];
            self.c_ee = vec![0.0; n * n];
            self.c_ex = vec![0.0; n * n];
            self.m2_x = vec![0.0; n];
            self.sum_p = vec![0.0; n * n];
            Ok(())
        } else if self.n == n {
            Ok(())
        } else {
            Err(mismatch(Quantity::Mean, self.n, n))
        }
    }

    /// Welford: with δ = v − mean_old, mean += δ/k and C += (k − 1)/k δ δᵀ. States of up to
    /// 6 components go through [`add_small`](Self::add_small) (the same operations in
    /// the same order, so the same bits, on fixed-size arrays the compiler unrolls).
    fn add(&mut self, e: &[f64], x: &[f64], p: &[f64], nees: f64, de: &mut [f64], dx: &mut [f64]) {
        let done = match self.n {
            1 => self.add_small::<1>(e, x, p, nees),
            2 => self.add_small::<2>(e, x, p, nees),
            3 => self.add_small::<3>(e, x, p, nees),
            4 => self.add_small::<4>(e, x, p, nees),
            5 => self.add_small::<5>(e, x, p, nees),
            6 => self.add_small::<6>(e, x, p, nees),
            _ => false,
        };
        if !done {
            self.add_any(e, x, p, nees, de, dx);
        }
    }

    /// [`add_any`](Self::add_any) for n = N; false (nothing changed) if a buffer is not of the
    /// size n says (never, for what this crate builds).
    #[inline(always)]
    fn add_small<const N: usize>(&mut self, e: &[f64], x: &[f64], p: &[f64], nees: f64) -> bool {
        let (Ok(e), Ok(x)) = (<&[f64; N]>::try_from(e), <&[f64; N]>::try_from(x)) else {
            return false;
        };
        let (Some(p), Some(c_ee), Some(c_ex), Some(sum_p)) = (
            square::<N>(p),
            square_mut::<N>(&mut self.c_ee),
            square_mut::<N>(&mut self.c_ex),
            square_mut::<N>(&mut self.sum_p),
        ) else {
            return false;
        };
        let (Ok(mean_e), Ok(mean_x), Ok(m2_x)) = (
            <&mut [f64; N]>::try_from(self.mean_e.as_mut_slice()),
            <&mut [f64; N]>::try_from(self.mean_x.as_mut_slice()),
            <&mut [f64; N]>::try_from(self.m2_x.as_mut_slice()),
        ) else {
            return false;
        };
        self.count += 1;
        let k = self.count as f64;
        let f = (k - 1.0) / k;
        let (mut de, mut dx) = ([0.0; N], [0.0; N]);
        for i in 0..N {
            de[i] = e[i] - mean_e[i];
            dx[i] = x[i] - mean_x[i];
            mean_e[i] += de[i] / k;
            mean_x[i] += dx[i] / k;
            m2_x[i] += f * (dx[i] * dx[i]);
        }
        for j in 0..N {
            for i in 0..N {
                c_ee[j][i] += f * (de[i] * de[j]);
                c_ex[j][i] += f * (de[i] * dx[j]);
                sum_p[j][i] += p[j][i];
            }
        }
        self.sum_nees += nees;
        true
    }

    /// The Welford update for any n.
    fn add_any(
        &mut self,
        e: &[f64],
        x: &[f64],
        p: &[f64],
        nees: f64,
        de: &mut [f64],
        dx: &mut [f64],
    ) {
        let n = self.n;
        self.count += 1;
        let k = self.count as f64;
        let f = (k - 1.0) / k;
        for i in 0..n {
            de[i] = e[i] - self.mean_e[i];
            dx[i] = x[i] - self.mean_x[i];
            self.mean_e[i] += de[i] / k;
            self.mean_x[i] += dx[i] / k;
            self.m2_x[i] += f * (dx[i] * dx[i]);
        }
        for j in 0..n {
            for i in 0..n {
                self.c_ee[i + j * n] += f * (de[i] * de[j]);
                self.c_ex[i + j * n] += f * (de[i] * dx[j]);
                self.sum_p[i + j * n] += p[i + j * n];
            }
        }
        self.sum_nees += nees;
    }

    /// Chan–Golub–LeVeque merge of `other` into `self`.
    fn merge(&mut self, other: &SlotAcc) -> Result<()> {
        self.nis_count += other.nis_count;
        self.nis_dof += other.nis_dof;
        self.sum_nis += other.sum_nis;
        self.sum_ll += other.sum_ll;
        if other.count == 0 {
            return Ok(());
        }
        self.ensure_dim(other.n)?;
        let n = self.n;
        let (na, nb) = (self.count as f64, other.count as f64);
        self.count += other.count;
        let total = self.count as f64;
        let w = nb / total;
        let f = na * nb / total;
        let de: Vec<f64> = (0..n).map(|i| other.mean_e[i] - self.mean_e[i]).collect();
        let dx: Vec<f64> = (0..n).map(|i| other.mean_x[i] - self.mean_x[i]).collect();
        for i in 0..n {
            self.mean_e[i] += de[i] * w;
            self.mean_x[i] += dx[i] * w;
            self.m2_x[i] = self.m2_x[i] + other.m2_x[i] + f * (dx[i] * dx[i]);
        }
        for j in 0..n {
            for i in 0..n {
                let ij = i + j * n;
                self.c_ee[ij] = self.c_ee[ij] + other.c_ee[ij] + f * (de[i] * de[j]);
                self.c_ex[ij] = self.c_ex[ij] + other.c_ex[ij] + f * (de[i] * dx[j]);
                self.sum_p[ij] += other.sum_p[ij];
            }
        }
        self.sum_nees += other.sum_nees;
        Ok(())
    }
}

/// Σ r(a) r(b)ᵀ and the squares for normalising, for one residual pair.
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
struct PairAcc {
    ma: usize,
    mb: usize,
    count: usize,
    /// Σ r(a) r(b)ᵀ, ma × mb column-major.
    sum_ab: Vec<f64>,
    sum_a2: Vec<f64>,
    sum_b2: Vec<f64>,
}

impl PairAcc {
    fn ensure_dims(&mut self, ma: usize, mb: usize) -> Result<()> {
        if self.count == 0 && self.ma == 0 && self.mb == 0 {
            self.ma = ma;
            self.mb = mb;
            self.sum_ab = vec![0.0; ma * mb];
            self.sum_a2 = vec![0.0; ma];
            self.sum_b2 = vec![0.0; mb];
            Ok(())
        } else if self.ma != ma {
            Err(mismatch(Quantity::Residual, self.ma, ma))
        } else if self.mb != mb {
            Err(mismatch(Quantity::Residual, self.mb, mb))
        } else {
            Ok(())
        }
    }

    fn add(&mut self, a: &[f64], b: &[f64]) -> Result<()> {
        self.ensure_dims(a.len(), b.len())?;
        self.count += 1;
        for (i, &ai) in a.iter().enumerate() {
            self.sum_a2[i] += ai * ai;
        }
        for (j, &bj) in b.iter().enumerate() {
            self.sum_b2[j] += bj * bj;
            for (i, &ai) in a.iter().enumerate() {
                self.sum_ab[i + j * self.ma] += ai * bj;
            }
        }
        Ok(())
    }

    fn merge(&mut self, other: &PairAcc) -> Result<()> {
        if other.count == 0 {
            return Ok(());
        }
        self.ensure_dims(other.ma, other.mb)?;
        self.count += other.count;
        for (s, o) in self.sum_ab.iter_mut().zip(&other.sum_ab) {
            *s += o;
        }
        for (s, o) in self.sum_a2.iter_mut().zip(&other.sum_a2) {
            *s += o;
        }
        for (s, o) in self.sum_b2.iter_mut().zip(&other.sum_b2) {
            *s += o;
        }
        Ok(())
    }
}

/// Everything accumulated over a set of runs.
#[derive(Clone, Debug)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
struct Accumulator {
    /// How many runs it holds.
    runs: usize,
    slots: Vec<SlotAcc>,
    pairs: Vec<PairAcc>,
}

impl Accumulator {
    fn new(slots: usize, pairs: usize) -> Self {
        Self {
            runs: 0,
            slots: vec![SlotAcc::default(); slots],
            pairs: vec![PairAcc::default(); pairs],
        }
    }

    /// Whether every buffer has the length its dimensions say: true for what this crate
    /// builds, checked for shards read back from a file (which could have been edited).
    fn well_formed(&self, slots: usize, pairs: usize) -> bool {
        let slot_ok = |a: &SlotAcc| {
            let (n, nn) = (a.n, a.n.checked_mul(a.n));
            let empty = a.count == 0 && a.n == 0;
            empty
                || (nn.is_some()
                    && [&a.mean_e, &a.mean_x, &a.m2_x].iter().all(|v| v.len() == n)
                    && [&a.c_ee, &a.c_ex, &a.sum_p]
                        .iter()
                        .all(|v| Some(v.len()) == nn))
        };
        let pair_ok = |p: &PairAcc| {
            Some(p.sum_ab.len()) == p.ma.checked_mul(p.mb)
                && p.sum_a2.len() == p.ma
                && p.sum_b2.len() == p.mb
        };
        self.slots.len() == slots
            && self.pairs.len() == pairs
            && self.slots.iter().all(slot_ok)
            && self.pairs.iter().all(pair_ok)
    }

    fn merge(&mut self, other: &Accumulator) -> Result<()> {
        self.runs += other.runs;
        for (s, o) in self.slots.iter_mut().zip(&other.slots) {
            s.merge(o)?;
        }
        for (s, o) in self.pairs.iter_mut().zip(&other.pairs) {
            s.merge(o)?;
        }
        Ok(())
    }
}

/// A residual waiting for the end of its run, at one pair endpoint slot.
#[derive(Clone, Debug, Default)]
struct Pending {
    set: bool,
    values: Vec<f64>,
}

/// What a realization writes its statistics into; handed to the closure of
/// [`MonteCarlo::run`]. Each record is checked before anything is accumulated, so a record
/// that errors changes nothing.
///
/// Records are converted to `f64`; the recorder is not generic, so one realization may record
/// filters of different scalar types or sizes at different slots (but each slot must have the
/// same sizes in every run).
#[derive(Debug)]
pub struct Recorder {
    acc: Accumulator,
    pairs: Vec<(usize, usize)>,
    run: usize,
    seed: u64,
    estimate_seen: Vec<usize>,
    innovation_seen: Vec<usize>,
    /// slot → index into `pending` when the slot is a pair endpoint.
    endpoint: Vec<Option<usize>>,
    pending: Vec<Pending>,
    e: Vec<f64>,
    x: Vec<f64>,
    p: Vec<f64>,
    chol: Vec<f64>,
    de: Vec<f64>,
    dx: Vec<f64>,
}

impl Recorder {
    fn new(slots: usize, pairs: &[(usize, usize)]) -> Self {
        let mut endpoint = vec![None; slots];
        let mut pending = Vec::new();
        for &(a, b) in pairs {
            for s in [a, b] {
                if endpoint[s].is_none() {
                    endpoint[s] = Some(pending.len());
                    pending.push(Pending::default());
                }
            }
        }
        Self {
            acc: Accumulator::new(slots, pairs.len()),
            pairs: pairs.to_vec(),
            run: usize::MAX,
            seed: 0,
            estimate_seen: vec![usize::MAX; slots],
            innovation_seen: vec![usize::MAX; slots],
            endpoint,
            pending,
            e: Vec::new(),
            x: Vec::new(),
            p: Vec::new(),
            chol: Vec::new(),
            de: Vec::new(),
            dx: Vec::new(),
        }
    }

    fn begin(&mut self, run: usize, seed: u64) {
        self.run = run;
        self.seed = seed;
        for p in &mut self.pending {
            p.set = false;
        }
    }

    /// Accumulates the residual pairs completed in this run.
    fn end_run(&mut self) -> Result<()> {
        for (k, &(a, b)) in self.pairs.iter().enumerate() {
            if let (Some(ia), Some(ib)) = (self.endpoint[a], self.endpoint[b]) {
                let (pa, pb) = (&self.pending[ia], &self.pending[ib]);
                if pa.set && pb.set {
                    self.acc.pairs[k].add(&pa.values, &pb.values)?;
                }
            }
        }
        Ok(())
    }

    /// The index of the run being recorded.
    pub fn run_index(&self) -> usize {
        self.run
    }

    /// Its seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    fn check_slot(&self, slot: usize) -> Result<()> {
        if slot < self.estimate_seen.len() {
            Ok(())
        } else {
            Err(slot_error(slot))
        }
    }

    /// Records the estimate (x̂, P) of the truth x at `slot`: the error e = x − x̂ enters the
    /// ensemble mean and covariance, the NEES eᵀP⁻¹e (Cholesky, in f64), P the mean filter
    /// covariance, and (e, x̂) the orthogonality statistics.
    ///
    /// At most once per slot and run. Errors: slot out of range ([`Setting::Slot`]), recorded
    /// twice ([`ValidationError::RecordedTwice`]), shapes, non-finite values, P not positive definite.
    pub fn record_estimate<T: Real, N: Dim>(
        &mut self,
        slot: usize,
        truth: &OVector<T, N>,
        estimate: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.check_slot(slot)?;
        if self.estimate_seen[slot] == self.run {
            return Err(ValidationError::RecordedTwice { slot });
        }
        let n = truth.nrows();
        ensure_shape(estimate, n, 1, STAGE, Quantity::Mean)?;
        ensure_shape(covariance, n, n, STAGE, Quantity::Covariance)?;
        let acc = &self.acc.slots[slot];
        if acc.n != 0 && acc.n != n {
            return Err(mismatch(Quantity::Mean, acc.n, n));
        }
        fill(&mut self.x, estimate.iter().map(|&v| to_f64(v)));
        fill(
            &mut self.e,
            truth.iter().zip(&self.x).map(|(&t, &x)| to_f64(t) - x),
        );
        fill(&mut self.p, covariance.iter().map(|&v| to_f64(v)));
        if !self.e.iter().chain(&self.x).all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Mean,
            }
            .into());
        }
        if !self.p.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Covariance,
            }
            .into());
        }
        let nees = match small_nees(&self.p, &self.e, n) {
            Some(nees) => nees,
            None => {
                self.chol.clone_from(&self.p);
                self.de.clone_from(&self.e);
                cholesky_quadratic_form(&mut self.chol, &mut self.de, n)
            }
        }
        .ok_or(Error::NotPositiveDefinite {
            stage: STAGE,
            quantity: Quantity::Covariance,
        })?;
        self.de.resize(n, 0.0);
        self.dx.resize(n, 0.0);
        let acc = &mut self.acc.slots[slot];
        acc.ensure_dim(n)?;
        acc.add(&self.e, &self.x, &self.p, nees, &mut self.de, &mut self.dx);
        self.estimate_seen[slot] = self.run;
        Ok(())
    }

    /// [`record_estimate`](Self::record_estimate) with the filter's current state and
    /// covariance.
    pub fn record_filter<T: Real, N: Dim, E: Estimator<T, N> + ?Sized>(
        &mut self,
        slot: usize,
        truth: &OVector<T, N>,
        filter: &E,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.record_estimate(slot, truth, filter.state(), filter.covariance())
    }

    /// Records an update's NIS (and log-likelihood) at `slot`; its degrees of freedom are the
    /// innovation's dimension m. At most once per slot and run (record the stacked
    /// measurement, or use different slots, for several updates at one time).
    pub fn record_innovation<T: Real, M: Dim>(
        &mut self,
        slot: usize,
        report: &UpdateReport<T, M>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<M>,
    {
        self.check_slot(slot)?;
        if self.innovation_seen[slot] == self.run {
            return Err(ValidationError::RecordedTwice { slot });
        }
        let (nis, ll) = (to_f64(report.nis), to_f64(report.log_likelihood));
        if !(nis >= 0.0) || !nis.is_finite() || !ll.is_finite() {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Innovation,
            }
            .into());
        }
        let acc = &mut self.acc.slots[slot];
        acc.nis_count += 1;
        acc.nis_dof += report.innovation.nrows();
        acc.sum_nis += nis;
        acc.sum_ll += ll;
        self.innovation_seen[slot] = self.run;
        Ok(())
    }

    /// Records the residual r at `slot` for the residual cross-correlation
    /// (1/N) Σ r(a) r(b)ᵀ of each requested pair (a, b) having `slot` as an end. Typically the
    /// innovation ([`UpdateReport::innovation`]), as in Lu's check. Ignored when `slot` is not
    /// the end of any pair; a pair counts in a run only if both its ends were recorded.
    ///
    /// At most once per slot and run. Errors: slot out of range or recorded twice, non-finite
    /// values.
    pub fn record_residual<T: Real, M: Dim>(
        &mut self,
        slot: usize,
        residual: &OVector<T, M>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<M>,
    {
        self.check_slot(slot)?;
        let Some(k) = self.endpoint[slot] else {
            return Ok(());
        };
        let pending = &mut self.pending[k];
        if pending.set {
            return Err(ValidationError::RecordedTwice { slot });
        }
        if !residual.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Residual,
            }
            .into());
        }
        fill(&mut pending.values, residual.iter().map(|&v| to_f64(v)));
        pending.set = true;
        Ok(())
    }
}

fn fill(buffer: &mut Vec<f64>, values: impl Iterator<Item = f64>) {
    buffer.clear();
    buffer.extend(values);
}

fn slot_error(slot: usize) -> ValidationError {
    ValidationError::setting(Setting::Slot, slot)
}

/// A Monte Carlo consistency experiment: how many runs, how many time slots, the master seed,
/// the residual pairs, and the chunking that makes results independent of the thread count.
/// `E` is the error type the realizations return ([`with_error`](Self::with_error)). See the
/// [module docs](self).
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

    /// Splits the runs into `chunks` ≥ 1 contiguous chunks (default 64; fewer if there are
    /// fewer runs). The statistics depend on it only through floating-point summation order;
    /// more chunks let more threads work, at (2 × threads + 1) × slots accumulators of memory.
    pub fn with_chunks(mut self, chunks: usize) -> Result<Self> {
        if chunks == 0 {
            return Err(ValidationError::setting(Setting::ChunkCount, 0));
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
    /// the wrong size ([`MonteCarloError::Shards`]); shapes that differ between shards
    /// ([`MonteCarloError::Shape`]).
    pub fn merge_shards(
        &self,
        shards: impl IntoIterator<Item = Shard>,
    ) -> Result<EnsembleStats, MonteCarloError<E>> {
        let invalid = |value: usize| MonteCarloError::Shards {
            error: ValidationError::setting(Setting::Shard, value),
        };
        let identity = self.identity();
        let mut shards: Vec<Shard> = shards.into_iter().collect();
        shards.sort_by_key(|s| s.first_chunk);
        let mut total = Accumulator::new(self.slots, self.pairs.len());
        let mut next = 0;
        for shard in &shards {
            if shard.experiment != identity || shard.first_chunk != next {
                return Err(invalid(shard.first_chunk));
            }
            for chunk in &shard.chunks {
                if !chunk.well_formed(self.slots, self.pairs.len()) {
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

/// The ensemble statistics of the estimates recorded at one slot, over the N runs that
/// recorded one. e = x − x̂ is the error, P the filter's covariance.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EstimateStats {
    /// N.
    pub samples: usize,
    /// The ensemble mean error ē = (1/N) Σ eˡ (Lu's e^ave).
    pub mean_error: DVector<f64>,
    /// The ensemble error covariance P_ens = 1/(N − 1) Σ (eˡ − ē)(eˡ − ē)ᵀ (Lu's P^ave);
    /// NaN when N < 2.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub error_covariance: DMatrix<f64>,
    /// The mean filter covariance P̄ = (1/N) Σ Pˡ, which P_ens should match.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub mean_covariance: DMatrix<f64>,
    /// The average NEES ε̄ = (1/N) Σ eˡᵀ (Pˡ)⁻¹ eˡ, ~ χ²_{N·n}/N when consistent.
    pub mean_nees: f64,
    /// Lu's orthogonality matrix (1/N) Σ (eˡ − ē) x̂ˡᵀ = (1/N) Σ (eˡ − ē)(x̂ˡ − x̄)ᵀ, entry
    /// (i, j) pairing error component i with estimate component j.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub orthogonality: DMatrix<f64>,
    /// Its normalised version: the sample correlation of eᵢ and x̂ⱼ across runs, in [−1, 1];
    /// NaN where either has no spread (e.g. x̂ at the prior, the same in every run).
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub orthogonality_correlation: DMatrix<f64>,
    /// The sample variance of each estimate component across runs, 1/(N − 1) Σ (x̂ˡ − x̄)².
    pub estimate_variance: DVector<f64>,
}

impl EstimateStats {
    fn from_acc(acc: &SlotAcc) -> Self {
        let n = acc.n;
        let count = acc.count as f64;
        let dof = count - 1.0;
        let unbiased = |v: f64| if acc.count >= 2 { v / dof } else { f64::NAN };
        let c_ee = DMatrix::from_column_slice(n, n, &acc.c_ee);
        let c_ex = DMatrix::from_column_slice(n, n, &acc.c_ex);
        let correlation = DMatrix::from_fn(n, n, |i, j| {
            let denominator = (c_ee[(i, i)] * acc.m2_x[j]).sqrt();
            if denominator > 0.0 {
                c_ex[(i, j)] / denominator
            } else {
                f64::NAN
            }
        });
        Self {
            samples: acc.count,
            mean_error: DVector::from_column_slice(&acc.mean_e),
            error_covariance: c_ee.map(unbiased),
            mean_covariance: DMatrix::from_column_slice(n, n, &acc.sum_p) / count,
            mean_nees: acc.sum_nees / count,
            orthogonality: c_ex / count,
            orthogonality_correlation: correlation,
            estimate_variance: DVector::from_iterator(n, acc.m2_x.iter().map(|&v| unbiased(v))),
        }
    }

    /// The state dimension n.
    pub fn state_dim(&self) -> usize {
        self.mean_error.nrows()
    }

    /// The band of [`mean_nees`](Self::mean_nees): χ²_{N·n}/N at `confidence`.
    pub fn nees_band(&self, confidence: f64) -> Result<ChiSquareBand> {
        ChiSquareBand::two_sided(self.state_dim(), self.samples, confidence)
    }

    /// The ratios (P_ens)ᵢᵢ / (P̄)ᵢᵢ, ≈ 1 when consistent.
    pub fn covariance_ratio(&self) -> DVector<f64> {
        DVector::from_fn(self.state_dim(), |i, _| {
            self.error_covariance[(i, i)] / self.mean_covariance[(i, i)]
        })
    }

    /// The band of each [`covariance_ratio`](Self::covariance_ratio) at `confidence`:
    /// χ²_{N−1}((1 ∓ c)/2)/(N − 1) (exact for Gaussian errors and a covariance that does not
    /// depend on the run, as in a linear Kalman filter). Needs N ≥ 2.
    pub fn covariance_ratio_band(&self, confidence: f64) -> Result<(f64, f64)> {
        let band = ChiSquareBand::for_sum(self.samples.saturating_sub(1), 1, confidence)?;
        let dof = (self.samples - 1) as f64;
        Ok((band.lower / dof, band.upper / dof))
    }

    /// The half-width of each component's band for [`mean_error`](Self::mean_error):
    /// t_{N−1,(1+c)/2} · sᵢ / √N with sᵢ² = (P_ens)ᵢᵢ. Needs N ≥ 2.
    pub fn mean_error_bound(&self, confidence: f64) -> Result<DVector<f64>> {
        let t = dist::t_two_sided(
            validate_confidence(confidence)?,
            self.samples.saturating_sub(1),
        )?;
        let root_n = (self.samples as f64).sqrt();
        Ok(DVector::from_fn(self.state_dim(), |i, _| {
            t * self.error_covariance[(i, i)].sqrt() / root_n
        }))
    }

    /// The bound on each entry of
    /// [`orthogonality_correlation`](Self::orthogonality_correlation) at `confidence`: the
    /// sample correlation r of independent Gaussians satisfies r √(N−2)/√(1−r²) ~ t_{N−2}, so
    /// |r| ≤ t/√(N − 2 + t²) with t = t_{N−2,(1+c)/2} (≈ z/√N). Needs N ≥ 3.
    pub fn orthogonality_bound(&self, confidence: f64) -> Result<f64> {
        let dof = self.samples.saturating_sub(2);
        let t = dist::t_two_sided(validate_confidence(confidence)?, dof)?;
        Ok(t / (dof as f64 + t * t).sqrt())
    }
}

/// The NIS statistics recorded at one slot.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct InnovationStats {
    /// Number of innovations recorded N.
    pub samples: usize,
    /// Σ m over them (N·m for a fixed measurement size m).
    pub degrees_of_freedom: usize,
    /// The average NIS (1/N) Σ νᵀS⁻¹ν, ~ χ²_{N·m}/N when consistent.
    pub mean_nis: f64,
    /// The average log-likelihood of the measurement at this slot.
    pub mean_log_likelihood: f64,
}

impl InnovationStats {
    /// The band of [`mean_nis`](Self::mean_nis) at `confidence`.
    pub fn nis_band(&self, confidence: f64) -> Result<ChiSquareBand> {
        ChiSquareBand::for_sum(self.degrees_of_freedom, self.samples, confidence)
    }
}

/// The statistics of one slot.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SlotStats {
    /// The slot index.
    pub slot: usize,
    /// Estimate statistics, if any run recorded an estimate here.
    pub estimate: Option<EstimateStats>,
    /// NIS statistics, if any run recorded an innovation here.
    pub innovation: Option<InnovationStats>,
}

/// Lu's residual check between slots a and b: (1/N) Σ r(a) r(b)ᵀ ≈ 0 for a consistent filter,
/// whose innovations are white.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ResidualPairStats {
    /// The first slot a.
    pub first: usize,
    /// The second slot b.
    pub second: usize,
    /// Number of runs that recorded both N.
    pub samples: usize,
    /// (1/N) Σ r(a) r(b)ᵀ (m_a × m_b; 0 × 0 when N = 0).
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub cross_correlation: DMatrix<f64>,
    /// Entry (i, j) normalised as in Bar-Shalom et al. eq 5.4.2-12:
    /// Σ rᵢ(a) rⱼ(b) / √(Σ rᵢ(a)² Σ rⱼ(b)²), ≈ N(0, 1/N) when r(a) and r(b) are independent
    /// and zero-mean; NaN where a component is identically 0.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub normalized: DMatrix<f64>,
}

impl ResidualPairStats {
    fn from_acc(first: usize, second: usize, acc: &PairAcc) -> Self {
        let (ma, mb) = (acc.ma, acc.mb);
        let sum = DMatrix::from_column_slice(ma, mb, &acc.sum_ab);
        let normalized = DMatrix::from_fn(ma, mb, |i, j| {
            let d = (acc.sum_a2[i] * acc.sum_b2[j]).sqrt();
            if d > 0.0 { sum[(i, j)] / d } else { f64::NAN }
        });
        Self {
            first,
            second,
            samples: acc.count,
            cross_correlation: sum / (acc.count.max(1) as f64),
            normalized,
        }
    }

    /// The bound z₍₁₊c₎/₂ / √N on each entry of [`normalized`](Self::normalized).
    pub fn bound(&self, confidence: f64) -> Result<f64> {
        crate::consistency::autocorrelation_bound(self.samples, confidence)
    }
}

/// What [`MonteCarlo::run`] returns: per-slot ensemble statistics and the residual pairs.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EnsembleStats {
    /// The number of runs N.
    pub runs: usize,
    /// One entry per slot, in slot order.
    pub slots: Vec<SlotStats>,
    /// One entry per requested residual pair, in request order.
    pub residual_pairs: Vec<ResidualPairStats>,
}

impl EnsembleStats {
    /// Runs every check at `confidence` (e.g. 0.95: a consistent filter fails each check with
    /// probability at most 5%), combining each check's single tests by Simes' rule
    /// ([`FamilyRule::Simes`]). See [`verdict_with`](Self::verdict_with).
    pub fn verdict(&self, confidence: f64) -> Result<Verdict> {
        self.verdict_with(confidence, FamilyRule::Simes)
    }

    /// Runs every check at `confidence`, combining each check's single tests by `rule`.
    ///
    /// Each single test has a two-sided band at c (= `confidence` under Simes, the rule's
    /// `test_confidence` under the binomial rule) and a two-sided p-value from the same
    /// distribution; the rule turns a check's p-values into its decision:
    ///
    /// | check | single test (one per slot and component or entry) | band at c |
    /// |---|---|---|
    /// | [`MeanError`](Check::MeanError) | t = ēᵢ / (sᵢ/√N), sᵢ² = (P_ens)ᵢᵢ | ±t_{N−1,(1+c)/2} |
    /// | [`ErrorCovariance`](Check::ErrorCovariance) | (P_ens)ᵢᵢ / (P̄)ᵢᵢ | χ²_{N−1}((1∓c)/2)/(N−1) |
    /// | [`Nees`](Check::Nees) | ε̄ | χ²_{N·n}((1∓c)/2)/N |
    /// | [`Nis`](Check::Nis) | average NIS | χ²_{N·m}((1∓c)/2)/N |
    /// | [`Orthogonality`](Check::Orthogonality) | corr(eᵢ, x̂ⱼ) | ±t/√(N−2+t²), t = t_{N−2,(1+c)/2} |
    /// | [`ResidualCorrelation`](Check::ResidualCorrelation) | normalised Σ rᵢ(a) rⱼ(b) | ±z_{(1+c)/2}/√N |
    ///
    /// The mean-error test uses the ensemble spread, not the filter's P, so it tests bias
    /// alone (a filter that is unbiased but over-confident fails only the covariance and NEES
    /// checks). Tests whose statistic is undefined (a component with no spread, e.g. x̂ at the
    /// prior) are skipped; a check with no test is [`NotRun`](crate::consistency::Outcome::NotRun).
    ///
    /// The bands are exact for a linear-Gaussian system and a Kalman filter whose model is
    /// the truth's (errors Gaussian, P the same in every run), and asymptotic otherwise. They
    /// assume the truth's initial state is drawn from the filter's prior: with a fixed initial
    /// truth, e and x̂ are correlated through the prior, and the orthogonality, covariance and
    /// NEES checks can fail for a correct filter until the prior is forgotten.
    pub fn verdict_with(&self, confidence: f64, rule: FamilyRule) -> Result<Verdict> {
        let family = |check| FamilyTest::new(check, confidence, rule);
        let mut mean = family(Check::MeanError)?;
        let mut cov = family(Check::ErrorCovariance)?;
        let mut nees = family(Check::Nees)?;
        let mut nis = family(Check::Nis)?;
        let mut orth = family(Check::Orthogonality)?;
        let mut resid = family(Check::ResidualCorrelation)?;
        let c = mean.band_confidence();
        let mut nees_band: Option<ChiSquareBand> = None;
        let mut nis_band: Option<ChiSquareBand> = None;
        for s in &self.slots {
            if let Some(e) = &s.estimate {
                estimate_tests(s.slot, e, c, &mut mean, &mut cov, &mut orth)?;
                let band = cached_band(&mut nees_band, e.state_dim() * e.samples, e.samples, c)?;
                nees.add(
                    Location::Slot { slot: s.slot },
                    e.mean_nees,
                    band.lower,
                    band.upper,
                    band.p_value(e.mean_nees)?,
                );
            }
            if let Some(i) = &s.innovation {
                let band = cached_band(&mut nis_band, i.degrees_of_freedom, i.samples, c)?;
                nis.add(
                    Location::Slot { slot: s.slot },
                    i.mean_nis,
                    band.lower,
                    band.upper,
                    band.p_value(i.mean_nis)?,
                );
            }
        }
        for p in &self.residual_pairs {
            if p.samples == 0 {
                continue;
            }
            let bound = p.bound(c)?;
            let root_n = (p.samples as f64).sqrt();
            for j in 0..p.normalized.ncols() {
                for i in 0..p.normalized.nrows() {
                    let rho = p.normalized[(i, j)];
                    if rho.is_nan() {
                        continue;
                    }
                    let location = Location::Pair {
                        first: p.first,
                        second: p.second,
                        row: i,
                        col: j,
                    };
                    resid.add(
                        location,
                        rho,
                        -bound,
                        bound,
                        dist::normal_p_value(rho * root_n),
                    );
                }
            }
        }
        Ok(Verdict {
            runs: self.runs,
            confidence,
            rule,
            checks: vec![
                mean.finish(),
                cov.finish(),
                nees.finish(),
                nis.finish(),
                orth.finish(),
                resid.finish(),
            ],
        })
    }
}

/// The χ² band for (dof, terms), recomputed only when they change (usually they never do).
fn cached_band(
    cache: &mut Option<ChiSquareBand>,
    dof: usize,
    terms: usize,
    confidence: f64,
) -> Result<ChiSquareBand> {
    match cache {
        Some(b) if b.degrees_of_freedom == dof && b.terms == terms => Ok(*b),
        _ => {
            let b = ChiSquareBand::for_sum(dof, terms, confidence)?;
            *cache = Some(b);
            Ok(b)
        }
    }
}

/// The mean-error, covariance and orthogonality tests of one slot.
fn estimate_tests(
    slot: usize,
    e: &EstimateStats,
    confidence: f64,
    mean: &mut FamilyTest,
    cov: &mut FamilyTest,
    orth: &mut FamilyTest,
) -> Result<()> {
    let n = e.state_dim();
    let samples = e.samples;
    if samples >= 2 {
        let dof = samples - 1;
        let t_crit = dist::t_two_sided(confidence, dof)?;
        let (lo, hi) = e.covariance_ratio_band(confidence)?;
        let root_n = (samples as f64).sqrt();
        for i in 0..n {
            let location = Location::Component { slot, component: i };
            let (m, var, p) = (
                e.mean_error[i],
                e.error_covariance[(i, i)],
                e.mean_covariance[(i, i)],
            );
            if !(m == 0.0 && var == 0.0) {
                let t = m / (var.sqrt() / root_n);
                mean.add(location, t, -t_crit, t_crit, dist::t_p_value(t, dof)?);
            }
            if !(var == 0.0 && p == 0.0) {
                let ratio = var / p;
                let p_value = dist::chi2_p_value(ratio * dof as f64, dof)?;
                cov.add(location, ratio, lo, hi, p_value);
            }
        }
    }
    if samples >= 3 {
        let dof = samples - 2;
        let bound = e.orthogonality_bound(confidence)?;
        for j in 0..n {
            for i in 0..n {
                let r = e.orthogonality_correlation[(i, j)];
                if r.is_nan() {
                    continue;
                }
                let t = r * (dof as f64 / (1.0 - r * r)).sqrt();
                let location = Location::Entry {
                    slot,
                    row: i,
                    col: j,
                };
                orth.add(location, r, -bound, bound, dist::t_p_value(t, dof)?);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fixed-size recording path (n ≤ 6) gives the bits of the runtime-size one: NEES by
    /// the same factorisation, Welford moments by the same operations.
    #[test]
    fn small_states_record_the_bits_of_the_runtime_size_path() {
        // Deterministic pseudo-random entries in (−1, 1) (SplitMix64).
        let mut seed = 0;
        let mut next = || {
            seed += 1;
            (run_seed(11, seed) >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        for n in 1..=6 {
            let (mut small, mut any) = (SlotAcc::default(), SlotAcc::default());
            small.ensure_dim(n).unwrap();
            any.ensure_dim(n).unwrap();
            for _ in 0..5 {
                let e: Vec<f64> = (0..n).map(|_| next()).collect();
                let x: Vec<f64> = (0..n).map(|_| 10.0 * next()).collect();
                // P = A Aᵀ + I, positive definite.
                let a: Vec<f64> = (0..n * n).map(|_| next()).collect();
                let p: Vec<f64> = (0..n * n)
                    .map(|ij| {
                        let (i, j) = (ij % n, ij / n);
                        let aat: f64 = (0..n).map(|k| a[i + k * n] * a[j + k * n]).sum();
                        aat + if i == j { 1.0 } else { 0.0 }
                    })
                    .collect();
                let (mut chol, mut v) = (p.clone(), e.clone());
                let reference = cholesky_quadratic_form(&mut chol, &mut v, n).unwrap();
                let nees = small_nees(&p, &e, n).unwrap().unwrap();
                assert_eq!(nees.to_bits(), reference.to_bits(), "n = {n}");
                let (mut de, mut dx) = (vec![0.0; n], vec![0.0; n]);
                small.add(&e, &x, &p, nees, &mut de, &mut dx);
                any.add_any(&e, &x, &p, nees, &mut de, &mut dx);
            }
            let bits = |a: &SlotAcc| {
                [&a.mean_e, &a.mean_x, &a.c_ee, &a.c_ex, &a.m2_x, &a.sum_p]
                    .iter()
                    .flat_map(|v| v.iter().map(|x| x.to_bits()))
                    .chain([a.sum_nees.to_bits(), a.count as u64])
                    .collect::<Vec<u64>>()
            };
            assert_eq!(bits(&small), bits(&any), "n = {n}");
        }
        // Not positive definite: refused on both paths.
        assert_eq!(
            small_nees(&[1.0, 2.0, 2.0, 1.0], &[1.0, 0.0], 2),
            Some(None)
        );
        assert!(small_nees(&[1.0; 49], &[1.0; 7], 7).is_none());
    }

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

    #[test]
    fn welford_and_chan_merge_match_two_pass() {
        // 7 samples of a 2-vector with a large offset (cancellation-prone for raw sums).
        let data: Vec<([f64; 2], [f64; 2])> = (0..7)
            .map(|k| {
                let k = k as f64;
                (
                    [0.3 * k - 1.0, (k * 1.7).sin()],
                    [1e8 + k * k, 1e8 - 2.0 * k],
                )
            })
            .collect();
        let p = [1.0, 0.0, 0.0, 1.0];
        let add = |acc: &mut SlotAcc, (e, x): &([f64; 2], [f64; 2])| {
            acc.ensure_dim(2).unwrap();
            acc.add(e, x, &p, 0.0, &mut [0.0; 2], &mut [0.0; 2]);
        };
        let mut a = SlotAcc::default();
        let mut b = SlotAcc::default();
        for d in &data[..3] {
            add(&mut a, d);
        }
        for d in &data[3..] {
            add(&mut b, d);
        }
        a.merge(&b).unwrap();
        let n = data.len() as f64;
        let me: Vec<f64> = (0..2)
            .map(|i| data.iter().map(|d| d.0[i]).sum::<f64>() / n)
            .collect();
        let mx: Vec<f64> = (0..2)
            .map(|i| data.iter().map(|d| d.1[i]).sum::<f64>() / n)
            .collect();
        for i in 0..2 {
            assert!((a.mean_e[i] - me[i]).abs() < 1e-14);
            for j in 0..2 {
                let cee: f64 = data
                    .iter()
                    .map(|d| (d.0[i] - me[i]) * (d.0[j] - me[j]))
                    .sum();
                let cex: f64 = data
                    .iter()
                    .map(|d| (d.0[i] - me[i]) * (d.1[j] - mx[j]))
                    .sum();
                assert!((a.c_ee[i + 2 * j] - cee).abs() < 1e-12 * cee.abs().max(1.0));
                assert!((a.c_ex[i + 2 * j] - cex).abs() < 1e-9 * cex.abs().max(1.0));
            }
            let m2: f64 = data.iter().map(|d| (d.1[i] - mx[i]).powi(2)).sum();
            assert!((a.m2_x[i] - m2).abs() < 1e-9 * m2);
        }
        assert_eq!(a.count, 7);
    }

    #[test]
    fn run_seed_is_splitmix64() {
        // SplitMix64 seeded with 0: first outputs (reference values of the algorithm).
        assert_eq!(run_seed(0, 0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(run_seed(0, 1), 0x6E78_9E6A_A1B9_65F4);
    }
}
