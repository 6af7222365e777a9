//! The square-root unscented steps (Van der Merwe & Wan 2001): sigma-point deviations
//! triangularised with the noise factor, and the array-form update.

use estim_core::checks::ensure_shape;
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::propagate::{SigmaDeviations, Unscented};
use estim_core::scalar::real;
use estim_core::{
    Alloc, Error, MeasurementModel, Observation, Quantity, Real, Stage, StateSpace, VectorFunction,
    error::Result,
};

use super::triangular::{Block, lower_triangularize, rank_one_downdate};
use super::{Estimate, finish_update, finite, innovation_into, noise_factor};
use crate::report::UpdateReport;

/// The sigma-point deviations of y = g(x) at (x̂, S): g(x̂), Dₚ = [g(x̂ + γSⱼ) ⊖ g(x̂)]ⱼ,
/// Dₘ = [g(x̂ − γSⱼ) ⊖ g(x̂)]ⱼ (m × n each), d̄ = w Σ dᵢ and w = 1/(2c), with γ = √c (a
/// scalar: keeping the offsets γS here cost the SR-UKF 6/4 firmware step 424 bytes of peak
/// stack, 3 444 against 3 020, `.ci/firmware`).
struct Deviations<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    gamma: T,
    value: OVector<T, M>,
    plus: OMatrix<T, M, N>,
    minus: OMatrix<T, M, N>,
    mean: OVector<T, M>,
    weight: T,
}

fn deviations<T, N, M, G>(
    ut: &Unscented<T>,
    x: &OVector<T, N>,
    s: &OMatrix<T, N, N>,
    g: &G,
    m_dim: M,
    stage: Stage,
) -> Result<Deviations<T, N, M>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let n_dim = x.shape_generic().0;
    let n = n_dim.value();
    // The accepted region for this n, as the full-covariance UKF checks it (c > 0 and
    // α²κ + nβ ≥ 0): outside it no factor of cov(y) exists for some functions.
    ut.check_dimension(n)?;
    let c = ut.alpha() * ut.alpha() * (real::<T>(n as f64) + ut.kappa());
    let gamma = c.sqrt();
    let offsets = s * gamma;
    let mut value = OVector::zeros_generic(m_dim, U1);
    let mut plus = OMatrix::zeros_generic(m_dim, n_dim);
    let mut minus = OMatrix::zeros_generic(m_dim, n_dim);
    // The crate's one sigma-point generator, as the full-covariance UKF forms its points.
    SigmaDeviations::default()
        .deviations_into(g, x, &offsets, &mut value, &mut plus, &mut minus, stage)?;
    finite(&value, stage, Quantity::FunctionValue)?;
    let weight = T::one() / (real::<T>(2.0) * c);
    let mut mean = OVector::zeros_generic(m_dim, U1);
    for points in [&plus, &minus] {
        finite(points, stage, Quantity::FunctionValue)?;
        for column in points.column_iter() {
            mean += column;
        }
    }
    mean *= weight;
    Ok(Deviations {
        gamma,
        value,
        plus,
        minus,
        mean,
        weight,
    })
}

/// The factor of w Σ dᵢdᵢᵀ + (β − α²) d̄ d̄ᵀ + N N ᵀ into `noise` (the m × m factor N on entry):
/// one triangularisation of [N | √w Dₚ | √w Dₘ | √(β − α²) d̄] when β ≥ α², else of the first
/// three blocks and a downdate by √(α² − β) d̄ (`Err(())` if it fails). Consumes the
/// deviations' columns.
fn deviation_factor<T: Real, N: Dim, M: Dim>(
    ut: &Unscented<T>,
    dev: &mut Deviations<T, N, M>,
    noise: &mut OMatrix<T, M, M>,
) -> core::result::Result<(), ()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (m, n) = dev.plus.shape();
    let root_w = dev.weight.sqrt();
    dev.plus *= root_w;
    dev.minus *= root_w;
    let centre = ut.beta() - ut.alpha() * ut.alpha();
    let mut column = dev.mean.clone();
    column *= centre.abs().sqrt();
    let extra = usize::from(centre > T::zero());
    lower_triangularize(
        m,
        0,
        &mut [
            Block::new(noise.as_mut_slice(), &mut [], m),
            Block::new(dev.plus.as_mut_slice(), &mut [], n),
            Block::new(dev.minus.as_mut_slice(), &mut [], n),
            Block::new(&mut column.as_mut_slice()[..m * extra], &mut [], extra),
        ],
    );
    if centre < T::zero() {
        rank_one_downdate(noise.as_mut_slice(), column.as_mut_slice(), m)?;
    }
    Ok(())
}

/// x̂⁻ = f(x̂) ⊞ d̄ and S⁻ from the sigma-point deviations and S_Q; the cross-covariance
/// cov(x, f(x)) into `cross` if given.
pub(super) fn unscented_predict<T, N, G>(
    ut: &Unscented<T>,
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    f: &G,
    q: &OMatrix<T, N, N>,
    cross: Option<&mut OMatrix<T, N, N>>,
) -> Result<Estimate<T, N>>
where
    T: Real,
    N: Dim,
    G: VectorFunction<T, N, N>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n_dim = state.shape_generic().0;
    let mut s = noise_factor(q, n_dim.value(), stage, Quantity::ProcessNoise)?;
    let mut dev = deviations(ut, state, factor, f, n_dim, stage)?;
    let mut mean = state.clone();
    f.output_plus_into(&dev.value, &dev.mean, &mut mean);
    ensure_shape(&mean, n_dim.value(), 1, stage, Quantity::Mean)?;
    finite(&mean, stage, Quantity::Mean)?;
    if let Some(cross) = cross {
        // C = Σ wᵢ (χᵢ − x̂)(yᵢ − ȳ)ᵀ over χ = x̂ ± γSⱼ, γ = √c, w = 1/(2c): the constant ȳ
        // cancels between the ± pairs, leaving w (γS) (Dₚ − Dₘ)ᵀ, with the offsets γS the
        // sigma points were taken at (as the full-covariance propagator forms it).
        let offsets = factor * dev.gamma; // the same bits as the sigma points' offsets
        cross.copy_from(&(offsets * (&dev.plus - &dev.minus).transpose() * dev.weight));
        finite(cross, stage, Quantity::CrossCovariance)?;
    }
    deviation_factor(ut, &mut dev, &mut s).map_err(|()| Error::NotPositiveSemiDefinite {
        stage,
        quantity: Quantity::Covariance,
    })?;
    finite(&s, stage, Quantity::Covariance)?;
    Ok((mean, s))
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
    report: &mut UpdateReport<T, M>,
) -> Result<Option<Estimate<T, N>>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let (n_dim, m_dim) = (state.shape_generic().0, z.shape_generic().0);
    let (n, m) = (n_dim.value(), m_dim.value());
    let h = Observation::on(space, model);
    let mut r = OMatrix::zeros_generic(m_dim, m_dim);
    estim_core::in_place::measurement_noise_into(model, state, &mut r);
    let mut l = noise_factor(&r, m, stage, Quantity::MeasurementNoise)?;
    let dev = deviations(ut, state, factor, &h, m_dim, stage).map_err(|e| match e {
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
    let mut predicted = dev.value.clone();
    h.output_plus_into(&dev.value, &dev.mean, &mut predicted);
    report.fit(m_dim);
    innovation_into(model, z, &predicted, report)?;
    let half_root = (real::<T>(2.0) * dev.weight).sqrt() * real::<T>(0.5);
    let mut odd = dev.plus.clone();
    odd -= &dev.minus;
    odd *= half_root;
    let mut even = dev.plus;
    even += &dev.minus;
    even *= half_root;
    let centre = ut.beta() - ut.alpha() * ut.alpha();
    let mut column = dev.mean;
    column *= centre.abs().sqrt();
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
    let mut kbar: OMatrix<T, N, M> = OMatrix::zeros_generic(n_dim, m_dim);
    let mut posterior: OMatrix<T, N, N> = OMatrix::zeros_generic(n_dim, n_dim);
    let mut below_centre: OVector<T, N> = OVector::zeros_generic(n_dim, U1);
    let mut prior = factor.clone();
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
    finish_update(space, state, &l, &kbar, posterior, threshold, report)
}
