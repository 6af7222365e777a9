//! One example's Monte Carlo experiments over many processes or machines (a Slurm job array,
//! `xargs -P`, a CI matrix): the flags every example that runs estim's Monte Carlo runner
//! takes, parsed here once, and the shard files.
//!
//! - `--shard I/N --out FILE`: run shard I (0 ≤ I < N) of each of the example's Monte Carlo
//!   experiments (`MonteCarlo::run_shard`) and write them to FILE (JSON); nothing else runs or
//!   prints.
//! - `--merge FILE...`: read the N shard files (any order), merge each experiment
//!   (`MonteCarlo::merge_shards`, bit-identical to one process) and print what the
//!   single-process run prints (its wall times aside: they time the merge).
//! - `--stats FILE` (a whole run or a merge): also write every experiment's ensemble statistics
//!   to FILE (JSON, every `f64` written exactly), the bits to compare between the two.
//!
//! The shards and the merge must be given the same other flags (`--quick`): a shard file
//! records them, and the merge refuses files of another example, other flags, another shard
//! count, a shard missing or given twice, or experiments of other sizes. The sbatch script
//! that runs an example this way is in `estim_filters::monte_carlo`'s docs
//! (`estim-filters/src/monte_carlo/job_array.sbatch`, the one `.ci/slurm` submits).
//!
//! An example body takes a [`Session`] and calls [`Session::run`] (or
//! [`run_with`](Session::run_with)) where it would call `MonteCarlo::run`: it gets `Some`
//! statistics in a whole run or a merge and `None` in a shard, where it skips what uses them.
//!
//! An example that loops over its runs by hand, with statistics of its own, calls
//! [`Session::records`] instead: each run gives a record (a flat `Vec<f64>`, stored bit for
//! bit), shard I of N runs the contiguous runs [`shard_runs`], and the merge hands back every
//! run's record in run order, so that the example's own sums over runs see the same numbers
//! in the same order as one process. [`Session::summary`] puts its results in `--stats`.
//!
//! An example whose statistics are sums over runs of many numbers per run (a curve per step,
//! say) calls [`Session::sums`]: each run adds its terms into [`ExactSums`], whose values do
//! not depend on the order of the additions, so a shard file holds the shard's sums (their
//! exact partials) rather than every run's terms, and the merge adds them to the bits of one
//! process.

use std::cell::RefCell;
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::exact_sum::{ExactSums, SumsState};
use estim::filters::ValidationError;
use estim::filters::monte_carlo::{EnsembleStats, MonteCarlo, MonteCarloError, Recorder, Shard};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// The shard file format (its `format` field); a file of another format is refused.
pub const FORMAT: &str = "estim-monte-carlo-shards/1";

/// What the process does with the Monte Carlo experiments.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Every run in this process (no sharding flag).
    Whole,
    /// Shard `index` of `count`, written to `out`.
    Shard {
        /// I, 0-based.
        index: usize,
        /// N ≥ 1.
        count: usize,
        /// Where the shard file goes.
        out: PathBuf,
    },
    /// Merge these shard files.
    Merge {
        /// The files, as given.
        files: Vec<PathBuf>,
    },
}

/// The sharding flags of a command line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Args {
    /// Whole run, shard or merge.
    pub mode: Mode,
    /// `--stats FILE`.
    pub stats: Option<PathBuf>,
}

/// Why sharding failed: bad flags, an unreadable or corrupt file, shards that do not belong
/// together. Its `Debug` is its message, so that `main` returning it prints the message.
pub struct ShardError(String);

impl ShardError {
    fn new(message: impl Into<String>) -> Self {
        Self(message.into())
    }
}

impl fmt::Display for ShardError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl fmt::Debug for ShardError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ShardError {}

const USAGE: &str = "usage: --shard I/N --out FILE (0 <= I < N), or --merge FILE..., \
                     optionally --stats FILE with a whole run or a merge";

fn usage(what: impl fmt::Display) -> ShardError {
    ShardError::new(format!("{what} ({USAGE})"))
}

/// Parses the sharding flags out of the arguments (without the program name); other flags
/// (`--quick`, `--json`, ...) are left to the example. Errors: I ≥ N, N = 0, a malformed
/// `I/N`, `--shard` without `--out` or the reverse, `--merge` without files, `--shard` with
/// `--merge`, `--stats` with `--shard`, a flag given twice.
pub fn parse<S: AsRef<str>>(args: impl IntoIterator<Item = S>) -> Result<Args, ShardError> {
    let args: Vec<String> = args.into_iter().map(|a| a.as_ref().to_string()).collect();
    let (mut shard, mut out, mut merge, mut stats) = (None, None, None::<Vec<PathBuf>>, None);
    let mut i = 0;
    let value = |i: usize, flag: &str| -> Result<String, ShardError> {
        match args.get(i + 1) {
            Some(v) if !v.starts_with("--") => Ok(v.clone()),
            _ => Err(usage(format!("{flag} needs a value"))),
        }
    };
    fn once<T>(slot: &mut Option<T>, v: T, flag: &str) -> Result<(), ShardError> {
        if slot.replace(v).is_some() {
            return Err(usage(format!("{flag} given twice")));
        }
        Ok(())
    }
    while i < args.len() {
        match args[i].as_str() {
            "--shard" => {
                let v = value(i, "--shard")?;
                once(&mut shard, parse_shard(&v)?, "--shard")?;
                i += 2;
            }
            "--out" => {
                once(&mut out, PathBuf::from(value(i, "--out")?), "--out")?;
                i += 2;
            }
            "--stats" => {
                once(&mut stats, PathBuf::from(value(i, "--stats")?), "--stats")?;
                i += 2;
            }
            "--merge" => {
                let files: Vec<PathBuf> = args[i + 1..]
                    .iter()
                    .take_while(|a| !a.starts_with("--"))
                    .map(PathBuf::from)
                    .collect();
                if files.is_empty() {
                    return Err(usage("--merge needs the shard files"));
                }
                i += 1 + files.len();
                once(&mut merge, files, "--merge")?;
            }
            _ => i += 1,
        }
    }
    let mode = match (shard, out, merge) {
        (None, None, None) => Mode::Whole,
        (Some((index, count)), Some(out), None) => {
            if stats.is_some() {
                return Err(usage(
                    "--stats goes with a whole run or a merge, not a shard",
                ));
            }
            Mode::Shard { index, count, out }
        }
        (None, None, Some(files)) => Mode::Merge { files },
        (Some(_), None, None) => return Err(usage("--shard needs --out FILE")),
        (None, Some(_), None) => return Err(usage("--out goes with --shard I/N")),
        (_, _, Some(_)) => return Err(usage("--merge cannot be combined with --shard or --out")),
    };
    Ok(Args { mode, stats })
}

/// `I/N` with 0 ≤ I < N.
fn parse_shard(v: &str) -> Result<(usize, usize), ShardError> {
    let bad = || usage(format!("--shard takes I/N, not '{v}'"));
    let (i, n) = v.split_once('/').ok_or_else(bad)?;
    let (i, n): (usize, usize) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 {
        return Err(usage("--shard I/N needs N >= 1 shards"));
    }
    if i >= n {
        return Err(usage(format!(
            "--shard {i}/{n}: the shard index I counts from 0 and must be below N = {n}"
        )));
    }
    Ok((i, n))
}

/// One experiment of a shard file: its key, its shard, and what the example keeps per shard
/// beside the runner's statistics ([`Session::extra`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Experiment {
    key: String,
    shard: Shard,
    extra: Option<serde_json::Value>,
}

/// One hand-looped experiment of a shard file ([`Session::records`]): runs `first ..
/// first + bits.len()` of `runs`, each run's record as the bits of its `f64`s.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Records {
    key: String,
    runs: usize,
    first: usize,
    bits: Vec<Vec<u64>>,
}

/// A shard file: the shards of every experiment of one example's run.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct ShardFile {
    format: String,
    example: String,
    settings: String,
    index: usize,
    count: usize,
    experiments: Vec<Experiment>,
    /// The hand-looped experiments (absent in files of runner-only examples).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    records: Vec<Records>,
    /// The experiments summed over runs ([`Session::sums`]; absent if none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    sums: Vec<SumsState>,
}

/// The runs of shard `index` of `count` of `runs` runs: `index·runs/count ..
/// (index+1)·runs/count`, contiguous, so the shards in index order are the runs in order.
pub fn shard_runs(index: usize, count: usize, runs: usize) -> Range<usize> {
    index * runs / count..(index + 1) * runs / count
}

fn to_bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// One process's part of an example's Monte Carlo experiments: whole, one shard, or the merge
/// of all shards (module docs).
pub struct Session {
    example: String,
    settings: String,
    args: Args,
    /// Shard mode: the experiments run so far. Whole and merge: unused.
    written: RefCell<Vec<Experiment>>,
    /// Merge mode: the files, sorted by shard index.
    loaded: Vec<ShardFile>,
    /// Whole and merge: each experiment's statistics, for `--stats`.
    stats: RefCell<Vec<(String, EnsembleStats)>>,
    /// Shard mode: the hand-looped experiments run so far; merge mode: their keys.
    records: RefCell<Vec<Records>>,
    /// Whole and merge: the hand-looped experiments' results ([`Session::summary`]), as bits.
    summaries: RefCell<Vec<(String, Vec<u64>)>>,
    /// Shard mode: the summed experiments run so far; whole and merge: their keys (empty sums).
    sums: RefCell<Vec<SumsState>>,
}

impl Session {
    /// Everything in this process, no files (what `run(quick)` of each example uses).
    pub fn whole() -> Self {
        Self {
            example: String::new(),
            settings: String::new(),
            args: Args {
                mode: Mode::Whole,
                stats: None,
            },
            written: RefCell::new(Vec::new()),
            loaded: Vec::new(),
            stats: RefCell::new(Vec::new()),
            records: RefCell::new(Vec::new()),
            summaries: RefCell::new(Vec::new()),
            sums: RefCell::new(Vec::new()),
        }
    }

    /// The session the command line asks for ([`parse`] of `std::env::args`): `example` is the
    /// example's name, `settings` the flags that change its experiments (e.g. `--quick`), both
    /// recorded in shard files and checked by the merge.
    pub fn from_args(example: &str, settings: &str) -> Result<Self, ShardError> {
        Self::new(example, settings, parse(std::env::args().skip(1))?)
    }

    /// The session of `args`; in merge mode the shard files are read and checked here.
    pub fn new(example: &str, settings: &str, args: Args) -> Result<Self, ShardError> {
        let loaded = match &args.mode {
            Mode::Merge { files } => load(example, settings, files)?,
            _ => Vec::new(),
        };
        Ok(Self {
            example: example.to_string(),
            settings: settings.to_string(),
            args,
            written: RefCell::new(Vec::new()),
            loaded,
            stats: RefCell::new(Vec::new()),
            records: RefCell::new(Vec::new()),
            summaries: RefCell::new(Vec::new()),
            sums: RefCell::new(Vec::new()),
        })
    }

    /// The mode.
    pub fn mode(&self) -> &Mode {
        &self.args.mode
    }

    /// [`run_with`](Self::run_with) with `MonteCarlo::run` for a whole run.
    pub fn run<E, F>(
        &self,
        key: &str,
        mc: &MonteCarlo<E>,
        simulate: F,
    ) -> Result<Option<EnsembleStats>, Box<dyn std::error::Error>>
    where
        F: Fn(usize, u64, &mut Recorder) -> Result<(), E> + Sync,
        E: From<ValidationError> + Send + std::error::Error + 'static,
    {
        self.run_with(key, mc, simulate, |mc, f| mc.run(f))
    }

    /// The experiment `key` (unique within the example): `whole(mc, simulate)` in a whole
    /// run; in a shard, this process's shard of it (kept for [`finish`](Self::finish)) and
    /// `None`; in a merge, the shard files' shards of it merged (`simulate` is not called).
    pub fn run_with<E, F>(
        &self,
        key: &str,
        mc: &MonteCarlo<E>,
        simulate: F,
        whole: impl FnOnce(&MonteCarlo<E>, F) -> Result<EnsembleStats, MonteCarloError<E>>,
    ) -> Result<Option<EnsembleStats>, Box<dyn std::error::Error>>
    where
        F: FnMut(usize, u64, &mut Recorder) -> Result<(), E>,
        E: From<ValidationError> + std::error::Error + 'static,
    {
        let stats = match &self.args.mode {
            Mode::Whole => whole(mc, simulate)?,
            Mode::Shard { index, count, .. } => {
                if self.written.borrow().iter().any(|e| e.key == key) {
                    return Err(ShardError::new(format!("experiment '{key}' run twice")).into());
                }
                let shard = mc.run_shard(*index, *count, simulate)?;
                self.written.borrow_mut().push(Experiment {
                    key: key.to_string(),
                    shard,
                    extra: None,
                });
                return Ok(None);
            }
            Mode::Merge { .. } => {
                let shards = self
                    .loaded
                    .iter()
                    .map(|f| Ok(experiment(f, key)?.shard.clone()))
                    .collect::<Result<Vec<_>, ShardError>>()?;
                mc.merge_shards(shards).map_err(|e| {
                    ShardError::new(format!(
                        "the shards of experiment '{key}' are not this run's (other runs, \
                         slots, seed or chunks?): {e}"
                    ))
                })?
            }
        };
        self.stats
            .borrow_mut()
            .push((key.to_string(), stats.clone()));
        Ok(Some(stats))
    }

    /// The hand-looped experiment `key` (unique within the example) of `runs` runs, `run(i)`
    /// giving run i's record: every run's record in run order in a whole run; in a shard, the
    /// records of its runs ([`shard_runs`]) are kept for [`finish`](Self::finish) and the
    /// result is `None`; in a merge, the shard files' records of every run, in run order, bit
    /// for bit (`run` is not called). Errors: `run`'s, and shards of another run count or
    /// with runs missing.
    pub fn records(
        &self,
        key: &str,
        runs: usize,
        mut run: impl FnMut(usize) -> Result<Vec<f64>, Box<dyn std::error::Error>>,
    ) -> Result<Option<Vec<Vec<f64>>>, Box<dyn std::error::Error>> {
        if self.records.borrow().iter().any(|r| r.key == key) {
            return Err(ShardError::new(format!("experiment '{key}' run twice")).into());
        }
        let merged = match &self.args.mode {
            Mode::Whole => return (0..runs).map(run).collect::<Result<_, _>>().map(Some),
            Mode::Shard { index, count, .. } => {
                let range = shard_runs(*index, *count, runs);
                let first = range.start;
                let bits = range
                    .map(|i| run(i).map(|r| to_bits(&r)))
                    .collect::<Result<_, _>>()?;
                self.records.borrow_mut().push(Records {
                    key: key.to_string(),
                    runs,
                    first,
                    bits,
                });
                return Ok(None);
            }
            Mode::Merge { .. } => {
                let mut merged = Vec::with_capacity(runs);
                for f in &self.loaded {
                    let r = f.records.iter().find(|r| r.key == key).ok_or_else(|| {
                        ShardError::new(format!(
                            "shard {} of {} has no experiment '{key}' (written by another \
                             version of the example?)",
                            f.index, f.example
                        ))
                    })?;
                    if r.runs != runs || r.first != merged.len() {
                        return Err(ShardError::new(format!(
                            "shard {} of experiment '{key}' holds runs {}..{} of {}, this \
                             merge expects runs from {} of {runs}",
                            f.index,
                            r.first,
                            r.first + r.bits.len(),
                            r.runs,
                            merged.len()
                        ))
                        .into());
                    }
                    merged.extend(
                        r.bits
                            .iter()
                            .map(|b| b.iter().map(|x| f64::from_bits(*x)).collect::<Vec<_>>()),
                    );
                }
                if merged.len() != runs {
                    return Err(ShardError::new(format!(
                        "the shards of experiment '{key}' hold {} of its {runs} runs",
                        merged.len()
                    ))
                    .into());
                }
                merged
            }
        };
        self.records.borrow_mut().push(Records {
            key: key.to_string(),
            runs,
            first: 0,
            bits: Vec::new(),
        });
        Ok(Some(merged))
    }

    /// The experiment `key` (unique within the example) of `runs` runs whose statistics are
    /// sums over runs: `run(i, sums)` adds run i's terms to `sums` (`len` of them). In a
    /// whole run, every run's terms summed; in a shard, its runs' ([`shard_runs`]) are kept for
    /// [`finish`](Self::finish) (the sums' exact state, not the terms) and the result is
    /// `None`; in a merge, the shard files' sums added (`run` is not called). The values
    /// ([`ExactSums::value`]) do not depend on the order of the additions, so the merge gives
    /// the whole run's bits. Errors: `run`'s, and shards of another run count or layout, with
    /// runs missing, or corrupt.
    pub fn sums(
        &self,
        key: &str,
        runs: usize,
        len: usize,
        mut run: impl FnMut(usize, &mut ExactSums) -> Result<(), Box<dyn std::error::Error>>,
    ) -> Result<Option<ExactSums>, Box<dyn std::error::Error>> {
        if self.sums.borrow().iter().any(|r| r.key == key) {
            return Err(ShardError::new(format!("experiment '{key}' run twice")).into());
        }
        let mut sums = ExactSums::new(len);
        let (first, count) = match &self.args.mode {
            Mode::Whole => {
                for i in 0..runs {
                    run(i, &mut sums)?;
                }
                (0, runs)
            }
            Mode::Shard { index, count, .. } => {
                let range = shard_runs(*index, *count, runs);
                for i in range.clone() {
                    run(i, &mut sums)?;
                }
                self.sums.borrow_mut().push(SumsState {
                    key: key.to_string(),
                    runs,
                    first: range.start,
                    count: range.len(),
                    sums: sums.to_bits(),
                });
                return Ok(None);
            }
            Mode::Merge { .. } => {
                let mut done = 0;
                for f in &self.loaded {
                    let r = f.sums.iter().find(|r| r.key == key).ok_or_else(|| {
                        ShardError::new(format!(
                            "shard {} of {} has no experiment '{key}' (written by another \
                             version of the example?)",
                            f.index, f.example
                        ))
                    })?;
                    if r.runs != runs || r.first != done || r.sums.len() != len {
                        return Err(ShardError::new(format!(
                            "shard {} of experiment '{key}' holds runs {}..{} of {} in {} sums, \
                             this merge expects runs from {done} of {runs} in {len} sums",
                            f.index,
                            r.first,
                            r.first + r.count,
                            r.runs,
                            r.sums.len()
                        ))
                        .into());
                    }
                    let part = ExactSums::from_bits(&r.sums).ok_or_else(|| {
                        ShardError::new(format!(
                            "shard {} of experiment '{key}': corrupt sums",
                            f.index
                        ))
                    })?;
                    sums.merge(&part);
                    done += r.count;
                }
                if done != runs {
                    return Err(ShardError::new(format!(
                        "the shards of experiment '{key}' hold {done} of its {runs} runs"
                    ))
                    .into());
                }
                (0, runs)
            }
        };
        self.sums.borrow_mut().push(SumsState {
            key: key.to_string(),
            runs,
            first,
            count,
            sums: Vec::new(),
        });
        Ok(Some(sums))
    }

    /// The results of the hand-looped experiment `key`, for `--stats` (written as the bits
    /// of each `f64`, exact, infinities and NaNs too); nothing in a shard.
    pub fn summary(&self, key: &str, values: &[f64]) {
        if !matches!(self.args.mode, Mode::Shard { .. }) {
            self.summaries
                .borrow_mut()
                .push((key.to_string(), to_bits(values)));
        }
    }

    /// What the example keeps of experiment `key` beside the runner's statistics (values
    /// collected per run, say), after [`run`](Self::run): `Some([value])` in a whole run;
    /// in a shard, `value` is stored with the shard and the result is `None`; in a merge,
    /// every shard's value in shard order (`value` itself, from no runs, is dropped).
    pub fn extra<X: Serialize + DeserializeOwned>(
        &self,
        key: &str,
        value: X,
    ) -> Result<Option<Vec<X>>, Box<dyn std::error::Error>> {
        match &self.args.mode {
            Mode::Whole => Ok(Some(vec![value])),
            Mode::Shard { .. } => {
                let mut written = self.written.borrow_mut();
                let e = written
                    .iter_mut()
                    .find(|e| e.key == key)
                    .ok_or_else(|| ShardError::new(format!("no experiment '{key}' was run")))?;
                e.extra = Some(serde_json::to_value(value)?);
                Ok(None)
            }
            Mode::Merge { .. } => self
                .loaded
                .iter()
                .map(|f| {
                    let e = experiment(f, key)?;
                    let v = e.extra.clone().ok_or_else(|| {
                        ShardError::new(format!(
                            "shard {} of experiment '{key}' has no per-shard values",
                            f.index
                        ))
                    })?;
                    serde_json::from_value(v).map_err(|err| {
                        ShardError::new(format!(
                            "shard {} of experiment '{key}': corrupt values: {err}",
                            f.index
                        ))
                        .into()
                    })
                })
                .collect::<Result<Vec<X>, Box<dyn std::error::Error>>>()
                .map(Some),
        }
    }

    /// Ends the session: in a shard, writes the shard file (and says so on stdout); with
    /// `--stats`, writes the statistics; in a merge, checks that every experiment of the
    /// files was merged.
    pub fn finish(&self) -> Result<(), ShardError> {
        match &self.args.mode {
            Mode::Shard { index, count, out } => {
                let experiments = self.written.borrow().clone();
                let records = self.records.borrow().clone();
                let sums = self.sums.borrow().clone();
                let runs: usize = experiments.iter().map(|e| e.shard.runs()).sum::<usize>()
                    + records.iter().map(|r| r.bits.len()).sum::<usize>()
                    + sums.iter().map(|r| r.count).sum::<usize>();
                let n = experiments.len() + records.len() + sums.len();
                let file = ShardFile {
                    format: FORMAT.to_string(),
                    example: self.example.clone(),
                    settings: self.settings.clone(),
                    index: *index,
                    count: *count,
                    experiments,
                    records,
                    sums,
                };
                write_json(out, &file)?;
                println!(
                    "{} shard {index}/{count}: {n} experiments, {runs} runs, written to {}",
                    self.example,
                    out.display()
                );
            }
            Mode::Merge { .. } => {
                let done = self.stats.borrow();
                if let Some(f) = self.loaded.first()
                    && let Some(e) = f
                        .experiments
                        .iter()
                        .find(|e| done.iter().all(|(k, _)| *k != e.key))
                {
                    return Err(ShardError::new(format!(
                        "the shard files hold experiment '{}', which this run of {} does not have",
                        e.key, self.example
                    )));
                }
                let done = self.records.borrow();
                if let Some(f) = self.loaded.first()
                    && let Some(r) = f
                        .records
                        .iter()
                        .find(|r| done.iter().all(|d| d.key != r.key))
                {
                    return Err(ShardError::new(format!(
                        "the shard files hold experiment '{}', which this run of {} does not have",
                        r.key, self.example
                    )));
                }
                let done = self.sums.borrow();
                if let Some(f) = self.loaded.first()
                    && let Some(r) = f.sums.iter().find(|r| done.iter().all(|d| d.key != r.key))
                {
                    return Err(ShardError::new(format!(
                        "the shard files hold experiment '{}', which this run of {} does not have",
                        r.key, self.example
                    )));
                }
            }
            Mode::Whole => {}
        }
        if let Some(path) = &self.args.stats {
            let summaries = self.summaries.borrow();
            if summaries.is_empty() {
                write_json(path, &*self.stats.borrow())?;
            } else {
                write_json(path, &(&*self.stats.borrow(), &*summaries))?;
            }
        }
        Ok(())
    }
}

/// The example output of a whole run ([`Session::whole`] always gives `Some`).
pub fn whole<T>(output: Option<T>) -> Result<T, ShardError> {
    output.ok_or_else(|| ShardError::new("a whole run returned no output"))
}

fn experiment<'a>(f: &'a ShardFile, key: &str) -> Result<&'a Experiment, ShardError> {
    f.experiments.iter().find(|e| e.key == key).ok_or_else(|| {
        ShardError::new(format!(
            "shard {} of {} has no experiment '{key}' (written by another version of the example?)",
            f.index, f.example
        ))
    })
}

fn write_json<T: Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), ShardError> {
    let io =
        |e: &dyn fmt::Display| ShardError::new(format!("cannot write {}: {e}", path.display()));
    let file = std::fs::File::create(path).map_err(|e| io(&e))?;
    let mut w = std::io::BufWriter::new(file);
    serde_json::to_writer(&mut w, value).map_err(|e| io(&e))?;
    std::io::Write::flush(&mut w).map_err(|e| io(&e))
}

/// Reads and checks the shard files: one example, its settings, one shard count, every shard
/// exactly once; sorted by shard index.
fn load(example: &str, settings: &str, files: &[PathBuf]) -> Result<Vec<ShardFile>, ShardError> {
    let mut loaded: Vec<(PathBuf, ShardFile)> = Vec::with_capacity(files.len());
    for path in files {
        let text = std::fs::read(path)
            .map_err(|e| ShardError::new(format!("cannot read {}: {e}", path.display())))?;
        let f: ShardFile = serde_json::from_slice(&text).map_err(|e| {
            ShardError::new(format!(
                "{} is not a shard file or is corrupt: {e}",
                path.display()
            ))
        })?;
        let p = path.display();
        if f.format != FORMAT {
            return Err(ShardError::new(format!(
                "{p} has format '{}', this program reads '{FORMAT}'",
                f.format
            )));
        }
        if f.example != example {
            return Err(ShardError::new(format!(
                "{p} holds shards of {}, not of {example}",
                f.example
            )));
        }
        if f.settings != settings {
            return Err(ShardError::new(format!(
                "{p} was run with settings '{}', this merge with '{settings}': give the merge \
                 the shards' flags",
                f.settings
            )));
        }
        if f.count == 0 || f.index >= f.count {
            return Err(ShardError::new(format!(
                "{p} claims to be shard {} of {}",
                f.index, f.count
            )));
        }
        if let Some((q, g)) = loaded.first()
            && g.count != f.count
        {
            return Err(ShardError::new(format!(
                "{p} is one of {} shards, {} one of {}: shards of different runs",
                f.count,
                q.display(),
                g.count
            )));
        }
        if let Some((q, _)) = loaded.iter().find(|(_, g)| g.index == f.index) {
            return Err(ShardError::new(format!(
                "shard {} of {} given twice: {} and {p}",
                f.index,
                f.count,
                q.display()
            )));
        }
        loaded.push((path.clone(), f));
    }
    let count = loaded.first().map_or(0, |(_, f)| f.count);
    if loaded.len() != count {
        let missing: Vec<String> = (0..count)
            .filter(|i| loaded.iter().all(|(_, f)| f.index != *i))
            .map(|i| i.to_string())
            .collect();
        return Err(ShardError::new(format!(
            "shards {} of {count} are missing",
            missing.join(", ")
        )));
    }
    loaded.sort_by_key(|(_, f)| f.index);
    Ok(loaded.into_iter().map(|(_, f)| f).collect())
}

/// For an example that cannot be sharded: refuses `--shard`, `--out`, `--merge` and `--stats`
/// on the command line (with `why`), rather than ignoring them and running whole in every task
/// of a job array.
pub fn refuse_flags(example: &str, why: &str) -> Result<(), ShardError> {
    refuse(example, why, parse(std::env::args().skip(1))?)
}

/// [`refuse_flags`] of parsed flags.
pub fn refuse(example: &str, why: &str, args: Args) -> Result<(), ShardError> {
    if args.mode == Mode::Whole && args.stats.is_none() {
        return Ok(());
    }
    Err(ShardError::new(format!(
        "{example} does not take --shard/--merge/--stats: {why}"
    )))
}

/// The settings string of an example whose only experiment-changing flag is `--quick`.
pub fn settings(quick: bool) -> &'static str {
    if quick { "--quick" } else { "full" }
}
