//! # LV2: best estimates of x and y from redundant x, y and q axes
//!
//! *Best estimates for X and Y given X, Y and Q*, LV2 IMU technical note, version 1.00,
//! 17 December 2004 (no author given). Plain text: `shared/papers/lv2-redundant-axis-fusion.txt`.
//!
//! The LV2 IMU measures in-plane acceleration on x and y and, redundantly, on a q axis at 45°
//! between them. The note derives the minimum-variance estimate of x from x̃, ỹ, q̃ (eq 1–6),
//! a consistency check between the redundant estimates (eq 7), and suggests dropping a
//! saturated axis. This module implements that, the parts the note leaves out (ŷ, the full
//! covariance, a χ² test with a false-alarm rate), and the general case: any number of axes at
//! known directions in the plane or in space, as a linear measurement model of the framework.
//!
//! ## Components
//!
//! | symbol | meaning | unit |
//! |---|---|---|
//! | θ = (x, y) (or (x, y, z) in space) | the sensed acceleration, the unknown | m/s² |
//! | x̃, ỹ, q̃ (zᵢ in general) | axis readings | m/s² |
//! | uᵢ | direction of axis i (row i of H): x (1, 0), y (0, 1), q (1/√2, 1/√2) | — |
//! | σx, σy, σq (σᵢ) | white-noise standard deviations, independent | m/s² |
//! | x̂, ŷ, P | estimate and its covariance | m/s², (m/s²)² |
//! | r = x̃ + ỹ − √2 q̃ | parity residual, x̂₁ − x̂₂ of eq 7 | m/s² |
//!
//! There is no state dynamics: each sample is fused on its own (static estimation). In a
//! filter over time, [`RedundantAxes`] is the measurement model.
//!
//! ## Equations implemented
//!
//! Model (eq 1): z = H θ + v, v ~ N(0, R), R = diag(σx², σy², σq²),
//! H = [[1, 0], [0, 1], [1/√2, 1/√2]]. Linear: Jacobian H, Hessians 0.
//!
//! Three axes, closed forms ([`xyq`]):
//!
//! ```text
//! x̂₁ = x̃,  x̂₂ = √2 q̃ − ỹ                                   (eq 2)
//! σ²x2 = 2σq² + σy²                                          (eq 4)
//! x̂ = (x̃ σ²x2 + x̂₂ σx²)/(σx² + σ²x2)                          (eq 3, 5)
//! s₁ = 2σq² + σy² + σx²,  f₁ = σ²x2/s₁,  f₂ = σx²/s₁,  x̂ = x̃ f₁ + (√2 q̃ − ỹ) f₂      (eq 6)
//! ŷ = ỹ g₁ + (√2 q̃ − x̃) g₂,  g₁ = (2σq² + σx²)/s₁,  g₂ = σy²/s₁                      (mirror)
//! P = (1/s₁) [[σx² (2σq² + σy²), −σx² σy²], [−σx² σy², σy² (2σq² + σx²)]]
//! r = x̂₁ − x̂₂ = x̃ + ỹ − √2 q̃,  χ² = r²/s₁  (1 degree of freedom)                  (eq 7)
//! ```
//!
//! Equivalently x̂ = x̃ − (σx²/s₁) r, ŷ = ỹ − (σy²/s₁) r: both estimates for 4 additions and
//! 3 multiplications.
//!
//! General ([`RedundantAxes`], any M axes in N dimensions, used rows u):
//!
//! ```text
//! θ̂ = (Hᵤᵀ Rᵤ⁻¹ Hᵤ)⁻¹ Hᵤᵀ Rᵤ⁻¹ zᵤ,   P = (Hᵤᵀ Rᵤ⁻¹ Hᵤ)⁻¹,   χ² = (zᵤ − Hᵤθ̂)ᵀ Rᵤ⁻¹ (zᵤ − Hᵤθ̂) ~ χ²(|u| − N)
//! ```
//!
//! ### Why eq 5, which eliminates y, equals the joint weighted least squares
//!
//! Every linear unbiased estimator of x from z is aᵀz with aᵀH = (1, 0). H has rank 2 in
//! ℝ³, so these a form a line: with n = (1, 1, −√2), the left null vector (nᵀH = 0), they are
//! a = (1, 0, 0) − t n, i.e. the estimators (1 − t) x̂₁ + t x̂₂. Because x̂₁ and x̂₂ use
//! disjoint channels they are independent, and the variance (1 − t)² σx² + t² σ²x2 is
//! minimised by a unique t, which is eq 3. The x-component of the WLS solution is linear and
//! unbiased, so it lies on the same line, and by the Gauss–Markov theorem it has the least
//! variance of all linear unbiased estimators of x: it is the same unique minimiser. Hence
//! eq 5 = WLS x̂ (and var = P₁₁), the joint WLS marginal. Eliminating y loses nothing
//! because one redundancy leaves one free parameter. With two or more redundancies the set of
//! unbiased estimators is a plane or larger, and a combination of two independent estimates is
//! no longer optimal in general: then the general WLS is needed.
//!
//! The WLS residual lies in the parity space spanned by R n, and rᵀR⁻¹r = (nᵀz)²/(nᵀRn)
//! (the identity R⁻¹ − R⁻¹HPHᵀR⁻¹ = n (nᵀRn)⁻¹ nᵀ): with nᵀz = x̂₁ − x̂₂ and nᵀRn = s₁ this is
//! the χ² of eq 7.
//!
//! ### Missing and saturated axes
//!
//! [`screen`] drops an axis flagged missing, a non-finite reading, or |reading| ≥ full scale
//! (the converter at its rail, as the note suggests); the others are fused as above. With the
//! three LV2 axes, losing any one leaves a square system ([`xyq::fuse`] lists the closed
//! forms: without x, x̂ = √2 q̃ − ỹ, ŷ = ỹ, …). With fewer usable axes than unknowns the
//! result is [`FusionError::TooFewAxes`]; with enough axes that do not span the space (e.g.
//! two parallel ones), [`FusionError::DependentAxes`]. Nothing panics.
//!
//! ### The framework route
//!
//! [`RedundantAxes`] implements `MeasurementModel`, `MeasurementJacobian` and
//! `LinearMeasurementModel`, so any filter takes it. [`RedundantAxes::fuse_with_filter`] gets
//! the WLS result from the framework with no approximation: it solves N independent axes
//! exactly (chosen by pivoting, for conditioning: x and y for the LV2 set), θ₀ = H_A⁻¹ z_A,
//! P₀ = H_A⁻¹ R_A H_A⁻ᵀ, which is the posterior from those axes under a flat prior, and
//! updates a `KalmanFilter` with each remaining axis. The sum of the updates' normalised
//! innovations squared is the WLS χ². `FadingMemoryRls` with γ = 1 started from the same prior
//! gives the same (tests `lv2_fusion::rls_gamma_one_from_exact_prior_equals_wls`,
//! `lv2_axes::random_planar_axis_sets_all_routes_agree`,
//! `lv2_axes::random_spatial_axis_sets_all_routes_agree`). Starting instead from a *diffuse*
//! prior N(0, κI) only approximates WLS: the estimate is off by O(1/κ) (test
//! `lv2_fusion::diffuse_prior_only_approximates_wls`).
//!
//! ## Assumptions
//!
//! - Independent, zero-mean white noise per channel with known σ; the χ² false-alarm rate also
//!   assumes Gaussian noise (the estimate and P do not: they are the BLUE for any noise with
//!   these variances).
//! - The axes are exactly where the note puts them (q at 45°, no misalignment or scale-factor
//!   error) and unbiased; a bias is a fault the χ² test is there to detect.
//! - A saturated reading is recognised by |reading| ≥ full scale (clipping at the rail).
//! - The note's last suggestion (an on-line variance estimate per axis, discarding an axis
//!   whose variance exceeds a threshold) is not implemented; the χ² test is the per-sample
//!   counterpart.
//!
//! ## Errata
//!
//! The note's equations are right; what it leaves out or states loosely:
//!
//! | # | the note | estim | test |
//! |---|---|---|---|
//! | E1 | eq 1–7 | no algebraic or numeric error found: eq 5 and eq 6 equal WLS to round-off, eq 6's "2 adds and 3 multiplies" counts correctly | `lv2_fusion::eq5_and_eq6_equal_weighted_least_squares`, `lv2_fusion::worked_example_numbers` |
//! | E2 | only x̂ is derived; "estimates of x and y" reads as two separate scalar fusions | ŷ is the mirror formula and x̂, ŷ are correlated, cov = −σx²σy²/s₁: a downstream filter must take the full 2×2 P | `lv2_fusion::closed_form_covariance_equals_wls_and_filter`, `lv2_fusion::covariance_by_moment_propagation`, `lv2_fusion_example::chi2_mean_false_alarm_rate_and_covariance` (root tests) |
//! | E3 | eq 3 is "the best estimate … given two measurements with Gaussian statistics" | eq 3 is the minimum-variance *linear unbiased* combination because x̂₁, x̂₂ are independent; Gaussianity is not needed for that (only for "maximum likelihood" and for the χ² false-alarm rate) | `lv2_fusion::eq3_is_the_best_of_the_unbiased_family`, `lv2_monte_carlo::covariance_holds_for_uniform_noise` |
//! | E4 | eq 7 checks x̂₁ against x̂₂ (no threshold) | the x-check and the y-check are the same residual r; χ² = r²/s₁ with 1 dof, threshold from the χ²₁ quantile; a bias on any axis moves the same r: detection, not isolation (the note says as much) | `lv2_fusion::x_and_y_parity_checks_are_one_residual`, `lv2_fusion_example::bias_detection_matches_predicted_power` (root tests) |
//! | E5 | the equation number "(4)" printed before its equation | cosmetic (PDF layout) | — |
//!
//! ## Where things are
//!
//! - [`xyq`]: the note's closed forms (eq 2–7, ŷ, P, dropped-axis cases, screening).
//! - [`RedundantAxes`], [`Fusion`], [`FilterFusion`], [`screen`], [`AxisStatus`]: the general
//!   model and its fusions.
//! - [`simulate`]: seeded sensor simulation (noise, bias, clipping, drop-outs).
//! - [`stats`]: erfc, normal and χ² distribution functions for the test thresholds.
//!
//! The note's worked example, the χ² Monte Carlo, the saturation run, the headline table and
//! the figures are the `lv2_fusion` example: `examples/lv2_fusion.rs`, whose body is
//! `examples/reproductions/lv2_fusion.rs`.

mod error;
#[cfg(feature = "std")]
mod model;
#[cfg(feature = "std")]
pub mod simulate;
#[cfg(feature = "std")]
pub mod stats;
pub mod xyq;

pub use error::FusionError;
#[cfg(feature = "std")]
pub use model::{
    AxisStatus, DynAxes, FilterFusion, Fusion, PlanarAxes, RedundantAxes, SpatialAxes, XyqModel,
    screen,
};
