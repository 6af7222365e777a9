//! estim facade
pub use estim_core as core;
