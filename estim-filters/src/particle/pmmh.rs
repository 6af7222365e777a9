//! Particle marginal Metropolis-Hastings (documented on [`pmmh`]).

use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, OVector};
use estim_core::rand::RngCore;
use estim_core::rand_distr::{Distribution, StandardNormal};
use estim_core::{
    Alloc, Error, Gaussian, MeasurementModel, Parameter, ProcessModel, Quantity, Real, Stage,
    error::Result,
};

use super::ParticleFilter;
use super::resample::to_f64;
use super::rng::ParticleRng;
use crate::traits::{Predict, Update};

/// The longest chain [`pmmh`] runs (bounds memory and time).
pub const MAX_PMMH_ITERATIONS: usize = 10_000_000;

/// A PMMH (or Metropolis) chain: the states θ₀..θ_I (θ₀ the start) and their log-likelihood
/// estimates, and how many proposals were accepted.
#[derive(Clone, Debug, PartialEq)]
pub struct PmmhChain {
    /// The chain's states, one column per iteration (d × (I + 1), the first the start).
    pub samples: DMatrix<f64>,
    /// ℓ̂(θᵢ) of each state (the estimate held when the state was accepted).
    pub log_likelihoods: Vec<f64>,
    /// The number of accepted proposals.
    pub accepted: usize,
}

/// A [`pmmh`] chain stopped by an error: the iteration, what failed, and the chain as it stood
/// before that iteration (its states θ₀..θᵢ₋₁, unchanged by the failed proposal; empty for
/// iteration 0, the settings and the start). Resuming from the chain's last state with the same
/// seed does not give the same draws (iteration numbers restart); the partial chain is for
/// inspection.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("PMMH iteration {iteration}: {error}")]
pub struct PmmhError {
    /// The iteration whose proposal failed (0: the settings or the start).
    pub iteration: usize,
    /// What failed: e.g. [`Error::NonFinite`] with [`Quantity::FunctionValue`] for a model that
    /// gave NaN (a bug in the model, not a likelihood of zero).
    pub error: Error,
    /// The chain up to iteration − 1.
    pub chain: PmmhChain,
}

impl From<PmmhError> for Error {
    /// The error alone (the iteration and the partial chain dropped).
    fn from(e: PmmhError) -> Self {
        e.error
    }
}

impl PmmhChain {
    /// The fraction of proposals accepted (0 for a chain of no iterations).
    pub fn acceptance_rate(&self) -> f64 {
        let iterations = self.samples.ncols().saturating_sub(1);
        if iterations == 0 {
            0.0
        } else {
            self.accepted as f64 / iterations as f64
        }
    }
}

/// Particle marginal Metropolis-Hastings (PMMH; Andrieu, Doucet & Holenstein 2010): Bayesian
/// parameter learning through a particle filter's likelihood estimate.
///
/// For a model parameterised by θ ∈ ℝᵈ (the user's map θ ↦ model, inside a closure) with
/// prior log-density log p(θ), a Gaussian random walk proposes θ' = θ + L ε (ε ~ N(0, I), L
/// the user's d × d scale: L Lᵀ is the proposal covariance), and θ' is accepted with
/// probability
///
/// ```text
/// α = min(1, exp(ℓ̂(θ') + log p(θ') − ℓ̂(θ) − log p(θ)))
/// ```
///
/// where ℓ̂(θ) is a particle filter's log-likelihood estimate ([`particle_log_likelihood`], or
/// any estimate the closure computes). Because exp ℓ̂ is an *unbiased* estimate of
/// p(z₁..T | θ) (the filter's likelihood is unbiased under adaptive resampling too), the
/// chain's stationary law is the exact posterior p(θ | z₁..T), whatever the particle count:
/// few particles only make the chain stickier. The current state's estimate ℓ̂(θ) is kept,
/// never recomputed (recomputing it would break exactness).
///
/// With a closure returning the exact log-likelihood (e.g. a Kalman filter's), the same
/// function is a plain random-walk Metropolis sampler.
///
/// Randomness: iteration i draws ε from the stream (seed, i, 0) and its acceptance uniform
/// from (seed, i, 1) ([`ParticleRng`]), and passes the closure the seed (seed, i) hashed
/// into one `u64` for the filter it runs; a seed gives the same chain bit for bit.
///
/// Runs `iterations` steps of PMMH (above) from `start` with random-walk scale `scale`
/// (L, d × d; the proposal is θ + L ε), prior log-density `log_prior` (−∞ outside the
/// support: such a proposal is rejected without running the filter) and log-likelihood
/// estimate `log_likelihood(θ, seed)` (`Ok(−∞)` for a likelihood of zero, which rejects the
/// proposal; any error stops the chain and is returned with its iteration).
///
/// Errors ([`PmmhError`]: the iteration, the error, the chain before that iteration):
/// `iterations` above [`MAX_PMMH_ITERATIONS`] ([`Parameter::StepCount`]); `scale` not d × d
/// ([`Error::DimensionMismatch`]) or not finite; a start whose prior or likelihood is not
/// finite ([`Error::NonFinite`] with [`Quantity::Mean`] for θ, [`Quantity::Weights`] for its
/// likelihood: a chain cannot start where the posterior is zero); a prior that is NaN or +∞
/// ([`Quantity::Mean`]); an estimate that is NaN or +∞ ([`Quantity::Weights`]); an error of
/// the closure (with [`particle_log_likelihood`]: a model giving NaN, [`Quantity::FunctionValue`]).
///
/// ```
/// use estim_core::nalgebra::{DMatrix, DVector, Matrix1, Vector1};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::particle::{particle_log_likelihood, pmmh};
///
/// // z = x + v with x ~ AR(1), coefficient θ unknown (true 0.8), prior uniform on (−1, 1).
/// let zs: Vec<Vector1<f64>> = [0.3, 1.2, 0.9, 1.5, 0.4, -0.2, 0.1, 0.8].map(Vector1::new).to_vec();
/// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(0.5) };
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let chain = pmmh(
///     &DVector::from_element(1, 0.5),
///     &DMatrix::from_element(1, 1, 0.3),
///     200,
///     7,
///     |theta| if theta[0].abs() < 1.0 { 0.0 } else { f64::NEG_INFINITY },
///     |theta, seed| {
///         let process = LinearProcess::without_input(Matrix1::new(theta[0]), Matrix1::new(0.5));
///         particle_log_likelihood(&prior, &process, &(), 1.0, &sensor, &zs, 50, seed)
///     },
/// )?;
/// assert_eq!(chain.samples.ncols(), 201);
/// assert!(chain.samples.iter().all(|t| t.abs() < 1.0)); // never leaves the prior's support
/// assert!(chain.acceptance_rate() > 0.05);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn pmmh<P, L>(
    start: &DVector<f64>,
    scale: &DMatrix<f64>,
    iterations: usize,
    seed: u64,
    mut log_prior: P,
    mut log_likelihood: L,
) -> core::result::Result<PmmhChain, PmmhError>
where
    P: FnMut(&DVector<f64>) -> f64,
    L: FnMut(&DVector<f64>, u64) -> Result<f64>,
{
    let d = start.nrows();
    let at_start = |error| PmmhError {
        iteration: 0,
        error,
        chain: PmmhChain {
            samples: DMatrix::zeros(d, 0),
            log_likelihoods: Vec::new(),
            accepted: 0,
        },
    };
    let mut current = start.clone();
    let (mut current_prior, mut current_ll) = chain_start(
        start,
        scale,
        iterations,
        seed,
        &mut log_prior,
        &mut log_likelihood,
    )
    .map_err(at_start)?;
    let mut samples = DMatrix::zeros(d, iterations + 1);
    samples.set_column(0, &current);
    let mut log_likelihoods = Vec::with_capacity(iterations + 1);
    log_likelihoods.push(current_ll);
    let mut accepted = 0;
    let mut noise = DVector::zeros(d);
    let mut proposal = DVector::zeros(d);
    for i in 1..=iterations {
        let step = i as u64;
        let mut rng = ParticleRng::stream(seed, step, 0);
        for v in noise.iter_mut() {
            *v = StandardNormal.sample(&mut rng);
        }
        proposal.copy_from(&current);
        proposal.gemv(1.0, scale, &noise, 1.0);
        let prior = log_prior(&proposal);
        #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
        let nan = prior != prior;
        let evaluated = if nan || prior == f64::INFINITY {
            Err(Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Mean,
            })
        } else if prior > f64::NEG_INFINITY {
            log_likelihood(&proposal, evaluation_seed(seed, step))
                .and_then(checked)
                .map(Some)
        } else {
            Ok(None)
        };
        let evaluated = match evaluated {
            Ok(evaluated) => evaluated,
            Err(error) => {
                // The chain before this iteration: its first i columns.
                return Err(PmmhError {
                    iteration: i,
                    error,
                    chain: PmmhChain {
                        samples: samples.columns(0, i).into_owned(),
                        log_likelihoods,
                        accepted,
                    },
                });
            }
        };
        if let Some(ll) = evaluated {
            let log_ratio = ll + prior - current_ll - current_prior;
            let u = ParticleRng::stream(seed, step, 1).uniform();
            if u.ln() < log_ratio {
                current.copy_from(&proposal);
                current_prior = prior;
                current_ll = ll;
                accepted += 1;
            }
        }
        samples.set_column(i, &current);
        log_likelihoods.push(current_ll);
    }
    Ok(PmmhChain {
        samples,
        log_likelihoods,
        accepted,
    })
}

/// Checks the settings and the start; its log prior and log-likelihood estimate.
fn chain_start<P, L>(
    start: &DVector<f64>,
    scale: &DMatrix<f64>,
    iterations: usize,
    seed: u64,
    log_prior: &mut P,
    log_likelihood: &mut L,
) -> Result<(f64, f64)>
where
    P: FnMut(&DVector<f64>) -> f64,
    L: FnMut(&DVector<f64>, u64) -> Result<f64>,
{
    let d = start.nrows();
    if iterations > MAX_PMMH_ITERATIONS {
        return Err(Error::InvalidParameter {
            parameter: Parameter::StepCount,
            value: iterations as f64,
        });
    }
    estim_core::checks::ensure_shape(scale, d, d, Stage::Construction, Quantity::Covariance)?;
    estim_core::checks::ensure_finite(scale, Stage::Construction, Quantity::Covariance)?;
    estim_core::checks::ensure_finite(start, Stage::Construction, Quantity::Mean)?;
    let not_finite = |quantity| Error::NonFinite {
        stage: Stage::Construction,
        quantity,
    };
    let prior = log_prior(start);
    if !prior.is_finite() {
        return Err(not_finite(Quantity::Mean));
    }
    let ll = checked(log_likelihood(start, evaluation_seed(seed, 0))?)?;
    if ll == f64::NEG_INFINITY {
        return Err(not_finite(Quantity::Weights));
    }
    Ok((prior, ll))
}

/// The seed passed to the likelihood estimate of iteration `step`.
fn evaluation_seed(seed: u64, step: u64) -> u64 {
    ParticleRng::stream(seed, step, 2).next_u64()
}

/// A log-likelihood estimate must not be NaN or +∞.
fn checked(value: f64) -> Result<f64> {
    #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
    let nan = value != value;
    if nan || value == f64::INFINITY {
        Err(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Weights,
        })
    } else {
        Ok(value)
    }
}

/// The bootstrap particle filter's log-likelihood estimate log p̂(z₁..T) over `readings`
/// (`count` particles from `prior`, seeded by `seed`; before each reading a prediction through
/// `process` with `input` over `dt`), in f64 for [`pmmh`]. A reading that no particle
/// explains (every weight zero: [`Error::NonFinite`] with [`Quantity::Weights`] from the
/// update) gives `Ok(−∞)`, a likelihood estimate of 0 that [`pmmh`] rejects. Other errors are
/// returned, among them a model that gives NaN (h(x) or the log-density:
/// [`Quantity::FunctionValue`]), which is a bug to fix, not a parameter to reject.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::particle::particle_log_likelihood;
/// use estim_filters::{KalmanFilter, Predict, Update};
///
/// let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
/// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let zs = [0.4, -0.3, 1.1].map(Vector1::new);
/// let estimate = particle_log_likelihood(&prior, &process, &(), 1.0, &sensor, &zs, 5000, 1)?;
/// let mut kf = KalmanFilter::new(prior);
/// let mut exact = 0.0;
/// for z in &zs {
///     kf.predict(&process, &(), 1.0)?;
///     exact += kf.update(&sensor, z)?.log_likelihood;
/// }
/// // Var ℓ̂ ≈ 0.8 T/N for this model (T = 3 readings, N = 5000): sd ≈ 0.02.
/// assert!((estimate - exact).abs() < 0.1);
/// # Ok::<(), estim_core::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn particle_log_likelihood<T, N, M, P, H>(
    prior: &Gaussian<T, N>,
    process: &P,
    input: &P::Input,
    dt: T,
    sensor: &H,
    readings: &[OVector<T, M>],
    count: usize,
    seed: u64,
) -> Result<f64>
where
    T: Real,
    N: Dim,
    M: Dim,
    P: ProcessModel<T, N> + Sync,
    P::Input: Sync,
    H: MeasurementModel<T, N, M> + Sync,
    DefaultAllocator: Alloc<N, M>,
{
    let mut filter = ParticleFilter::new(prior.clone(), count, seed)?;
    for z in readings {
        filter.predict(process, input, dt)?;
        match filter.update(sensor, z) {
            Ok(_) => {}
            Err(Error::NonFinite {
                quantity: Quantity::Weights,
                ..
            }) => {
                return Ok(f64::NEG_INFINITY);
            }
            Err(error) => return Err(error),
        }
    }
    Ok(to_f64(filter.log_likelihood()))
}
