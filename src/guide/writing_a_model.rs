//! # Writing a model
//!
//! A model is its function values and, for the filters that need them, its derivatives: the
//! UKF needs values, the EKF the Jacobian, the second-order EKF the Hessian of each output
//! component. Two ways to give the derivatives, and one way to check them.
//!
//! **By hand.** Implement [`ProcessModel`](crate::core::ProcessModel) (f(x, u, Δt) and Q),
//! then [`ProcessJacobian`](crate::core::ProcessJacobian) (F = ∂f/∂x) and
//! [`ProcessHessian`](crate::core::ProcessHessian) (∂²fₖ/∂x², `None` for an affine fₖ); the
//! same three levels for measurements ([`MeasurementModel`](crate::core::MeasurementModel),
//! …). The [quickstart](crate::guide::choosing_a_filter) shows a complete set.
//!
//! **Automatically.** With feature `autodiff`, write f (or h) once over a generic scalar
//! `D: AdScalar<f64>` and wrap the model in `estim::core::autodiff::AutoDiff`: it implements
//! all three levels from that one function, by dual numbers (Jacobians: n first-order passes;
//! Hessians: n(n+1)/2 hyper-dual passes for all components at once). The results are exact up
//! to the rounding of your own arithmetic: no step size, no truncation. The elementary functions
//! are methods (`x[0].sin()`, `.sqrt()`, `.atan2(b)`), `T` constants mix in (`x[1] * dt`), and
//! Q and R are written plainly.
//!
//! **Checking.** [`check_process_model`](crate::core::derivative::check_process_model)
//! compares hand-written derivatives with finite differences (to ≈ 10⁻⁶);
//! [`compare_process_models`](crate::core::derivative::compare_process_models) compares them
//! with another implementation of the same model, such as its `AutoDiff` form, entry by entry
//! (to rounding, ≈ 10⁻¹²): keep the hand-written derivatives for speed, and let AD prove them.
//!
//! A pendulum, x = (θ, ω), x⁺ = (θ + Δt ω, ω − Δt (g/l) sin θ), seen through the bob's
//! horizontal position l sin θ, run in the second-order EKF with derivatives it never wrote:
//!
//! ```
//! # #[cfg(feature = "autodiff")]
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use estim::core::autodiff::{AdScalar, AutoDiff, AutoDiffMeasurement, AutoDiffProcess};
//! use estim::nalgebra::{Matrix1, Matrix2, U1, U2, Vector1, Vector2};
//! use estim::prelude::*;
//!
//! struct Pendulum;
//! impl AutoDiffProcess<f64, U2> for Pendulum {
//!     type Input = ();
//!     fn transition<D: AdScalar<f64>>(&self, x: &Vector2<D>, _: &(), dt: f64) -> Vector2<D> {
//!         Vector2::new(x[0] + x[1] * dt, x[1] - x[0].sin() * (9.81 * dt))
//!     }
//!     fn process_noise(&self, _: &Vector2<f64>, _: &(), dt: f64) -> Matrix2<f64> {
//!         Matrix2::new(1e-6, 0.0, 0.0, 1e-4) * dt
//!     }
//! }
//!
//! struct Bob;
//! impl AutoDiffMeasurement<f64, U2, U1> for Bob {
//!     fn measure<D: AdScalar<f64>>(&self, x: &Vector2<D>) -> Vector1<D> {
//!         Vector1::new(x[0].sin())
//!     }
//!     fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> {
//!         Matrix1::new(1e-4)
//!     }
//! }
//!
//! let (pendulum, bob) = (AutoDiff::new(Pendulum), AutoDiff::new(Bob));
//! let prior = Gaussian::new(Vector2::new(0.5, 0.0), Matrix2::identity() * 0.01)?;
//! let mut filter = SecondOrderEkf::new(prior);
//! let mut truth = Vector2::new(0.45, 0.0);
//! for _ in 0..200 {
//!     truth = pendulum.transition(&truth, &(), 0.01);
//!     filter.predict(&pendulum, &(), 0.01)?;
//!     filter.update(&bob, &bob.measure(&truth))?;
//! }
//! assert!((filter.state() - truth).norm() < 0.05);
//!
//! // Hand-written derivatives of the same pendulum, proven by the AD form at a point.
//! struct HandPendulum;
//! impl ProcessModel<f64, U2> for HandPendulum {
//!     type Input = ();
//!     fn transition(&self, x: &Vector2<f64>, _: &(), dt: f64) -> Vector2<f64> {
//!         Vector2::new(x[0] + x[1] * dt, x[1] - x[0].sin() * (9.81 * dt))
//!     }
//!     fn process_noise(&self, x: &Vector2<f64>, u: &(), dt: f64) -> Matrix2<f64> {
//!         Pendulum.process_noise(x, u, dt)
//!     }
//! }
//! impl ProcessJacobian<f64, U2> for HandPendulum {
//!     fn transition_jacobian(&self, x: &Vector2<f64>, _: &(), dt: f64) -> Matrix2<f64> {
//!         Matrix2::new(1.0, dt, -x[0].cos() * 9.81 * dt, 1.0)
//!     }
//! }
//! impl ProcessHessian<f64, U2> for HandPendulum {
//!     fn transition_hessian(&self, x: &Vector2<f64>, _: &(), dt: f64, k: usize) -> Option<Matrix2<f64>> {
//!         (k == 1).then(|| Matrix2::new(x[0].sin() * 9.81 * dt, 0.0, 0.0, 0.0))
//!     }
//! }
//! let x = Vector2::new(0.3, -0.2);
//! let report = estim::core::derivative::compare_process_models(
//!     &HandPendulum, &pendulum, &x, &(), &(), 0.01,
//! )?;
//! assert!(report.is_accurate(1e-12), "{report}");
//! # Ok(())
//! # }
//! # #[cfg(not(feature = "autodiff"))]
//! # fn main() {}
//! ```
//!
//! Runnable examples: `examples/attitude.rs` (an AHRS whose quaternion measurement model is
//! differentiated automatically, on a 3-dimensional attitude-error state) and
//! `examples/reproductions/heading_wrap.rs` (a heading state across ±π with
//! [`WrappedAngles`](crate::core::WrappedAngles)).
//!
//! **A missing derivative** is a compile error that names the trait to implement in its first
//! line (each capability trait carries a `#[diagnostic::on_unimplemented]` message). Running a
//! model with only its values through the EKF, which linearises it:
//!
//! ```compile_fail,E0277
//! use estim::nalgebra::{Matrix1, Vector1};
//! use estim::prelude::*;
//!
//! /// A random walk x⁺ = x + w, with values only: no Jacobian.
//! struct Walk;
//! impl ProcessModel<f64, estim::nalgebra::U1> for Walk {
//!     type Input = ();
//!     fn transition(&self, x: &Vector1<f64>, _: &(), _: f64) -> Vector1<f64> {
//!         *x
//!     }
//!     fn process_noise(&self, _: &Vector1<f64>, _: &(), dt: f64) -> Matrix1<f64> {
//!         Matrix1::new(dt)
//!     }
//! }
//!
//! let mut ekf = Ekf::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?);
//! // Expected: error[E0277]: `Walk` has no process Jacobian: implement
//! // `ProcessJacobian<f64, Const<1>>` for it (F = ∂f/∂x), or use a filter that needs none (`Ukf`)
//! ekf.predict(&Walk, &(), 0.1)?;
//! # Ok::<(), estim::core::Error>(())
//! ```
//!
//! The same model runs as it is in the UKF (`Ukf::new`), which needs only the values.
//!
//! **A filter over your models, as a bound.** A function generic over the filter names it
//! with [`FilterOver`](crate::filters::FilterOver) (predicts through `P`, updates with `H`) or
//! [`Smoothable`](crate::filters::Smoothable) (also records what the RTS smoother needs),
//! instead of the step traits or the propagator bounds of
//! [`GaussianFilter`](crate::filters::GaussianFilter):
//!
//! ```
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, U1, U2, Vector1, Vector2};
//! use estim::prelude::*;
//! use estim::filters::{FilterOver, Smoothable, Rts};
//!
//! type Motion = LinearProcess<f64, U2, U1>;
//! type Position = LinearMeasurement<f64, U2, U1>;
//!
//! /// Filters the readings with any filter, recording the run for the RTS smoother; returns
//! /// the smoothed estimates (one per reading).
//! fn smoothed<F: Smoothable<f64, U2, U1, Motion, Position>>(
//!     filter: &mut F,
//!     (motion, sensor): (&Motion, &Position),
//!     zs: &[f64],
//! ) -> Result<Vec<Gaussian<f64, U2>>, Box<dyn std::error::Error>> {
//!     let mut rts = Rts::new();
//!     for (k, &z) in zs.iter().enumerate() {
//!         if k > 0 {
//!             rts.predict(filter, motion, &Vector1::zeros(), 1.0)?;
//!         }
//!         filter.update(sensor, &Vector1::new(z))?;
//!     }
//!     Ok(rts.smooth(filter)?)
//! }
//!
//! /// Only filters: the estimate after the last reading.
//! fn filtered<F: FilterOver<f64, U2, U1, Motion, Position>>(
//!     filter: &mut F,
//!     (motion, sensor): (&Motion, &Position),
//!     zs: &[f64],
//! ) -> Result<Vector2<f64>, estim::core::Error> {
//!     for (k, &z) in zs.iter().enumerate() {
//!         if k > 0 {
//!             filter.predict(motion, &Vector1::zeros(), 1.0)?;
//!         }
//!         filter.update(sensor, &Vector1::new(z))?;
//!     }
//!     Ok(filter.state().clone())
//! }
//!
//! let motion = Motion {
//!     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
//!     input: Matrix2x1::zeros(),
//!     noise: Matrix2::identity() * 1e-2,
//! };
//! let sensor = Position { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?;
//! let zs = [0.1, 1.2, 1.9, 3.1];
//! let run = smoothed(&mut Ukf::new(prior.clone()), (&motion, &sensor), &zs)?;
//! let last = filtered(&mut Ekf::new(prior), (&motion, &sensor), &zs)?;
//! assert_eq!(run.len(), zs.len());
//! // The smoother's last estimate is the filter's (nothing comes after it); on a linear model
//! // the UKF and the EKF compute the same moments, so they agree up to rounding (1e-9).
//! assert!((run[zs.len() - 1].mean() - last).norm() < 1e-9);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
