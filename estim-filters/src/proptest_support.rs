//! [proptest](https://docs.rs/proptest) strategies and assertions for estimation code
//! (feature `proptest-support`).
//!
//! - [`spd_matrix`]: symmetric positive-definite matrices with a bounded condition number,
//! - [`gaussian`]: Gaussians with such covariances,
//! - [`stable_linear_system`]: random stable linear-Gaussian systems (process, sensor, prior),
//! - [`vector`]: points to test at,
//! - [`assert_jacobian`], [`assert_derivatives`] and the model forms
//!   ([`assert_process_jacobian`], [`assert_measurement_derivatives`], ...): the
//!   [`estim_core::derivative`] checker as a `TestCaseResult`, so a wrong derivative fails the
//!   property (and proptest shrinks to a small failing point).
//!
//! Sizes are nalgebra dimension values: `U3` (or `Const::<3>`) for static sizes, `Dyn(5)` for
//! runtime ones.
//!
//! ```
//! use estim_core::nalgebra::U3;
//! use estim_filters::proptest_support::{spd_matrix, vector, assert_jacobian};
//! use proptest::prelude::*;
//! # use estim_core::{Differentiable, VectorFunction, nalgebra::{Matrix3, Vector3}};
//! # struct Square;
//! # impl VectorFunction<f64, U3, U3> for Square { fn eval(&self, x: &Vector3<f64>) -> Vector3<f64> { x.component_mul(x) } }
//! # impl Differentiable<f64, U3, U3> for Square { fn jacobian(&self, x: &Vector3<f64>) -> Matrix3<f64> { Matrix3::from_diagonal(&(x * 2.0)) } }
//!
//! proptest!(|(p in spd_matrix::<f64, _>(U3, 1e3))| {
//!     let eig = p.symmetric_eigenvalues();
//!     prop_assert!(eig.max() / eig.min() <= 1e3 * (1.0 + 1e-9));
//! });
//! proptest!(|(x in vector::<f64, _>(U3, 10.0))| {
//!     assert_jacobian(&Square, &x, 1e-6)?;
//! });
//! ```

use core::f64::consts::TAU;
use core::fmt;

use estim_core::derivative::{self, DerivativeReport};
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, OMatrix, OVector, U1, allocator::Allocator,
};
use estim_core::{
    Alloc, Differentiable, Gaussian, LinearMeasurement, LinearProcess, MeasurementHessian,
    MeasurementJacobian, ProcessHessian, ProcessJacobian, Real, TwiceDifferentiable, error::Result,
    scalar::real,
};
use proptest::collection::vec;
use proptest::prelude::*;
use proptest::test_runner::{TestCaseError, TestCaseResult};

/// A standard normal value from two uniforms (Box–Muller); shrinks towards 0.
pub fn standard_normal() -> impl Strategy<Value = f64> + Clone {
    (0.0..1.0f64, 0.0..1.0f64).prop_map(|(a, b)| (-2.0 * (1.0 - a).ln()).sqrt() * (TAU * b).cos())
}

fn normals(count: usize) -> impl Strategy<Value = Vec<f64>> + Clone {
    vec(standard_normal(), count)
}

/// A Haar-distributed orthogonal matrix: Q of the QR factorisation of a standard Gaussian
/// matrix (identity if that matrix is degenerate, as when proptest shrinks it to zero).
fn orthogonal(n: usize, entries: Vec<f64>) -> DMatrix<f64> {
    let a = DMatrix::from_vec(n, n, entries);
    let qr = a.clone().qr();
    // Fix the signs (R with a positive diagonal) so Q is Haar-distributed.
    let signs = DVector::from_fn(n, |i, _| if qr.r()[(i, i)] < 0.0 { -1.0 } else { 1.0 });
    let mut q = qr.q();
    for (j, s) in signs.iter().enumerate() {
        q.column_mut(j).scale_mut(*s);
    }
    let error = (q.transpose() * &q - DMatrix::identity(n, n)).amax();
    if error.is_finite() && error < 1e-10 {
        q
    } else {
        DMatrix::identity(n, n)
    }
}

/// Q diag(λ) Qᵀ with log-uniform λ in [1, κ], exactly symmetrised.
fn spd_from(n: usize, kappa: f64, q_entries: Vec<f64>, exponents: Vec<f64>) -> DMatrix<f64> {
    let q = orthogonal(n, q_entries);
    let lambda = DVector::from_iterator(n, exponents.iter().map(|u| kappa.powf(*u)));
    let a = &q * DMatrix::from_diagonal(&lambda) * q.transpose();
    (&a + a.transpose()) * 0.5
}

fn valid_condition(max_condition: f64) -> f64 {
    if max_condition.is_finite() && max_condition >= 1.0 {
        max_condition
    } else {
        1.0
    }
}

fn to_generic<T: Real, R: Dim, C: Dim>(rows: R, cols: C, m: &DMatrix<f64>) -> OMatrix<T, R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    OMatrix::<T, R, C>::from_fn_generic(rows, cols, |i, j| real(m[(i, j)]))
}

/// Symmetric positive-definite `dim × dim` matrices A = Q diag(λ) Qᵀ: Q a random orthogonal
/// matrix (QR of a Gaussian matrix, so Haar-distributed), eigenvalues λ log-uniform in
/// [1, `max_condition`]. So every matrix has eigenvalues in [1, κ] and condition number at
/// most κ = `max_condition` (values below 1 or not finite are taken as 1, giving orthogonal
/// similarity transforms of I = I). Scale the result for other magnitudes.
pub fn spd_matrix<T: Real, N: Dim>(
    dim: N,
    max_condition: f64,
) -> impl Strategy<Value = OMatrix<T, N, N>> + Clone
where
    DefaultAllocator: Allocator<N, N>,
{
    let n = dim.value();
    let kappa = valid_condition(max_condition);
    (normals(n * n), vec(0.0..=1.0f64, n))
        .prop_map(move |(q, u)| to_generic(dim, dim, &spd_from(n, kappa, q, u)))
}

/// Vectors with entries uniform in [−`magnitude`, `magnitude`] (shrinking towards 0).
pub fn vector<T: Real, N: Dim>(
    dim: N,
    magnitude: f64,
) -> impl Strategy<Value = OVector<T, N>> + Clone
where
    DefaultAllocator: Allocator<N>,
{
    let m = if magnitude.is_finite() {
        magnitude.abs()
    } else {
        0.0
    };
    vec(-m..=m, dim.value())
        .prop_map(move |v| OVector::<T, N>::from_iterator_generic(dim, U1, v.into_iter().map(real)))
}

/// Gaussians N(μ, C) of dimension `dim` with μ uniform in [−10, 10]ⁿ and C from
/// [`spd_matrix`]`(dim, 1000)`. See [`gaussian_with`] for other ranges.
pub fn gaussian<T: Real, N: Dim>(dim: N) -> impl Strategy<Value = Gaussian<T, N>> + Clone
where
    DefaultAllocator: Alloc<N>,
{
    gaussian_with(dim, 10.0, 1e3)
}

/// Gaussians with mean entries in [−`mean_magnitude`, `mean_magnitude`] and covariance from
/// [`spd_matrix`]`(dim, max_condition)`.
pub fn gaussian_with<T: Real, N: Dim>(
    dim: N,
    mean_magnitude: f64,
    max_condition: f64,
) -> impl Strategy<Value = Gaussian<T, N>> + Clone
where
    DefaultAllocator: Alloc<N>,
{
    (vector(dim, mean_magnitude), spd_matrix(dim, max_condition))
        // The covariance is symmetric and positive definite by construction.
        .prop_map(|(mean, covariance)| Gaussian::new_unchecked(mean, covariance))
}

/// A random stable linear-Gaussian system with `N` states, one scalar input and `M`
/// measurements, as [`stable_linear_system`] makes them.
#[derive(Clone, PartialEq)]
pub struct LinearSystem<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U1>,
{
    /// x⁺ = F x + B u + w with ‖F‖₂ = `spectral_norm` < 1, w ~ N(0, Q).
    pub process: LinearProcess<f64, N, U1>,
    /// z = H x + v, v ~ N(0, R).
    pub measurement: LinearMeasurement<f64, N, M>,
    /// The prior of x₀.
    pub prior: Gaussian<f64, N>,
    /// ‖F‖₂, the largest singular value of F; it bounds the spectral radius, so the system
    /// is stable (and contractive in the 2-norm).
    pub spectral_norm: f64,
}

impl<N: Dim, M: Dim> fmt::Debug for LinearSystem<N, M>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U1>,
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LinearSystem")
            .field("F", &self.process.transition)
            .field("B", &self.process.input)
            .field("Q", &self.process.noise)
            .field("H", &self.measurement.observation)
            .field("R", &self.measurement.noise)
            .field("prior", &self.prior)
            .field("spectral_norm", &self.spectral_norm)
            .finish()
    }
}

/// Random stable linear-Gaussian systems with `n` states and `m` measurements:
///
/// - F = ρ A / ‖A‖₂ for a standard Gaussian n × n matrix A and ρ uniform in [0.2, 0.98], so
///   the spectral radius is at most ‖F‖₂ = ρ < 1 (A = 0, which shrinking can reach, gives
///   F = ρ I);
/// - B (n × 1) and H (m × n) standard Gaussian;
/// - Q = s_q · [`spd_matrix`]`(n, 100)` with s_q log-uniform in [10⁻³, 1];
///   R = s_r · [`spd_matrix`]`(m, 100)` with s_r log-uniform in [10⁻², 1];
/// - prior N(μ₀, P₀) with μ₀ standard Gaussian and P₀ from [`spd_matrix`]`(n, 100)`.
pub fn stable_linear_system<N: Dim, M: Dim>(
    n: N,
    m: M,
) -> impl Strategy<Value = LinearSystem<N, M>> + Clone
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U1>,
{
    let (nv, mv) = (n.value(), m.value());
    (
        (
            normals(nv * nv),
            0.2..=0.98f64,
            normals(nv),
            normals(mv * nv),
        ),
        (spd_matrix::<f64, N>(n, 100.0), -3.0..=0.0f64),
        (spd_matrix::<f64, M>(m, 100.0), -2.0..=0.0f64),
        (normals(nv), spd_matrix::<f64, N>(n, 100.0)),
    )
        .prop_map(move |((a, rho, b, h), (q, sq), (r, sr), (mu, p0))| {
            let a = DMatrix::from_vec(nv, nv, a);
            let norm = if nv == 0 {
                0.0
            } else {
                a.singular_values().max()
            };
            let f = if norm > 0.0 && norm.is_finite() {
                a * (rho / norm)
            } else {
                DMatrix::identity(nv, nv) * rho
            };
            let spectral_norm = if nv == 0 {
                0.0
            } else {
                f.singular_values().max()
            };
            LinearSystem {
                process: LinearProcess {
                    transition: to_generic(n, n, &f),
                    input: to_generic(n, U1, &DMatrix::from_vec(nv, 1, b)),
                    noise: q * 10f64.powf(sq),
                },
                measurement: LinearMeasurement {
                    observation: to_generic(m, n, &DMatrix::from_vec(mv, nv, h)),
                    noise: r * 10f64.powf(sr),
                },
                prior: Gaussian::new_unchecked(
                    OVector::<f64, N>::from_iterator_generic(n, U1, mu),
                    p0,
                ),
                spectral_norm,
            }
        })
}

fn judge<T: Real>(report: Result<DerivativeReport<T>>, tol: T, what: &str) -> TestCaseResult {
    match report {
        Err(e) => Err(TestCaseError::fail(format!(
            "{what}: derivative check failed: {e}"
        ))),
        Ok(r) if r.is_accurate(tol) => Ok(()),
        Ok(r) => Err(TestCaseError::fail(format!(
            "{what} disagrees with finite differences beyond {tol}: {r}"
        ))),
    }
}

/// Fails the test case unless g's analytic Jacobian at `x` agrees with central differences:
/// |analytic − numeric| ≤ `tol` · max(1, |numeric|) for every entry
/// ([`DerivativeReport::is_accurate`]; `tol` ≈ 10⁻⁶ suits smooth `f64` functions).
pub fn assert_jacobian<T, N, M, G>(g: &G, x: &OVector<T, N>, tol: T) -> TestCaseResult
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    judge(derivative::check_jacobian(g, x), tol, "Jacobian")
}

/// [`assert_jacobian`] for the Jacobian and every Hessian of g.
pub fn assert_derivatives<T, N, M, G>(g: &G, x: &OVector<T, N>, tol: T) -> TestCaseResult
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    judge(
        derivative::check_derivatives(g, x),
        tol,
        "Jacobian/Hessians",
    )
}

/// [`assert_jacobian`] for a process model's ∂f/∂x at (x, u, Δt).
pub fn assert_process_jacobian<T, N, P>(
    model: &P,
    x: &OVector<T, N>,
    input: &P::Input,
    dt: T,
    tol: T,
) -> TestCaseResult
where
    T: Real,
    N: Dim,
    P: ProcessJacobian<T, N>,
    DefaultAllocator: Alloc<N>,
{
    judge(
        derivative::check_process_jacobian(model, x, input, dt),
        tol,
        "process Jacobian",
    )
}

/// [`assert_derivatives`] for a process model's Jacobian and Hessians at (x, u, Δt).
pub fn assert_process_derivatives<T, N, P>(
    model: &P,
    x: &OVector<T, N>,
    input: &P::Input,
    dt: T,
    tol: T,
) -> TestCaseResult
where
    T: Real,
    N: Dim,
    P: ProcessHessian<T, N>,
    DefaultAllocator: Alloc<N>,
{
    judge(
        derivative::check_process_model(model, x, input, dt),
        tol,
        "process Jacobian/Hessians",
    )
}

/// [`assert_jacobian`] for a measurement model's ∂h/∂x at x.
pub fn assert_measurement_jacobian<T, N, M, H>(
    model: &H,
    x: &OVector<T, N>,
    tol: T,
) -> TestCaseResult
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    judge(
        derivative::check_measurement_jacobian(model, x),
        tol,
        "measurement Jacobian",
    )
}

/// [`assert_derivatives`] for a measurement model's Jacobian and Hessians at x.
pub fn assert_measurement_derivatives<T, N, M, H>(
    model: &H,
    x: &OVector<T, N>,
    tol: T,
) -> TestCaseResult
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    judge(
        derivative::check_measurement_model(model, x),
        tol,
        "measurement Jacobian/Hessians",
    )
}
