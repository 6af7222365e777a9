//! Fading-memory recursive least squares: Lee & Huang's own-ship trajectory estimator.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{Alloc, Error, Gaussian, MeasurementJacobian, Parameter, Real, error::Result};

use crate::gaussian_filter::Ekf;
use crate::report::{UpdateOutcome, UpdateReport};
use crate::snapshot::EstimateSnapshot;
use crate::traits::{Estimator, Rollback, Update};
use crate::update::{CovarianceUpdate, Gate};

/// Recursive least squares with exponential forgetting (the own-ship trajectory estimator,
/// OTE, of Lee & Huang 2002, eq 46-48), for observations z = B θ + v, v ~ N(0, S):
///
/// ```text
/// K  = γ⁻¹ P Bᵀ (B γ⁻¹ P Bᵀ + S)⁻¹
/// θ⁺ = θ + K (z − B θ)
/// P⁺ = (I − K B) γ⁻¹ P
/// ```
///
/// with forgetting factor 0 < γ ≤ 1: data n steps old is weighted γⁿ. It is the Kalman update
/// applied to the inflated covariance γ⁻¹P, and it shares that code: the regressor B is the
/// measurement model's Jacobian (so a nonlinear h gives the linearised RLS), S is its noise,
/// and the Joseph form is used by default. γ = 1 is ordinary recursive least squares and
/// reproduces batch weighted least squares.
///
/// **Steady state for B = I.** With P = p S, the recursion is p⁺ = (1 − k) p/γ with
/// k = (p/γ)/(p/γ + 1). A fixed point needs 1 − k = γ, so k = 1 − γ and, from
/// k (p/γ + 1) = p/γ, p = 1 − γ: the gain tends to (1 − γ) I and P to (1 − γ) S.
///
/// Requirements on the model: [`MeasurementJacobian`]. It implements [`Update`] and
/// [`Estimator`] (no [`Predict`](crate::Predict): the parameters are constant but for the
/// forgetting), so it swaps with the Kalman filters on parameter-estimation problems.
///
/// An update inflates the EKF's P to γ⁻¹P in place, then runs the EKF's own update; if that
/// fails or is gated, the estimate saved before the inflation is put back ([`Rollback`]), so
/// a failed or gated update leaves the estimator exactly as it was.
#[derive(Clone, Debug)]
pub struct FadingMemoryRls<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The estimate, settings and buffers: an EKF whose updates start from γ⁻¹P.
    filter: Ekf<T, N>,
    forgetting: T,
    /// The estimate before the update in progress (a buffer, sized once; not state).
    before: EstimateSnapshot<T, N>,
}

/// Equal estimates, settings and γ (the buffer of the update in progress is not compared).
impl<T: Real, N: Dim> PartialEq for FadingMemoryRls<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn eq(&self, other: &Self) -> bool {
        self.filter == other.filter && self.forgetting == other.forgetting
    }
}

impl<T: Real, N: Dim> FadingMemoryRls<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// An estimator starting from `prior` (θ₀, P₀) with forgetting factor `forgetting` = γ,
    /// which must satisfy 0 < γ ≤ 1.
    pub fn new(prior: Gaussian<T, N>, forgetting: T) -> Result<Self> {
        if !(forgetting > T::zero() && forgetting <= T::one()) {
            return Err(Error::InvalidParameter {
                parameter: Parameter::ForgettingFactor,
                value: estim_core::nalgebra::try_convert::<T, f64>(forgetting).unwrap_or(f64::NAN),
            });
        }
        let filter = Ekf::new(prior);
        let before = filter.snapshot();
        Ok(Self {
            filter,
            forgetting,
            before,
        })
    }

    /// Uses `form` for the covariance update (default: Joseph).
    pub fn with_covariance_update(mut self, form: CovarianceUpdate) -> Self {
        self.filter = self.filter.with_covariance_update(form);
        self
    }

    /// Rejects the updates `gate` says ([`GaussianFilter::with_gate`](crate::GaussianFilter::with_gate)).
    pub fn with_gate(mut self, gate: impl Into<Gate<T>>) -> Result<Self> {
        self.filter = self.filter.with_gate(gate)?;
        Ok(self)
    }

    /// The forgetting factor γ.
    pub fn forgetting_factor(&self) -> T {
        self.forgetting
    }

    /// The EKF that carries the estimate and the settings (its updates start from γ⁻¹P).
    pub fn ekf(&self) -> &Ekf<T, N> {
        &self.filter
    }

    /// The estimator around `filter`'s estimate and settings with forgetting factor γ
    /// (0 < γ ≤ 1, as [`new`](Self::new) checks): how a checkpoint resumes.
    pub fn from_ekf(filter: Ekf<T, N>, forgetting: T) -> Result<Self> {
        let mut rls = Self::new(filter.estimate(), forgetting)?;
        rls.filter = filter;
        Ok(rls)
    }
}

impl<T: Real, N: Dim> Estimator<T, N> for FadingMemoryRls<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn state(&self) -> &OVector<T, N> {
        self.filter.state()
    }

    fn covariance(&self) -> &OMatrix<T, N, N> {
        self.filter.covariance()
    }

    fn reset(&mut self, prior: Gaussian<T, N>) {
        self.filter.reset(prior);
    }
}

/// The estimate (θ̂, P) is all an RLS carries from step to step: γ is configuration.
impl<T: Real, N: Dim> Rollback for FadingMemoryRls<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = EstimateSnapshot<T, N>;

    fn snapshot(&self) -> EstimateSnapshot<T, N> {
        self.filter.snapshot()
    }

    fn snapshot_into(&self, snapshot: &mut EstimateSnapshot<T, N>) {
        self.filter.snapshot_into(snapshot);
    }

    fn restore(&mut self, snapshot: &EstimateSnapshot<T, N>) {
        self.filter.restore(snapshot);
    }
}

impl<T, N, M, H> Update<T, N, M, H> for FadingMemoryRls<T, N>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.filter.snapshot_into(&mut self.before);
        self.filter.inflate_covariance(self.forgetting);
        let result = self.filter.update_into(model, z, report);
        if result.is_err() || report.outcome != UpdateOutcome::Applied {
            self.filter.restore(&self.before);
        }
        result
    }

    fn prepare_update(&mut self, model: &H, report: &mut UpdateReport<T, M>) -> Result<()> {
        self.filter.snapshot_into(&mut self.before);
        self.filter.inflate_covariance(self.forgetting);
        let result = self.filter.prepare_update(model, report);
        self.filter.restore(&self.before);
        result
    }
}
