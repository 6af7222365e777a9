//! estim-models' integration tests, one binary: one module per model family and topic, and the
//! shared support (`lv2_support`) written once. The paper reproductions (the examples' bodies)
//! are tested in the `estim` package's `tests/it`.
//!
//! `cargo test -p estim-models` (or `--test it`; a single module: `cargo test -p estim-models
//! --test it lv2_fusion::`).

mod autodiff;
mod bad_settings;
mod boje_derivatives;
mod boje_filter;
mod boje_moments;
mod boje_rate;
mod lee_huang_models;
mod lee_huang_ote;
mod lee_huang_sensors;
mod lu_filter;
mod lu_models;
mod lv2_axes;
mod lv2_fusion;
mod lv2_monte_carlo;
mod lv2_stats;
mod lv2_support;
mod motion_derivatives;
mod motion_discretization;
mod motion_filtering;
mod nav;
