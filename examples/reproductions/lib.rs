//! The bodies of estim's examples (the papers' reproductions and estim's own): each module is one example's body (the
//! experiment, its tables, figures, headlines and JSON), run by `examples/<name>.rs` (flags and
//! `main`), the papers' by `examples/papers.rs` (the main job), and checked by the `estim`
//! package's tests (`tests/it`). Example code, not an API: not published, and its items are
//! documented where it helps a reader of the example rather than item by item.
#![allow(missing_docs)]

#[path = "../common/mod.rs"]
pub mod common;

pub mod boje_circle;
pub mod boje_lambda;
pub mod boje_moments;
pub mod boje_rate;
pub mod consistency;
pub mod exact_sum;
pub mod flight_ins;
pub mod heading_wrap;
pub mod large_state;
pub mod lee_huang;
pub mod lu_calibration;
pub mod lu_delays;
pub mod lu_noise_id;
pub mod lv2_fusion;
pub mod manoeuvring_target;
pub mod particle_growth;
pub mod plaza_range;
pub mod sharding;
