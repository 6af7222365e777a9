//! One filter step (predict + update) of the KF, EKF and UKF at runtime sizes n = 2, 4, 6, 12,
//! 16, 24, 50, 100, 200 states with m = n/2 measurements (1, 2, 3, 6, 8, …), measured five ways
//! side by side:
//!
//! - `estim`: the library through its public API with `N = M = Dyn` ([`DVector`], [`DMatrix`]):
//!   [`KalmanFilter`], [`Ekf`], [`Ukf`], calling [`Predict::predict`] then
//!   [`Update::update_into`] with one [`UpdateReport`] made before timing (`update` would
//!   allocate a fresh report each call). The bench's nonlinear models opt in to writing their
//!   outputs in place ([`InPlace`]), as the library's linear models do, so a `Dyn` step
//!   allocates nothing; with `DYNAMIC_BENCH_OWNED=1` they do not, and every value, noise and
//!   Jacobian is a fresh allocation (what a model without the opt-in costs).
//! - `estim_static`: the same with static sizes (`Const<n>`/`Const<n/2>` for n = 2, 4, 6, 12,
//!   16, 24, 50), for the static/dynamic crossover and the static reference at small n.
//! - `dmatrix`: a hand-written step with nalgebra `DMatrix` operator formulas, allocating
//!   freely, as a user would write it (no estim code).
//! - `dmatrix_prealloc`: the same algebra on nalgebra `DMatrix`es with every buffer (model
//!   outputs, Jacobians and their transposes, the sigma-point deviations) allocated once before
//!   timing, as a careful user would write it: `mul_to`, `gemm`, `gemm_tr`, `gemv_tr`, `ger`,
//!   `transpose_to`, nalgebra's `Cholesky` on the moved buffer (`unpack_dirty` gives the same
//!   storage back) and its in-place triangular solves. The baseline of the small sizes.
//! - `faer`: a hand-written step with faer 0.24, single-threaded (`Par::Seq`), every buffer
//!   (including the model outputs and the Cholesky scratch) allocated once before timing:
//!   `matmul` into preallocated matrices, `cholesky_in_place`, triangular solves in place,
//!   transposes as free views.
//!
//! **Names.** One criterion group per filter and size, `kf/n=12` … `ukf/n=200`, holding the
//! functions `estim`, `estim_static`, `dmatrix`, `dmatrix_prealloc`, `faer`; so the benchmark
//! ids are e.g. `ukf/n=200/faer`.
//!
//! **Commands.**
//!
//! ```text
//! # everything (≈ 8 min on the shared 2-core box; results in target/criterion/)
//! cargo bench -p estim-filters-benches --bench dynamic
//! # one group or one id (criterion's regex filter; anchor it, or kf/ matches ekf/ and ukf/)
//! cargo bench -p estim-filters-benches --bench dynamic -- '^ukf/n=100/'
//! # counted mode: no criterion; only the named (filter, n) is set up and cross-checked (5 steps),
//! # then the named variant runs <count> steps. For CPU time per step, run the binary under perf:
//! BIN=$(cargo bench -p estim-filters-benches --bench dynamic --no-run --message-format=json \
//!       | jq -r 'select(.executable != null) | .executable')
//! DYNAMIC_BENCH_STEPS=ukf/n=200/estim=200 perf stat -e task-clock "$BIN" --bench
//! # (count = 0 measures the set-up and the cross-check alone, to subtract)
//! ```
//!
//! **The models** (seed 1, [`StdRng`]): F = 0.95 Q₀ with Q₀ the orthogonal factor of a Gaussian
//! matrix (spectral radius and every singular value 0.95, dense, perfectly conditioned), H an m×n
//! Gaussian matrix / √n, Q = G Gᵀ/n + 0.1 I, R = G' G'ᵀ/m + 0.1 I, prior x = 0, P = I. The KF
//! uses f(x) = F x ([`LinearProcess`] with no input, `U0`) and h(x) = H x ([`LinearMeasurement`]);
//! the EKF and UKF use f(x) = F x + ε sin x and h(x) = H x + ε sin(H x) (elementwise, ε = 0.05),
//! with exact Jacobians F + ε diag(cos x) and diag(1 + ε cos(H x)) H. The measurements are
//! [`STEPS`] readings of a simulation of the true system (with noise drawn from Q and R), one
//! set for the linear and one for the nonlinear system.
//!
//! **The algebra** (every way computes it):
//!
//! ```text
//! KF/EKF predict: x⁻ = f(x); F = ∂f/∂x(x); A = F P; P⁻ = A Fᵀ + Q; P⁻ ← (P⁻ + P⁻ᵀ)/2
//! update:         ẑ = h(x⁻); H = ∂h/∂x(x⁻); B = H P⁻ (m×n); S = B Hᵀ + R; S ← (S + Sᵀ)/2;
//!                 L Lᵀ = S; ν = z − ẑ; w = L⁻¹ ν; NIS = wᵀ w; ln det S = 2 Σ ln Lᵢᵢ;
//!                 Kᵀ = L⁻ᵀ (L⁻¹ B); x⁺ = x⁻ + (Kᵀ)ᵀ ν; X = (Kᵀ)ᵀ (−B) (= −K Pₓᵤᵀ, n×n);
//!                 P⁺[i,j] = (P⁻[i,j] + X[i,j]) + X[j,i] (in that order);
//!                 P⁺ += (S Kᵀ)ᵀ Kᵀ (= K S Kᵀ); P⁺ ← (P⁺ + P⁺ᵀ)/2
//!                 (the Joseph form P − K Pₓᵤᵀ − Pₓᵤ Kᵀ + K S Kᵀ, grouped as the library groups
//!                 it, so that P + X cancels exactly when a state is measured almost exactly)
//! UKF transform of g at (x, P), α = 10⁻³, β = 2, κ = 0: c = α²(n + κ); L = √c chol(P);
//!                 w = 1/(2c); y₀ = g(x); D±[:, j] = g(x ± Lⱼ) − y₀; d̄ = w Σⱼ (D₊ + D₋)[:, j];
//!                 cov = w (D₊ D₊ᵀ + D₋ D₋ᵀ) + (β − α²) d̄ d̄ᵀ; mean = y₀ + d̄;
//!                 Pₓᵤ = w L (D₊ − D₋)ᵀ (update only)
//! UKF predict:    x⁻ = mean, P⁻ = cov + Q, symmetrised
//! UKF update:     ẑ = mean, S = cov + R, B = Pₓᵤᵀ, then the update above from "S ← …"
//! ```
//!
//! Today's library computes the same quantities with rounding-level differences (its UKF
//! factor is its own semi-definite Cholesky loop, it accumulates the sigma-point sums point by
//! point, and its Joseph update is the one above, so the baselines time the same operation
//! count). The baselines
//! evaluate the UKF's sigma points one at a time, as the library does (a batched evaluation,
//! F X for all 2n points in one product, would be faster for this model but is a property of
//! the model, not of the filter).
//!
//! **What one iteration is** (as in the `filters` bench): each variant keeps its estimate across
//! iterations and takes one predict and one update per iteration with the next measurement;
//! after [`STEPS`] steps it is reset to the prior. The estimate passes through `black_box` and
//! the step's NIS is returned to criterion (the baselines also compute ln p(z), as the library's
//! report does, and `black_box` it).
//!
//! **Correctness guard.** Before anything is timed, every variant runs [`CHECK_STEPS`] steps
//! from the prior with the same measurements, and the states, covariances and NIS are compared
//! with the `dmatrix` ones (relative max-abs gap, max|a − b| / max(1, max|b|)); the bench panics
//! if any differs by more than [`TOLERANCE`] = 1e-8 (for the UKF too, whose mean amplifies
//! round-off by 1/α²: derivation there). The gaps are printed to stderr.

mod common;

use std::f64::consts::PI;
use std::hint::black_box;
use std::time::Duration;

use common::{Steps, counted_spec};
use criterion::{Criterion, SamplingMode, criterion_group, criterion_main};
use estim_core::kernel;
use estim_core::nalgebra::allocator::Allocator;
use estim_core::nalgebra::{
    Const, DMatrix, DVector, DVectorViewMut, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U0,
};
use estim_core::{
    Alloc, Gaussian, InPlace, LinearMeasurement, LinearProcess, MeasurementJacobian,
    MeasurementModel, ProcessJacobian, ProcessModel,
};
use estim_filters::{Ekf, Estimator, KalmanFilter, Predict, Ukf, Update, UpdateReport};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{
    LltRegularization, cholesky_in_place, cholesky_in_place_scratch,
};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::reborrow::ReborrowMut;
use faer::{Accum, Col, ColMut, ColRef, Mat, MatMut, MatRef, Par};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// State dimensions; m = n/2.
const SIZES: [usize; 9] = [2, 4, 6, 12, 16, 24, 50, 100, 200];

/// Recorded measurements per system; the filters are reset to the prior after each pass.
const STEPS: usize = 200;

/// Steps of the correctness guard.
const CHECK_STEPS: usize = 5;

/// Strength of the sine terms of the nonlinear models.
const EPS: f64 = 0.05;

/// The models ignore Δt.
const DT: f64 = 1.0;

/// The unscented parameters (= `Unscented::default()`).
const ALPHA: f64 = 1e-3;
const BETA: f64 = 2.0;
const KAPPA: f64 = 0.0;

/// Largest relative gap (max|a − b| / max(1, max|b|), over x, P and each step's NIS) allowed
/// between any variant and `dmatrix` after [`CHECK_STEPS`] steps, for all three filters.
///
/// - KF, EKF: the variants do the same arithmetic in different summation orders (blocked or
///   unblocked products and Cholesky), O(u) relative per operation (u = 2⁻⁵³ ≈ 1.1e-16) on
///   well-conditioned matrices, not amplified: expected ≈ 1e-15 (measured 3e-16 … 1.2e-15).
/// - UKF: the mean is y₀ + w Σᵢ dᵢ with dᵢ = g(χᵢ) − y₀ and 2n w = 1/α² = 10⁶, so a rounding
///   error δ ≈ u ‖y‖ in y₀ (whose product F x or H x each implementation sums in its own order)
///   reaches the mean as δ (1 − 1/α²): ≈ u/α² ≈ 1.1e-10 relative per transform, the library's
///   documented ε‖y‖/α² (the covariance is unaffected: it never multiplies by 1/α²). Two
///   transforms per step, 5 steps, adding in the worst case: 10 u/α² ≈ 1.1e-9 (measured
///   2e-10 … 8e-10 at n = 12 … 200). So 1e-8 holds for the UKF too, with a margin of ≈ 10 for
///   ‖y‖ > 1 and long sums; anything larger means a different algorithm, not round-off.
const TOLERANCE: f64 = 1e-8;

// ---------------------------------------------------------------------------------------------
// The problem (plain nalgebra) and the estim models
// ---------------------------------------------------------------------------------------------

fn gaussian_matrix(rng: &mut StdRng, rows: usize, cols: usize) -> DMatrix<f64> {
    DMatrix::from_fn(rows, cols, |_, _| rng.sample::<f64, _>(StandardNormal))
}

/// G Gᵀ / k + 0.1 I for a k×k Gaussian G.
fn random_spd(rng: &mut StdRng, k: usize) -> DMatrix<f64> {
    let g = gaussian_matrix(rng, k, k);
    &g * g.transpose() / k as f64 + DMatrix::identity(k, k) * 0.1
}

/// x ↦ F x + ε sin x.
fn sine_process_value(f: &DMatrix<f64>, x: &DVector<f64>) -> DVector<f64> {
    f * x + x.map(|v| EPS * v.sin())
}

/// x ↦ H x + ε sin(H x).
fn sine_measurement_value(h: &DMatrix<f64>, x: &DVector<f64>) -> DVector<f64> {
    (h * x).map(|v| v + EPS * v.sin())
}

/// F + ε diag(cos x).
fn sine_process_jacobian(f: &DMatrix<f64>, x: &DVector<f64>) -> DMatrix<f64> {
    let mut j = f.clone();
    for i in 0..x.len() {
        j[(i, i)] += EPS * x[i].cos();
    }
    j
}

/// diag(1 + ε cos(H x)) H.
fn sine_measurement_jacobian(h: &DMatrix<f64>, x: &DVector<f64>) -> DMatrix<f64> {
    let hx = h * x;
    let mut j = h.clone();
    for i in 0..hx.len() {
        j.row_mut(i).scale_mut(1.0 + EPS * hx[i].cos());
    }
    j
}

/// The matrices of one size and the recorded measurements.
struct Problem {
    n: usize,
    m: usize,
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    /// Measurements of the linear system (KF).
    z_linear: Vec<DVector<f64>>,
    /// Measurements of the nonlinear system (EKF, UKF).
    z_sine: Vec<DVector<f64>>,
}

impl Problem {
    fn new(n: usize) -> Self {
        let m = n / 2;
        let mut rng = StdRng::seed_from_u64(1);
        let f = gaussian_matrix(&mut rng, n, n).qr().q() * 0.95;
        let h = gaussian_matrix(&mut rng, m, n) / (n as f64).sqrt();
        let q = random_spd(&mut rng, n);
        let r = random_spd(&mut rng, m);
        let (lq, lr) = (
            q.clone().cholesky().expect("Q SPD").unpack(),
            r.clone().cholesky().expect("R SPD").unpack(),
        );
        let x0 = DVector::from_fn(n, |_, _| rng.sample::<f64, _>(StandardNormal));
        let mut simulate = |nonlinear: bool| {
            let mut x = x0.clone();
            (0..STEPS)
                .map(|_| {
                    let w = &lq * DVector::from_fn(n, |_, _| rng.sample::<f64, _>(StandardNormal));
                    let v = &lr * DVector::from_fn(m, |_, _| rng.sample::<f64, _>(StandardNormal));
                    if nonlinear {
                        x = sine_process_value(&f, &x) + w;
                        sine_measurement_value(&h, &x) + v
                    } else {
                        x = &f * &x + w;
                        &h * &x + v
                    }
                })
                .collect::<Vec<_>>()
        };
        let z_linear = simulate(false);
        let z_sine = simulate(true);
        Self {
            n,
            m,
            f,
            h,
            q,
            r,
            z_linear,
            z_sine,
        }
    }
}

/// f(x) = F x + ε sin x, noise Q.
#[derive(Clone, Debug)]
struct SineProcess<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    f: OMatrix<f64, N, N>,
    q: OMatrix<f64, N, N>,
    /// Opted in to [`InPlace`] (off with `DYNAMIC_BENCH_OWNED=1`, to time the owned route).
    in_place: bool,
}

impl<N: Dim> ProcessModel<f64, N> for SineProcess<N>
where
    DefaultAllocator: Alloc<N>,
{
    type Input = ();

    fn transition(&self, x: &OVector<f64, N>, _: &(), _: f64) -> OVector<f64, N> {
        let mut y = &self.f * x;
        y.zip_apply(x, |yi, xi| *yi += EPS * xi.sin());
        y
    }

    fn process_noise(&self, _: &OVector<f64, N>, _: &(), _: f64) -> OMatrix<f64, N, N> {
        self.q.clone()
    }

    fn in_place(&self) -> Option<&dyn InPlace<f64, N, N>> {
        self.in_place.then_some(self as &dyn InPlace<f64, N, N>)
    }
}

/// The allocation-free route (the library's one opt-in, [`InPlace`]): F x + ε sin x, Q and
/// F + ε diag(cos x) written into the filter's buffers.
impl<N: Dim> InPlace<f64, N, N> for SineProcess<N>
where
    DefaultAllocator: Alloc<N>,
{
    fn value_into(&self, x: &OVector<f64, N>, _: &(), _: f64, out: &mut OVector<f64, N>) {
        product_into(out, &self.f, x);
        out.zip_apply(x, |yi, xi| *yi += EPS * xi.sin());
    }

    fn noise_into(&self, _: &OVector<f64, N>, _: &(), _: f64, out: &mut OMatrix<f64, N, N>) {
        assign(out, &self.q);
    }

    fn jacobian_into(&self, x: &OVector<f64, N>, _: &(), _: f64, out: &mut OMatrix<f64, N, N>) {
        assign(out, &self.f);
        for i in 0..x.nrows() {
            out[(i, i)] += EPS * x[i].cos();
        }
    }

    /// Never asked: the model has no Hessian traits.
    fn hessian_into<'o>(
        &self,
        _: &OVector<f64, N>,
        _: &(),
        _: f64,
        _: usize,
        _: &'o mut OMatrix<f64, N, N>,
    ) -> Option<&'o mut OMatrix<f64, N, N>> {
        None
    }
}

/// out ← a, without allocating when the shapes agree.
fn assign<R: Dim, C: Dim>(out: &mut OMatrix<f64, R, C>, a: &OMatrix<f64, R, C>)
where
    DefaultAllocator: Allocator<R, C>,
{
    if out.shape() == a.shape() {
        kernel::copy(out, a);
    } else {
        *out = a.clone();
    }
}

/// out ← A x, without allocating, through `estim_core::kernel::mul` as the library's linear
/// models do it (for `Dyn` and static sizes above 8 its matrix–vector sweep, compiled for the
/// CPU at run time; static sizes up to 8 the operator form, which unrolls; the faer baseline's
/// models use faer's general product). With the operator form at every static size (before
/// this was the library's rule too), nalgebra's unblocked fixed-size product made the static
/// UKF 2.0× (n = 24) and 2.9× (n = 50) the `Dyn` step: the model's cost, not the filter's.
fn product_into<R: Dim, C: Dim>(
    out: &mut OVector<f64, R>,
    a: &OMatrix<f64, R, C>,
    x: &OVector<f64, C>,
) where
    DefaultAllocator: Allocator<R, C> + Allocator<R> + Allocator<C>,
{
    if a.shape() == (out.nrows(), x.nrows()) {
        kernel::mul(out, kernel::Accum::Replace, 1.0, a, x);
    } else {
        *out = a * x;
    }
}

impl<N: Dim> ProcessJacobian<f64, N> for SineProcess<N>
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_jacobian(&self, x: &OVector<f64, N>, _: &(), _: f64) -> OMatrix<f64, N, N> {
        let mut j = self.f.clone();
        for i in 0..x.nrows() {
            j[(i, i)] += EPS * x[i].cos();
        }
        j
    }
}

/// h(x) = H x + ε sin(H x), noise R.
#[derive(Clone, Debug)]
struct SineMeasurement<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    h: OMatrix<f64, M, N>,
    r: OMatrix<f64, M, M>,
    /// As [`SineProcess::in_place`].
    in_place: bool,
}

impl<N: Dim, M: Dim> MeasurementModel<f64, N, M> for SineMeasurement<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measure(&self, x: &OVector<f64, N>) -> OVector<f64, M> {
        let mut y = &self.h * x;
        y.apply(|v| *v += EPS * v.sin());
        y
    }

    fn measurement_noise(&self, _: &OVector<f64, N>) -> OMatrix<f64, M, M> {
        self.r.clone()
    }

    fn in_place(&self) -> Option<&dyn InPlace<f64, N, M>> {
        self.in_place.then_some(self as &dyn InPlace<f64, N, M>)
    }
}

/// H x + ε sin(H x), R, a − b and the Jacobian written into the filter's buffers.
impl<N: Dim, M: Dim> InPlace<f64, N, M> for SineMeasurement<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn value_into(&self, x: &OVector<f64, N>, _: &(), _: f64, out: &mut OVector<f64, M>) {
        product_into(out, &self.h, x);
        out.apply(|v| *v += EPS * v.sin());
    }

    fn noise_into(&self, _: &OVector<f64, N>, _: &(), _: f64, out: &mut OMatrix<f64, M, M>) {
        assign(out, &self.r);
    }

    /// Row i of H scaled by 1 + ε cos((H x)ᵢ), with (H x)ᵢ as a row-times-vector dot product
    /// (no m-vector of scratch; the order of the sum differs from `measurement_jacobian`'s
    /// only by rounding).
    fn jacobian_into(&self, x: &OVector<f64, N>, _: &(), _: f64, out: &mut OMatrix<f64, M, N>) {
        assign(out, &self.h);
        for i in 0..self.h.nrows() {
            let s = 1.0 + EPS * self.h.row(i).tr_dot(x).cos();
            out.row_mut(i).scale_mut(s);
        }
    }

    /// Never asked: the model has no Hessian traits.
    fn hessian_into<'o>(
        &self,
        _: &OVector<f64, N>,
        _: &(),
        _: f64,
        _: usize,
        _: &'o mut OMatrix<f64, N, N>,
    ) -> Option<&'o mut OMatrix<f64, N, N>> {
        None
    }
}

impl<N: Dim, M: Dim> MeasurementJacobian<f64, N, M> for SineMeasurement<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn measurement_jacobian(&self, x: &OVector<f64, N>) -> OMatrix<f64, M, N> {
        let hx = &self.h * x;
        let mut j = self.h.clone();
        for i in 0..hx.nrows() {
            let s = 1.0 + EPS * hx[i].cos();
            j.row_mut(i).scale_mut(s);
        }
        j
    }
}

/// The estim models and measurements of a [`Problem`] at dimension types (N, M): `Dyn` or
/// `Const`.
struct Models<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U0>,
{
    linear_process: LinearProcess<f64, N, U0>,
    linear_measurement: LinearMeasurement<f64, N, M>,
    sine_process: SineProcess<N>,
    sine_measurement: SineMeasurement<N, M>,
    z_linear: Vec<OVector<f64, M>>,
    z_sine: Vec<OVector<f64, M>>,
    prior: Gaussian<f64, N>,
}

impl<N: Dim, M: Dim> Models<N, M>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U0>,
{
    fn new(p: &Problem, n: N, m: M) -> Self {
        assert_eq!((n.value(), m.value()), (p.n, p.m), "dimension types");
        let vecs = |zs: &[DVector<f64>]| {
            zs.iter()
                .map(|z| OVector::<f64, M>::from_column_slice_generic(m, Const::<1>, z.as_slice()))
                .collect()
        };
        let f = OMatrix::<f64, N, N>::from_column_slice_generic(n, n, p.f.as_slice());
        let h = OMatrix::<f64, M, N>::from_column_slice_generic(m, n, p.h.as_slice());
        let q = OMatrix::<f64, N, N>::from_column_slice_generic(n, n, p.q.as_slice());
        let r = OMatrix::<f64, M, M>::from_column_slice_generic(m, m, p.r.as_slice());
        let in_place = std::env::var_os("DYNAMIC_BENCH_OWNED").is_none();
        Self {
            linear_process: LinearProcess {
                transition: f.clone(),
                input: OMatrix::zeros_generic(n, Const::<0>),
                noise: q.clone(),
            },
            linear_measurement: LinearMeasurement {
                observation: h.clone(),
                noise: r.clone(),
            },
            sine_process: SineProcess { f, q, in_place },
            sine_measurement: SineMeasurement { h, r, in_place },
            z_linear: vecs(&p.z_linear),
            z_sine: vecs(&p.z_sine),
            prior: Gaussian::new(
                OVector::zeros_generic(n, Const::<1>),
                OMatrix::identity_generic(n, n),
            )
            .expect("valid prior"),
        }
    }
}

/// The three filters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Kf,
    Ekf,
    Ukf,
}

impl Kind {
    const ALL: [Kind; 3] = [Kind::Kf, Kind::Ekf, Kind::Ukf];

    fn name(self) -> &'static str {
        match self {
            Kind::Kf => "kf",
            Kind::Ekf => "ekf",
            Kind::Ukf => "ukf",
        }
    }
}

/// One estim step: predict, then update; returns the NIS.
#[inline(always)]
fn estim_step<N, M, F, P, H>(
    filter: &mut F,
    process: &P,
    input: &P::Input,
    measurement: &H,
    z: &OVector<f64, M>,
    report: &mut UpdateReport<f64, M>,
) -> f64
where
    N: Dim,
    M: Dim,
    P: ProcessModel<f64, N>,
    H: MeasurementModel<f64, N, M>,
    F: Predict<f64, N, P> + Update<f64, N, M, H>,
    DefaultAllocator: Alloc<N, M>,
{
    filter.predict(process, input, DT).expect("estim predict");
    filter
        .update_into(measurement, z, report)
        .expect("estim update");
    report.nis
}

/// Runs `steps` estim steps of `kind` from the prior: (x, P, NIS of each step) as DMatrix.
fn estim_run<N: Dim, M: Dim>(
    kind: Kind,
    models: &Models<N, M>,
    steps: usize,
) -> (DVector<f64>, DMatrix<f64>, Vec<f64>)
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U0>,
{
    fn finish<N: Dim, E: Estimator<f64, N>>(f: &E) -> (DVector<f64>, DMatrix<f64>)
    where
        DefaultAllocator: Alloc<N>,
    {
        let (x, p) = (f.state(), f.covariance());
        (
            DVector::<f64>::from_column_slice_generic(
                Dyn(x.nrows()),
                estim_core::nalgebra::U1,
                x.as_slice(),
            ),
            DMatrix::<f64>::from_column_slice_generic(Dyn(p.nrows()), Dyn(p.ncols()), p.as_slice()),
        )
    }
    let m = models;
    let u = OVector::<f64, U0>::zeros();
    let mut report = UpdateReport::zeros(m.z_linear[0].shape_generic().0);
    let r = &mut report;
    let (x, p, nis) = match kind {
        Kind::Kf => {
            let mut f = KalmanFilter::new(m.prior.clone());
            let (pm, hm) = (&m.linear_process, &m.linear_measurement);
            let nis = (0..steps)
                .map(|k| estim_step(&mut f, pm, &u, hm, &m.z_linear[k], r))
                .collect();
            let (x, p) = finish(&f);
            (x, p, nis)
        }
        Kind::Ekf => {
            let mut f = Ekf::new(m.prior.clone());
            let (pm, hm) = (&m.sine_process, &m.sine_measurement);
            let nis = (0..steps)
                .map(|k| estim_step(&mut f, pm, &(), hm, &m.z_sine[k], r))
                .collect();
            let (x, p) = finish(&f);
            (x, p, nis)
        }
        Kind::Ukf => {
            let mut f = Ukf::new(m.prior.clone());
            let (pm, hm) = (&m.sine_process, &m.sine_measurement);
            let nis = (0..steps)
                .map(|k| estim_step(&mut f, pm, &(), hm, &m.z_sine[k], r))
                .collect();
            let (x, p) = finish(&f);
            (x, p, nis)
        }
    };
    (x, p, nis)
}

/// Registers the estim variant of `kind` as `name` in `group`.
fn bench_estim<N: Dim, M: Dim>(
    group: &mut Steps<'_, STEPS>,
    name: &str,
    kind: Kind,
    m: &Models<N, M>,
) where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U0>,
{
    let u = OVector::<f64, U0>::zeros();
    // One report for all the steps, made before timing.
    let mut report = UpdateReport::zeros(m.z_linear[0].shape_generic().0);
    let r = &mut report;
    match kind {
        Kind::Kf => {
            let (pm, hm, zs) = (&m.linear_process, &m.linear_measurement, &m.z_linear);
            group.bench(name, &KalmanFilter::new(m.prior.clone()), |f, i| {
                estim_step(f, black_box(pm), &u, black_box(hm), &zs[i], r)
            });
        }
        Kind::Ekf => {
            let (pm, hm, zs) = (&m.sine_process, &m.sine_measurement, &m.z_sine);
            group.bench(name, &Ekf::new(m.prior.clone()), |f, i| {
                estim_step(f, black_box(pm), &(), black_box(hm), &zs[i], r)
            });
        }
        Kind::Ukf => {
            let (pm, hm, zs) = (&m.sine_process, &m.sine_measurement, &m.z_sine);
            group.bench(name, &Ukf::new(m.prior.clone()), |f, i| {
                estim_step(f, black_box(pm), &(), black_box(hm), &zs[i], r)
            });
        }
    }
}

/// `Some(body)` with `models` bound to the static-size [`Models`] for n = 2, 4, 6, 12, 16, 24,
/// 50; `None` for the other sizes.
macro_rules! with_static_models {
    ($problem:expr, |$models:ident| $body:expr) => {
        match $problem.n {
            2 => {
                let $models = Models::new($problem, Const::<2>, Const::<1>);
                Some($body)
            }
            4 => {
                let $models = Models::new($problem, Const::<4>, Const::<2>);
                Some($body)
            }
            6 => {
                let $models = Models::new($problem, Const::<6>, Const::<3>);
                Some($body)
            }
            12 => {
                let $models = Models::new($problem, Const::<12>, Const::<6>);
                Some($body)
            }
            16 => {
                let $models = Models::new($problem, Const::<16>, Const::<8>);
                Some($body)
            }
            24 => {
                let $models = Models::new($problem, Const::<24>, Const::<12>);
                Some($body)
            }
            50 => {
                let $models = Models::new($problem, Const::<50>, Const::<25>);
                Some($body)
            }
            _ => None,
        }
    };
}

// ---------------------------------------------------------------------------------------------
// Baseline 1: nalgebra DMatrix operator formulas, allocating freely
// ---------------------------------------------------------------------------------------------

/// A hand-written filter's estimate (DMatrix).
#[derive(Clone, Debug)]
struct DmEstimate {
    x: DVector<f64>,
    p: DMatrix<f64>,
}

/// (M + Mᵀ)/2.
fn dm_symmetrized(a: DMatrix<f64>) -> DMatrix<f64> {
    (&a + a.transpose()) * 0.5
}

/// The update from ν, S (R included, symmetrised) and B = Pₓᵤᵀ; returns the NIS (and computes
/// ln p(z), which goes through `black_box`).
fn dm_kalman_update(e: &mut DmEstimate, nu: DVector<f64>, b: DMatrix<f64>, s: DMatrix<f64>) -> f64 {
    let chol = s.clone().cholesky().expect("S positive definite");
    let w = chol
        .l_dirty()
        .solve_lower_triangular(&nu)
        .expect("L invertible");
    let nis = w.norm_squared();
    let log_det = 2.0 * chol.l_dirty().diagonal().map(f64::ln).sum();
    black_box(-0.5 * (nis + log_det + nu.len() as f64 * (2.0 * PI).ln()));
    let mut kt = b.clone();
    chol.solve_mut(&mut kt);
    e.x += kt.transpose() * &nu;
    // X = (Kᵀ)ᵀ (−B); P⁺ = (P + X) + Xᵀ elementwise, then + (S Kᵀ)ᵀ Kᵀ, symmetrised.
    let x = kt.transpose() * -b;
    let mut p = &e.p + &x;
    p += x.transpose();
    p += (&s * &kt).transpose() * &kt;
    e.p = dm_symmetrized(p);
    nis
}

/// KF/EKF predict from x⁻ = f(x) and F = ∂f/∂x(x).
fn dm_linearized_predict(e: &mut DmEstimate, x: DVector<f64>, f: &DMatrix<f64>, q: &DMatrix<f64>) {
    let a = f * &e.p;
    e.p = dm_symmetrized(a * f.transpose() + q);
    e.x = x;
}

/// KF/EKF update from ẑ = h(x⁻) and H = ∂h/∂x(x⁻).
fn dm_linearized_update(
    e: &mut DmEstimate,
    z_hat: DVector<f64>,
    h: &DMatrix<f64>,
    r: &DMatrix<f64>,
    z: &DVector<f64>,
) -> f64 {
    let b = h * &e.p;
    let s = dm_symmetrized(&b * h.transpose() + r);
    dm_kalman_update(e, z - z_hat, b, s)
}

/// The unscented transform of g at (x, P): (mean, cov, B = Pₓᵤᵀ if `cross`).
fn dm_unscented(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    g: impl Fn(&DVector<f64>) -> DVector<f64>,
    cross: bool,
) -> (DVector<f64>, DMatrix<f64>, Option<DMatrix<f64>>) {
    let n = x.len();
    let c = ALPHA * ALPHA * (n as f64 + KAPPA);
    let l = p.clone().cholesky().expect("P positive definite").unpack() * c.sqrt();
    let y0 = g(x);
    let mut d_plus = DMatrix::zeros(y0.len(), n);
    let mut d_minus = DMatrix::zeros(y0.len(), n);
    for j in 0..n {
        d_plus.set_column(j, &(g(&(x + l.column(j))) - &y0));
        d_minus.set_column(j, &(g(&(x - l.column(j))) - &y0));
    }
    let w = 1.0 / (2.0 * c);
    let d_bar = (d_plus.column_sum() + d_minus.column_sum()) * w;
    let cov = (&d_plus * d_plus.transpose() + &d_minus * d_minus.transpose()) * w
        + &d_bar * d_bar.transpose() * (BETA - ALPHA * ALPHA);
    let b = cross.then(|| (&l * (d_plus - d_minus).transpose() * w).transpose());
    (y0 + d_bar, cov, b)
}

fn dm_kf_step(pr: &Problem, e: &mut DmEstimate, z: &DVector<f64>) -> f64 {
    dm_linearized_predict(e, &pr.f * &e.x, &pr.f, &pr.q);
    dm_linearized_update(e, &pr.h * &e.x, &pr.h, &pr.r, z)
}

fn dm_ekf_step(pr: &Problem, e: &mut DmEstimate, z: &DVector<f64>) -> f64 {
    let x = sine_process_value(&pr.f, &e.x);
    let f = sine_process_jacobian(&pr.f, &e.x);
    dm_linearized_predict(e, x, &f, &pr.q);
    let z_hat = sine_measurement_value(&pr.h, &e.x);
    let h = sine_measurement_jacobian(&pr.h, &e.x);
    dm_linearized_update(e, z_hat, &h, &pr.r, z)
}

fn dm_ukf_step(pr: &Problem, e: &mut DmEstimate, z: &DVector<f64>) -> f64 {
    let (x, cov, _) = dm_unscented(&e.x, &e.p, |x| sine_process_value(&pr.f, x), false);
    e.x = x;
    e.p = dm_symmetrized(cov + &pr.q);
    let (z_hat, cov, b) = dm_unscented(&e.x, &e.p, |x| sine_measurement_value(&pr.h, x), true);
    let s = dm_symmetrized(cov + &pr.r);
    dm_kalman_update(e, z - z_hat, b.expect("cross-covariance"), s)
}

fn dm_step(kind: Kind, pr: &Problem, e: &mut DmEstimate, i: usize) -> f64 {
    match kind {
        Kind::Kf => dm_kf_step(pr, e, &pr.z_linear[i]),
        Kind::Ekf => dm_ekf_step(pr, e, &pr.z_sine[i]),
        Kind::Ukf => dm_ukf_step(pr, e, &pr.z_sine[i]),
    }
}

fn dm_prior(n: usize) -> DmEstimate {
    DmEstimate {
        x: DVector::zeros(n),
        p: DMatrix::identity(n, n),
    }
}

// ---------------------------------------------------------------------------------------------
// Baseline 1b: nalgebra DMatrix, every buffer allocated once
// ---------------------------------------------------------------------------------------------

/// A model function for the preallocated `DMatrix` baseline: writes into given outputs.
trait PaFunction {
    /// out = g(x).
    fn eval(&self, x: &DVector<f64>, out: DVectorViewMut<'_, f64>);
    /// ∂g/∂x at x, in `buf` or borrowed from the model (constant Jacobians are not copied).
    fn jacobian<'a>(&'a self, x: &DVector<f64>, buf: &'a mut DMatrix<f64>) -> &'a DMatrix<f64>;
}

/// g(x) = A x.
struct PaLinear<'a>(&'a DMatrix<f64>);

impl PaFunction for PaLinear<'_> {
    fn eval(&self, x: &DVector<f64>, mut out: DVectorViewMut<'_, f64>) {
        self.0.mul_to(x, &mut out);
    }

    fn jacobian<'a>(&'a self, _: &DVector<f64>, _: &'a mut DMatrix<f64>) -> &'a DMatrix<f64> {
        self.0
    }
}

/// g(x) = F x + ε sin x.
struct PaSineProcess<'a>(&'a DMatrix<f64>);

impl PaFunction for PaSineProcess<'_> {
    fn eval(&self, x: &DVector<f64>, mut out: DVectorViewMut<'_, f64>) {
        self.0.mul_to(x, &mut out);
        out.zip_apply(x, |yi, xi| *yi += EPS * xi.sin());
    }

    fn jacobian<'a>(&'a self, x: &DVector<f64>, buf: &'a mut DMatrix<f64>) -> &'a DMatrix<f64> {
        buf.copy_from(self.0);
        for i in 0..x.len() {
            buf[(i, i)] += EPS * x[i].cos();
        }
        buf
    }
}

/// g(x) = H x + ε sin(H x).
struct PaSineMeasurement<'a>(&'a DMatrix<f64>);

impl PaFunction for PaSineMeasurement<'_> {
    fn eval(&self, x: &DVector<f64>, mut out: DVectorViewMut<'_, f64>) {
        self.0.mul_to(x, &mut out);
        out.apply(|v| *v += EPS * v.sin());
    }

    /// Row i of H scaled by 1 + ε cos((H x)ᵢ) (the dot product per row: no scratch).
    fn jacobian<'a>(&'a self, x: &DVector<f64>, buf: &'a mut DMatrix<f64>) -> &'a DMatrix<f64> {
        buf.copy_from(self.0);
        for i in 0..self.0.nrows() {
            let s = 1.0 + EPS * self.0.row(i).tr_dot(x).cos();
            buf.row_mut(i).scale_mut(s);
        }
        buf
    }
}

/// Every buffer of the preallocated `DMatrix` steps, allocated once.
#[derive(Clone)]
struct PaWork {
    /// x⁻ while P⁻ is computed from x (n).
    x_pred: DVector<f64>,
    /// ∂f/∂x (n × n) and its transpose.
    jf: DMatrix<f64>,
    jft: DMatrix<f64>,
    /// ∂h/∂x (m × n) and its transpose.
    jh: DMatrix<f64>,
    jht: DMatrix<f64>,
    /// F P (n × n).
    a: DMatrix<f64>,
    /// ẑ (m).
    z_hat: DVector<f64>,
    /// B = H P⁻ or Pₓᵤᵀ (m × n).
    b: DMatrix<f64>,
    /// S (m × m) and its factor L (lower triangle).
    s: DMatrix<f64>,
    l: DMatrix<f64>,
    /// ν, L⁻¹ ν (m).
    nu: DVector<f64>,
    w: DVector<f64>,
    /// Kᵀ and S Kᵀ (m × n).
    kt: DMatrix<f64>,
    skt: DMatrix<f64>,
    /// X = (Kᵀ)ᵀ (−B) (n × n).
    t: DMatrix<f64>,
    ut_process: PaUnscented,
    ut_measurement: PaUnscented,
}

/// Buffers of one unscented transform from dimension n to dimension k.
#[derive(Clone)]
struct PaUnscented {
    /// √c L (n × n, upper triangle zero) and its transpose.
    l: DMatrix<f64>,
    lt: DMatrix<f64>,
    /// A sigma point (n).
    sigma: DVector<f64>,
    /// y₀ (k).
    y0: DVector<f64>,
    /// [D₊ D₋] (k × 2n) and its transpose.
    d: DMatrix<f64>,
    dt: DMatrix<f64>,
    /// d̄ (k).
    d_bar: DVector<f64>,
    /// The output covariance (k × k).
    cov: DMatrix<f64>,
    /// D₊ − D₋ (k × n).
    diff: DMatrix<f64>,
}

impl PaUnscented {
    fn new(n: usize, k: usize) -> Self {
        Self {
            l: DMatrix::zeros(n, n),
            lt: DMatrix::zeros(n, n),
            sigma: DVector::zeros(n),
            y0: DVector::zeros(k),
            d: DMatrix::zeros(k, 2 * n),
            dt: DMatrix::zeros(2 * n, k),
            d_bar: DVector::zeros(k),
            cov: DMatrix::zeros(k, k),
            diff: DMatrix::zeros(k, n),
        }
    }
}

impl PaWork {
    fn new(n: usize, m: usize) -> Self {
        Self {
            x_pred: DVector::zeros(n),
            jf: DMatrix::zeros(n, n),
            jft: DMatrix::zeros(n, n),
            jh: DMatrix::zeros(m, n),
            jht: DMatrix::zeros(n, m),
            a: DMatrix::zeros(n, n),
            z_hat: DVector::zeros(m),
            b: DMatrix::zeros(m, n),
            s: DMatrix::zeros(m, m),
            l: DMatrix::zeros(m, m),
            nu: DVector::zeros(m),
            w: DVector::zeros(m),
            kt: DMatrix::zeros(m, n),
            skt: DMatrix::zeros(m, n),
            t: DMatrix::zeros(n, n),
            ut_process: PaUnscented::new(n, n),
            ut_measurement: PaUnscented::new(n, m),
        }
    }
}

/// A ← (A + Aᵀ)/2 in place.
fn pa_symmetrize(a: &mut DMatrix<f64>) {
    for j in 0..a.ncols() {
        for i in (j + 1)..a.nrows() {
            let v = (a[(i, j)] + a[(j, i)]) * 0.5;
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
}

/// `a` ← its lower Cholesky factor, in place (nalgebra's `Cholesky` takes the matrix by value
/// and gives the same storage back: no allocation).
fn pa_cholesky(a: &mut DMatrix<f64>) {
    let owned = std::mem::replace(a, DMatrix::zeros(0, 0));
    *a = owned.cholesky().expect("positive definite").unpack_dirty();
}

/// The update from ws.z_hat, ws.b (B) and ws.s (S, R included, symmetrised); returns the NIS
/// (ln p(z) goes through `black_box`).
fn pa_kalman_update(e: &mut DmEstimate, ws: &mut PaWork, z: &DVector<f64>) -> f64 {
    let (n, m) = (e.x.len(), z.len());
    ws.l.copy_from(&ws.s);
    pa_cholesky(&mut ws.l);
    ws.nu.copy_from(z);
    ws.nu -= &ws.z_hat;
    ws.w.copy_from(&ws.nu);
    ws.l.solve_lower_triangular_unchecked_mut(&mut ws.w);
    let nis = ws.w.norm_squared();
    let log_det = 2.0 * (0..m).map(|i| ws.l[(i, i)].ln()).sum::<f64>();
    black_box(-0.5 * (nis + log_det + m as f64 * (2.0 * PI).ln()));
    ws.kt.copy_from(&ws.b);
    ws.l.solve_lower_triangular_unchecked_mut(&mut ws.kt);
    ws.l.tr_solve_lower_triangular_unchecked_mut(&mut ws.kt);
    e.x.gemv_tr(1.0, &ws.kt, &ws.nu, 1.0);
    // X = (Kᵀ)ᵀ (−B); P⁺ = (P + X) + Xᵀ elementwise, then + (S Kᵀ)ᵀ Kᵀ, symmetrised.
    ws.t.gemm_tr(-1.0, &ws.kt, &ws.b, 0.0);
    for j in 0..n {
        for i in 0..n {
            e.p[(i, j)] = (e.p[(i, j)] + ws.t[(i, j)]) + ws.t[(j, i)];
        }
    }
    ws.s.mul_to(&ws.kt, &mut ws.skt);
    e.p.gemm_tr(1.0, &ws.skt, &ws.kt, 1.0);
    pa_symmetrize(&mut e.p);
    nis
}

/// KF/EKF predict.
fn pa_linearized_predict(
    e: &mut DmEstimate,
    ws: &mut PaWork,
    f: &impl PaFunction,
    q: &DMatrix<f64>,
) {
    f.eval(&e.x, ws.x_pred.column_mut(0));
    let jf = f.jacobian(&e.x, &mut ws.jf);
    jf.mul_to(&e.p, &mut ws.a);
    jf.transpose_to(&mut ws.jft);
    e.p.copy_from(q);
    e.p.gemm(1.0, &ws.a, &ws.jft, 1.0);
    pa_symmetrize(&mut e.p);
    e.x.copy_from(&ws.x_pred);
}

/// KF/EKF update.
fn pa_linearized_update(
    e: &mut DmEstimate,
    ws: &mut PaWork,
    h: &impl PaFunction,
    r: &DMatrix<f64>,
    z: &DVector<f64>,
) -> f64 {
    h.eval(&e.x, ws.z_hat.column_mut(0));
    let jh = h.jacobian(&e.x, &mut ws.jh);
    jh.mul_to(&e.p, &mut ws.b);
    jh.transpose_to(&mut ws.jht);
    ws.s.copy_from(r);
    ws.s.gemm(1.0, &ws.b, &ws.jht, 1.0);
    pa_symmetrize(&mut ws.s);
    pa_kalman_update(e, ws, z)
}

/// The unscented transform of g at (x, P) into `u` (mean in `u.y0`, covariance in `u.cov`);
/// with `b`, also B = Pₓᵤᵀ = w (D₊ − D₋) Lᵀ.
fn pa_unscented(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    g: &impl PaFunction,
    u: &mut PaUnscented,
    b: Option<&mut DMatrix<f64>>,
) {
    let n = x.len();
    let c = ALPHA * ALPHA * (n as f64 + KAPPA);
    u.l.copy_from(p);
    pa_cholesky(&mut u.l);
    let sc = c.sqrt();
    for j in 0..n {
        for i in 0..j {
            u.l[(i, j)] = 0.0;
        }
        for i in j..n {
            u.l[(i, j)] *= sc;
        }
    }
    g.eval(x, u.y0.column_mut(0));
    for j in 0..n {
        for (col, sign) in [(j, 1.0), (n + j, -1.0)] {
            u.sigma.copy_from(x);
            u.sigma.axpy(sign, &u.l.column(j), 1.0);
            g.eval(&u.sigma, u.d.column_mut(col));
            u.d.column_mut(col).axpy(-1.0, &u.y0, 1.0);
        }
    }
    let w = 1.0 / (2.0 * c);
    u.d_bar.fill(0.0);
    for j in 0..2 * n {
        u.d_bar += u.d.column(j);
    }
    u.d_bar *= w;
    u.d.transpose_to(&mut u.dt);
    u.cov.gemm(w, &u.d, &u.dt, 0.0);
    u.cov.ger(BETA - ALPHA * ALPHA, &u.d_bar, &u.d_bar, 1.0);
    u.y0 += &u.d_bar;
    if let Some(b) = b {
        u.diff.copy_from(&u.d.columns(0, n));
        u.diff -= &u.d.columns(n, n);
        u.l.transpose_to(&mut u.lt);
        b.gemm(w, &u.diff, &u.lt, 0.0);
    }
}

fn pa_ukf_step(pr: &Problem, e: &mut DmEstimate, ws: &mut PaWork, z: &DVector<f64>) -> f64 {
    let u = &mut ws.ut_process;
    pa_unscented(&e.x, &e.p, &PaSineProcess(&pr.f), u, None);
    e.x.copy_from(&u.y0);
    e.p.copy_from(&u.cov);
    e.p += &pr.q;
    pa_symmetrize(&mut e.p);
    let u = &mut ws.ut_measurement;
    pa_unscented(&e.x, &e.p, &PaSineMeasurement(&pr.h), u, Some(&mut ws.b));
    ws.z_hat.copy_from(&u.y0);
    ws.s.copy_from(&u.cov);
    ws.s += &pr.r;
    pa_symmetrize(&mut ws.s);
    pa_kalman_update(e, ws, z)
}

fn pa_step(kind: Kind, pr: &Problem, e: &mut DmEstimate, ws: &mut PaWork, i: usize) -> f64 {
    match kind {
        Kind::Kf => {
            pa_linearized_predict(e, ws, &PaLinear(&pr.f), &pr.q);
            pa_linearized_update(e, ws, &PaLinear(&pr.h), &pr.r, &pr.z_linear[i])
        }
        Kind::Ekf => {
            pa_linearized_predict(e, ws, &PaSineProcess(&pr.f), &pr.q);
            pa_linearized_update(e, ws, &PaSineMeasurement(&pr.h), &pr.r, &pr.z_sine[i])
        }
        Kind::Ukf => pa_ukf_step(pr, e, ws, &pr.z_sine[i]),
    }
}

// ---------------------------------------------------------------------------------------------
// Baseline 2: faer, preallocated buffers
// ---------------------------------------------------------------------------------------------

/// A hand-written filter's estimate (faer).
#[derive(Clone, Debug)]
struct FaerEstimate {
    x: Col<f64>,
    p: Mat<f64>,
}

fn faer_mat(a: &DMatrix<f64>) -> Mat<f64> {
    Mat::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)])
}

fn faer_col(a: &DVector<f64>) -> Col<f64> {
    Col::from_fn(a.len(), |i| a[i])
}

fn faer_prior(n: usize) -> FaerEstimate {
    FaerEstimate {
        x: Col::zeros(n),
        p: Mat::identity(n, n),
    }
}

/// A ← (A + Aᵀ)/2.
fn faer_symmetrize(a: &mut Mat<f64>) {
    for j in 0..a.ncols() {
        for i in (j + 1)..a.nrows() {
            let v = (a[(i, j)] + a[(j, i)]) * 0.5;
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
}

/// Output buffers of a Jacobian: the matrix and an m-vector of scratch.
struct JacobianBuffer {
    mat: Mat<f64>,
    tmp: Col<f64>,
}

impl JacobianBuffer {
    fn new(rows: usize, cols: usize) -> Self {
        Self {
            mat: Mat::zeros(rows, cols),
            tmp: Col::zeros(rows),
        }
    }
}

/// A model function for the faer baseline: writes into preallocated outputs.
trait FaerFunction {
    /// out = g(x).
    fn eval(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>);
    /// ∂g/∂x at x, in `buf` or borrowed from the model (constant Jacobians are not copied).
    fn jacobian<'a>(&'a self, x: ColRef<'_, f64>, buf: &'a mut JacobianBuffer) -> MatRef<'a, f64>;
}

/// g(x) = A x.
struct FaerLinear {
    a: Mat<f64>,
}

impl FaerFunction for FaerLinear {
    fn eval(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) {
        matmul(out, Accum::Replace, &self.a, x, 1.0, Par::Seq);
    }

    fn jacobian<'a>(&'a self, _: ColRef<'_, f64>, _: &'a mut JacobianBuffer) -> MatRef<'a, f64> {
        self.a.as_ref()
    }
}

/// g(x) = F x + ε sin x.
struct FaerSineProcess {
    f: Mat<f64>,
}

impl FaerFunction for FaerSineProcess {
    fn eval(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) {
        matmul(out.rb_mut(), Accum::Replace, &self.f, x, 1.0, Par::Seq);
        for i in 0..x.nrows() {
            out[i] += EPS * x[i].sin();
        }
    }

    fn jacobian<'a>(&'a self, x: ColRef<'_, f64>, buf: &'a mut JacobianBuffer) -> MatRef<'a, f64> {
        buf.mat.copy_from(&self.f);
        for i in 0..x.nrows() {
            buf.mat[(i, i)] += EPS * x[i].cos();
        }
        buf.mat.as_ref()
    }
}

/// g(x) = H x + ε sin(H x).
struct FaerSineMeasurement {
    h: Mat<f64>,
}

impl FaerFunction for FaerSineMeasurement {
    fn eval(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) {
        matmul(out.rb_mut(), Accum::Replace, &self.h, x, 1.0, Par::Seq);
        for i in 0..out.nrows() {
            out[i] += EPS * out[i].sin();
        }
    }

    fn jacobian<'a>(&'a self, x: ColRef<'_, f64>, buf: &'a mut JacobianBuffer) -> MatRef<'a, f64> {
        matmul(&mut buf.tmp, Accum::Replace, &self.h, x, 1.0, Par::Seq);
        let (rows, cols) = (self.h.nrows(), self.h.ncols());
        for i in 0..rows {
            buf.tmp[i] = 1.0 + EPS * buf.tmp[i].cos();
        }
        for j in 0..cols {
            for i in 0..rows {
                buf.mat[(i, j)] = buf.tmp[i] * self.h[(i, j)];
            }
        }
        buf.mat.as_ref()
    }
}

/// The faer models of a [`Problem`].
struct FaerModels {
    linear_process: FaerLinear,
    linear_measurement: FaerLinear,
    sine_process: FaerSineProcess,
    sine_measurement: FaerSineMeasurement,
    q: Mat<f64>,
    r: Mat<f64>,
    z_linear: Vec<Col<f64>>,
    z_sine: Vec<Col<f64>>,
}

impl FaerModels {
    fn new(p: &Problem) -> Self {
        Self {
            linear_process: FaerLinear { a: faer_mat(&p.f) },
            linear_measurement: FaerLinear { a: faer_mat(&p.h) },
            sine_process: FaerSineProcess { f: faer_mat(&p.f) },
            sine_measurement: FaerSineMeasurement { h: faer_mat(&p.h) },
            q: faer_mat(&p.q),
            r: faer_mat(&p.r),
            z_linear: p.z_linear.iter().map(faer_col).collect(),
            z_sine: p.z_sine.iter().map(faer_col).collect(),
        }
    }
}

/// Buffers of one unscented transform from dimension n to dimension k.
struct UnscentedBuffers {
    /// √c L, lower triangular (n × n).
    l: Mat<f64>,
    /// A sigma point (n).
    sigma: Col<f64>,
    /// y₀ = g(x) (k).
    y0: Col<f64>,
    /// [D₊ D₋] (k × 2n).
    d: Mat<f64>,
    /// d̄ (k).
    d_bar: Col<f64>,
    /// The output covariance (k × k).
    cov: Mat<f64>,
    /// D₊ − D₋ (k × n), update only.
    diff: Mat<f64>,
}

impl UnscentedBuffers {
    fn new(n: usize, k: usize) -> Self {
        Self {
            l: Mat::zeros(n, n),
            sigma: Col::zeros(n),
            y0: Col::zeros(k),
            d: Mat::zeros(k, 2 * n),
            d_bar: Col::zeros(k),
            cov: Mat::zeros(k, k),
            diff: Mat::zeros(k, n),
        }
    }
}

/// Every buffer of the faer steps, allocated once.
struct FaerWork {
    /// x⁻ while P⁻ is computed from x (n).
    x_pred: Col<f64>,
    jf: JacobianBuffer,
    jh: JacobianBuffer,
    /// F P (n × n).
    a: Mat<f64>,
    /// ẑ (m).
    z_hat: Col<f64>,
    /// B = H P⁻ or Pₓᵤᵀ (m × n).
    b: Mat<f64>,
    /// S (m × m).
    s: Mat<f64>,
    /// L, in the lower triangle (m × m).
    l: Mat<f64>,
    /// ν (m).
    nu: Col<f64>,
    /// L⁻¹ ν (m).
    w: Col<f64>,
    /// Kᵀ (m × n).
    kt: Mat<f64>,
    /// S Kᵀ (m × n).
    skt: Mat<f64>,
    /// X = (Kᵀ)ᵀ (−B) = −K Pₓᵤᵀ (n × n).
    t: Mat<f64>,
    ut_process: UnscentedBuffers,
    ut_measurement: UnscentedBuffers,
    /// Cholesky scratch for dimension max(n, m).
    mem: MemBuffer,
}

impl FaerWork {
    fn new(n: usize, m: usize) -> Self {
        Self {
            x_pred: Col::zeros(n),
            jf: JacobianBuffer::new(n, n),
            jh: JacobianBuffer::new(m, n),
            a: Mat::zeros(n, n),
            z_hat: Col::zeros(m),
            b: Mat::zeros(m, n),
            s: Mat::zeros(m, m),
            l: Mat::zeros(m, m),
            nu: Col::zeros(m),
            w: Col::zeros(m),
            kt: Mat::zeros(m, n),
            skt: Mat::zeros(m, n),
            t: Mat::zeros(n, n),
            ut_process: UnscentedBuffers::new(n, n),
            ut_measurement: UnscentedBuffers::new(n, m),
            mem: MemBuffer::new(cholesky_in_place_scratch::<f64>(
                n.max(m),
                Par::Seq,
                Default::default(),
            )),
        }
    }
}

/// In-place lower Cholesky factor of `a` (upper triangle left as it was).
fn faer_cholesky(a: MatMut<'_, f64>, mem: &mut MemBuffer) {
    cholesky_in_place(
        a,
        LltRegularization::default(),
        Par::Seq,
        MemStack::new(mem),
        Default::default(),
    )
    .expect("positive definite");
}

/// The update from ws.z_hat (ẑ), ws.b (B) and ws.s (S, R included, symmetrised); returns the
/// NIS (ln p(z) goes through `black_box`).
fn faer_kalman_update(e: &mut FaerEstimate, ws: &mut FaerWork, z: &Col<f64>) -> f64 {
    let (n, m) = (e.x.nrows(), z.nrows());
    ws.l.copy_from(&ws.s);
    faer_cholesky(ws.l.as_mut(), &mut ws.mem);
    for i in 0..m {
        ws.nu[i] = z[i] - ws.z_hat[i];
    }
    ws.w.copy_from(&ws.nu);
    solve_lower_triangular_in_place(ws.l.as_ref(), ws.w.as_mat_mut(), Par::Seq);
    let mut nis = 0.0;
    let mut log_det = 0.0;
    for i in 0..m {
        nis += ws.w[i] * ws.w[i];
        log_det += ws.l[(i, i)].ln();
    }
    log_det *= 2.0;
    black_box(-0.5 * (nis + log_det + m as f64 * (2.0 * PI).ln()));
    ws.kt.copy_from(&ws.b);
    solve_lower_triangular_in_place(ws.l.as_ref(), ws.kt.as_mut(), Par::Seq);
    solve_upper_triangular_in_place(ws.l.transpose(), ws.kt.as_mut(), Par::Seq);
    matmul(
        &mut e.x,
        Accum::Add,
        ws.kt.transpose(),
        &ws.nu,
        1.0,
        Par::Seq,
    );
    // X = (Kᵀ)ᵀ (−B) (the −1 is exact); P⁺ = (P + X) + Xᵀ elementwise, then + (S Kᵀ)ᵀ Kᵀ,
    // symmetrised.
    matmul(
        &mut ws.t,
        Accum::Replace,
        ws.kt.transpose(),
        &ws.b,
        -1.0,
        Par::Seq,
    );
    for j in 0..n {
        for i in 0..n {
            e.p[(i, j)] = (e.p[(i, j)] + ws.t[(i, j)]) + ws.t[(j, i)];
        }
    }
    matmul(&mut ws.skt, Accum::Replace, &ws.s, &ws.kt, 1.0, Par::Seq);
    matmul(
        &mut e.p,
        Accum::Add,
        ws.skt.transpose(),
        &ws.kt,
        1.0,
        Par::Seq,
    );
    faer_symmetrize(&mut e.p);
    nis
}

/// KF/EKF predict.
fn faer_linearized_predict(
    e: &mut FaerEstimate,
    ws: &mut FaerWork,
    f: &impl FaerFunction,
    q: &Mat<f64>,
) {
    f.eval(e.x.as_ref(), ws.x_pred.as_mut());
    let jf = f.jacobian(e.x.as_ref(), &mut ws.jf);
    matmul(&mut ws.a, Accum::Replace, jf, &e.p, 1.0, Par::Seq);
    e.p.copy_from(q);
    matmul(&mut e.p, Accum::Add, &ws.a, jf.transpose(), 1.0, Par::Seq);
    faer_symmetrize(&mut e.p);
    e.x.copy_from(&ws.x_pred);
}

/// KF/EKF update.
fn faer_linearized_update(
    e: &mut FaerEstimate,
    ws: &mut FaerWork,
    h: &impl FaerFunction,
    r: &Mat<f64>,
    z: &Col<f64>,
) -> f64 {
    h.eval(e.x.as_ref(), ws.z_hat.as_mut());
    let jh = h.jacobian(e.x.as_ref(), &mut ws.jh);
    matmul(&mut ws.b, Accum::Replace, jh, &e.p, 1.0, Par::Seq);
    ws.s.copy_from(r);
    matmul(&mut ws.s, Accum::Add, &ws.b, jh.transpose(), 1.0, Par::Seq);
    faer_symmetrize(&mut ws.s);
    faer_kalman_update(e, ws, z)
}

/// The unscented transform of g at (x, P) into `u` (mean = y₀ + d̄ left in `u.y0`, covariance
/// in `u.cov`); with `b`, also B = Pₓᵤᵀ = w (D₊ − D₋) Lᵀ.
fn faer_unscented(
    x: ColRef<'_, f64>,
    p: MatRef<'_, f64>,
    g: &impl FaerFunction,
    u: &mut UnscentedBuffers,
    mem: &mut MemBuffer,
    b: Option<&mut Mat<f64>>,
) {
    let n = x.nrows();
    let k = u.y0.nrows();
    let c = ALPHA * ALPHA * (n as f64 + KAPPA);
    u.l.copy_from(p);
    faer_cholesky(u.l.as_mut(), mem);
    let sc = c.sqrt();
    for j in 0..n {
        for i in 0..j {
            u.l[(i, j)] = 0.0;
        }
        for i in j..n {
            u.l[(i, j)] *= sc;
        }
    }
    g.eval(x, u.y0.as_mut());
    for j in 0..n {
        for (col, sign) in [(j, 1.0), (n + j, -1.0)] {
            for i in 0..n {
                u.sigma[i] = x[i] + sign * u.l[(i, j)];
            }
            g.eval(u.sigma.as_ref(), u.d.col_mut(col));
            for i in 0..k {
                u.d[(i, col)] -= u.y0[i];
            }
        }
    }
    let w = 1.0 / (2.0 * c);
    u.d_bar.fill(0.0);
    for j in 0..2 * n {
        for i in 0..k {
            u.d_bar[i] += u.d[(i, j)];
        }
    }
    for i in 0..k {
        u.d_bar[i] *= w;
    }
    matmul(
        &mut u.cov,
        Accum::Replace,
        &u.d,
        u.d.transpose(),
        w,
        Par::Seq,
    );
    let beta = BETA - ALPHA * ALPHA;
    for j in 0..k {
        for i in 0..k {
            u.cov[(i, j)] += beta * u.d_bar[i] * u.d_bar[j];
        }
    }
    for i in 0..k {
        u.y0[i] += u.d_bar[i];
    }
    if let Some(b) = b {
        for j in 0..n {
            for i in 0..k {
                u.diff[(i, j)] = u.d[(i, j)] - u.d[(i, n + j)];
            }
        }
        matmul(b, Accum::Replace, &u.diff, u.l.transpose(), w, Par::Seq);
    }
}

fn faer_ukf_step(e: &mut FaerEstimate, ws: &mut FaerWork, fm: &FaerModels, z: &Col<f64>) -> f64 {
    let n = e.x.nrows();
    let u = &mut ws.ut_process;
    faer_unscented(
        e.x.as_ref(),
        e.p.as_ref(),
        &fm.sine_process,
        u,
        &mut ws.mem,
        None,
    );
    e.x.copy_from(&u.y0);
    for j in 0..n {
        for i in 0..n {
            e.p[(i, j)] = u.cov[(i, j)] + fm.q[(i, j)];
        }
    }
    faer_symmetrize(&mut e.p);
    let u = &mut ws.ut_measurement;
    faer_unscented(
        e.x.as_ref(),
        e.p.as_ref(),
        &fm.sine_measurement,
        u,
        &mut ws.mem,
        Some(&mut ws.b),
    );
    let m = u.y0.nrows();
    ws.z_hat.copy_from(&u.y0);
    for j in 0..m {
        for i in 0..m {
            ws.s[(i, j)] = u.cov[(i, j)] + fm.r[(i, j)];
        }
    }
    faer_symmetrize(&mut ws.s);
    faer_kalman_update(e, ws, z)
}

fn faer_step(
    kind: Kind,
    fm: &FaerModels,
    e: &mut FaerEstimate,
    ws: &mut FaerWork,
    i: usize,
) -> f64 {
    match kind {
        Kind::Kf => {
            faer_linearized_predict(e, ws, &fm.linear_process, &fm.q);
            faer_linearized_update(e, ws, &fm.linear_measurement, &fm.r, &fm.z_linear[i])
        }
        Kind::Ekf => {
            faer_linearized_predict(e, ws, &fm.sine_process, &fm.q);
            faer_linearized_update(e, ws, &fm.sine_measurement, &fm.r, &fm.z_sine[i])
        }
        Kind::Ukf => faer_ukf_step(e, ws, fm, &fm.z_sine[i]),
    }
}

// ---------------------------------------------------------------------------------------------
// Correctness guard
// ---------------------------------------------------------------------------------------------

/// max |a − b| / max(1, max |b|).
fn rel_gap(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}

/// (x, P, NIS per step) of one variant after [`CHECK_STEPS`] steps, as DMatrix.
type Outcome = (DVector<f64>, DMatrix<f64>, Vec<f64>);

/// The largest gap between two outcomes (state, covariance, NIS).
fn outcome_gap(a: &Outcome, reference: &Outcome) -> f64 {
    let nis_gap =
        a.2.iter()
            .zip(&reference.2)
            .map(|(a, b)| (a - b).abs() / b.abs().max(1.0))
            .fold(0.0, f64::max);
    let x = |v: &DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
    rel_gap(&x(&a.0), &x(&reference.0))
        .max(rel_gap(&a.1, &reference.1))
        .max(nis_gap)
}

/// Runs every variant of `kind` for [`CHECK_STEPS`] steps from the prior and panics if any
/// differs from `dmatrix` by more than the tolerance.
fn check(kind: Kind, pr: &Problem, models: &Models<Dyn, Dyn>, fm: &FaerModels) {
    let (n, m) = (pr.n, pr.m);
    let mut dm = dm_prior(n);
    let dm_nis = (0..CHECK_STEPS)
        .map(|k| dm_step(kind, pr, &mut dm, k))
        .collect();
    let reference: Outcome = (dm.x, dm.p, dm_nis);

    let mut fe = faer_prior(n);
    let mut ws = FaerWork::new(n, m);
    let faer_nis = (0..CHECK_STEPS)
        .map(|k| faer_step(kind, fm, &mut fe, &mut ws, k))
        .collect();
    let faer: Outcome = (
        DVector::from_fn(n, |i, _| fe.x[i]),
        DMatrix::from_fn(n, n, |i, j| fe.p[(i, j)]),
        faer_nis,
    );

    let mut pa = dm_prior(n);
    let mut pws = PaWork::new(n, m);
    let pa_nis = (0..CHECK_STEPS)
        .map(|k| pa_step(kind, pr, &mut pa, &mut pws, k))
        .collect();
    let pa: Outcome = (pa.x, pa.p, pa_nis);

    let tolerance = TOLERANCE;
    let mut gaps = vec![
        (
            "estim",
            outcome_gap(&estim_run(kind, models, CHECK_STEPS), &reference),
        ),
        ("faer", outcome_gap(&faer, &reference)),
        ("dmatrix_prealloc", outcome_gap(&pa, &reference)),
    ];
    if let Some(gap) = with_static_models!(pr, |s| outcome_gap(
        &estim_run(kind, &s, CHECK_STEPS),
        &reference
    )) {
        gaps.push(("estim_static", gap));
    }
    let listed: Vec<String> = gaps.iter().map(|(v, g)| format!("{v} {g:.1e}")).collect();
    eprintln!(
        "check {}/n={n}: gap to dmatrix after {CHECK_STEPS} steps: {} (tolerance {tolerance:.1e})",
        kind.name(),
        listed.join(", ")
    );
    for (variant, gap) in gaps {
        assert!(
            gap < tolerance,
            "{}/n={n}: {variant} differs from dmatrix by {gap:e} (> {tolerance:e}) after \
             {CHECK_STEPS} steps: the implementations do not compute the same algebra",
            kind.name()
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Benchmarks
// ---------------------------------------------------------------------------------------------

/// The counted-mode variable of this bench (see [`common`]).
const COUNTED_VAR: &str = "DYNAMIC_BENCH_STEPS";

/// A group of this bench's steps ([`Steps`], reset every [`STEPS`] steps), with few, long
/// samples: the large sizes take milliseconds per step.
fn steps(c: &mut Criterion, name: String, n: usize) -> Steps<'_, STEPS> {
    let mut group = c.benchmark_group(&name);
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(2));
    if n >= 100 {
        group.sampling_mode(SamplingMode::Flat);
    }
    Steps::new(group, name, COUNTED_VAR)
}

fn dynamic(c: &mut Criterion) {
    // In counted mode, set up and check only the named (filter, n).
    let counted = counted_spec(COUNTED_VAR);
    let wanted = |kind: Kind, n: usize| match &counted {
        Some((id, _)) => id.starts_with(&format!("{}/n={n}/", kind.name())),
        None => true,
    };
    if let Some((id, _)) = &counted {
        assert!(
            SIZES
                .iter()
                .any(|&n| Kind::ALL.iter().any(|&k| wanted(k, n))),
            "DYNAMIC_BENCH_STEPS: no group matches {id:?}"
        );
    }
    for n in SIZES {
        if !Kind::ALL.iter().any(|&k| wanted(k, n)) {
            continue;
        }
        let problem = Problem::new(n);
        let models = Models::new(&problem, Dyn(n), Dyn(problem.m));
        let fm = FaerModels::new(&problem);
        for kind in Kind::ALL {
            if !wanted(kind, n) {
                continue;
            }
            check(kind, &problem, &models, &fm);
            let mut group = steps(c, format!("{}/n={n}", kind.name()), n);
            bench_estim(&mut group, "estim", kind, &models);
            with_static_models!(&problem, |s| bench_estim(
                &mut group,
                "estim_static",
                kind,
                &s
            ));
            let pr = &problem;
            group.bench("dmatrix", &dm_prior(n), |e, i| {
                dm_step(kind, black_box(pr), e, i)
            });
            let mut pws = PaWork::new(n, problem.m);
            group.bench("dmatrix_prealloc", &dm_prior(n), |e, i| {
                pa_step(kind, black_box(pr), e, &mut pws, i)
            });
            let mut ws = FaerWork::new(n, problem.m);
            let fm = &fm;
            group.bench("faer", &faer_prior(n), |e, i| {
                faer_step(kind, black_box(fm), e, &mut ws, i)
            });
            group.finish();
        }
    }
}

criterion_group!(benches, dynamic);
criterion_main!(benches);
