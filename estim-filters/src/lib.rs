//! estim-filters
