//! Runtime sizes (`Dyn`) against static sizes, and large runtime-sized filters.
//!
//! (a) The same model, run once with static sizes (`U4`/`U2`) and once with `Dyn` sizes, gives
//!     the same estimates with every filter: the dynamic path may route its kernels elsewhere
//!     (faer), with another summation order, so the two agree to round-off, not bit for bit.
//!     Filters: KalmanFilter (random linear system from `common`), Ekf, SecondOrderEkf,
//!     GaussianSecondOrderEkf, Ukf (default α and cubature) on one smooth nonlinear model
//!     written once, generic over `N: Dim` and `M: Dim` (a target in a steering field, ranged
//!     by two beacons), and FadingMemoryRls (random linear regressors, γ = 0.95). A second
//!     property test perturbs the dynamic run by a few ulps per step, so the tolerances are
//!     exercised even while static and dynamic happen to round alike.
//! (b) Large dynamic filters (n = 100 and 200 states) against a hand-written nalgebra Kalman
//!     filter, to a tolerance set by the condition numbers met along the run.
//!
//! The whole file runs in well under a second at the test profile's opt-level 2.

use crate::common;

use std::cell::Cell;

use common::{
    DynSystem, ReferenceKf, StaticSystem, Trajectory, estimate_rel_diff, gaussian_matrix,
    random_dyn_system, random_spd, random_static_system, rng, sample, simulate,
};
use estim_core::derivative::{check_measurement_model, check_process_model};
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Dyn, Matrix4, OMatrix, OVector, U1, U2, U4, Vector2,
    Vector4, allocator::Allocator,
};
use estim_core::propagate::{Linearized, SecondOrder, SecondOrderGaussian, Unscented};
use estim_core::{
    Alloc, Gaussian, LinearMeasurement, MeasurementHessian, MeasurementJacobian, MeasurementModel,
    ProcessHessian, ProcessJacobian, ProcessModel,
};
use estim_filters::{
    Ekf, Estimator, FadingMemoryRls, GaussianFilter, KalmanFilter, Predict, Update,
};
use proptest::prelude::*;
use rand::Rng;

// ---------------------------------------------------------------------------------------------
// Round-off emulation.
// ---------------------------------------------------------------------------------------------

/// Relative perturbations of a few ulps, drawn from a seeded generator (SplitMix64), standing
/// in for the different rounding of another summation order. `amplitude` 0 leaves values
/// untouched (and then the dynamic run is the plain one).
#[derive(Debug)]
struct Jitter {
    state: Cell<u64>,
    /// Perturbations are uniform in ±amplitude · ε, relative.
    amplitude: f64,
}

impl Jitter {
    fn none() -> Self {
        Self {
            state: Cell::new(0),
            amplitude: 0.0,
        }
    }

    fn new(seed: u64, amplitude: f64) -> Self {
        Self {
            state: Cell::new(seed),
            amplitude,
        }
    }

    /// v · (1 + δ), δ uniform in ±amplitude · ε.
    fn apply(&self, v: f64) -> f64 {
        if self.amplitude == 0.0 {
            return v;
        }
        let mut z = self.state.get().wrapping_add(0x9e37_79b9_7f4a_7c15);
        self.state.set(z);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        let u = (z >> 11) as f64 / (1u64 << 53) as f64; // [0, 1)
        v * (1.0 + (2.0 * u - 1.0) * self.amplitude * f64::EPSILON)
    }

    fn vector<N: Dim>(&self, x: &OVector<f64, N>) -> OVector<f64, N>
    where
        DefaultAllocator: Allocator<N>,
    {
        x.map(|v| self.apply(v))
    }

    /// A symmetric perturbation of a covariance (the filters keep P exactly symmetric).
    fn symmetric<N: Dim>(&self, p: &OMatrix<f64, N, N>) -> OMatrix<f64, N, N>
    where
        DefaultAllocator: Allocator<N, N>,
    {
        let mut out = p.clone();
        for j in 0..p.ncols() {
            for i in j..p.nrows() {
                let v = self.apply(p[(i, j)]);
                out[(i, j)] = v;
                out[(j, i)] = v;
            }
        }
        out
    }

    /// Replaces a filter's estimate by a perturbed copy (emulating kernels that round
    /// differently); does nothing without jitter.
    fn estimate<F: Estimator<f64, N>, N: Dim>(&self, filter: &mut F)
    where
        DefaultAllocator: Alloc<N>,
    {
        if self.amplitude == 0.0 {
            return;
        }
        let x = self.vector(filter.state());
        let p = self.symmetric(filter.covariance());
        filter.reset(Gaussian::new(x, p).expect("a few-ulp perturbation keeps P SPD"));
    }
}

// ---------------------------------------------------------------------------------------------
// A smooth nonlinear model, generic over the dimensions.
// ---------------------------------------------------------------------------------------------

/// A planar target x = (px, py, vx, vy) in a steering field: each step the velocity turns by
/// θ(py) = Δt (ω₀ + a sin py) and the position integrates the old velocity,
///
/// ```text
/// f(x) = (px + Δt vx,  py + Δt vy,  cos θ vx − sin θ vy,  sin θ vx + cos θ vy),
/// ```
///
/// with white-acceleration noise of intensity q on each axis. The same code serves `U4` and
/// `Dyn` (the dimension must be 4). Inputs to every evaluation pass through `jitter`.
#[derive(Debug)]
struct SteeringField {
    omega0: f64,
    gain: f64,
    q: f64,
    jitter: Jitter,
}

impl SteeringField {
    /// θ(py), θ′(py), θ″(py).
    fn turn(&self, py: f64, dt: f64) -> (f64, f64, f64) {
        let (s, c) = py.sin_cos();
        (
            dt * (self.omega0 + self.gain * s),
            dt * self.gain * c,
            -dt * self.gain * s,
        )
    }

    fn input<N: Dim>(&self, x: &OVector<f64, N>) -> OVector<f64, N>
    where
        DefaultAllocator: Allocator<N>,
    {
        assert_eq!(x.nrows(), 4, "the steering-field target has 4 states");
        self.jitter.vector(x)
    }
}

impl<N: Dim> ProcessModel<f64, N> for SteeringField
where
    DefaultAllocator: Alloc<N>,
{
    type Input = ();

    fn transition(&self, x: &OVector<f64, N>, _: &(), dt: f64) -> OVector<f64, N> {
        let x = self.input(x);
        let (s, c) = self.turn(x[1], dt).0.sin_cos();
        let mut y = x.clone();
        y[0] = x[0] + dt * x[2];
        y[1] = x[1] + dt * x[3];
        y[2] = c * x[2] - s * x[3];
        y[3] = s * x[2] + c * x[3];
        y
    }

    fn process_noise(&self, x: &OVector<f64, N>, _: &(), dt: f64) -> OMatrix<f64, N, N> {
        let d = x.shape_generic().0;
        let mut q = OMatrix::<f64, N, N>::zeros_generic(d, d);
        let (a, b, c) = (dt.powi(3) / 3.0, dt.powi(2) / 2.0, dt);
        for axis in 0..2 {
            q[(axis, axis)] = a * self.q;
            q[(axis, axis + 2)] = b * self.q;
            q[(axis + 2, axis)] = b * self.q;
            q[(axis + 2, axis + 2)] = c * self.q;
        }
        q
    }
}

impl<N: Dim> ProcessJacobian<f64, N> for SteeringField
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_jacobian(&self, x: &OVector<f64, N>, _: &(), dt: f64) -> OMatrix<f64, N, N> {
        let x = self.input(x);
        let (theta, d_theta, _) = self.turn(x[1], dt);
        let (s, c) = theta.sin_cos();
        // y₂ = c vx − s vy, y₃ = s vx + c vy; ∂y₂/∂py = −y₃ θ′, ∂y₃/∂py = y₂ θ′.
        let (y2, y3) = (c * x[2] - s * x[3], s * x[2] + c * x[3]);
        let d = x.shape_generic().0;
        let mut f = OMatrix::<f64, N, N>::identity_generic(d, d);
        f[(0, 2)] = dt;
        f[(1, 3)] = dt;
        f[(2, 1)] = -y3 * d_theta;
        f[(2, 2)] = c;
        f[(2, 3)] = -s;
        f[(3, 1)] = y2 * d_theta;
        f[(3, 2)] = s;
        f[(3, 3)] = c;
        f
    }
}

impl SteeringField {
    /// ∂²fₖ/∂x² (the code behind both `ProcessHessian` impls below).
    fn hessian<N: Dim>(&self, x: &OVector<f64, N>, dt: f64, k: usize) -> Option<OMatrix<f64, N, N>>
    where
        DefaultAllocator: Alloc<N>,
    {
        if k < 2 {
            return None; // the positions are linear in x
        }
        let x = self.input(x);
        let (theta, d1, d2) = self.turn(x[1], dt);
        let (s, c) = theta.sin_cos();
        let (y2, y3) = (c * x[2] - s * x[3], s * x[2] + c * x[3]);
        let d = x.shape_generic().0;
        let mut h = OMatrix::<f64, N, N>::zeros_generic(d, d);
        // Only py (index 1) enters nonlinearly; vx, vy enter linearly, times functions of py.
        let (pp, pvx, pvy) = if k == 2 {
            // ∂/∂py of (−y₃ θ′) = −(y₂ θ′) θ′ − y₃ θ″; ∂²y₂/∂py∂vx = −s θ′, ∂py∂vy = −c θ′.
            (-y2 * d1 * d1 - y3 * d2, -s * d1, -c * d1)
        } else {
            // ∂/∂py of (y₂ θ′) = −y₃ θ′ θ′ + y₂ θ″; ∂²y₃/∂py∂vx = c θ′, ∂py∂vy = −s θ′.
            (-y3 * d1 * d1 + y2 * d2, c * d1, -s * d1)
        };
        h[(1, 1)] = pp;
        h[(1, 2)] = pvx;
        h[(2, 1)] = pvx;
        h[(1, 3)] = pvy;
        h[(3, 1)] = pvy;
        Some(h)
    }
}

// The Hessian traits have blanket impls for linear models, so coherence wants them per
// dimension; both delegate to the one generic `hessian`.
impl ProcessHessian<f64, U4> for SteeringField {
    fn transition_hessian(
        &self,
        x: &Vector4<f64>,
        _: &(),
        dt: f64,
        k: usize,
    ) -> Option<Matrix4<f64>> {
        self.hessian(x, dt, k)
    }
}

impl ProcessHessian<f64, Dyn> for SteeringField {
    fn transition_hessian(
        &self,
        x: &DVector<f64>,
        _: &(),
        dt: f64,
        k: usize,
    ) -> Option<DMatrix<f64>> {
        self.hessian(x, dt, k)
    }
}

/// Ranges from the target's position (px, py) to fixed beacons, one measurement per beacon
/// (so generic over M: `U2` or `Dyn` with two beacons), with noise σ² on the diagonal and
/// correlation `rho` between beacons.
#[derive(Debug)]
struct Ranges {
    beacons: Vec<[f64; 2]>,
    sigma: f64,
    rho: f64,
    jitter: Jitter,
}

impl Ranges {
    /// (px − bx, py − by, r) for beacon k.
    fn offset<N: Dim>(&self, x: &OVector<f64, N>, k: usize) -> (f64, f64, f64)
    where
        DefaultAllocator: Allocator<N>,
    {
        let [bx, by] = self.beacons[k];
        let (dx, dy) = (x[0] - bx, x[1] - by);
        (dx, dy, dx.hypot(dy))
    }

    fn input<N: Dim>(&self, x: &OVector<f64, N>) -> OVector<f64, N>
    where
        DefaultAllocator: Allocator<N>,
    {
        assert_eq!(x.nrows(), 4, "the steering-field target has 4 states");
        self.jitter.vector(x)
    }
}

impl<N: Dim, M: Dim> MeasurementModel<f64, N, M> for Ranges
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<f64, N>) -> OVector<f64, M> {
        let x = self.input(x);
        OVector::<f64, M>::from_fn_generic(M::from_usize(self.beacons.len()), U1, |k, _| {
            self.offset(&x, k).2
        })
    }

    fn measurement_noise(&self, _: &OVector<f64, N>) -> OMatrix<f64, M, M> {
        let m = M::from_usize(self.beacons.len());
        let s2 = self.sigma * self.sigma;
        OMatrix::<f64, M, M>::from_fn_generic(m, m, |i, j| if i == j { s2 } else { self.rho * s2 })
    }
}

impl<N: Dim, M: Dim> MeasurementJacobian<f64, N, M> for Ranges
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, x: &OVector<f64, N>) -> OMatrix<f64, M, N> {
        let x = self.input(x);
        let m = M::from_usize(self.beacons.len());
        let mut h = OMatrix::<f64, M, N>::zeros_generic(m, x.shape_generic().0);
        for k in 0..self.beacons.len() {
            let (dx, dy, r) = self.offset(&x, k);
            h[(k, 0)] = dx / r;
            h[(k, 1)] = dy / r;
        }
        h
    }
}

impl Ranges {
    /// ∂²rₖ/∂x² (the code behind both `MeasurementHessian` impls below).
    fn hessian<N: Dim>(&self, x: &OVector<f64, N>, k: usize) -> Option<OMatrix<f64, N, N>>
    where
        DefaultAllocator: Alloc<N>,
    {
        let x = self.input(x);
        let (dx, dy, r) = self.offset(&x, k);
        let (ux, uy) = (dx / r, dy / r);
        let d = x.shape_generic().0;
        let mut h = OMatrix::<f64, N, N>::zeros_generic(d, d);
        // ∇²r = (I − u uᵀ) / r on the position block.
        h[(0, 0)] = (1.0 - ux * ux) / r;
        h[(0, 1)] = -ux * uy / r;
        h[(1, 0)] = -ux * uy / r;
        h[(1, 1)] = (1.0 - uy * uy) / r;
        Some(h)
    }
}

impl MeasurementHessian<f64, U4, U2> for Ranges {
    fn measurement_hessian(&self, x: &Vector4<f64>, k: usize) -> Option<Matrix4<f64>> {
        self.hessian(x, k)
    }
}

impl MeasurementHessian<f64, Dyn, Dyn> for Ranges {
    fn measurement_hessian(&self, x: &DVector<f64>, k: usize) -> Option<DMatrix<f64>> {
        self.hessian(x, k)
    }
}

// ---------------------------------------------------------------------------------------------
// Static ↔ dynamic conversions and runs.
// ---------------------------------------------------------------------------------------------

fn dm<R: Dim, C: Dim>(a: &OMatrix<f64, R, C>) -> DMatrix<f64>
where
    DefaultAllocator: Allocator<R, C>,
{
    DMatrix::from_iterator(a.nrows(), a.ncols(), a.iter().copied())
}

fn dv<R: Dim>(a: &OVector<f64, R>) -> DVector<f64>
where
    DefaultAllocator: Allocator<R>,
{
    DVector::from_iterator(a.nrows(), a.iter().copied())
}

fn dyn_gaussian<N: Dim>(g: &Gaussian<f64, N>) -> Gaussian<f64, Dyn>
where
    DefaultAllocator: Alloc<N>,
{
    Gaussian::<f64, Dyn>::new(dv(g.mean()), dm(g.covariance())).expect("same SPD covariance")
}

fn dyn_system(s: &StaticSystem) -> DynSystem {
    DynSystem {
        process: estim_core::LinearProcess {
            transition: dm(&s.process.transition),
            input: dm(&s.process.input),
            noise: dm(&s.process.noise),
        },
        measurement: LinearMeasurement {
            observation: dm(&s.measurement.observation),
            noise: dm(&s.measurement.noise),
        },
        prior: dyn_gaussian(&s.prior),
    }
}

/// The estimate after each step.
type Run<N> = Vec<(OVector<f64, N>, OMatrix<f64, N, N>)>;

/// Predict with `inputs[k]`, update with `zs[k]`, for every k; `jitter` perturbs the estimate
/// after each predict and each update.
fn run<F, N, M, P, H>(
    mut filter: F,
    process: &P,
    inputs: &[P::Input],
    sensor: &H,
    zs: &[OVector<f64, M>],
    dt: f64,
    jitter: &Jitter,
) -> Run<N>
where
    N: Dim,
    M: Dim,
    P: ProcessModel<f64, N>,
    H: MeasurementModel<f64, N, M>,
    F: Predict<f64, N, P> + Update<f64, N, M, H>,
    DefaultAllocator: Alloc<N, M>,
{
    assert_eq!(inputs.len(), zs.len());
    let mut out = Vec::with_capacity(zs.len());
    for (u, z) in inputs.iter().zip(zs) {
        filter.predict(process, u, dt).expect("predict");
        jitter.estimate(&mut filter);
        let report = filter.update(sensor, z).expect("update");
        assert!(report.applied());
        jitter.estimate(&mut filter);
        out.push((filter.state().clone(), filter.covariance().clone()));
    }
    out
}

/// The worst relative differences (state, covariance) over a run, the static run being the
/// reference (see `common::estimate_rel_diff`).
fn worst_diff<N: Dim>(stat: &Run<N>, dynamic: &Run<Dyn>) -> (f64, f64)
where
    DefaultAllocator: Alloc<N>,
{
    assert_eq!(stat.len(), dynamic.len());
    stat.iter()
        .zip(dynamic)
        .fold((0.0_f64, 0.0_f64), |(wx, wp), ((xs, ps), (xd, pd))| {
            let (dx, dp) = estimate_rel_diff::<Dyn>(xd, pd, &dv(xs), &dm(ps));
            (wx.max(dx), wp.max(dp))
        })
}

// ---------------------------------------------------------------------------------------------
// (a) Static vs dynamic.
// ---------------------------------------------------------------------------------------------

/// Steps per run.
const STEPS: usize = 50;
/// Time step of the steering-field scenario.
const DT: f64 = 0.1;

// Tolerances, static vs dynamic, relative in the sense of `common::estimate_rel_diff` (state
// against max(max |x|, √max Pᵢᵢ), covariance against max |P| of the static run).
//
// Both runs do the same arithmetic up to the summation order of the kernels, so one step's
// outputs differ by the rounding of those kernels, and the differences of the 50 steps add up.
// We assume no forgetting (the filters are stable: the posterior covariance is a contraction
// of the prior one and the state error passes through the stable closed loop (I − K H) F, so
// the true accumulation is smaller).
//
// 1. Kernels (every filter). n = 4 states and m = 2 measurements, so every product has inner
//    dimension ≤ 4 and rounds to within γ₄ ≈ 4ε relative: seven of them per step (F P, · Fᵀ,
//    H P, · Hᵀ, and the three of the Joseph update) give 28 ε. The gain's solve with S is
//    backward stable (Cholesky: γ₃ₘ₊₁ = 7ε for m = 2) and κ(S) turns that into a forward
//    error of 7 κ(S) ε. Per step (28 + 7 κ(S)) ε, times 50 steps: `kernel_tol`. For the
//    steering field κ(S) ≤ `COND_S_MAX` = 5 gives 3150 ε = 7.0·10⁻¹³; the random linear
//    systems' S reach κ ≈ 200 (worst of 2000 seeds), where it is 1.7·10⁻¹¹.
// 2. Sigma points (the UKFs). χᵢ = μ + √c Lⱼ is computed by the same code in both runs, but
//    once μ or L differ in their last bits the rounding of χᵢ differs by up to an ulp,
//    independently for each point, and the transform amplifies that (`common` explains it for
//    the mean). With c = α² n, w = 1/(2c) and per-point errors eᵢ ≈ ε |g| (g′ = O(1) here),
//    summed with random signs over the 2n points:
//    - mean: w √(2n) ε |g| = ½ √(2/n) ε |g| / α² ≈ 0.354 ε |g| / α² (n = 4);
//    - covariance: w Σᵢ (dᵢ eᵢᵀ + eᵢ dᵢᵀ) with |dᵢ| ≈ √c σ gives √2 σ ε |g| / α, and the
//      cross-covariance w Σᵢ (χᵢ − μ) eᵢᵀ gives σₓ ε |g| / (√2 α).
//    Through one predict and one update, relative to the scales compared, that is
//    0.354 ε/α² · lever_x for the state and √2 ε/α · lever_p for the covariance, with the
//    levers of [`Premises`] (≤ `LEVER_X_MAX`, `LEVER_P_MAX`), times 50 steps:
//    `sigma_point_tol`. For the default α = 10⁻³: 283 ε/α² = 6.3·10⁻⁸ (state) and
//    4.2·10⁴ ε/α = 9.4·10⁻⁹ (covariance). For the cubature rule (α = 1, c = n) the same
//    mechanism without the 1/α amplification: 6.3·10⁻¹⁴ and 9.4·10⁻¹², on top of item 1.
//
// The premises are asserted on every scenario. Measured (`survey_static_dynamic_differences`,
// 2000 seeds): without perturbation static and dynamic agree bit for bit today (both run
// nalgebra's generic code); with the dynamic run perturbed by an ulp per model input and four
// per estimate entry (`tolerances_admit_ulp_level_rounding_differences`), the worst difference
// is 0.19 of its tolerance (default-α UKF covariance, 1.7·10⁻⁹), 0.043 for the default-α UKF
// state (2.7·10⁻⁹) and ≤ 0.05 for every other filter (≤ 5·10⁻¹⁴). Perturbing the estimates
// by 4000 ulps instead fails the EKF at 7·10⁻¹², so the tolerances do discriminate.

/// Rounding per step of the kernels, in ε (seven products with inner dimension ≤ 4).
const PRODUCT_ROUNDING: f64 = 28.0;
/// Backward error of the Cholesky solve with m = 2, in ε, to be multiplied by κ(S).
const SOLVE_ROUNDING: f64 = 7.0;

/// Item 1 above: (28 + 7 κ(S)) ε per step, over the 50 steps.
fn kernel_tol(cond_s: f64) -> f64 {
    STEPS as f64 * (PRODUCT_ROUNDING + SOLVE_ROUNDING * cond_s) * f64::EPSILON
}

/// Item 2 above, for spread α and n = 4: (state, covariance).
fn sigma_point_tol(alpha: f64) -> (f64, f64) {
    let steps = STEPS as f64;
    (
        steps * 0.5 * (2.0_f64 / 4.0).sqrt() * LEVER_X_MAX * f64::EPSILON / (alpha * alpha),
        steps * 2.0_f64.sqrt() * LEVER_P_MAX * f64::EPSILON / alpha,
    )
}

/// The steering field's κ(S) bound (worst of 2000 seeds: 3.6).
const COND_S_MAX: f64 = 5.0;
/// The steering field's `lever_x` bound (worst of 2000 seeds: 12.5).
const LEVER_X_MAX: f64 = 16.0;
/// The steering field's `lever_p` bound (worst of 2000 seeds: 445).
const LEVER_P_MAX: f64 = 600.0;

/// The emulated rounding difference of a sigma point (or any model input): one ulp, relative.
const INPUT_JITTER_ULPS: f64 = 1.0;
/// The emulated rounding difference of a kernel's output entry: a 4-term sum in another order
/// differs by up to ≈ 4 ε relative.
const KERNEL_JITTER_ULPS: f64 = 4.0;

/// The nonlinear scenario: model, sensor, prior and measurements, static sizes.
struct Scenario {
    field: SteeringField,
    ranges: Ranges,
    prior: Gaussian<f64, U4>,
    truth: Vec<Vector4<f64>>,
    zs: Vec<Vector2<f64>>,
}

/// A random steering field (ω₀ ∈ [−0.5, 0.5], a ∈ [0.2, 1]), beacons at (−10, 0) and
/// (0, −10), a prior around a position in [2, 4]² (away from the origin, so the state scale
/// stays O(1)), the truth drawn from the prior, 50 steps of Δt = 0.1.
fn scenario(seed: u64) -> Scenario {
    let mut r = rng(seed);
    let field = SteeringField {
        omega0: r.random_range(-0.5..0.5),
        gain: r.random_range(0.2..1.0),
        q: 0.05,
        jitter: Jitter::none(),
    };
    let ranges = Ranges {
        beacons: vec![[-10.0, 0.0], [0.0, -10.0]],
        sigma: 0.2,
        rho: 0.2,
        jitter: Jitter::none(),
    };
    let mean = Vector4::from_fn(|i, _| {
        if i < 2 {
            r.random_range(2.0..4.0)
        } else {
            r.random_range(-0.8..0.8)
        }
    });
    let cov = Matrix4::from_diagonal(&Vector4::new(0.25, 0.25, 0.04, 0.04))
        + random_spd(&mut r, U4, 0.02, 0.0);
    let prior = Gaussian::new(mean, cov).expect("SPD prior");
    let mut x = sample(&mut r, prior.mean(), prior.covariance());
    let q = ProcessModel::<f64, U4>::process_noise(&field, &x, &(), DT);
    let rr = MeasurementModel::<f64, U4, U2>::measurement_noise(&ranges, &x);
    let (mut truth, mut zs) = (Vec::new(), Vec::new());
    for _ in 0..STEPS {
        x = ProcessModel::<f64, U4>::transition(&field, &x, &(), DT)
            + sample(&mut r, &Vector4::zeros(), &q);
        let z: Vector2<f64> = MeasurementModel::<f64, U4, U2>::measure(&ranges, &x)
            + sample(&mut r, &Vector2::zeros(), &rr);
        truth.push(x);
        zs.push(z);
    }
    Scenario {
        field,
        ranges,
        prior,
        truth,
        zs,
    }
}

/// The quantities the tolerances' derivations rest on, measured along a static EKF run of the
/// scenario (the other filters' estimates stay close to it on this mildly nonlinear model, so
/// the same bounds serve them).
#[derive(Clone, Copy, Debug)]
struct Premises {
    /// max κ(S) over the updates, S = H P⁻ Hᵀ + R.
    cond_s: f64,
    /// max over steps of (|x̂⁻|∞ + ‖K‖∞ |ẑ|∞) / scale: how much larger than the state scale
    /// (`estimate_rel_diff`'s, after the update) the values are whose rounding the sigma-point
    /// mean amplifies (the predicted state, and the predicted measurement through the gain).
    lever_x: f64,
    /// max over steps of |x̂⁻|∞ / σ⁻ + |ẑ|∞ (‖K‖∞ σ⁻ + ‖K‖∞² σ_z) / σ⁺², with σ = √max Pᵢᵢ
    /// (⁻ predicted, ⁺ updated) and σ_z = √max (H P⁻ Hᵀ)ᵢᵢ: the same for the covariance (the
    /// predicted covariance's error relative to its scale, and the update's errors in Pₓᵤ and
    /// S carried into P⁺ = P⁻ − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ, relative to P⁺'s scale).
    lever_p: f64,
}

impl Premises {
    fn worst(self, o: Self) -> Self {
        Self {
            cond_s: self.cond_s.max(o.cond_s),
            lever_x: self.lever_x.max(o.lever_x),
            lever_p: self.lever_p.max(o.lever_p),
        }
    }

    /// Asserts the bounds the tolerances assume.
    fn assert_within_bounds(&self) {
        assert!(
            self.cond_s <= COND_S_MAX && self.lever_x <= LEVER_X_MAX && self.lever_p <= LEVER_P_MAX,
            "a tolerance's premise fails: {self:?}"
        );
    }
}

/// The largest row sum of |K|.
fn inf_norm<R: Dim, C: Dim>(k: &OMatrix<f64, R, C>) -> f64
where
    DefaultAllocator: Allocator<R, C>,
{
    k.row_iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

fn premises(s: &Scenario) -> Premises {
    let mut f = Ekf::new(s.prior.clone());
    let mut out = Premises {
        cond_s: 0.0,
        lever_x: 0.0,
        lever_p: 0.0,
    };
    for z in &s.zs {
        f.predict(&s.field, &(), DT).unwrap();
        let (x, p) = (*f.state(), *f.covariance());
        let sigma_pred = p.diagonal().max().sqrt();
        let h = MeasurementJacobian::<f64, U4, U2>::measurement_jacobian(&s.ranges, &x);
        let r = MeasurementModel::<f64, U4, U2>::measurement_noise(&s.ranges, &x);
        let hph = h * p * h.transpose();
        let sm = hph + r;
        out.cond_s = out.cond_s.max(cond_spd(&sm));
        let zhat: Vector2<f64> = MeasurementModel::<f64, U4, U2>::measure(&s.ranges, &x);
        let k = inf_norm(&(p * h.transpose() * sm.try_inverse().unwrap()));
        let sigma_z = hph.diagonal().max().sqrt();
        f.update(&s.ranges, z).unwrap();
        let (xu, pu) = (*f.state(), *f.covariance());
        let scale = xu.amax().max(pu.diagonal().max().sqrt());
        out.lever_x = out.lever_x.max((x.amax() + k * zhat.amax()) / scale);
        out.lever_p = out.lever_p.max(
            x.amax() / sigma_pred
                + zhat.amax() * (k * sigma_pred + k * k * sigma_z) / pu.diagonal().max(),
        );
    }
    out
}

/// κ₂ of a symmetric positive definite matrix (symmetric eigenvalues).
fn cond_spd<N: Dim>(s: &OMatrix<f64, N, N>) -> f64
where
    DefaultAllocator: Alloc<N>,
{
    let e = dm(s).symmetric_eigenvalues();
    e.max() / e.min()
}

/// One comparison's outcome.
#[derive(Debug)]
struct Agreement {
    what: String,
    dx: f64,
    dp: f64,
    tol_x: f64,
    tol_p: f64,
}

impl Agreement {
    fn holds(&self) -> bool {
        self.dx <= self.tol_x && self.dp <= self.tol_p
    }
}

/// Static and dynamic runs of `GaussianFilter<_, _, Pr>` on the scenario.
fn compare_propagator<Pr: Clone + estim_core::PropagatorWorkspace<f64>>(
    s: &Scenario,
    propagator: Pr,
    jitter_seed: Option<u64>,
    what: &str,
    (tol_x, tol_p): (f64, f64),
) -> Agreement
where
    GaussianFilter<f64, U4, Pr>: Predict<f64, U4, SteeringField> + Update<f64, U4, U2, Ranges>,
    GaussianFilter<f64, Dyn, Pr>: Predict<f64, Dyn, SteeringField> + Update<f64, Dyn, Dyn, Ranges>,
{
    let inputs = vec![(); STEPS];
    let stat = run(
        GaussianFilter::with_propagator(s.prior.clone(), propagator.clone()),
        &s.field,
        &inputs,
        &s.ranges,
        &s.zs,
        DT,
        &Jitter::none(),
    );
    let (field, ranges, jitter) = jittered(s, jitter_seed);
    let zs: Vec<DVector<f64>> = s.zs.iter().map(dv).collect();
    let dynamic = run(
        GaussianFilter::with_propagator(dyn_gaussian(&s.prior), propagator),
        &field,
        &inputs,
        &ranges,
        &zs,
        DT,
        &jitter,
    );
    let (dx, dp) = worst_diff(&stat, &dynamic);
    Agreement {
        what: what.into(),
        dx,
        dp,
        tol_x,
        tol_p,
    }
}

/// The scenario's models for the dynamic run, and the estimate jitter, perturbing if `seed`
/// is given.
fn jittered(s: &Scenario, seed: Option<u64>) -> (SteeringField, Ranges, Jitter) {
    let j = |k: u64, ulps: f64| match seed {
        Some(seed) => Jitter::new(seed.wrapping_mul(3).wrapping_add(k), ulps),
        None => Jitter::none(),
    };
    (
        SteeringField {
            omega0: s.field.omega0,
            gain: s.field.gain,
            q: s.field.q,
            jitter: j(1, INPUT_JITTER_ULPS),
        },
        Ranges {
            beacons: s.ranges.beacons.clone(),
            sigma: s.ranges.sigma,
            rho: s.ranges.rho,
            jitter: j(2, INPUT_JITTER_ULPS),
        },
        j(3, KERNEL_JITTER_ULPS),
    )
}

/// Every filter of the Kalman family on the steering-field scenario.
fn nonlinear_agreements(seed: u64, jitter_seed: Option<u64>) -> Vec<Agreement> {
    let s = scenario(seed);
    premises(&s).assert_within_bounds();
    let exact = kernel_tol(COND_S_MAX);
    let with_sigma_points = |alpha: f64| {
        let (x, p) = sigma_point_tol(alpha);
        (exact + x, exact + p)
    };
    let j = jitter_seed;
    vec![
        compare_propagator(&s, Linearized, j, "Ekf", (exact, exact)),
        compare_propagator(&s, SecondOrder, j, "SecondOrderEkf", (exact, exact)),
        compare_propagator(
            &s,
            SecondOrderGaussian,
            j,
            "GaussianSecondOrderEkf",
            (exact, exact),
        ),
        compare_propagator(
            &s,
            Unscented::<f64>::default(),
            j,
            "Ukf (alpha = 1e-3)",
            with_sigma_points(1e-3),
        ),
        compare_propagator(
            &s,
            Unscented::<f64>::cubature(),
            j,
            "Ukf (cubature)",
            with_sigma_points(1.0),
        ),
    ]
}

/// KalmanFilter on a random linear system (`common::random_static_system`) and
/// FadingMemoryRls (γ = 0.95) on random regressors; the tolerance of each is `kernel_tol` at
/// the largest κ(S) of its run.
fn linear_agreements(seed: u64, jitter_seed: Option<u64>) -> Vec<Agreement> {
    let mut r = rng(seed);
    let jitter = || match jitter_seed {
        Some(j) => Jitter::new(j, KERNEL_JITTER_ULPS),
        None => Jitter::none(),
    };

    // Kalman filter.
    let system = random_static_system(&mut r);
    let traj = simulate(&mut r, &system, STEPS);
    let stat = run(
        KalmanFilter::new(system.prior.clone()),
        &system.process,
        &traj.inputs,
        &system.measurement,
        &traj.measurements,
        1.0,
        &Jitter::none(),
    );
    let dsys = dyn_system(&system);
    let dtraj = dyn_trajectory(&traj);
    let dynamic = run(
        KalmanFilter::new(dsys.prior.clone()),
        &dsys.process,
        &dtraj.inputs,
        &dsys.measurement,
        &dtraj.measurements,
        1.0,
        &jitter(),
    );
    let (dx, dp) = worst_diff(&stat, &dynamic);
    // κ(S) of each update, S = H (F P Fᵀ + Q) Hᵀ + R from the static run's previous posterior.
    let (f, h) = (&system.process.transition, &system.measurement.observation);
    let cond_s = std::iter::once(system.prior.covariance())
        .chain(stat.iter().map(|(_, p)| p))
        .take(STEPS)
        .map(|p| {
            let predicted = f * p * f.transpose() + system.process.noise;
            cond_spd(&(h * predicted * h.transpose() + system.measurement.noise))
        })
        .fold(0.0, f64::max);
    let kf = Agreement {
        what: "KalmanFilter".into(),
        dx,
        dp,
        tol_x: kernel_tol(cond_s),
        tol_p: kernel_tol(cond_s),
    };

    // Fading-memory RLS: z = Bₖ θ + vₖ with random 2×4 regressors Bₖ.
    let gamma = 0.95;
    let theta = gaussian_matrix(&mut r, U4, U1);
    let prior = Gaussian::new(
        gaussian_matrix(&mut r, U4, U1),
        random_spd(&mut r, U4, 1.0, 0.1),
    )
    .unwrap();
    let mut rls_s = FadingMemoryRls::new(prior.clone(), gamma).unwrap();
    let mut rls_d = FadingMemoryRls::new(dyn_gaussian(&prior), gamma).unwrap();
    let j = jitter();
    let (mut wx, mut wp, mut cond_s) = (0.0_f64, 0.0_f64, 0.0_f64);
    for _ in 0..STEPS {
        let b = gaussian_matrix(&mut r, U2, U4);
        let noise = random_spd(&mut r, U2, 0.5, 0.1);
        let z = b * theta + sample(&mut r, &Vector2::zeros(), &noise);
        cond_s = cond_s.max(cond_spd(
            &(b * rls_s.covariance() * b.transpose() / gamma + noise),
        ));
        let dmodel = LinearMeasurement {
            observation: dm(&b),
            noise: dm(&noise),
        };
        let model = LinearMeasurement {
            observation: b,
            noise,
        };
        assert!(rls_s.update(&model, &z).unwrap().applied());
        assert!(rls_d.update(&dmodel, &dv(&z)).unwrap().applied());
        j.estimate(&mut rls_d);
        let (dx, dp) = estimate_rel_diff::<Dyn>(
            rls_d.state(),
            rls_d.covariance(),
            &dv(rls_s.state()),
            &dm(rls_s.covariance()),
        );
        wx = wx.max(dx);
        wp = wp.max(dp);
    }
    let rls = Agreement {
        what: "FadingMemoryRls (gamma = 0.95)".into(),
        dx: wx,
        dp: wp,
        tol_x: kernel_tol(cond_s),
        tol_p: kernel_tol(cond_s),
    };
    vec![kf, rls]
}

fn dyn_trajectory<N: Dim, M: Dim, U: Dim>(t: &Trajectory<N, M, U>) -> Trajectory<Dyn, Dyn, Dyn>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    Trajectory {
        inputs: t.inputs.iter().map(dv).collect(),
        truth: t.truth.iter().map(dv).collect(),
        measurements: t.measurements.iter().map(dv).collect(),
    }
}

#[track_caller]
fn assert_agree(all: &[Agreement], context: &str) {
    for a in all {
        assert!(
            a.holds(),
            "{context}: {}: static vs dynamic relative state diff {:e} (tol {:e}), covariance \
             diff {:e} (tol {:e})",
            a.what,
            a.dx,
            a.tol_x,
            a.dp,
            a.tol_p
        );
    }
}

proptest! {
    // 32 cases × 7 filters × 50 steps × 2 sizes: well under a second at opt-level 2.
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Same model, static sizes and `Dyn` sizes: every filter agrees to round-off.
    #[test]
    fn static_and_dynamic_sizes_agree(seed in any::<u64>()) {
        assert_agree(&nonlinear_agreements(seed, None), "steering field");
        assert_agree(&linear_agreements(seed, None), "linear");
    }

    /// The tolerances hold for rounding that differs, not only where static and dynamic
    /// happen to round alike: a dynamic run whose every model input is perturbed by an ulp and
    /// every estimate entry by four (as sigma points and kernels with another summation order
    /// would be) still agrees.
    #[test]
    fn tolerances_admit_ulp_level_rounding_differences(seed in any::<u64>()) {
        let j = Some(seed ^ 0x5eed);
        assert_agree(&nonlinear_agreements(seed, j), "steering field, jittered");
        assert_agree(&linear_agreements(seed, j), "linear, jittered");
    }
}

/// Measures the premises and the worst differences over 2000 seeds, against the tolerances
/// (for the comments above):
/// `cargo test -p estim-filters --test it -- --ignored --nocapture dynamic::survey`.
#[test]
#[ignore]
fn survey_static_dynamic_differences() {
    let w = (0..2000u64)
        .map(|seed| premises(&scenario(seed)))
        .reduce(Premises::worst)
        .unwrap();
    eprintln!("steering-field premises, worst of 2000 seeds: {w:?}");
    for jitter in [false, true] {
        // (filter, worst state diff, its ratio to the tolerance, same for the covariance)
        let mut worst: Vec<(String, f64, f64, f64, f64)> = Vec::new();
        for seed in 0..2000u64 {
            let js = jitter.then_some(seed ^ 0x5eed);
            let all = nonlinear_agreements(seed, js)
                .into_iter()
                .chain(linear_agreements(seed, js));
            for a in all {
                let (rx, rp) = (a.dx / a.tol_x, a.dp / a.tol_p);
                match worst.iter_mut().find(|w| w.0 == a.what) {
                    Some(w) => {
                        w.1 = w.1.max(a.dx);
                        w.2 = w.2.max(rx);
                        w.3 = w.3.max(a.dp);
                        w.4 = w.4.max(rp);
                    }
                    None => worst.push((a.what.clone(), a.dx, rx, a.dp, rp)),
                }
            }
        }
        eprintln!("jitter = {jitter}: worst difference (worst difference / tolerance)");
        for w in &worst {
            eprintln!(
                "  {:<32} state {:.2e} ({:.3})  covariance {:.2e} ({:.3})",
                w.0, w.1, w.2, w.3, w.4
            );
        }
    }
}

/// The steering-field model's analytic Jacobians and Hessians match finite differences, with
/// static and dynamic sizes.
#[test]
fn steering_field_derivatives_are_right() {
    let s = scenario(3);
    // With the default step h = ε^⅓ the central-difference error is ≈ h² |f‴| ≈ 10⁻¹⁰ for
    // these O(1) derivatives; 10⁻⁶ is the checker's documented threshold for correct f64
    // derivatives and still far below a real mistake (a wrong term is O(Δt a) ≥ 10⁻²).
    let tol = 1e-6;
    for x in s.truth.iter().step_by(10) {
        let p = check_process_model(&s.field, x, &(), DT).unwrap();
        assert!(p.is_accurate(tol), "process, static: {p}");
        let m = check_measurement_model::<f64, U4, U2, _>(&s.ranges, x).unwrap();
        assert!(m.is_accurate(tol), "ranges, static: {m}");
        let xd = dv(x);
        let p = check_process_model(&s.field, &xd, &(), DT).unwrap();
        assert!(p.is_accurate(tol), "process, dynamic: {p}");
        let m = check_measurement_model::<f64, Dyn, Dyn, _>(&s.ranges, &xd).unwrap();
        assert!(m.is_accurate(tol), "ranges, dynamic: {m}");
    }
}

// ---------------------------------------------------------------------------------------------
// (b) Large dynamic filters against a hand-written Kalman filter.
// ---------------------------------------------------------------------------------------------

/// The large-filter tolerance for the Kalman filter and the EKF (which does the same
/// arithmetic on a linear model): relative error ≤ C · n · ε · κ̄(S), κ̄(S) the largest κ₂(S)
/// of the updates so far (S = H P⁻ Hᵀ + R of the reference, from its symmetric eigenvalues).
///
/// One step of either implementation is backward stable: each of the ~7 products (F P, · Fᵀ,
/// H P, · Hᵀ, the Joseph products) rounds to within γₙ ≈ nε of |A||B|, which for these
/// well-scaled random matrices is of the size of the result, and the gain's solve with S
/// (the library's Cholesky, backward error γ₃ₘ₊₁ ≈ 1.5 nε for m = n/2; the reference's
/// explicit LU inverse, of the same order) becomes a forward error ≈ 1.5 nε κ(S) in each.
/// Together ≤ (7 + 2 · 1.5) nε κ(S) = 10 nε κ(S), so C = 10. Earlier steps' errors do not
/// add to this: the Joseph covariance map is non-expansive (Riccati) and the state error
/// passes through Φ = (I − K H) F, non-expansive in the P⁻¹ norm (Φᵀ P⁺⁻¹ Φ ⪯ P⁻¹); and
/// the worst-case γₙ = nε already exceeds typical rounding (√n ε) by √n ≥ 10.
///
/// For n = 100 and κ(S) ≈ 100–160 (the seeds below) that is ≈ 3·10⁻¹¹; the measured
/// differences are ≈ 10⁻¹⁵ (ratio ≈ 10⁻⁴ of the bound, `survey_large_filters`): a bound, not
/// an estimate. A real defect (a wrong transpose, a dropped term) is ≥ 10⁻³.
const LARGE_C: f64 = 10.0;

/// The same for the cubature UKF. It forms the covariances from the 2n deviations
/// dᵢ = F χᵢ − F μ (and H χᵢ − H μ), each a difference of two n-term sums of size
/// |F| (|μ| + √n σ) for a deviation of size √n |F| σ, so each carries ≈ nε (1 + |μ|/(√n σ))
/// relative rounding instead of a product's nε; with the state within a few σ·√n of 0
/// (|μ| ≲ √n σ, true here) that doubles the product share: C = 20.
const LARGE_C_UKF: f64 = 20.0;

/// One large-filter comparison step: the filter's relative differences from the reference and
/// the largest κ(S) met so far.
#[derive(Clone, Copy, Debug)]
struct LargeStep {
    dx: f64,
    dp: f64,
    cond_s: f64,
}

/// A random stable system (`common::random_dyn_system`: F with spectral radius in
/// [0.5, 0.97], Gaussian H, Q ⪰ 0.01 I, R ⪰ 0.05 I) with n states, n/2 measurements and one
/// input, simulated for `steps` steps.
fn large_case(seed: u64, n: usize, steps: usize) -> (DynSystem, Trajectory<Dyn, Dyn, Dyn>) {
    let mut r = rng(seed);
    let system = random_dyn_system(&mut r, n, n / 2, 1);
    let traj = simulate(&mut r, &system, steps);
    (system, traj)
}

/// The reference over the run, with the largest κ(S) so far at each step.
///
/// `common::ReferenceKf` is the textbook Kalman filter written directly on nalgebra matrices
/// (for `Dyn`, `DMatrix`): P⁻ = F P Fᵀ + Q, S = H P⁻ Hᵀ + R, K = P⁻ Hᵀ S⁻¹ with an explicit
/// (LU) inverse, Joseph covariance. It shares no code with the library's update.
fn reference_run(system: &DynSystem, traj: &Trajectory<Dyn, Dyn, Dyn>) -> (Run<Dyn>, Vec<f64>) {
    let mut kf = ReferenceKf::new(&system.prior);
    let h = &system.measurement.observation;
    let (mut run, mut conds, mut cond_s) = (Vec::new(), Vec::new(), 0.0_f64);
    for (u, z) in traj.inputs.iter().zip(&traj.measurements) {
        kf.predict(&system.process, u);
        cond_s = cond_s.max(cond_spd(
            &(h * &kf.p * h.transpose() + &system.measurement.noise),
        ));
        kf.update(&system.measurement, z);
        run.push((kf.x.clone(), kf.p.clone()));
        conds.push(cond_s);
    }
    (run, conds)
}

/// A filter's run compared step by step with the reference.
fn compare_large<F>(
    filter: F,
    system: &DynSystem,
    traj: &Trajectory<Dyn, Dyn, Dyn>,
    reference: &(Run<Dyn>, Vec<f64>),
) -> Vec<LargeStep>
where
    F: Predict<f64, Dyn, estim_core::LinearProcess<f64, Dyn, Dyn>>
        + Update<f64, Dyn, Dyn, LinearMeasurement<f64, Dyn, Dyn>>,
{
    let got = run(
        filter,
        &system.process,
        &traj.inputs,
        &system.measurement,
        &traj.measurements,
        1.0,
        &Jitter::none(),
    );
    got.iter()
        .zip(reference.0.iter().zip(&reference.1))
        .map(|((x, p), ((xr, pr), &cond_s))| {
            let (dx, dp) = estimate_rel_diff::<Dyn>(x, p, xr, pr);
            LargeStep { dx, dp, cond_s }
        })
        .collect()
}

/// Asserts every step within C · n · ε · κ̄(S).
#[track_caller]
fn assert_large(steps: &[LargeStep], n: usize, c: f64, what: &str) {
    for (k, s) in steps.iter().enumerate() {
        let tol = c * n as f64 * f64::EPSILON * s.cond_s;
        assert!(
            s.dx <= tol && s.dp <= tol,
            "{what}, n = {n}, step {k}: relative state diff {:e}, covariance diff {:e} > \
             {c} n ε κ(S) = {tol:e} (κ(S) = {:e})",
            s.dx,
            s.dp,
            s.cond_s
        );
    }
}

/// Steps of the n = 100 runs; the n = 200 run takes half (its steps cost ~8× more).
const LARGE_STEPS: usize = 20;

#[test]
fn kalman_filter_with_100_states_matches_the_reference() {
    let (system, traj) = large_case(100, 100, LARGE_STEPS);
    let reference = reference_run(&system, &traj);
    let kf = compare_large(
        KalmanFilter::new(system.prior.clone()),
        &system,
        &traj,
        &reference,
    );
    assert_large(&kf, 100, LARGE_C, "KalmanFilter");
}

#[test]
fn kalman_filter_with_200_states_matches_the_reference() {
    let (system, traj) = large_case(200, 200, LARGE_STEPS / 2);
    let reference = reference_run(&system, &traj);
    let kf = compare_large(
        KalmanFilter::new(system.prior.clone()),
        &system,
        &traj,
        &reference,
    );
    assert_large(&kf, 200, LARGE_C, "KalmanFilter");
}

/// On the same system as the 100-state Kalman filter test. Both are exact for linear models:
/// the EKF's Jacobians are F and H, the cubature rule integrates the linear maps' first two
/// moments exactly.
#[test]
fn ekf_and_cubature_ukf_with_100_states_match_the_reference() {
    let (system, traj) = large_case(100, 100, LARGE_STEPS);
    let reference = reference_run(&system, &traj);
    let ekf = compare_large(Ekf::new(system.prior.clone()), &system, &traj, &reference);
    assert_large(&ekf, 100, LARGE_C, "Ekf");
    let ukf = compare_large(
        GaussianFilter::with_propagator(system.prior.clone(), Unscented::<f64>::cubature()),
        &system,
        &traj,
        &reference,
    );
    assert_large(&ukf, 100, LARGE_C_UKF, "cubature Ukf");
}

/// The large runs' worst differences against their bounds, over a few seeds:
/// `cargo test -p estim-filters --test it -- --ignored --nocapture dynamic::survey_large`.
#[test]
#[ignore]
fn survey_large_filters() {
    for (n, steps) in [(100, LARGE_STEPS), (200, LARGE_STEPS / 2)] {
        for seed in 0..5u64 {
            let (system, traj) = large_case(seed, n, steps);
            let reference = reference_run(&system, &traj);
            let prior = || system.prior.clone();
            let ukf = GaussianFilter::with_propagator(prior(), Unscented::<f64>::cubature());
            for (what, c, steps) in [
                (
                    "KalmanFilter",
                    LARGE_C,
                    compare_large(KalmanFilter::new(prior()), &system, &traj, &reference),
                ),
                (
                    "Ekf",
                    LARGE_C,
                    compare_large(Ekf::new(prior()), &system, &traj, &reference),
                ),
                (
                    "cubature Ukf",
                    LARGE_C_UKF,
                    compare_large(ukf, &system, &traj, &reference),
                ),
            ] {
                let worst = |f: fn(&LargeStep) -> f64| steps.iter().map(f).fold(0.0, f64::max);
                let ratio = steps
                    .iter()
                    .map(|s| s.dx.max(s.dp) / (c * n as f64 * f64::EPSILON * s.cond_s))
                    .fold(0.0, f64::max);
                eprintln!(
                    "n {n} seed {seed} {what:<13} κ(S) ≤ {:.3e}: state {:.2e}, covariance {:.2e}, \
                     worst / bound {ratio:.2e}",
                    worst(|s| s.cond_s),
                    worst(|s| s.dx),
                    worst(|s| s.dp)
                );
            }
        }
    }
}
