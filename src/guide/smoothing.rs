//! # Smoothing recorded data
//!
//! Offline, every estimate can use every measurement, before and after it. The
//! Rauch–Tung–Striebel smoother ([`smoother`](crate::filters::smoother)) serves every Gaussian
//! filter through the cross-covariance its propagator already computes (so the UKF gives the
//! unscented RTS smoother). For a recorded sequence with missing measurements:
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::smoother::smooth_sequence;
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//!
//! let process = LinearProcess {
//!     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
//!     input: Matrix2x1::zeros(),
//!     noise: Matrix2::identity() * 1e-2,
//! };
//! let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
//! let zs = [Some(Vector1::new(0.0)), Some(Vector1::new(1.1)), None, Some(Vector1::new(2.9))];
//! let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?);
//! let run = smooth_sequence(&mut kf, &process, &[Vector1::zeros(); 3], 1.0, &sensor, &zs)?;
//! // Time 2 had no measurement: its smoothed position comes from both neighbours.
//! assert!(f64::abs(run.estimates[2].mean()[0] - 2.0) < 0.3);
//! println!("log-likelihood of the record: {}", run.log_likelihood);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Drive your own loop with [`Rts::predict`](crate::filters::Rts::predict) in place of
//! `predict` (several sensors, varying Δt and inputs), then call
//! [`Rts::smooth`](crate::filters::Rts::smooth); [`Rts::with_lag`](crate::filters::Rts::with_lag)
//! keeps only the last L steps, a fixed-lag smoother for online use.
//!
//! For the E-step of EM, [`Rts::smooth_with_cross_covariances`](crate::filters::Rts::smooth_with_cross_covariances)
//! (or [`smooth_sequence_with_cross_covariances`](crate::filters::smooth_sequence_with_cross_covariances))
//! also returns the lag-one smoothed cross-covariances Pₖ₊₁,ₖ|K = cov(xₖ₊₁, xₖ | all data) from
//! the same backward pass:
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::smoother::smooth_sequence_with_cross_covariances;
//! use estim::nalgebra::{Matrix1, Matrix1x2, Matrix2, Matrix2x1, Vector1, Vector2};
//!
//! let process = LinearProcess {
//!     transition: Matrix2::new(1.0, 1.0, 0.0, 1.0),
//!     input: Matrix2x1::zeros(),
//!     noise: Matrix2::identity() * 1e-2,
//! };
//! let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
//! let zs = [Some(Vector1::new(0.0)), Some(Vector1::new(1.1)), None, Some(Vector1::new(2.9))];
//! let mut kf = KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?);
//! let (run, cross) =
//!     smooth_sequence_with_cross_covariances(&mut kf, &process, &[Vector1::zeros(); 3], 1.0, &sensor, &zs)?;
//! // E[xₖ₊₁ xₖᵀ | all data] = Pₖ₊₁,ₖ|K + x̂ˢₖ₊₁ x̂ˢₖᵀ, the sufficient statistic EM needs.
//! let second_moment = cross[0] + run.estimates[1].mean() * run.estimates[0].mean().transpose();
//! assert!(f64::is_finite(second_moment[(0, 0)]));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! A log with irregular times and several sensors goes through `smooth_readings` (a
//! `(time, reading)` log and a `SensorSet`, as for the fusion driver), and
//! `Rts::smooth_with_times` returns each estimate with its time. A state with zero variance
//! (a fixed offset) is smoothed as a constant; where the predicted covariance is singular for
//! another reason, `SmootherError::state` names the state.
//!
//! On any error the sequence functions return a [`SmootherError`](crate::filters::SmootherError)
//! naming the time of the failing step and leave the filter as it was.
//!
//! # Smoothing a multiple-model run
//!
//! An [`Imm`](crate::filters::imm::Imm) run is smoothed by
//! [`ImmSmoother`](crate::filters::imm::ImmSmoother): call its `predict` in place of the
//! IMM's, then `smooth` gives, at every time, the smoothed mixture (combined Gaussian, mode
//! probabilities, each mode's Gaussian). It is Kim's Rauch–Tung–Striebel-form backward pass
//! with each pair of modes weighted by the likelihood of the data after it (the module docs
//! give the equations and why this algorithm): exact for one mode and for a static bank, and
//! within 0.23 σ of the exact smoothed posterior on a short manoeuvre where Kim's plain pass
//! is 1.1 σ off.
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::imm::{Imm, ImmSmoother};
//! use estim::nalgebra::{DMatrix, DVector, Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
//!
//! let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
//! let models = (
//!     LinearProcess::without_input(f, Matrix2::identity() * 1e-4),
//!     LinearProcess::without_input(f, Matrix2::identity() * 1e-1),
//! );
//! let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
//! let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
//! let modes = (KalmanFilter::new(prior.clone()), Ukf::new(prior));
//! let pi = DMatrix::from_row_slice(2, 2, &[0.95, 0.05, 0.10, 0.90]);
//! let mut imm = Imm::new(modes, pi, DVector::from_vec(vec![0.5, 0.5]))?;
//! let mut smoother = ImmSmoother::new();
//! for z in [0.1, 0.9, 2.2, 2.8, 4.1, 6.3, 9.2] {
//!     smoother.predict(&mut imm, &models, &(), 1.0)?;
//!     imm.update_modes(&sensor, &Vector1::new(z))?;
//! }
//! let smoothed = smoother.smooth(&imm)?;
//! assert_eq!(smoothed.len(), 8);
//! assert!(f64::abs(smoothed[2].probabilities.sum() - 1.0) < 1e-12);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
