//! Seeded simulator: the true planar motion, the four accelerometer signals, the derived inputs
//! and the attitude measurement.
//!
//! The truth is a rigid body with constant body-frame specific force f_b and constant angular
//! rate ω (ω̇ = 0), integrated in closed form (φ = ω t, J = \[\[0, −1\], \[1, 0\]\]):
//!
//! ```text
//! θ(t) = θ₀ + ω t
//! v(t) = v₀ + g_vec t + R(θ₀) [I sin φ/ω + J (1 − cos φ)/ω] f_b
//! p(t) = p₀ + v₀ t + ½ g_vec t² + R(θ₀) [I (1 − cos φ)/ω² + J (φ − sin φ)/ω²] f_b
//! ```
//!
//! (series expansions for |φ| < 10⁻²; ω = 0 gives constant acceleration R(θ₀) f_b + g_vec).
//! At every sample t_k = k T the sensors give
//!
//! ```text
//! A_k = A(motion(t_k)) + b_A                       four signals, forward model of appendix B
//! u_k = (y_ax, y_ay, y_ω̇)(A_k) + W_k,  W_k ~ N(0, diag σ_W²)   eq 17–19 (δ terms after combining)
//! E_k = wrap(θ(t_k) + ε_k),  ε_k ~ N(0, σ_ε²)                   eq 21
//! ```
//!
//! The per-sensor bias b_A is the minimum-norm one that gives the requested derived-input bias
//! ([`FourAccelerometers::sensor_bias_for`]).

use nalgebra::{Matrix2, Vector2, Vector3, Vector4, Vector6};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use super::model::{Plane, STANDARD_GRAVITY, wrap_angle};
use super::sensors::{FourAccelerometers, RigidBodyMotion, rotation};

/// A rigid-body trajectory with constant body-frame specific force and angular rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scenario {
    /// D(0) = (x, y, v_x, v_y, θ, ω) \[m, m, m/s, m/s, rad, rad/s\].
    pub initial_state: Vector6<f64>,
    /// f_b: body-frame specific force at the centre of gravity \[m/s²\], constant.
    pub specific_force: Vector2<f64>,
    /// Plane of motion (gravity).
    pub plane: Plane,
}

impl Scenario {
    /// Section IV as printed: x(0) = 10 m, y(0) = 5 m, v_x(0) = v_y(0) = 2 m/s, θ ≡ 30°,
    /// ω ≡ 0, 2 g along body x, horizontal plane (estim's reading of E4).
    pub fn section_iv() -> Self {
        Self {
            initial_state: Vector6::new(10.0, 5.0, 2.0, 2.0, 30f64.to_radians(), 0.0),
            specific_force: Vector2::new(2.0 * STANDARD_GRAVITY, 0.0),
            plane: Plane::Horizontal,
        }
    }

    /// estim's radial-consistent reading of section IV (not the paper's): position and velocity
    /// start along the 30° body axis, p(0) = 10 m (cos 30°, sin 30°), v(0) = 2 m/s (cos 30°,
    /// sin 30°), so the flight is radial — the geometry the OTE pseudo-measurement assumes
    /// (erratum E10).
    pub fn radial() -> Self {
        let (s, c) = 30f64.to_radians().sin_cos();
        Self {
            initial_state: Vector6::new(
                10.0 * c,
                10.0 * s,
                2.0 * c,
                2.0 * s,
                30f64.to_radians(),
                0.0,
            ),
            ..Self::section_iv()
        }
    }

    /// The true state D(t).
    pub fn state_at(&self, t: f64) -> Vector6<f64> {
        let d0 = &self.initial_state;
        let (theta0, w) = (d0[4], d0[5]);
        let phi = w * t;
        // ∫₀ᵗ R(ωs) ds = I c1 + J s1 and its integral I c2 + J s2.
        let (c1, s1, c2, s2) = if phi.abs() < 1e-2 {
            let x2 = phi * phi;
            (
                t * (1.0 - x2 / 6.0 + x2 * x2 / 120.0),
                t * (phi / 2.0 - phi * x2 / 24.0 + phi * x2 * x2 / 720.0),
                t * t * (0.5 - x2 / 24.0 + x2 * x2 / 720.0),
                t * t * (phi / 6.0 - phi * x2 / 120.0 + phi * x2 * x2 / 5040.0),
            )
        } else {
            let (s, c) = phi.sin_cos();
            (
                s / w,
                (1.0 - c) / w,
                (1.0 - c) / (w * w),
                (phi - s) / (w * w),
            )
        };
        let j = Matrix2::new(0.0, -1.0, 1.0, 0.0);
        let r0 = rotation(theta0);
        let g = self.plane.gravity();
        let p0 = Vector2::new(d0[0], d0[1]);
        let v0 = Vector2::new(d0[2], d0[3]);
        let v = v0 + g * t + r0 * (Matrix2::identity() * c1 + j * s1) * self.specific_force;
        let p = p0
            + v0 * t
            + g * (0.5 * t * t)
            + r0 * (Matrix2::identity() * c2 + j * s2) * self.specific_force;
        Vector6::new(p.x, p.y, v.x, v.y, theta0 + phi, w)
    }

    /// The rigid-body motion at t, as the accelerometers see it.
    pub fn motion_at(&self, t: f64) -> RigidBodyMotion {
        let d = self.state_at(t);
        RigidBodyMotion {
            attitude: d[4],
            rate: d[5],
            angular_acceleration: 0.0,
            acceleration: rotation(d[4]) * self.specific_force + self.plane.gravity(),
        }
    }
}

/// Sensor settings of a simulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorConfig {
    /// Sample period T \[s\] (inputs and attitude measurement at every sample).
    pub dt: f64,
    /// Number of steps (samples 0..=steps are produced).
    pub steps: usize,
    /// The accelerometer array.
    pub accelerometers: FourAccelerometers,
    /// Bias of the derived inputs (b_x, b_y, b_ω̇) \[m/s², m/s², rad/s²\].
    pub input_bias: Vector3<f64>,
    /// σ_W of the white input errors (δa_x, δa_y, δω̇) per sample.
    pub input_noise_std: Vector3<f64>,
    /// σ_ε of the attitude measurement \[rad\].
    pub attitude_std: f64,
}

/// One sample of sensor data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorSample {
    /// t_k \[s\].
    pub time: f64,
    /// The four accelerometer outputs A₁…A₄ (with bias, before the input noise) \[m/s²\].
    pub signals: Vector4<f64>,
    /// u_k = derived inputs + W_k (what the filter uses).
    pub inputs: Vector3<f64>,
    /// E_k: the attitude measurement \[rad\], wrapped into (−π, π].
    pub attitude: f64,
}

/// A simulated run.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    /// True states D(t_k), k = 0..=steps.
    pub truth: Vec<Vector6<f64>>,
    /// Sensor samples at t_k, k = 0..=steps.
    pub samples: Vec<SensorSample>,
}

/// Simulates `scenario` with `config`; the same seed gives the same data.
///
/// Errors, checked before anything is allocated: Δt not finite and > 0
/// ([`Parameter::StepSize`](estim_core::Parameter)), more than
/// [`MAX_STEPS`](crate::limits::MAX_STEPS) steps ([`Parameter::StepCount`](estim_core::Parameter);
/// the stored run then stays under 1.2 GB).
///
/// ```
/// use estim_models::lee_huang::{FourAccelerometers, Scenario, SensorConfig, simulate};
/// use estim_core::nalgebra::Vector3;
/// let config = SensorConfig {
///     dt: 0.01,
///     steps: 100,
///     accelerometers: FourAccelerometers::default(),
///     input_bias: Vector3::zeros(),
///     input_noise_std: Vector3::zeros(),
///     attitude_std: 0.01,
/// };
/// assert_eq!(simulate(&Scenario::section_iv(), &config, 1)?.samples.len(), 101);
/// let endless = SensorConfig { steps: usize::MAX, ..config };
/// assert!(simulate(&Scenario::section_iv(), &endless, 1).is_err());
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn simulate(
    scenario: &Scenario,
    config: &SensorConfig,
    seed: u64,
) -> Result<Simulation, estim_core::Error> {
    crate::limits::check_period(config.dt, estim_core::Parameter::StepSize)?;
    crate::limits::check_steps(config.steps)?;
    let mut rng = StdRng::seed_from_u64(seed);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let gravity = scenario.plane.gravity();
    let sensor_bias = config.accelerometers.sensor_bias_for(&config.input_bias);
    let mut truth = Vec::with_capacity(config.steps + 1);
    let mut samples = Vec::with_capacity(config.steps + 1);
    for k in 0..=config.steps {
        let t = k as f64 * config.dt;
        let state = scenario.state_at(t);
        let signals = config
            .accelerometers
            .signals(&scenario.motion_at(t), &gravity)
            + sensor_bias;
        let noise =
            Vector3::new(normal(), normal(), normal()).component_mul(&config.input_noise_std);
        let inputs = config.accelerometers.derived_inputs(&signals) + noise;
        let attitude = wrap_angle(state[4] + config.attitude_std * normal());
        truth.push(state);
        samples.push(SensorSample {
            time: t,
            signals,
            inputs,
            attitude,
        });
    }
    Ok(Simulation { truth, samples })
}
