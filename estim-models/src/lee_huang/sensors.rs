//! The planar four-accelerometer configuration of appendix B (eq 58–62), sign-corrected.
//!
//! Four single-axis accelerometers sit at body positions ρ lᵢ with sensing directions βᵢ
//! (body frame, eq 58/59):
//!
//! ```text
//! l = [(0, −1), (1, 0), (0, 1), (−1, 0)]      β = [(1, 0), (0, 1), (−1, 0), (0, −1)]
//! ```
//!
//! so βᵢ = ẑ × lᵢ: every sensor is tangential. The specific force at sensor i is the rigid-body
//! acceleration of its point minus gravity, projected on its inertial sensing direction:
//!
//! ```text
//! Aᵢ = (a + ω̇ ẑ × rᵢ − ω² rᵢ − g_vec) · R(θ) βᵢ,     rᵢ = R(θ) ρ lᵢ
//!    = f_b · βᵢ + ρ ω̇                                  (−ω² rᵢ ⟂ βᵢ drops out)
//! ```
//!
//! with the body-frame specific force at the centre of gravity f_b = R(θ)ᵀ (a − g_vec). The
//! derived inputs of eq 17–19 (eq 61/62), with the sign of y_ay corrected (erratum E1) and the
//! 1/ρ of y_ω̇ restored (E13):
//!
//! ```text
//! y_ax = (A₁ − A₃)/2 = f_bx,   y_ay = (A₂ − A₄)/2 = f_by,   y_ω̇ = (A₁ + A₂ + A₃ + A₄)/(4ρ) = ω̇
//! ```

use nalgebra::{Matrix2, Vector2, Vector3, Vector4};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// Rotation from the body frame to the inertial frame, R(θ) = \[\[cos θ, −sin θ\], \[sin θ, cos θ\]\]
/// (counter-clockwise, as in eq 16c/d).
pub fn rotation(theta: f64) -> Matrix2<f64> {
    let (s, c) = theta.sin_cos();
    Matrix2::new(c, -s, s, c)
}

/// The planar rigid-body motion at one instant, as the accelerometers see it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidBodyMotion {
    /// Attitude θ of the body x axis from the inertial x axis \[rad\].
    pub attitude: f64,
    /// Angular rate ω = θ̇ \[rad/s\].
    pub rate: f64,
    /// Angular acceleration ω̇ \[rad/s²\].
    pub angular_acceleration: f64,
    /// Inertial acceleration of the centre of gravity a = (ẍ, ÿ) \[m/s²\].
    pub acceleration: Vector2<f64>,
}

impl RigidBodyMotion {
    /// The body-frame specific force at the centre of gravity, f_b = R(θ)ᵀ (a − g_vec), for the
    /// gravitational acceleration `gravity` = g_vec in the inertial frame (zero in the
    /// horizontal plane).
    pub fn body_specific_force(&self, gravity: &Vector2<f64>) -> Vector2<f64> {
        rotation(self.attitude).transpose() * (self.acceleration - gravity)
    }
}

/// The four tangential accelerometers of appendix B on a circle of radius ρ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FourAccelerometers {
    /// Lever arm ρ \[m\] (> 0; the paper uses ρ = 1).
    pub radius: f64,
}

impl Default for FourAccelerometers {
    /// ρ = 1 m, as in the paper.
    fn default() -> Self {
        Self { radius: 1.0 }
    }
}

/// Unit locations lᵢ (eq 58, columns).
const LOCATIONS: [[f64; 2]; 4] = [[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]];
/// Sensing directions βᵢ (eq 59, columns).
const DIRECTIONS: [[f64; 2]; 4] = [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]];

impl FourAccelerometers {
    /// Body-frame sensor positions ρ lᵢ (eq 58) \[m\].
    pub fn locations(&self) -> [Vector2<f64>; 4] {
        LOCATIONS.map(|l| Vector2::new(l[0], l[1]) * self.radius)
    }

    /// Body-frame sensing directions βᵢ (eq 59), unit vectors.
    pub fn directions(&self) -> [Vector2<f64>; 4] {
        DIRECTIONS.map(|b| Vector2::new(b[0], b[1]))
    }

    /// The forward model: the four noise-free accelerometer outputs Aᵢ \[m/s²\] for the rigid-body
    /// `motion` under gravity `gravity` (inertial g_vec; zero in the horizontal plane).
    ///
    /// Computed from the full rigid-body acceleration of each sensor point (eq 1 with the
    /// tangential and centripetal terms, no shortcut), so that [`derived_inputs`](Self::derived_inputs)
    /// can be checked against it.
    pub fn signals(&self, motion: &RigidBodyMotion, gravity: &Vector2<f64>) -> Vector4<f64> {
        let r = rotation(motion.attitude);
        let (w, wdot) = (motion.rate, motion.angular_acceleration);
        let mut out = Vector4::zeros();
        for (i, (l, beta)) in self
            .locations()
            .iter()
            .zip(self.directions().iter())
            .enumerate()
        {
            let ri = r * l;
            // ω̇ ẑ × r = ω̇ (−r_y, r_x); ω × (ω × r) = −ω² r in the plane.
            let tangential = Vector2::new(-ri.y, ri.x) * wdot;
            let centripetal = -ri * (w * w);
            let specific_force = motion.acceleration + tangential + centripetal - gravity;
            out[i] = specific_force.dot(&(r * beta));
        }
        out
    }

    /// The inversion (eq 17–19 / 61–62, corrected): (y_ax, y_ay, y_ω̇) = (f_bx, f_by, ω̇) from
    /// the four outputs.
    pub fn derived_inputs(&self, a: &Vector4<f64>) -> Vector3<f64> {
        Vector3::new(
            0.5 * (a[0] - a[2]),
            0.5 * (a[1] - a[3]),
            (a[0] + a[1] + a[2] + a[3]) / (4.0 * self.radius),
        )
    }

    /// The inversion as printed (eq 18/62: y_ay = −(A₂ − A₄)/2; eq 19/61 without 1/ρ). Kept to
    /// show erratum E1: with the printed l, β it returns −f_by.
    pub fn derived_inputs_as_printed(&self, a: &Vector4<f64>) -> Vector3<f64> {
        Vector3::new(
            0.5 * (a[0] - a[2]),
            -0.5 * (a[1] - a[3]),
            0.25 * (a[0] + a[1] + a[2] + a[3]),
        )
    }

    /// Per-sensor biases that produce the derived-input bias `input_bias` = (b_x, b_y, b_ω̇)
    /// through [`derived_inputs`](Self::derived_inputs): the minimum-norm solution
    /// (b_x + ρb_ω̇, b_y + ρb_ω̇, −b_x + ρb_ω̇, −b_y + ρb_ω̇). A bias common to all four sensors
    /// would cancel in y_ax, y_ay and appear only in y_ω̇.
    pub fn sensor_bias_for(&self, input_bias: &Vector3<f64>) -> Vector4<f64> {
        let c = self.radius * input_bias.z;
        Vector4::new(
            input_bias.x + c,
            input_bias.y + c,
            -input_bias.x + c,
            -input_bias.y + c,
        )
    }
}
