//! Robust measurement updates: Huber or Student-t down-weighting of the innovation, beside
//! gating (which rejects outright).
//!
//! With the predicted innovation ν, its covariance S and d² = νᵀ S⁻¹ ν (the NIS, m
//! components), a weight w(d) ∈ (0, 1] is chosen and the measurement is used with the
//! innovation covariance inflated to S/w, by inflating the noise:
//!
//! ```text
//! R_w = R + (1/w − 1) S      ⇒   S_w = cov(ẑ) + R_w = S/w
//! K_w = Pₓᵤ S_w⁻¹ = w K,     x⁺ = x ⊞ w K ν,     P⁺ = P − w K S Kᵀ
//! Huber(k):      w = min(1, k/d)
//! Student-t(ν):  w = min(1, (ν + m)/(ν + d²))       (the t likelihood's IRLS weight, capped at 1)
//! ```
//!
//! **Guarantees** (for a filter whose joint covariance of (x, ẑ) is positive semi-definite,
//! which makes ‖P^{-1/2} Pₓᵤ S^{-1/2}‖ ≤ 1: every linearised and second-order propagator, and
//! the unscented one with non-negative weights):
//!
//! - **It reduces to the filter's own update, bit for bit,** when w = 1: d ≤ k (Huber), or
//!   d² ≤ m (Student-t). Then the one update computed is the filter's.
//! - **The step is bounded.** The correction is the Kalman one scaled by w, so its length in
//!   the prior's metric is ‖P^{-1/2} w K ν‖ ≤ w d: at most **k** for Huber (whatever the
//!   outlier), at most **(ν + m)/(2√ν)** for Student-t (the maximum of d(ν + m)/(ν + d²)), and
//!   the Student-t step goes to 0 as d → ∞ (a gross outlier is all but ignored).
//! - **The covariance is not overconfident:** P − K S Kᵀ ≤ P⁺ ≤ P; P⁺ is the exact posterior
//!   covariance for the inflated noise R_w.
//!
//! What it does not do: it bounds the damage of one reading, it does not identify the outlier's
//! cause, and a run of consistent biased readings still pulls the estimate (each by ≤ k σ).
//! Gating, when also set on the filter, acts first, on the nominal NIS.
//!
//! Cost: one extra update when w < 1 (the nominal update gives ν and S, the filter is rolled
//! back, the inflated one is applied); none when w = 1.

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::{
    Alloc, Error, LinearMeasurementModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, Parameter, Real, error::Result, scalar::real,
};

use crate::report::{UpdateOutcome, UpdateReport};
use crate::traits::{Rollback, Update};

/// How a robust update weighs an innovation of Mahalanobis length d (see the
/// [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum RobustWeight<T> {
    /// Huber with threshold k (in standard deviations of the innovation, finite and > 0):
    /// w = min(1, k/d). The step is at most k prior standard deviations.
    Huber(T),
    /// Student-t with ν degrees of freedom (finite and > 0): w = min(1, (ν + m)/(ν + d²)).
    /// Redescending: a gross outlier moves the estimate by ~(ν + m)/d.
    StudentT(T),
}

impl<T: Real> RobustWeight<T> {
    /// `Ok` if the parameter is finite and > 0, else [`Error::InvalidParameter`]
    /// (`GateThreshold`: it is the threshold of the weighting, as a gate's is of the gate).
    pub fn validate(&self) -> Result<()> {
        let (RobustWeight::Huber(p) | RobustWeight::StudentT(p)) = *self;
        if p.is_finite() && p > T::zero() {
            Ok(())
        } else {
            Err(Error::InvalidParameter {
                parameter: Parameter::GateThreshold,
                value: estim_core::nalgebra::try_convert::<T, f64>(p).unwrap_or(f64::NAN),
            })
        }
    }

    /// w(d) ∈ (0, 1] for NIS d² = `nis` of an `m`-component measurement.
    ///
    /// ```
    /// use estim_filters::robust::RobustWeight;
    ///
    /// assert_eq!(RobustWeight::Huber(2.0).weight(1.0, 1), 1.0);
    /// assert_eq!(RobustWeight::Huber(2.0).weight(16.0, 1), 0.5); // d = 4: w = k/d
    /// assert_eq!(RobustWeight::StudentT(4.0).weight(11.0, 1), 1.0 / 3.0); // (4+1)/(4+11)
    /// ```
    pub fn weight(&self, nis: T, m: usize) -> T {
        let one = T::one();
        match *self {
            RobustWeight::Huber(k) => {
                let d = nis.sqrt();
                if d <= k { one } else { k / d }
            }
            RobustWeight::StudentT(nu) => {
                let w = (nu + real::<T>(m as f64)) / (nu + nis);
                if w >= one { one } else { w }
            }
        }
    }

    /// The bound on the step's length in the prior's metric, ‖P^{-1/2} (x⁺ − x)‖, for an
    /// `m`-component measurement: k (Huber) or (ν + m)/(2√ν) (Student-t).
    ///
    /// ```
    /// use estim_filters::robust::RobustWeight;
    ///
    /// assert_eq!(RobustWeight::Huber(3.0).step_bound(2), 3.0);
    /// assert_eq!(RobustWeight::StudentT(4.0).step_bound(2), 1.5); // (4 + 2)/(2·2)
    /// ```
    pub fn step_bound(&self, m: usize) -> T {
        match *self {
            RobustWeight::Huber(k) => k,
            RobustWeight::StudentT(nu) => (nu + real::<T>(m as f64)) / (real::<T>(2.0) * nu.sqrt()),
        }
    }
}

/// What [`robust_update`] did: the report of the update applied (for w < 1 its innovation
/// covariance is S/w and its NIS w d², its log-likelihood that of the inflated noise) and the
/// weight.
#[derive(Clone, Debug, PartialEq)]
pub struct RobustReport<T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    /// The report of the update applied.
    pub report: UpdateReport<T, M>,
    /// The weight w ∈ (0, 1] (1: the filter's own update).
    pub weight: T,
    /// The nominal NIS d² = νᵀ S⁻¹ ν the weight was computed from.
    pub nominal_nis: T,
}

/// A measurement model with its noise inflated by a fixed matrix: R′(x) = R(x) + `extra`;
/// everything else forwarded. What [`robust_update`] applies (with extra = (1/w − 1) S).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Vector2};
/// use estim_core::{LinearMeasurement, MeasurementModel};
/// use estim_filters::robust::InflatedNoise;
///
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
/// let inflated = InflatedNoise { model: &sensor, extra: Matrix1::new(2.0) };
/// assert_eq!(inflated.measurement_noise(&Vector2::zeros()), Matrix1::new(2.5));
/// ```
#[derive(Debug)]
pub struct InflatedNoise<'a, H, T: Real, M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    /// The model.
    pub model: &'a H,
    /// What is added to its R.
    pub extra: OMatrix<T, M, M>,
}

impl<H, T, N, M> MeasurementModel<T, N, M> for InflatedNoise<'_, H, T, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.model.measure(x)
    }

    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M> {
        self.model.measurement_noise(x) + &self.extra
    }

    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.residual_into(a, b, out);
    }
}

impl<H, T, N, M> MeasurementJacobian<T, N, M> for InflatedNoise<'_, H, T, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.model.measurement_jacobian(x)
    }
}

impl<H, T, N, M> MeasurementHessian<T, N, M> for InflatedNoise<'_, H, T, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        self.model.measurement_hessian(x, k)
    }
}

impl<H, T, N, M> LinearMeasurementModel<T, N, M> for InflatedNoise<'_, H, T, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: LinearMeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
}

/// Updates `filter` with `z` robustly (see the [module docs](self) for the weights and the
/// guarantees): the nominal update gives d² and S; if w(d) = 1 it is kept as is, otherwise the
/// filter is rolled back and updated with the noise inflated so that S becomes S/w.
///
/// # Errors
///
/// An invalid weight parameter ([`RobustWeight::validate`]), or the filter's own update
/// errors; on error the filter is exactly as it was.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1};
/// use estim_core::{Gaussian, LinearMeasurement};
/// use estim_filters::robust::{RobustWeight, robust_update};
/// use estim_filters::{Estimator, KalmanFilter};
///
/// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
/// let mut kf = KalmanFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?);
/// // A 100σ outlier: S = 2, d = 100/√2; Huber(2) moves the mean by at most 2 prior σ.
/// let r = robust_update(&mut kf, &sensor, &Vector1::new(100.0 * 2f64.sqrt()), RobustWeight::Huber(2.0))?;
/// assert!(r.weight < 0.03);
/// assert!(kf.state()[0] <= 2.0 + 1e-12);
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn robust_update<T, N, M, H, F>(
    filter: &mut F,
    model: &H,
    z: &OVector<T, M>,
    weight: RobustWeight<T>,
) -> Result<RobustReport<T, M>>
where
    T: Real,
    N: Dim,
    M: Dim,
    F: Update<T, N, M, H> + for<'a> Update<T, N, M, InflatedNoise<'a, H, T, M>> + Rollback,
    DefaultAllocator: Alloc<N, M>,
{
    weight.validate()?;
    let saved = filter.snapshot();
    let nominal = Update::<T, N, M, H>::update(filter, model, z)?;
    let d2 = nominal.nis;
    let w = weight.weight(d2, z.nrows());
    if nominal.outcome != UpdateOutcome::Applied || w >= T::one() {
        return Ok(RobustReport {
            report: nominal,
            weight: T::one(),
            nominal_nis: d2,
        });
    }
    filter.restore(&saved);
    let inflated = InflatedNoise {
        model,
        extra: &nominal.innovation_covariance * (T::one() / w - T::one()),
    };
    match Update::<T, N, M, InflatedNoise<'_, H, T, M>>::update(filter, &inflated, z) {
        Ok(report) => Ok(RobustReport {
            report,
            weight: w,
            nominal_nis: d2,
        }),
        Err(e) => {
            filter.restore(&saved);
            Err(e)
        }
    }
}
