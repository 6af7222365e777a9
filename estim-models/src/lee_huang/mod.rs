//! # Lee & Huang: all-accelerometer planar INS, CKF and own-ship trajectory estimator
//!
//! S.-C. Lee, Y.-C. Huang, *Innovative estimation method with measurement likelihood for
//! all-accelerometer type inertial navigation system*, IEEE Transactions on Aerospace and
//! Electronic Systems 38(1), 2002 (correspondence, IEEE Log No. T-AES/38/1/02601).
//!
//! What estim takes from it:
//!
//! - [`sensors`]: the planar four-accelerometer configuration of appendix B (eq 58–62),
//!   forward model (rigid-body motion → four signals) and inversion (signals → y_ax, y_ay,
//!   y_ω̇), sign-corrected (E1).
//! - [`model`]: the 6-state planar INS driven by the derived inputs (eq 15–21), as
//!   [`InsProcess`] (true Jacobian and Hessians, for the EKF family) and [`CkfProcess`] (the
//!   paper's CKF, eq 33–37: Jacobian Ψ = I + F T, affine, runs in the linear
//!   [`KalmanFilter`](estim_filters::KalmanFilter)); the attitude measurement
//!   [`AttitudeMeasurement`]; gravity as an option ([`Plane`]).
//! - [`likelihood`]: the velocity "measurement likelihood" g(D) of eq 27/28 (E2) with analytic
//!   Jacobian and Hessians.
//! - [`ote`]: the own-ship trajectory estimator (eq 40–48) on the framework's
//!   [`FadingMemoryRls`](estim_filters::FadingMemoryRls), and its steady state.
//! - [`simulation`]: seeded truth and sensor data.
//!
//! Section IV and its variants (the runs, the headline table, the figures) are the `lee_huang`
//! example: `examples/lee_huang.rs`, whose body is `examples/reproductions/lee_huang.rs`.
//!
//! ## State, input and measurement
//!
//! | index | state D | unit | input u | unit | measurement E | unit |
//! |---|---|---|---|---|---|---|
//! | 0 | x | m | y_ax = f_bx | m/s² | θ + ε | rad |
//! | 1 | y | m | y_ay = f_by | m/s² | | |
//! | 2 | v_x | m/s | y_ω̇ = ω̇ | rad/s² | | |
//! | 3 | v_y | m/s | | | | |
//! | 4 | θ (body x axis from inertial x, CCW) | rad | | | | |
//! | 5 | ω = θ̇ | rad/s | | | | |
//!
//! Input noise W = (δa_x, δa_y, δω̇) (eq 17–19), per-sample covariance Σ_W; measurement noise
//! ε ~ N(0, R_v), R_v scalar. The OTE state is r_e = (v_x, v_y) \[m/s\], its measurement the
//! pseudo-measurement Z_p = g(D̂) \[m/s\].
//!
//! ## Equations implemented
//!
//! Sensors (appendix B, corrected): sensor i at body position ρ lᵢ, direction βᵢ,
//! l = \[(0,−1), (1,0), (0,1), (−1,0)\], β = \[(1,0), (0,1), (−1,0), (0,−1)\];
//!
//! ```text
//! Aᵢ = (a + ω̇ ẑ × rᵢ − ω² rᵢ − g_vec) · R(θ) βᵢ = f_b · βᵢ + ρ ω̇,   f_b = R(θ)ᵀ (a − g_vec)
//! y_ax = (A₁ − A₃)/2,   y_ay = (A₂ − A₄)/2,   y_ω̇ = (A₁ + A₂ + A₃ + A₄)/(4ρ)
//! ```
//!
//! Process (eq 16, discretised with θ frozen over the step; ZOH default, Euler = eq 33):
//!
//! ```text
//! f(D, u) = Ψ D + G_d(θ) u + c(g_vec),   Ψ = I + F T
//! G_d(θ): x, y rows (T²/2) R(θ) [y_ax, y_ay];  v rows T R(θ) [y_ax, y_ay];  θ row T²/2 y_ω̇;  ω row T y_ω̇
//! Q = G_d(θ) Σ_W G_d(θ)ᵀ                   (Euler: T² Γ Σ_W Γᵀ, eq 36)
//! full Jacobian  ∂f/∂D = Ψ + [∂(G_d u)/∂θ] e₄ᵀ;   CKF Jacobian  Ψ  (G at θ̂, eq 33)
//! ```
//!
//! Measurement (eq 21): E = θ + ε, H = e₄ᵀ (innovation wrapped into (−π, π]).
//!
//! CKF (eq 33–37): the Kalman filter over [`CkfProcess`] with input
//! [`CkfInput`] { u, θ̂_{k−1|k−1} } and [`AttitudeMeasurement`].
//!
//! Velocity likelihood (eq 27/28 with the state substituted as in eq 30/31):
//!
//! ```text
//! d = |p|,  ρ̇ = p·v/d,  g(D) = ρ̇ (cos θ, sin θ) + d ω (−sin θ, cos θ)
//! ```
//!
//! OTE (eq 44–48, B = I₂, z = B r_e + n, n ~ N(0, S_p)): per cycle, after the CKF update,
//! Z_p = g(D̂_{k|k}); r̂_e = CKF velocity; M = P_p/γ; K_p = M (M + S_p)⁻¹; P_p ← (I − K_p) M;
//! r̂_e ← r̂_e + K_p (Z_p − r̂_e); the CKF velocity is overwritten with r̂_e (the CKF covariance is
//! left as it is: the paper is silent, and P_p is not an error covariance, E9). Steady state:
//! K_p → (1 − γ) I, P_p → (1 − γ) S_p.
//!
//! ## Assumptions and readings (section IV)
//!
//! | item | estim | why |
//! |---|---|---|
//! | plane | horizontal, no gravity ([`Plane::Horizontal`]); vertical plane with g_vec = (0, −g₀) as an option | eq 16 has no gravity term and section II says gravity is neglected. With gravity modelled in both truth and filter the CKF errors are *identical* (g_vec is known and cancels in the error dynamics, test `gravity_does_not_change_ckf_errors`); only the OTE sees the difference, and in the vertical plane 2 g along a 30°-pitched body gives level flight a = (√3 g, 0), a permanent 30° angle between velocity and body axis that the OTE's radial-flight assumption turns into a 1.7 km error. The horizontal reading is the one most favourable to the paper's OTE claim |
//! | truth | θ ≡ 30°, ω ≡ 0, f_b = (2 g₀, 0), D(0) = (10 m, 5 m, 2 m/s, 2 m/s, 30°, 0) | printed |
//! | T, duration | 0.01 s, 20 s | not given; "within 5 s" needs more than 5 s |
//! | bias | 10 mg = 0.0981 m/s² on y_ax and y_ay, none on y_ω̇ | a bias common to all four sensors would cancel in y_ax, y_ay and give 0.098 rad/s² on y_ω̇, contradicting "satisfactory angle and angular rate" |
//! | W | σ_W = √(0.01 T) = 0.01 per channel per sample (Q_v = 0.01 I T literally, E8) | |
//! | ε | R_v = 0.01/T = 1 rad² (E6) | printed; this large attitude noise dominates the CKF position error |
//! | CKF init | D̂(0) = D(0), P(0) = diag(1, 1, 0.1, 0.1, (1°)², (1°/s)²) | ICs "given"; P(0) not given |
//! | OTE | γ = 0.95, S_p = 0.01 I, P_p(0) = I (the issue's); γ = 0.99, P_p(0) = S_p as a variant | steady state is S_p-independent; time constant T/(1 − γ) = 0.2 s |
//! | seeds | RMS over 20 seeds (5 in the quick form) | |
//!
//! What the run shows (see the `lee_huang` example): the CKF position error grows without
//! bound (≈ 100 m at 20 s), as the unobservability predicts; the OTE does **not** make it
//! converge — it roughly doubles it — because g(D̂) re-expresses the CKF's own estimate and
//! assumes radial flight. estim's second scenario (radial initial conditions, σ_ε = 0.01 rad,
//! clearly not the paper's) shows the one thing the OTE can do: remove the cross-track drift,
//! leaving the along-track ½ b t².
//!
//! ## Errata
//!
//! | # | the paper prints | estim uses | shown by |
//! |---|---|---|---|
//! | E1 | eq 18/62: y_ay = −(A₂ − A₄)/2 | +(A₂ − A₄)/2 with the printed l, β and the CCW R(θ) of eq 16 | `inversion_recovers_specific_force_and_angular_acceleration`, `printed_y_ay_sign_returns_minus_f_by` |
//! | E2 | eq 38/39: v̂_x = ρ̇ sin x₅ − d x₆ cos x₅, v̂_y = ρ̇ cos x₅ + d x₆ sin x₅ | eq 27/28: ρ̇ cos x₅ − d x₆ sin x₅, ρ̇ sin x₅ + d x₆ cos x₅ | `eq27_28_reproduce_polar_velocity_eq38_39_do_not`, `printed_eq38_39_likelihood_diverges` |
//! | E3 | eq 43 and eq 45 define Ẑ_p(k) and r̂_e(k/k) identically | Z_p = g(D̂_{k/k}), r̂_e = CKF velocity (taken literally the OTE is a no-op) | `literal_eq43_45_make_the_ote_a_no_op` |
//! | E4 | eq 16 has no gravity, eq 60/62 say the signals contain it | gravity optional, horizontal default (table above) | `gravity_does_not_change_ckf_errors` |
//! | E5 | eq 60: R(θ + (i−1)π/2)\[ẍ; ÿ − g\] + … then "· β"; centripetal ωᵢ₊₁ × (ωᵢ₊₂ × rᵢ) | the per-sensor rotation already projects on the sensing axis (no second · β); centripetal ω × (ω × rᵢ) ⟂ βᵢ; with y up the vector is a − g_vec = \[ẍ; ÿ + g\] | `eq60_per_sensor_rotation_reading_matches_forward_model` |
//! | E6 | R_v = 0.01 I₆ₓ₆/T | scalar R_v = 0.01/T (H is 1 × 6) | by construction ([`AttitudeMeasurement`] has a 1 × 1 R) |
//! | E7 | eq 33: G_T = G T (Euler) | zero-order hold (T²/2 position terms); Euler kept as an option. Euler shifts position by −½ a T t | `zoh_model_reproduces_constant_acceleration_truth`, `euler_position_offset_is_half_a_t_t` |
//! | E8 | Q_v = 0.01 I T with Γ_T = Γ T, but R_v = 0.01/T | literal: per-sample input noise covariance 0.01 T (σ_W = 0.01 m/s² at T = 0.01 s); the PSD reading (σ_W = 1 m/s²) would swamp the 10 mg bias | `process_noise_matches_unscented_propagation_of_input_noise` (Q = G_d Σ_W G_dᵀ) |
//! | E9 | "P_p(k+1) is the error covariance of r̂_e(k+1/k+1)" | P_p is a fading-memory weight; smoothing white noise of covariance S_p gives S_p (1 − γ)/(1 + γ), not (1 − γ) S_p | `ote_covariance_is_not_the_error_covariance` |
//! | E10 | eq 23 defines θ as the bearing of the position; eq 30/31, 38/39 substitute the body attitude x₅ and rate x₆ | with the bearing g(D) ≡ v (no information); with x₅, x₆ (as the paper) it imposes radial flight, violated by section IV's ICs; so the paper's "CKF+OTE converges within 5 s" does not reproduce | `likelihood_is_the_velocity_when_theta_is_the_bearing`, `ote_makes_position_worse_with_paper_initial_conditions`, `ote_removes_cross_track_drift_in_radial_scenario` |
//! | E11 | appendix A eq 56: … − K γ − Γ W | + K γ with X̃ = X̂ − X (no effect on eq 57) | derivation only (appendix A is not implemented) |
//! | E12 | W = \[δa_x, δa_y, δa_z\]ᵀ | third component δω̇ (eq 19) | notation |
//! | E13 | eq 19/61: y_ω̇ = ΣA/4 | ΣA/(4ρ) (equal for ρ = 1 only) | `printed_angular_acceleration_needs_one_over_rho` |
//! | E14 | section IV: "2 degrees of freedom" | the planar body has 3 (x, y, θ) | notation |
//!
//! Also shown: position and velocity are unobservable from θ (`position_and_velocity_are_unobservable_from_attitude`);
//! the paper's CKF Jacobian Ψ is not the model's Jacobian (`paper_ckf_jacobian_drops_attitude_velocity_coupling`).
//!
//! ## Consistency (estim's toolkit)
//!
//! `cargo run --release --example consistency` runs section IV (the reading above) on estim's
//! Monte Carlo runner: 1000 runs (200 with `--quick`), 40 slots every 0.5 s from 0.5 s to 20 s
//! (after the attitude update, and for CKF+OTE after the OTE correction), attitude NIS,
//! residual pair 10 s × 20 s; each check at 99 % (Simes).
//!
//! - **CKF: not consistent.** Mean error, ensemble/filter variance ratio and average NEES fail
//!   (p-values 0). The NEES (band \[5.72, 6.29\]) starts far *below* the band (0.07 at 0.5 s,
//!   1.3 at 2 s: the CKF starts at the true D(0) with P(0) = diag(1, 1, 0.1, 0.1, …), and
//!   position and velocity are unobservable from θ, so that P never shrinks) and then
//!   explodes (63 at 5 s, 1548 at 10 s, 1.9·10⁴ at 20 s): the unobservable position/velocity
//!   error grows without bound — the unmodelled bias (½ b t²) and the attitude-driven error of
//!   the diagnostics below — while P only grows with the white input noise. The attitude NIS and the
//!   residual correlation pass: the θ channel itself is consistent.
//! - **CKF+OTE: not consistent**, worse: NEES 5.2 at 0.5 s, 1025 at 5 s, 3·10⁵ at 20 s; the OTE
//!   overwrites the velocity without touching P.
//! - Diagnostics (not the paper's) separating the causes: without the 10 mg bias and with
//!   D̂(0) − D(0) ~ N(0, P(0)), the CKF **still** fails (NEES 16 at 2 s, 2.3·10⁴ at 20 s; the
//!   mean-error check then passes). Its Jacobian Ψ drops the attitude → velocity coupling:
//!   the attitude error (≈ 1°) turns the 2 g specific force into a cross-track acceleration
//!   error (≈ 0.34 m/s², 3.5 × the bias) that P does not carry — the ensemble position errors
//!   are correlated ≈ −0.99 between x and y where the CKF's P has 0. The full-Jacobian EKF on
//!   the same data passes the mean-error and variance-ratio checks, but its NEES still leaves
//!   the band after ≈ 5 s (12 at 10 s, 48 at 20 s): its P is nearly singular (condition
//!   number ≈ 2·10⁹ at 20 s, position, velocity and attitude correlated up to 0.99), and the
//!   small differences between the ensemble's correlations and P's put the joint error
//!   outside that thin ellipsoid.
//! - All of them fail *error ⟂ estimate* by construction: the truth is one fixed trajectory
//!   (x̂ = x − e with x fixed), which that check does not allow for.

pub mod likelihood;
pub mod model;
pub mod ote;
pub mod sensors;
#[cfg(feature = "std")]
pub mod simulation;

pub use likelihood::{LikelihoodForm, VelocityLikelihood, velocity_likelihood_as_printed};
pub use model::{
    AttitudeMeasurement, CkfInput, CkfProcess, Discretization, InsProcess, Plane, STANDARD_GRAVITY,
    input_matrix, transition_matrix, wrap_angle,
};
pub use ote::{OteSettings, OteSteadyState, OteStep, OwnShipTrajectoryEstimator, ote_steady_state};
pub use sensors::{FourAccelerometers, RigidBodyMotion, rotation};
#[cfg(feature = "std")]
pub use simulation::{Scenario, SensorConfig, SensorSample, Simulation, simulate};
