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
//!   (a bank of turn rates, say): the prediction takes a `Vec<P>` (or an array `[P; K]`) of
//!   models, one per mode.
//!
//! Through the [`Predict`] trait the set of models is the user's type implementing
//! [`ModeModels`] and [`ProcessInput`]; [`Imm::predict_modes`](super::Imm::predict_modes) takes
//! it bare.
//!
//! Each mode filter implements [`Rollback`]: a failed IMM step puts every mode back from its
//! snapshot (a square-root filter with its factor, bit for bit).
//!
//! Every mode takes the same input u (the physical control, shared by all hypotheses) and the
//! same measurement model (the sensor does not depend on the mode). Modes implement
//! [`Modes`] (read, restart, snapshot), [`PredictModes`] and [`UpdateModes`]; a mode set of
//! another shape (modes that own extra state, say) implements these three traits.

use estim_core::nalgebra::{DefaultAllocator, Dim, OVector};
use estim_core::{Alloc, Error, Gaussian, Quantity, Real, Stage, error::Result};

use crate::report::UpdateReport;
use crate::traits::{Estimator, Predict, ProcessInput, Rollback, Update};

/// A set of per-mode process models as the model of the IMM's [`Predict`] impl: the user's
/// own type, which names the input ([`ProcessInput`]) and lends the models as the mode set
/// takes them (a tuple `(P0, P1, …)` for a tuple of modes, a `Vec<P>` or `[P; K]` for a
/// `Vec` of modes).
///
/// Why the user's type: `Predict`'s model must implement [`ProcessInput`], which every
/// [`ProcessModel`](estim_core::ProcessModel) does through a blanket impl. A wrapper generic
/// over the scalar type cannot implement it beside that blanket impl (a crate with its own
/// scalar type could make the wrapper a process model: E0119), but a type with concrete
/// scalar and dimensions can, in the user's crate:
///
/// ```
/// use estim_core::LinearProcess;
/// use estim_core::nalgebra::{U1, U2};
/// use estim_filters::ProcessInput;
/// use estim_filters::imm::ModeModels;
///
/// type Cv = LinearProcess<f64, U2, U1>;
/// /// Quiet and manoeuvring constant-velocity models.
/// struct TwoModes((Cv, Cv));
/// impl ProcessInput<f64, U2> for TwoModes {
///     type Input = estim_core::nalgebra::Vector1<f64>;
/// }
/// impl ModeModels for TwoModes {
///     type Models = (Cv, Cv);
///     fn models(&self) -> &(Cv, Cv) {
///         &self.0
///     }
/// }
/// ```
///
/// [`Imm::predict_modes`](super::Imm::predict_modes) takes the bare tuple or `Vec` without it.
pub trait ModeModels {
    /// The per-mode models as the mode set takes them.
    type Models: ?Sized;
    /// The per-mode models.
    fn models(&self) -> &Self::Models;
}

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
    ///
    /// # Panics
    /// The implementations of the crate panic when `i` ≥ [`count`](Modes::count) and
    /// `models` has an entry `i` (a programmer error; the IMM asks only for its modes). A list
    /// of models without entry `i` is an [`Error::DimensionMismatch`] instead.
    fn predict_mode(&mut self, i: usize, models: &P, input: &Self::Input, dt: T) -> Result<()>;
}

/// Mode-matched update: every mode updates with the same measurement model `H`.
pub trait UpdateModes<T: Real, N: Dim, M: Dim, H: ?Sized>: Modes<T, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Updates mode `i` with `z`, its report into `report`.
    ///
    /// # Panics
    /// The implementations of the crate panic when `i` ≥ [`count`](Modes::count) (a
    /// programmer error; the IMM asks only for its modes).
    fn update_mode(
        &mut self,
        i: usize,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>;
}

/// Mode `i`'s model in `models`, or a [`Error::DimensionMismatch`] (quantity
/// [`ModeProbabilities`](Quantity::ModeProbabilities): one model per mode, `count` of them)
/// when the list is too short.
pub(crate) fn model_of<P>(models: &[P], i: usize, count: usize) -> Result<&P> {
    models.get(i).ok_or(Error::DimensionMismatch {
        stage: Stage::Prediction,
        quantity: Quantity::ModeProbabilities,
        expected_rows: count,
        expected_cols: 1,
        found_rows: models.len(),
        found_cols: 1,
    })
}

#[track_caller]
pub(crate) fn no_mode(i: usize, count: usize) -> ! {
    panic!("mode {i} of a set of {count} modes")
}

macro_rules! tuple_modes {
    ($count:literal; $($F:ident $P:ident $idx:tt),+) => {
        impl<T: Real, N: Dim, $($F),+> Modes<T, N> for ($($F,)+)
        where
            $($F: Estimator<T, N> + Rollback,)+
            DefaultAllocator: Alloc<N>,
        {
            type Snapshot = ($($F::Snapshot,)+);

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
                ($(self.$idx.snapshot(),)+)
            }

            fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
                $(self.$idx.snapshot_into(&mut snapshot.$idx);)+
            }

            fn restore(&mut self, snapshot: &Self::Snapshot) {
                $(self.$idx.restore(&snapshot.$idx);)+
            }
        }

        impl<T: Real, N: Dim, U, $($F, $P),+> PredictModes<T, N, ($($P,)+)> for ($($F,)+)
        where
            $($F: Predict<T, N, $P> + Rollback, $P: ProcessInput<T, N, Input = U>,)+
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
            H: ?Sized,
            $($F: Update<T, N, M, H> + Rollback,)+
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
    F: Estimator<T, N> + Rollback,
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = Vec<F::Snapshot>;

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
        self.iter().map(Rollback::snapshot).collect()
    }

    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        if snapshot.len() != self.len() {
            *snapshot = self.snapshot();
            return;
        }
        for (mode, saved) in self.iter().zip(snapshot.iter_mut()) {
            mode.snapshot_into(saved);
        }
    }

    /// # Panics
    /// If `snapshot` was taken from a set with another number of modes.
    #[track_caller]
    fn restore(&mut self, snapshot: &Self::Snapshot) {
        assert_eq!(snapshot.len(), self.len(), "snapshot of another mode count");
        for (mode, saved) in self.iter_mut().zip(snapshot) {
            mode.restore(saved);
        }
    }
}

/// Errors: fewer models than modes ([`Error::DimensionMismatch`], quantity
/// [`ModeProbabilities`](Quantity::ModeProbabilities)).
impl<T: Real, N: Dim, F, P> PredictModes<T, N, [P]> for Vec<F>
where
    F: Predict<T, N, P> + Rollback,
    P: ProcessInput<T, N>,
    DefaultAllocator: Alloc<N>,
{
    type Input = P::Input;

    #[track_caller]
    fn predict_mode(&mut self, i: usize, models: &[P], input: &P::Input, dt: T) -> Result<()> {
        let model = model_of(models, i, self.len())?;
        self[i].predict(model, input, dt)
    }
}

/// Errors: fewer models than modes ([`Error::DimensionMismatch`], quantity
/// [`ModeProbabilities`](Quantity::ModeProbabilities)).
impl<T: Real, N: Dim, F, P> PredictModes<T, N, Vec<P>> for Vec<F>
where
    F: Predict<T, N, P> + Rollback,
    P: ProcessInput<T, N>,
    DefaultAllocator: Alloc<N>,
{
    type Input = P::Input;

    #[track_caller]
    fn predict_mode(&mut self, i: usize, models: &Vec<P>, input: &P::Input, dt: T) -> Result<()> {
        let model = model_of(&models[..], i, self.len())?;
        self[i].predict(model, input, dt)
    }
}

/// Errors: fewer models than modes ([`Error::DimensionMismatch`], quantity
/// [`ModeProbabilities`](Quantity::ModeProbabilities)).
impl<T: Real, N: Dim, F, P, const K: usize> PredictModes<T, N, [P; K]> for Vec<F>
where
    F: Predict<T, N, P> + Rollback,
    P: ProcessInput<T, N>,
    DefaultAllocator: Alloc<N>,
{
    type Input = P::Input;

    #[track_caller]
    fn predict_mode(&mut self, i: usize, models: &[P; K], input: &P::Input, dt: T) -> Result<()> {
        let model = model_of(&models[..], i, self.len())?;
        self[i].predict(model, input, dt)
    }
}

impl<T: Real, N: Dim, M: Dim, F, H: ?Sized> UpdateModes<T, N, M, H> for Vec<F>
where
    F: Update<T, N, M, H> + Rollback,
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
