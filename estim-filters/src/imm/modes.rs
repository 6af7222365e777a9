//! The mode set of a multiple-model estimator: the user's filters, one per mode.
//!
//! Two shapes, both the user's own values (the estimator owns them and hands them back with
//! [`Imm::into_modes`](super::Imm::into_modes)):
//!
//! - **A tuple** `(F0, F1, …)` of up to six filters, each of its own type: a KF for the
//!   constant-velocity mode beside a UKF for the coordinated turn, a square-root filter beside
//!   an EKF. Dispatch is static and nothing is boxed, so a step costs the modes' own steps plus
//!   the mixing. Each mode has its own process model: the IMM's prediction takes the tuple
//!   `(P0, P1, …)` of models, mode i predicting with model i.
//! - **A `Vec<F>`** of one filter type, when the number of modes is known only at run time
//!   (a bank of turn rates, say): the prediction takes a slice `[P]` of models, one per mode.
//!
//! Every mode takes the same input u (the physical control, shared by all hypotheses) and the
//! same measurement model (the sensor does not depend on the mode). Modes implement
//! [`Modes`] (read, restart, snapshot), [`PredictModes`] and [`UpdateModes`]; a mode set of
//! another shape (modes that own extra state, say) implements these three traits.

use estim_core::nalgebra::{DefaultAllocator, Dim, OVector};
use estim_core::{Alloc, Gaussian, ProcessModel, Real, error::Result};

use crate::report::UpdateReport;
use crate::traits::{Estimator, Predict, Update};

/// A set of mode filters over the same `N`-dimensional state.
pub trait Modes<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// What [`snapshot`](Self::snapshot) saves: every mode filter's own state.
    type Snapshot: Clone;

    /// The number of modes m (at least 1).
    fn count(&self) -> usize;

    /// Mode `i`'s filter, read side.
    ///
    /// # Panics
    /// If `i ≥ count()`.
    fn mode(&self, i: usize) -> &dyn Estimator<T, N>;

    /// Restarts mode `i` from `prior` (the IMM's mixing step).
    ///
    /// # Panics
    /// If `i ≥ count()`.
    fn reset_mode(&mut self, i: usize, prior: Gaussian<T, N>);

    /// Saves every mode's state.
    fn snapshot(&self) -> Self::Snapshot;

    /// [`snapshot`](Self::snapshot) into `snapshot`, reusing its buffers.
    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        *snapshot = self.snapshot();
    }

    /// Puts back what [`snapshot`](Self::snapshot) saved.
    fn restore(&mut self, snapshot: &Self::Snapshot);
}

/// Mode-matched prediction: mode `i` predicts through its own model, taken from the set of
/// per-mode models `P`.
pub trait PredictModes<T: Real, N: Dim, P: ?Sized>: Modes<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The input u every mode takes.
    type Input;

    /// Predicts mode `i` through its model in `models`.
    fn predict_mode(&mut self, i: usize, models: &P, input: &Self::Input, dt: T) -> Result<()>;
}

/// Mode-matched update: every mode updates with the same measurement model `H`.
pub trait UpdateModes<T: Real, N: Dim, M: Dim, H: ?Sized>: Modes<T, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Updates mode `i` with `z`, its report into `report`.
    fn update_mode(
        &mut self,
        i: usize,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>;
}

#[track_caller]
fn no_mode(i: usize, count: usize) -> ! {
    panic!("mode {i} of a set of {count} modes")
}

macro_rules! tuple_modes {
    ($count:literal; $($F:ident $P:ident $idx:tt),+) => {
        impl<T: Real, N: Dim, $($F),+> Modes<T, N> for ($($F,)+)
        where
            $($F: Estimator<T, N> + Clone,)+
            DefaultAllocator: Alloc<N>,
        {
            type Snapshot = ($($F,)+);

            fn count(&self) -> usize {
                $count
            }

            #[track_caller]
            fn mode(&self, i: usize) -> &dyn Estimator<T, N> {
                match i {
                    $($idx => &self.$idx,)+
                    _ => no_mode(i, $count),
                }
            }

            #[track_caller]
            fn reset_mode(&mut self, i: usize, prior: Gaussian<T, N>) {
                match i {
                    $($idx => self.$idx.reset(prior),)+
                    _ => no_mode(i, $count),
                }
            }

            fn snapshot(&self) -> Self::Snapshot {
                self.clone()
            }

            fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
                $(snapshot.$idx.clone_from(&self.$idx);)+
            }

            fn restore(&mut self, snapshot: &Self::Snapshot) {
                $(self.$idx.clone_from(&snapshot.$idx);)+
            }
        }

        impl<T: Real, N: Dim, U, $($F, $P),+> PredictModes<T, N, ($($P,)+)> for ($($F,)+)
        where
            $($F: Predict<T, N, $P> + Clone, $P: ProcessModel<T, N, Input = U>,)+
            DefaultAllocator: Alloc<N>,
        {
            type Input = U;

            #[track_caller]
            fn predict_mode(&mut self, i: usize, models: &($($P,)+), input: &U, dt: T) -> Result<()> {
                match i {
                    $($idx => self.$idx.predict(&models.$idx, input, dt),)+
                    _ => no_mode(i, $count),
                }
            }
        }

        impl<T: Real, N: Dim, M: Dim, H, $($F),+> UpdateModes<T, N, M, H> for ($($F,)+)
        where
            H: estim_core::MeasurementModel<T, N, M>,
            $($F: Update<T, N, M, H> + Clone,)+
            DefaultAllocator: Alloc<N, M>,
        {
            #[track_caller]
            fn update_mode(
                &mut self,
                i: usize,
                model: &H,
                z: &OVector<T, M>,
                report: &mut UpdateReport<T, M>,
            ) -> Result<()> {
                match i {
                    $($idx => self.$idx.update_into(model, z, report),)+
                    _ => no_mode(i, $count),
                }
            }
        }
    };
}

tuple_modes!(1; F0 P0 0);
tuple_modes!(2; F0 P0 0, F1 P1 1);
tuple_modes!(3; F0 P0 0, F1 P1 1, F2 P2 2);
tuple_modes!(4; F0 P0 0, F1 P1 1, F2 P2 2, F3 P3 3);
tuple_modes!(5; F0 P0 0, F1 P1 1, F2 P2 2, F3 P3 3, F4 P4 4);
tuple_modes!(6; F0 P0 0, F1 P1 1, F2 P2 2, F3 P3 3, F4 P4 4, F5 P5 5);

impl<T: Real, N: Dim, F> Modes<T, N> for Vec<F>
where
    F: Estimator<T, N> + Clone,
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = Vec<F>;

    fn count(&self) -> usize {
        self.len()
    }

    #[track_caller]
    fn mode(&self, i: usize) -> &dyn Estimator<T, N> {
        &self[i]
    }

    #[track_caller]
    fn reset_mode(&mut self, i: usize, prior: Gaussian<T, N>) {
        self[i].reset(prior);
    }

    fn snapshot(&self) -> Self::Snapshot {
        self.clone()
    }

    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        snapshot.clone_from(self);
    }

    fn restore(&mut self, snapshot: &Self::Snapshot) {
        self.clone_from(snapshot);
    }
}

/// # Panics
/// If `models` has fewer entries than there are modes.
impl<T: Real, N: Dim, F, P> PredictModes<T, N, [P]> for Vec<F>
where
    F: Predict<T, N, P> + Clone,
    P: ProcessModel<T, N>,
    DefaultAllocator: Alloc<N>,
{
    type Input = P::Input;

    #[track_caller]
    fn predict_mode(&mut self, i: usize, models: &[P], input: &P::Input, dt: T) -> Result<()> {
        self[i].predict(&models[i], input, dt)
    }
}

impl<T: Real, N: Dim, M: Dim, F, H> UpdateModes<T, N, M, H> for Vec<F>
where
    F: Update<T, N, M, H> + Clone,
    H: estim_core::MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    #[track_caller]
    fn update_mode(
        &mut self,
        i: usize,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self[i].update_into(model, z, report)
    }
}
