//! The step harness shared by the `filters` and `dynamic` benches, included with `mod common;`.
//!
//! **What one iteration is.** Each variant keeps its state across iterations and takes one
//! step per iteration with the input and measurement of step i of a recorded trajectory of
//! `PERIOD` steps; after step `PERIOD` it is reset to the prior (one `clone_from`, amortised
//! over the period) and the trajectory starts again. The state passes through `black_box` after
//! every step and the step's result is returned to criterion, so nothing is optimised away.
//!
//! **Counted mode.** With `<VAR>=<group>/<name>=<count>` in the environment (each bench names
//! its own variable: `FILTERS_BENCH_STEPS`, `DYNAMIC_BENCH_STEPS`), nothing is timed: the named
//! variant runs `count` steps of the same loop in [`run_counted`] and everything else is
//! skipped, for `perf stat -e task-clock`, `perf record` and
//! `valgrind --tool=callgrind --toggle-collect='*run_counted*'` (the scripts
//! `filters_counted.sh` and `dynamic_counted.sh` drive it). Count 0 measures the set-up alone.

use std::hint::black_box;

use criterion::{BenchmarkGroup, measurement::WallTime};

/// `(id, count)` from `<var>=<group>/<name>=<count>`, if `var` is set.
pub fn counted_spec(var: &str) -> Option<(String, usize)> {
    std::env::var(var).ok().map(|spec| {
        let (id, count) = spec
            .rsplit_once('=')
            .unwrap_or_else(|| panic!("{var}=<group>/<name>=<count>"));
        (id.to_owned(), count.parse().expect("a step count"))
    })
}

/// A benchmark group of filter steps whose states are reset every `PERIOD` steps (see the
/// module docs for what one iteration is and for counted mode). `PERIOD` is a constant, as it
/// was in each bench before the harness was shared, so the loops compile as they did.
pub struct Steps<'a, const PERIOD: usize> {
    group: BenchmarkGroup<'a, WallTime>,
    name: String,
    counted: Option<(String, usize)>,
}

impl<'a, const PERIOD: usize> Steps<'a, PERIOD> {
    /// Wraps `group` (configured by the caller), named `name`; counted mode is read from the
    /// environment variable `var`.
    pub fn new(group: BenchmarkGroup<'a, WallTime>, name: impl Into<String>, var: &str) -> Self {
        Self {
            group,
            name: name.into(),
            counted: counted_spec(var),
        }
    }

    /// Times `step(state, i)` on a state kept across iterations, i cycling over the trajectory
    /// and the state reset to `prior` whenever i wraps.
    pub fn bench<S: Clone, R>(
        &mut self,
        name: &str,
        prior: &S,
        mut step: impl FnMut(&mut S, usize) -> R,
    ) {
        if let Some((id, count)) = &self.counted {
            if *id == format!("{}/{name}", self.name) {
                run_counted::<PERIOD, _, _>(*count, prior, &mut step);
            }
            return;
        }
        self.group.bench_function(name, |b| {
            let mut state = prior.clone();
            let mut i = 0;
            b.iter(|| {
                if i == PERIOD {
                    state.clone_from(prior);
                    i = 0;
                }
                let r = step(&mut state, i);
                // The estimate is the product: make the compiler keep every step's result.
                black_box(&mut state);
                i += 1;
                r
            })
        });
    }

    /// Ends the group.
    pub fn finish(self) {
        self.group.finish();
    }
}

/// The loop of [`Steps::bench`] run `count` times outside criterion.
#[inline(never)]
pub fn run_counted<const PERIOD: usize, S: Clone, R>(
    count: usize,
    prior: &S,
    step: &mut impl FnMut(&mut S, usize) -> R,
) {
    let mut state = prior.clone();
    let mut i = 0;
    for _ in 0..count {
        if i == PERIOD {
            state.clone_from(prior);
            i = 0;
        }
        black_box(step(&mut state, i));
        black_box(&mut state);
        i += 1;
    }
}
