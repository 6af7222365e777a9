//! Maximum-likelihood noise identification for every filter of the family (feature
//! `likelihood`).
//!
//! The prediction-error decomposition gives the log-likelihood of a recorded sequence as the sum
//! of the filter's per-update log-likelihoods, ℓ(θ) = Σₖ ln N(νₖ; 0, Sₖ(θ)), exactly for a linear
//! model and to the filter's approximation for the EKF, UKF and second-order EKF. It is what
//! [`filter_sequence`] returns. [`MaximumLikelihood`] maximises
//! ℓ over a parameter vector θ ∈ ℝᵖ that the user maps to a model (typically log-variances, so
//! that every θ is a valid model) and reports:
//!
//! - θ̂ and ℓ(θ̂);
//! - the observed information −∇²ℓ(θ̂) and its inverse, the asymptotic covariance of θ̂, whose
//!   diagonal square roots are the standard errors (in θ's units; for a variance σ² = e^θ the
//!   delta method gives se(σ̂²) ≈ σ̂² · se(θ̂)).
//!
//! **Optimiser.** L-BFGS (argmin's `LBFGS`, memory 7 by default) with the Moré–Thuente line
//! search, on the cost −ℓ(θ) / (1 + |ℓ(θ₀)|) (scaled so that the tolerance means the same for
//! short and long records), with central-difference gradients
//! ∂ᵢℓ ≈ (ℓ(θ + hᵢeᵢ) − ℓ(θ − hᵢeᵢ)) / 2hᵢ, hᵢ = ε^{1/3} max(|θᵢ|, 1) (the step that balances
//! the O(h²) truncation against the O(ε/h) round-off). L-BFGS rather than Nelder–Mead: ℓ is
//! smooth, p is small, and a quasi-Newton method converges superlinearly to the precision the
//! standard errors and the comparison with EM need, where a simplex stalls at √(tolerance) in θ.
//! One Newton step with the finite-difference Hessian then polishes θ̂ (kept only if ℓ rises).
//!
//! **Hessian.** Central second differences with hᵢ = ε^{1/4} max(|θᵢ|, 1) (≈ 1.2·10⁻⁴ for f64:
//! the step that balances the O(h²) truncation of the second difference against its O(ε/h²)
//! round-off): ∂ᵢ²ℓ ≈ (ℓ(θ + hᵢeᵢ) − 2ℓ(θ) + ℓ(θ − hᵢeᵢ)) / hᵢ² and
//! ∂ᵢ∂ⱼℓ ≈ (ℓ(++) − ℓ(+−) − ℓ(−+) + ℓ(−−)) / 4hᵢhⱼ; 1 + 2p² evaluations.
//! If −∇²ℓ is not positive definite (a flat or upward direction: the data do not determine that
//! parameter), [`MlEstimate::standard_errors`] says which parameter, as
//! [`Unidentifiable::FlatLikelihood`].
//!
//! ```
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_core::nalgebra::{Matrix1, Vector1};
//! use estim_core::rand::{SeedableRng, rngs::StdRng};
//! use estim_core::rand_distr::{Distribution, Normal};
//! use estim_filters::Ekf;
//! use estim_filters::noise_id::{MaximumLikelihood, likelihood::sequence_log_likelihood};
//!
//! // A random walk with Q = 0.04, seen through noise R = 0.25.
//! let (mut rng, mut x) = (StdRng::seed_from_u64(3), 0.0);
//! let (w, v) = (Normal::new(0.0, 0.2)?, Normal::new(0.0, 0.5)?);
//! let zs: Vec<_> = (0..400).map(|_| { x += w.sample(&mut rng); Some(Vector1::new(x + v.sample(&mut rng))) }).collect();
//! let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(10.0))?;
//! // θ = (ln Q, ln R).
//! let log_likelihood = |theta: &[f64]| {
//!     let process = LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(theta[0].exp()) };
//!     let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(theta[1].exp()) };
//!     sequence_log_likelihood(&Ekf::new(prior.clone()), &process, &vec![Vector1::zeros(); 399], 1.0, &sensor, &zs)
//! };
//! let fit = MaximumLikelihood::new().maximize(log_likelihood, &[0.0, 0.0])?;
//! let se = fit.standard_errors()?;
//! // Within 3 standard errors of the truth (in ln units).
//! assert!((fit.parameters[0] - 0.04f64.ln()).abs() < 3.0 * se[0]);
//! assert!((fit.parameters[1] - 0.25f64.ln()).abs() < 3.0 * se[1]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use core::cell::Cell;

use argmin::core::{CostFunction, Executor, Gradient, State, TerminationReason};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, OVector};
use estim_core::propagate::{MomentPropagator, PropagatorWorkspace};
use estim_core::{Alloc, MeasurementModel, ProcessModel, Real, StateSpace, Transition};

use super::{NoiseIdError, OptimizerFailure, Setting, Unidentifiable};
use crate::gaussian_filter::GaussianFilter;
use crate::smoother::filter_sequence;
use crate::traits::Update;

/// The maximum-likelihood optimiser (module docs): L-BFGS on −ℓ with numerical gradients,
/// then a Newton polish and the finite-difference Hessian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaximumLikelihood {
    max_iterations: usize,
    tolerance: f64,
    memory: usize,
}

impl Default for MaximumLikelihood {
    fn default() -> Self {
        Self {
            max_iterations: 200,
            tolerance: 1e-9,
            memory: 7,
        }
    }
}

/// The maximum-likelihood estimate and its uncertainty.
#[derive(Clone, Debug, PartialEq)]
pub struct MlEstimate {
    /// θ̂.
    pub parameters: Vec<f64>,
    /// ℓ(θ̂).
    pub log_likelihood: f64,
    /// ∇²ℓ(θ̂) by central differences (p × p, symmetric).
    pub hessian: DMatrix<f64>,
    /// L-BFGS iterations run.
    pub iterations: usize,
    /// Evaluations of ℓ, the Hessian's included.
    pub evaluations: usize,
    /// Whether L-BFGS met its gradient or cost tolerance (rather than its iteration cap or a
    /// line search that could not improve further, which near the optimum is round-off).
    pub converged: bool,
}

impl MlEstimate {
    /// The asymptotic covariance (−∇²ℓ(θ̂))⁻¹ of θ̂.
    ///
    /// Errors: [`Unidentifiable::FlatLikelihood`] naming the first parameter along which
    /// −∇²ℓ is not positive definite.
    pub fn covariance(&self) -> Result<DMatrix<f64>, NoiseIdError> {
        let information = -&self.hessian;
        let p = information.nrows();
        // Cholesky, column by column, to name the first failing parameter.
        let mut l = DMatrix::<f64>::zeros(p, p);
        for j in 0..p {
            let mut d = information[(j, j)];
            for k in 0..j {
                d -= l[(j, k)] * l[(j, k)];
            }
            if !(d > 0.0 && d.is_finite()) {
                return Err(NoiseIdError::Unidentifiable(
                    Unidentifiable::FlatLikelihood { index: j },
                ));
            }
            l[(j, j)] = d.sqrt();
            for i in (j + 1)..p {
                let mut s = information[(i, j)];
                for k in 0..j {
                    s -= l[(i, k)] * l[(j, k)];
                }
                l[(i, j)] = s / l[(j, j)];
            }
        }
        let factor = estim_core::nalgebra::Cholesky::pack_dirty(l);
        Ok(factor.inverse())
    }

    /// The standard errors √diag((−∇²ℓ)⁻¹) of θ̂; errors as [`covariance`](Self::covariance).
    pub fn standard_errors(&self) -> Result<Vec<f64>, NoiseIdError> {
        let c = self.covariance()?;
        Ok((0..c.nrows()).map(|i| c[(i, i)].sqrt()).collect())
    }
}

impl MaximumLikelihood {
    /// At most 200 L-BFGS iterations, gradient tolerance 10⁻⁹ on the scaled cost, memory 7.
    pub fn new() -> Self {
        Self::default()
    }

    /// At most `n` L-BFGS iterations (≥ 1).
    pub fn with_max_iterations(mut self, n: usize) -> Result<Self, NoiseIdError> {
        super::check_iteration_settings(n, self.tolerance)?;
        self.max_iterations = n;
        Ok(self)
    }

    /// Stop when the gradient of −ℓ/(1 + |ℓ(θ₀)|) has norm ≤ `tolerance` (finite, ≥ 0), or
    /// the scaled cost changes by less than ε.
    pub fn with_tolerance(mut self, tolerance: f64) -> Result<Self, NoiseIdError> {
        super::check_iteration_settings(self.max_iterations, tolerance)?;
        self.tolerance = tolerance;
        Ok(self)
    }

    /// The number of correction pairs L-BFGS keeps (≥ 1).
    pub fn with_memory(mut self, memory: usize) -> Result<Self, NoiseIdError> {
        if memory == 0 {
            return Err(NoiseIdError::InvalidSetting {
                setting: Setting::Memory,
                value: 0.0,
            });
        }
        self.memory = memory;
        Ok(self)
    }

    /// Maximises `log_likelihood` from `initial` (module docs).
    ///
    /// `log_likelihood(θ)` must be finite for every θ the search visits: map θ to a model so
    /// that every θ ∈ ℝᵖ is valid (log-variances, Cholesky entries). Errors: an
    /// [`InvalidSetting`](NoiseIdError::InvalidSetting) for an empty or non-finite `initial`;
    /// the first error `log_likelihood` returned, if the search did not get past it;
    /// [`OptimizerFailure::NonFiniteOptimum`] if ℓ is not finite where the search ended.
    pub fn maximize<F>(
        &self,
        log_likelihood: F,
        initial: &[f64],
    ) -> Result<MlEstimate, NoiseIdError>
    where
        F: Fn(&[f64]) -> Result<f64, NoiseIdError>,
    {
        if initial.is_empty() || initial.iter().any(|v| !v.is_finite()) {
            return Err(NoiseIdError::InvalidSetting {
                setting: Setting::InitialParameter,
                value: initial
                    .iter()
                    .copied()
                    .find(|v| !v.is_finite())
                    .unwrap_or(0.0),
            });
        }
        let counted = Counted {
            function: &log_likelihood,
            evaluations: Cell::new(0),
            first_error: Cell::new(None),
        };
        let l0 = counted.eval(initial)?;
        let problem = Problem {
            counted: &counted,
            scale: 1.0 + l0.abs(),
        };
        let line_search = MoreThuenteLineSearch::new();
        let solver = LBFGS::new(line_search, self.memory)
            .with_tolerance_grad(self.tolerance)
            .and_then(|s| s.with_tolerance_cost(f64::EPSILON))
            .map_err(|_| NoiseIdError::Optimizer(OptimizerFailure::Internal))?;
        let max_iterations = self.max_iterations as u64;
        let result = Executor::new(problem, solver)
            .configure(|state| state.param(initial.to_vec()).max_iters(max_iterations))
            .timer(false)
            .run();
        let (mut theta, iterations, converged) = match result {
            Ok(result) => {
                let state = result.state();
                let converged = matches!(
                    state.get_termination_reason(),
                    Some(TerminationReason::SolverConverged)
                );
                let best = state
                    .get_best_param()
                    .cloned()
                    .unwrap_or_else(|| initial.to_vec());
                (best, state.get_iter() as usize, converged)
            }
            Err(_) => match counted.first_error.get() {
                Some(error) => return Err(error),
                None => return Err(NoiseIdError::Optimizer(OptimizerFailure::Internal)),
            },
        };
        let mut value = counted.eval(&theta)?;
        if !value.is_finite() {
            return Err(NoiseIdError::Optimizer(OptimizerFailure::NonFiniteOptimum));
        }
        let mut hessian = counted.hessian(&theta, value)?;
        // One Newton step θ − H⁻¹ g, kept if ℓ rises.
        let gradient = DVector::from_vec(counted.gradient(&theta)?);
        if let Some(step) = (-&hessian).cholesky().map(|c| c.solve(&gradient)) {
            let candidate: Vec<f64> = theta.iter().zip(step.iter()).map(|(t, s)| t + s).collect();
            if let Ok(v) = counted.eval(&candidate)
                && v.is_finite()
                && v > value
            {
                theta = candidate;
                value = v;
                hessian = counted.hessian(&theta, value)?;
            }
        }
        Ok(MlEstimate {
            parameters: theta,
            log_likelihood: value,
            hessian,
            iterations,
            evaluations: counted.evaluations.get(),
            converged,
        })
    }
}

/// ℓ with an evaluation count and the first error it returned.
struct Counted<'a, F> {
    function: &'a F,
    evaluations: Cell<usize>,
    first_error: Cell<Option<NoiseIdError>>,
}

impl<F: Fn(&[f64]) -> Result<f64, NoiseIdError>> Counted<'_, F> {
    fn eval(&self, theta: &[f64]) -> Result<f64, NoiseIdError> {
        self.evaluations.set(self.evaluations.get() + 1);
        let value = (self.function)(theta);
        if let Err(error) = value
            && self.first_error.get().is_none()
        {
            self.first_error.set(Some(error));
        }
        value
    }

    fn at(&self, theta: &[f64], moves: &[(usize, f64)]) -> Result<f64, NoiseIdError> {
        let mut x = theta.to_vec();
        for &(i, d) in moves {
            x[i] += d;
        }
        self.eval(&x)
    }

    /// Central-difference gradient, hᵢ = ε^{1/3} max(|θᵢ|, 1).
    fn gradient(&self, theta: &[f64]) -> Result<Vec<f64>, NoiseIdError> {
        (0..theta.len())
            .map(|i| {
                let h = f64::EPSILON.cbrt() * theta[i].abs().max(1.0);
                Ok((self.at(theta, &[(i, h)])? - self.at(theta, &[(i, -h)])?) / (2.0 * h))
            })
            .collect()
    }

    /// Central second differences, hᵢ = ε^{1/4} max(|θᵢ|, 1); `value` = ℓ(θ).
    fn hessian(&self, theta: &[f64], value: f64) -> Result<DMatrix<f64>, NoiseIdError> {
        let p = theta.len();
        let h: Vec<f64> = theta
            .iter()
            .map(|t| f64::EPSILON.sqrt().sqrt() * t.abs().max(1.0))
            .collect();
        let mut hessian = DMatrix::zeros(p, p);
        for i in 0..p {
            let plus = self.at(theta, &[(i, h[i])])?;
            let minus = self.at(theta, &[(i, -h[i])])?;
            hessian[(i, i)] = (plus - 2.0 * value + minus) / (h[i] * h[i]);
            for j in 0..i {
                let pp = self.at(theta, &[(i, h[i]), (j, h[j])])?;
                let pm = self.at(theta, &[(i, h[i]), (j, -h[j])])?;
                let mp = self.at(theta, &[(i, -h[i]), (j, h[j])])?;
                let mm = self.at(theta, &[(i, -h[i]), (j, -h[j])])?;
                let v = (pp - pm - mp + mm) / (4.0 * h[i] * h[j]);
                hessian[(i, j)] = v;
                hessian[(j, i)] = v;
            }
        }
        Ok(hessian)
    }
}

/// The argmin problem: the scaled cost −ℓ(θ)/scale and its numerical gradient.
struct Problem<'a, 'f, F> {
    counted: &'a Counted<'f, F>,
    scale: f64,
}

/// The error argmin carries when ℓ failed (the typed error is kept in [`Counted`]).
#[derive(Debug, thiserror::Error)]
#[error("log-likelihood evaluation failed")]
struct EvaluationFailed;

impl<F: Fn(&[f64]) -> Result<f64, NoiseIdError>> CostFunction for Problem<'_, '_, F> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, theta: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        match self.counted.eval(theta) {
            Ok(v) if v.is_finite() => Ok(-v / self.scale),
            _ => Err(EvaluationFailed.into()),
        }
    }
}

impl<F: Fn(&[f64]) -> Result<f64, NoiseIdError>> Gradient for Problem<'_, '_, F> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;

    fn gradient(&self, theta: &Vec<f64>) -> Result<Vec<f64>, argmin::core::Error> {
        match self.counted.gradient(theta) {
            Ok(g) if g.iter().all(|v| v.is_finite()) => {
                Ok(g.into_iter().map(|v| -v / self.scale).collect())
            }
            _ => Err(EvaluationFailed.into()),
        }
    }
}

/// The prediction-error log-likelihood of one recorded sequence under a filter: `filter`
/// (cloned, so it is left as it is) run by [`filter_sequence`] over `measurements` (one more
/// than `inputs`; `None` = missing), as `f64`. The building block of a log-likelihood for
/// [`MaximumLikelihood::maximize`]; sum it over several sequences.
///
/// Errors: [`NoiseIdError::NonFiniteData`] for a non-finite measurement;
/// [`NoiseIdError::AllMissing`] if every measurement is missing; a failing filter step as
/// [`NoiseIdError::Pass`] (sequence 0).
pub fn sequence_log_likelihood<T, N, M, Pr, S, P, H>(
    filter: &GaussianFilter<T, N, Pr, S>,
    process: &P,
    inputs: &[P::Input],
    dt: T,
    measurement: &H,
    measurements: &[Option<OVector<T, M>>],
) -> Result<f64, NoiseIdError>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessModel<T, N>,
    H: MeasurementModel<T, N, M>,
    Pr: PropagatorWorkspace<T>
        + Clone
        + for<'a> MomentPropagator<T, N, N, Transition<'a, P, P::Input, T, S>>,
    S: StateSpace<T, N> + Clone,
    GaussianFilter<T, N, Pr, S>: Update<T, N, M, H>,
    DefaultAllocator: Alloc<N, M>,
{
    super::check_measurements(0, measurements)?;
    if measurements.iter().all(Option::is_none) {
        return Err(NoiseIdError::AllMissing);
    }
    let mut filter = filter.clone();
    let run = filter_sequence(&mut filter, process, inputs, dt, measurement, measurements)
        .map_err(|error| NoiseIdError::Pass { sequence: 0, error })?;
    Ok(run.log_likelihood.to_subset().unwrap_or(f64::NAN))
}
