//! Expectation–maximisation for time-invariant linear-Gaussian models
//! (Shumway & Stoffer 1982; Särkkä 2013, §12.2.3).
//!
//! The model ([`LinearGaussian`]) is
//!
//! ```text
//! x₀ ~ N(μ₀, P₀),   xₖ₊₁ = F xₖ + B uₖ + wₖ, wₖ ~ N(0, Q),   zₖ = H xₖ + vₖ, vₖ ~ N(0, R)
//! ```
//!
//! over one or many recorded sequences, each with its inputs and its measurements (`None` where
//! missing). Each iteration is:
//!
//! - **E-step**: for each sequence, the Kalman filter and the RTS smoother with lag-one
//!   cross-covariances ([`smooth_sequence_with_cross_covariances`]): x̂ˢₖ, Pˢₖ and
//!   Pₖ₊₁,ₖ|K, and the prediction-error log-likelihood ℓ of the current model. With
//!   yₖ = x̂ˢₖ₊₁ − B uₖ, the expected sufficient statistics over all sequences are
//!   ```text
//!   S₀₀ = Σ Pˢₖ + x̂ˢₖ x̂ˢₖᵀ   S₁₀ = Σ Pₖ₊₁,ₖ|K + yₖ x̂ˢₖᵀ   S₁₁ = Σ Pˢₖ₊₁ + yₖ yₖᵀ   (T transitions)
//!   Szz = Σ zₖ zₖᵀ   Szx = Σ zₖ x̂ˢₖᵀ   Sxx = Σ Pˢₖ + x̂ˢₖ x̂ˢₖᵀ                         (O observed times)
//!   ```
//!   (The noise covariances below are evaluated in the equivalent centred form
//!   Σ [Pˢₖ₊₁ − F Pₖ₊₁,ₖ|Kᵀ − Pₖ₊₁,ₖ|K Fᵀ + F Pˢₖ Fᵀ + (yₖ − F x̂ˢₖ)(yₖ − F x̂ˢₖ)ᵀ], which
//!   keeps its precision when the states are large against the noise.)
//! - **M-step**, in closed form, one block at a time given the others (an ECM step, Meng &
//!   Rubin 1993, which keeps the monotone likelihood):
//!   ```text
//!   F = S₁₀ S₀₀⁻¹                      Q̄ = (S₁₁ − F S₁₀ᵀ − S₁₀ Fᵀ + F S₀₀ Fᵀ) / T
//!   H = Szx Sxx⁻¹                      R̄ = (Szz − H Szxᵀ − Szx Hᵀ + H Sxx Hᵀ) / O
//!   μ₀ = mean of x̂ˢ₀                   P̄₀ = mean of Pˢ₀ + (x̂ˢ₀ − μ₀)(x̂ˢ₀ − μ₀)ᵀ
//!   ```
//!   and each covariance is then Q̄ itself ([`CovarianceStructure::Full`]), its diagonal
//!   (`Diagonal`, some entries possibly held: `DiagonalWithFixed`), or c · S with
//!   c = tr(S⁺ Q̄) / rank S (`ScalarMultiple(S)`, the maximiser over c, S possibly singular:
//!   e.g. Q = W Γ Γᵀ for a scalar noise W entering through Γ). F or H with only some entries free
//!   ([`MatrixStructure::FreeEntries`]) solve the generalised least-squares normal equations
//!   \[Q⁻¹ (F S₀₀ − S₁₀)\]ᵢⱼ = 0 on the free entries (R⁻¹ and the measurement statistics for H).
//!
//! The log-likelihood of every iteration's model is recorded ([`EmEstimate::history`]); it never
//! decreases beyond round-off (EM's defining property; the tests assert it). EM stops when an
//! iteration raises ℓ by at most `tolerance · (1 + |ℓ|)`, or after `max_iterations` E-steps, and
//! returns the model with the highest recorded ℓ (the last one, unless round-off at convergence
//! made the last step a hair lower). EM does not give standard errors: use
//! [`likelihood`](super) (feature `likelihood`) at its optimum for those.
//!
//! **Before the first E-step** every free covariance is put in its structure (off-diagonals of a
//! diagonal structure zeroed, a scalar multiple fitted as c = tr(S⁺ Q)/rank S), so that the
//! starting model belongs to the family being searched and the first step cannot decrease ℓ.
//!
//! **Identifiability** (checked up front, [`Unidentifiable`]): F, H and Q all free lets any
//! change of state coordinates explain the data; H entirely free with a free Q leaves the scale
//! of the state free; Q or F free needs a transition; a scalar multiple needs a nonzero PSD
//! shape. P₀ is estimable only from many sequences: with one, its EM estimate shrinks towards
//! the smoothed covariance of x₀ (the likelihood has no interior maximum in P₀); keep it fixed.
//!
//! ```
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_core::nalgebra::{Matrix1, Vector1};
//! use estim_core::rand::{SeedableRng, rngs::StdRng};
//! use estim_core::rand_distr::{Distribution, Normal};
//! use estim_filters::noise_id::{CovarianceStructure, EmSettings, LinearGaussian, Record, em::estimate};
//!
//! // A random walk with Q = 0.04 seen through noise R = 0.25; EM starts from Q = R = 1.
//! let (mut rng, mut x) = (StdRng::seed_from_u64(3), 0.0);
//! let (w, v) = (Normal::new(0.0, 0.2)?, Normal::new(0.0, 0.5)?);
//! let zs: Vec<_> = (0..400).map(|_| { x += w.sample(&mut rng); Some(Vector1::new(x + v.sample(&mut rng))) }).collect();
//! let inputs = vec![Vector1::<f64>::zeros(); 399];
//! let model = LinearGaussian {
//!     process: LinearProcess { transition: Matrix1::new(1.0), input: Matrix1::zeros(), noise: Matrix1::new(1.0) },
//!     measurement: LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) },
//!     prior: Gaussian::new(Vector1::new(0.0), Matrix1::new(10.0))?,
//! };
//! let settings = EmSettings::new()
//!     .with_process_noise(CovarianceStructure::Full)
//!     .with_measurement_noise(CovarianceStructure::Full)
//!     .with_iterations(100, 1e-8)?;
//! let fit = estimate(&model, &settings, &[Record { inputs: &inputs, measurements: &zs }])?;
//! assert!(fit.history.windows(2).all(|w| w[1] >= w[0] - 1e-9 * w[0].abs()));
//! assert!((fit.model.process.noise[(0, 0)] - 0.04).abs() < 0.02);
//! assert!((fit.model.measurement.noise[(0, 0)] - 0.25).abs() < 0.05);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use estim_core::checks::{all_finite, ensure_finite, ensure_psd, ensure_symmetric, symmetrize};
use estim_core::nalgebra::{DMatrix, DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess, Quantity, Real, Stage};

use super::{NoiseIdError, Unidentifiable, check_iteration_settings, check_measurements};
use crate::gaussian_filter::KalmanFilter;
use crate::smoother::smooth_sequence_with_cross_covariances;

/// A time-invariant linear-Gaussian state-space model: process, measurement and prior.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearGaussian<T: Real, N: Dim, M: Dim, U: Dim>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    /// x⁺ = F x + B u + w, w ~ N(0, Q).
    pub process: LinearProcess<T, N, U>,
    /// z = H x + v, v ~ N(0, R).
    pub measurement: LinearMeasurement<T, N, M>,
    /// x₀ ~ N(μ₀, P₀).
    pub prior: Gaussian<T, N>,
}

/// What EM may change in a covariance (Q, R or P₀).
#[derive(Clone, Debug, PartialEq)]
pub enum CovarianceStructure<T: Real, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// Held at its starting value.
    Fixed,
    /// Any symmetric positive semi-definite matrix.
    Full,
    /// Diagonal, every variance free.
    Diagonal,
    /// Diagonal, with the listed diagonal entries held at their starting values.
    DiagonalWithFixed(Vec<usize>),
    /// c · S for the given shape S (symmetric PSD, nonzero, possibly singular), c ≥ 0 free.
    ScalarMultiple(OMatrix<T, D, D>),
}

impl<T: Real, D: Dim> CovarianceStructure<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn is_free(&self) -> bool {
        !matches!(self, Self::Fixed)
    }
}

/// What EM may change in F or H.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MatrixStructure {
    /// Held at its starting value.
    Fixed,
    /// Every entry free.
    Free,
    /// The listed (row, column) entries free, the others held.
    FreeEntries(Vec<(usize, usize)>),
}

impl MatrixStructure {
    fn is_free(&self) -> bool {
        match self {
            Self::Fixed => false,
            Self::Free => true,
            Self::FreeEntries(entries) => !entries.is_empty(),
        }
    }
}

/// What EM estimates, and when it stops. [`new`](Self::new) frees nothing (EM then evaluates
/// the starting model's log-likelihood once).
#[derive(Clone, Debug, PartialEq)]
pub struct EmSettings<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Structure of Q.
    pub process_noise: CovarianceStructure<T, N>,
    /// Structure of R.
    pub measurement_noise: CovarianceStructure<T, M>,
    /// Whether μ₀ is estimated.
    pub initial_mean: bool,
    /// Structure of P₀.
    pub initial_covariance: CovarianceStructure<T, N>,
    /// Structure of F.
    pub transition: MatrixStructure,
    /// Structure of H.
    pub observation: MatrixStructure,
    /// At most this many E-steps (≥ 1).
    pub max_iterations: usize,
    /// Stop when an iteration raises ℓ by ≤ `tolerance · (1 + |ℓ|)` (finite, ≥ 0).
    pub tolerance: T,
}

impl<T: Real, N: Dim, M: Dim> Default for EmSettings<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn default() -> Self {
        Self {
            process_noise: CovarianceStructure::Fixed,
            measurement_noise: CovarianceStructure::Fixed,
            initial_mean: false,
            initial_covariance: CovarianceStructure::Fixed,
            transition: MatrixStructure::Fixed,
            observation: MatrixStructure::Fixed,
            max_iterations: 200,
            tolerance: T::from_f64(1e-9).unwrap_or_else(T::default_epsilon),
        }
    }
}

impl<T: Real, N: Dim, M: Dim> EmSettings<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Nothing free; at most 200 iterations, tolerance 10⁻⁹.
    pub fn new() -> Self {
        Self::default()
    }

    /// Q's structure.
    pub fn with_process_noise(mut self, structure: CovarianceStructure<T, N>) -> Self {
        self.process_noise = structure;
        self
    }

    /// R's structure.
    pub fn with_measurement_noise(mut self, structure: CovarianceStructure<T, M>) -> Self {
        self.measurement_noise = structure;
        self
    }

    /// μ₀ free or not, and P₀'s structure.
    pub fn with_prior(mut self, mean: bool, covariance: CovarianceStructure<T, N>) -> Self {
        self.initial_mean = mean;
        self.initial_covariance = covariance;
        self
    }

    /// F's structure.
    pub fn with_transition(mut self, structure: MatrixStructure) -> Self {
        self.transition = structure;
        self
    }

    /// H's structure.
    pub fn with_observation(mut self, structure: MatrixStructure) -> Self {
        self.observation = structure;
        self
    }

    /// The iteration cap (≥ 1) and tolerance (finite, ≥ 0).
    pub fn with_iterations(mut self, max: usize, tolerance: T) -> Result<Self, NoiseIdError> {
        check_iteration_settings(max, tolerance.to_subset().unwrap_or(f64::NAN))?;
        self.max_iterations = max;
        self.tolerance = tolerance;
        Ok(self)
    }
}

/// One recorded sequence: the inputs u₀ … u_{K−1} and the measurements z₀ … z_K (`None` where
/// missing): `measurements.len() == inputs.len() + 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record<'a, T: Real, M: Dim, U: Dim>
where
    DefaultAllocator: Alloc<M, U>,
{
    /// uₖ, k = 0 … K − 1.
    pub inputs: &'a [OVector<T, U>],
    /// zₖ, k = 0 … K.
    pub measurements: &'a [Option<OVector<T, M>>],
}

/// What EM returns.
#[derive(Clone, Debug, PartialEq)]
pub struct EmEstimate<T: Real, N: Dim, M: Dim, U: Dim>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    /// The estimated model.
    pub model: LinearGaussian<T, N, M, U>,
    /// Its log-likelihood (summed over the sequences).
    pub log_likelihood: T,
    /// The log-likelihood of each iteration's model, first (the starting model) to last. When
    /// an iteration decreased ℓ, the model before it is returned, so the last entry is then
    /// below [`log_likelihood`](Self::log_likelihood).
    pub history: Vec<T>,
    /// Whether the tolerance was met, or ℓ decreased by no more than it (round-off at the
    /// optimum); `false` at the iteration cap or after a larger decrease.
    pub converged: bool,
}

/// The expected sufficient statistics of one E-step (module docs). The raw second moments
/// (S₀₀, S₁₀, Szx, Sxx) serve the regressions for F and H; the noise covariances are formed
/// from the covariance sums and the per-step mean residuals instead, because S₁₁ − F S₁₀ᵀ − …
/// cancels catastrophically when the states are large against the noise (Lu: positions of
/// tens of metres, process noise of 10⁻¹¹ m² per epoch).
struct Statistics<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    s00: OMatrix<T, N, N>,
    s10: OMatrix<T, N, N>,
    /// Σ Pˢₖ, Σ Pₖ₊₁,ₖ|K, Σ Pˢₖ₊₁ over the transitions.
    cov00: OMatrix<T, N, N>,
    cov10: OMatrix<T, N, N>,
    cov11: OMatrix<T, N, N>,
    /// (x̂ˢₖ, yₖ) of every transition.
    transition_means: Vec<MeanPair<T, N, N>>,
    szx: OMatrix<T, M, N>,
    sxx: OMatrix<T, N, N>,
    /// Σ Pˢₖ over the observed times.
    covxx: OMatrix<T, N, N>,
    /// (x̂ˢₖ, zₖ) of every observed time.
    observed_means: Vec<MeanPair<T, N, M>>,
    initial_means: Vec<OVector<T, N>>,
    initial_covariance_sum: OMatrix<T, N, N>,
}

/// A smoothed mean x̂ₖ and the vector it predicts (yₖ or zₖ).
type MeanPair<T, C, R> = (OVector<T, C>, OVector<T, R>);

/// A scalar-multiple shape, prepared: S, S⁺, rank S.
struct Shape<T: Real, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    pseudo_inverse: OMatrix<T, D, D>,
    rank: usize,
}

/// EM from `initial` over `records` (module docs).
///
/// Errors: [`NoiseIdError::SequenceLength`] (no record, or lengths that disagree);
/// [`NoiseIdError::NonFiniteData`]; [`NoiseIdError::AllMissing`];
/// [`NoiseIdError::Unidentifiable`]; [`NoiseIdError::Model`] for a starting model that is not
/// finite or whose covariances are not symmetric PSD (and for an F or H with free entries whose
/// weighting Q or R is singular); [`NoiseIdError::Pass`] for a failing filter or smoother step.
///
/// # Panics
///
/// If a [`MatrixStructure::FreeEntries`] or [`CovarianceStructure::DiagonalWithFixed`] index
/// is outside its matrix (a programmer error).
#[track_caller]
pub fn estimate<T: Real, N: Dim, M: Dim, U: Dim>(
    initial: &LinearGaussian<T, N, M, U>,
    settings: &EmSettings<T, N, M>,
    records: &[Record<'_, T, M, U>],
) -> Result<EmEstimate<T, N, M, U>, NoiseIdError>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U> + Alloc<M, U>,
{
    check_iteration_settings(
        settings.max_iterations,
        settings.tolerance.to_subset().unwrap_or(f64::NAN),
    )?;
    check_records(records)?;
    check_model(initial)?;
    let (n, m) = (
        initial.prior.mean().shape_generic().0,
        initial.measurement.observation.shape_generic().0,
    );
    check_indices(settings, n.value(), m.value());
    check_identifiable(settings, records)?;
    let q_shape = prepare_shape(&settings.process_noise, Quantity::ProcessNoise)?;
    let r_shape = prepare_shape(&settings.measurement_noise, Quantity::MeasurementNoise)?;
    let p_shape = prepare_shape(&settings.initial_covariance, Quantity::Covariance)?;

    // The starting model, put in its structure.
    let mut model = initial.clone();
    model.process.noise = structured(
        &settings.process_noise,
        q_shape.as_ref(),
        &model.process.noise,
        &model.process.noise,
    );
    model.measurement.noise = structured(
        &settings.measurement_noise,
        r_shape.as_ref(),
        &model.measurement.noise,
        &model.measurement.noise,
    );
    let p0 = structured(
        &settings.initial_covariance,
        p_shape.as_ref(),
        model.prior.covariance(),
        model.prior.covariance(),
    );
    model.prior = Gaussian::new_unchecked(model.prior.mean().clone(), p0);

    let nothing_free = !(settings.process_noise.is_free()
        || settings.measurement_noise.is_free()
        || settings.initial_mean
        || settings.initial_covariance.is_free()
        || settings.transition.is_free()
        || settings.observation.is_free());
    let tolerance = settings.tolerance;
    let mut history: Vec<T> = Vec::new();
    let mut previous: Option<LinearGaussian<T, N, M, U>> = None;
    let mut converged = false;
    loop {
        let (ll, stats) = expectation(&model, records, n, m)?;
        let last = history.last().copied();
        history.push(ll);
        if let (Some(last), Some(prev)) = (last, previous.take()) {
            if ll < last {
                // EM never decreases ℓ in exact arithmetic. A decrease within the tolerance is
                // round-off at convergence; a larger one means the M-step lost accuracy (an
                // ill-conditioned regression), which must not be reported as converged. Either
                // way the better model is kept.
                let roundoff = last - ll <= tolerance * (T::one() + last.abs());
                return Ok(EmEstimate {
                    model: prev,
                    log_likelihood: last,
                    history,
                    converged: roundoff,
                });
            }
            if ll - last <= tolerance * (T::one() + ll.abs()) {
                converged = true;
                break;
            }
        }
        if nothing_free {
            converged = true;
            break;
        }
        if history.len() >= settings.max_iterations {
            break;
        }
        let next = maximization(&model, &stats, settings, [&q_shape, &p_shape], &r_shape)?;
        previous = Some(core::mem::replace(&mut model, next));
    }
    let log_likelihood = *history.last().expect("at least one E-step");
    Ok(EmEstimate {
        model,
        log_likelihood,
        history,
        converged,
    })
}

fn check_records<T: Real, M: Dim, U: Dim>(
    records: &[Record<'_, T, M, U>],
) -> Result<(), NoiseIdError>
where
    DefaultAllocator: Alloc<M, U>,
{
    if records.is_empty() {
        return Err(NoiseIdError::SequenceLength {
            sequence: 0,
            expected: 1,
            found: 0,
        });
    }
    for (sequence, record) in records.iter().enumerate() {
        if record.measurements.len() != record.inputs.len() + 1 {
            return Err(NoiseIdError::SequenceLength {
                sequence,
                expected: record.inputs.len() + 1,
                found: record.measurements.len(),
            });
        }
        check_measurements(sequence, record.measurements)?;
        if let Some(step) = record.inputs.iter().position(|u| !all_finite(u)) {
            return Err(NoiseIdError::NonFiniteInput { sequence, step });
        }
    }
    if records
        .iter()
        .all(|r| r.measurements.iter().all(Option::is_none))
    {
        return Err(NoiseIdError::AllMissing);
    }
    Ok(())
}

fn check_model<T: Real, N: Dim, M: Dim, U: Dim>(
    model: &LinearGaussian<T, N, M, U>,
) -> Result<(), NoiseIdError>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    let stage = Stage::Construction;
    let covariance = |c: &OMatrix<T, N, N>, q| {
        ensure_finite(c, stage, q)
            .and_then(|()| ensure_symmetric(c, stage, q))
            .and_then(|()| ensure_psd(c, stage, q))
    };
    let r = &model.measurement.noise;
    covariance(&model.process.noise, Quantity::ProcessNoise)
        .and_then(|()| covariance(model.prior.covariance(), Quantity::Covariance))
        .and_then(|()| ensure_finite(model.prior.mean(), stage, Quantity::Mean))
        .and_then(|()| ensure_finite(&model.process.transition, stage, Quantity::Jacobian))
        .and_then(|()| ensure_finite(&model.process.input, stage, Quantity::Jacobian))
        .and_then(|()| ensure_finite(&model.measurement.observation, stage, Quantity::Jacobian))
        .and_then(|()| ensure_finite(r, stage, Quantity::MeasurementNoise))
        .and_then(|()| ensure_symmetric(r, stage, Quantity::MeasurementNoise))
        .and_then(|()| ensure_psd(r, stage, Quantity::MeasurementNoise))
        .map_err(NoiseIdError::Model)
}

#[track_caller]
fn check_indices<T: Real, N: Dim, M: Dim>(settings: &EmSettings<T, N, M>, n: usize, m: usize)
where
    DefaultAllocator: Alloc<N, M>,
{
    // The panics are in this function's body, not in closures: `#[track_caller]` does not
    // reach into closures, and the location reported must be the caller's.
    fn diagonal<T: Real, D: Dim>(s: &CovarianceStructure<T, D>, d: usize) -> Option<usize>
    where
        DefaultAllocator: Alloc<D>,
    {
        match s {
            CovarianceStructure::DiagonalWithFixed(s) => s.iter().find(|&&i| i >= d).copied(),
            _ => None,
        }
    }
    let entries = |s: &MatrixStructure, rows: usize, cols: usize| match s {
        MatrixStructure::FreeEntries(e) => {
            e.iter().find(|&&(i, j)| i >= rows || j >= cols).copied()
        }
        _ => None,
    };
    for (what, structure, d) in [
        ("Q", &settings.process_noise, n),
        ("P0", &settings.initial_covariance, n),
    ] {
        if let Some(i) = diagonal(structure, d) {
            panic!("{what}: diagonal index {i} outside a {d} × {d} matrix");
        }
    }
    if let Some(i) = diagonal(&settings.measurement_noise, m) {
        panic!("R: diagonal index {i} outside a {m} × {m} matrix");
    }
    for (what, structure, rows) in [
        ("F", &settings.transition, n),
        ("H", &settings.observation, m),
    ] {
        if let Some((i, j)) = entries(structure, rows, n) {
            panic!("{what}: entry ({i}, {j}) outside a {rows} × {n} matrix");
        }
    }
}

fn check_identifiable<T: Real, N: Dim, M: Dim, U: Dim>(
    settings: &EmSettings<T, N, M>,
    records: &[Record<'_, T, M, U>],
) -> Result<(), NoiseIdError>
where
    DefaultAllocator: Alloc<N, M> + Alloc<M, U>,
{
    let q_free = settings.process_noise.is_free();
    if settings.transition.is_free() && settings.observation.is_free() && q_free {
        return Err(NoiseIdError::Unidentifiable(Unidentifiable::StateBasis));
    }
    if settings.observation == MatrixStructure::Free && q_free {
        return Err(NoiseIdError::Unidentifiable(Unidentifiable::StateScale));
    }
    if (q_free || settings.transition.is_free()) && records.iter().all(|r| r.inputs.is_empty()) {
        return Err(NoiseIdError::Unidentifiable(Unidentifiable::NoTransitions));
    }
    Ok(())
}

/// S⁺ and rank S for a scalar-multiple structure (symmetric eigendecomposition, eigenvalues
/// below 16 n ε λ_max counted as zero); `None` for the other structures.
fn prepare_shape<T: Real, D: Dim>(
    structure: &CovarianceStructure<T, D>,
    quantity: Quantity,
) -> Result<Option<Shape<T, D>>, NoiseIdError>
where
    DefaultAllocator: Alloc<D>,
{
    let CovarianceStructure::ScalarMultiple(s) = structure else {
        return Ok(None);
    };
    let degenerate = NoiseIdError::Unidentifiable(Unidentifiable::DegenerateShape(quantity));
    let stage = Stage::Construction;
    ensure_finite(s, stage, quantity)
        .and_then(|()| ensure_symmetric(s, stage, quantity))
        .and_then(|()| ensure_psd(s, stage, quantity))
        .map_err(|_| degenerate)?;
    let d = s.nrows();
    let eigen = DMatrix::from_iterator(d, d, s.iter().copied()).symmetric_eigen();
    let largest = eigen.eigenvalues.iter().fold(T::zero(), |a, &v| a.max(v));
    let floor =
        T::from_usize(16 * d.max(1)).unwrap_or_else(T::one) * T::default_epsilon() * largest;
    let mut rank = 0;
    let mut inverse_values = eigen.eigenvalues.clone();
    for v in inverse_values.iter_mut() {
        if *v > floor && largest > T::zero() {
            *v = T::one() / *v;
            rank += 1;
        } else {
            *v = T::zero();
        }
    }
    if rank == 0 {
        return Err(degenerate);
    }
    let vectors = &eigen.eigenvectors;
    let mut scaled = vectors.clone();
    for (j, &w) in inverse_values.iter().enumerate() {
        scaled.column_mut(j).scale_mut(w);
    }
    let pinv = scaled * vectors.transpose();
    let (rows, cols) = s.shape_generic();
    Ok(Some(Shape {
        pseudo_inverse: OMatrix::from_iterator_generic(rows, cols, pinv.iter().copied()),
        rank,
    }))
}

/// The covariance in `structure` that maximises the expected log-likelihood given the
/// unconstrained maximiser `target` (`current` supplies held entries).
fn structured<T: Real, D: Dim>(
    structure: &CovarianceStructure<T, D>,
    shape: Option<&Shape<T, D>>,
    target: &OMatrix<T, D, D>,
    current: &OMatrix<T, D, D>,
) -> OMatrix<T, D, D>
where
    DefaultAllocator: Alloc<D>,
{
    let diagonal = |held: &[usize]| {
        let mut out = OMatrix::zeros_generic(target.shape_generic().0, target.shape_generic().1);
        for i in 0..target.nrows() {
            out[(i, i)] = if held.contains(&i) {
                current[(i, i)]
            } else {
                target[(i, i)]
            };
        }
        out
    };
    match structure {
        CovarianceStructure::Fixed => current.clone(),
        CovarianceStructure::Full => {
            let mut out = target.clone();
            symmetrize(&mut out);
            out
        }
        CovarianceStructure::Diagonal => diagonal(&[]),
        CovarianceStructure::DiagonalWithFixed(held) => diagonal(held),
        CovarianceStructure::ScalarMultiple(s) => {
            let shape = shape.expect("prepared for every scalar-multiple structure");
            // c = tr(S⁺ target) / rank S.
            let trace = shape
                .pseudo_inverse
                .iter()
                .zip(target.transpose().iter())
                .fold(T::zero(), |a, (&p, &t)| a + p * t);
            let c = (trace / T::from_usize(shape.rank).unwrap_or_else(T::one)).max(T::zero());
            s * c
        }
    }
}

/// The E-step over every record: the summed log-likelihood and the statistics.
fn expectation<T: Real, N: Dim, M: Dim, U: Dim>(
    model: &LinearGaussian<T, N, M, U>,
    records: &[Record<'_, T, M, U>],
    n: N,
    m: M,
) -> Result<(T, Statistics<T, N, M>), NoiseIdError>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U> + Alloc<M, U>,
{
    let mut stats = Statistics {
        s00: OMatrix::zeros_generic(n, n),
        s10: OMatrix::zeros_generic(n, n),
        cov00: OMatrix::zeros_generic(n, n),
        cov10: OMatrix::zeros_generic(n, n),
        cov11: OMatrix::zeros_generic(n, n),
        transition_means: Vec::new(),
        szx: OMatrix::zeros_generic(m, n),
        sxx: OMatrix::zeros_generic(n, n),
        covxx: OMatrix::zeros_generic(n, n),
        observed_means: Vec::new(),
        initial_means: Vec::with_capacity(records.len()),
        initial_covariance_sum: OMatrix::zeros_generic(n, n),
    };
    let mut ll = T::zero();
    for (sequence, record) in records.iter().enumerate() {
        let mut kf = KalmanFilter::new(model.prior.clone());
        let (run, cross) = smooth_sequence_with_cross_covariances(
            &mut kf,
            &model.process,
            record.inputs,
            T::one(),
            &model.measurement,
            record.measurements,
        )
        .map_err(|error| NoiseIdError::Pass { sequence, error })?;
        ll += run.log_likelihood;
        let xs = &run.estimates;
        stats.initial_means.push(xs[0].mean().clone());
        stats.initial_covariance_sum += xs[0].covariance();
        for (k, (u, c)) in record.inputs.iter().zip(&cross).enumerate() {
            let (now, next) = (&xs[k], &xs[k + 1]);
            let y = next.mean() - &model.process.input * u;
            stats.s00 += now.covariance() + now.mean() * now.mean().transpose();
            stats.s10 += c + &y * now.mean().transpose();
            stats.cov00 += now.covariance();
            stats.cov10 += c;
            stats.cov11 += next.covariance();
            stats.transition_means.push((now.mean().clone(), y));
        }
        for (z, x) in record.measurements.iter().zip(xs) {
            if let Some(z) = z {
                stats.szx += z * x.mean().transpose();
                stats.sxx += x.covariance() + x.mean() * x.mean().transpose();
                stats.covxx += x.covariance();
                stats.observed_means.push((x.mean().clone(), z.clone()));
            }
        }
    }
    Ok((ll, stats))
}

/// The M-step (module docs), block by block.
fn maximization<T: Real, N: Dim, M: Dim, U: Dim>(
    model: &LinearGaussian<T, N, M, U>,
    stats: &Statistics<T, N, M>,
    settings: &EmSettings<T, N, M>,
    [q_shape, p_shape]: [&Option<Shape<T, N>>; 2],
    r_shape: &Option<Shape<T, M>>,
) -> Result<LinearGaussian<T, N, M, U>, NoiseIdError>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    let mut next = model.clone();
    if !stats.transition_means.is_empty() {
        let f = regression(
            &settings.transition,
            &model.process.transition,
            &stats.s10,
            &stats.s00,
            &model.process.noise,
            Quantity::ProcessNoise,
        )?;
        let target = residual_covariance(
            &f,
            &stats.cov11,
            &stats.cov10,
            &stats.cov00,
            &stats.transition_means,
        );
        next.process.noise = structured(
            &settings.process_noise,
            q_shape.as_ref(),
            &target,
            &model.process.noise,
        );
        next.process.transition = f;
    }
    if !stats.observed_means.is_empty() {
        let h = regression(
            &settings.observation,
            &model.measurement.observation,
            &stats.szx,
            &stats.sxx,
            &model.measurement.noise,
            Quantity::MeasurementNoise,
        )?;
        let zero = OMatrix::zeros_generic(h.shape_generic().0, h.shape_generic().0);
        let cross = OMatrix::zeros_generic(h.shape_generic().0, h.shape_generic().1);
        let target = residual_covariance(&h, &zero, &cross, &stats.covxx, &stats.observed_means);
        next.measurement.noise = structured(
            &settings.measurement_noise,
            r_shape.as_ref(),
            &target,
            &model.measurement.noise,
        );
        next.measurement.observation = h;
    }
    let count = T::from_usize(stats.initial_means.len()).unwrap_or_else(T::one);
    let mean = if settings.initial_mean {
        stats
            .initial_means
            .iter()
            .fold(model.prior.mean() * T::zero(), |a, x| a + x)
            / count
    } else {
        model.prior.mean().clone()
    };
    let mut spread = stats.initial_covariance_sum.clone();
    for x in &stats.initial_means {
        let d = x - &mean;
        spread += &d * d.transpose();
    }
    spread /= count;
    let covariance = structured(
        &settings.initial_covariance,
        p_shape.as_ref(),
        &spread,
        model.prior.covariance(),
    );
    next.prior = Gaussian::new_unchecked(mean, covariance);
    Ok(next)
}

/// (1/K) Σₖ E[(yₖ − A xₖ)(yₖ − A xₖ)ᵀ] from the covariance sums (Σ cov yₖ = `cyy`,
/// Σ cov(yₖ, xₖ) = `cyx`, Σ cov xₖ = `cxx`) and the K mean pairs (x̂ₖ, ŷₖ), symmetrised:
/// cyy − A cyxᵀ − cyx Aᵀ + A cxx Aᵀ + Σ (ŷ − A x̂)(ŷ − A x̂)ᵀ, each term of the size of the
/// result (no cancellation of large second moments).
fn residual_covariance<T: Real, R: Dim, C: Dim>(
    a: &OMatrix<T, R, C>,
    cyy: &OMatrix<T, R, R>,
    cyx: &OMatrix<T, R, C>,
    cxx: &OMatrix<T, C, C>,
    means: &[MeanPair<T, C, R>],
) -> OMatrix<T, R, R>
where
    DefaultAllocator: Alloc<R, C>,
{
    let cross = a * cyx.transpose();
    let mut out = cyy - &cross - cross.transpose() + a * cxx * a.transpose();
    for (x, y) in means {
        let e = y - a * x;
        out += &e * e.transpose();
    }
    out /= T::from_usize(means.len().max(1)).unwrap_or_else(T::one);
    symmetrize(&mut out);
    out
}

/// The M-step of a regression matrix A (F or H) in `structure`: A = S_yx S_xx⁻¹ when free;
/// with free entries, the normal equations \[W⁻¹ (A S_xx − S_yx)\]ᵢⱼ = 0 on them, W the noise
/// covariance (Q or R); `current` supplies the held entries.
fn regression<T: Real, R: Dim, C: Dim>(
    structure: &MatrixStructure,
    current: &OMatrix<T, R, C>,
    syx: &OMatrix<T, R, C>,
    sxx: &OMatrix<T, C, C>,
    weight: &OMatrix<T, R, R>,
    weight_quantity: Quantity,
) -> Result<OMatrix<T, R, C>, NoiseIdError>
where
    DefaultAllocator: Alloc<R, C>,
{
    let singular = |q| {
        NoiseIdError::Model(estim_core::Error::NotPositiveDefinite {
            stage: Stage::Construction,
            quantity: q,
        })
    };
    match structure {
        MatrixStructure::Fixed => Ok(current.clone()),
        MatrixStructure::FreeEntries(entries) if entries.is_empty() => Ok(current.clone()),
        MatrixStructure::Free => {
            // A Sxx = Syx  ⇔  Sxx A ᵀ = Syxᵀ (Sxx symmetric PD).
            let chol = sxx
                .clone()
                .cholesky()
                .ok_or(singular(Quantity::Covariance))?;
            Ok(chol.solve(&syx.transpose()).transpose())
        }
        MatrixStructure::FreeEntries(entries) => {
            let w_inv = weight
                .clone()
                .cholesky()
                .ok_or(singular(weight_quantity))?
                .inverse();
            let p = entries.len();
            // Fixed part of A: the current matrix with the free entries zeroed.
            let mut fixed = current.clone();
            for &(i, j) in entries {
                fixed[(i, j)] = T::zero();
            }
            let rhs_matrix = &w_inv * (syx - &fixed * sxx);
            let mut system = DMatrix::<T>::zeros(p, p);
            let mut rhs = DMatrix::<T>::zeros(p, 1);
            for (a, &(i, j)) in entries.iter().enumerate() {
                rhs[(a, 0)] = rhs_matrix[(i, j)];
                for (b, &(k, l)) in entries.iter().enumerate() {
                    system[(a, b)] = w_inv[(i, k)] * sxx[(l, j)];
                }
            }
            let solution = system
                .cholesky()
                .ok_or(singular(Quantity::Covariance))?
                .solve(&rhs);
            let mut out = fixed;
            for (a, &(i, j)) in entries.iter().enumerate() {
                out[(i, j)] = solution[(a, 0)];
            }
            Ok(out)
        }
    }
}
