//! estim-core's integration tests, built as one binary (one module per topic) so that the
//! workspace links one test executable per crate instead of one per file.
//!
//! Run one topic with `cargo test -p estim-core --test it <module>::`, e.g.
//! `cargo test -p estim-core --test it papoulis::`.

mod common;

mod angles;
mod derivative;
mod errors;
mod gaussian;
mod linear;
mod no_alloc;
mod nonlinear;
mod papoulis;
mod quadratic;
mod sigma_points;
