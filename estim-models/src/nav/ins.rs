//! The strapdown mechanisation as a process model on the 15-state error state, with its
//! Jacobian on the attitude manifold.

use estim_core::manifold::{AttitudeError, so3_exp, so3_log};
use estim_core::nalgebra::{Const, Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};
use estim_core::{ProcessJacobian, ProcessModel};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

use super::earth::{NavError, Origin};

/// The state dimension.
pub const STATE: usize = 15;
/// First index of the attitude block θ.
pub const ATTITUDE: usize = 0;
/// First index of the NED velocity.
pub const VELOCITY: usize = 3;
/// First index of the NED position.
pub const POSITION: usize = 6;
/// First index of the gyro bias.
pub const GYRO_BIAS: usize = 9;
/// First index of the accelerometer bias.
pub const ACCEL_BIAS: usize = 12;

type State = SVector<f64, STATE>;
type Square = SMatrix<f64, STATE, STATE>;

/// The filter's state space: the attitude block on the quaternion manifold, the rest plain.
pub fn state_space() -> AttitudeError {
    AttitudeError::at(ATTITUDE)
}

/// The attitude q = Exp(θ) (body → NED) of a state.
pub fn attitude(x: &State) -> UnitQuaternion<f64> {
    so3_exp(&x.fixed_rows::<3>(ATTITUDE).into_owned())
}

/// One IMU sample, the mean over the interval it covers: body rate \[rad/s\] and specific
/// force \[m/s²\], body frame FRD (at rest, level: f ≈ (0, 0, −g)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Imu {
    /// ω̃ \[rad/s\].
    pub gyro: Vector3<f64>,
    /// f̃ \[m/s²\].
    pub accel: Vector3<f64>,
}

/// The noise densities and the options of the mechanisation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InsSettings {
    /// Gyro white noise (angle random walk) \[rad/s/√Hz\].
    pub gyro_noise: f64,
    /// Accelerometer white noise (velocity random walk) \[m/s²/√Hz\].
    pub accel_noise: f64,
    /// Gyro bias random walk \[rad/s²/√Hz\].
    pub gyro_bias_walk: f64,
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub accel_bias_walk: f64,
    /// Include the earth rate ω_ie (attitude and Coriolis).
    pub earth_rate: bool,
    /// Include the transport rate ω_en (attitude and Coriolis).
    pub transport_rate: bool,
}

impl Default for InsSettings {
    /// A MEMS IMU, set generously: 0.015 rad/s/√Hz, 0.35 m/s²/√Hz (the values of ArduPilot's
    /// EKF3 defaults, which EKF3 uses as per-step σ, a density of σ √Δt: 0.0021 and 0.049 at
    /// 50 Hz), bias walks 10⁻⁴ rad/s²/√Hz and 10⁻³ m/s³/√Hz; earth and transport rates off
    /// (below a MEMS gyro's noise).
    fn default() -> Self {
        Self {
            gyro_noise: 0.015,
            accel_noise: 0.35,
            gyro_bias_walk: 1e-4,
            accel_bias_walk: 1e-3,
            earth_rate: false,
            transport_rate: false,
        }
    }
}

/// The strapdown mechanisation about an [`Origin`] (see the [module docs](super)): a
/// [`ProcessModel`] whose input is an [`Imu`] sample, with its [`ProcessJacobian`] on the
/// attitude manifold.
///
/// ```
/// use estim_core::nalgebra::{SVector, Vector3};
/// use estim_core::ProcessModel;
/// use estim_models::nav::{Imu, InsSettings, Origin, Strapdown, VELOCITY};
///
/// let origin = Origin::from_degrees(51.6, -2.5, 60.0)?;
/// let ins = Strapdown::new(origin, InsSettings::default())?;
/// // Level and at rest: the accelerometer cancels gravity, nothing moves.
/// let imu = Imu { gyro: Vector3::zeros(), accel: Vector3::new(0.0, 0.0, -origin.gravity(0.0)) };
/// let x = ins.transition(&SVector::<f64, 15>::zeros(), &imu, 0.02);
/// assert!(x.fixed_rows::<3>(VELOCITY).norm() < 1e-15);
/// # Ok::<(), estim_models::nav::NavError>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Strapdown {
    origin: Origin,
    settings: InsSettings,
    /// ω_ie in NED (zero when off).
    earth: Vector3<f64>,
    /// ω_en = A v (A zero when off).
    transport: Matrix3<f64>,
}

/// The intermediate quantities of one step, shared by the transition and its Jacobian.
struct Step {
    q: UnitQuaternion<f64>,
    q_next: UnitQuaternion<f64>,
    phi: Vector3<f64>,
    f: Vector3<f64>,
    /// R(Exp(−ω_in Δt/2) ⊗ q ⊗ Exp(φ/2)): the body at mid-step in the navigation frame at
    /// mid-step.
    r_mid: Matrix3<f64>,
    /// R(Exp(−ω_in Δt/2)).
    nav_half: Matrix3<f64>,
    /// ω_in.
    nav_rate: Vector3<f64>,
    /// 2 ω_ie + ω_en.
    coriolis: Vector3<f64>,
    v_next: Vector3<f64>,
}

impl Strapdown {
    /// The mechanisation about `origin` with `settings`.
    ///
    /// Errors: [`NavError::NonFinite`] for a non-finite or negative noise density.
    pub fn new(origin: Origin, settings: InsSettings) -> Result<Self, NavError> {
        for (value, what) in [
            (settings.gyro_noise, "gyro noise"),
            (settings.accel_noise, "accelerometer noise"),
            (settings.gyro_bias_walk, "gyro bias walk"),
            (settings.accel_bias_walk, "accelerometer bias walk"),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(NavError::NonFinite(what));
            }
        }
        let earth = if settings.earth_rate {
            origin.earth_rate()
        } else {
            Vector3::zeros()
        };
        let transport = if settings.transport_rate {
            let (rm, rn) = origin.radii();
            let (rm, rn) = (rm + origin.height(), rn + origin.height());
            let tan = origin.latitude().tan();
            Matrix3::new(0.0, 1.0 / rn, 0.0, -1.0 / rm, 0.0, 0.0, 0.0, -tan / rn, 0.0)
        } else {
            Matrix3::zeros()
        };
        Ok(Self {
            origin,
            settings,
            earth,
            transport,
        })
    }

    /// The origin.
    pub fn origin(&self) -> &Origin {
        &self.origin
    }

    /// The settings.
    pub fn settings(&self) -> &InsSettings {
        &self.settings
    }

    fn step(&self, x: &State, imu: &Imu, dt: f64) -> Step {
        let q = attitude(x);
        let v = x.fixed_rows::<3>(VELOCITY).into_owned();
        let phi = (imu.gyro - x.fixed_rows::<3>(GYRO_BIAS)) * dt;
        let f = imu.accel - x.fixed_rows::<3>(ACCEL_BIAS);
        let transport = self.transport * v;
        let nav_rate = self.earth + transport;
        let coriolis = self.earth * 2.0 + transport;
        let mut q_next = so3_exp(&(-nav_rate * dt)) * q * so3_exp(&phi);
        q_next.renormalize();
        let nav_half = so3_exp(&(-nav_rate * (0.5 * dt)))
            .to_rotation_matrix()
            .into_inner();
        let r_mid = nav_half
            * (q * so3_exp(&(phi * 0.5)))
                .to_rotation_matrix()
                .into_inner();
        let gravity = Vector3::new(0.0, 0.0, self.origin.gravity(x[POSITION + 2]));
        let v_next = v + (r_mid * f - coriolis.cross(&v) + gravity) * dt;
        Step {
            q,
            q_next,
            phi,
            f,
            r_mid,
            nav_half,
            nav_rate,
            coriolis,
            v_next,
        }
    }
}

/// J_r(φ) = I − (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×², the right Jacobian of SO(3)
/// (series below θ = 10⁻⁴, where the next terms are below 10⁻¹⁷).
fn right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = phi.norm_squared();
    let k = phi.cross_matrix();
    let (a, b) = if t2 < 1e-8 {
        (0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        let t = t2.sqrt();
        ((1.0 - t.cos()) / t2, (t - t.sin()) / (t2 * t))
    };
    Matrix3::identity() - k * a + k * k * b
}

impl ProcessModel<f64, Const<STATE>> for Strapdown {
    type Input = Imu;

    /// One step of the mechanisation (see the [module docs](super)).
    fn transition(&self, x: &State, imu: &Imu, dt: f64) -> State {
        let s = self.step(x, imu, dt);
        let mut out = *x;
        out.fixed_rows_mut::<3>(ATTITUDE)
            .copy_from(&so3_log(&s.q_next));
        let v = x.fixed_rows::<3>(VELOCITY).into_owned();
        out.fixed_rows_mut::<3>(POSITION)
            .copy_from(&(x.fixed_rows::<3>(POSITION) + (v + s.v_next) * (0.5 * dt)));
        out.fixed_rows_mut::<3>(VELOCITY).copy_from(&s.v_next);
        out
    }

    /// Q for white gyro and accelerometer noise over Δt: σ_g² Δt on the attitude error,
    /// σ_a² [Δt³/3, Δt²/2; Δt²/2, Δt] on (position, velocity) per axis (the accelerometer
    /// noise is isotropic, so rotating it to NED changes nothing), σ² Δt on the biases.
    fn process_noise(&self, _: &State, _: &Imu, dt: f64) -> Square {
        let s = &self.settings;
        let mut q = Square::zeros();
        let a2 = s.accel_noise * s.accel_noise;
        for i in 0..3 {
            q[(ATTITUDE + i, ATTITUDE + i)] = s.gyro_noise * s.gyro_noise * dt;
            q[(VELOCITY + i, VELOCITY + i)] = a2 * dt;
            q[(POSITION + i, POSITION + i)] = a2 * dt * dt * dt / 3.0;
            q[(POSITION + i, VELOCITY + i)] = a2 * dt * dt / 2.0;
            q[(VELOCITY + i, POSITION + i)] = a2 * dt * dt / 2.0;
            q[(GYRO_BIAS + i, GYRO_BIAS + i)] = s.gyro_bias_walk * s.gyro_bias_walk * dt;
            q[(ACCEL_BIAS + i, ACCEL_BIAS + i)] = s.accel_bias_walk * s.accel_bias_walk * dt;
        }
        q
    }
}

impl ProcessJacobian<f64, Const<STATE>> for Strapdown {
    /// F = ∂(f(x ⊞ δ) ⊟ f(x))/∂δ at δ = 0, exactly (δθ the body-frame attitude error):
    ///
    /// ```text
    /// δθ⁺ = Exp(φ)ᵀ δθ − J_r(φ) Δt δb_g − R(q⁺)ᵀ J_r(ω_in Δt) A Δt δv
    /// δv⁺ = δv + Δt (−E R(q)[R(Exp(φ/2)) f]× δθ + ½ R_mid [f]× J_r(φ/2) Δt δb_g − R_mid δb_a
    ///                − ([2ω_ie + ω_en]× − [v]× A − ½ Δt E [w]× J_r(−ω_in Δt/2) A) δv
    ///                − γ'(h) e_D δp_D)
    /// δp⁺ = δp + (δv + δv⁺) Δt / 2
    /// ```
    ///
    /// (A the transport-rate matrix ω_en = A v, zero when off; γ' the free-air gradient;
    /// E = R(Exp(−ω_in Δt/2)) and w = R(q ⊗ Exp(φ/2)) f, so R_mid f = E w.)
    fn transition_jacobian(&self, x: &State, imu: &Imu, dt: f64) -> Square {
        let s = self.step(x, imu, dt);
        let v = x.fixed_rows::<3>(VELOCITY).into_owned();
        let mut fm = Square::identity();
        let b = so3_exp(&s.phi).to_rotation_matrix().into_inner();
        let r_next = s.q_next.to_rotation_matrix().into_inner();
        let rq = s.q.to_rotation_matrix().into_inner();
        let half = so3_exp(&(s.phi * 0.5)).to_rotation_matrix().into_inner();
        // Attitude.
        let dtheta_dv =
            -(r_next.transpose() * right_jacobian(&(s.nav_rate * dt)) * self.transport) * dt;
        fm.fixed_view_mut::<3, 3>(ATTITUDE, ATTITUDE)
            .copy_from(&b.transpose());
        fm.fixed_view_mut::<3, 3>(ATTITUDE, GYRO_BIAS)
            .copy_from(&(-right_jacobian(&s.phi) * dt));
        fm.fixed_view_mut::<3, 3>(ATTITUDE, VELOCITY)
            .copy_from(&dtheta_dv);
        // Velocity: ∂a/∂· for a the acceleration of the step.
        let body_mid = rq * (half * s.f);
        let da_dtheta = -(s.nav_half * rq * (half * s.f).cross_matrix());
        let da_dbg = s.r_mid * s.f.cross_matrix() * right_jacobian(&(s.phi * 0.5)) * (0.5 * dt);
        let da_dba = -s.r_mid;
        // ω_in = ω_ie + A v also turns the mid-step navigation frame E = Exp(−ω_in Δt/2):
        // E Exp(J_r(−ω_in Δt/2) (−A δv Δt/2)) w ≈ E w + E [w]× J_r(−ω_in Δt/2) A δv Δt/2.
        let da_dv = -(s.coriolis.cross_matrix() - v.cross_matrix() * self.transport)
            + s.nav_half
                * body_mid.cross_matrix()
                * right_jacobian(&(-s.nav_rate * (0.5 * dt)))
                * self.transport
                * (0.5 * dt);
        let mut da_dp = Matrix3::zeros();
        da_dp[(2, 2)] = -crate::nav::normal_gravity_gradient(
            self.origin.latitude(),
            self.origin.height() - x[POSITION + 2],
        );
        let mut dv = SMatrix::<f64, 3, STATE>::zeros();
        dv.fixed_view_mut::<3, 3>(0, ATTITUDE)
            .copy_from(&(da_dtheta * dt));
        dv.fixed_view_mut::<3, 3>(0, VELOCITY)
            .copy_from(&(Matrix3::identity() + da_dv * dt));
        dv.fixed_view_mut::<3, 3>(0, POSITION)
            .copy_from(&(da_dp * dt));
        dv.fixed_view_mut::<3, 3>(0, GYRO_BIAS)
            .copy_from(&(da_dbg * dt));
        dv.fixed_view_mut::<3, 3>(0, ACCEL_BIAS)
            .copy_from(&(da_dba * dt));
        fm.fixed_view_mut::<3, STATE>(VELOCITY, 0).copy_from(&dv);
        // Position: p⁺ = p + (v + v⁺) Δt/2.
        let mut dp = dv * (0.5 * dt);
        for i in 0..3 {
            dp[(i, POSITION + i)] += 1.0;
            dp[(i, VELOCITY + i)] += 0.5 * dt;
        }
        fm.fixed_view_mut::<3, STATE>(POSITION, 0).copy_from(&dp);
        fm
    }
}
