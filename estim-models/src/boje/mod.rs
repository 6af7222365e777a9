//! # Boje: planar state estimation with two two-axis accelerometers
//!
//! E. Boje, *Approximations for state estimation in a plane using two two-axis
//! accelerometers*, School of Electrical, Electronic and Computer Engineering, University of
//! KwaZulu-Natal (conference paper, c. 2008). Checked notes: `docs/paper-notes/boje.md`.
//!
//! An object moves in the plane carrying two two-axis accelerometers at ±R along its body u
//! axis and no gyro. The paper inverts the sensor geometry to inertial accelerations, angular
//! acceleration and squared rate (eq 5), propagates the sensor noise and the heading
//! uncertainty through the inversion with Papoulis' second-order moments (eq 7–13), and feeds
//! the result to a 6-state Kalman filter with GPS/compass fixes and the squared rate as an extra
//! nonlinear measurement whose noise is correlated with the process noise (eq 14–16).
//!
//! | module | paper | what |
//! |---|---|---|
//! | [`moments`] | §2.2, eq 7–11 | the worked examples cos θ, sin θ, x cos θ, x sin θ: [`TrigProducts`] for the generic [`SecondOrder`](estim_core::SecondOrder), exact and printed closed forms |
//! | [`geometry`] | eq 1–5, 12, 13 | [`AccelerometerInversion`] (eq 5 with Jacobian and Hessians), [`inertial_mean`] (eq 12), [`lambda()`] (eq 13 corrected) |
//! | [`filter`] | eq 14–16 | [`PlanarProcess`], [`NonlinearPlanarProcess`], [`RateSquaredMeasurement`], [`PositionHeadingMeasurement`], [`filter_step`] |
//! | [`rate`] | §3, eq 17–19 | the scalar rate sub-model, closed forms, Riccati iteration |
//! | [`circle`] | §4, Table 1 | the scenario ([`CircleConfig`]) and its simulator ([`simulate_circle`]) |
//!
//! The paper's experiments (the moments and λ examples, the rate Monte Carlo, the circle Monte
//! Carlo, their headline tables and figures) are the examples `boje_moments`, `boje_lambda`,
//! `boje_rate` and `boje_circle`: `examples/<name>.rs`, whose body is
//! `examples/reproductions/<name>.rs`.
//!
//! ## State and measurements
//!
//! | index | state x | unit | | measurement | unit | rate |
//! |---|---|---|---|---|---|---|
//! | 0 [`filter::VX`] | ẋ | m/s | | x (GPS) | m | 1 Hz |
//! | 1 [`filter::VY`] | ẏ | m/s | | y (GPS) | m | 1 Hz |
//! | 2 [`filter::RATE`] | θ̇ | rad/s | | θ (compass, residual wrapped to (−π, π]) | rad | 1 Hz |
//! | 3 [`filter::X`] | x | m | | θ̇² = (a_u2 − a_u1)/(2R) | rad²/s² | every accelerometer step (100 Hz) |
//! | 4 [`filter::Y`] | y | m | | | | |
//! | 5 [`filter::HEADING`] | θ (unwrapped) | rad | | | | |
//!
//! Sensor signals a = (a_u1, a_v1, a_u2, a_v2) in m/s², channel variances σ²_u1 … σ²_v2 in
//! (m/s²)² ([`ChannelVariances`]); R = half the sensor separation, m.
//!
//! ## Equations implemented
//!
//! Geometry (eq 4) and its inverse (eq 5), with S_u = a_u1 + a_u2, S_v = a_v1 + a_v2,
//! c = cos θ, s = sin θ:
//!
//! ```text
//! (a_u1, a_v1, a_u2, a_v2) = M(θ) (ẍ, ÿ, θ̈, θ̇²),   M(θ) = [[c, s, 0, −R], [−s, c, R, 0], [c, s, 0, R], [−s, c, −R, 0]]
//! g(θ, a) = (½(c S_u − s S_v), ½(s S_u + c S_v), (a_v1 − a_v2)/(2R), (a_u2 − a_u1)/(2R))
//! ```
//!
//! Moments for z = (θ, a) ~ (z̄, C_z = diag(σ²_θ, σ²_u1, σ²_v1, σ²_u2, σ²_v2)) — eq 7 and 9,
//! i.e. the generic `SecondOrder` propagator on [`AccelerometerInversion`]:
//!
//! ```text
//! E{g} ≈ (g1 (1 − σ²_θ/2), g2 (1 − σ²_θ/2), g3, g4)                                    (eq 12)
//! λ11 = [σ²_θ (S_u s + S_v c)² + (σ²_u1+σ²_u2) c² + (σ²_v1+σ²_v2) s²]/4
//! λ12 = [σ²_θ (−S_u s − S_v c)(S_u c − S_v s) + (σ²_u1+σ²_u2−σ²_v1−σ²_v2) s c]/4
//! λ22 = [σ²_θ (S_u c − S_v s)² + (σ²_u1+σ²_u2) s² + (σ²_v1+σ²_v2) c²]/4
//! λ13 = (σ²_v2 − σ²_v1) s/(4R),  λ23 = (σ²_v1 − σ²_v2) c/(4R)
//! λ14 = (σ²_u2 − σ²_u1) c/(4R),  λ24 = (σ²_u2 − σ²_u1) s/(4R)
//! λ33 = (σ²_v1 + σ²_v2)/(4R²),   λ44 = (σ²_u1 + σ²_u2)/(4R²),   λ34 = 0               (eq 13, corrected)
//! ```
//!
//! Filter (eq 14–16, corrected), accelerometer period Δt:
//!
//! ```text
//! A = [[I₃, 0], [Δt I₃, I₃]],  B = [Δt I₃; Δt²/2 I₃]
//! uᵢ = (E{ẍ}, E{ÿ}, θ̈) from eq 12 at θ̄ = x̂ᵢ[5], σ²_θ = Pᵢ[5,5];  Λᵢ from eq 13 likewise
//! xᵢ₊₁ = A xᵢ + B (uᵢ + vᵢ),  Q = B Λ_vv Bᵀ,  S = E{B vᵢ wᵢ} = B Λ_vw,  R_θ̇² = λ44
//! yᵢ = (x, y, θ, θ̇²) + wᵢ,  R_fix = diag(σ²_xy, σ²_xy, σ²_yθ)
//! eq 16: K = (A P Cᵀ + S)(R + C P Cᵀ)⁻¹,  x̂ᵢ₊₁ = A x̂ᵢ + B uᵢ + K (y − ŷ),
//!        Pᵢ₊₁ = A P Aᵀ − K (C P Aᵀ + Sᵀ) + Q
//! ```
//!
//! estim runs eq 16 as update(θ̇²) → update(fix, when present) →
//! [`predict_correlated`](estim_filters::PredictCorrelated::predict_correlated)(process, θ̇²
//! model, S) ([`filter_step`]), on any filter ([`FilterKind`]: EKF = eq 16, second-order EKF,
//! UKF). With equal channel variances (Table 1) S = 0 and this is eq 16 to round-off; with
//! S ≠ 0 the framework's decorrelated prediction is eq 16 exactly when given the θ̇² model
//! linearised at x̂ᵢ (test `eq16_predictor_equals_update_then_decorrelated_predict`);
//! [`filter_step`] passes the nonlinear θ̇² model, which re-linearises the small decorrelation
//! term at the updated state (≈ 10⁻⁶ relative, test
//! `filter_step_relinearisation_difference_is_second_order`) and keeps the second-order and
//! unscented filters consistent.
//!
//! Rate accuracy (§3), scalar sub-model ω⁺ = ω + Δt θ̈, y = ω², c = 2ω₀, q = λ33 Δt², r = λ44:
//!
//! ```text
//! pᵢ₊₁ = pᵢ − (pᵢ c + s)²/(r + pᵢ c²) + q                     (eq 17)
//! p = q/2 + √(q²/4 + q r/c²)                                  (eq 18, one-step predicted)
//! p = Δt² σ²/(4R²) (1 + √(1 + 4/(cΔt)²))   (equal channels)   (eq 19, corrected)
//! ```
//!
//! ## Assumptions
//!
//! - Accelerometer noise white, independent between channels and of the heading estimate
//!   (as the paper); no bias, no misalignment, no gravity (horizontal plane).
//! - The inertial input of step i is the accelerometer sample aᵢ at tᵢ held over [tᵢ, tᵢ₊₁]
//!   (zero-order hold); the θ̇² measurement of step i uses the same sample, hence S.
//! - θ̇² carries no sign: the EKF keeps the sign of its estimate; the rate reversal at t_end/2
//!   in §4 is seen through the θ̈ input (one large sample) and the compass.
//! - §3: σ = 1.4 mg = 1.4·10⁻³ · 9.80665 m/s² per channel; the datasheet conversions use the
//!   noise bandwidth (π/2)/Δt = 157 Hz, which reproduces the paper's 1.4 mg and 0.63 °/s.
//!
//! ## Section 4 reading
//!
//! The paper gives "the CG of an object with R = 0.5 m moves in a circle of radius 10 m while
//! rotating at sgn(t − t_end/2)·0.1·t rad/s" and Table 1, not t_end nor how the orbit relates
//! to the rotation. estim reads (notes §5): a rigid arm about the origin, CG at 10 m, heading
//! tangent (θ = φ + π/2), ω(t) = sgn(t − t_end/2)·0.1·t with sgn(0) = +1, t_end = 20 s (ω goes
//! 0 → −1 rad/s, jumps to +1, → +2 rad/s; CG acceleration up to 40 m/s²). Truth discretely
//! consistent with the model (exact velocities at the samples, uₖ = (vₖ₊₁ − vₖ)/h,
//! xₖ₊₁ = A xₖ + B uₖ, so the positions stay within 0.1 m of the circle; aₖ = M(θₖ)(uₖ, ωₖ²) +
//! noise). GPS/compass at t = 1, 2, … s. Correct ICs (Fig 3): P₀ = diag(0.1², 0.1², 0.01²,
//! 0.5², 0.5², 0.01²) with x̂₀ − x₀ drawn from N(0, P₀) per run (a consistent prior). Wrong ICs
//! (Fig 2): P₀ = diag(1, 1, 1, 25, 25, 1), x̂₀ = x₀ + (1, −1, 0.5, 5, −5, 0.5). Reported
//! averages are over the **settled part t ∈ \[2, 20\] s** (after two fixes; P₀ is already at the
//! steady level) and all runs, at every 10 ms step, of the one-step predictions x̂ᵢ.
//!
//! ## Results (full runs; see the examples `boje_*`)
//!
//! | quantity | paper | estim |
//! |---|---|---|
//! | rate std at 80 °/s, R = 0.1 m | 0.24 °/s (eq 19) | 0.3352 °/s (eq 18 = eq 17 iterated); scalar EKF Monte Carlo 0.336 °/s |
//! | full-scale rate; accel noise; gyro noise; ratio | 740 °/s; 1.4 mg; 0.63 °/s; ≈ 10 | 739.8 °/s; 1.38 mg; 0.627 °/s; 9.66 |
//! | position std (§4) | around 0.5 m | √P 0.50 m (x 0.47, y 0.54), RMS error 0.48 m (50 runs) |
//! | heading std (§4) | 0.01 rad | √P 0.0113 rad, RMS error 0.0107 rad |
//! | velocity (§4) | — | √P 0.098 m/s, RMS 0.122 m/s: ẋ error 1.5× its √P (see below) |
//!
//! **Model limitation and the nonlinear variant.** The paper folds σ²_θ into Q as if the
//! heading error were white, but it is a slowly varying state error, so the velocity noise it
//! drives is correlated with the heading error the filter carries. The paper's filter is
//! consistent in position, heading and rate (RMS/√P 0.95–1.1) but its ẋ RMS is ≈ 1.5× its √P
//! (1.8× after the rate reversal). [`NonlinearPlanarProcess`] puts θ inside f through eq 5, so
//! the coupling lives in F P Fᵀ: on the same data its EKF, second-order EKF and UKF all give
//! ẋ, ẏ ratios ≈ 0.97–0.99 with position and heading √P within 8 % of the paper's model (test
//! `nonlinear_process_fixes_velocity_consistency`, example `boje_circle`).
//!
//! ## Errata
//!
//! | # | the paper prints | estim uses | shown by (test) |
//! |---|---|---|---|
//! | E1 | eq 13: λ33 = (σ²_u1+σ²_u2)/(4R²), λ44 = (σ²_v1+σ²_v2)/(4R²) | swapped: θ̈ = (a_v1 − a_v2)/(2R) uses the v channels, θ̇² the u channels ([`lambda()`]; the printed form is [`lambda_as_printed`]) | `lambda33_lambda44_swapped_in_paper` (generic J C Jᵀ and 10⁶-sample Monte Carlo, unequal variances), `eq13_lambda_equals_generic_jcjt` |
//! | E2 | A_c = `[[0, I], [I, 0]]` | `[[0, 0], [I, 0]]` (ẋ = v, v̇ = u) | `printed_continuous_transition_is_not_kinematic` (printed: v = sinh 1, x = cosh 1 − 1 after 1 s of 1 m/s²) |
//! | E3 | Q = `[[Λ_vv, 0], [0, 0]]`, S = `[0, (λ14, λ24, λ34, 0)ᵀ]` (no Δt) | v enters as B v: Q = B Λ_vv Bᵀ, S = B Λ_vw (§3 itself uses q = λ33 Δt²) | `eq16_predictor_equals_update_then_decorrelated_predict`, `circle_quick_monte_carlo` (θ̇² NIS ≈ 1, position/heading RMS inside √P) |
//! | E4 | R top-left = cov(n_ax, n_ay, n_aθ) | diag(σ²_xy, σ²_xy, σ²_yθ), the GPS/compass noise ([`PositionHeadingMeasurement`]) | `circle_quick_monte_carlo` (fix NIS ≈ 3) |
//! | E5 | P₀ = diag{12, 12, 12, 52, 52, 12}, diag{0.12, …} | lost superscripts: diag(1², 1², 1², 5², 5², 1²), diag(0.1², 0.1², 0.01², 0.5², 0.5², 0.01²) ([`InitialConditions`]) | `circle_quick_monte_carlo` (√P settles at ≈ 0.5 m, 0.011 rad = the Fig 3 values) |
//! | E6 | eq 19: 1 + √(1 + 1/(cΔt)²) | 1 + √(1 + 4/(cΔt)²) ([`rate::steady_state_eq19`]; printed: [`rate::steady_state_eq19_printed`]) | `eq19_as_printed_differs_from_eq18`, `eq19_corrected_equals_eq18` |
//! | E7 | §3: "0.24 °/s from eq 19" | 0.335 °/s (predicted), 0.330 °/s (filtered) | `eq19_as_printed_differs_from_eq18`, `scalar_ekf_monte_carlo_matches_eq18` |
//! | E8 | §4: t_end not given, orbit vs rotation unspecified | the reading above | `circle_truth_is_consistent` |
//! | E9 | eq 15/16 "when output measurements are not available" | θ̇² is available at every step; only x, y, θ are 1 Hz (as §3's analysis presumes) | `scalar_ekf_monte_carlo_matches_eq18` |
//! | E10 | u = (a_x, a_y, a_θ) undefined | u = (E{g1}, E{g2}, g3) from eq 12 at θ̄ = x̂\[5\], σ²_θ = P\[5,5\] ([`planar_input`]) | `eq16_predictor_equals_update_then_decorrelated_predict` |
//! | E11 | "E{x₁x₂} ≈ x̄₁x̄₂ + cov(x₁x₂)" | exact, with cov(x₁, x₂) (cosmetic) | — |
//!
//! ## Consistency (estim's toolkit)
//!
//! `cargo run --release --example consistency` runs the circle scenario (Table 1, t_end = 20 s,
//! correct ICs with x̂₀ − x₀ ~ N(0, P₀)) on estim's Monte Carlo runner with the EKF: 1000 runs
//! (200 with `--quick`), 19 slots at the fixes t = 1 … 19 s (after the fix update), NIS of the
//! fixes, residual pair t = 5 s × 15 s; each check at 99 % (Simes).
//!
//! - **Paper's linear process: not consistent.** Ensemble/filter variance ratio and average
//!   NEES fail (check p-values underflow to 0): the worst variance ratio is ẋ's, 6.3 at 14 s,
//!   and the NEES (band \[5.72, 6.29\]) is 6.0 at 1–2 s but 13.4 at 9 s and 20.5 at 19 s. The
//!   mean error, the fix NIS and the residual correlation pass. The heading variance is folded
//!   into Q as white noise, but the heading error is a slowly varying state error, so the
//!   velocity error it drives is correlated over time and with the heading error: the
//!   filter's velocity P is optimistic.
//! - **Nonlinear process ([`NonlinearPlanarProcess`]): consistent** in mean error, variance
//!   ratios (p = 0.47), NEES (p = 0.95; every slot inside the band, 5.93–6.01 at 1, 2, 5, 9,
//!   12, 15, 19 s), NIS (p = 0.055) and residuals (p = 0.18).
//! - Both fail *error ⟂ estimate*, by construction: the simulator flies one fixed trajectory
//!   (only x̂₀ and the sensor noise are random), so x̂ = x − e with x fixed and
//!   corr(e, x̂) = −1. The check assumes the truth is drawn from the prior; it says nothing
//!   about the filter here.

#[cfg(feature = "std")]
pub mod circle;
pub mod filter;
pub mod geometry;
pub mod moments;
pub mod rate;

#[cfg(feature = "std")]
pub use circle::{
    CircleConfig, CircleData, FilterKind, InitialConditions, ProcessKind, simulate_circle,
};
pub use filter::{
    AccelerometerProcess, NonlinearPlanarProcess, PlanarFilter, PlanarInput, PlanarProcess,
    PositionHeadingMeasurement, RateSquaredMeasurement, StepReport, filter_step, planar_input,
};
pub use geometry::{
    AccelerometerInversion, ChannelVariances, InertialMoments, InversionInput, inertial_mean,
    inertial_moments, lambda, lambda_as_printed,
};
pub use moments::{TrigMoments, TrigProducts};
pub use rate::{ScalarRateProcess, ScalarRateSquared};

/// An angle wrapped to (−π, π] (estim-core's helper, re-exported here for the model's users).
pub use estim_core::wrap_angle;
