//! Covariance analysis: the exact first and second moments of the estimation error that the
//! Monte Carlo of §3.2 estimates, for the consistent filter and for the mismatched ones.
//!
//! Everything is linear and the gains do not depend on the data, so the pair (δx, δx̂) of the
//! true error state and the filter's estimate is Gaussian with a mean and a 6 × 6 covariance C
//! that propagate exactly (Gelb, *Applied Optimal Estimation*, §7.2, "sensitivity analysis"):
//!
//! ```text
//! accelerometer step:  δx⁺ = Φ_t δx − Γ w + d_j,   δx̂⁺ = Φ_f δx̂
//!                      C ← A C Aᵀ + diag(Γ W_t Γᵀ, 0),  A = diag(Φ_t, Φ_f);  m ← A m + (d_j, 0)
//! GPS fix:             δx̂⁺ = K H δx + (I − K H) δx̂ + K η
//!                      C ← B C Bᵀ + (0, K) V (0, K)ᵀ,   B = [[I, 0], [K H, I − K H]];   m ← B m
//! ```
//!
//! with Φ_t, W_t, M₀ of the truth (the scenario), Φ_f, K from the filter's own recursion with
//! its settings, δx(0) ~ N(0, M₀), δx̂(0) = 0. d_j is the deterministic difference between the
//! closed-form truth and one Euler step of it (zero for the Euler-consistent truth, erratum
//! E5); it does not depend on p(0), v(0). From (m, C): the mean error E\[e\] = m_x − m_x̂, the
//! error covariance of e = δx − δx̂ (what P^ave estimates) and the cross-covariance
//! E\[(e − ē)(δx̂ − E δx̂)ᵀ\] (what the orthogonality matrix estimates).

use estim_core::{Error, Quantity, Stage};
use nalgebra::{Matrix2, Matrix3, Matrix3x2, Matrix6, Vector3, Vector6};

use super::filter::{FilterSettings, nearest};
use super::model::{GpsMeasurement, Scenario, TruthIntegration, noise_input, transition_matrix};

/// The exact moments at t = 0 and after every GPS update (a posteriori).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CovarianceAnalysis {
    /// Times \[s\] (0, then the update times).
    pub time: Vec<f64>,
    /// The filter's own P.
    pub filter_covariance: Vec<Matrix3<f64>>,
    /// E\[e\], e = δx − δx̂.
    pub mean_error: Vec<Vector3<f64>>,
    /// cov(e): what the ensemble covariance P^ave estimates.
    pub error_covariance: Vec<Matrix3<f64>>,
    /// cov(e, δx̂), entry (i, j) = error component i with estimate component j.
    pub cross_covariance: Vec<Matrix3<f64>>,
    /// cov(δx̂).
    pub estimate_covariance: Vec<Matrix3<f64>>,
}

impl CovarianceAnalysis {
    /// The index nearest to time `t`.
    pub fn index_at(&self, t: f64) -> usize {
        nearest(&self.time, t)
    }

    /// corr(eᵢ, δx̂ⱼ) at entry `k` (NaN where δx̂ⱼ has no spread, as at t = 0).
    ///
    /// # Panics
    /// When `k` is not an entry (`k` ≥ the length of `time`), as indexing does.
    #[track_caller]
    pub fn orthogonality_correlation(&self, k: usize) -> Matrix3<f64> {
        let (e, x, c) = (
            &self.error_covariance[k],
            &self.estimate_covariance[k],
            &self.cross_covariance[k],
        );
        Matrix3::from_fn(|i, j| {
            let d = (e[(i, i)] * x[(j, j)]).sqrt();
            if d > 0.0 { c[(i, j)] / d } else { f64::NAN }
        })
    }

    /// max over entries of |corr(e, δx̂)| at entry `k` (NaN if none is defined).
    ///
    /// # Panics
    /// When `k` is not an entry, as [`orthogonality_correlation`](Self::orthogonality_correlation).
    #[track_caller]
    pub fn max_orthogonality(&self, k: usize) -> f64 {
        self.orthogonality_correlation(k)
            .iter()
            .filter(|v| v.is_finite())
            .fold(
                f64::NAN,
                |m, v| if m.is_nan() { v.abs() } else { m.max(v.abs()) },
            )
    }

    /// diag cov(e) ./ diag P at entry `k`: 1 for a consistent filter.
    ///
    /// # Panics
    /// When `k` is not an entry (`k` ≥ the length of `time`), as indexing does.
    #[track_caller]
    pub fn covariance_ratio(&self, k: usize) -> Vector3<f64> {
        self.error_covariance[k]
            .diagonal()
            .component_div(&self.filter_covariance[k].diagonal())
    }
}

/// The deterministic error-state drive d_j of the closed-form truth over step j: the exact
/// (p, v) increment minus one Euler step of the truth with a(t_j). Zero for the Euler truth.
pub fn quadrature_drive(scenario: &Scenario, j: usize) -> Vector3<f64> {
    match scenario.truth {
        TruthIntegration::Euler => Vector3::zeros(),
        TruthIntegration::Exact => {
            let dt = scenario.dt;
            let t = j as f64 * dt;
            let (p0, v0) = scenario.exact_position_velocity(0.0, 0.0, t);
            let (p1, v1) = scenario.exact_position_velocity(0.0, 0.0, t + dt);
            let a = scenario.acceleration(t);
            Vector3::new(
                p1 - (p0 + v0 * dt + 0.5 * a * dt * dt),
                v1 - (v0 + a * dt),
                0.0,
            )
        }
    }
}

/// The covariance analysis of the filter `settings` on `scenario` (module docs). Errors if
/// the scenario or settings are invalid or an innovation covariance is singular.
pub fn covariance_analysis(
    scenario: &Scenario,
    settings: &FilterSettings,
) -> Result<CovarianceAnalysis, Error> {
    scenario.validate()?;
    settings.validate()?;
    let dt = scenario.dt;
    let phi_t = transition_matrix(dt, Default::default());
    let phi_f = transition_matrix(dt, settings.coupling);
    let g = noise_input(dt);
    let q_t = g * g.transpose() * scenario.accel_noise_variance;
    let q_f = settings.process().noise_covariance(dt);
    let h = GpsMeasurement::observation();
    let v: Matrix2<f64> = scenario.gps().noise_covariance();

    let mut a = Matrix6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&phi_t);
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&phi_f);
    let mut q = Matrix6::zeros();
    q.fixed_view_mut::<3, 3>(0, 0).copy_from(&q_t);

    let mut c = Matrix6::zeros();
    c.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&scenario.error_prior_covariance());
    let mut m = Vector6::zeros();
    let mut p = settings.initial_covariance;

    let mut out = CovarianceAnalysis::default();
    let mut record = |t: f64, c: &Matrix6<f64>, m: &Vector6<f64>, p: &Matrix3<f64>| {
        let cxx = c.fixed_view::<3, 3>(0, 0).into_owned();
        let cxh = c.fixed_view::<3, 3>(0, 3).into_owned();
        let chh = c.fixed_view::<3, 3>(3, 3).into_owned();
        out.time.push(t);
        out.filter_covariance.push(*p);
        out.mean_error
            .push(m.fixed_rows::<3>(0).into_owned() - m.fixed_rows::<3>(3).into_owned());
        out.error_covariance.push(cxx - cxh - cxh.transpose() + chh);
        out.cross_covariance.push(cxh - chh);
        out.estimate_covariance.push(chh);
    };
    record(0.0, &c, &m, &p);
    let singular = Error::NotPositiveDefinite {
        stage: Stage::Update,
        quantity: Quantity::InnovationCovariance,
    };
    for j in 0..scenario.steps {
        c = a * c * a.transpose() + q;
        m = a * m;
        let d = quadrature_drive(scenario, j);
        for i in 0..3 {
            m[i] += d[i];
        }
        p = phi_f * p * phi_f.transpose() + q_f;
        if (j + 1) % scenario.gps_every == 0 {
            let s = h * p * h.transpose() + v;
            let k: Matrix3x2<f64> = p * h.transpose() * s.try_inverse().ok_or(singular)?;
            let ikh = Matrix3::identity() - k * h;
            p = ikh * p * ikh.transpose() + k * v * k.transpose();
            let mut b = Matrix6::identity();
            b.fixed_view_mut::<3, 3>(3, 0).copy_from(&(k * h));
            b.fixed_view_mut::<3, 3>(3, 3).copy_from(&ikh);
            let mut kv = Matrix6::zeros();
            kv.fixed_view_mut::<3, 3>(3, 3)
                .copy_from(&(k * v * k.transpose()));
            c = b * c * b.transpose() + kv;
            c = (c + c.transpose()) * 0.5;
            m = b * m;
            record((j + 1) as f64 * dt, &c, &m, &p);
        }
    }
    Ok(out)
}

/// The paper's printed residual check (1/N) Σ r(20) r(30)ᵀ (§3.2), which white residuals do
/// not produce (erratum E11).
pub const PAPER_RESIDUAL_CORRELATION: [[f64; 2]; 2] = [[0.0486, -0.0023], [0.0002, 0.0002]];
