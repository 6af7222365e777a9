//! The array-form steps through a linear or linearised function: the square-root KF
//! ([`Affine`](estim_core::propagate::Affine)) and EKF ([`Linearized`](estim_core::Linearized)).

use estim_core::checks::ensure_shape;
use estim_core::kernel::{self, Accum};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::{
    Alloc, Differentiable, MeasurementJacobian, Observation, Quantity, Real, Stage, StateSpace,
    error::Result,
};

use super::triangular::{Block, lower_triangularize};
use super::{Estimate, finish_update, finite, innovation_into, noise_factor};
use crate::report::UpdateReport;

/// x̂⁻ = f(x̂), S⁻ from [F S | S_Q]: the predicted state and factor; C = S (F S)ᵀ into
/// `cross` if given.
pub(super) fn linearized_predict<T, N, G>(
    state: &OVector<T, N>,
    factor: &OMatrix<T, N, N>,
    f: &G,
    q: &OMatrix<T, N, N>,
    cross: Option<&mut OMatrix<T, N, N>>,
) -> Result<Estimate<T, N>>
where
    T: Real,
    N: Dim,
    G: Differentiable<T, N, N>,
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Prediction;
    let n_dim = state.shape_generic().0;
    let n = n_dim.value();
    let mut sq = noise_factor(q, n, stage, Quantity::ProcessNoise)?;
    let mut mean = OVector::zeros_generic(n_dim, U1);
    estim_core::in_place::eval_into(f, state, &mut mean);
    ensure_shape(&mean, n, 1, stage, Quantity::FunctionValue)?;
    finite(&mean, stage, Quantity::Mean)?;
    let mut jacobian = OMatrix::zeros_generic(n_dim, n_dim);
    estim_core::in_place::jacobian_into(f, state, &mut jacobian);
    ensure_shape(&jacobian, n, n, stage, Quantity::Jacobian)?;
    finite(&jacobian, stage, Quantity::Jacobian)?;
    let mut fs = OMatrix::zeros_generic(n_dim, n_dim);
    kernel::mul(&mut fs, Accum::Replace, T::one(), &jacobian, factor);
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
    finite(&fs, stage, Quantity::Covariance)?;
    Ok((mean, fs))
}

/// The array-form update: ẑ = h(x̂), H = ∂h/∂x, and from the pre-array [[S_R, H S], [0, S]]
/// the factor L of S_zz, K̄ = P Hᵀ L⁻ᵀ and S⁺; then the shared tail.
pub(super) fn linearized_update<T, N, M, H, S>(
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
    H: MeasurementJacobian<T, N, M>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::Update;
    let (n_dim, m_dim) = (state.shape_generic().0, z.shape_generic().0);
    let (n, m) = (n_dim.value(), m_dim.value());
    let h = Observation::on(space, model);
    let mut predicted = OVector::zeros_generic(m_dim, U1);
    estim_core::in_place::eval_into(&h, state, &mut predicted);
    ensure_shape(&predicted, m, 1, stage, Quantity::Measurement)?;
    let mut r = OMatrix::zeros_generic(m_dim, m_dim);
    estim_core::in_place::measurement_noise_into(model, state, &mut r);
    let mut l = noise_factor(&r, m, stage, Quantity::MeasurementNoise)?;
    report.fit(m_dim);
    innovation_into(model, z, &predicted, report)?;
    let mut jacobian = OMatrix::zeros_generic(m_dim, n_dim);
    estim_core::in_place::jacobian_into(&h, state, &mut jacobian);
    ensure_shape(&jacobian, m, n, stage, Quantity::Jacobian)?;
    finite(&jacobian, stage, Quantity::Jacobian)?;
    let mut hs = OMatrix::zeros_generic(m_dim, n_dim);
    kernel::mul(&mut hs, Accum::Replace, T::one(), &jacobian, factor);
    let mut kbar: OMatrix<T, N, M> = OMatrix::zeros_generic(n_dim, m_dim);
    let mut posterior = factor.clone();
    lower_triangularize(
        m,
        n,
        &mut [
            Block::new(l.as_mut_slice(), kbar.as_mut_slice(), m),
            Block::new(hs.as_mut_slice(), posterior.as_mut_slice(), n),
        ],
    );
    finish_update(space, state, &l, &kbar, posterior, threshold, report)
}
