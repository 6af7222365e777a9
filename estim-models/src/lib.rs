//! # estim-models
//!
//! Four papers on accelerometer-based navigation, each a model plugin for the estim filters,
//! with its simulator:
//!
//! - [`boje`]: planar motion from two two-axis accelerometers (second-order moments, the λ
//!   covariance, the 6-state EKF with correlated noise, rate accuracy, the circle example).
//! - [`lee_huang`]: the all-accelerometer planar INS, its conventional Kalman filter and the
//!   own-ship trajectory estimator (fading-memory RLS).
//! - [`lv2`]: minimum-variance fusion of redundant accelerometer axes.
//! - [`lu`]: accelerometer bias calibration from GPS, with Monte Carlo validation.
//!
//! And the models every tracker needs, so that a user does not write them by hand:
//!
//! - [`motion`]: constant velocity and acceleration (1-3 D), coordinated turn (known or
//!   estimated rate), unicycle/odometry, random walk, first-order Gauss-Markov; the exact
//!   discretisation of continuous-time noise (closed forms, Van Loan).
//! - [`sensors`]: position, range, bearing, range-bearing.
//! - [`augment`]: a model with bias / Gauss-Markov states appended, a sensor reading them.
//!
//! They live here rather than in estim-core because they are models, like the papers', and
//! estim-core stays the traits and the machinery; like the papers' models they are static-size
//! and generic over the scalar.
//!
//! Every model's analytic derivatives pass the estim-core derivative checker, and every
//! closed form taken from a paper is tested against an independent route. Where a paper is
//! wrong, the module's *Errata* section says what it prints, what estim uses and which test
//! shows it.
//!
//! The papers' experiments (runs, headline tables, figures) are not in this crate: each is an
//! example of the `estim` package, `examples/<name>.rs`, whose body is
//! `examples/reproductions/<name>.rs`; `cargo run --release --example papers` runs them all.
//!
//! ## Without std
//!
//! With default features off (no `std`) the crate is `#![no_std]` and needs no allocator:
//! [`nav`] (the INS, its sensors, the static alignment, normal gravity, the origin's radii and
//! earth rate), [`motion`], [`sensors`], [`augment`], [`limits`] and the papers' models and
//! filters build for a bare-metal target (`.ci/firmware` checks `thumbv7em-none-eabihf`), their
//! f64 functions through `num_traits::Float` (libm), the papers' filters on estim-filters
//! without std. What needs `std`:
//!
//! - `nav::Origin::ned` (geodetic → NED): the `map_3d` crate calls std's float functions;
//! - `motion::van_loan`: its 2n × 2n exponential is a runtime-sized matrix (the closed forms
//!   `continuous_white_noise` and `discrete_white_noise` stay);
//! - the papers' simulators, which draw from rand's `StdRng` and return `Vec`s
//!   (`boje::circle`, `lee_huang::simulation`, `lu::simulation`, `lv2::simulate`), and their
//!   recorded runs, which are `Vec`s (`boje::rate::iterate_riccati`, `lu::analysis`, and
//!   `lu::covariance_history`, `lu::run_realization` with their records);
//! - lv2's general model (`Fusion`, `RedundantAxes` and the rest of its fusion): its axis
//!   sets are `Vec`s and its χ² screening is statrs (`lv2::stats`); its three-axis closed
//!   forms (`lv2::xyq`) and `FusionError` stay.
#![cfg_attr(not(feature = "std"), no_std)]
// Without std the std-only items (simulators, the papers' runtime-size filters, `Origin::ned`)
// do not exist, so the docs' links to them cannot resolve; the API docs are checked for dead
// links with every feature on (`.ci/run`, as docs.rs builds them).
#![cfg_attr(not(feature = "std"), allow(rustdoc::broken_intra_doc_links))]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod augment;
pub mod boje;
pub mod lee_huang;
pub mod limits;
pub mod lu;
pub mod lv2;
pub mod motion;
pub mod nav;
pub mod sensors;
