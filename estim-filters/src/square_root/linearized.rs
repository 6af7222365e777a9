//! The array-form steps through a linear or linearised function: the square-root KF
//! ([`Affine`](estim_core::propagate::Affine)) and EKF ([`Linearized`](estim_core::Linearized)).

use estim_core::checks::ensure_shape;
use estim_core::kernel::{self, Accum};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{
    Alloc, Differentiable, MeasurementJacobian, Observation, Quantity, Real, Stage, StateSpace,
    error::Result,
};

use super::scratch::FactorScratch;
use super::triangular::{Block, lower_triangularize};
use super::{finish_update, finite, innovation_into, noise_factor};
use crate::report::UpdateReport;

/// x̂⁻ = f(x̂) into `scratch.state`, S⁻ from [F S | S_Q] into `scratch.factor` (Q in
/// `scratch.noise`); C = S (F S)ᵀ into `cross` if given.
pub(super) fn linearized_predict<T, N, G>(
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    f: &G,
    scratch: &mut FactorScratch<T, N, N>,
    cross: Option<&mut OMatrix<T, N, N>>,
) -> Result<()>
where
    T: Real,
    N: Dim,
    G: Differentiable<T, N, N>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n = state.nrows();
    let FactorScratch {
        state: mean,
        factor: fs,
        noise: q,
        root: sq,
        left: jacobian,
        ..
    } = scratch;
    noise_factor(q, sq, n, stage, Quantity::ProcessNoise)?;
    estim_core::function::eval_into(f, state, mean);
    ensure_shape(mean, n, 1, stage, Quantity::FunctionValue)?;
    finite(mean, stage, Quantity::Mean)?;
    estim_core::function::jacobian_into(f, state, jacobian);
    ensure_shape(jacobian, n, n, stage, Quantity::Jacobian)?;
    finite(jacobian, stage, Quantity::Jacobian)?;
    kernel::mul(fs, Accum::Replace, T::one(), jacobian, factor);
    if let Some(cross) = cross {
        // C = cov(x, f(x)) = P Fᵀ = S (F S)ᵀ, before F S is triangularised.
        cross.copy_from(&(factor * fs.transpose()));
        finite(cross, stage, Quantity::CrossCovariance)?;
    }
    lower_triangularize(
        n,
        0,
        &mut [
            Block::new(fs.as_mut_slice(), &mut [], n),
            Block::new(sq.as_mut_slice(), &mut [], n),
        ],
    );
    finite(fs, stage, Quantity::Covariance)
}

/// The array-form update: ẑ = h(x̂), H = ∂h/∂x, and from the pre-array [[S_R, H S], [0, S]]
/// the factor L of S_zz, K̄ = P Hᵀ L⁻ᵀ and S⁺ (into `scratch.factor`); then the shared tail.
#[allow(clippy::too_many_arguments)]
pub(super) fn linearized_update<T, N, M, H, S>(
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
    H: MeasurementJacobian<T, N, M>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let m_dim = z.shape_generic().0;
    let (n, m) = (state.nrows(), m_dim.value());
    let h = Observation::on(space, model);
    let FactorScratch {
        factor: posterior,
        noise: r,
        root: l,
        value: predicted,
        left: jacobian,
        right: hs,
        gain: kbar,
        ..
    } = &mut *scratch;
    estim_core::function::eval_into(&h, state, predicted);
    ensure_shape(predicted, m, 1, stage, Quantity::Measurement)?;
    estim_core::model::measurement_noise_into(model, state, r);
    noise_factor(r, l, m, stage, Quantity::MeasurementNoise)?;
    report.fit(m_dim);
    innovation_into(model, z, predicted, report)?;
    estim_core::function::jacobian_into(&h, state, jacobian);
    ensure_shape(jacobian, m, n, stage, Quantity::Jacobian)?;
    finite(jacobian, stage, Quantity::Jacobian)?;
    kernel::mul(hs, Accum::Replace, T::one(), jacobian, factor);
    kbar.fill(T::zero());
    kernel::copy(posterior, factor);
    lower_triangularize(
        m,
        n,
        &mut [
            Block::new(l.as_mut_slice(), kbar.as_mut_slice(), m),
            Block::new(hs.as_mut_slice(), posterior.as_mut_slice(), n),
        ],
    );
    finish_update(space, state, threshold, scratch, report)
}
