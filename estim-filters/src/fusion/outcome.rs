//! What the driver decided for a measurement, and why.

use estim_core::Real;
use estim_core::nalgebra::{DefaultAllocator, Dim, allocator::Allocator};

use crate::report::{UpdateOutcome, UpdateReport};

/// How many normalised innovation components an [`Innovation`] lists (the largest one is
/// always reported, whatever the dimension).
pub const MAX_REPORTED_COMPONENTS: usize = 8;

/// The part of an update report the driver decides on, of fixed size whatever the sensor's
/// dimension: the NIS and the normalised innovations νᵢ / √Sᵢᵢ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Innovation<T> {
    /// The NIS νᵀ S⁻¹ ν.
    pub nis: T,
    /// The measurement's dimension m.
    pub dimension: usize,
    /// The component with the largest |νᵢ| / √Sᵢᵢ.
    pub largest_component: usize,
    /// That largest |νᵢ| / √Sᵢᵢ.
    pub largest: T,
    /// Whether the filter applied the update (`false` only if the filter has its own gate).
    pub applied: bool,
    /// ln N(ν; 0, S) = −½ (νᵀ S⁻¹ ν + ln det(2π S)), the update's term of the
    /// prediction-error log-likelihood (the report's `log_likelihood`).
    pub log_likelihood: T,
    normalized: [T; MAX_REPORTED_COMPONENTS],
}

impl<T: Real> Innovation<T> {
    /// The summary of an update report.
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix2, U2, Vector2};
    /// use estim_filters::{UpdateReport, fusion::Innovation};
    /// let mut report = UpdateReport::<f64, U2>::zeros(U2);
    /// report.innovation = Vector2::new(3.0, -1.0);
    /// report.innovation_covariance = Matrix2::new(9.0, 0.0, 0.0, 4.0);
    /// report.nis = 1.25;
    /// let i = Innovation::of(&report);
    /// assert_eq!(i.normalized(), &[1.0, -0.5]);
    /// assert_eq!((i.largest_component, i.largest), (0, 1.0));
    /// ```
    pub fn of<M: Dim>(report: &UpdateReport<T, M>) -> Self
    where
        DefaultAllocator: Allocator<M> + Allocator<M, M>,
    {
        let m = report.innovation.nrows();
        let mut normalized = [T::zero(); MAX_REPORTED_COMPONENTS];
        let (mut largest_component, mut largest) = (0, T::zero());
        for i in 0..m {
            let s = report.innovation_covariance[(i, i)];
            let v = report.innovation[i] / s.sqrt();
            if i < MAX_REPORTED_COMPONENTS {
                normalized[i] = v;
            }
            // `!(a <= b)` so that a NaN component is reported as the largest.
            if i == 0 || !(v.abs() <= largest) {
                largest_component = i;
                largest = v.abs();
            }
        }
        Self {
            nis: report.nis,
            dimension: m,
            largest_component,
            largest,
            applied: report.outcome == UpdateOutcome::Applied,
            log_likelihood: report.log_likelihood,
            normalized,
        }
    }

    /// νᵢ / √Sᵢᵢ for the first min(m, [`MAX_REPORTED_COMPONENTS`]) components.
    pub fn normalized(&self) -> &[T] {
        &self.normalized[..self.dimension.min(MAX_REPORTED_COMPONENTS)]
    }
}

/// Why a reset happened.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ResetReason<T> {
    /// This many consecutive rejections, during which no other sensor was accepted.
    RejectionRun {
        /// The length of the run, this measurement included.
        rejections: usize,
    },
    /// The predicted variance of a reset state exceeded the blow-up limit.
    CovarianceBlowUp {
        /// The state.
        state: usize,
        /// Its predicted variance.
        variance: T,
    },
}

/// Why a measurement was not applied because of its sensor's health.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ExclusionReason<T> {
    /// This measurement made the windowed NIS sum exceed the threshold: the sensor is
    /// excluded from now on.
    FaultDetected {
        /// The sum of the (clipped) NIS in the window.
        window_sum: T,
        /// The threshold q.
        threshold: T,
    },
    /// The sensor was already excluded.
    SensorExcluded {
        /// The sum of the (clipped) NIS in the window since the exclusion.
        window_sum: T,
        /// How many deliveries since the exclusion.
        since_exclusion: usize,
    },
    /// The window, full again since the exclusion, passed: the sensor is readmitted from the
    /// next measurement on.
    Readmitted {
        /// The window sum, ≤ the threshold.
        window_sum: T,
    },
}

/// The decision on one measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome<T> {
    /// Applied.
    Accepted {
        /// Its innovation.
        innovation: Innovation<T>,
    },
    /// Not applied: its NIS exceeded the gate; the estimate is as before it.
    Rejected {
        /// Its innovation.
        innovation: Innovation<T>,
        /// NIS / gate (> 1).
        test_ratio: T,
    },
    /// The filter's reset states were re-initialised and the measurement applied to them.
    Reset {
        /// The innovation against the estimate before the reset.
        innovation: Innovation<T>,
        /// Why.
        reason: ResetReason<T>,
    },
    /// Not applied: the sensor is (now) excluded as faulty.
    Excluded {
        /// Its innovation.
        innovation: Innovation<T>,
        /// Why.
        reason: ExclusionReason<T>,
    },
}

impl<T: Copy> Outcome<T> {
    /// The innovation of the measurement.
    pub fn innovation(&self) -> &Innovation<T> {
        match self {
            Outcome::Accepted { innovation }
            | Outcome::Rejected { innovation, .. }
            | Outcome::Reset { innovation, .. }
            | Outcome::Excluded { innovation, .. } => innovation,
        }
    }

    /// Whether the measurement changed the estimate (accepted or reset).
    pub fn applied(&self) -> bool {
        matches!(self, Outcome::Accepted { .. } | Outcome::Reset { .. })
    }
}

/// What [`FusionDriver::fuse`](super::FusionDriver::fuse) (or
/// [`fuse_all`](super::FusionDriver::fuse_all)) did with a measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fused<T> {
    /// The sensor.
    pub sensor: usize,
    /// The measurement's timestamp.
    pub time: f64,
    /// The decision (made at its time, against the estimate then).
    pub outcome: Outcome<T>,
    /// How many later events were re-run after it (0 for a measurement in time order). Their
    /// decisions are re-made too, as a time-ordered delivery would have made them.
    pub replayed: usize,
    /// `true` when the reading was not fused because
    /// [`DuplicatePolicy::KeepFirst`](super::DuplicatePolicy::KeepFirst) kept an earlier
    /// reading of its sensor at its time: `outcome` is then that earlier reading's, and
    /// nothing changed.
    pub ignored: bool,
}
