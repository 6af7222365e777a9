//! # A strapdown INS model set: GPS/INS in a local-level NED frame
//!
//! An error-state navigation filter for a vehicle with an IMU (gyroscopes and accelerometers,
//! body frame FRD), GNSS position and velocity, a barometer and a magnetometer, as estim
//! models: the filters, the fusion driver and the derivative checks take them unchanged.
//!
//! ## State (15, static size)
//!
//! | index | block | unit |
//! |---|---|---|
//! | 0..3 | θ, the rotation vector of the attitude q = Exp(θ), body → NED | rad |
//! | 3..6 | v, the velocity in NED | m/s |
//! | 6..9 | p, the position in NED about the [`Origin`] | m |
//! | 9..12 | b_g, the gyro bias | rad/s |
//! | 12..15 | b_a, the accelerometer bias | m/s² |
//!
//! Give the filter the state space [`state_space`] (an
//! [`AttitudeError`](estim_core::manifold::AttitudeError) on the first block): its ⊞ composes
//! rotations on the right, q ⊞ δθ = q ⊗ Exp(δθ), so the covariance of the first block is that
//! of the **body-frame attitude error** on the quaternion manifold (the multiplicative EKF),
//! and every Jacobian here is the one on that manifold. The attitude lives in the filter's
//! own state (no reference beside it), so the fusion driver's rollback and replay restore it
//! with everything else.
//!
//! ## Mechanisation ([`Strapdown`])
//!
//! With ω̃, f̃ the IMU sample over (t, t + Δt] ([`Imu`]; the fusion driver's
//! `InputConvention::Preceding`), φ = (ω̃ − b_g) Δt and f = f̃ − b_a:
//!
//! ```text
//! q⁺ = Exp(−ω_in Δt) ⊗ q ⊗ Exp(φ)                 ω_in = ω_ie + ω_en
//! v⁺ = v + (R(Exp(−ω_in Δt/2) ⊗ q ⊗ Exp(φ/2)) f − (2ω_ie + ω_en) × v + (0, 0, γ(h₀ − p_D))) Δt
//! p⁺ = p + (v + v⁺) Δt / 2
//! ```
//!
//! The specific force is rotated with the attitude at mid-step, both the body's half turn φ/2
//! and the navigation frame's −ω_in Δt/2: without the second, a vehicle at rest on the
//! rotating earth would see a horizontal force error of γ |ω_ie × e_D| Δt/2 (4·10⁻⁶ m/s² at
//! 50 Hz and 52° N).
//!
//! ω_ie = Ω (cos φ₀, 0, −sin φ₀) the earth rate and ω_en = (v_E/(R_N+h₀), −v_N/(R_M+h₀),
//! −v_E tan φ₀/(R_N+h₀)) the transport rate, each optional ([`InsSettings`]), evaluated at the
//! origin (latitude φ₀, height h₀): the frame is the local level at the origin, valid over
//! ranges of a few km (ranges ≪ the earth's radius). γ is the WGS-84 normal gravity
//! ([`normal_gravity`]).
//!
//! ## Sensors
//!
//! [`GnssPosition`] (p), [`GnssVelocity`] (v), [`BaroHeight`] (−p_D), [`Magnetometer`]
//! (R(q)ᵀ m, the earth field m in NED), [`Heading`] (the yaw of q). [`static_alignment`] gives
//! the initial attitude from the mean accelerometer and magnetometer readings at rest.
//!
//! ## Geodesy
//!
//! Geodetic ↔ local NED comes from the `map_3d` crate ([`Origin::ned`]); normal gravity is the
//! Somigliana formula with the WGS-84 constants (no maintained crate provides it).

mod alignment;
mod earth;
mod ins;
mod sensors;

pub use alignment::static_alignment;
pub use earth::{EARTH_RATE, NavError, Origin, normal_gravity, normal_gravity_gradient};
pub use ins::{
    ACCEL_BIAS, ATTITUDE, GYRO_BIAS, Imu, InsSettings, POSITION, STATE, Strapdown, VELOCITY,
    attitude, state_space,
};
pub use sensors::{BaroHeight, GnssPosition, GnssVelocity, Heading, Magnetometer};
