//! Fuzzing every Gaussian filter with sane and adversarial numbers (issue 18): the KF, EKF,
//! second-order EKF, Gaussian second-order EKF and UKF (several α, β, κ, extreme ones
//! included), each covariance form, the square-root KF, EKF and UKF, `f32` and `f64`, static (3 states, 2 measurements, 1
//! input) and runtime (`Dyn`, same sizes) dimensions. A case is a prior and a sequence of
//! predictions and updates on linear models whose entries are sane (uniform in ±2, noise
//! covariances A Aᵀ + δ I scaled by 10⁻⁶…10⁶) or adversarial (NaN, ±∞, ±10³⁰⁰, 10⁻³⁰⁰,
//! subnormals, ±10³⁸ and 10⁻⁴⁰ for `f32`, negative noise variances, Δt ≤ 0 or non-finite).
//!
//! Asserted after every call (each run inside `catch_unwind`):
//! - no panic (a panic fails the case and reports the input);
//! - an error leaves the filter bit-identical: `==` (when the filter holds only finite numbers) and the bits
//!   of x and P equal those of a clone taken before the call;
//! - an `Ok` leaves x finite and P finite, symmetric and with no eigenvalue below −tol, where
//!   tol = c · ε · A · k · ‖P‖, ‖P‖ the largest |entry| of P over the run so far (round-off
//!   made at an earlier, larger scale persists), k the number of calls so far (each adds its
//!   own), c = 8 n² = 72
//!   for n = 3 (each entry of the products F P Fᵀ, K S Kᵀ, … is a sum of at most n² terms, each
//!   rounded a few times, and the eigenvalue perturbation is bounded by the n-fold entry
//!   error), A = 1 except for the UKF, where A = Σᵢ |W⁽ᶜ⁾ᵢ| (the sigma-point sum multiplies
//!   each rounding by its weight; α = 10⁻³ gives A ≈ 2·10⁶). The earlier, larger scale also
//!   covers an update that removes most of the variance (R ≪ P): it leaves rounding of the
//!   size of the prior's entries. The standard form (P − K Pₓᵤᵀ, documented as drifting from
//!   symmetry) is held to symmetry within √ε ‖P‖ only, the tolerance `Gaussian::new` accepts:
//!   its asymmetry is the round-off of K Pₓᵤᵀ, whose entries reach cond(S) ‖P‖ (measured
//!   123 ε ‖P‖ with R = 10⁻⁴).
//!
//! Generator limits (not loosened assertions; each is issue 18 item 3, checked constructors):
//! - noise matrices Q, R are never non-symmetric (the filters use their symmetric part, and
//!   the fuzz compares nothing against Q itself); they are made indefinite with a positive
//!   diagonal by an off-diagonal pair (refused per step since the semi-definiteness check of
//!   the noise; before it such a Q or R returned an indefinite P as `Ok`), other finite
//!   adversarial values go on the diagonal (both triangles kept equal), non-finite ones
//!   anywhere.
//! - finite huge values (10²⁰, 10³⁸, 10³⁰⁰) go only into vectors (x₀, z, u) and Δt, not into
//!   F, B, H, P₀, Q, R: in a matrix they give condition numbers ≫ 1/ε, where the full-P forms
//!   lose definiteness (found: P₀₂₂ = 10³⁸, an update, then a predict gave an `Ok` P with
//!   λ_min = −2.5·10⁵⁹ beside variances of 10⁻³). That needs the square-root forms (issue 18
//!   item 1). The worst case found before this limit, a negative variance returned as `Ok`,
//!   is now an error (the regression tests below).
//! - in f32, prior and noise covariances are scaled by 10^k with |k| ≤ 1 (f64: ≤ 6): with R ≪ P
//!   (found: R = 10⁻⁶ I, ‖P‖ = 7) the f32 Joseph form returns λ_min = −2.5·10⁻⁴ (300 ε ‖P‖),
//!   the f32 failure issue 18 item 2 assigns to the square-root forms.
//! - R never gets a tiny (≤ 10⁻³⁰⁰, subnormal, ±0, or negative within the PSD tolerance, a
//!   zero variance to the filter) variance replacing a larger one: a nearly
//!   exact measurement direction makes the expanded Joseph sum lose definiteness beyond
//!   c ε ‖P‖ (found in the long run: R = diag(10⁻³⁰⁰, 10⁻³), λ_min = −1.0·10⁻¹¹ at a run
//!   scale ‖P‖ ≈ 130, about 350 ε ‖P‖; the issue measured −2·10⁻¹⁰ ‖P‖): square-root forms.
//!
//! CI runs 2048 cases (about 10⁴ calls, well under a second). The longer run, ≥ 10⁶ filter calls:
//! `ESTIM_FUZZ_CASES=210000 cargo test -p estim-filters --all-features --test it fuzz:: --
//! --nocapture`, which prints the number of calls made: 1 024 265 calls in 9.9 s, all
//! properties held (test profile, 2026-12-04, with indefinite noise in the generator and the
//! filters remembering the last accepted Q; before that memory, 1 023 983 calls and also 10
//! runs of 100 000 cases, 4.9·10⁶ calls, all held).
//!
//! The classes an outside campaign found beyond this generator (issue 41: square-root filters
//! whose P = S Sᵀ overflows, noise matching, `Rts::with_lag`, corrupted checkpoints) are
//! fuzzed in [`extremes`].

mod extremes;

use core::fmt::Debug;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicUsize, Ordering};

use estim_core::nalgebra::{self, DMatrix, DefaultAllocator, Dim, Dyn, OMatrix, U1, U2, U3};
use estim_core::propagate::Unscented;
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess, Real};
use estim_filters::{
    CovarianceUpdate, Ekf, Estimator, GaussianFilter, GaussianSecondOrderEkf, KalmanFilter,
    Predict, PredictCross, SecondOrderEkf, SquareRootFilter, SrEkf, SrKalmanFilter, Update,
};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

const N: usize = 3;
const M: usize = 2;
const U: usize = 1;

/// Filter calls made by this module (all threads), printed at the end of the test.
static CALLS: AtomicUsize = AtomicUsize::new(0);

/// The bits of a scalar, to compare states and covariances bit for bit (NaN included).
trait Bits: Real + Debug {
    /// Machine epsilon as `f64`.
    const EPS: f64;
    fn bits(self) -> u64;
}

impl Bits for f32 {
    const EPS: f64 = f32::EPSILON as f64;
    fn bits(self) -> u64 {
        u64::from(self.to_bits())
    }
}

impl Bits for f64 {
    const EPS: f64 = f64::EPSILON;
    fn bits(self) -> u64 {
        self.to_bits()
    }
}

/// The adversarial values.
const ADVERSARIAL: [f64; 14] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    1e300,
    -1e300,
    1e-300,
    5e-324,
    1e-310,
    0.0,
    -0.0,
    1e38,
    -1e38,
    1e-40,
    1e20,
];

fn adversarial() -> impl Strategy<Value = f64> {
    prop::sample::select(ADVERSARIAL.to_vec())
}

/// The adversarial values for matrix entries: not the finite huge ones (generator limit 2 in
/// the module docs).
fn adversarial_in_matrix() -> impl Strategy<Value = f64> {
    prop::sample::select(
        ADVERSARIAL
            .iter()
            .copied()
            .filter(|v| !(v.is_finite() && v.abs() > 1.0))
            .collect::<Vec<_>>(),
    )
}

/// `len` sane entries in ±2, and with probability ¼ one of them overwritten by an adversarial
/// value.
fn entries(len: usize, in_matrix: bool) -> impl Strategy<Value = Vec<f64>> {
    let pick = if in_matrix {
        adversarial_in_matrix().boxed()
    } else {
        adversarial().boxed()
    };
    (
        prop::collection::vec(-2.0..2.0f64, len),
        prop::option::weighted(0.25, (0..len, pick)),
    )
        .prop_map(|(mut v, hit)| {
            if let Some((i, a)) = hit {
                v[i] = a;
            }
            v
        })
}

/// A d×d covariance, row-major: A Aᵀ + 10⁻³ I scaled by 10^k (|k| ≤ `kmax`); with probability ¼
/// one diagonal entry overwritten by an adversarial value (a negative one included), or any
/// entry pair by a non-finite one (generator limit in the module docs).
fn covariance(d: usize, kmax: i32, near_singular: bool) -> impl Strategy<Value = Vec<f64>> {
    (
        prop::collection::vec(-1.0..1.0f64, d * d),
        -kmax..=kmax,
        prop::option::weighted(0.25, (0..d, 0..d, adversarial_in_matrix(), -1.0..1.0f64)),
    )
        .prop_map(move |(a, k, hit)| {
            let a = DMatrix::from_row_slice(d, d, &a);
            let p = (&a * a.transpose() + DMatrix::identity(d, d) * 1e-3) * 10f64.powi(k);
            // Exactly symmetric (the upper triangle mirrored), also after conversion to f32.
            let mut v: Vec<f64> = (0..d * d)
                .map(|e| p[((e / d).min(e % d), (e / d).max(e % d))])
                .collect();
            if let Some((i, j, value, sign)) = hit {
                if value.is_finite() && sign.abs() > 0.75 && d > 1 {
                    // Indefinite with a positive diagonal: an entry pair of 2 √(vᵢᵢ vⱼⱼ) makes
                    // the 2 × 2 minor −3 vᵢᵢ vⱼⱼ < 0 (an eigenvalue of the entries' size,
                    // far beyond the PSD tolerance); a step given it as Q or R must refuse it.
                    let j = if j == i { (i + 1) % d } else { j };
                    let c = 2.0 * (v[i * d + i] * v[j * d + j]).sqrt() * sign.signum();
                    v[i * d + j] = c;
                    v[j * d + i] = c;
                } else if value.is_finite() {
                    // On the diagonal, possibly negated: a negative variance must be refused.
                    // A value smaller than the old one would make the matrix indefinite with
                    // a diagonal that passes the check (positive, or negative within the PSD
                    // tolerance: the generator limit), so its row and column are zeroed: a
                    // negative variance stays, the rest is PSD and (nearly) singular.
                    let old = v[i * d + i];
                    let new = if sign < 0.0 {
                        -value.abs()
                    } else {
                        value.abs()
                    };
                    if new < old && !near_singular {
                        // Generator limit 4: no nearly exact measurement directions in R (every
                        // finite adversarial matrix value is tiny, and a tiny negative one is
                        // within the PSD tolerance: a zero variance to the filter).
                    } else if new < old {
                        for l in 0..d {
                            v[i * d + l] = 0.0;
                            v[l * d + i] = 0.0;
                        }
                    }
                    if new >= old || near_singular {
                        v[i * d + i] = new;
                    }
                } else {
                    v[i * d + j] = value;
                    v[j * d + i] = value;
                }
            }
            v
        })
}

fn time_step() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => 0.0..2.0f64,
        1 => prop::sample::select(vec![-1.0, -0.0, 0.0, f64::NAN, f64::INFINITY, 1e300, 1e-300, 5e-324]),
    ]
}

#[derive(Clone, Debug)]
enum Op {
    Predict {
        f: Vec<f64>,
        b: Vec<f64>,
        q: Vec<f64>,
        u: Vec<f64>,
        dt: f64,
    },
    Update {
        h: Vec<f64>,
        r: Vec<f64>,
        z: Vec<f64>,
    },
}

fn op(kmax: i32) -> impl Strategy<Value = Op> {
    prop_oneof![
        (
            entries(N * N, true),
            entries(N * U, true),
            covariance(N, kmax, true),
            entries(U, false),
            time_step()
        )
            .prop_map(|(f, b, q, u, dt)| Op::Predict { f, b, q, u, dt }),
        (
            entries(M * N, true),
            covariance(M, kmax, false),
            entries(M, false)
        )
            .prop_map(|(h, r, z)| Op::Update { h, r, z }),
    ]
}

/// The UKF parameters tried: the default, cubature, small and large spreads, a negative κ.
const UKF_PARAMETERS: [(f64, f64, f64); 7] = [
    (1e-3, 2.0, 0.0),
    (1.0, 0.0, 0.0),
    (0.5, 2.0, 0.0),
    (1e-4, 2.0, 0.0),
    (1.0, 2.0, -2.0),
    (3.0, 2.0, 0.0),
    (1e-2, 0.0, 1e3),
];

#[derive(Clone, Debug)]
struct Case {
    f32: bool,
    dynamic: bool,
    /// 0 KF, 1 EKF, 2 second-order EKF, 3 Gaussian second-order EKF, 4 UKF.
    filter: usize,
    form: CovarianceUpdate,
    ukf: (f64, f64, f64),
    mean: Vec<f64>,
    covariance: Vec<f64>,
    ops: Vec<Op>,
}

fn case() -> impl Strategy<Value = Case> {
    any::<bool>().prop_flat_map(case_in)
}

/// Noise and prior scales 10^k, |k| ≤ 6 in f64, ≤ 1 in f32 (generator limit 3).
fn case_in(f32: bool) -> impl Strategy<Value = Case> {
    let kmax = if f32 { 1 } else { 6 };
    (
        Just(f32),
        any::<bool>(),
        0..8usize,
        prop::sample::select(vec![
            CovarianceUpdate::Joseph,
            CovarianceUpdate::Standard,
            CovarianceUpdate::Symmetrized,
        ]),
        prop::sample::select(UKF_PARAMETERS.to_vec()),
        entries(N, false),
        covariance(N, kmax, true),
        prop::collection::vec(op(kmax), 1..12),
    )
        .prop_map(
            |(f32, dynamic, filter, form, ukf, mean, covariance, ops)| Case {
                f32,
                dynamic,
                filter,
                form,
                ukf,
                mean,
                covariance,
                ops,
            },
        )
}

fn convert<T: Real>(v: f64) -> T {
    nalgebra::convert(v)
}

fn matrix<T: Real, R: Dim, C: Dim>(r: R, c: C, v: &[f64]) -> OMatrix<T, R, C>
where
    DefaultAllocator: nalgebra::allocator::Allocator<R, C>,
{
    let cols = c.value();
    OMatrix::from_fn_generic(r, c, |i, j| convert(v[i * cols + j]))
}

fn to_f64<T: Real, R: Dim, C: Dim>(m: &OMatrix<T, R, C>) -> DMatrix<f64>
where
    DefaultAllocator: nalgebra::allocator::Allocator<R, C>,
{
    DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| {
        nalgebra::try_convert::<T, f64>(m[(i, j)]).unwrap_or(f64::NAN)
    })
}

fn max_abs(m: &DMatrix<f64>) -> f64 {
    m.iter().fold(0.0, |a, v| a.max(v.abs()))
}

/// Σᵢ |W⁽ᶜ⁾ᵢ| of the unscented rule on n states: W₀ = λ/(n+λ) + 1 − α² + β, Wᵢ = 1/(2(n+λ)),
/// λ = α²(n+κ) − n.
fn ukf_weight_sum((alpha, beta, kappa): (f64, f64, f64), n: f64) -> f64 {
    let lambda = alpha * alpha * (n + kappa) - n;
    let w0 = lambda / (n + lambda) + 1.0 - alpha * alpha + beta;
    w0.abs() + 2.0 * n / (2.0 * (n + lambda))
}

/// A description of the filter for failure messages.
fn describe<T: Bits, N: Dim, F: Estimator<T, N>>(f: &F) -> String
where
    DefaultAllocator: Alloc<N>,
{
    format!("x = {:?}, P = {:?}", f.state(), f.covariance())
}

/// One call, checked: no panic; an error leaves `filter` bit-identical; an `Ok` leaves x
/// finite and P finite, symmetric and positive semi-definite to `amplification`·c·ε·‖P‖.
fn checked_call<T, N, F, R>(
    filter: &mut F,
    amplification: f64,
    scale: &mut f64,
    steps: usize,
    exactly_symmetric: bool,
    what: &dyn Fn() -> String,
    call: impl FnOnce(&mut F) -> Result<R, estim_core::Error>,
) -> Result<(), TestCaseError>
where
    T: Bits,
    N: Dim,
    DefaultAllocator: Alloc<N>,
    F: Estimator<T, N> + Clone + PartialEq + Debug,
{
    CALLS.fetch_add(1, Ordering::Relaxed);
    let before = filter.clone();
    let outcome = catch_unwind(AssertUnwindSafe(|| call(filter)));
    let result = match outcome {
        Ok(result) => result,
        Err(_) => {
            return Err(TestCaseError::fail(format!(
                "panic in {} on {}",
                what(),
                describe(&before)
            )));
        }
    };
    let same_bits = |a: &OMatrix<T, N, N>, b: &OMatrix<T, N, N>| {
        a.iter().zip(b.iter()).all(|(x, y)| x.bits() == y.bits())
    };
    match result {
        Err(e) => {
            let state_bits = filter
                .state()
                .iter()
                .zip(before.state().iter())
                .all(|(x, y)| x.bits() == y.bits());
            prop_assert!(
                state_bits && same_bits(filter.covariance(), before.covariance()),
                "{e:?} changed the filter in {}: before {}, after {}",
                what(),
                describe(&before),
                describe(filter)
            );
            let non_finite = before.state().iter().any(|v| !v.is_finite())
                || before.covariance().iter().any(|v| !v.is_finite());
            prop_assert!(
                non_finite || *filter == before,
                "{e:?} changed the filter's settings in {}",
                what()
            );
        }
        Ok(_) => {
            prop_assert!(
                filter.state().iter().all(|v| v.is_finite()),
                "Ok with a non-finite state in {}: {}",
                what(),
                describe(filter)
            );
            let p = to_f64(filter.covariance());
            prop_assert!(
                p.iter().all(|v| v.is_finite()),
                "Ok with a non-finite covariance in {}: {}",
                what(),
                describe(filter)
            );
            *scale = scale
                .max(max_abs(&p))
                .max(max_abs(&to_f64(before.covariance())));
            let n = p.nrows() as f64;
            let tol = 8.0 * n * n * T::EPS * amplification * steps as f64 * *scale;
            let asymmetry = max_abs(&(&p - p.transpose()));
            let symmetry_tol = if exactly_symmetric {
                tol
            } else {
                T::EPS.sqrt() * *scale
            };
            prop_assert!(
                asymmetry <= symmetry_tol,
                "Ok with P asymmetric by {asymmetry:e} > {tol:e} in {}: before {}, after {}",
                what(),
                describe(&before),
                describe(filter)
            );
            // Halves first: P + Pᵀ overflows for a finite P with entries above 9·10³⁰⁷ (the
            // square-root filters in `extremes` reach them).
            let symmetric = &p * 0.5 + p.transpose() * 0.5;
            let min = symmetric.symmetric_eigenvalues().min();
            prop_assert!(
                min >= -tol,
                "Ok with λ_min(P) = {min:e} < −{tol:e} in {}: before {}, after {}",
                what(),
                describe(&before),
                describe(filter)
            );
        }
    }
    Ok(())
}

/// Runs `case` on the filter `make` builds, with dimensions (n, m, u).
fn run_case<T, Nd, Md, Ud, F>(
    case: &Case,
    dims: (Nd, Md, Ud),
    make: impl Fn(Gaussian<T, Nd>) -> Result<F, estim_core::Error>,
) -> Result<(), TestCaseError>
where
    T: Bits,
    Nd: Dim,
    Md: Dim,
    Ud: Dim,
    DefaultAllocator: Alloc<Nd, Md> + Alloc<Nd, Ud>,
    F: Predict<T, Nd, LinearProcess<T, Nd, Ud>>
        + Update<T, Nd, Md, LinearMeasurement<T, Nd, Md>>
        + Clone
        + PartialEq
        + Debug,
{
    let (n, m, u) = dims;
    let symmetric = case.form != CovarianceUpdate::Standard;
    let amplification = if case.filter == 4 || case.filter == 7 {
        ukf_weight_sum(case.ukf, N as f64)
    } else {
        1.0
    };
    // The checked constructors must refuse bad priors and UKF settings with a typed error.
    let built = catch_unwind(AssertUnwindSafe(|| {
        Gaussian::new(matrix(n, U1, &case.mean), matrix(n, n, &case.covariance)).and_then(&make)
    }));
    // The largest ‖P‖ of the run so far: rounding made at that scale persists.
    let mut scale = max_abs(&DMatrix::from_row_slice(N, N, &case.covariance));
    let mut filter = match built {
        Err(_) => return Err(TestCaseError::fail("panic building the prior or filter")),
        Ok(Err(_)) => return Ok(()),
        Ok(Ok(f)) => f,
    };
    for (k, op) in case.ops.iter().enumerate() {
        let what = || format!("step {k}: {op:?}");
        type Call<'a, F> = Box<dyn Fn(&mut F) -> Result<(), estim_core::Error> + 'a>;
        let call: Call<'_, F> = match op {
            Op::Predict {
                f,
                b,
                q,
                u: input,
                dt,
            } => {
                let model = LinearProcess {
                    transition: matrix(n, n, f),
                    input: matrix(n, u, b),
                    noise: matrix(n, n, q),
                };
                let input = matrix(u, U1, input);
                let dt = convert(*dt);
                Box::new(move |f: &mut F| f.predict(&model, &input, dt))
            }
            Op::Update { h, r, z } => {
                let model = LinearMeasurement {
                    observation: matrix(m, n, h),
                    noise: matrix(m, m, r),
                };
                let z = matrix(m, U1, z);
                Box::new(move |f: &mut F| f.update(&model, &z).map(|_| ()))
            }
        };
        checked_call(
            &mut filter,
            amplification,
            &mut scale,
            k + 1,
            symmetric,
            &what,
            call,
        )?;
    }
    Ok(())
}

/// Dispatches a case to the filter, scalar and size class it names.
macro_rules! dispatch {
    ($case:expr, $t:ty, $dims:expr) => {{
        let case: &Case = $case;
        let form = case.form;
        let (a, b, k) = case.ukf;
        match case.filter {
            0 => run_case::<$t, _, _, _, _>(case, $dims, |p| {
                Ok(KalmanFilter::new(p).with_covariance_update(form))
            }),
            1 => run_case::<$t, _, _, _, _>(case, $dims, |p| {
                Ok(Ekf::new(p).with_covariance_update(form))
            }),
            2 => run_case::<$t, _, _, _, _>(case, $dims, |p| {
                Ok(SecondOrderEkf::new(p).with_covariance_update(form))
            }),
            3 => run_case::<$t, _, _, _, _>(case, $dims, |p| {
                Ok(GaussianSecondOrderEkf::new(p).with_covariance_update(form))
            }),
            4 => run_case::<$t, _, _, _, _>(case, $dims, |p| {
                let rule = Unscented::new(convert(a), convert(b), convert(k))?;
                Ok(GaussianFilter::with_propagator(p, rule).with_covariance_update(form))
            }),
            // The square-root forms (the covariance form does not apply).
            5 => run_case::<$t, _, _, _, _>(case, $dims, |p| Ok(SrKalmanFilter::new(p))),
            6 => run_case::<$t, _, _, _, _>(case, $dims, |p| Ok(SrEkf::new(p))),
            _ => run_case::<$t, _, _, _, _>(case, $dims, |p| {
                let rule = Unscented::new(convert(a), convert(b), convert(k))?;
                Ok(SquareRootFilter::with_propagator(p, rule))
            }),
        }
    }};
}

fn run(case: &Case) -> Result<(), TestCaseError> {
    match (case.f32, case.dynamic) {
        (false, false) => dispatch!(case, f64, (U3, U2, U1)),
        (false, true) => dispatch!(case, f64, (Dyn(N), Dyn(M), Dyn(U))),
        (true, false) => dispatch!(case, f32, (U3, U2, U1)),
        (true, true) => dispatch!(case, f32, (Dyn(N), Dyn(M), Dyn(U))),
    }
}

fn cases() -> u32 {
    std::env::var("ESTIM_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2048)
}

#[test]
fn no_filter_panics_corrupts_or_returns_an_invalid_covariance() {
    let config = ProptestConfig {
        cases: cases(),
        failure_persistence: None,
        ..ProptestConfig::default()
    };
    let start = std::time::Instant::now();
    proptest!(config, |(case in case())| {
        run(&case)?;
    });
    println!(
        "fuzz: {} filter calls in {:.1} s",
        CALLS.load(Ordering::Relaxed),
        start.elapsed().as_secs_f64()
    );
}

/// Regression (found by the fuzz test): a prior variance of −10⁻³⁰⁰, inside `Gaussian::new`'s
/// PSD tolerance, times a transition entry of 10³⁰⁰ gave P⁻₀₀ = −10³⁰⁰ as `Ok`. Now a typed
/// error, and the filter is unchanged.
#[test]
fn a_prediction_that_turns_a_variance_negative_is_refused() {
    use estim_core::nalgebra::{Matrix3, Matrix3x1, Vector1, Vector3};
    use estim_core::{Error, Quantity, Stage};
    let prior = Gaussian::new(
        Vector3::zeros(),
        Matrix3::from_diagonal(&Vector3::new(1e-3, -1e-300, 1e-3)),
    )
    .unwrap();
    let mut transition = Matrix3::zeros();
    transition[(0, 1)] = 1e300;
    let process = LinearProcess {
        transition,
        input: Matrix3x1::zeros(),
        noise: Matrix3::identity() * 1e-3,
    };
    let expected = Error::NotPositiveSemiDefinite {
        stage: Stage::Prediction,
        quantity: Quantity::Covariance,
    };
    let mut kf = KalmanFilter::new(prior.clone());
    let before = kf.clone();
    assert_eq!(kf.predict(&process, &Vector1::zeros(), 0.1), Err(expected));
    assert!(kf == before);
    let mut ekf = Ekf::new(prior);
    let before = ekf.clone();
    assert_eq!(
        ekf.predict_with_cross_covariance(&process, &Vector1::zeros(), 0.1),
        Err(expected)
    );
    assert!(ekf == before);
}

/// Regression (found by the fuzz test): an update with cond ≫ 1/ε (P ≈ 10²⁰ nearly rank
/// one, R = 10⁻³ I) gave a posterior with variances of −10¹³ as `Ok` in the Joseph form. Now a
/// typed error, and the filter is unchanged.
#[test]
fn an_update_that_turns_a_variance_negative_is_refused() {
    use estim_core::nalgebra::{DMatrix, DVector};
    use estim_core::{Error, Quantity, Stage};
    let p = DMatrix::from_row_slice(
        3,
        3,
        &[
            8.483433123513074e19,
            1.064694336029949e20,
            1.3265931119602788e20,
            1.064694336029949e20,
            1.3362208585488699e20,
            1.6649110707382583e20,
            1.3265931119602788e20,
            1.6649110707382583e20,
            2.074454126151811e20,
        ],
    );
    let measurement = LinearMeasurement {
        observation: DMatrix::from_row_slice(
            2,
            3,
            &[
                -1.3146931848042451,
                -1.8144826572506987,
                0.807299640094222,
                -1.56403908778412,
                -1.540156310385038,
                0.4020547907802314,
            ],
        ),
        noise: DMatrix::identity(2, 2) * 1e-3,
    };
    let mut kf = KalmanFilter::new(Gaussian::new(DVector::zeros(3), p).unwrap());
    let before = kf.clone();
    let result = kf.update(&measurement, &DVector::zeros(2));
    // S = H P Hᵀ + R has cond ≈ 10²³ here, so the sign of its second Cholesky pivot is the
    // rounding of S: faer's fused multiply–adds (larger sizes, `dense`) make it positive and the
    // negative posterior variance is caught; the small-size loops (and builds without `dense`)
    // round it to ≤ 0 and S itself is refused. Either is a refusal of this update.
    let refused_s = Error::NotPositiveDefinite {
        stage: Stage::Update,
        quantity: Quantity::InnovationCovariance,
    };
    let refused_p = Error::NotPositiveSemiDefinite {
        stage: Stage::Update,
        quantity: Quantity::Covariance,
    };
    let error = result.map(|_| ()).expect_err("the update must be refused");
    assert!(error == refused_s || error == refused_p, "{error:?}");
    assert!(kf == before);
}
