//! Reproduction of the optimised-build divergence of the analytic EKF (see the module docs of
//! `estim_filters::update`, "Optimised builds"): `benches/autodiff.rs` cut down to its models,
//! its trajectory and the EKF lockstep, no criterion. A bench target of the bench package
//! (`slp_joseph_repro`), so every lint compiles it.
//!
//! To run it: restore the inlined `Standard`/`Symmetrized` arms of `update::apply` (as at
//! `df5c075`) and
//!
//! ```text
//! cargo rustc -p estim-filters-benches --profile bench --bench slp_joseph_repro     # gap 4.1e-2
//! cargo rustc ... -- -C no-vectorize-slp                                    # 6.7e-16
//! cargo rustc ... -- -C codegen-units=1   (or -C opt-level=1, -C opt-level=2) # 6.7e-16
//! RUSTC_BOOTSTRAP=1 cargo rustc -j1 ... -- -C llvm-args=-debug-counter=slp-vectorized=0-N
//! ```
//!
//! then run `target/release/deps/slp_joseph_repro-*`. Non-incremental builds only: with
//! `CARGO_INCREMENTAL=1` the crate is split into other codegen units and the gap is 6.7e-16.
//! Bisecting N (`-j1` keeps the counter's order fixed) finds the one SLP tree that breaks it;
//! in a variant of this file that also logged every step it was N = 580 (0-579: 6.7e-16,
//! 0-580: 4.7e-2), a tree rooted at the stores of the `Symmetrized` arm's symmetrisation that
//! includes the product X = −K Pₓᵤᵀ computed before the arms (IR from
//! `-C llvm-args=-print-after=slp-vectorizer -C llvm-args=-filter-print-funcs=<lockstep>`).
//!
//! Other discriminators, all at `df5c075`: the whole build (every dependency) with
//! `RUSTC_BOOTSTRAP=1 RUSTFLAGS="-Zub-checks=yes -C debug-assertions=on"` in its own target
//! directory: no check fires and the gap is 6.7e-16 (the assertions change the code, so this
//! neither shows nor excludes the fault; it finds no precondition violated on the path). The
//! bench crate alone with those flags: no check fires, gap 4.4e-2; with `-Zmir-opt-level=0`:
//! 4.4e-2 (not a MIR optimisation of this crate). `valgrind --tool=memcheck` on the autodiff
//! bench binary with `AUTODIFF_BENCH_STEPS=autodiff_6x4/Ekf_analytic=0` (set-up and lockstep
//! only): 6,098 errors from 209 contexts (uninitialised values, the first at the finiteness
//! check of x⁺ in the inlined analytic update) at `df5c075`, 0 errors at `05d49fa`.
//!
//! Every figure here was measured when this file held its own copy of the models at its crate
//! root; they now come from module `vehicle`, which may split the codegen units otherwise (the
//! fault depended on the split): not re-measured since.

#[path = "../vehicle.rs"]
mod vehicle;

use estim_filters::Ekf;
use vehicle::{lockstep, trajectory};

fn main() {
    let (zs, prior) = trajectory();
    let gap = lockstep(Ekf::new(prior.clone()), Ekf::new(prior), &zs);
    println!("lockstep EKF analytic vs AD: largest relative gap {gap:.1e}");
}
