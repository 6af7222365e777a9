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
//! On a Slurm cluster, this job-array script runs a program that takes `--shard I/N --out
//! FILE` (task I of N writes shard I) and `--merge FILE...` (the merge), as estim's Monte
//! Carlo examples do (`cargo run --example lu_delays -- --quick --shard 0/4 --out s0.json`).
//! It is `estim-filters/src/monte_carlo/job_array.sbatch` in the repository, the very file the
//! CI submits to a one-node cluster (`.ci/slurm`) before checking the merge against a single
//! process's run bit for bit:
//!
//! ```sh
#![doc = include_str!("job_array.sbatch")]
//! ```
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

mod accumulator;
mod error;
mod recorder;
mod runner;
mod seed;
mod stats;

pub use error::MonteCarloError;
pub use recorder::Recorder;
pub use runner::{MonteCarlo, Progress, Shard};
pub use seed::run_seed;
pub use stats::{EnsembleStats, EstimateStats, InnovationStats, ResidualPairStats, SlotStats};
