//! # Single precision (`f32`)
//!
//! Every filter is generic over the scalar: write `f32` where you wrote `f64`. What changes is
//! the rounding, ε = 1.2·10⁻⁷ instead of 2.2·10⁻¹⁶, and with it three things to watch:
//!
//! - **The unscented spread.** The unscented mean's round-off grows as ε/α², so the `f64`
//!   default α = 10⁻³ (centre weight about −10⁶) would cost an `f32` mean all its digits.
//!   `Ukf::new` in `f32` therefore uses α = 0.5; if you set α yourself, keep it of order one
//!   in `f32`, or use the cubature rule (`Unscented::cubature()`, all weights 1/2n).
//! - **The covariance form.** Keep the default Joseph form
//!   ([`CovarianceUpdate::Joseph`](crate::filters::CovarianceUpdate::Joseph)): the standard
//!   form P − K S Kᵀ loses symmetry and definiteness first.
//! - **Very precise measurements.** When R ≪ P the innovation covariance S ≈ H P Hᵀ is formed
//!   by cancellation; scale the states (units) so that P and R are within a few orders of
//!   magnitude, or start from a tighter prior.
//!
//! ```
//! use estim::prelude::*;
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//!
//! let process = LinearProcess {
//!     transition: Matrix2::new(1.0f32, 0.1, 0.0, 1.0),
//!     input: Matrix2x1::new(0.005, 0.1),
//!     noise: Matrix2::identity() * 1e-4,
//! };
//! let gps = LinearMeasurement { observation: Matrix1x2::new(1.0f32, 0.0), noise: Matrix1::new(0.25) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?;
//! let mut ukf = Ukf::with_propagator(prior, Unscented::cubature());
//! for k in 1..=50 {
//!     ukf.predict(&process, &Vector1::new(1.0), 0.1)?;
//!     let t = k as f32 * 0.1;
//!     ukf.update(&gps, &Vector1::new(0.5 * t * t))?;
//! }
//! assert!((ukf.state()[1] - 5.0).abs() < 0.5);
//! # Ok::<(), estim::core::Error>(())
//! ```
