//! # Verifying a filter and a model
//!
//! Three levels, cheapest first.
//!
//! **Your derivatives.** [`check_process_model`](crate::core::derivative::check_process_model)
//! and [`check_measurement_model`](crate::core::derivative::check_measurement_model) compare
//! analytic Jacobians and Hessians with finite differences at a point; call them from your own
//! tests (with feature `proptest-support`, at random points).
//!
//! **One run.** Every update returns its NIS (ν ᵀ S⁻¹ ν, χ²ₘ-distributed when the filter is
//! consistent) and log-likelihood; with a simulated truth,
//! [`consistency::nees`](crate::filters::consistency::nees) gives the NEES:
//!
//! ```
//! use estim::filters::consistency::nees;
//! use estim::nalgebra::{Matrix2, Vector2};
//!
//! let error = Vector2::new(0.1, -0.2);
//! let p = Matrix2::new(0.04, 0.0, 0.0, 0.04);
//! assert!((nees(&error, &p)? - 1.25).abs() < 1e-12);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! **Many runs.** [`MonteCarlo`](crate::filters::MonteCarlo) runs seeded realizations (in
//! parallel with feature `parallel`, bit-identical to sequential) and returns per-time ensemble
//! statistics — mean error, ensemble vs filter covariance, NEES/NIS against their χ² bands,
//! orthogonality, residual correlation — and a [`Verdict`](crate::filters::Verdict) to assert
//! in a test. The module docs of [`monte_carlo`](crate::filters::monte_carlo) show a complete
//! run.
