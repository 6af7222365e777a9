//! The `estim` package's integration tests, one binary: the examples' runs (each example's
//! body is module `<name>` of the `estim-reproductions` library in `examples/reproductions/`,
//! the one the example runs, compiled once for both; `attitude`, which needs the `autodiff`
//! feature, is included by `#[path]`).
//!
//! `cargo test -p estim --test it`

// The examples' shared helpers and bodies, under the names they have in the examples.
#[cfg(feature = "autodiff")]
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/attitude.rs"]
mod attitude;
use estim_reproductions::boje_circle;
use estim_reproductions::boje_lambda;
use estim_reproductions::boje_moments;
use estim_reproductions::boje_rate;
use estim_reproductions::common;
use estim_reproductions::consistency;
use estim_reproductions::exact_sum;
use estim_reproductions::flight_ins;
use estim_reproductions::heading_wrap;
use estim_reproductions::large_state;
use estim_reproductions::lee_huang;
use estim_reproductions::lu_calibration;
use estim_reproductions::lu_delays;
use estim_reproductions::lu_noise_id;
use estim_reproductions::lv2_fusion;
use estim_reproductions::manoeuvring_target;
use estim_reproductions::particle_growth;
use estim_reproductions::plaza_range;
use estim_reproductions::sharding;

// The tests, one module per example (or per paper for Boje's four).
#[cfg(feature = "autodiff")]
mod attitude_example;
mod boje_circle_smoothing;
mod boje_examples;
mod consistency_example;
mod figure_dir;
mod figure_layout;
mod firmware;
mod flight_ins_example;
mod heading_wrap_example;
mod large_state_example;
mod lee_huang_example;
mod lu_calibration_example;
mod lu_delays_example;
mod lu_noise_id_example;
mod lv2_fusion_example;
mod manoeuvring_target_example;
mod particle_growth_example;
mod plaza_range_example;
mod sharding_flags;
