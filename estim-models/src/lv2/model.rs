//! Any number of redundant sensing axes at known directions: the general measurement model,
//! its weighted least-squares fusion, the consistency χ², axis screening, and the same fusion
//! done by the framework's Kalman filter.

use core::f64::consts::FRAC_1_SQRT_2;

use estim_core::checks::{ensure_finite, ensure_shape, symmetrize};
use estim_core::nalgebra::{
    Cholesky, Const, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1, U2, U3, Vector1,
    allocator::Allocator,
};
use estim_core::scalar::real;
use estim_core::{
    Alloc, Error, Gaussian, LinearMeasurementModel, MeasurementJacobian, MeasurementModel,
    Quantity, Real, Stage,
};
use estim_filters::{Estimator, KalmanFilter, Update};

use super::error::FusionError;
use super::stats::{chi2_quantile_upper, chi2_sf};
use super::xyq::XyqSigmas;

/// `M` sensing axes measuring the projections of an `N`-dimensional vector (N = 2: in the
/// plane; N = 3: in space) with independent white noise:
///
/// ```text
/// z = H θ + v,   row i of H = uᵢᵀ (the direction of axis i),   v ~ N(0, R),  R = diag(σ₁², …, σ_M²)
/// ```
///
/// Directions are normally unit vectors; any finite row is accepted (a row of length g is an
/// axis with scale factor g). `M` and `N` are nalgebra dimensions: `Const<M>` for sizes fixed
/// at compile time (stack only), `Dyn` for sizes chosen at run time, through the same code.
///
/// It is a [`LinearMeasurementModel`] of the framework (Jacobian H, zero Hessians), so every
/// filter accepts it: fusing the axes is a single Kalman / least-squares update
/// ([`fuse_with_filter`](Self::fuse_with_filter)); [`fuse`](Self::fuse) is the same
/// estimate computed directly as weighted least squares.
#[derive(Clone, Debug, PartialEq)]
pub struct RedundantAxes<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    directions: OMatrix<T, M, N>,
    sigmas: OVector<T, M>,
}

/// The LV2 configuration: x, y and q = (x + y)/√2 (f64, static sizes).
pub type XyqModel = RedundantAxes<f64, U2, U3>;
/// `M` axes in the plane, sizes fixed at compile time.
pub type PlanarAxes<const M: usize> = RedundantAxes<f64, U2, Const<M>>;
/// `M` axes in space, sizes fixed at compile time.
pub type SpatialAxes<const M: usize> = RedundantAxes<f64, U3, Const<M>>;
/// A run-time number of axes in an `N`-dimensional space.
pub type DynAxes<N> = RedundantAxes<f64, N, Dyn>;

/// What screening decided about one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AxisStatus {
    /// The reading is used.
    Used,
    /// Flagged missing by the caller (a dropped sample, a failed channel).
    Missing,
    /// |reading| ≥ the full-scale limit: the converter is at its rail, the reading is biased.
    Saturated,
    /// The reading is NaN or infinite.
    NonFinite,
}

/// Screens readings as the note suggests: an axis is dropped when flagged in `missing`
/// (empty slice: none missing; otherwise one flag per axis), when its reading is not finite,
/// or when |reading| ≥ `full_scale` (`None`: no saturation check).
///
/// Errors: `missing` neither empty nor of length M ([`FusionError::Core`], dimension mismatch).
pub fn screen<T: Real, M: Dim>(
    z: &OVector<T, M>,
    missing: &[bool],
    full_scale: Option<T>,
) -> Result<Vec<AxisStatus>, FusionError>
where
    DefaultAllocator: Allocator<M>,
{
    let m = z.nrows();
    if !missing.is_empty() && missing.len() != m {
        return Err(mask_mismatch(m, missing.len()));
    }
    Ok((0..m)
        .map(|i| {
            if missing.get(i).copied().unwrap_or(false) {
                AxisStatus::Missing
            } else if !z[i].is_finite() {
                AxisStatus::NonFinite
            } else if full_scale.is_some_and(|fs| z[i].abs() >= fs) {
                AxisStatus::Saturated
            } else {
                AxisStatus::Used
            }
        })
        .collect())
}

fn mask_mismatch(expected: usize, found: usize) -> FusionError {
    Error::DimensionMismatch {
        stage: Stage::Update,
        quantity: Quantity::Measurement,
        expected_rows: expected,
        expected_cols: 1,
        found_rows: found,
        found_cols: 1,
    }
    .into()
}

/// The weighted least-squares fusion of the used axes.
#[derive(Clone, Debug, PartialEq)]
pub struct Fusion<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// θ̂ = (Hᵀ R⁻¹ H)⁻¹ Hᵀ R⁻¹ z over the used rows.
    pub estimate: OVector<T, N>,
    /// P = (Hᵀ R⁻¹ H)⁻¹ over the used rows: the covariance of θ̂ − θ.
    pub covariance: OMatrix<T, N, N>,
    /// r = z − H θ̂ on the used axes, 0 on dropped ones.
    pub residual: OVector<T, M>,
    /// rᵀ R⁻¹ r: χ² with `dof` degrees of freedom when the used axes are fault-free and
    /// Gaussian.
    pub chi2: T,
    /// Used axes − N (the redundancy left).
    pub dof: usize,
    /// What screening decided, per axis.
    pub status: Vec<AxisStatus>,
}

impl<N: Dim, M: Dim> Fusion<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// P(χ²_dof > chi2): the probability of a χ² at least this large from fault-free axes
    /// (1 when no redundancy is left).
    pub fn p_value(&self) -> f64 {
        chi2_sf(self.chi2, self.dof)
    }

    /// Whether the axes pass the consistency test at false-alarm rate `false_alarm`
    /// (χ² ≤ the upper α quantile of χ²_dof). Always `true` without redundancy (dof = 0).
    pub fn is_consistent(&self, false_alarm: f64) -> bool {
        self.dof == 0 || self.chi2 <= chi2_quantile_upper(false_alarm, self.dof)
    }
}

/// The same fusion by the framework: an exact prior from N independent axes, then Kalman
/// updates with the others (see [`RedundantAxes::fuse_with_filter`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FilterFusion<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The filter's final state.
    pub estimate: OVector<T, N>,
    /// The filter's final covariance.
    pub covariance: OMatrix<T, N, N>,
    /// The sum of the updates' normalised innovations squared; equals the WLS rᵀ R⁻¹ r.
    pub chi2: T,
    /// Number of scalar updates (= used axes − N).
    pub dof: usize,
    /// The axes that gave the exact prior, in order.
    pub initial_axes: Vec<usize>,
    /// The axes then applied as Kalman updates, in order.
    pub update_axes: Vec<usize>,
}

impl<T: Real, N: Dim, M: Dim> RedundantAxes<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Axes with directions (rows of `directions`, M × N) and noise standard deviations
    /// `sigmas`.
    ///
    /// Errors ([`FusionError::Core`]): a shape mismatch (runtime sizes), non-finite entries,
    /// a σ ≤ 0.
    pub fn new(directions: OMatrix<T, M, N>, sigmas: OVector<T, M>) -> Result<Self, FusionError> {
        let stage = Stage::Construction;
        ensure_shape(
            &sigmas,
            directions.nrows(),
            1,
            stage,
            Quantity::MeasurementNoise,
        )?;
        ensure_finite(&directions, stage, Quantity::Jacobian)?;
        ensure_finite(&sigmas, stage, Quantity::MeasurementNoise)?;
        if !sigmas.iter().all(|s| *s > T::zero()) {
            return Err(Error::NotPositiveDefinite {
                stage,
                quantity: Quantity::MeasurementNoise,
            }
            .into());
        }
        Ok(Self { directions, sigmas })
    }

    /// H: the axis directions as rows (M × N).
    pub fn directions(&self) -> &OMatrix<T, M, N> {
        &self.directions
    }

    /// The noise standard deviations σᵢ.
    pub fn sigmas(&self) -> &OVector<T, M> {
        &self.sigmas
    }

    /// The number of axes M.
    pub fn len(&self) -> usize {
        self.directions.nrows()
    }

    /// Whether there are no axes (possible only with `Dyn`).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The dimension N of the sensed vector.
    pub fn state_dim(&self) -> usize {
        self.directions.ncols()
    }

    /// Axis `i` alone, as a one-component model (`None` if out of range).
    pub fn axis(&self, i: usize) -> Option<RedundantAxes<T, N, U1>>
    where
        DefaultAllocator: Alloc<N, U1>,
    {
        (i < self.len()).then(|| RedundantAxes {
            directions: self.directions.row(i).into_owned(),
            sigmas: Vector1::new(self.sigmas[i]),
        })
    }

    /// The axes `indices`, in that order, as a runtime-sized model (`None` if an index is out
    /// of range).
    pub fn select(&self, indices: &[usize]) -> Option<RedundantAxes<T, N, Dyn>>
    where
        DefaultAllocator: Alloc<N, Dyn>,
    {
        if indices.iter().any(|&i| i >= self.len()) {
            return None;
        }
        let (_, ndim) = self.directions.shape_generic();
        let k = Dyn(indices.len());
        Some(RedundantAxes {
            directions: OMatrix::from_fn_generic(k, ndim, |r, c| self.directions[(indices[r], c)]),
            sigmas: OVector::from_fn_generic(k, U1, |r, _| self.sigmas[indices[r]]),
        })
    }

    /// The noise-free reading H θ.
    pub fn ideal_reading(&self, theta: &OVector<T, N>) -> OVector<T, M> {
        &self.directions * theta
    }

    /// Weighted least squares over every axis with a finite reading (equivalently
    /// [`fuse_screened`](Self::fuse_screened) with [`screen`]`(z, &[], None)`).
    pub fn fuse(&self, z: &OVector<T, M>) -> Result<Fusion<T, N, M>, FusionError> {
        let status = screen(z, &[], None)?;
        self.fuse_screened(z, &status)
    }

    /// Weighted least squares over the axes marked [`AxisStatus::Used`]:
    ///
    /// ```text
    /// θ̂ = (Hᵤᵀ Rᵤ⁻¹ Hᵤ)⁻¹ Hᵤᵀ Rᵤ⁻¹ zᵤ,   P = (Hᵤᵀ Rᵤ⁻¹ Hᵤ)⁻¹,   χ² = rᵤᵀ Rᵤ⁻¹ rᵤ,  rᵤ = zᵤ − Hᵤ θ̂
    /// ```
    ///
    /// solved through the Cholesky factor of the information matrix Hᵤᵀ Rᵤ⁻¹ Hᵤ (N × N).
    ///
    /// Errors: fewer used axes than N ([`FusionError::TooFewAxes`]); used axes that do not span
    /// the space ([`FusionError::DependentAxes`]); wrong `z`/`status` length or a non-finite
    /// used reading ([`FusionError::Core`]).
    pub fn fuse_screened(
        &self,
        z: &OVector<T, M>,
        status: &[AxisStatus],
    ) -> Result<Fusion<T, N, M>, FusionError> {
        let m = self.len();
        let n = self.state_dim();
        let used = self.used_axes(z, status)?;
        if used.len() < n {
            return Err(FusionError::TooFewAxes {
                usable: used.len(),
                required: n,
            });
        }
        let (_, ndim) = self.directions.shape_generic();
        let mut info = OMatrix::<T, N, N>::zeros_generic(ndim, ndim);
        let mut rhs = OVector::<T, N>::zeros_generic(ndim, U1);
        for &i in &used {
            let h = self.directions.row(i).transpose();
            let w = T::one() / (self.sigmas[i] * self.sigmas[i]);
            info.ger(w, &h, &h, T::one());
            rhs.axpy(w * z[i], &h, T::one());
        }
        let chol = full_rank_cholesky(info).ok_or(FusionError::DependentAxes {
            usable: used.len(),
            required: n,
        })?;
        let estimate = chol.solve(&rhs);
        let mut covariance = chol.inverse();
        symmetrize(&mut covariance);
        let predicted = &self.directions * &estimate;
        let mut residual = z - predicted;
        let mut chi2 = T::zero();
        for i in 0..m {
            if status[i] == AxisStatus::Used {
                let u = residual[i] / self.sigmas[i];
                chi2 += u * u;
            } else {
                residual[i] = T::zero();
            }
        }
        let stage = Stage::Update;
        ensure_finite(&estimate, stage, Quantity::Mean)?;
        ensure_finite(&covariance, stage, Quantity::Covariance)?;
        Ok(Fusion {
            estimate,
            covariance,
            residual,
            chi2,
            dof: used.len() - n,
            status: status.to_vec(),
        })
    }

    /// The same fusion through the framework, with no approximation:
    ///
    /// 1. pick N used axes A that are as far from dependent as possible (pivoted Gram–Schmidt:
    ///    each next axis is the one at the largest angle to the span of those already
    ///    picked, ties to the lowest index; for x, y, q this is x then y) and solve them
    ///    exactly, θ₀ = H_A⁻¹ z_A, P₀ = H_A⁻¹ R_A H_A⁻ᵀ: this is the posterior given those
    ///    axes alone under a flat prior (the pivoting keeps P₀, and so the round-off of the
    ///    later updates, small);
    /// 2. start a [`KalmanFilter`] at N(θ₀, P₀) and update it with each remaining used axis
    ///    in turn, as a one-axis [`RedundantAxes`].
    ///
    /// Sequential Bayesian updates of an exact posterior give the posterior given all axes,
    /// which for a linear-Gaussian model is the WLS estimate and covariance, so this agrees
    /// with [`fuse_screened`](Self::fuse_screened) to round-off; and the normalised innovations
    /// squared add up to the WLS χ² (each NIS is the increase of the minimum of the WLS
    /// cost when one axis is added). A diffuse prior N(0, κ I) instead would only approximate
    /// it, with an O(1/κ) error.
    ///
    /// Errors: as [`fuse_screened`](Self::fuse_screened), plus framework errors from the
    /// filter.
    pub fn fuse_with_filter(
        &self,
        z: &OVector<T, M>,
        status: &[AxisStatus],
    ) -> Result<FilterFusion<T, N>, FusionError>
    where
        DefaultAllocator: Alloc<N, U1>,
    {
        let n = self.state_dim();
        let used = self.used_axes(z, status)?;
        if used.len() < n {
            return Err(FusionError::TooFewAxes {
                usable: used.len(),
                required: n,
            });
        }
        let initial = self.pivot_axes(&used).ok_or(FusionError::DependentAxes {
            usable: used.len(),
            required: n,
        })?;
        let prior = self.exact_prior(z, &initial)?;
        let mut filter = KalmanFilter::new(prior);
        let mut chi2 = T::zero();
        let mut update_axes = Vec::with_capacity(used.len() - n);
        for &i in used.iter().filter(|i| !initial.contains(i)) {
            let axis = self.axis(i).ok_or(mask_mismatch(self.len(), i))?;
            let report = filter.update(&axis, &Vector1::new(z[i]))?;
            chi2 += report.nis;
            update_axes.push(i);
        }
        Ok(FilterFusion {
            estimate: filter.state().clone(),
            covariance: filter.covariance().clone(),
            chi2,
            dof: update_axes.len(),
            initial_axes: initial,
            update_axes,
        })
    }

    /// The exact estimate from exactly N axes `axes` (indices): θ₀ = H_A⁻¹ z_A,
    /// P₀ = H_A⁻¹ R_A H_A⁻ᵀ, as a [`Gaussian`] to start a filter from.
    ///
    /// Errors: `axes.len() ≠ N` or an index out of range ([`FusionError::Core`], dimension
    /// mismatch); H_A singular ([`FusionError::DependentAxes`]); a non-finite result.
    pub fn exact_prior(
        &self,
        z: &OVector<T, M>,
        axes: &[usize],
    ) -> Result<Gaussian<T, N>, FusionError> {
        let n = self.state_dim();
        if axes.len() != n || axes.iter().any(|&i| i >= self.len()) {
            return Err(mask_mismatch(n, axes.len()));
        }
        let (_, ndim) = self.directions.shape_generic();
        let a =
            OMatrix::<T, N, N>::from_fn_generic(ndim, ndim, |r, c| self.directions[(axes[r], c)]);
        let inv = a.try_inverse().ok_or(FusionError::DependentAxes {
            usable: n,
            required: n,
        })?;
        let z_a = OVector::<T, N>::from_fn_generic(ndim, U1, |r, _| z[axes[r]]);
        let r_a = OMatrix::<T, N, N>::from_fn_generic(ndim, ndim, |r, c| {
            if r == c {
                self.sigmas[axes[r]] * self.sigmas[axes[r]]
            } else {
                T::zero()
            }
        });
        let mean = &inv * z_a;
        let mut cov = &inv * r_a * inv.transpose();
        symmetrize(&mut cov);
        Ok(Gaussian::new(mean, cov)?)
    }

    /// Indices of the used axes, after checking lengths and finiteness.
    fn used_axes(
        &self,
        z: &OVector<T, M>,
        status: &[AxisStatus],
    ) -> Result<Vec<usize>, FusionError> {
        let m = self.len();
        ensure_shape(z, m, 1, Stage::Update, Quantity::Measurement)?;
        if status.len() != m {
            return Err(mask_mismatch(m, status.len()));
        }
        let used: Vec<usize> = (0..m).filter(|&i| status[i] == AxisStatus::Used).collect();
        if used.iter().any(|&i| !z[i].is_finite()) {
            return Err(Error::NonFinite {
                stage: Stage::Update,
                quantity: Quantity::Measurement,
            }
            .into());
        }
        Ok(used)
    }

    /// N of the axes `candidates` chosen by pivoted Gram–Schmidt (largest sin² of the angle to
    /// the span of the axes already chosen, first index on ties), or `None` when the best
    /// remaining sin² is ≤ 10⁴ n ε (the candidates do not span the space).
    fn pivot_axes(&self, candidates: &[usize]) -> Option<Vec<usize>> {
        let n = self.state_dim();
        let tol = real::<T>(1e4 * n as f64) * T::default_epsilon();
        let mut basis: Vec<OVector<T, N>> = Vec::with_capacity(n);
        let mut chosen = Vec::with_capacity(n);
        while chosen.len() < n {
            let mut best: Option<(T, usize, OVector<T, N>)> = None;
            for &i in candidates.iter().filter(|i| !chosen.contains(*i)) {
                let u = self.directions.row(i).transpose();
                let norm2 = u.norm_squared();
                if !(norm2 > T::zero()) {
                    continue;
                }
                let mut v = u;
                for b in &basis {
                    let c = b.dot(&v);
                    v.axpy(-c, b, T::one());
                }
                let sin2 = v.norm_squared() / norm2;
                if best.as_ref().is_none_or(|(s, _, _)| sin2 > *s) {
                    best = Some((sin2, i, v));
                }
            }
            let (sin2, i, v) = best?;
            if !(sin2 > tol) {
                return None;
            }
            let len = v.norm();
            basis.push(v / len);
            chosen.push(i);
        }
        Some(chosen)
    }
}

impl<T: Real, M: Dim> RedundantAxes<T, U2, M>
where
    DefaultAllocator: Alloc<U2, M>,
{
    /// Axes in the plane at angles `angles` (rad, from the x axis towards y): uᵢ = (cos aᵢ,
    /// sin aᵢ). Errors as [`new`](Self::new).
    pub fn planar(angles: &OVector<T, M>, sigmas: OVector<T, M>) -> Result<Self, FusionError> {
        let (mdim, _) = angles.shape_generic();
        let directions = OMatrix::<T, M, U2>::from_fn_generic(mdim, U2, |i, c| {
            if c == 0 {
                angles[i].cos()
            } else {
                angles[i].sin()
            }
        });
        Self::new(directions, sigmas)
    }
}

impl RedundantAxes<f64, U2, U3> {
    /// The LV2 axes: x = (1, 0), y = (0, 1), q = (1/√2, 1/√2), in that order, with σx, σy, σq.
    ///
    /// Errors: a σ not finite or ≤ 0.
    pub fn xyq(s: &XyqSigmas) -> Result<Self, FusionError> {
        let h = OMatrix::<f64, U3, U2>::new(1.0, 0.0, 0.0, 1.0, FRAC_1_SQRT_2, FRAC_1_SQRT_2);
        Self::new(h, OVector::<f64, U3>::new(s.x, s.y, s.q))
    }
}

/// The Cholesky factor of a symmetric information (or Gram) matrix, or `None` when it is
/// singular to working precision: a pivot Lᵢᵢ² ≤ 10⁴ n ε max Aⱼⱼ. (The estimate along such a
/// direction would be amplified by more than ≈ 10¹¹ relative to the best one: not an estimate.)
fn full_rank_cholesky<T: Real, D: Dim>(a: OMatrix<T, D, D>) -> Option<Cholesky<T, D>>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = a.nrows();
    let max_diag = (0..n).fold(T::zero(), |m, i| m.max(a[(i, i)].abs()));
    if !(max_diag > T::zero()) || !max_diag.is_finite() {
        return None;
    }
    let tol = real::<T>(1e4 * n as f64) * T::default_epsilon() * max_diag;
    let chol = Cholesky::new(a)?;
    let l = chol.l_dirty();
    (0..n).all(|i| l[(i, i)] * l[(i, i)] > tol).then_some(chol)
}

impl<T: Real, N: Dim, M: Dim> MeasurementModel<T, N, M> for RedundantAxes<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// h(θ) = H θ.
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        &self.directions * x
    }

    /// R = diag(σᵢ²).
    fn measurement_noise(&self, _: &OVector<T, N>) -> OMatrix<T, M, M> {
        OMatrix::from_diagonal(&self.sigmas.map(|s| s * s))
    }
}

impl<T: Real, N: Dim, M: Dim> MeasurementJacobian<T, N, M> for RedundantAxes<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// ∂h/∂θ = H (constant).
    fn measurement_jacobian(&self, _: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.directions.clone()
    }
}

impl<T: Real, N: Dim, M: Dim> LinearMeasurementModel<T, N, M> for RedundantAxes<T, N, M> where
    DefaultAllocator: Alloc<N, M>
{
}

/// Affine: every Hessian is zero.
impl<T: Real, N: Dim, M: Dim> estim_core::MeasurementHessian<T, N, M> for RedundantAxes<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_hessian(&self, _: &OVector<T, N>, _: usize) -> Option<OMatrix<T, N, N>> {
        None
    }
}
