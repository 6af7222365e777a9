//! When a Gaussian is not enough: two problems with multimodal posteriors, run by the EKF,
//! the UKF and the particle filters on the same models.
//!
//! **1. The univariate nonstationary growth model** (Gordon, Salmond & Smith 1993; Kitagawa
//! 1996):
//!
//! ```text
//! xₖ = xₖ₋₁/2 + 25 xₖ₋₁/(1 + xₖ₋₁²) + 8 cos(1.2 k) + wₖ,   wₖ ~ N(0, 10)
//! zₖ = xₖ²/20 + vₖ,                                      vₖ ~ N(0, 1),   x₀ ~ N(0, 5)
//! ```
//!
//! z sees x², not its sign, so the posterior is bimodal whenever the dynamics do not settle the
//! sign. The EKF, the UKF, the bootstrap particle filter and the auxiliary particle filter
//! (1000 particles each) run on the same simulated readings; the RMSE of each filter's
//! posterior mean over every step of every run (200 runs × 50 steps, seeded; `--quick` 40 runs)
//! is the table. A figure shows, at the most bimodal step of run 0, the bootstrap filter's
//! weighted histogram beside the EKF's and UKF's Gaussians and the true state.
//!
//! **2. Range-only localisation from far away.** A robot drives with known odometry
//! (1 m/step in x, 0.2 m/step in y, process noise σ = 0.1 m) and measures its range to two
//! beacons at (0, 0) and (30, 0) (σ = 1 m). It starts at (5, 12); the filters are told
//! N((5, −12), 15² I): the mirror image across the beacons' line, 24 m away. The ranges cannot
//! tell the two sides apart at first; the odometry's y-motion (away from the line on the true
//! side, towards it on the mirror side) does, over a few steps. The EKF linearises at the
//! mirror and locks onto it. The particle filter (10 000 particles) keeps both hypotheses
//! until the motion kills the wrong one. The (cubature) UKF recovers too in this setting: its
//! sigma points at ±√2·15 m reach the true side. Reported: each filter's final position error
//! over 50 runs (`--quick` 10), 60 steps each.
//!
//! `--shard I/N --out FILE` runs shard I of N of both Monte Carlos' runs and writes their
//! records to FILE; `--merge FILE...` merges the N files and prints what one process prints,
//! bit for bit (the figure's single run is run by the merge); `--stats FILE` writes the sums
//! over runs and the final errors exactly (`estim_reproductions::sharding`).
//!
//! `cargo run --release --example particle_growth [-- --json] [-- --quick] [-- --shard I/N --out FILE | --merge FILE...] [-- --stats FILE]`

fn main() -> Result<(), Box<dyn std::error::Error>> {
    estim_reproductions::particle_growth::main()
}
