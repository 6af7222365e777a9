//! # estim-models
//!
//! The models of four papers on accelerometer-based navigation, each a plugin for the estim
//! filters, with its simulator. (Being built: see the project issues.)
#![deny(missing_docs)]
