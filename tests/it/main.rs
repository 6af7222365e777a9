//! The `estim` package's integration tests, one binary: the examples' reproductions of the
//! papers (each example's body, module `<name>` of the `estim-reproductions` library in
//! `examples/reproductions/`, the one the examples run) and the other examples' runs (their
//! files included by `#[path]`).
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
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/heading_wrap.rs"]
mod heading_wrap;
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/large_state.rs"]
mod large_state;
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/manoeuvring_target.rs"]
mod manoeuvring_target;
use estim_reproductions::lee_huang;
#[allow(dead_code)] // its `main` and printing helpers
#[path = "../../examples/particle_growth.rs"]
mod particle_growth;
use estim_reproductions::lu_calibration;
use estim_reproductions::lu_delays;
use estim_reproductions::lu_noise_id;
use estim_reproductions::lv2_fusion;
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
