//! estim-models
