//! estim-core's integration tests, built as one binary (one module per topic) so that the
//! workspace links one test executable per crate instead of one per file.
//!
//! Run one topic with `cargo test -p estim-core --test it <module>::`, e.g.
//! `cargo test -p estim-core --test it papoulis::`.

mod common;
// The counting `#[global_allocator]` (per-thread counts) for the allocation tests, shared with
// estim-filters' binary. It implements the unsafe `GlobalAlloc` trait: the workspace denies
// `unsafe_code`, and this module is the one place in the tests that needs it.
#[allow(unsafe_code)]
mod counting;

mod angles;
#[cfg(feature = "autodiff")]
mod autodiff;
mod checked;
mod derivative;
mod errors;
mod gaussian;
mod in_place;
mod linear;
mod manifold;
mod no_alloc;
mod nonlinear;
mod papoulis;
mod quadratic;
#[cfg(feature = "autodiff")]
mod rotation_ad;
mod ukf_region;
