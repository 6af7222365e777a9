//! What a realization records into: estimates, innovations and residuals, checked and
//! converted to f64 before they enter the accumulators.

use estim_core::checks::ensure_shape;
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Error, Quantity, Real};

use crate::consistency::{STAGE, cholesky_quadratic_form, to_f64};
use crate::report::UpdateReport;
use crate::traits::Estimator;
use crate::validation::{Result, Setting, ValidationError};

use super::accumulator::{Accumulator, mismatch, small_nees};

/// A residual waiting for the end of its run, at one pair endpoint slot.
#[derive(Clone, Debug, Default)]
struct Pending {
    set: bool,
    values: Vec<f64>,
}

/// What a realization writes its statistics into; handed to the closure of
/// [`MonteCarlo::run`](super::MonteCarlo::run). Each record is checked before anything is accumulated, so a record
/// that errors changes nothing.
///
/// Records are converted to `f64`; the recorder is not generic, so one realization may record
/// filters of different scalar types or sizes at different slots (but each slot must have the
/// same sizes in every run).
#[derive(Debug)]
pub struct Recorder {
    pub(super) acc: Accumulator,
    pairs: Vec<(usize, usize)>,
    run: usize,
    seed: u64,
    estimate_seen: Vec<usize>,
    innovation_seen: Vec<usize>,
    /// slot → index into `pending` when the slot is a pair endpoint.
    endpoint: Vec<Option<usize>>,
    pending: Vec<Pending>,
    e: Vec<f64>,
    x: Vec<f64>,
    p: Vec<f64>,
    chol: Vec<f64>,
    de: Vec<f64>,
    dx: Vec<f64>,
}

impl Recorder {
    pub(super) fn new(slots: usize, pairs: &[(usize, usize)]) -> Self {
        let mut endpoint = vec![None; slots];
        let mut pending = Vec::new();
        for &(a, b) in pairs {
            for s in [a, b] {
                if endpoint[s].is_none() {
                    endpoint[s] = Some(pending.len());
                    pending.push(Pending::default());
                }
            }
        }
        Self {
            acc: Accumulator::new(slots, pairs.len()),
            pairs: pairs.to_vec(),
            run: usize::MAX,
            seed: 0,
            estimate_seen: vec![usize::MAX; slots],
            innovation_seen: vec![usize::MAX; slots],
            endpoint,
            pending,
            e: Vec::new(),
            x: Vec::new(),
            p: Vec::new(),
            chol: Vec::new(),
            de: Vec::new(),
            dx: Vec::new(),
        }
    }

    pub(super) fn begin(&mut self, run: usize, seed: u64) {
        self.run = run;
        self.seed = seed;
        for p in &mut self.pending {
            p.set = false;
        }
    }

    /// Accumulates the residual pairs completed in this run.
    pub(super) fn end_run(&mut self) -> Result<()> {
        for (k, &(a, b)) in self.pairs.iter().enumerate() {
            if let (Some(ia), Some(ib)) = (self.endpoint[a], self.endpoint[b]) {
                let (pa, pb) = (&self.pending[ia], &self.pending[ib]);
                if pa.set && pb.set {
                    self.acc.pairs[k].add(&pa.values, &pb.values)?;
                }
            }
        }
        Ok(())
    }

    /// The index of the run being recorded.
    pub fn run_index(&self) -> usize {
        self.run
    }

    /// Its seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    fn check_slot(&self, slot: usize) -> Result<()> {
        if slot < self.estimate_seen.len() {
            Ok(())
        } else {
            Err(slot_error(slot))
        }
    }

    /// Records the estimate (x̂, P) of the truth x at `slot`: the error e = x − x̂ enters the
    /// ensemble mean and covariance, the NEES eᵀP⁻¹e (Cholesky, in f64), P the mean filter
    /// covariance, and (e, x̂) the orthogonality statistics.
    ///
    /// At most once per slot and run. Errors: slot out of range ([`Setting::Slot`]), recorded
    /// twice ([`ValidationError::RecordedTwice`]), shapes, non-finite values, P not positive definite.
    pub fn record_estimate<T: Real, N: Dim>(
        &mut self,
        slot: usize,
        truth: &OVector<T, N>,
        estimate: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.check_slot(slot)?;
        if self.estimate_seen[slot] == self.run {
            return Err(ValidationError::RecordedTwice { slot });
        }
        let n = truth.nrows();
        ensure_shape(estimate, n, 1, STAGE, Quantity::Mean)?;
        ensure_shape(covariance, n, n, STAGE, Quantity::Covariance)?;
        let acc = &self.acc.slots[slot];
        if acc.n != 0 && acc.n != n {
            return Err(mismatch(Quantity::Mean, acc.n, n));
        }
        fill(&mut self.x, estimate.iter().map(|&v| to_f64(v)));
        fill(
            &mut self.e,
            truth.iter().zip(&self.x).map(|(&t, &x)| to_f64(t) - x),
        );
        fill(&mut self.p, covariance.iter().map(|&v| to_f64(v)));
        if !self.e.iter().chain(&self.x).all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Mean,
            }
            .into());
        }
        if !self.p.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Covariance,
            }
            .into());
        }
        let nees = match small_nees(&self.p, &self.e, n) {
            Some(nees) => nees,
            None => {
                self.chol.clone_from(&self.p);
                self.de.clone_from(&self.e);
                cholesky_quadratic_form(&mut self.chol, &mut self.de, n)
            }
        }
        .ok_or(Error::NotPositiveDefinite {
            stage: STAGE,
            quantity: Quantity::Covariance,
        })?;
        self.de.resize(n, 0.0);
        self.dx.resize(n, 0.0);
        let acc = &mut self.acc.slots[slot];
        acc.ensure_dim(n)?;
        acc.add(&self.e, &self.x, &self.p, nees, &mut self.de, &mut self.dx);
        self.estimate_seen[slot] = self.run;
        Ok(())
    }

    /// [`record_estimate`](Self::record_estimate) with the filter's current state and
    /// covariance.
    pub fn record_filter<T: Real, N: Dim, E: Estimator<T, N> + ?Sized>(
        &mut self,
        slot: usize,
        truth: &OVector<T, N>,
        filter: &E,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.record_estimate(slot, truth, filter.state(), filter.covariance())
    }

    /// Records an update's NIS (and log-likelihood) at `slot`; its degrees of freedom are the
    /// innovation's dimension m. At most once per slot and run (record the stacked
    /// measurement, or use different slots, for several updates at one time).
    pub fn record_innovation<T: Real, M: Dim>(
        &mut self,
        slot: usize,
        report: &UpdateReport<T, M>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<M>,
    {
        self.check_slot(slot)?;
        if self.innovation_seen[slot] == self.run {
            return Err(ValidationError::RecordedTwice { slot });
        }
        let (nis, ll) = (to_f64(report.nis), to_f64(report.log_likelihood));
        if !(nis >= 0.0) || !nis.is_finite() || !ll.is_finite() {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Innovation,
            }
            .into());
        }
        let acc = &mut self.acc.slots[slot];
        acc.nis_count += 1;
        acc.nis_dof += report.innovation.nrows();
        acc.sum_nis += nis;
        acc.sum_ll += ll;
        self.innovation_seen[slot] = self.run;
        Ok(())
    }

    /// Records the residual r at `slot` for the residual cross-correlation
    /// (1/N) Σ r(a) r(b)ᵀ of each requested pair (a, b) having `slot` as an end. Typically the
    /// innovation ([`UpdateReport::innovation`]), as in Lu's check. Ignored when `slot` is not
    /// the end of any pair; a pair counts in a run only if both its ends were recorded.
    ///
    /// At most once per slot and run. Errors: slot out of range or recorded twice, non-finite
    /// values.
    pub fn record_residual<T: Real, M: Dim>(
        &mut self,
        slot: usize,
        residual: &OVector<T, M>,
    ) -> Result<()>
    where
        DefaultAllocator: Alloc<M>,
    {
        self.check_slot(slot)?;
        let Some(k) = self.endpoint[slot] else {
            return Ok(());
        };
        let pending = &mut self.pending[k];
        if pending.set {
            return Err(ValidationError::RecordedTwice { slot });
        }
        if !residual.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                stage: STAGE,
                quantity: Quantity::Residual,
            }
            .into());
        }
        fill(&mut pending.values, residual.iter().map(|&v| to_f64(v)));
        pending.set = true;
        Ok(())
    }
}

fn fill(buffer: &mut Vec<f64>, values: impl Iterator<Item = f64>) {
    buffer.clear();
    buffer.extend(values);
}

pub(super) fn slot_error(slot: usize) -> ValidationError {
    ValidationError::setting(Setting::Slot, slot)
}
