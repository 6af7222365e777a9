//! The IMM smoother ([`ImmSmoother`](crate::imm::ImmSmoother)) over modes of different
//! sizes: a mode's prediction with its cross-covariance, carried through its map.
//!
//! The mode's filter, started from the projection D xₖ of a common-state Gaussian
//! N(x̂, P), gives its prediction and Cₘ = cov(D xₖ, xₘ,ₖ₊₁). The common-state cross-covariance
//! is then
//!
//! ```text
//! C = cov(xₖ, Eₘ xₘ,ₖ₊₁ + lifted defaults) = P Dᵀ (D P Dᵀ)⁻¹ Cₘ Eₘᵀ
//! ```
//!
//! exactly for a Gaussian start: the mode's prediction depends on xₖ only through D xₖ, and
//! the rest of xₖ is its regression on D xₖ plus a part independent of both (the lifted
//! defaults are independent of everything). Started from its own lifted estimate, whose
//! missing components are independent of the rest, this is Eₘ Cₘ Eₘᵀ with no solve.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::{Alloc, Error, Gaussian, Quantity, Real, Stage, error::Result};

use super::{Embedded, EmbeddedModes};
use crate::imm::modes::no_mode;
use crate::imm::{PredictCrossModes, Prediction};
use crate::traits::{Estimator, PredictCross, ProcessInput, Rollback};

impl<T: Real, Nm: Dim, N: Dim, F> Embedded<T, Nm, N, F>
where
    F: Estimator<T, Nm>,
    DefaultAllocator: Alloc<N, Nm>,
{
    /// A clone of the filter, restarted from the projection of `start` if given, predicted
    /// through `model`: the lifted prediction and the common-state cross-covariance.
    fn predict_from<P: ProcessInput<T, Nm> + ?Sized>(
        &self,
        start: Option<&Gaussian<T, N>>,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<Prediction<T, N>>
    where
        F: PredictCross<T, Nm, P> + Clone,
    {
        let (map, places) = (&self.map, &self.map.places);
        let mut filter = self.filter.clone();
        if let Some(start) = start {
            filter.reset(map.project(start));
        }
        let mode_cross = filter.predict_with_cross_covariance(model, input, dt)?;
        let n = map.mean.shape_generic().0;
        let (mut state, mut covariance) =
            (OVector::zeros_generic(n, U1), OMatrix::zeros_generic(n, n));
        map.lift_into(
            filter.state(),
            filter.covariance(),
            &mut state,
            &mut covariance,
        );
        // cov(xₖ, xₘ,ₖ₊₁), n × nₘ.
        let left: OMatrix<T, N, Nm> = match start {
            None => {
                let mut left = OMatrix::zeros_generic(n, map.mode);
                for (a, &i) in places.iter().enumerate() {
                    left.row_mut(i).copy_from(&mode_cross.row(a));
                }
                left
            }
            Some(start) => {
                let p = start.covariance();
                let pd =
                    OMatrix::<T, N, Nm>::from_fn_generic(n, map.mode, |r, a| p[(r, places[a])]);
                let dpd = map.project(start).into_parts().1;
                // (D P Dᵀ)⁻¹ Cₘ by Cholesky, then P Dᵀ times it.
                let solved = dpd.cholesky().map(|c| c.solve(&mode_cross)).ok_or(
                    Error::NotPositiveDefinite {
                        stage: Stage::Prediction,
                        quantity: Quantity::Covariance,
                    },
                )?;
                pd * solved
            }
        };
        let mut cross = OMatrix::zeros_generic(n, n);
        for (a, &i) in places.iter().enumerate() {
            cross.column_mut(i).copy_from(&left.column(a));
        }
        Ok(Prediction {
            state,
            covariance,
            cross,
        })
    }
}

macro_rules! embedded_cross_modes {
    ($count:literal; $($F:ident $D:ident $P:ident $idx:tt),+) => {
        /// Errors: a mode's prediction error, or the start's covariance on the mode's
        /// components not positive definite ([`Error::NotPositiveDefinite`], quantity
        /// [`Covariance`](Quantity::Covariance)).
        impl<T: Real, N: Dim, U, $($D: Dim, $F, $P),+> PredictCrossModes<T, N, ($($P,)+)>
            for EmbeddedModes<($(Embedded<T, $D, N, $F>,)+)>
        where
            $($F: PredictCross<T, $D, $P> + Rollback + Clone,
              $P: ProcessInput<T, $D, Input = U>,)+
            DefaultAllocator: Alloc<N> $(+ Alloc<N, $D>)+,
        {
            #[track_caller]
            fn predict_from(
                &self,
                j: usize,
                start: Option<&Gaussian<T, N>>,
                models: &($($P,)+),
                input: &U,
                dt: T,
            ) -> Result<Prediction<T, N>> {
                match j {
                    $($idx => (self.0).$idx.predict_from(start, &models.$idx, input, dt),)+
                    _ => no_mode(j, $count),
                }
            }
        }
    };
}

embedded_cross_modes!(1; F0 D0 P0 0);
embedded_cross_modes!(2; F0 D0 P0 0, F1 D1 P1 1);
embedded_cross_modes!(3; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2);
embedded_cross_modes!(4; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2, F3 D3 P3 3);
embedded_cross_modes!(5; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2, F3 D3 P3 3, F4 D4 P4 4);
embedded_cross_modes!(6; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2, F3 D3 P3 3, F4 D4 P4 4, F5 D5 P5 5);
