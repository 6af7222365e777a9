//! Motion models every tracker needs, and the exact discretisation of continuous-time noise.
//!
//! | model | state | input | linear |
//! |---|---|---|---|
//! | [`ConstantVelocity<T, D>`] (D = 1, 2, 3) | (p, v), 2D | – | yes |
//! | [`ConstantAcceleration<T, D>`] (D = 1, 2, 3) | (p, v, a), 3D | – | yes |
//! | [`CoordinatedTurn`] (known ω) | (x, y, vₓ, v_y) | – | yes |
//! | [`CoordinatedTurnRate`] (ω estimated) | (x, y, vₓ, v_y, ω) | – | no (Hessians) |
//! | [`Unicycle`] (odometry) | (x, y, ψ) | (v, ω) | no (Hessians) |
//! | [`RandomWalk<T, N>`] | N | – | yes |
//! | [`GaussMarkov<T, N>`] (first order) | N | – | yes |
//!
//! Every model is generic over the scalar (`f32`, `f64`) and has static sizes (on the stack),
//! implements the value, Jacobian and Hessian capabilities (`None` Hessians for the linear ones,
//! which also carry the [`LinearProcessModel`](estim_core::LinearProcessModel) marker), and
//! its derivatives are checked against automatic differentiation in the crate's tests. The
//! state always starts with the position, so the [`sensors`](crate::sensors) read any of
//! them: the kinematic states are ordered **by block**, (p₁..p_D, v₁..v_D[, a₁..a_D]), not
//! per axis as FilterPy's examples do (x, vₓ, y, v_y).
//!
//! **Why one type per model, generic over the dimension.** `ConstantVelocity<f64, 2>` names the
//! model by its physics; the state size 2D is derived (a `Const`), per D by a macro, because
//! stable Rust cannot write `Const<{2 * D}>`.
//!
//! **Noise over irregular steps.** The process noise of every model here is the exact
//! discretisation of a continuous-time white noise, so any Δt (a log's irregular times) is
//! exact with one intensity; see [`continuous_white_noise`] and [`van_loan`] for the general
//! tools, and [`Noise`] for FilterPy's discrete form.
//!
//! ```
//! use estim_core::nalgebra::{Matrix2, Matrix4, Vector2, Vector4};
//! use estim_core::Gaussian;
//! use estim_filters::{Estimator, KalmanFilter, Predict, Update};
//! use estim_models::motion::{ConstantVelocity, Noise};
//! use estim_models::sensors::Position;
//!
//! let cv = ConstantVelocity::<f64, 2>::new(Noise::Continuous(0.01));
//! let gps = Position::<f64, 2> { noise: Matrix2::identity() * 0.25 };
//! let mut kf = KalmanFilter::new(Gaussian::new(Vector4::zeros(), Matrix4::identity() * 100.0)?);
//! // Irregular steps: one model, any Δt.
//! for (k, dt) in [0.1, 0.35, 0.05, 0.5, 0.2].into_iter().cycle().take(40).enumerate() {
//!     kf.predict(&cv, &(), dt)?;
//!     let t = (k + 1) as f64;
//!     kf.update(&gps, &Vector2::new(t, -t))?;
//! }
//! assert!(kf.state().fixed_rows::<2>(0).iter().all(|p| p.is_finite()));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod discretize;
mod kinematic;
mod stochastic;
mod trig;
mod turn;
mod unicycle;

#[cfg(feature = "std")]
pub use discretize::van_loan;
pub use discretize::{continuous_white_noise, discrete_white_noise};
pub use kinematic::{ConstantAcceleration, ConstantVelocity, Noise};
pub use stochastic::{GaussMarkov, RandomWalk};
pub use turn::{CoordinatedTurn, CoordinatedTurnRate};
pub use unicycle::Unicycle;
