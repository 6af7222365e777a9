//! estim-filters' integration tests of the estimators beyond one Gaussian: particle filters
//! (bootstrap, auxiliary, guided, Rao-Blackwellised, FFBSi, PMMH) and the multiple-model
//! estimators (IMM, its smoother, the Gaussian sum). A test binary of its own beside `tests/it`
//! so that the two compile in parallel (one binary was the longest unit of the test build).
//!
//! Run one topic with `cargo test -p estim-filters --test sampling <module>::`, e.g.
//! `cargo test -p estim-filters --test sampling imm::`.

#[path = "../it/common/mod.rs"]
mod common;
// The counting `#[global_allocator]` of estim-core's test support (see `tests/it/main.rs`).
#[allow(unsafe_code)]
#[path = "../../../estim-core/tests/it/counting.rs"]
mod counting;

mod gaussian_sum;
mod imm;
mod imm_consistency;
mod imm_sizes;
mod imm_smoother;
mod particle;
mod particle_algorithms;
mod particle_common;
mod particle_parallel;
mod rbpf_contract;
