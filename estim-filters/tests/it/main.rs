//! estim-filters' integration tests of the Gaussian filters, smoothers, fusion and noise
//! identification, built as one binary (one module per topic) instead of one per file; the
//! particle filters and multiple-model estimators are in `tests/sampling`.
//!
//! Run one topic with `cargo test -p estim-filters --test it <module>::`, e.g.
//! `cargo test -p estim-filters --test it equivalence::`.

mod common;
mod consistency_common;
// The counting `#[global_allocator]` (per-thread counts) for the allocation tests, written
// once in estim-core's test support. It implements the unsafe `GlobalAlloc` trait: the
// workspace denies `unsafe_code`, and this module is the one place in the tests that needs it.
#[allow(unsafe_code)]
#[path = "../../../estim-core/tests/it/counting.rs"]
mod counting;

mod adapters;
mod atomicity;
mod consider;
mod consistency_monte_carlo;
mod consistency_proptest;
mod consistency_statistics;
mod correlated;
mod covariance_forms;
mod dyn_estimator;
mod dynamic;
mod equivalence;
mod fusion_errors;
mod fusion_gating;
mod fusion_inputs;
mod fusion_log;
mod fusion_replay;
mod fusion_sizes;
mod fusion_support;
mod fuzz;
mod gating;
mod iekf;
mod multirate;
mod nees;
mod no_alloc;
mod no_alloc_dynamic;
mod noise_id_adaptive;
mod noise_id_em;
#[cfg(feature = "likelihood")]
mod noise_id_likelihood;
mod noise_policy;
mod residual_wrapping;
mod rls;
mod robust;
mod second_order;
#[cfg(feature = "serde")]
mod serde_checkpoint;
mod smoother;
mod smoother_bad_input;
mod smoother_nonlinear;
mod smoother_proptest;
mod square_root;
mod state_space;
mod ukf_extreme;
