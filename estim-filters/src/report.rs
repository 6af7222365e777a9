//! What a measurement update reports.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Real, nalgebra::allocator::Allocator};

/// Whether an update changed the estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum UpdateOutcome {
    /// The measurement was used.
    Applied,
    /// The NIS exceeded the filter's gate: the measurement was rejected, the estimate is
    /// unchanged.
    Gated,
}

/// The statistics of one measurement update.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(bound(
        serialize = "OVector<T, M>: serde::Serialize, OMatrix<T, M, M>: serde::Serialize, T: serde::Serialize",
        deserialize = "OVector<T, M>: serde::Deserialize<'de>, OMatrix<T, M, M>: serde::Deserialize<'de>, T: serde::Deserialize<'de>"
    ))
)]
pub struct UpdateReport<T: Real, M: Dim>
where
    DefaultAllocator: Allocator<M> + Allocator<M, M>,
{
    /// The innovation ν = z ⊖ ẑ.
    pub innovation: OVector<T, M>,
    /// Its predicted covariance S = cov(ẑ) + R.
    #[cfg_attr(
        feature = "serde",
        serde(deserialize_with = "estim_core::serialize::checked_matrix")
    )]
    pub innovation_covariance: OMatrix<T, M, M>,
    /// The normalised innovation squared νᵀ S⁻¹ ν (χ² with m degrees of freedom when the
    /// filter is consistent).
    pub nis: T,
    /// The log-likelihood of z: −½ (νᵀ S⁻¹ ν + ln det S + m ln 2π).
    pub log_likelihood: T,
    /// Whether the measurement was used.
    pub outcome: UpdateOutcome,
    /// How the iterations of an iterated update went ([`Iekf`](crate::Iekf)); `None` for the
    /// filters that update in one step.
    pub iterations: Option<Iterations<T>>,
}

/// The convergence report of an iterated measurement update ([`Iekf`](crate::Iekf)).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Iterations<T> {
    /// Gauss–Newton steps computed (linearisations of h); 0 when the update was gated.
    pub count: usize,
    /// Whether the last step met the step tolerance (`false` when the iteration cap was
    /// reached, the step-size safeguard found no decrease of the cost, or the update was
    /// gated).
    pub converged: bool,
    /// ‖xᵢ₊₁ − xᵢ‖ of the last step taken (0 when gated).
    pub step_norm: T,
}

impl<T: Real, M: Dim> UpdateReport<T, M>
where
    DefaultAllocator: Allocator<M> + Allocator<M, M>,
{
    /// A report for `m` measurement components, all zero: a buffer for
    /// [`Update::update_into`](crate::Update::update_into).
    pub fn zeros(m: M) -> Self {
        Self {
            innovation: OVector::zeros_generic(m, estim_core::nalgebra::U1),
            innovation_covariance: OMatrix::zeros_generic(m, m),
            nis: T::zero(),
            log_likelihood: T::zero(),
            outcome: UpdateOutcome::Applied,
            iterations: None,
        }
    }

    /// Gives the buffers `m` components (reallocating only if they have another size).
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn fit(&mut self, m: M) {
        if self.innovation.nrows() != m.value() || self.innovation_covariance.nrows() != m.value() {
            *self = Self::zeros(m);
        }
    }

    /// `true` unless the update was gated.
    pub fn applied(&self) -> bool {
        self.outcome == UpdateOutcome::Applied
    }
}
