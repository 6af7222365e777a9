//! A 200-state linear filter: the 1-D heat equation on a rod, observed at every other node.
//!
//! The rod [0, 1] m has 200 interior nodes (spacing h = 1/201 m) and its ends held at the
//! ambient temperature; the state is the temperature above ambient at each node. Explicit
//! (forward) Euler on u_t = D u_xx gives
//!
//! ```text
//! uᵢ⁺ = uᵢ + r (uᵢ₋₁ − 2uᵢ + uᵢ₊₁) + Δt bᵢ s + wᵢ,     r = D Δt / h²,
//! ```
//!
//! which is stable for r ≤ ½: the eigenvalues of F = I + r L (L the second-difference matrix)
//! are 1 − 4r sin²(kπ / (2(n + 1))), k = 1…n, inside (1 − 4r, 1), so |λ| < 1 needs r ≤ ½. We
//! take r = ¼, so F's eigenvalues lie in (0, 1) (no mode flips sign), and D = 10⁻⁴ m²/s (a
//! metal), which makes Δt = r h²/D = 61.9 ms. F is tridiagonal but stored dense. A heater at
//! x = 0.3 m adds s(t) = 2.5 (1 + sin(2π t / 5 s)) K/s at its node (the known input). Process
//! noise: white, (0.02 K)² per node and step. Measurements: the 100 odd-numbered nodes (every
//! other one), noise (0.1 K)² each, independent. Prior: 10 sin(πx) K with a squared-exponential
//! covariance (σ = 1 K, length 0.05 m) plus (0.1 K)² on the diagonal; the truth starts from a
//! draw of the prior, so a correct filter is consistent: the NEES of each step is χ²₂₀₀.
//!
//! Filters: `KalmanFilter<f64, Dyn>` and `Ukf<f64, Dyn>` (the default scaled unscented
//! transform, α = 10⁻³, β = 2, κ = 0, with 2n + 1 = 401 sigma points) from the same prior,
//! both driven by `estim_core::linear::{LinearProcess, LinearMeasurement}`. Printed: wall time
//! per step (predict + update on prepared filters; median and mean over the run), RMS
//! error against the truth, the NEES, and the largest KF−UKF difference against the round-off
//! bound it should respect (the UKF is exact on a linear model; α = 10⁻³ amplifies its
//! round-off).
//!
//! `cargo run --release --example large_state [-- --json] [-- --quick]`

fn main() -> Result<(), Box<dyn std::error::Error>> {
    estim_reproductions::large_state::main()
}
