//! # Learning Q and R from data
//!
//! [`noise_id`](crate::filters::noise_id) offers three routes:
//!
//! | you have | use | you get |
//! |---|---|---|
//! | a linear model and recorded sequences | EM ([`noise_id::em`](crate::filters::noise_id::em)) | Q, R (and x₀, P₀, F, H) under structure constraints; ℓ of every iteration |
//! | any model and filter (EKF, UKF, second-order EKF) | maximum likelihood (`noise_id::likelihood`, feature `likelihood`) | your parameters with standard errors |
//! | a running filter whose sensor noise drifts | covariance matching ([`noise_id::adaptive`](crate::filters::noise_id::adaptive)) | R̂ after every update |
//!
//! ## EM: noise covariances of a linear model
//!
//! Say which parts are free and in which structure (full, diagonal, some diagonal entries
//! held, or a scalar times a fixed shape, possibly singular as for a scalar noise entering
//! through a vector Γ), hand in one or many records (`None` for a missing measurement):
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::noise_id::{CovarianceStructure, EmSettings, LinearGaussian, Record, em::estimate};
//! use estim::nalgebra::{Matrix1, Matrix2, Matrix1x2, Matrix2x1, Vector1, Vector2};
//! use estim::rand::{SeedableRng, rngs::StdRng};
//! use estim::rand_distr::{Distribution, StandardNormal};
//!
//! // Constant velocity driven by an acceleration noise of variance q through Γ = (½, 1).
//! let gamma = Vector2::new(0.5, 1.0);
//! let (q, r) = (0.01f64, 0.5f64);
//! let mut rng = StdRng::seed_from_u64(1);
//! let mut n = || -> f64 { StandardNormal.sample(&mut rng) };
//! let (mut x, mut zs) = (Vector2::new(0.0, 1.0), Vec::new());
//! for k in 0..600 {
//!     if k > 0 { x = Matrix2::new(1.0, 1.0, 0.0, 1.0) * x + gamma * (q.sqrt() * n()); }
//!     // Every third position is lost.
//!     zs.push((k % 3 != 2).then(|| Vector1::new(x[0] + r.sqrt() * n())));
//! }
//! let inputs = vec![Vector1::zeros(); zs.len() - 1];
//! let start = LinearGaussian {
//!     process: LinearProcess { transition: Matrix2::new(1.0, 1.0, 0.0, 1.0), input: Matrix2x1::zeros(), noise: gamma * gamma.transpose() },
//!     measurement: LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(1.0) },
//!     prior: Gaussian::new(Vector2::zeros(), Matrix2::identity() * 10.0)?,
//! };
//! let settings = EmSettings::new()
//!     .with_process_noise(CovarianceStructure::ScalarMultiple(gamma * gamma.transpose()))
//!     .with_measurement_noise(CovarianceStructure::Full)
//!     .with_iterations(100, 1e-9)?;
//! let fit = estimate(&start, &settings, &[Record { inputs: &inputs, measurements: &zs }])?;
//! let q_hat = fit.model.process.noise[(1, 1)]; // Γ₂ = 1
//! assert!((q_hat / q - 1.0).abs() < 0.5 && (fit.model.measurement.noise[(0, 0)] / r - 1.0).abs() < 0.2);
//! // ℓ never decreases from one iteration to the next.
//! assert!(fit.history.windows(2).all(|w| w[1] >= w[0] - 1e-9 * w[0].abs()));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! EM climbs fast and then crawls where a parameter is weakly identified; it gives no standard
//! errors. Cap it and finish with maximum likelihood from its estimate (the `lu_noise_id`
//! example does exactly that).
//!
//! ## Maximum likelihood: any filter, your parameterisation
//!
//! Write the prediction-error log-likelihood as a function of θ ∈ ℝᵖ (log-variances keep every
//! θ valid) with `sequence_log_likelihood`, and maximise it (L-BFGS with numerical gradients,
//! then a finite-difference Hessian for the standard errors):
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::noise_id::{MaximumLikelihood, likelihood::sequence_log_likelihood};
//! use estim::nalgebra::{Matrix1, Vector1};
//! use estim::rand::{SeedableRng, rngs::StdRng};
//! use estim::rand_distr::{Distribution, Normal};
//!
//! let (mut rng, mut x) = (StdRng::seed_from_u64(2), 0.0);
//! let (w, v) = (Normal::new(0.0, 0.1)?, Normal::new(0.0, 0.3)?);
//! let zs: Vec<_> = (0..300).map(|_| { x += w.sample(&mut rng); Some(Vector1::new(x + v.sample(&mut rng))) }).collect();
//! let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
//! let ll = |theta: &[f64]| {
//!     let process = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(theta[0].exp()) };
//!     let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(theta[1].exp()) };
//!     // Any filter: Ukf::new(prior.clone()) works the same way.
//!     sequence_log_likelihood(&Ekf::new(prior.clone()), &process, &vec![Vector1::zeros(); 299], 1.0, &sensor, &zs)
//! };
//! let fit = MaximumLikelihood::new().maximize(ll, &[0.0, 0.0])?;
//! let se = fit.standard_errors()?; // of ln Q and ln R; se(R̂) ≈ R̂ · se[1]
//! assert!((fit.parameters[1] - 0.09f64.ln()).abs() < 4.0 * se[1]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! A parameter the data do not determine shows as a Hessian that is not negative definite:
//! `standard_errors` then names it (`Unidentifiable::FlatLikelihood`).
//!
//! ## Covariance matching: online R
//!
//! Wrap the sensor model (its R becomes the running estimate), update as usual, feed the report
//! back. The window L sets the trade-off: σ(R̂) ≈ S/√L for a scalar, a step in R followed with
//! time constant L updates.
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::noise_id::MeasurementNoiseMatching;
//! use estim::nalgebra::{Matrix1, Vector1};
//!
//! let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
//! let process = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(0.01) };
//! let mut adaptive = MeasurementNoiseMatching::new(sensor.noise, 50.0, 1e-6)?;
//! let mut kf = KalmanFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?);
//! for z in [0.3, -0.2, 0.1, 0.4, -0.1] {
//!     kf.predict(&process, &Vector1::zeros(), 1.0)?;
//!     let report = kf.update(&adaptive.model(&sensor), &Vector1::new(z))?;
//!     adaptive.observe(&report)?;
//! }
//! assert!(adaptive.noise()[(0, 0)] > 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! It cannot tell a wrong Q from a wrong R (both raise the innovations), and a short window can
//! make the statistic indefinite; R̂ is then clipped to the floor (see the module's *Failure
//! modes*).
