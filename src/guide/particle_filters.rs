//! # When a Gaussian is not enough
//!
//! Every Gaussian filter here (KF, EKF, UKF, their square-root and iterated forms) carries the
//! posterior as a mean and a covariance. That is exact for linear-Gaussian models and good
//! when the posterior is close to one bump. It fails when the posterior has **several modes**
//! (a sensor that cannot tell x from −x, range-only fixes with a mirror ambiguity, a robot that
//! may be in one of several corridors), when the noise is **heavy-tailed or bounded** (outliers,
//! quantised or clipped sensors), or when the model is so nonlinear over the prior's spread that
//! one linearisation point or one set of sigma points misses where the mass goes.
//!
//! A particle filter ([`ParticleFilter`](crate::filters::particle::ParticleFilter)) carries N
//! weighted samples instead, and runs the same models: changing filter is changing the
//! constructor. The reading below sees only x², so the posterior has a mode at each sign. The
//! EKF linearises at x̂ = 0, where the Jacobian h′(0) is zero, and learns nothing; the particle
//! filter finds both modes:
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::particle::ParticleFilter;
//! use estim::nalgebra::{Matrix1, U1, Vector1};
//!
//! /// z = x²/20 + v, R = 1 (the growth model's sensor, Gordon, Salmond & Smith 1993).
//! struct Square;
//! impl MeasurementModel<f64, U1, U1> for Square {
//!     fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> { Vector1::new(x[0] * x[0] / 20.0) }
//!     fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> { Matrix1::new(1.0) }
//! }
//! impl MeasurementJacobian<f64, U1, U1> for Square {
//!     fn measurement_jacobian(&self, x: &Vector1<f64>) -> Matrix1<f64> { Matrix1::new(x[0] / 10.0) }
//! }
//!
//! let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(25.0))?;
//! let z = Vector1::new(1.8); // x² ≈ 36 ± 20: x ≈ ±6, pulled in by the prior
//! let mut ekf = Ekf::new(prior.clone());
//! ekf.update(&Square, &z)?;
//! // H = h′(0) = 0: the EKF's posterior is its prior.
//! assert_eq!((ekf.state()[0], ekf.covariance()[(0, 0)]), (0.0, 25.0));
//!
//! let mut pf = ParticleFilter::new(prior, 4000, 7)?;
//! pf.update(&Square, &z)?;
//! let mut w = Vec::new();
//! pf.weights_into(&mut w);
//! let negative: f64 = pf.particles().iter().zip(&w).filter(|(x, _)| **x < 0.0).map(|(_, w)| w).sum();
//! let mean_abs: f64 = pf.particles().iter().zip(&w).map(|(x, w)| x.abs() * w).sum();
//! // The exact E|x| by quadrature of N(x; 0, 25) N(1.8; x²/20, 1) on [−30, 30] (6001 nodes:
//! // the integrand is smooth and negligible at the ends, error ≪ 10⁻⁶): 4.38.
//! let density = |x: f64| (-x * x / 50.0 - (1.8 - x * x / 20.0).powi(2) / 2.0).exp();
//! let nodes = (0..=6000).map(|i| -30.0 + 0.01 * i as f64);
//! let (mass, first) = nodes.fold((0.0, 0.0), |(m, f), x| (m + density(x), f + x.abs() * density(x)));
//! let exact = first / mass;
//! // Half the mass at each sign (by symmetry). The effective sample size is ≈ 0.7 N = 2800, so
//! // the split has standard error 0.5/√2800 ≈ 0.01, and E|x| (posterior sd of |x| ≈ 2)
//! // ≈ 0.04: bounds of 0.06 and 0.25 are 6 standard errors.
//! assert!(pf.effective_sample_size() > 2000.0);
//! assert!((negative - 0.5).abs() < 0.06, "{negative}");
//! assert!((mean_abs - exact).abs() < 0.25, "{mean_abs} vs {exact}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## What carries over, what changes
//!
//! - **The models.** Any [`ProcessModel`](crate::core::ProcessModel) and
//!   [`MeasurementModel`](crate::core::MeasurementModel) run with Gaussian noise drawn from Q
//!   (its PSD factor, so a singular Q is fine) and weights from N(z ⊖ h(x), R) with the model's
//!   residual (angles wrap). No Jacobians are needed. For non-Gaussian noise, implement
//!   [`ProcessSampler`](crate::filters::particle::ProcessSampler) or
//!   [`MeasurementLikelihood`](crate::filters::particle::MeasurementLikelihood) and wrap the
//!   model in [`NonGaussian`](crate::filters::particle::NonGaussian) (or use
//!   [`NonGaussianFilter`](crate::filters::particle::NonGaussianFilter) through the step traits).
//! - **The contract.** `predict`/`update`, `state()`/`covariance()` (the weighted moments —
//!   of a bimodal cloud, the mean sits between the modes: look at
//!   [`particles`](crate::filters::particle::ParticleFilter::particles) and
//!   [`weights_into`](crate::filters::particle::ParticleFilter::weights_into) for the shape),
//!   snapshots and rollback, the fusion driver, `filter_sequence`, serde checkpoints.
//! - **The likelihood.** [`log_likelihood`](crate::filters::particle::ParticleFilter::log_likelihood)
//!   is an unbiased estimate (in exp) of p(z₁..ₖ), with adaptive resampling too: the input of
//!   likelihood-based parameter fits.
//! - **Settings.** Resampling scheme ([`Resampling`](crate::filters::particle::Resampling),
//!   systematic by default) and trigger ([`ResampleWhen`](crate::filters::particle::ResampleWhen),
//!   ESS below N/2 by default); the auxiliary filter
//!   ([`auxiliary_step`](crate::filters::particle::ParticleFilter::auxiliary_step)) looks ahead at
//!   the reading before resampling, which helps when the sensor is sharp relative to Q.
//! - **Cost and reproducibility.** A step costs N model evaluations (a Gaussian filter costs a
//!   few, plus n³ algebra). The per-particle loops run in fixed chunks; with the `parallel`
//!   feature they run on rayon's pool from
//!   [`PARALLEL_MIN`](crate::filters::particle::PARALLEL_MIN) particles, and a seed gives the
//!   same bits on any number of threads. Steps allocate nothing after the first.
//!
//! ## How many particles
//!
//! The Monte Carlo error of a weighted mean is about σ_posterior/√ESS, so watch
//! [`effective_sample_size`](crate::filters::particle::ParticleFilter::effective_sample_size)
//! after updates: an ESS that collapses to a handful means the sensor is much sharper than the
//! prediction (more particles, or the auxiliary step). For the multimodal cases, the particles
//! must cover every mode the prior allows: a prior that is too narrow loses a mode for good.
//!
//! The repository's example `particle_growth` runs the growth model (EKF, UKF, bootstrap and
//! auxiliary particle filters: RMSE table and a figure of the bimodal posterior) and a
//! range-only localisation started at the mirror image of the truth, where the Gaussian
//! filters lock onto the wrong side and the particle filter does not:
//! `cargo run --release --example particle_growth`.
