//! The `estim` package's integration tests, one binary: the examples' reproductions of the
//! papers (each example's body, `examples/reproductions/<name>.rs`, included by `#[path]` as
//! module `<name>`, exactly as the examples include it) and the other examples' runs.
//!
//! `cargo test -p estim --test it`

// The examples' shared helpers and bodies, under the names they have in the examples (the
// bodies refer to `crate::common` and to each other by these names).
#[cfg(feature = "autodiff")]
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/attitude.rs"]
mod attitude;
#[path = "../../examples/reproductions/boje_circle.rs"]
mod boje_circle;
#[path = "../../examples/reproductions/boje_lambda.rs"]
mod boje_lambda;
#[path = "../../examples/reproductions/boje_moments.rs"]
mod boje_moments;
#[path = "../../examples/reproductions/boje_rate.rs"]
mod boje_rate;
#[path = "../../examples/common/mod.rs"]
mod common;
#[path = "../../examples/reproductions/consistency.rs"]
mod consistency;
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/heading_wrap.rs"]
mod heading_wrap;
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/large_state.rs"]
mod large_state;
#[path = "../../examples/reproductions/lee_huang.rs"]
mod lee_huang;
#[path = "../../examples/reproductions/lu_calibration.rs"]
mod lu_calibration;
#[path = "../../examples/reproductions/lu_delays.rs"]
mod lu_delays;
#[path = "../../examples/reproductions/lu_noise_id.rs"]
mod lu_noise_id;
#[path = "../../examples/reproductions/lv2_fusion.rs"]
mod lv2_fusion;

// The tests, one module per example (or per paper for Boje's four).
#[cfg(feature = "autodiff")]
mod attitude_example;
mod boje_circle_smoothing;
mod boje_examples;
mod consistency_example;
mod firmware;
mod heading_wrap_example;
mod large_state_example;
mod lee_huang_example;
mod lu_calibration_example;
mod lu_delays_example;
mod lu_noise_id_example;
mod lv2_fusion_example;
