//! A heading across ±π: the same UKF with a plain vector state and with a wrapping ⊞.
//!
//! A vehicle drives a circle in the plane: state (x, y, θ), odometry input (v, ω) with
//! v = 2 m/s and ω = 0.8 rad/s, so θ crosses ±π every 7.9 s (13 times in 100 s).
//! The process model is the unicycle
//!
//! ```text
//! x⁺ = x + v Δt cos θ,  y⁺ = y + v Δt sin θ,  θ⁺ = wrap(θ + ω Δt),   Δt = 0.1 s,
//! ```
//!
//! with the heading wrapped into (−π, π], as models usually are, and additive noise
//! σ = (0.02 m, 0.02 m, 0.01 rad) per step. Measurements every step: a GPS position
//! (σ = 0.5 m) and a compass (σ = 0.05 rad, residual wrapped). Prior N(truth, diag(1 m²,
//! 1 m², 0.1² rad²)), the truth drawn from it, so a correct filter is consistent: the NEES of
//! e = x̂ ⊟ x (heading difference wrapped) is χ²₃.
//!
//! Filters: the cubature UKF (sigma points at ±√(3P) about the mean) on plain ℝ³, and the same
//! filter with `WrappedAngles::new([2])` as its state space. Without ⊞, at every crossing the
//! sigma points straddle ±π, their deviations f(χ) − f(x̂) jump by 2π, and the predicted mean
//! and P are wrong by ~π and ~π²; with ⊞ nothing changes at the crossing. A Monte Carlo
//! (200 runs, 1000 steps) gives the average NEES at each step against its 99 % χ² band, and
//! the worst heading error; a figure shows both filters' average NEES.
//!
//! `--shard I/N --out FILE` runs shard I of N of each filter's runs and writes their records to
//! FILE; `--merge FILE...` merges the N files and prints what one process prints, bit for bit;
//! `--stats FILE` writes the sums over runs exactly (`estim_reproductions::sharding`).
//!
//! `cargo run --release --example heading_wrap [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

fn main() -> Result<(), Box<dyn std::error::Error>> {
    estim_reproductions::heading_wrap::main()
}
