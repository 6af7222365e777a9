//! The square-root unscented steps (Van der Merwe & Wan 2001): sigma-point deviations
//! triangularised with the noise factor, and the array-form update.

use estim_core::checks::ensure_shape;
use estim_core::kernel;
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::propagate::Unscented;
use estim_core::scalar::real;
use estim_core::{
    Alloc, Error, MeasurementModel, Observation, Quantity, Real, Stage, StateSpace, VectorFunction,
    error::Result,
};

use super::scratch::FactorScratch;
use super::triangular::{Block, lower_triangularize, rank_one_downdate};
use super::{finish_update, finite, innovation_into, noise_factor};
use crate::report::UpdateReport;

/// The sigma-point deviations of y = g(x) at (x̂, S) into `scratch`, with γ = √c (c = α²(n +
/// κ)); returns the weight w = 1/(2c). g(x̂) into `value`,
/// D₊ = [g(x̂ + γSⱼ) ⊖ g(x̂)]ⱼ into `left`, D₋ = [g(x̂ − γSⱼ) ⊖ g(x̂)]ⱼ into `right` (m × n
/// each), d̄ = w Σ dᵢ into `mean`, and the offsets γS into `factor` (kept there, not in a
/// buffer of their own, for the SR-UKF 6/4 firmware step's peak stack: a separate γS cost
/// it 424 bytes, 3 444 against 3 020, `.ci/firmware`).
fn deviations<T, N, M, G>(
    ut: &Unscented<T>,
    x: &OVector<T, N>,
    s: &OMatrix<T, N, N>,
    g: &G,
    scratch: &mut FactorScratch<T, N, M>,
    stage: Stage,
) -> Result<T>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let n = x.nrows();
    // The accepted region for this n, as the full-covariance UKF checks it (c > 0 and
    // α²κ + nβ ≥ 0): outside it no factor of cov(y) exists for some functions.
    ut.check_dimension(n)?;
    let c = ut.alpha() * ut.alpha() * (real::<T>(n as f64) + ut.kappa());
    let gamma = c.sqrt();
    let FactorScratch {
        factor: offsets,
        value,
        mean,
        left: plus,
        right: minus,
        sigma,
        ..
    } = scratch;
    // Slices, not nalgebra's strided iterators (≈ 20 instructions an entry at 6/4).
    for (o, &v) in offsets.as_mut_slice().iter_mut().zip(s.as_slice()) {
        *o = v * gamma;
    }
    // The crate's one sigma-point generator, as the full-covariance UKF forms its points.
    sigma.deviations_into(g, x, offsets, value, plus, minus, stage)?;
    finite(value, stage, Quantity::FunctionValue)?;
    let weight = T::one() / (real::<T>(2.0) * c);
    mean.fill(T::zero());
    for points in [&*plus, &*minus] {
        finite(points, stage, Quantity::FunctionValue)?;
        for column in points.column_iter() {
            *mean += column;
        }
    }
    *mean *= weight;
    Ok(weight)
}

/// The factor of w Σ dᵢdᵢᵀ + (β − α²) d̄ d̄ᵀ + N N ᵀ into `noise` (the m × m factor N on entry):
/// one triangularisation of [N | √w Dₚ | √w Dₘ | √(β − α²) d̄] when β ≥ α², else of the first
/// three blocks and a downdate by √(α² − β) d̄ (`Err(())` if it fails). Consumes the
/// deviations' columns and d̄ (`plus`, `minus`, `mean`).
fn deviation_factor<T: Real, N: Dim, M: Dim>(
    ut: &Unscented<T>,
    weight: T,
    noise: &mut OMatrix<T, M, M>,
    plus: &mut OMatrix<T, M, N>,
    minus: &mut OMatrix<T, M, N>,
    column: &mut OVector<T, M>,
) -> core::result::Result<(), ()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (m, n) = plus.shape();
    let root_w = weight.sqrt();
    *plus *= root_w;
    *minus *= root_w;
    let centre = ut.beta() - ut.alpha() * ut.alpha();
    *column *= centre.abs().sqrt();
    let extra = usize::from(centre > T::zero());
    lower_triangularize(
        m,
        0,
        &mut [
            Block::new(noise.as_mut_slice(), &mut [], m),
            Block::new(plus.as_mut_slice(), &mut [], n),
            Block::new(minus.as_mut_slice(), &mut [], n),
            Block::new(&mut column.as_mut_slice()[..m * extra], &mut [], extra),
        ],
    );
    if centre < T::zero() {
        rank_one_downdate(noise.as_mut_slice(), column.as_mut_slice(), m)?;
    }
    Ok(())
}

/// x̂⁻ = f(x̂) ⊞ d̄ into `scratch.state` and S⁻ from the sigma-point deviations and S_Q into
/// `scratch.factor` (Q in `scratch.noise`); the cross-covariance cov(x, f(x)) into `cross` if
/// given.
pub(super) fn unscented_predict<T, N, G>(
    ut: &Unscented<T>,
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    f: &G,
    scratch: &mut FactorScratch<T, N, N>,
    cross: Option<&mut OMatrix<T, N, N>>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    G: VectorFunction<T, N, N>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n = state.nrows();
    noise_factor(
        &scratch.noise,
        &mut scratch.root,
        n,
        stage,
        Quantity::ProcessNoise,
    )?;
    let weight = deviations(ut, state, factor, f, scratch, stage)?;
    let FactorScratch {
        state: mean,
        factor: offsets,
        root: s,
        value,
        mean: centre,
        left: plus,
        right: minus,
        ..
    } = &mut *scratch;
    f.output_plus_into(value, centre, mean);
    ensure_shape(mean, n, 1, stage, Quantity::Mean)?;
    finite(mean, stage, Quantity::Mean)?;
    if let Some(cross) = cross {
        // C = Σ wᵢ (χᵢ − x̂)(yᵢ − ȳ)ᵀ over χ = x̂ ± γSⱼ, γ = √c, w = 1/(2c): the constant ȳ
        // cancels between the ± pairs, leaving w (γS) (Dₚ − Dₘ)ᵀ, with the offsets γS the
        // sigma points were taken at (as the full-covariance propagator forms it).
        cross.copy_from(&(&*offsets * (&*plus - &*minus).transpose() * weight));
        finite(cross, stage, Quantity::CrossCovariance)?;
    }
    deviation_factor(ut, weight, s, plus, minus, centre).map_err(|()| {
        Error::NotPositiveSemiDefinite {
            stage,
            quantity: Quantity::Covariance,
        }
    })?;
    finite(s, stage, Quantity::Covariance)?;
    // S⁻ is the filter's new factor.
    core::mem::swap(s, offsets);
    Ok(())
}

/// The square-root UKF update in array form (module docs): with Aⱼ = (d₊ⱼ − d₋ⱼ)/2 and
/// Bⱼ = (d₊ⱼ + d₋ⱼ)/2, H̃S = √(2w) A (H̃ = P_xzᵀP⁻¹, the statistical linearisation) and
/// R̃ = R + 2w B Bᵀ + (β − α²) d̄ d̄ᵀ, the pre-array [[S_R̃, H̃S], [0, S]] gives L, K̄ = P_xz L⁻ᵀ and
/// S⁺ at once. R̃'s factor comes from [S_R | √(2w) B | √(β − α²) d̄] inside the array when
/// β ≥ α², else from [S_R | √(2w) B] and a rank-one downdate by √(α² − β) d̄ (its failure is
/// `NotPositiveDefinite`, `InnovationCovariance`).
#[allow(clippy::too_many_arguments)]
pub(super) fn unscented_update<T, N, M, H, S>(
    ut: &Unscented<T>,
    space: &S,
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    model: &H,
    z: &OVector<T, M>,
    threshold: Option<T>,
    scratch: &mut FactorScratch<T, N, M>,
    report: &mut UpdateReport<T, M>,
) -> Result<bool>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let m_dim = z.shape_generic().0;
    let (n, m) = (state.nrows(), m_dim.value());
    let h = Observation::on(space, model);
    estim_core::model::measurement_noise_into(model, state, &mut scratch.noise);
    noise_factor(
        &scratch.noise,
        &mut scratch.root,
        m,
        stage,
        Quantity::MeasurementNoise,
    )?;
    let weight = deviations(ut, state, factor, &h, scratch, stage).map_err(|e| match e {
        Error::DimensionMismatch { .. } => Error::DimensionMismatch {
            stage,
            quantity: Quantity::Measurement,
            expected_rows: model.measure(state).nrows(),
            expected_cols: 1,
            found_rows: m,
            found_cols: 1,
        },
        e => e,
    })?;
    let FactorScratch {
        state: below_centre,
        factor: posterior,
        covariance: prior,
        root: l,
        value,
        mean: column,
        left: even,
        right: odd,
        gain: kbar,
        whitened: predicted,
        ..
    } = &mut *scratch;
    h.output_plus_into(value, column, predicted);
    report.fit(m_dim);
    innovation_into(model, z, predicted, report)?;
    // (odd, even) = ((d₊ − d₋), (d₊ + d₋)) √(2w)/2, in place of (D₋, D₊).
    let half_root = (real::<T>(2.0) * weight).sqrt() * real::<T>(0.5);
    for (p, q) in even.as_mut_slice().iter_mut().zip(odd.as_mut_slice()) {
        let (plus, minus) = (*p, *q);
        *q = (plus - minus) * half_root;
        *p = (plus + minus) * half_root;
    }
    let centre = ut.beta() - ut.alpha() * ut.alpha();
    *column *= centre.abs().sqrt();
    if centre < T::zero() {
        lower_triangularize(
            m,
            0,
            &mut [
                Block::new(l.as_mut_slice(), &mut [], m),
                Block::new(even.as_mut_slice(), &mut [], n),
            ],
        );
        rank_one_downdate(l.as_mut_slice(), column.as_mut_slice(), m).map_err(|()| {
            Error::NotPositiveDefinite {
                stage,
                quantity: Quantity::InnovationCovariance,
            }
        })?;
    }
    let extra = usize::from(centre > T::zero());
    kbar.fill(T::zero());
    posterior.fill(T::zero());
    below_centre.fill(T::zero());
    kernel::copy(prior, factor);
    lower_triangularize(
        m,
        n,
        &mut [
            Block::new(l.as_mut_slice(), kbar.as_mut_slice(), m),
            Block::new(even.as_mut_slice(), posterior.as_mut_slice(), n),
            Block::new(
                &mut column.as_mut_slice()[..m * extra],
                &mut below_centre.as_mut_slice()[..n * extra],
                extra,
            ),
            Block::new(odd.as_mut_slice(), prior.as_mut_slice(), n),
        ],
    );
    finish_update(space, state, threshold, scratch, report)
}
