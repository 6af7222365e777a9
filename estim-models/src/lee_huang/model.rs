//! The 6-state planar INS of eq 15–21 driven by the accelerometer-derived inputs, and its
//! attitude measurement.
//!
//! State D = (x, y, v_x, v_y, θ, ω), input u = (y_ax, y_ay, y_ω̇). Continuous model (eq 16, with
//! an optional gravity term, see [`Plane`]):
//!
//! ```text
//! ẋ = v_x,  ẏ = v_y,  (v̇_x, v̇_y) = R(θ) (y_ax, y_ay) + g_vec,  θ̇ = ω,  ω̇ = y_ω̇
//! ```
//!
//! Discretised over a step T with θ frozen at its value at the start of the step (the paper
//! does the same: G is evaluated at θ̂), f(D, u) = Ψ D + G_d(θ) u + c, Ψ = I + F T (exact, F² = 0):
//!
//! ```text
//! zero-order hold:  G_d rows  x: (T²/2)[c, −s, 0]  y: (T²/2)[s, c, 0]  v_x: T[c, −s, 0]
//!                             v_y: T[s, c, 0]      θ: [0, 0, T²/2]     ω: [0, 0, T]
//!                   c = (T²/2 g_vec, T g_vec, 0, 0)
//! Euler (eq 33):    G_d = G T (no position or θ rows), c = (0, T g_vec, 0, 0)
//! ```
//!
//! The input noise W (per-sample covariance Σ_W, eq 17–19's δ terms) enters like the input, so
//! Q = G_d(θ) Σ_W G_d(θ)ᵀ; for Euler this is eq 36, Γ_T Q_v Γ_Tᵀ with Γ_T = Γ T.
//!
//! Two process types share these equations and differ only in the Jacobian:
//! [`InsProcess`] is the model itself (∂f/∂D including the θ → velocity coupling, Hessians), for
//! the EKF and its relatives; [`CkfProcess`] is the paper's CKF (eq 33–37): G is evaluated at an
//! attitude passed in the input ([`CkfInput`]), so the model is affine in D with Jacobian Ψ and
//! runs in the linear [`KalmanFilter`](estim_filters::KalmanFilter).

use estim_core::{
    LinearMeasurementModel, LinearProcessModel, MeasurementJacobian, MeasurementModel,
    ProcessHessian, ProcessJacobian, ProcessModel,
};
use nalgebra::{
    Matrix1, Matrix3, Matrix6, Matrix6x3, RowVector6, U1, U6, Vector1, Vector2, Vector3, Vector6,
};

use super::sensors::rotation;
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// Standard gravity g₀ = 9.80665 m/s².
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// Which plane the motion is in: decides the gravity term (erratum E4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Plane {
    /// Horizontal plane: no gravity in the signals or the model (eq 16 as printed; estim's
    /// default for section IV).
    #[default]
    Horizontal,
    /// Vertical plane, y up: g_vec = (0, −g₀). The accelerometers sense f = a − g_vec and the
    /// model adds g_vec back: v̇ = R(θ) y_a + g_vec.
    Vertical,
}

impl Plane {
    /// The gravitational acceleration g_vec in the inertial frame \[m/s²\].
    pub fn gravity(self) -> Vector2<f64> {
        match self {
            Plane::Horizontal => Vector2::zeros(),
            Plane::Vertical => Vector2::new(0.0, -STANDARD_GRAVITY),
        }
    }
}

/// How the continuous model is discretised (erratum E7).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Discretization {
    /// Exact for inputs held constant over the step (θ frozen): position gets T²/2 terms.
    #[default]
    ZeroOrderHold,
    /// The paper's eq 33: G_T = G T, no input in the position and θ rows.
    Euler,
}

/// Ψ = I + F T (eq 33; exact, F² = 0).
pub fn transition_matrix(dt: f64) -> Matrix6<f64> {
    let mut psi = Matrix6::identity();
    psi[(0, 2)] = dt;
    psi[(1, 3)] = dt;
    psi[(4, 5)] = dt;
    psi
}

/// The discrete input matrix G_d(θ) (see the [module docs](self)).
pub fn input_matrix(theta: f64, dt: f64, discretization: Discretization) -> Matrix6x3<f64> {
    let r = rotation(theta);
    let mut g = Matrix6x3::zeros();
    let half = 0.5 * dt * dt;
    for i in 0..2 {
        for j in 0..2 {
            g[(2 + i, j)] = dt * r[(i, j)];
            if discretization == Discretization::ZeroOrderHold {
                g[(i, j)] = half * r[(i, j)];
            }
        }
    }
    g[(5, 2)] = dt;
    if discretization == Discretization::ZeroOrderHold {
        g[(4, 2)] = half;
    }
    g
}

fn gravity_term(plane: Plane, dt: f64, discretization: Discretization) -> Vector6<f64> {
    let g = plane.gravity();
    let p = match discretization {
        Discretization::ZeroOrderHold => 0.5 * dt * dt,
        Discretization::Euler => 0.0,
    };
    Vector6::new(p * g.x, p * g.y, dt * g.x, dt * g.y, 0.0, 0.0)
}

/// ∂/∂θ of the discrete input contribution G_d(θ) u (column 4 of the full Jacobian minus Ψ's).
fn input_attitude_derivative(
    theta: f64,
    u: &Vector3<f64>,
    dt: f64,
    discretization: Discretization,
) -> Vector6<f64> {
    let (s, c) = theta.sin_cos();
    // a_I' = ∂(R(θ) u_xy)/∂θ
    let ax = -s * u.x - c * u.y;
    let ay = c * u.x - s * u.y;
    let p = match discretization {
        Discretization::ZeroOrderHold => 0.5 * dt * dt,
        Discretization::Euler => 0.0,
    };
    Vector6::new(p * ax, p * ay, dt * ax, dt * ay, 0.0, 0.0)
}

/// The model shared by [`InsProcess`] and [`CkfProcess`].
fn transition(
    x: &Vector6<f64>,
    theta: f64,
    u: &Vector3<f64>,
    dt: f64,
    discretization: Discretization,
    plane: Plane,
) -> Vector6<f64> {
    transition_matrix(dt) * x
        + input_matrix(theta, dt, discretization) * u
        + gravity_term(plane, dt, discretization)
}

/// The planar INS process model with its true Jacobian and Hessians (θ → velocity coupling
/// kept): use it with [`Ekf`](estim_filters::Ekf), [`SecondOrderEkf`](estim_filters::SecondOrderEkf),
/// [`Ukf`](estim_filters::Ukf). Input: u = (y_ax, y_ay, y_ω̇).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InsProcess {
    /// Σ_W: per-sample covariance of the input errors (δa_x, δa_y, δω̇) \[(m/s²)², (m/s²)², (rad/s²)²\].
    pub input_noise: Matrix3<f64>,
    /// Discretisation of the continuous model.
    pub discretization: Discretization,
    /// Plane of motion (gravity term).
    pub plane: Plane,
}

impl InsProcess {
    /// The paper's CKF on the same equations (Jacobian Ψ).
    pub fn ckf(&self) -> CkfProcess {
        CkfProcess {
            input_noise: self.input_noise,
            discretization: self.discretization,
            plane: self.plane,
        }
    }
}

impl ProcessModel<f64, U6> for InsProcess {
    type Input = Vector3<f64>;

    fn transition(&self, x: &Vector6<f64>, u: &Vector3<f64>, dt: f64) -> Vector6<f64> {
        transition(x, x[4], u, dt, self.discretization, self.plane)
    }

    fn process_noise(&self, x: &Vector6<f64>, _: &Vector3<f64>, dt: f64) -> Matrix6<f64> {
        let g = input_matrix(x[4], dt, self.discretization);
        g * self.input_noise * g.transpose()
    }
}

impl ProcessJacobian<f64, U6> for InsProcess {
    fn transition_jacobian(&self, x: &Vector6<f64>, u: &Vector3<f64>, dt: f64) -> Matrix6<f64> {
        let mut f = transition_matrix(dt);
        let col = input_attitude_derivative(x[4], u, dt, self.discretization);
        for i in 0..6 {
            f[(i, 4)] += col[i];
        }
        f
    }
}

impl ProcessHessian<f64, U6> for InsProcess {
    fn transition_hessian(
        &self,
        x: &Vector6<f64>,
        u: &Vector3<f64>,
        dt: f64,
        k: usize,
    ) -> Option<Matrix6<f64>> {
        // Only θ enters nonlinearly, through R(θ): ∂²(R u)/∂θ² = −R u.
        let scale = match (k, self.discretization) {
            (0 | 1, Discretization::ZeroOrderHold) => 0.5 * dt * dt,
            (2 | 3, _) => dt,
            _ => return None,
        };
        let a = rotation(x[4]) * Vector2::new(u.x, u.y);
        let mut h = Matrix6::zeros();
        h[(4, 4)] = -scale * a[k % 2];
        Some(h)
    }
}

/// The input of the paper's CKF: the derived accelerometer inputs and the attitude θ̂ at which
/// G is evaluated (eq 33: G_T = G(θ̂_{k−1|k−1}) T). Passing θ̂ in the input is what makes the
/// CKF a linear Kalman filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CkfInput {
    /// u = (y_ax, y_ay, y_ω̇).
    pub signals: Vector3<f64>,
    /// θ̂ at which G and Γ are evaluated \[rad\].
    pub attitude: f64,
}

/// The paper's CKF process model (eq 33–36): f(D; u, θ̂) = Ψ D + G_d(θ̂) u, affine in D with
/// Jacobian Ψ, i.e. the θ → velocity coupling of the true model dropped. Implements
/// [`LinearProcessModel`], so it runs in the linear [`KalmanFilter`](estim_filters::KalmanFilter)
/// (and, with the same result, in any other Gaussian filter).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CkfProcess {
    /// Σ_W: per-sample covariance of the input errors, as in [`InsProcess`].
    pub input_noise: Matrix3<f64>,
    /// Discretisation of the continuous model.
    pub discretization: Discretization,
    /// Plane of motion (gravity term).
    pub plane: Plane,
}

impl ProcessModel<f64, U6> for CkfProcess {
    type Input = CkfInput;

    fn transition(&self, x: &Vector6<f64>, u: &CkfInput, dt: f64) -> Vector6<f64> {
        transition(
            x,
            u.attitude,
            &u.signals,
            dt,
            self.discretization,
            self.plane,
        )
    }

    fn process_noise(&self, _: &Vector6<f64>, u: &CkfInput, dt: f64) -> Matrix6<f64> {
        let g = input_matrix(u.attitude, dt, self.discretization);
        g * self.input_noise * g.transpose()
    }
}

impl ProcessJacobian<f64, U6> for CkfProcess {
    fn transition_jacobian(&self, _: &Vector6<f64>, _: &CkfInput, dt: f64) -> Matrix6<f64> {
        transition_matrix(dt)
    }
}

impl LinearProcessModel<f64, U6> for CkfProcess {}

/// Affine: every Hessian is zero (the second-order filters and the derivative checker ask).
impl estim_core::ProcessHessian<f64, estim_core::nalgebra::U6> for CkfProcess {
    fn transition_hessian(
        &self,
        _: &estim_core::nalgebra::OVector<f64, estim_core::nalgebra::U6>,
        _: &CkfInput,
        _: f64,
        _: usize,
    ) -> Option<
        estim_core::nalgebra::OMatrix<f64, estim_core::nalgebra::U6, estim_core::nalgebra::U6>,
    > {
        None
    }
}

/// Wraps an angle into (−π, π] (estim-core's helper, re-exported here for the model's users).
pub use estim_core::wrap_angle;

/// The attitude measurement E = H D + ε, H = e₄ᵀ (eq 21; "gravity sensing"), ε ~ N(0, R_v).
/// The innovation is wrapped into (−π, π].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudeMeasurement {
    /// R_v \[rad²\] (scalar: H is 1 × 6, erratum E6).
    pub variance: f64,
}

impl MeasurementModel<f64, U6, U1> for AttitudeMeasurement {
    fn measure(&self, x: &Vector6<f64>) -> Vector1<f64> {
        Vector1::new(x[4])
    }

    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix1<f64> {
        Matrix1::new(self.variance)
    }

    fn residual_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
        *out = Vector1::new(wrap_angle(a[0] - b[0]));
    }
}

impl MeasurementJacobian<f64, U6, U1> for AttitudeMeasurement {
    fn measurement_jacobian(&self, _: &Vector6<f64>) -> RowVector6<f64> {
        RowVector6::new(0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    }
}

impl LinearMeasurementModel<f64, U6, U1> for AttitudeMeasurement {}

/// Affine: every Hessian is zero (the second-order filters and the derivative checker ask).
impl estim_core::MeasurementHessian<f64, estim_core::nalgebra::U6, estim_core::nalgebra::U1>
    for AttitudeMeasurement
{
    fn measurement_hessian(
        &self,
        _: &estim_core::nalgebra::OVector<f64, estim_core::nalgebra::U6>,
        _: usize,
    ) -> Option<
        estim_core::nalgebra::OMatrix<f64, estim_core::nalgebra::U6, estim_core::nalgebra::U6>,
    > {
        None
    }
}
