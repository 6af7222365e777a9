//! The iterated extended Kalman filter: Gauss–Newton iterations on the measurement update.

use estim_core::checks::ensure_shape;
use estim_core::kernel::{self, CholeskyScratch};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::scalar::real;
use estim_core::{
    Alloc, Error, Euclidean, Gaussian, Linearized, MeasurementJacobian, MeasurementModel,
    Parameter, ProcessModel, Quantity, Real, Stage, error::Result,
};

use crate::gaussian_filter::{Ekf, measurement_update};
use crate::report::{Iterations, UpdateReport};
use crate::scratch::UpdateScratch;
use crate::snapshot::EstimateSnapshot;
use crate::traits::{Estimator, OnStateSpace, Predict, PredictCross, Rollback, Update};
use crate::update::{CovarianceUpdate, Gate, UpdateSettings};

/// Most step halvings of the step-size safeguard per Gauss–Newton step: 2⁻³⁰ ≈ 10⁻⁹ of the
/// full step, below which a step cannot lower the cost beyond round-off anyway.
const MAX_HALVINGS: usize = 30;

/// The iterated extended Kalman filter (Bell & Cathey 1993): the EKF's prediction, and a
/// measurement update that relinearises h at its own result until the estimate stops moving.
///
/// The update is Gauss–Newton on the maximum a posteriori cost of the step,
///
/// ```text
/// J(x) = ½ |z ⊖ h(x)|²_{R⁻¹} + ½ |x − x⁻|²_{P⁻⁻¹},
/// ```
///
/// starting from the prediction x₀ = x⁻. Step i linearises at xᵢ, with Hᵢ = ∂h/∂x(xᵢ):
///
/// ```text
/// Kᵢ   = P⁻ Hᵢᵀ (Hᵢ P⁻ Hᵢᵀ + R)⁻¹
/// gᵢ   = x⁻ + Kᵢ (z ⊖ [h(xᵢ) + Hᵢ (x⁻ − xᵢ)])      (the Gauss–Newton point)
/// xᵢ₊₁ = xᵢ + t (gᵢ − xᵢ),  t = 1, ½, ¼, …          (the first t with J(xᵢ₊₁) ≤ J(xᵢ) (1 + 16 ε))
/// ```
///
/// Each step is the crate's shared Kalman update (see [`crate::update`]) applied to the affine
/// model h(xᵢ) + Hᵢ (x − xᵢ) at the prior, so the gain, the factorisation, the checks and the
/// covariance form are the EKF's. The iteration stops when
/// ‖xᵢ₊₁ − xᵢ‖ ≤ tol · (‖xᵢ₊₁‖ + √tr P⁻) (a step small relative to the state, with the
/// prior's spread as the floor so that a state near zero still converges; both terms are in
/// the state's units), after the iteration cap, or when no halving (at most 30) gives a J no
/// larger than the current one (within its round-off, 16 ε J).
/// The covariance is that of the last step, at its linearisation Hᵢ, in the filter's form
/// (Joseph by default: P⁺ = (I − Kᵢ Hᵢ) P⁻ (I − Kᵢ Hᵢ)ᵀ + Kᵢ R Kᵢᵀ).
///
/// **The step-size safeguard** needs J, so it needs P⁻ and R positive definite (each is
/// factorised once per update, when more than one iteration is allowed); when either is only
/// semi-definite the full Gauss–Newton steps are taken.
///
/// **The report.** The innovation, its covariance, the NIS and the log-likelihood are those
/// of the first linearisation, at x⁻: the EKF's predictive statistics of z, which the gate
/// also uses (a gated update does not iterate). [`UpdateReport::iterations`] says how the
/// iterations went ([`Iterations`]).
///
/// **One iteration is the EKF, bit for bit** (`with_iterations(1, _)`): the first step is the
/// EKF's update itself, run through the same code on the same values (at its linearisation
/// point the affine model returns h(x⁻) itself, not h(x⁻) + H · 0), and with one iteration
/// the safeguard is off (J is not even formed). With more iterations the first step, too, is
/// halved if it raises J.
///
/// Requirements on the model: Jacobians ([`ProcessJacobian`](estim_core::ProcessJacobian),
/// [`MeasurementJacobian`]). The state is a vector (the EKF's [`Euclidean`] state space) and R is
/// evaluated once per update, at x⁻ (as every filter of the crate does). An update allocates
/// its buffers with runtime sizes (static sizes: nothing).
///
/// Reference: B. M. Bell and F. W. Cathey, "The iterated Kalman filter update as a
/// Gauss–Newton method", IEEE Trans. Automatic Control 38(2), 1993.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix2, RowVector2, Vector1, Vector2};
/// use estim_core::{Gaussian, MeasurementJacobian, MeasurementModel};
/// use estim_filters::{Ekf, Estimator, Iekf, Update};
///
/// /// A range |p| to a 2-D position p.
/// struct Range;
/// impl MeasurementModel<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1> for Range {
///     fn measure(&self, p: &Vector2<f64>) -> Vector1<f64> { Vector1::new(p.norm()) }
///     fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix1<f64> { Matrix1::new(0.01) }
/// }
/// impl MeasurementJacobian<f64, estim_core::nalgebra::U2, estim_core::nalgebra::U1> for Range {
///     fn measurement_jacobian(&self, p: &Vector2<f64>) -> RowVector2<f64> {
///         (p / p.norm()).transpose()
///     }
/// }
/// let prior = Gaussian::new(Vector2::new(10.0, 0.0), Matrix2::identity() * 4.0)?;
/// let mut iekf = Iekf::new(prior.clone()).with_iterations(20, 1e-10)?;
/// let report = iekf.update(&Range, &Vector1::new(7.0))?;
/// let its = report.iterations.unwrap();
/// assert!(its.converged && its.count >= 2);
/// // One iteration is the EKF.
/// let mut one = Iekf::new(prior.clone()).with_iterations(1, 0.0)?;
/// let mut ekf = Ekf::new(prior);
/// one.update(&Range, &Vector1::new(7.0))?;
/// ekf.update(&Range, &Vector1::new(7.0))?;
/// assert_eq!(one.state(), ekf.state());
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Iekf<T: Real, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    filter: Ekf<T, N>,
    max_iterations: usize,
    tolerance: T,
}

impl<T: Real, N: Dim> Iekf<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// Most Gauss–Newton steps per update [`with_iterations`](Self::with_iterations) accepts.
    pub const MAX_ITERATIONS: usize = 1000;

    /// A filter starting from `prior`, with at most 10 Gauss–Newton steps per update and the
    /// step tolerance √ε (1.5 · 10⁻⁸ in `f64`, 3.5 · 10⁻⁴ in `f32`).
    pub fn new(prior: Gaussian<T, N>) -> Self {
        Self::from_ekf(Ekf::new(prior))
    }

    /// The iterated filter built on `filter`'s estimate, gate and covariance form.
    pub fn from_ekf(filter: Ekf<T, N>) -> Self {
        Self {
            filter,
            max_iterations: 10,
            tolerance: T::default_epsilon().sqrt(),
        }
    }

    /// At most `max` Gauss–Newton steps per update (1 ≤ `max` ≤ [`MAX_ITERATIONS`](Self::MAX_ITERATIONS):
    /// [`Parameter::StepCount`]), stopping early once a step is within `tolerance` (relative;
    /// see the [type docs](Self); finite and ≥ 0: [`Parameter::Tolerance`]; 0 runs every step
    /// until the estimate stops changing).
    ///
    /// ```
    /// use estim_core::{Error, Gaussian, Parameter, nalgebra::{Matrix1, Vector1}};
    /// use estim_filters::Iekf;
    /// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
    /// assert!(Iekf::new(prior.clone()).with_iterations(5, 1e-9).is_ok());
    /// assert!(matches!(
    ///     Iekf::new(prior).with_iterations(0, 1e-9),
    ///     Err(Error::InvalidParameter { parameter: Parameter::StepCount, .. })
    /// ));
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn with_iterations(mut self, max: usize, tolerance: T) -> Result<Self> {
        if !(1..=Self::MAX_ITERATIONS).contains(&max) {
            return Err(Error::InvalidParameter {
                parameter: Parameter::StepCount,
                value: max as f64,
            });
        }
        if !(tolerance.is_finite() && tolerance >= T::zero()) {
            return Err(Error::InvalidParameter {
                parameter: Parameter::Tolerance,
                value: estim_core::nalgebra::try_convert::<T, f64>(tolerance).unwrap_or(f64::NAN),
            });
        }
        self.max_iterations = max;
        self.tolerance = tolerance;
        Ok(self)
    }

    /// Gates the measurements as [`GaussianFilter::with_gate`](crate::GaussianFilter::with_gate)
    /// does, on the first linearisation's NIS.
    pub fn with_gate(self, gate: impl Into<Gate<T>>) -> Result<Self> {
        Ok(Self {
            filter: self.filter.with_gate(gate)?,
            ..self
        })
    }

    /// Uses `form` for the covariance of every step (default: Joseph).
    pub fn with_covariance_update(self, form: CovarianceUpdate) -> Self {
        Self {
            filter: self.filter.with_covariance_update(form),
            ..self
        }
    }

    /// The iteration cap and the step tolerance.
    pub fn iterations(&self) -> (usize, T) {
        (self.max_iterations, self.tolerance)
    }

    /// The EKF underneath (its estimate is this filter's).
    pub fn ekf(&self) -> &Ekf<T, N> {
        &self.filter
    }
}

impl<T: Real, N: Dim> Estimator<T, N> for Iekf<T, N>
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

/// The inner EKF's snapshot: the iteration settings are configuration.
impl<T: Real, N: Dim> Rollback for Iekf<T, N>
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

/// Euclidean, as its inner EKF.
impl<T: Real, N: Dim> OnStateSpace<T, N> for Iekf<T, N>
where
    DefaultAllocator: Alloc<N>,
{
    type Space = Euclidean;

    fn state_space(&self) -> &Euclidean {
        self.filter.state_space()
    }
}

/// The EKF's prediction, so an IEKF run can be smoothed.
impl<T, N, P> PredictCross<T, N, P> for Iekf<T, N>
where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N>,
    Ekf<T, N>: PredictCross<T, N, P>,
    DefaultAllocator: Alloc<N>,
{
    fn predict_with_cross_covariance(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<OMatrix<T, N, N>> {
        self.filter.predict_with_cross_covariance(model, input, dt)
    }
}

/// The EKF's prediction.
impl<T, N, P> Predict<T, N, P> for Iekf<T, N>
where
    T: Real,
    N: Dim,
    P: ProcessModel<T, N>,
    Ekf<T, N>: Predict<T, N, P>,
    DefaultAllocator: Alloc<N>,
{
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.filter.predict(model, input, dt)
    }

    fn prepare_predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.filter.prepare_predict(model, input, dt)
    }
}

impl<T, N, M, H> Update<T, N, M, H> for Iekf<T, N>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    /// The iterated update (see the [type docs](Iekf)); on error the filter is unchanged.
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        let (max, tol) = (self.max_iterations, self.tolerance);
        let (state, covariance, settings) = self.filter.estimate_mut();
        let posterior = iterate(state, covariance, settings, max, tol, model, z, report)?;
        if let Some((x, p)) = posterior {
            *state = x;
            *covariance = p;
        }
        Ok(())
    }
}

/// The iterated update from the prior (x⁻, P⁻): the posterior (`None` if gated), the report
/// filled in. Nothing is written to the filter.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn iterate<T, N, M, H>(
    prior: &OVector<T, N>,
    prior_covariance: &OMatrix<T, N, N>,
    settings: UpdateSettings<T>,
    max: usize,
    tol: T,
    model: &H,
    z: &OVector<T, M>,
    report: &mut UpdateReport<T, M>,
) -> Result<Option<(OVector<T, N>, OMatrix<T, N, N>)>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let (n, m) = (prior.shape_generic().0, z.shape_generic().0);
    let mut work = UpdateScratch::<T, N, M, Linearized>::new(n, m);
    // Step 0, at the prior: the EKF's update, whose report is the one returned.
    let mut point = prior.clone();
    let lin = Linearization::at(model, &point, m);
    let applied = measurement_update(
        &Linearized,
        &Euclidean,
        prior,
        prior_covariance,
        &lin,
        z,
        settings,
        &mut work,
        report,
    )?;
    if !applied {
        report.iterations = Some(Iterations {
            count: 0,
            converged: false,
            step_norm: T::zero(),
        });
        return Ok(None);
    }
    let cost = (max > 1)
        .then(|| MapCost::new(model, prior, prior_covariance, z))
        .flatten();
    let spread = (0..prior_covariance.nrows())
        .fold(T::zero(), |s, i| {
            s + prior_covariance[(i, i)].max(T::zero())
        })
        .sqrt();
    let mut current_cost = cost.as_ref().map(|c| c.eval(model, z, prior, &point));
    let mut scratch_report = UpdateReport::zeros(m);
    // The gate judged step 0 (the EKF's statistics); later steps are never gated.
    let mut later = settings;
    later.gate = None;
    let mut count = 1;
    let (mut converged, mut step_norm);
    loop {
        // work.state holds the Gauss–Newton point gᵢ from `point`, work.covariance its P.
        let gauss_newton = work.state.clone();
        let full = &gauss_newton - &point;
        let full_norm = full.norm();
        let (next, next_cost) = if full_norm <= tol * (gauss_newton.norm() + spread) {
            converged = true;
            (gauss_newton, None)
        } else {
            converged = false;
            match (&cost, current_cost) {
                (Some(c), Some(j0)) => match backtrack(c, model, z, prior, &point, &full, j0) {
                    Some((x, j)) => (x, Some(j)),
                    // No halving lowers J: stop at the current point, which the last step's
                    // covariance linearised at.
                    None => {
                        step_norm = T::zero();
                        break;
                    }
                },
                _ => (gauss_newton, None),
            }
        };
        step_norm = (&next - &point).norm();
        point = next;
        current_cost = next_cost.or(current_cost);
        if converged || count == max {
            break;
        }
        // Step `count`, at the new point.
        let lin = Linearization::at(model, &point, m);
        lin.ensure_shapes(n.value())?;
        measurement_update(
            &Linearized,
            &Euclidean,
            prior,
            prior_covariance,
            &lin,
            z,
            later,
            &mut work,
            &mut scratch_report,
        )?;
        count += 1;
    }
    report.iterations = Some(Iterations {
        count,
        converged,
        step_norm,
    });
    let covariance = work.covariance.clone();
    Ok(Some((point, covariance)))
}

/// The first of xᵢ + t d, t = 1, ½, … (at most [`MAX_HALVINGS`] halvings) whose cost does not
/// exceed `j0` beyond its round-off, and its cost; t = 1 gives xᵢ + d as computed (the
/// Gauss–Newton point itself). `None` if none does.
fn backtrack<T, N, M, H>(
    cost: &MapCost<T, N, M>,
    model: &H,
    z: &OVector<T, M>,
    prior: &OVector<T, N>,
    point: &OVector<T, N>,
    full: &OVector<T, N>,
    j0: T,
) -> Option<(OVector<T, N>, T)>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let half = real::<T>(0.5);
    // J is computed with a relative error of a few ε, so near the minimum, where a step
    // changes J by less than that, "no increase" is judged within 16 ε J: otherwise every
    // step below √(ε J / ‖∇²J‖) would look like an increase and the iteration would stall
    // short of its tolerance.
    let slack = real::<T>(16.0) * T::default_epsilon() * j0.abs();
    let mut t = T::one();
    for k in 0..=MAX_HALVINGS {
        let candidate = if k == 0 {
            point + full
        } else {
            point + full * t
        };
        if candidate == *point {
            // The step vanished in round-off: nothing left to try.
            return None;
        }
        let j = cost.eval(model, z, prior, &candidate);
        // A NaN cost (h undefined there) is a rejection.
        if j <= j0 + slack {
            return Some((candidate, j));
        }
        t *= half;
    }
    None
}

/// The factors of R and P⁻ that evaluate the MAP cost J(x) with two triangular solves.
struct MapCost<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    noise_factor: OMatrix<T, M, M>,
    prior_factor: OMatrix<T, N, N>,
}

impl<T: Real, N: Dim, M: Dim> MapCost<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// `None` unless R(x⁻) and P⁻ are positive definite.
    fn new<H: MeasurementModel<T, N, M>>(
        model: &H,
        prior: &OVector<T, N>,
        prior_covariance: &OMatrix<T, N, N>,
        z: &OVector<T, M>,
    ) -> Option<Self> {
        let m = z.shape_generic().0;
        let mut noise_factor = OMatrix::zeros_generic(m, m);
        estim_core::model::measurement_noise_into(model, prior, &mut noise_factor);
        let mut prior_factor = prior_covariance.clone();
        let mut scratch = CholeskyScratch::default();
        let ok = noise_factor.shape() == (m.value(), m.value())
            && kernel::cholesky_in_place(&mut noise_factor, &mut scratch)
            && kernel::cholesky_in_place(&mut prior_factor, &mut scratch);
        ok.then_some(Self {
            noise_factor,
            prior_factor,
        })
    }

    /// J(x) = ½ |L_R⁻¹ (z ⊖ h(x))|² + ½ |L_P⁻¹ (x − x⁻)|².
    fn eval<H: MeasurementModel<T, N, M>>(
        &self,
        model: &H,
        z: &OVector<T, M>,
        prior: &OVector<T, N>,
        x: &OVector<T, N>,
    ) -> T {
        let predicted = model.measure(x);
        if predicted.shape() != z.shape() {
            // NaN: the step is rejected.
            return T::zero() / T::zero();
        }
        let mut r = predicted.clone();
        model.residual_into(z, &predicted, &mut r);
        if r.shape() != z.shape() {
            return T::zero() / T::zero();
        }
        kernel::solve_lower_in_place(&self.noise_factor, &mut r);
        let mut d = x - prior;
        kernel::solve_lower_in_place(&self.prior_factor, &mut d);
        real::<T>(0.5) * (r.norm_squared() + d.norm_squared())
    }
}

/// The affine model h(xᵢ) + Hᵢ (x − xᵢ) of `model` linearised at xᵢ, with `model`'s noise and
/// residual.
struct Linearization<'a, H, T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    model: &'a H,
    point: OVector<T, N>,
    value: OVector<T, M>,
    jacobian: OMatrix<T, M, N>,
}

impl<'a, H, T, N, M> Linearization<'a, H, T, N, M>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    /// h and ∂h/∂x at `point`, in place for an [`InPlace`](estim_core::InPlace) model (as the
    /// EKF calls them).
    fn at(model: &'a H, point: &OVector<T, N>, m: M) -> Self {
        let n = point.shape_generic().0;
        let mut value = OVector::zeros_generic(m, U1);
        estim_core::model::measure_into(model, point, &mut value);
        let mut jacobian = OMatrix::zeros_generic(m, n);
        estim_core::function::jacobian_into(
            &estim_core::Observation::new(model),
            point,
            &mut jacobian,
        );
        Self {
            model,
            point: point.clone(),
            value,
            jacobian,
        }
    }

    /// The value and the Jacobian have the shapes of step 0 (which the propagator checked);
    /// checked before the affine model does arithmetic with them.
    fn ensure_shapes(&self, n: usize) -> Result<()> {
        let m = self.value.nrows();
        let stage = Stage::Propagation;
        ensure_shape(&self.value, m, 1, stage, Quantity::FunctionValue)?;
        ensure_shape(&self.jacobian, m, n, stage, Quantity::Jacobian)
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>> MeasurementModel<T, N, M>
    for Linearization<'_, H, T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// h(xᵢ) + Hᵢ (x − xᵢ); at x = xᵢ, h(xᵢ) itself.
    fn measure(&self, x: &OVector<T, N>) -> OVector<T, M> {
        if *x == self.point {
            self.value.clone()
        } else {
            &self.value + &self.jacobian * (x - &self.point)
        }
    }

    fn measurement_noise(&self, x: &OVector<T, N>) -> OMatrix<T, M, M> {
        self.model.measurement_noise(x)
    }

    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.residual_into(a, b, out);
    }
}

impl<T: Real, N: Dim, M: Dim, H: MeasurementModel<T, N, M>> MeasurementJacobian<T, N, M>
    for Linearization<'_, H, T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, _: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.jacobian.clone()
    }
}
