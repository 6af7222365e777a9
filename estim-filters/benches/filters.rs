//! Benchmarks of one predict + update step of the estim-filters filters with static sizes,
//! against hand-written fixed-size nalgebra steps (no estim code) as baselines.
//!
//! Two problems:
//!
//! - **3 states / 2 measurements, linear**: position, velocity and acceleration driven by a
//!   jerk input, observed in position and velocity ([`LinearProcess`], [`LinearMeasurement`]).
//!   Filters: [`KalmanFilter`], [`Ekf`], [`Ukf`]. Baselines: a hand-written KF and a
//!   hand-written textbook UKF.
//! - **6 states / 4 measurements, nonlinear**: a planar constant-turn-rate,
//!   constant-acceleration vehicle x = (p_x, p_y, v, ψ, ω, a) (Euler-discretised), seen in range
//!   and bearing from two beacons. Analytic Jacobians and Hessians, checked against finite
//!   differences before anything is timed. Filters: [`Ekf`], [`SecondOrderEkf`], [`Ukf`].
//!   Baselines: a hand-written EKF and a hand-written textbook UKF.
//!
//! **What the baselines compute.** The same outputs as the framework's step, with the same
//! formulas, and nothing else:
//!
//! ```text
//! predict:  x⁻ = f(x) (F x + B u),  P⁻ = (F P) Fᵀ + Q,  symmetrised once
//! update:   ẑ = h(x⁻), Pₓᵤ = P⁻ Hᵀ, S = H Pₓᵤ + R, ν = z ⊖ ẑ, S = L Lᵀ (nalgebra Cholesky),
//!           K = Pₓᵤ S⁻¹ (solved), x⁺ = x⁻ + K ν,
//!           P⁺ = P⁻ − K Pₓᵤᵀ − Pₓᵤ Kᵀ + (K S) Kᵀ  (Joseph, as the framework), symmetrised once
//! report:   NIS = νᵀ S⁻¹ ν (solved),  ln p(z) = −½ (NIS + 2 Σ ln Lᵢᵢ + m ln 2π)
//! ```
//!
//! The UKF baselines are the textbook scaled unscented transform (Wan & van der Merwe 2000)
//! with the framework's default α = 10⁻³, β = 2, κ = 0: a Cholesky factor of the covariance
//! (the same column-by-column loop as the framework's sigma-point factor; S still goes through
//! nalgebra's `Cholesky`, as in the framework),
//! 2n + 1 sigma points, all 2n + 1 values stored, ȳ = Σ Wᵐᵢ yᵢ, cov = Σ Wᶜᵢ (yᵢ ⊖ ȳ)(yᵢ ⊖ ȳ)ᵀ,
//! Pₓᵧ = Σ Wᶜᵢ (χᵢ − x)(yᵢ ⊖ ȳ)ᵀ (update only; the zero centre term skipped), fresh sigma
//! points from (x⁻, P⁻) for the update, then the same Kalman update as above.
//!
//! The baselines do no finiteness checks, no `Result`s, and no symmetrisation beyond one per
//! step half. Each `hand_*_no_report` variant also skips the report (NIS and log-likelihood),
//! to show what the report costs.
//!
//! **What one iteration is.** Each filter keeps its state across iterations and takes one
//! predict and one update per iteration, with the input and measurement of step i of a
//! 64-step recorded trajectory; after step 64 it is reset to the prior and the trajectory starts
//! again. So the numbers are per step of a filter tracking a real trajectory (covariances that
//! evolve, measurements that are consistent with the model), no clone is timed, and the reset
//! (one copy of x and P) is amortised over 64 steps. The estimate passes through `black_box`
//! after every step and the update report is returned to criterion, so nothing can be optimised
//! away. Every timed variant, framework and baseline, runs the same loop.
//!
//! Before timing, every baseline is run in lockstep with its framework counterpart over the
//! trajectory and their estimates and reports are checked to agree.
//!
//! The `breakdown_*` groups time each half-step alone (predict only, update only, same loop)
//! and some pieces of the framework's step (its finiteness checks, its covariance factor), to
//! show where the framework's extra time goes. For profilers, set
//! `FILTERS_BENCH_STEPS=<group>/<name>=<count>` to run one variant for `count` steps outside
//! criterion (see [`common`]).
//!
//! Run with `cargo bench -p estim-filters-benches --bench filters`.

mod common;

use std::f64::consts::PI;
use std::hint::black_box;
use std::time::Duration;

use common::Steps;
use criterion::{Criterion, criterion_group, criterion_main};
use estim_core::derivative::{check_measurement_model, check_process_model};
use estim_core::nalgebra::{U1, U2, U3, U4, U6};
use estim_core::{
    Gaussian, LinearMeasurement, LinearProcess, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel,
};
use estim_filters::{
    Ekf, Estimator, KalmanFilter, Predict, SecondOrderEkf, Ukf, Update, UpdateReport,
};
use nalgebra::{SMatrix, SVector};

/// Steps in the recorded trajectory; the filters are reset after each pass.
const STEPS: usize = 64;

/// Time step of both problems (s).
const DT: f64 = 0.1;

// ---------------------------------------------------------------------------------------------
// Hand-written building blocks (plain nalgebra, no estim code)
// ---------------------------------------------------------------------------------------------

/// P ← (P + Pᵀ)/2 over the strict lower triangle (the same loop the framework uses).
#[inline]
fn symmetrize<const N: usize>(p: &mut SMatrix<f64, N, N>) {
    for j in 0..N {
        for i in (j + 1)..N {
            let v = (p[(i, j)] + p[(j, i)]) * 0.5;
            p[(i, j)] = v;
            p[(j, i)] = v;
        }
    }
}

/// What a hand-written update reports (the framework's `UpdateReport` without the outcome).
#[derive(Clone, Copy, Debug)]
struct HandReport<const M: usize> {
    innovation: SVector<f64, M>,
    innovation_covariance: SMatrix<f64, M, M>,
    nis: f64,
    log_likelihood: f64,
}

/// The Kalman update from ν, S (noise included) and Pₓᵤ: Cholesky of S, solved gain, Joseph
/// form P − K Pₓᵤᵀ − Pₓᵤ Kᵀ + (K S) Kᵀ, symmetrised; with `REPORT`, also NIS and ln p(z).
#[inline]
fn hand_kalman_update<const N: usize, const M: usize, const REPORT: bool>(
    x: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    innovation: SVector<f64, M>,
    s: SMatrix<f64, M, M>,
    cross: SMatrix<f64, N, M>,
) -> Option<HandReport<M>> {
    let chol = s.cholesky().expect("S positive definite");
    let gain = chol.solve(&cross.transpose()).transpose();
    *x += gain * innovation;
    let k_cross_t = gain * cross.transpose();
    let mut p_new = *p - k_cross_t - k_cross_t.transpose() + gain * s * gain.transpose();
    symmetrize(&mut p_new);
    *p = p_new;
    if REPORT {
        let nis = innovation.dot(&chol.solve(&innovation));
        let log_det: f64 = chol.l_dirty().diagonal().iter().map(|d| d.ln()).sum();
        let log_likelihood = -0.5 * (nis + 2.0 * log_det + M as f64 * (2.0 * PI).ln());
        Some(HandReport {
            innovation,
            innovation_covariance: s,
            nis,
            log_likelihood,
        })
    } else {
        None
    }
}

/// Lower-triangular L with L Lᵀ = C (C symmetric positive definite; only its lower triangle is
/// read): the column-by-column Cholesky loop, which is what the framework's sigma-point factor
/// runs for a positive definite C (nalgebra's `Cholesky` is slower at these sizes).
#[inline]
fn hand_cholesky<const N: usize>(c: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
    let mut l = SMatrix::<f64, N, N>::zeros();
    for j in 0..N {
        let mut d = c[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        assert!(d > 0.0, "covariance positive definite");
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        for i in (j + 1)..N {
            let mut s = c[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / ljj;
        }
    }
    l
}

/// The textbook scaled-unscented weights for dimension n.
#[derive(Clone, Copy, Debug)]
struct UtWeights {
    /// √(n + λ): sigma points are x ± γ Lⱼ.
    gamma: f64,
    /// W₀ᵐ = λ / (n + λ).
    wm0: f64,
    /// W₀ᶜ = W₀ᵐ + 1 − α² + β.
    wc0: f64,
    /// Wᵢ = 1 / (2 (n + λ)) for i ≥ 1.
    wi: f64,
}

impl UtWeights {
    fn new(n: usize, alpha: f64, beta: f64, kappa: f64) -> Self {
        let n = n as f64;
        let lambda = alpha * alpha * (n + kappa) - n;
        let c = n + lambda;
        let wm0 = lambda / c;
        Self {
            gamma: c.sqrt(),
            wm0,
            wc0: wm0 + 1.0 - alpha * alpha + beta,
            wi: 1.0 / (2.0 * c),
        }
    }

    /// The framework's default: α = 10⁻³, β = 2, κ = 0.
    fn default_for(n: usize) -> Self {
        Self::new(n, 1e-3, 2.0, 0.0)
    }
}

/// The textbook unscented transform of y = g(x), x ~ N(mean, cov): returns (ȳ, cov y, cov(x, y)),
/// the last only when `CROSS` (zero otherwise). `diff` is the output residual a ⊖ b.
#[inline]
fn hand_unscented<const N: usize, const M: usize, const CROSS: bool>(
    mean: &SVector<f64, N>,
    cov: &SMatrix<f64, N, N>,
    w: &UtWeights,
    g: impl Fn(&SVector<f64, N>) -> SVector<f64, M>,
    diff: impl Fn(&SVector<f64, M>, &SVector<f64, M>) -> SVector<f64, M>,
) -> (SVector<f64, M>, SMatrix<f64, M, M>, SMatrix<f64, N, M>) {
    let offsets = hand_cholesky(cov) * w.gamma;
    let y0 = g(mean);
    let mut y_plus = [SVector::<f64, M>::zeros(); N];
    let mut y_minus = [SVector::<f64, M>::zeros(); N];
    for j in 0..N {
        y_plus[j] = g(&(mean + offsets.column(j)));
        y_minus[j] = g(&(mean - offsets.column(j)));
    }
    let mut y_bar = y0 * w.wm0;
    for j in 0..N {
        y_bar += y_plus[j] * w.wi;
        y_bar += y_minus[j] * w.wi;
    }
    let d0 = diff(&y0, &y_bar);
    let mut cov_y = d0 * d0.transpose() * w.wc0;
    let mut cross = SMatrix::<f64, N, M>::zeros();
    for j in 0..N {
        let dp = diff(&y_plus[j], &y_bar);
        let dm = diff(&y_minus[j], &y_bar);
        cov_y += dp * dp.transpose() * w.wi;
        cov_y += dm * dm.transpose() * w.wi;
        if CROSS {
            let s = offsets.column(j);
            cross += s * dp.transpose() * w.wi;
            cross -= s * dm.transpose() * w.wi;
        }
    }
    (y_bar, cov_y, cross)
}

/// A hand-written filter's estimate.
#[derive(Clone, Copy, Debug)]
struct HandEstimate<const N: usize> {
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
}

// ---------------------------------------------------------------------------------------------
// (a) 3 states / 2 measurements, linear
// ---------------------------------------------------------------------------------------------

type State3 = SVector<f64, 3>;
type Square3 = SMatrix<f64, 3, 3>;
type Meas2 = SVector<f64, 2>;
type Input1 = SVector<f64, 1>;

/// The linear problem's matrices as plain nalgebra values (what the baselines use).
#[derive(Clone, Copy, Debug)]
struct LinearSystem {
    f: Square3,
    b: SMatrix<f64, 3, 1>,
    q: Square3,
    h: SMatrix<f64, 2, 3>,
    r: SMatrix<f64, 2, 2>,
}

impl LinearSystem {
    /// Position, velocity, acceleration with a jerk input u, observed in position and velocity;
    /// Q is the discrete white-jerk noise (σ = 0.5 m/s³) and R uncorrelated.
    fn new() -> Self {
        let dt = DT;
        let f = Square3::new(1.0, dt, dt * dt / 2.0, 0.0, 1.0, dt, 0.0, 0.0, 1.0);
        let g = State3::new(dt * dt * dt / 6.0, dt * dt / 2.0, dt);
        let q = g * g.transpose() * 0.25 + Square3::identity() * 1e-6;
        Self {
            f,
            b: g,
            q,
            h: SMatrix::<f64, 2, 3>::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
            r: SMatrix::<f64, 2, 2>::new(0.04, 0.0, 0.0, 0.01),
        }
    }

    fn process(&self) -> LinearProcess<f64, U3, U1> {
        LinearProcess {
            transition: self.f,
            input: self.b,
            noise: self.q,
        }
    }

    fn measurement(&self) -> LinearMeasurement<f64, U3, U2> {
        LinearMeasurement {
            observation: self.h,
            noise: self.r,
        }
    }

    /// Inputs and measurements of a 64-step trajectory (deterministic pseudo-noise), and the
    /// prior.
    fn trajectory(&self) -> (Vec<Input1>, Vec<Meas2>, HandEstimate<3>) {
        let mut truth = State3::new(0.0, 1.0, 0.0);
        let mut inputs = Vec::with_capacity(STEPS);
        let mut measurements = Vec::with_capacity(STEPS);
        for k in 0..STEPS {
            let u = Input1::new((0.3 * k as f64).sin());
            truth = self.f * truth + self.b * u;
            let noise = Meas2::new(0.2 * (1.7 * k as f64).sin(), 0.1 * (2.3 * k as f64).cos());
            inputs.push(u);
            measurements.push(self.h * truth + noise);
        }
        let prior = HandEstimate {
            x: State3::new(0.5, 0.5, 0.0),
            p: Square3::from_diagonal(&State3::new(1.0, 1.0, 0.5)),
        };
        (inputs, measurements, prior)
    }

    /// Hand-written KF predict.
    #[inline]
    fn predict(&self, e: &mut HandEstimate<3>, u: &Input1) {
        e.x = self.f * e.x + self.b * u;
        e.p = self.f * e.p * self.f.transpose() + self.q;
        symmetrize(&mut e.p);
    }

    /// Hand-written KF update.
    #[inline]
    fn update<const REPORT: bool>(
        &self,
        e: &mut HandEstimate<3>,
        z: &Meas2,
    ) -> Option<HandReport<2>> {
        let z_hat = self.h * e.x;
        let cross = e.p * self.h.transpose();
        let s = self.h * cross + self.r;
        hand_kalman_update::<3, 2, REPORT>(&mut e.x, &mut e.p, z - z_hat, s, cross)
    }

    /// Hand-written textbook UKF predict.
    #[inline]
    fn ukf_predict(&self, e: &mut HandEstimate<3>, u: &Input1, w: &UtWeights) {
        let (x, p, _) =
            hand_unscented::<3, 3, false>(&e.x, &e.p, w, |x| self.f * x + self.b * u, |a, b| a - b);
        e.x = x;
        e.p = p + self.q;
        symmetrize(&mut e.p);
    }

    /// Hand-written textbook UKF update.
    #[inline]
    fn ukf_update<const REPORT: bool>(
        &self,
        e: &mut HandEstimate<3>,
        z: &Meas2,
        w: &UtWeights,
    ) -> Option<HandReport<2>> {
        let (z_hat, cov_z, cross) =
            hand_unscented::<3, 2, true>(&e.x, &e.p, w, |x| self.h * x, |a, b| a - b);
        hand_kalman_update::<3, 2, REPORT>(&mut e.x, &mut e.p, z - z_hat, cov_z + self.r, cross)
    }
}

// ---------------------------------------------------------------------------------------------
// (b) 6 states / 4 measurements, nonlinear
// ---------------------------------------------------------------------------------------------

type State6 = SVector<f64, 6>;
type Square6 = SMatrix<f64, 6, 6>;
type Meas4 = SVector<f64, 4>;
type Jacobian4x6 = SMatrix<f64, 4, 6>;

/// Planar constant turn rate and acceleration, Euler-discretised, x = (p_x, p_y, v, ψ, ω, a):
///
/// ```text
/// p_x⁺ = p_x + Δt v cos ψ,   p_y⁺ = p_y + Δt v sin ψ,   v⁺ = v + Δt a,   ψ⁺ = ψ + Δt ω,
/// ω⁺ = ω,   a⁺ = a
/// ```
///
/// Q is precomputed for the benchmark's Δt (white jerk and white yaw acceleration, plus a small
/// position term). The computations are inherent methods on plain nalgebra types, so the
/// baselines call them without any estim trait.
#[derive(Clone, Copy, Debug)]
struct Vehicle {
    noise: Square6,
}

impl Vehicle {
    fn new() -> Self {
        let dt = DT;
        let mut q = Square6::zeros();
        q[(0, 0)] = 1e-4;
        q[(1, 1)] = 1e-4;
        // (v, a) driven by white jerk, (ψ, ω) by white yaw acceleration.
        for (i, j, sigma2) in [(2, 5, 0.5), (3, 4, 0.01)] {
            q[(i, i)] = dt * dt * dt / 3.0 * sigma2;
            q[(i, j)] = dt * dt / 2.0 * sigma2;
            q[(j, i)] = q[(i, j)];
            q[(j, j)] = dt * sigma2;
        }
        Self { noise: q }
    }

    fn value(&self, x: &State6, dt: f64) -> State6 {
        let (s, c) = x[3].sin_cos();
        State6::new(
            x[0] + dt * x[2] * c,
            x[1] + dt * x[2] * s,
            x[2] + dt * x[5],
            x[3] + dt * x[4],
            x[4],
            x[5],
        )
    }

    fn jacobian_at(&self, x: &State6, dt: f64) -> Square6 {
        let (s, c) = x[3].sin_cos();
        let mut j = Square6::identity();
        j[(0, 2)] = dt * c;
        j[(0, 3)] = -dt * x[2] * s;
        j[(1, 2)] = dt * s;
        j[(1, 3)] = dt * x[2] * c;
        j[(2, 5)] = dt;
        j[(3, 4)] = dt;
        j
    }

    /// Only p_x⁺ and p_y⁺ are nonlinear (in v and ψ).
    fn hessian_at(&self, x: &State6, dt: f64, k: usize) -> Option<Square6> {
        let (s, c) = x[3].sin_cos();
        let (d_v_psi, d_psi_psi) = match k {
            0 => (-dt * s, -dt * x[2] * c),
            1 => (dt * c, -dt * x[2] * s),
            _ => return None,
        };
        let mut h = Square6::zeros();
        h[(2, 3)] = d_v_psi;
        h[(3, 2)] = d_v_psi;
        h[(3, 3)] = d_psi_psi;
        Some(h)
    }
}

impl ProcessModel<f64, U6> for Vehicle {
    type Input = ();

    fn transition(&self, x: &State6, _: &(), dt: f64) -> State6 {
        self.value(x, dt)
    }

    fn process_noise(&self, _: &State6, _: &(), _: f64) -> Square6 {
        self.noise
    }
}

impl ProcessJacobian<f64, U6> for Vehicle {
    fn transition_jacobian(&self, x: &State6, _: &(), dt: f64) -> Square6 {
        self.jacobian_at(x, dt)
    }
}

impl ProcessHessian<f64, U6> for Vehicle {
    fn transition_hessian(&self, x: &State6, _: &(), dt: f64, k: usize) -> Option<Square6> {
        self.hessian_at(x, dt, k)
    }
}

/// Wraps an angle difference into (−π, π] (the inputs are differences of angles in (−π, π]).
/// One branch, as a hand-written filter would wrap, shared by the framework model and the
/// baselines (`estim_core::wrap_angle` takes any angle, at the cost of a `%`).
#[inline]
fn wrap(d: f64) -> f64 {
    if d > PI {
        d - 2.0 * PI
    } else if d <= -PI {
        d + 2.0 * PI
    } else {
        d
    }
}

/// Range and bearing to two beacons: z = (r₁, β₁, r₂, β₂), rᵢ = |p − bᵢ|,
/// βᵢ = atan2(p_y − bᵢ_y, p_x − bᵢ_x); bearings are differenced with wrapping.
#[derive(Clone, Copy, Debug)]
struct Beacons {
    beacons: [[f64; 2]; 2],
    noise: SMatrix<f64, 4, 4>,
}

impl Beacons {
    fn new() -> Self {
        Self {
            // Both to the left of the whole trajectory, so no bearing crosses ±π.
            beacons: [[-60.0, -30.0], [-60.0, 40.0]],
            noise: SMatrix::<f64, 4, 4>::from_diagonal(&Meas4::new(0.25, 1e-4, 0.25, 1e-4)),
        }
    }

    /// (dx, dy, r²) from beacon `i`.
    #[inline]
    fn offset(&self, x: &State6, i: usize) -> (f64, f64, f64) {
        let dx = x[0] - self.beacons[i][0];
        let dy = x[1] - self.beacons[i][1];
        (dx, dy, dx * dx + dy * dy)
    }

    fn value(&self, x: &State6) -> Meas4 {
        let mut z = Meas4::zeros();
        for i in 0..2 {
            let (dx, dy, r2) = self.offset(x, i);
            z[2 * i] = r2.sqrt();
            z[2 * i + 1] = dy.atan2(dx);
        }
        z
    }

    fn jacobian_at(&self, x: &State6) -> Jacobian4x6 {
        let mut j = Jacobian4x6::zeros();
        for i in 0..2 {
            let (dx, dy, r2) = self.offset(x, i);
            let r = r2.sqrt();
            j[(2 * i, 0)] = dx / r;
            j[(2 * i, 1)] = dy / r;
            j[(2 * i + 1, 0)] = -dy / r2;
            j[(2 * i + 1, 1)] = dx / r2;
        }
        j
    }

    /// ∇²r = [dy², −dx dy; −dx dy, dx²] / r³ and ∇²β = [2 dx dy, dy² − dx²; dy² − dx², −2 dx dy] / r⁴
    /// in the (p_x, p_y) block.
    fn hessian_at(&self, x: &State6, k: usize) -> Square6 {
        let (dx, dy, r2) = self.offset(x, k / 2);
        let (a, b, c) = if k.is_multiple_of(2) {
            let r3 = r2 * r2.sqrt();
            (dy * dy / r3, -dx * dy / r3, dx * dx / r3)
        } else {
            let r4 = r2 * r2;
            (
                2.0 * dx * dy / r4,
                (dy * dy - dx * dx) / r4,
                -2.0 * dx * dy / r4,
            )
        };
        let mut h = Square6::zeros();
        h[(0, 0)] = a;
        h[(0, 1)] = b;
        h[(1, 0)] = b;
        h[(1, 1)] = c;
        h
    }

    fn residual_of(&self, a: &Meas4, b: &Meas4) -> Meas4 {
        Meas4::new(
            a[0] - b[0],
            wrap(a[1] - b[1]),
            a[2] - b[2],
            wrap(a[3] - b[3]),
        )
    }
}

impl MeasurementModel<f64, U6, U4> for Beacons {
    fn measure(&self, x: &State6) -> Meas4 {
        self.value(x)
    }

    fn measurement_noise(&self, _: &State6) -> SMatrix<f64, 4, 4> {
        self.noise
    }

    fn residual_into(&self, a: &Meas4, b: &Meas4, out: &mut Meas4) {
        *out = self.residual_of(a, b);
    }
}

impl MeasurementJacobian<f64, U6, U4> for Beacons {
    fn measurement_jacobian(&self, x: &State6) -> Jacobian4x6 {
        self.jacobian_at(x)
    }
}

impl MeasurementHessian<f64, U6, U4> for Beacons {
    fn measurement_hessian(&self, x: &State6, k: usize) -> Option<Square6> {
        Some(self.hessian_at(x, k))
    }
}

/// The nonlinear problem's hand-written steps.
struct NonlinearSystem {
    vehicle: Vehicle,
    beacons: Beacons,
}

impl NonlinearSystem {
    fn new() -> Self {
        Self {
            vehicle: Vehicle::new(),
            beacons: Beacons::new(),
        }
    }

    /// Measurements of a 64-step trajectory (a 25 m circle at 5 m/s, gently accelerating,
    /// deterministic pseudo-noise) and the prior (offset from the truth).
    fn trajectory(&self) -> (Vec<Meas4>, HandEstimate<6>) {
        let start = State6::new(25.0, 0.0, 5.0, PI / 2.0, 0.2, 0.1);
        let mut truth = start;
        let mut measurements = Vec::with_capacity(STEPS);
        for k in 0..STEPS {
            truth = self.vehicle.value(&truth, DT);
            let kf = k as f64;
            let noise = Meas4::new(
                0.3 * (1.3 * kf).sin(),
                0.005 * (2.1 * kf).cos(),
                0.3 * (0.7 * kf).cos(),
                0.005 * (1.9 * kf).sin(),
            );
            measurements.push(self.beacons.value(&truth) + noise);
        }
        let prior = HandEstimate {
            x: start + State6::new(1.0, -1.0, 0.5, 0.05, -0.02, 0.0),
            p: Square6::from_diagonal(&State6::new(2.0, 2.0, 1.0, 0.01, 0.004, 0.1)),
        };
        (measurements, prior)
    }

    /// Hand-written EKF predict.
    #[inline]
    fn ekf_predict(&self, e: &mut HandEstimate<6>) {
        let x = self.vehicle.value(&e.x, DT);
        let f = self.vehicle.jacobian_at(&e.x, DT);
        e.p = f * e.p * f.transpose() + self.vehicle.noise;
        symmetrize(&mut e.p);
        e.x = x;
    }

    /// Hand-written EKF update.
    #[inline]
    fn ekf_update<const REPORT: bool>(
        &self,
        e: &mut HandEstimate<6>,
        z: &Meas4,
    ) -> Option<HandReport<4>> {
        let z_hat = self.beacons.value(&e.x);
        let h = self.beacons.jacobian_at(&e.x);
        let cross = e.p * h.transpose();
        let s = h * cross + self.beacons.noise;
        let innovation = self.beacons.residual_of(z, &z_hat);
        hand_kalman_update::<6, 4, REPORT>(&mut e.x, &mut e.p, innovation, s, cross)
    }

    /// Hand-written textbook UKF predict.
    #[inline]
    fn ukf_predict(&self, e: &mut HandEstimate<6>, w: &UtWeights) {
        let (x, p, _) = hand_unscented::<6, 6, false>(
            &e.x,
            &e.p,
            w,
            |x| self.vehicle.value(x, DT),
            |a, b| a - b,
        );
        e.x = x;
        e.p = p + self.vehicle.noise;
        symmetrize(&mut e.p);
    }

    /// Hand-written textbook UKF update.
    #[inline]
    fn ukf_update<const REPORT: bool>(
        &self,
        e: &mut HandEstimate<6>,
        z: &Meas4,
        w: &UtWeights,
    ) -> Option<HandReport<4>> {
        let (z_hat, cov_z, cross) = hand_unscented::<6, 4, true>(
            &e.x,
            &e.p,
            w,
            |x| self.beacons.value(x),
            |a, b| self.beacons.residual_of(a, b),
        );
        let innovation = self.beacons.residual_of(z, &z_hat);
        hand_kalman_update::<6, 4, REPORT>(
            &mut e.x,
            &mut e.p,
            innovation,
            cov_z + self.beacons.noise,
            cross,
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Checks before timing
// ---------------------------------------------------------------------------------------------

/// max |a − b| / max(1, max |b|).
fn rel_gap<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>) -> f64 {
    (a - b).amax() / b.amax().max(1.0)
}

/// Runs a framework filter and a hand-written one in lockstep over the trajectory and returns
/// the largest relative gap between their states, covariances and update reports.
fn lockstep<const N: usize, const M: usize, F: Estimator<f64, nalgebra::Const<N>>>(
    mut framework: F,
    mut framework_step: impl FnMut(&mut F, usize) -> UpdateReport<f64, nalgebra::Const<M>>,
    mut hand: HandEstimate<N>,
    mut hand_step: impl FnMut(&mut HandEstimate<N>, usize) -> Option<HandReport<M>>,
) -> f64 {
    let mut worst: f64 = 0.0;
    for k in 0..STEPS {
        let a = framework_step(&mut framework, k);
        let b = hand_step(&mut hand, k).expect("a report");
        let scalar_gap = |a: f64, b: f64| (a - b).abs() / b.abs().max(1.0);
        worst = worst
            .max(rel_gap(framework.state(), &hand.x))
            .max(rel_gap(framework.covariance(), &hand.p))
            .max(rel_gap(&a.innovation, &b.innovation))
            .max(rel_gap(&a.innovation_covariance, &b.innovation_covariance))
            .max(scalar_gap(a.nis, b.nis))
            .max(scalar_gap(a.log_likelihood, b.log_likelihood));
    }
    worst
}

// ---------------------------------------------------------------------------------------------
// Benchmarks
// ---------------------------------------------------------------------------------------------

/// A group of this bench's steps ([`Steps`], reset every [`STEPS`] steps); counted mode from
/// `FILTERS_BENCH_STEPS=<group>/<name>=<count>`.
fn steps<'a>(c: &'a mut Criterion, name: &'static str) -> Steps<'a, STEPS> {
    Steps::new(c.benchmark_group(name), name, "FILTERS_BENCH_STEPS")
}

fn linear_3x2(c: &mut Criterion) {
    let sys = LinearSystem::new();
    let process = sys.process();
    let measurement = sys.measurement();
    let (inputs, measurements, hand_prior) = sys.trajectory();
    let prior = Gaussian::new(hand_prior.x, hand_prior.p).expect("valid prior");
    let w3 = UtWeights::default_for(3);

    // The baselines must compute what the filters compute. KF and EKF do identical arithmetic
    // (measured gap ≈ 2e-14, bound 1e-12); the textbook UKF multiplies by W₀ᵐ ≈ −10⁶ where the
    // framework's shifted form does not, which costs ≈ 6-7 digits (measured ≈ 4e-8, bound 1e-6).
    let kf_step = |f: &mut KalmanFilter<f64, U3>, k: usize| {
        f.predict(&process, &inputs[k], DT).unwrap();
        f.update(&measurement, &measurements[k]).unwrap()
    };
    let gap = lockstep(
        KalmanFilter::new(prior.clone()),
        kf_step,
        hand_prior,
        |e, k| {
            sys.predict(e, &inputs[k]);
            sys.update::<true>(e, &measurements[k])
        },
    );
    eprintln!("lockstep 3x2 KF: largest relative gap {gap:.1e}");
    assert!(
        gap < 1e-12,
        "hand-written KF differs from KalmanFilter by {gap:e}"
    );
    let gap = lockstep(
        Ukf::new(prior.clone()),
        |f: &mut Ukf<f64, U3>, k| {
            f.predict(&process, &inputs[k], DT).unwrap();
            f.update(&measurement, &measurements[k]).unwrap()
        },
        hand_prior,
        |e, k| {
            sys.ukf_predict(e, &inputs[k], &w3);
            sys.ukf_update::<true>(e, &measurements[k], &w3)
        },
    );
    eprintln!("lockstep 3x2 UKF: largest relative gap {gap:.1e}");
    assert!(gap < 1e-6, "hand-written UKF differs from Ukf by {gap:e}");

    let mut group = steps(c, "step_3x2_linear");
    let (p, m) = (&process, &measurement);
    let (us, zs) = (&inputs, &measurements);
    group.bench("KalmanFilter", &KalmanFilter::new(prior.clone()), |f, i| {
        f.predict(black_box(p), &us[i], DT).unwrap();
        f.update(black_box(m), &zs[i]).unwrap()
    });
    group.bench("hand_kf", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.predict(e, &us[i]);
        s.update::<true>(e, &zs[i])
    });
    group.bench("hand_kf_no_report", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.predict(e, &us[i]);
        s.update::<false>(e, &zs[i]);
    });
    group.bench("Ekf", &Ekf::new(prior.clone()), |f, i| {
        f.predict(black_box(p), &us[i], DT).unwrap();
        f.update(black_box(m), &zs[i]).unwrap()
    });
    group.bench("Ukf", &Ukf::new(prior.clone()), |f, i| {
        f.predict(black_box(p), &us[i], DT).unwrap();
        f.update(black_box(m), &zs[i]).unwrap()
    });
    group.bench("hand_ukf", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.ukf_predict(e, &us[i], &w3);
        s.ukf_update::<true>(e, &zs[i], &w3)
    });
    group.bench("hand_ukf_no_report", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.ukf_predict(e, &us[i], &w3);
        s.ukf_update::<false>(e, &zs[i], &w3);
    });
    group.finish();

    // Where the time goes: each half-step alone (same loop; without the other half the
    // covariance only grows or only shrinks between resets).
    let mut group = steps(c, "breakdown_3x2");
    group.bench(
        "KalmanFilter_predict",
        &KalmanFilter::new(prior.clone()),
        |f, i| f.predict(black_box(p), &us[i], DT).unwrap(),
    );
    group.bench("hand_kf_predict", &hand_prior, |e, i| {
        black_box(&sys).predict(e, &us[i])
    });
    group.bench(
        "KalmanFilter_update",
        &KalmanFilter::new(prior.clone()),
        |f, i| f.update(black_box(m), &zs[i]).unwrap(),
    );
    group.bench("hand_kf_update", &hand_prior, |e, i| {
        black_box(&sys).update::<true>(e, &zs[i])
    });
    group.bench("Ukf_predict", &Ukf::new(prior.clone()), |f, i| {
        f.predict(black_box(p), &us[i], DT).unwrap()
    });
    group.bench("hand_ukf_predict", &hand_prior, |e, i| {
        black_box(&sys).ukf_predict(e, &us[i], &w3)
    });
    group.bench("Ukf_update", &Ukf::new(prior.clone()), |f, i| {
        f.update(black_box(m), &zs[i]).unwrap()
    });
    group.bench("hand_ukf_update", &hand_prior, |e, i| {
        black_box(&sys).ukf_update::<true>(e, &zs[i], &w3)
    });
    group.finish();
}

fn nonlinear_6x4(c: &mut Criterion) {
    let sys = NonlinearSystem::new();
    let (vehicle, beacons) = (&sys.vehicle, &sys.beacons);
    let (measurements, hand_prior) = sys.trajectory();
    let prior = Gaussian::new(hand_prior.x, hand_prior.p).expect("valid prior");
    let w6 = UtWeights::default_for(6);

    // Time correct models only: analytic derivatives against finite differences, at the
    // prior and along the trajectory's first steps.
    let mut x = hand_prior.x;
    for _ in 0..8 {
        let report = check_process_model(vehicle, &x, &(), DT).expect("derivative check runs");
        assert!(report.is_accurate(1e-6), "Vehicle derivatives: {report}");
        let report = check_measurement_model(beacons, &x).expect("derivative check runs");
        assert!(report.is_accurate(1e-6), "Beacons derivatives: {report}");
        x = vehicle.value(&x, DT);
    }

    // The baselines must compute what the filters compute (tolerances as in `linear_3x2`;
    // measured gaps ≈ 5e-14 for the EKF, ≈ 9e-8 for the UKF).
    let gap = lockstep(
        Ekf::new(prior.clone()),
        |f: &mut Ekf<f64, U6>, k| {
            f.predict(vehicle, &(), DT).unwrap();
            f.update(beacons, &measurements[k]).unwrap()
        },
        hand_prior,
        |e, k| {
            sys.ekf_predict(e);
            sys.ekf_update::<true>(e, &measurements[k])
        },
    );
    eprintln!("lockstep 6x4 EKF: largest relative gap {gap:.1e}");
    assert!(gap < 1e-12, "hand-written EKF differs from Ekf by {gap:e}");
    let gap = lockstep(
        Ukf::new(prior.clone()),
        |f: &mut Ukf<f64, U6>, k| {
            f.predict(vehicle, &(), DT).unwrap();
            f.update(beacons, &measurements[k]).unwrap()
        },
        hand_prior,
        |e, k| {
            sys.ukf_predict(e, &w6);
            sys.ukf_update::<true>(e, &measurements[k], &w6)
        },
    );
    eprintln!("lockstep 6x4 UKF: largest relative gap {gap:.1e}");
    assert!(gap < 1e-6, "hand-written UKF differs from Ukf by {gap:e}");

    let mut group = steps(c, "step_6x4_nonlinear");
    let zs = &measurements;
    group.bench("Ekf", &Ekf::new(prior.clone()), |f, i| {
        f.predict(black_box(vehicle), &(), DT).unwrap();
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    group.bench("hand_ekf", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.ekf_predict(e);
        s.ekf_update::<true>(e, &zs[i])
    });
    group.bench("hand_ekf_no_report", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.ekf_predict(e);
        s.ekf_update::<false>(e, &zs[i]);
    });
    group.bench(
        "SecondOrderEkf",
        &SecondOrderEkf::new(prior.clone()),
        |f, i| {
            f.predict(black_box(vehicle), &(), DT).unwrap();
            f.update(black_box(beacons), &zs[i]).unwrap()
        },
    );
    group.bench("Ukf", &Ukf::new(prior.clone()), |f, i| {
        f.predict(black_box(vehicle), &(), DT).unwrap();
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    group.bench("hand_ukf", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.ukf_predict(e, &w6);
        s.ukf_update::<true>(e, &zs[i], &w6)
    });
    group.bench("hand_ukf_no_report", &hand_prior, |e, i| {
        let s = black_box(&sys);
        s.ukf_predict(e, &w6);
        s.ukf_update::<false>(e, &zs[i], &w6);
    });
    group.finish();

    // The state-space layer on a vector state: the default (Euclidean, whose fused x + K ν
    // and batched sigma points run) against the same + and − given as a user StateSpace that
    // does not declare itself VECTOR (so every ⊞ and ⊟ is a call through the trait).
    let mut group = steps(c, "state_space_6x4");
    group.bench("Ekf", &Ekf::new(prior.clone()), |f, i| {
        f.predict(black_box(vehicle), &(), DT).unwrap();
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    let plain_ekf = Ekf::new(prior.clone()).with_state_space(PlainVector);
    group.bench("Ekf_plain_vector_space", &plain_ekf, |f, i| {
        f.predict(black_box(vehicle), &(), DT).unwrap();
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    group.bench("Ukf", &Ukf::new(prior.clone()), |f, i| {
        f.predict(black_box(vehicle), &(), DT).unwrap();
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    let plain_ukf = Ukf::new(prior.clone()).with_state_space(PlainVector);
    group.bench("Ukf_plain_vector_space", &plain_ukf, |f, i| {
        f.predict(black_box(vehicle), &(), DT).unwrap();
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    group.finish();

    // Where the time goes: each half-step alone, then pieces of the framework's step.
    let mut group = steps(c, "breakdown_6x4");
    group.bench("Ekf_predict", &Ekf::new(prior.clone()), |f, _| {
        f.predict(black_box(vehicle), &(), DT).unwrap()
    });
    group.bench("hand_ekf_predict", &hand_prior, |e, _| {
        black_box(&sys).ekf_predict(e)
    });
    group.bench("Ekf_update", &Ekf::new(prior.clone()), |f, i| {
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    group.bench("hand_ekf_update", &hand_prior, |e, i| {
        black_box(&sys).ekf_update::<true>(e, &zs[i])
    });
    group.bench("Ukf_predict", &Ukf::new(prior.clone()), |f, _| {
        f.predict(black_box(vehicle), &(), DT).unwrap()
    });
    group.bench("hand_ukf_predict", &hand_prior, |e, _| {
        black_box(&sys).ukf_predict(e, &w6)
    });
    group.bench("Ukf_update", &Ukf::new(prior.clone()), |f, i| {
        f.update(black_box(beacons), &zs[i]).unwrap()
    });
    group.bench("hand_ukf_update", &hand_prior, |e, i| {
        black_box(&sys).ukf_update::<true>(e, &zs[i], &w6)
    });
    // The 13 finiteness checks of one framework EKF step, on matrices of the same shapes:
    // predict Q, propagated mean, covariance and cross-covariance, P⁻; update's propagated
    // mean, covariance and cross-covariance, R, ν, K, x⁺, P⁺.
    let (x6, p6) = (hand_prior.x, hand_prior.p);
    let (z4, r4, k64) = (zs[0], beacons.noise, SMatrix::<f64, 6, 4>::repeat(0.5));
    group.bench("ensure_finite_x13", &(), |_, _| {
        use estim_core::checks::ensure_finite;
        use estim_core::{Quantity::Mean, Stage::Update};
        let ok = ensure_finite(black_box(&p6), Update, Mean).is_ok()
            & ensure_finite(black_box(&x6), Update, Mean).is_ok()
            & ensure_finite(black_box(&p6), Update, Mean).is_ok()
            & ensure_finite(black_box(&p6), Update, Mean).is_ok()
            & ensure_finite(black_box(&p6), Update, Mean).is_ok()
            & ensure_finite(black_box(&z4), Update, Mean).is_ok()
            & ensure_finite(black_box(&r4), Update, Mean).is_ok()
            & ensure_finite(black_box(&k64), Update, Mean).is_ok()
            & ensure_finite(black_box(&r4), Update, Mean).is_ok()
            & ensure_finite(black_box(&z4), Update, Mean).is_ok()
            & ensure_finite(black_box(&k64), Update, Mean).is_ok()
            & ensure_finite(black_box(&x6), Update, Mean).is_ok()
            & ensure_finite(black_box(&p6), Update, Mean).is_ok();
        assert!(ok);
    });
    // The UKF factorises P twice per step: estim's semi-definite factor, the baselines' plain
    // Cholesky loop and nalgebra's `Cholesky` (which the update uses for S).
    group.bench("psd_factor_6x6", &(), |_, _| {
        estim_core::linalg::psd_factor(black_box(&p6), estim_core::Stage::Propagation).unwrap()
    });
    group.bench("hand_cholesky_6x6", &(), |_, _| {
        hand_cholesky(black_box(&p6))
    });
    group.bench("nalgebra_cholesky_6x6", &(), |_, _| {
        black_box(p6).cholesky().unwrap().unpack()
    });
    group.finish();
}

/// x ⊞ δ = x + δ and a ⊟ b = a − b, written as a user would, without `VECTOR = true`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PlainVector;

impl estim_core::StateSpace<f64, U6> for PlainVector {
    fn plus_into(&self, x: &SVector<f64, 6>, delta: &SVector<f64, 6>, out: &mut SVector<f64, 6>) {
        *out = x + delta;
    }
    fn minus_into(&self, a: &SVector<f64, 6>, b: &SVector<f64, 6>, out: &mut SVector<f64, 6>) {
        *out = a - b;
    }
}

fn config() -> Criterion {
    // Modest times: the benchmark machine is a shared, noisy 2-core box.
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
}

criterion_group! {
    name = benches;
    config = config();
    targets = linear_3x2, nonlinear_6x4
}
criterion_main!(benches);
