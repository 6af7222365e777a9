//! The user guide: how to do the common things, each page a set of compiled examples.
//!
//! | page | for |
//! |---|---|
//! | [`choosing_a_filter`] | which filter for which model, and the one-line swap |
//! | [`runtime_sizes`] | states whose size comes from configuration (`DVector`) |
//! | [`verifying`] | NEES/NIS, the Monte Carlo runner, checking your derivatives |
//! | [`writing_a_model`] | analytic derivatives, checking them, automatic derivatives (`autodiff`), a missing derivative's error, generic code over the filter (`FilterOver`, `Smoothable`) |
//! | [`smoothing`] | Rauch–Tung–Striebel, fixed lag, and whole recorded sequences |
//! | [`noise_identification`] | learning Q and R from data: EM, maximum likelihood, online matching |
//! | [`particle_filters`] | when a Gaussian is not enough: multimodal posteriors, non-Gaussian noise |
//! | [`sensor_fusion`] | timestamped sensors: late measurements, gating outcomes, faulty sensors |
//! | [`gps_ins`] | a GPS/INS: the nav model set, alignment, IMU samples and late fixes in the driver |
//! | [`single_precision`] | what changes in `f32`, and the settings that survive it |
//! | [`from_filterpy`] | a table of FilterPy (and pykalman) equivalents |
//!
//! The API reference is the rest of these docs; the papers reproduced with estim are the
//! repository's examples (`cargo run --release --example papers`).

pub mod choosing_a_filter;
pub mod from_filterpy;
#[cfg(feature = "models")]
pub mod gps_ins;
pub mod noise_identification;
pub mod particle_filters;
pub mod runtime_sizes;
pub mod sensor_fusion;
pub mod single_precision;
pub mod smoothing;
pub mod verifying;
pub mod writing_a_model;
