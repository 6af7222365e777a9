//! The factor form of the moment propagators: how a [`SquareRootFilter`] moves (x̂, S)
//! through a process model and corrects it with a measurement model. [`Affine`] takes linear
//! models, [`Linearized`] models with Jacobians, [`Unscented`] any model: the same bounds as
//! the full-covariance filters with the same propagator, so a square-root filter takes
//! exactly the models its full-covariance twin takes.
//!
//! [`SquareRootFilter`]: super::SquareRootFilter

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::propagate::{Affine, Linearized, Unscented};
use estim_core::{
    Alloc, LinearMeasurementModel, LinearProcessModel, MeasurementJacobian, MeasurementModel,
    ProcessJacobian, ProcessModel, Real, StateSpace, Transition, error::Result,
};

use super::linearized::{linearized_predict, linearized_update};
use super::scratch::FactorScratch;
use super::unscented::{unscented_predict, unscented_update};
use crate::report::UpdateReport;

/// The prediction of a square-root filter through process models `P`.
pub trait FactorPredict<T: Real, N: Dim, P: ProcessModel<T, N>>
where
    DefaultAllocator: Alloc<N>,
{
    /// (x̂⁻, S⁻) into `scratch.state` and `scratch.factor` for x⁺ = f(x, u, Δt) + w,
    /// w ~ N(0, Q) with Q = Q(x̂, u, Δt) in `scratch.noise` on entry, from x ~ N(x̂, S Sᵀ) on the
    /// state space `space` (sigma points x̂ ⊞ δ, deviations ⊟); C = cov(x, f(x)) into `cross`
    /// if given. Errors as the filter's `predict`; the filter commits nothing then.
    #[allow(clippy::too_many_arguments)]
    fn predict_factor<S: StateSpace<T, N>>(
        &self,
        space: &S,
        state: &OVector<T, N>,
        factor: &OMatrix<T, N, N>,
        model: &P,
        input: &P::Input,
        dt: T,
        scratch: &mut FactorScratch<T, N, N>,
        cross: Option<&mut OMatrix<T, N, N>>,
    ) -> Result<()>;
}

/// The update of a square-root filter with measurement models `H` of `M` components.
pub trait FactorUpdate<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The report of the update with `z` (innovation, its covariance, NIS, log-likelihood,
    /// outcome) and, unless the NIS exceeds `threshold`, the corrected (x̂⁺, S⁺) into
    /// `scratch.state` and `scratch.factor`, x̂⁺ = x̂ ⊞ K ν on the state space `space`. `true`
    /// when the filter is to commit them, `false` when the update was gated.
    #[allow(clippy::too_many_arguments)]
    fn update_factor<S: StateSpace<T, N>>(
        &self,
        space: &S,
        state: &OVector<T, N>,
        factor: &OMatrix<T, N, N>,
        model: &H,
        z: &OVector<T, M>,
        threshold: Option<T>,
        scratch: &mut FactorScratch<T, N, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<bool>;
}

/// Writes the two impls of a derivative-based propagator (`Affine`, `Linearized`), which
/// differ only in the models they accept.
macro_rules! linear_factor_propagator {
    ($propagator:ty, $process:ident, $measurement:ident) => {
        impl<T: Real, N: Dim, P: $process<T, N>> FactorPredict<T, N, P> for $propagator
        where
            DefaultAllocator: Alloc<N>,
        {
            fn predict_factor<S: StateSpace<T, N>>(
                &self,
                space: &S,
                state: &OVector<T, N>,
                factor: &OMatrix<T, N, N>,
                model: &P,
                input: &P::Input,
                dt: T,
                scratch: &mut FactorScratch<T, N, N>,
                cross: Option<&mut OMatrix<T, N, N>>,
            ) -> Result<()> {
                let f = Transition::on(space, model, input, dt);
                linearized_predict(state, factor, &f, scratch, cross)
            }
        }

        impl<T: Real, N: Dim, M: Dim, H: $measurement<T, N, M>> FactorUpdate<T, N, M, H>
            for $propagator
        where
            DefaultAllocator: Alloc<N, M>,
        {
            fn update_factor<S: StateSpace<T, N>>(
                &self,
                space: &S,
                state: &OVector<T, N>,
                factor: &OMatrix<T, N, N>,
                model: &H,
                z: &OVector<T, M>,
                threshold: Option<T>,
                scratch: &mut FactorScratch<T, N, M>,
                report: &mut UpdateReport<T, M>,
            ) -> Result<bool> {
                linearized_update(space, state, factor, model, z, threshold, scratch, report)
            }
        }
    };
}

linear_factor_propagator!(Affine, LinearProcessModel, LinearMeasurementModel);
linear_factor_propagator!(Linearized, ProcessJacobian, MeasurementJacobian);

impl<T: Real, N: Dim, P: ProcessModel<T, N>> FactorPredict<T, N, P> for Unscented<T>
where
    DefaultAllocator: Alloc<N>,
{
    fn predict_factor<S: StateSpace<T, N>>(
        &self,
        space: &S,
        state: &OVector<T, N>,
        factor: &OMatrix<T, N, N>,
        model: &P,
        input: &P::Input,
        dt: T,
        scratch: &mut FactorScratch<T, N, N>,
        cross: Option<&mut OMatrix<T, N, N>>,
    ) -> Result<()> {
        let f = Transition::on(space, model, input, dt);
        unscented_predict(self, state, factor, &f, scratch, cross)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>> FactorUpdate<T, N, M, H>
    for Unscented<T>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn update_factor<S: StateSpace<T, N>>(
        &self,
        space: &S,
        state: &OVector<T, N>,
        factor: &OMatrix<T, N, N>,
        model: &H,
        z: &OVector<T, M>,
        threshold: Option<T>,
        scratch: &mut FactorScratch<T, N, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<bool> {
        unscented_update(
            self, space, state, factor, model, z, threshold, scratch, report,
        )
    }
}
