//! Shared support for the estim-core integration tests.
//!
//! - Test functions with analytic derivatives, generic over the scalar and over static or
//!   dynamic sizes: [`AffineMap`], [`Quadratic`], [`TrigSum`] (sums of terms
//!   (c₀ + bᵀx)·cos(aᵀx + φ), which covers x₀ cos x₁, sin x₀ cos x₁, …) and [`Boje`] (the
//!   transformation of Boje's eq 5).
//! - Their exact moments when x is Gaussian (closed forms, derived below).
//! - Rigorous bounds on the truncation error of each moment approximation for a [`TrigSum`]
//!   ([`taylor_bounds`], [`unscented_bounds`]).
//! - Sampling standard errors of the Monte Carlo reference ([`sampling_error`]) and the
//!   entrywise comparison [`assert_within`].
//!
//! Notation: x ~ N(μ, C), e = x − μ, u = ε/2 the unit round-off. `EPS` is ε = 2u, so
//! [`gamma`]`(k)` = kε bounds Higham's γₖ = ku/(1 − ku) for every k used here.
#![allow(dead_code)] // every test binary uses a different subset of this module

use estim_core::linalg::psd_factor;
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1, allocator::Allocator};
use estim_core::{
    AffineFunction, Alloc, Differentiable, Moments, Real, Stage, TwiceDifferentiable,
    VectorFunction,
};
use proptest::test_runner::{Config, RngSeed};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

/// z-factor for every comparison with a Monte Carlo estimate: a two-sided normal tail of
/// 5.7·10⁻⁷ per entry, so even the ~10⁴ entries compared over the whole suite would give a
/// false failure with probability below 1% for a fresh seed (and the seeds are fixed).
pub const Z: f64 = 5.0;

/// ε for f64.
pub const EPS: f64 = f64::EPSILON;

/// ε for f32, as f64.
pub const EPS32: f64 = f32::EPSILON as f64;

/// kε ≥ γₖ (Higham): the relative error bound of a k-term sum or dot product in f64.
pub fn gamma(k: usize) -> f64 {
    k as f64 * EPS
}

/// kε₃₂ ≥ γₖ in f32.
pub fn gamma32(k: usize) -> f64 {
    k as f64 * EPS32
}

/// A deterministic proptest configuration: fixed seed, no regression files.
pub fn config(cases: u32, seed: u64) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..Config::default()
    }
}

// ---------------------------------------------------------------------------------------------
// Matrix helpers
// ---------------------------------------------------------------------------------------------

/// An r × c matrix from column-major entries (at least r·c of them).
pub fn mat<R: Dim, C: Dim>(r: R, c: C, entries: &[f64]) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    OMatrix::from_iterator_generic(r, c, entries.iter().copied())
}

/// A vector from entries.
pub fn vector<N: Dim>(n: N, entries: &[f64]) -> OVector<f64, N>
where
    DefaultAllocator: Allocator<N>,
{
    OVector::from_iterator_generic(n, U1, entries.iter().copied())
}

/// The i-th unit vector.
pub fn unit<N: Dim>(n: N, i: usize) -> OVector<f64, N>
where
    DefaultAllocator: Allocator<N>,
{
    OVector::from_fn_generic(n, U1, |r, _| if r == i { 1.0 } else { 0.0 })
}

/// A random SPD covariance scale² (B Bᵀ / n + 0.1 I) from n² entries of B in [−1, 1]:
/// correlated, with eigenvalues in [0.1, n + 0.1]·scale².
pub fn spd<N: Dim>(n: N, entries: &[f64], scale: f64) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Allocator<N, N>,
{
    let b = mat(n, n, entries);
    let dim = n.value() as f64;
    let mut c = &b * b.transpose() / dim;
    for i in 0..n.value() {
        c[(i, i)] += 0.1;
    }
    c * (scale * scale)
}

/// Entrywise |m|.
pub fn abs<R: Dim, C: Dim>(m: &OMatrix<f64, R, C>) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    m.map(f64::abs)
}

/// √diag(C).
pub fn std_devs<N: Dim>(c: &OMatrix<f64, N, N>) -> OVector<f64, N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    OVector::from_fn_generic(c.shape_generic().0, U1, |i, _| c[(i, i)].sqrt())
}

/// Entrywise conversion to f32 (rounding).
pub fn to32<R: Dim, C: Dim>(m: &OMatrix<f64, R, C>) -> OMatrix<f32, R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    m.map(|v| v as f32)
}

/// Entrywise conversion to f64 (exact).
pub fn to64<R: Dim, C: Dim>(m: &OMatrix<f32, R, C>) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    m.map(f64::from)
}

/// Converts f32 moments to f64 for comparison.
pub fn moments_f64<N: Dim, M: Dim>(m: &Moments<f32, N, M>) -> Moments<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    Moments {
        mean: to64(&m.mean),
        covariance: to64(&m.covariance),
        cross_covariance: to64(&m.cross_covariance),
    }
}

/// Asserts |got − want| ≤ tol entrywise (NaN fails), naming the worst entry.
#[track_caller]
pub fn assert_within<R: Dim, C: Dim>(
    what: &str,
    got: &OMatrix<f64, R, C>,
    want: &OMatrix<f64, R, C>,
    tol: &OMatrix<f64, R, C>,
) where
    DefaultAllocator: Allocator<R, C>,
{
    assert_eq!(got.shape(), want.shape(), "{what}: shapes differ");
    assert_eq!(got.shape(), tol.shape(), "{what}: tolerance shape");
    let mut worst: Option<(f64, usize, usize)> = None;
    let mut largest_ratio = 0.0f64;
    for j in 0..got.ncols() {
        for i in 0..got.nrows() {
            let err = (got[(i, j)] - want[(i, j)]).abs();
            let ok = err <= tol[(i, j)];
            if err > 0.0 {
                largest_ratio = largest_ratio.max(err / tol[(i, j)]);
            }
            if !ok {
                let ratio = if err.is_nan() {
                    f64::INFINITY
                } else {
                    err / tol[(i, j)]
                };
                if worst.is_none_or(|w| ratio > w.0) {
                    worst = Some((ratio, i, j));
                }
            }
        }
    }
    // ESTIM_TEST_RATIOS=1 prints how much of each tolerance is used (for reviewing them).
    if std::env::var_os("ESTIM_TEST_RATIOS").is_some() {
        eprintln!("ratio {largest_ratio:.3e} {what}");
    }
    if let Some((ratio, i, j)) = worst {
        panic!(
            "{what}: entry ({i}, {j}) got {:e}, want {:e}, |error| {:e} exceeds tolerance {:e} \
             ({ratio:.3}×)\ngot:{got}want:{want}tolerance:{tol}",
            got[(i, j)],
            want[(i, j)],
            (got[(i, j)] - want[(i, j)]).abs(),
            tol[(i, j)],
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Affine functions
// ---------------------------------------------------------------------------------------------

/// g(x) = A x + b.
#[derive(Clone, Debug)]
pub struct AffineMap<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A (m × n).
    pub a: OMatrix<T, M, N>,
    /// b (m).
    pub b: OVector<T, M>,
}

impl<T: Real, N: Dim, M: Dim> VectorFunction<T, N, M> for AffineMap<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        let mut y = self.b.clone();
        y.gemv(T::one(), &self.a, x, T::one());
        y
    }
}

impl<T: Real, N: Dim, M: Dim> Differentiable<T, N, M> for AffineMap<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, _: &OVector<T, N>) -> OMatrix<T, M, N> {
        self.a.clone()
    }
}

impl<T: Real, N: Dim, M: Dim> TwiceDifferentiable<T, N, M> for AffineMap<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn hessian(&self, _: &OVector<T, N>, _: usize) -> Option<OMatrix<T, N, N>> {
        None
    }
}

impl<T: Real, N: Dim, M: Dim> AffineFunction<T, N, M> for AffineMap<T, N, M> where
    DefaultAllocator: Alloc<N, M>
{
}

impl<N: Dim, M: Dim> AffineMap<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The same map in f32.
    pub fn to_f32(&self) -> AffineMap<f32, N, M> {
        AffineMap {
            a: to32(&self.a),
            b: to32(&self.b),
        }
    }

    /// Exact: E y = Aμ + b, cov y = A C Aᵀ, cov(x, y) = C Aᵀ (any distribution).
    pub fn exact(&self, mu: &OVector<f64, N>, c: &OMatrix<f64, N, N>) -> Moments<f64, N, M> {
        Moments {
            mean: &self.a * mu + &self.b,
            covariance: &self.a * c * self.a.transpose(),
            cross_covariance: c * self.a.transpose(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Quadratic functions
// ---------------------------------------------------------------------------------------------

/// gₖ(x) = xᵀ Qₖ x + aₖᵀ x + cₖ with symmetric Qₖ; a zero Qₖ is reported as affine (`None`).
#[derive(Clone, Debug)]
pub struct Quadratic<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Q₀ … Q_{m−1}, symmetric.
    pub q: Vec<OMatrix<T, N, N>>,
    /// Rows aₖᵀ (m × n).
    pub a: OMatrix<T, M, N>,
    /// c (m).
    pub c: OVector<T, M>,
}

impl<T: Real, N: Dim, M: Dim> VectorFunction<T, N, M> for Quadratic<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        let mut y = self.c.clone();
        y.gemv(T::one(), &self.a, x, T::one());
        for (k, q) in self.q.iter().enumerate() {
            y[k] += x.dot(&(q * x));
        }
        y
    }
}

impl<T: Real, N: Dim, M: Dim> Differentiable<T, N, M> for Quadratic<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        let mut j = self.a.clone();
        let two = T::one() + T::one();
        for (k, q) in self.q.iter().enumerate() {
            let qx = q * x;
            for i in 0..x.nrows() {
                j[(k, i)] += two * qx[i];
            }
        }
        j
    }
}

impl<T: Real, N: Dim, M: Dim> TwiceDifferentiable<T, N, M> for Quadratic<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn hessian(&self, _: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        let q = &self.q[k];
        if q.iter().all(|v| *v == T::zero()) {
            None
        } else {
            Some(q * (T::one() + T::one()))
        }
    }
}

impl<N: Dim, M: Dim> Quadratic<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The same function in f32.
    pub fn to_f32(&self) -> Quadratic<f32, N, M> {
        Quadratic {
            q: self.q.iter().map(to32).collect(),
            a: to32(&self.a),
            c: to32(&self.c),
        }
    }

    /// bₖ = ∇gₖ(μ) = 2 Qₖ μ + aₖ, as the rows of an m × n matrix (the Jacobian at μ).
    pub fn gradients(&self, mu: &OVector<f64, N>) -> OMatrix<f64, M, N> {
        self.jacobian(mu)
    }

    /// Exact moments for Gaussian x. With e = x − μ, gₖ(x) = gₖ(μ) + bₖᵀe + eᵀQₖe, so
    ///
    /// - E gₖ = gₖ(μ) + tr(Qₖ C) (any distribution with covariance C),
    /// - cov(gₖ, gₗ) = bₖᵀ C bₗ + cov(eᵀQₖe, eᵀQₗe) = bₖᵀ C bₗ + 2 tr(Qₖ C Qₗ C): the cross
    ///   terms cov(bᵀe, eᵀQe) are third moments (zero), and Isserlis' theorem gives
    ///   E[eᵀAe eᵀBe] = tr(AC) tr(BC) + 2 tr(ACBC) for symmetric A, B. Expanding
    ///   bₖ = 2Qₖμ + aₖ reproduces 2tr(QₖCQₗC) + 4μᵀQₖCQₗμ plus the linear terms
    ///   aₖᵀCaₗ + 2aₖᵀCQₗμ + 2μᵀQₖCaₗ,
    /// - cov(x, gₖ) = E[e (bₖᵀe + eᵀQₖe)] = C bₖ (third moments vanish).
    pub fn exact(&self, mu: &OVector<f64, N>, c: &OMatrix<f64, N, N>) -> Moments<f64, N, M> {
        let b = self.gradients(mu);
        let mut mean = self.eval(mu);
        for (k, q) in self.q.iter().enumerate() {
            mean[k] += (q * c).trace();
        }
        let mut covariance = &b * c * b.transpose();
        for (k, qk) in self.q.iter().enumerate() {
            for (l, ql) in self.q.iter().enumerate() {
                covariance[(k, l)] += 2.0 * (qk * c * ql * c).trace();
            }
        }
        Moments {
            mean,
            covariance,
            cross_covariance: c * b.transpose(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Sums of (c₀ + bᵀx) cos(aᵀx + φ)
// ---------------------------------------------------------------------------------------------

/// One term (c₀ + bᵀx)·cos(aᵀx + φ). With a = 0 it is affine; with b = 0 a pure sinusoid
/// (sin z = cos(z − π/2)).
#[derive(Clone, Debug)]
pub struct Term<T: Real, N: Dim>
where
    DefaultAllocator: Allocator<N>,
{
    /// c₀.
    pub c0: T,
    /// b.
    pub b: OVector<T, N>,
    /// a.
    pub a: OVector<T, N>,
    /// φ.
    pub phase: T,
}

impl<T: Real, N: Dim> Term<T, N>
where
    DefaultAllocator: Allocator<N>,
{
    fn is_affine(&self) -> bool {
        self.a.iter().all(|v| *v == T::zero())
    }
}

impl<N: Dim> Term<f64, N>
where
    DefaultAllocator: Allocator<N>,
{
    fn to_f32(&self) -> Term<f32, N> {
        Term {
            c0: self.c0 as f32,
            b: to32(&self.b),
            a: to32(&self.a),
            phase: self.phase as f32,
        }
    }
}

/// gₖ(x) = Σ over the terms of output k of (c₀ + bᵀx)·cos(aᵀx + φ).
///
/// Every moment of such a g under a Gaussian x has a closed form ([`TrigSum::exact`]), and
/// its Taylor remainders have explicit bounds ([`taylor_bounds`]), so the approximations can
/// be checked against the truth with a tolerance that is a proof, not a guess.
#[derive(Clone, Debug)]
pub struct TrigSum<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The output dimension.
    pub m: M,
    /// The terms of each output component.
    pub outputs: Vec<Vec<Term<T, N>>>,
}

impl<T: Real, N: Dim, M: Dim> VectorFunction<T, N, M> for TrigSum<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        OVector::from_fn_generic(self.m, U1, |k, _| {
            self.outputs[k].iter().fold(T::zero(), |s, t| {
                s + (t.c0 + t.b.dot(x)) * (t.a.dot(x) + t.phase).cos()
            })
        })
    }
}

impl<T: Real, N: Dim, M: Dim> Differentiable<T, N, M> for TrigSum<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// ∇[(c₀ + bᵀx) cos ψ] = b cos ψ − (c₀ + bᵀx) sin ψ a, ψ = aᵀx + φ.
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        let n = x.shape_generic().0;
        let mut j = OMatrix::zeros_generic(self.m, n);
        for (k, terms) in self.outputs.iter().enumerate() {
            for t in terms {
                let u = t.c0 + t.b.dot(x);
                let (s, c) = (t.a.dot(x) + t.phase).sin_cos();
                for i in 0..x.nrows() {
                    j[(k, i)] += t.b[i] * c - u * s * t.a[i];
                }
            }
        }
        j
    }
}

impl<T: Real, N: Dim, M: Dim> TwiceDifferentiable<T, N, M> for TrigSum<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// ∇²[(c₀ + bᵀx) cos ψ] = −sin ψ (b aᵀ + a bᵀ) − (c₀ + bᵀx) cos ψ a aᵀ.
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        let terms = &self.outputs[k];
        if terms.iter().all(Term::is_affine) {
            return None;
        }
        let n = x.shape_generic().0;
        let mut h = OMatrix::zeros_generic(n, n);
        for t in terms {
            let u = t.c0 + t.b.dot(x);
            let (s, c) = (t.a.dot(x) + t.phase).sin_cos();
            for j in 0..x.nrows() {
                for i in 0..x.nrows() {
                    h[(i, j)] += -s * (t.b[i] * t.a[j] + t.a[i] * t.b[j]) - u * c * t.a[i] * t.a[j];
                }
            }
        }
        Some(h)
    }
}

/// (2k − 1)!! = E z²ᵏ for z ~ N(0, 1), and 1 for k ≤ 0.
fn gaussian_moment(two_k: i32) -> f64 {
    let mut r = 1.0;
    let mut i = two_k - 1;
    while i > 1 {
        r *= i as f64;
        i -= 2;
    }
    r
}

fn factorial(q: i32) -> f64 {
    (1..=q).fold(1.0, |r, i| r * i as f64)
}

impl<N: Dim, M: Dim> TrigSum<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The function of Boje's worked examples and the brief, ℝ³ → ℝ³:
    ///
    /// ```text
    /// g₀ = x₀ cos x₁
    /// g₁ = sin x₀ cos x₁ = ½ sin(x₀ + x₁) + ½ sin(x₀ − x₁)
    /// g₂ = x₂ sin x₁ + ½ x₀
    /// ```
    pub fn products(n: N, m: M) -> Self {
        assert_eq!((n.value(), m.value()), (3, 3));
        let e = |i| unit(n, i);
        let zero = OVector::zeros_generic(n, U1);
        let half_pi = std::f64::consts::FRAC_PI_2;
        let term = |c0, b: OVector<f64, N>, a: OVector<f64, N>, phase| Term { c0, b, a, phase };
        Self {
            m,
            outputs: vec![
                vec![term(0.0, e(0), e(1), 0.0)],
                vec![
                    term(0.5, zero.clone(), e(0) + e(1), -half_pi),
                    term(0.5, zero.clone(), e(0) - e(1), -half_pi),
                ],
                vec![
                    term(0.0, e(2), e(1), -half_pi),
                    term(0.0, e(0) * 0.5, zero.clone(), 0.0),
                ],
            ],
        }
    }

    /// A random sum: output k has two terms with c₀, b, a, φ taken in turn from `p`
    /// (needs m·2·(2n + 2) numbers; a is scaled to entries in [−1, 1]).
    pub fn random(n: N, m: M, p: &[f64]) -> Self {
        let dim = n.value();
        let mut it = p.iter().copied();
        let mut next = || it.next().expect("enough parameters");
        let outputs = (0..m.value())
            .map(|_| {
                (0..2)
                    .map(|_| {
                        let c0 = next();
                        let b = OVector::from_fn_generic(n, U1, |_, _| next());
                        let a = OVector::from_fn_generic(n, U1, |_, _| next());
                        let phase = next() * std::f64::consts::PI;
                        Term { c0, b, a, phase }
                    })
                    .collect()
            })
            .collect();
        let _ = dim;
        Self { m, outputs }
    }

    /// The number of parameters [`TrigSum::random`] needs.
    pub fn random_len(n: usize, m: usize) -> usize {
        m * 2 * (2 * n + 2)
    }

    /// The same function in f32.
    pub fn to_f32(&self) -> TrigSum<f32, N, M> {
        TrigSum {
            m: self.m,
            outputs: self
                .outputs
                .iter()
                .map(|ts| ts.iter().map(Term::to_f32).collect())
                .collect(),
        }
    }

    /// Exact moments for x ~ N(μ, C).
    ///
    /// For a term (p + bᵀe)(q + b'ᵀe) cos(ψ + aᵀe), with p, q the linear factors at μ, the
    /// Gaussian characteristic function E e^{i aᵀe} = e^{−v/2}, v = aᵀCa, and its derivatives
    /// E[e e^{i aᵀe}] = i C a e^{−v/2}, E[e eᵀ e^{i aᵀe}] = (C − C a aᵀ C) e^{−v/2} give
    ///
    /// ```text
    /// E[(p + bᵀe)(q + b'ᵀe) e^{i(ψ + aᵀe)}]
    ///     = e^{iψ − v/2} [p q + bᵀCb' − β β' + i (p β' + q β)],   β = bᵀCa, β' = b'ᵀCa
    /// ```
    ///
    /// whose real part is the expectation with cos. Products of two terms use
    /// cos X cos Y = ½[cos(X + Y) + cos(X − Y)]; the cross-covariance uses
    /// E[e (p + bᵀe) e^{i(ψ + aᵀe)}] = e^{iψ − v/2} [C b − C a β + i p C a].
    pub fn exact(&self, mu: &OVector<f64, N>, c: &OMatrix<f64, N, N>) -> Moments<f64, N, M> {
        let m = self.outputs.len();
        let n_dim = mu.shape_generic().0;
        // Re E[(p + bᵀe)(q + b'ᵀe) cos(ψ + aᵀe)].
        let pair = |p: f64,
                    b: &OVector<f64, N>,
                    q: f64,
                    b2: &OVector<f64, N>,
                    psi: f64,
                    a: &OVector<f64, N>| {
            let ca = c * a;
            let v = a.dot(&ca);
            let (beta, beta2) = (b.dot(&ca), b2.dot(&ca));
            let re = p * q + b.dot(&(c * b2)) - beta * beta2;
            let im = p * beta2 + q * beta;
            (-v / 2.0).exp() * (re * psi.cos() - im * psi.sin())
        };
        let zero = OVector::<f64, N>::zeros_generic(n_dim, U1);
        let lin = |t: &Term<f64, N>| t.c0 + t.b.dot(mu);
        let psi = |t: &Term<f64, N>| t.a.dot(mu) + t.phase;

        let mut mean = OVector::<f64, M>::zeros_generic(self.m, U1);
        let mut second = OMatrix::<f64, M, M>::zeros_generic(self.m, self.m);
        let mut cross = OMatrix::<f64, N, M>::zeros_generic(n_dim, self.m);
        for k in 0..m {
            for t in &self.outputs[k] {
                mean[k] += pair(lin(t), &t.b, 1.0, &zero, psi(t), &t.a);
                let ca = c * &t.a;
                let beta = t.b.dot(&ca);
                let v = t.a.dot(&ca);
                let (s, co) = psi(t).sin_cos();
                let col = ((c * &t.b - &ca * beta) * co - &ca * (lin(t) * s)) * (-v / 2.0).exp();
                let mut target = cross.column_mut(k);
                target += col;
            }
            for l in 0..m {
                for t in &self.outputs[k] {
                    for t2 in &self.outputs[l] {
                        let sum = pair(
                            lin(t),
                            &t.b,
                            lin(t2),
                            &t2.b,
                            psi(t) + psi(t2),
                            &(&t.a + &t2.a),
                        );
                        let dif = pair(
                            lin(t),
                            &t.b,
                            lin(t2),
                            &t2.b,
                            psi(t) - psi(t2),
                            &(&t.a - &t2.a),
                        );
                        second[(k, l)] += 0.5 * (sum + dif);
                    }
                }
            }
        }
        let covariance = second - &mean * mean.transpose();
        Moments {
            mean,
            covariance,
            cross_covariance: cross,
        }
    }

    /// Per output k, Σ over its terms of (|c₀| + |b|ᵀX)(1 + |a|ᵀX + |φ|), X = |μ| + spread:
    /// a majorant of the magnitudes that enter gₖ and its derivatives at points within
    /// `spread` of μ, in units where cos/sin argument errors are counted (an absolute error
    /// δψ in ψ moves cos ψ by ≤ δψ, and δψ ≤ γ (|a|ᵀX + |φ|)). Round-off allowances are
    /// multiples of ε times this.
    pub fn magnitude(&self, mu: &OVector<f64, N>, spread: &OVector<f64, N>) -> OVector<f64, M> {
        let x = abs(mu) + spread;
        OVector::from_fn_generic(self.m, U1, |k, _| {
            self.outputs[k].iter().fold(0.0, |s, t| {
                s + (t.c0.abs() + abs(&t.b).dot(&x)) * (1.0 + abs(&t.a).dot(&x) + t.phase.abs())
            })
        })
    }

    /// An upper bound on ‖Rq‖₂ = (E Rq(e)²)^½ for output k, where Rq = gₖ(μ + e) minus its
    /// Taylor polynomial of degree q − 1 at μ, e ~ N(0, C).
    ///
    /// For one term (p + bᵀe) w(e), w = cos(ψ + aᵀe), the Taylor polynomial of degree q − 1 is
    /// p T_{q−1}[w] + bᵀe T_{q−2}[w], so Rq = p R_q[w] + bᵀe R_{q−1}[w], and Lagrange's
    /// remainder with |cos⁽ʲ⁾| ≤ 1 gives |R_j[w]| ≤ |aᵀe|ʲ / j!. Then Minkowski and
    /// Cauchy–Schwarz with E(aᵀe)²ʲ = vʲ (2j − 1)!!, v = aᵀCa, E(bᵀe)⁴ = 3 (bᵀCb)²:
    ///
    /// ```text
    /// ‖Rq‖₂ ≤ |p| v^{q/2} √((2q−1)!!) / q!  +  (3 (bᵀCb)²)^¼ (v^{2q−2} (4q−5)!!)^¼ / (q−1)!
    /// ```
    ///
    /// (for q = 1 the second part is √(bᵀCb)). Terms add by Minkowski.
    pub fn remainder_l2(
        &self,
        k: usize,
        q: i32,
        mu: &OVector<f64, N>,
        c: &OMatrix<f64, N, N>,
    ) -> f64 {
        self.outputs[k].iter().fold(0.0, |s, t| {
            let p = t.c0 + t.b.dot(mu);
            let v = t.a.dot(&(c * &t.a)).max(0.0);
            let wb = t.b.dot(&(c * &t.b)).max(0.0);
            let first =
                p.abs() * v.powf(q as f64 / 2.0) * gaussian_moment(2 * q).sqrt() / factorial(q);
            let second = if q == 1 {
                wb.sqrt()
            } else {
                (3.0 * wb * wb).powf(0.25)
                    * (v.powi(2 * q - 2) * gaussian_moment(4 * q - 4)).powf(0.25)
                    / factorial(q - 1)
            };
            s + first + second
        })
    }

    /// A pointwise bound on |Rq(d)| for output k at a fixed deviation d (same remainder as
    /// [`remainder_l2`](Self::remainder_l2)): Σ |p| |aᵀd|^q / q! + |bᵀd| |aᵀd|^{q−1} / (q−1)!.
    /// Symmetric in d ↦ −d.
    pub fn remainder_at(&self, k: usize, q: i32, mu: &OVector<f64, N>, d: &OVector<f64, N>) -> f64 {
        self.outputs[k].iter().fold(0.0, |s, t| {
            let p = t.c0 + t.b.dot(mu);
            let ad = t.a.dot(d).abs();
            let bd = t.b.dot(d).abs();
            s + p.abs() * ad.powi(q) / factorial(q) + bd * ad.powi(q - 1) / factorial(q - 1)
        })
    }
}

/// Entrywise majorants of a [`TrigSum`] and its derivatives over the box |x − μ| ≤ spread,
/// each term weighted by its argument-size factor A = 1 + |a|ᵀX + |φ| (X = |μ| + spread):
/// cos ψ computed from a rounded ψ is off by up to the absolute error of ψ, which is
/// γ (|a|ᵀX + |φ|), so γ times a majorant bounds the round-off of the quantity it majorises.
///
/// For a term with U = |c₀| + |b|ᵀX ≥ |c₀ + bᵀx|: value U·A, gradient (|b| + U|a|)·A,
/// Hessian (|b||a|ᵀ + |a||b|ᵀ + U|a||a|ᵀ)·A.
#[derive(Clone, Debug)]
pub struct Majorants<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Values (m).
    pub value: OVector<f64, M>,
    /// Gradients, as rows (m × n).
    pub gradient: OMatrix<f64, M, N>,
    /// Hessians (m of n × n).
    pub hessian: Vec<OMatrix<f64, N, N>>,
}

impl<N: Dim, M: Dim> TrigSum<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// See [`Majorants`].
    pub fn majorants(&self, mu: &OVector<f64, N>, spread: &OVector<f64, N>) -> Majorants<N, M> {
        let n_dim = mu.shape_generic().0;
        let x = abs(mu) + spread;
        let mut value = OVector::<f64, M>::zeros_generic(self.m, U1);
        let mut gradient = OMatrix::<f64, M, N>::zeros_generic(self.m, n_dim);
        let mut hessian = Vec::new();
        for (k, terms) in self.outputs.iter().enumerate() {
            let mut h = OMatrix::<f64, N, N>::zeros_generic(n_dim, n_dim);
            for t in terms {
                let (ba, aa) = (abs(&t.b), abs(&t.a));
                let u = t.c0.abs() + ba.dot(&x);
                let arg = 1.0 + aa.dot(&x) + t.phase.abs();
                value[k] += u * arg;
                let g = (&ba + &aa * u) * arg;
                let mut row = gradient.row_mut(k);
                row += g.transpose();
                h += (&ba * aa.transpose() + &aa * ba.transpose() + &aa * aa.transpose() * u) * arg;
            }
            hessian.push(h);
        }
        Majorants {
            value,
            gradient,
            hessian,
        }
    }

    /// The longest chain of roundings in any quantity the tests compare, K = 4n² + 40: an
    /// n²-term Frobenius product or trace (⟨H, C⟩, tr(HCHC)), two n-term matrix products, the
    /// (n + 1)-term dots inside each term, ≤ 10 more for term sums, cos/sin and the final
    /// additions, doubled for the two sides of a comparison.
    pub fn chain(n: usize) -> usize {
        4 * n * n + 40
    }

    /// Round-off allowance of the derivative-based propagators (γ the working precision's):
    /// γ_K times the magnitudes of what they compute, g(μ) + ½⟨H, C⟩, JCJᵀ + ½tr(HCHC), CJᵀ,
    /// with majorants at μ.
    pub fn roundoff_derivative(
        &self,
        mu: &OVector<f64, N>,
        c: &OMatrix<f64, N, N>,
        g: fn(usize) -> f64,
    ) -> ApproxBounds<N, M> {
        let n = mu.nrows();
        let k = g(Self::chain(n));
        let zero = OVector::zeros_generic(mu.shape_generic().0, U1);
        let maj = self.majorants(mu, &zero);
        let ca = abs(c);
        let m_dim = self.m;
        let mean = OVector::from_fn_generic(m_dim, U1, |i, _| {
            k * (maj.value[i] + 0.5 * maj.hessian[i].dot(&ca))
        });
        let cov = OMatrix::from_fn_generic(m_dim, m_dim, |i, j| {
            k * ((maj.gradient.row(i) * &ca * maj.gradient.row(j).transpose())[(0, 0)]
                + 0.5 * (&maj.hessian[i] * &ca * &maj.hessian[j] * &ca).trace())
        });
        ApproxBounds {
            mean,
            cov,
            cross: &ca * maj.gradient.transpose() * k,
        }
    }

    /// Round-off allowance of the closed forms in [`TrigSum::exact`]: the covariance is
    /// E[gₖgₗ] − E gₖ E gₗ, so it carries γ_K times |gₖ||gₗ| (cancellation when the means
    /// dominate); the mean and cross-covariance γ_K times their majorants. Majorants over
    /// ±4σ bound the expectations' magnitudes up to the Gaussian tail, which only enters
    /// through e^{−v/2} ≤ 1 factors.
    pub fn roundoff_exact(
        &self,
        mu: &OVector<f64, N>,
        c: &OMatrix<f64, N, N>,
        g: fn(usize) -> f64,
    ) -> ApproxBounds<N, M> {
        let n = mu.nrows();
        let k = g(Self::chain(n));
        let maj = self.majorants(mu, &(std_devs(c) * 4.0));
        ApproxBounds {
            mean: &maj.value * k,
            cov: &maj.value * maj.value.transpose() * k,
            cross: abs(c) * maj.gradient.transpose() * k,
        }
    }

    /// Round-off allowance of the unscented transform (first order in ε), as derived for
    /// affine g in `linear.rs`, with the majorants over the sigma-point box standing in for
    /// |A|: with c = α²(n + κ), w = 1/(2c), L the Cholesky factor, Y and G the value and
    /// gradient majorants at spread √c|L|1, each deviation dᵢ is off by e = 2γ_K Y, and
    /// w Σᵢ|dᵢ| ≤ wD = G|L|1/√c (mean value theorem). Then
    /// mean: δ = n e/c, plus γ_{2n} wD, plus γ_K Y for g(μ);
    /// covariance: wD eᵀ + e wDᵀ + γ_{3n+2} Σⱼ (G|Lⱼ|)(G|Lⱼ|)ᵀ + |β − α²|(δ wDᵀ + wD δᵀ + δδᵀ);
    /// cross: |L|1 eᵀ/√c + γ_{3n+2} Σⱼ |Lⱼ|(G|Lⱼ|)ᵀ.
    pub fn roundoff_unscented(
        &self,
        mu: &OVector<f64, N>,
        c: &OMatrix<f64, N, N>,
        (alpha, beta, kappa): (f64, f64, f64),
        g: fn(usize) -> f64,
    ) -> ApproxBounds<N, M> {
        let n = mu.nrows();
        let n_dim = mu.shape_generic().0;
        let scale = alpha * alpha * (n as f64 + kappa);
        let root = scale.sqrt();
        let la = abs(&psd_factor(c, Stage::Propagation).expect("PSD covariance"));
        let ones = OVector::<f64, N>::from_element_generic(n_dim, U1, 1.0);
        let l1 = &la * &ones;
        let maj = self.majorants(mu, &(&l1 * root));
        let k = g(Self::chain(n));
        let e = &maj.value * (2.0 * k);
        let wd = &maj.gradient * &l1 / root;
        let delta = &e * (n as f64 / scale);
        let gl = &maj.gradient * &la;
        let mean = &delta + &wd * g(2 * n) + &maj.value * k;
        let cov = &wd * e.transpose()
            + &e * wd.transpose()
            + &gl * gl.transpose() * g(3 * n + 2)
            + (&delta * wd.transpose() + &wd * delta.transpose() + &delta * delta.transpose())
                * (beta - alpha * alpha).abs();
        let cross = &l1 * e.transpose() / root + &la * gl.transpose() * g(3 * n + 2);
        ApproxBounds { mean, cov, cross }
    }
}

/// Bounds on |approximation − exact| for the mean, covariance and cross-covariance.
#[derive(Clone, Debug)]
pub struct ApproxBounds<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Mean (m).
    pub mean: OVector<f64, M>,
    /// Covariance (m × m).
    pub cov: OMatrix<f64, M, M>,
    /// Cross-covariance (n × m).
    pub cross: OMatrix<f64, N, M>,
}

/// Truncation bounds of the derivative-based propagators.
#[derive(Clone, Debug)]
pub struct TaylorBounds<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// [`estim_core::Linearized`]: mean error O(σ²), covariance O(σ⁴).
    pub linearized: ApproxBounds<N, M>,
    /// [`estim_core::SecondOrder`]: mean O(σ⁴), covariance O(σ⁴).
    pub second_order: ApproxBounds<N, M>,
    /// [`estim_core::SecondOrderGaussian`]: mean O(σ⁴), covariance O(σ⁴).
    pub gaussian: ApproxBounds<N, M>,
}

/// Rigorous truncation bounds for the derivative-based propagators on a [`TrigSum`].
///
/// Write yₖ = gₖ(μ) + Lₖ + Qₖ + R₃ₖ with Lₖ = Jₖe, Qₖ = ½ eᵀHₖe, R₂ₖ = Qₖ + R₃ₖ, R₄ the
/// remainder after the cubic Cₖ. Odd Gaussian moments vanish, so E Lₖ = E Cₖ = 0,
/// cov(Lₖ, Qₗ) = 0 and cov(e, Qₖ) = 0; every other covariance is bounded by
/// |cov(A, B)| ≤ ‖A‖₂ ‖B‖₂. Hence, with ‖Lₖ‖² = JₖCJₖᵀ and
/// ‖Qₖ‖² = ¼ (tr(HₖC)² + 2 tr(HₖCHₖC)):
///
/// ```text
/// |g(μ) − E y|                ≤ min(‖R₂‖, |½tr(HC)| + ‖R₄‖)         (O(σ²))
/// |g(μ) + ½tr(HC) − E y|      = |E R₄| ≤ ‖R₄‖                      (O(σ⁴))
/// |JCJᵀ − cov y|ₖₗ            ≤ ‖Lₖ‖‖R₃ₗ‖ + ‖R₃ₖ‖‖Lₗ‖ + ‖R₂ₖ‖‖R₂ₗ‖ (O(σ⁴))
/// |JCJᵀ + ½tr(HₖCHₗC) − cov|  ≤ ‖Lₖ‖‖R₃ₗ‖ + ‖R₃ₖ‖‖Lₗ‖ + ‖Qₖ‖‖R₃ₗ‖ + ‖R₃ₖ‖‖Qₗ‖ + ‖R₃ₖ‖‖R₃ₗ‖
/// |CJᵀ − cov(x, y)|ᵢₖ         ≤ √Cᵢᵢ ‖R₃ₖ‖                         (O(σ⁴))
/// ```
///
/// (cov(Qₖ, Qₗ) = ½ tr(HₖCHₗC) exactly, by Isserlis.) Note that the Gaussian second-order
/// covariance is not of higher order than the linear one for non-quadratic g: the term
/// cov(Lₖ, Cₗ) of the cubic is O(σ⁴) too; it only removes the ‖R₂‖‖R₂‖ part.
pub fn taylor_bounds<N: Dim, M: Dim>(
    f: &TrigSum<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
) -> TaylorBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let m = f.outputs.len();
    let n_dim = mu.shape_generic().0;
    let j = f.jacobian(mu);
    let (mut l, mut qn, mut half_tr, mut r2, mut r3, mut r4) = (
        vec![0.0; m],
        vec![0.0; m],
        vec![0.0; m],
        vec![0.0; m],
        vec![0.0; m],
        vec![0.0; m],
    );
    for k in 0..m {
        let jk = j.row(k);
        l[k] = (jk * c * jk.transpose())[(0, 0)].max(0.0).sqrt();
        if let Some(h) = f.hessian(mu, k) {
            let hc = &h * c;
            let tr = hc.trace();
            qn[k] = 0.5 * (tr * tr + 2.0 * hc.tr_dot(&hc)).max(0.0).sqrt();
            half_tr[k] = 0.5 * tr;
        }
        r3[k] = f.remainder_l2(k, 3, mu, c);
        r4[k] = f.remainder_l2(k, 4, mu, c);
        r2[k] = f.remainder_l2(k, 2, mu, c).min(qn[k] + r3[k]);
    }
    let lin_mean = OVector::from_fn_generic(f.m, U1, |k, _| r2[k].min(half_tr[k].abs() + r4[k]));
    let so_mean = OVector::from_fn_generic(f.m, U1, |k, _| r4[k]);
    let lin_cov =
        OMatrix::from_fn_generic(f.m, f.m, |k, i| l[k] * r3[i] + r3[k] * l[i] + r2[k] * r2[i]);
    let sog_cov = OMatrix::from_fn_generic(f.m, f.m, |k, i| {
        l[k] * r3[i] + r3[k] * l[i] + qn[k] * r3[i] + r3[k] * qn[i] + r3[k] * r3[i]
    });
    let cross = OMatrix::from_fn_generic(n_dim, f.m, |i, k| c[(i, i)].sqrt() * r3[k]);
    TaylorBounds {
        linearized: ApproxBounds {
            mean: lin_mean,
            cov: lin_cov.clone(),
            cross: cross.clone(),
        },
        second_order: ApproxBounds {
            mean: so_mean.clone(),
            cov: lin_cov.clone(),
            cross: cross.clone(),
        },
        gaussian: ApproxBounds {
            mean: so_mean,
            cov: sog_cov,
            cross,
        },
    }
}

/// Rigorous bounds on |unscented − exact| for a [`TrigSum`], for the scaled transform with
/// parameters (α, β, κ): c = α²(n + κ), sⱼ = √c Lⱼ (L the lower Cholesky factor of C, as the
/// library uses), w = 1/(2c), and ρ±ⱼ = g(μ ± sⱼ) − g(μ) ∓ J sⱼ = R₂(±sⱼ).
///
/// - Mean: the symmetric sigma points integrate polynomials of degree ≤ 3 exactly under
///   N(μ, C) (linear and cubic parts cancel in ± pairs, the quadratic one gives ½tr(HC)), so
///   unscented − exact = w Σᵢ R₄(dᵢ) − E R₄, bounded by w Σⱼ 2 r₄(sⱼ) + ‖R₄‖.
/// - Covariance: w Σᵢ dᵢdᵢᵀ = JCJᵀ + w Σⱼ [Jsⱼ(ρ⁺ⱼ − ρ⁻ⱼ)ᵀ + (ρ⁺ⱼ − ρ⁻ⱼ)(Jsⱼ)ᵀ + ρ⁺ρ⁺ᵀ + ρ⁻ρ⁻ᵀ],
///   with |ρ⁺ⱼ − ρ⁻ⱼ| = |R₃(sⱼ) − R₃(−sⱼ)| ≤ 2 r₃(sⱼ), |ρ±ⱼ| ≤ r₂(sⱼ), and the extra
///   (β − α²) d̄d̄ᵀ with |d̄| = |w Σⱼ (ρ⁺ⱼ + ρ⁻ⱼ)| ≤ w Σⱼ 2 r₂(sⱼ); then add the bound on
///   |JCJᵀ − cov y| from [`taylor_bounds`].
/// - Cross-covariance: w Σⱼ sⱼ (d⁺ⱼ − d⁻ⱼ)ᵀ = CJᵀ + w Σⱼ sⱼ (ρ⁺ⱼ − ρ⁻ⱼ)ᵀ, plus the
///   |CJᵀ − cov(x, y)| bound.
///
/// rq(d) is [`TrigSum::remainder_at`]. Every piece is O(σ⁴).
pub fn unscented_bounds<N: Dim, M: Dim>(
    f: &TrigSum<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    (alpha, beta, kappa): (f64, f64, f64),
) -> ApproxBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = mu.nrows();
    let m = f.outputs.len();
    let scale = alpha * alpha * (n as f64 + kappa);
    let w = 1.0 / (2.0 * scale);
    let lower = psd_factor(c, Stage::Propagation).expect("PSD covariance");
    let j = f.jacobian(mu);
    let taylor = taylor_bounds(f, mu, c);
    let mut mean = taylor.second_order.mean.clone();
    let mut cov = taylor.linearized.cov.clone();
    let mut cross = taylor.linearized.cross.clone();
    let mut dbar = vec![0.0; m];
    for col in 0..n {
        let s = lower.column(col) * scale.sqrt();
        let js = &j * &s;
        let r2: Vec<f64> = (0..m).map(|k| f.remainder_at(k, 2, mu, &s)).collect();
        let r3: Vec<f64> = (0..m).map(|k| f.remainder_at(k, 3, mu, &s)).collect();
        for k in 0..m {
            mean[k] += w * 2.0 * f.remainder_at(k, 4, mu, &s);
            dbar[k] += w * 2.0 * r2[k];
            for l in 0..m {
                cov[(k, l)] += w
                    * (js[k].abs() * 2.0 * r3[l] + 2.0 * r3[k] * js[l].abs() + 2.0 * r2[k] * r2[l]);
            }
            for i in 0..n {
                cross[(i, k)] += w * s[i].abs() * 2.0 * r3[k];
            }
        }
    }
    for k in 0..m {
        for l in 0..m {
            cov[(k, l)] += (beta - alpha * alpha).abs() * dbar[k] * dbar[l];
        }
    }
    ApproxBounds { mean, cov, cross }
}

// ---------------------------------------------------------------------------------------------
// Boje's eq 5
// ---------------------------------------------------------------------------------------------

/// Boje's eq 5: (ẍ, ÿ, θ̈, θ̇²) = ½ M(θ) (a_u1, a_v1, a_u2, a_v2) with
///
/// ```text
///        ⎡  cos θ  −sin θ   cos θ  −sin θ ⎤
/// M(θ) = ⎢  sin θ   cos θ   sin θ   cos θ ⎥
///        ⎢    0      1/R      0     −1/R  ⎥
///        ⎣  −1/R      0      1/R      0   ⎦
/// ```
///
/// as a function of the 5-vector x = (a_u1, a_v1, a_u2, a_v2, θ), every entry random.
#[derive(Clone, Copy, Debug)]
pub struct Boje<T> {
    /// Half the distance between the two accelerometers.
    pub r: T,
}

use estim_core::nalgebra::{Matrix4, Matrix4x5, Matrix5, U4, U5, Vector4, Vector5};

impl<T: Real> Boje<T> {
    /// ½ M(θ).
    pub fn matrix(&self, theta: T) -> Matrix4<T> {
        let (s, c) = theta.sin_cos();
        let (z, ir) = (T::zero(), T::one() / self.r);
        let half: T = estim_core::scalar::real(0.5);
        Matrix4::new(
            c, -s, c, -s, //
            s, c, s, c, //
            z, ir, z, -ir, //
            -ir, z, ir, z,
        ) * half
    }

    /// ½ dM/dθ.
    fn matrix_derivative(&self, theta: T) -> Matrix4<T> {
        let (s, c) = theta.sin_cos();
        let z = T::zero();
        let half: T = estim_core::scalar::real(0.5);
        Matrix4::new(
            -s, -c, -s, -c, //
            c, -s, c, -s, //
            z, z, z, z, //
            z, z, z, z,
        ) * half
    }
}

impl<T: Real> VectorFunction<T, U5, U4> for Boje<T> {
    fn eval(&self, x: &Vector5<T>) -> Vector4<T> {
        self.matrix(x[4]) * x.fixed_rows::<4>(0)
    }
}

impl<T: Real> Differentiable<T, U5, U4> for Boje<T> {
    fn jacobian(&self, x: &Vector5<T>) -> Matrix4x5<T> {
        let mut j = Matrix4x5::zeros();
        j.fixed_columns_mut::<4>(0).copy_from(&self.matrix(x[4]));
        j.set_column(4, &(self.matrix_derivative(x[4]) * x.fixed_rows::<4>(0)));
        j
    }
}

impl<T: Real> TwiceDifferentiable<T, U5, U4> for Boje<T> {
    /// Rows 0, 1 are bilinear in (a, θ) and trigonometric in θ; rows 2, 3 are linear.
    fn hessian(&self, x: &Vector5<T>, k: usize) -> Option<Matrix5<T>> {
        if k >= 2 {
            return None;
        }
        let (s, c) = x[4].sin_cos();
        let half: T = estim_core::scalar::real(0.5);
        let a = x.fixed_rows::<4>(0);
        // ∂/∂θ of row k of ½M: the mixed second derivatives ∂²/∂aᵢ∂θ.
        let dm = self.matrix_derivative(x[4]);
        let mut h = Matrix5::zeros();
        for i in 0..4 {
            h[(i, 4)] = dm[(k, i)];
            h[(4, i)] = dm[(k, i)];
        }
        let (su, sv) = (a[0] + a[2], a[1] + a[3]);
        h[(4, 4)] = if k == 0 {
            // ẍ = ½(cos θ Su − sin θ Sv)
            half * (-c * su + s * sv)
        } else {
            // ÿ = ½(sin θ Su + cos θ Sv)
            half * (-s * su - c * sv)
        };
        Some(h)
    }
}

impl Boje<f64> {
    /// The same map as a [`TrigSum`] (for its exact moments and bounds):
    /// ẍ = ½Su cos θ + ½Sv cos(θ + π/2), ÿ = ½Su cos(θ − π/2) + ½Sv cos θ,
    /// θ̈ = (a_v1 − a_v2)/(2R), θ̇² = (a_u2 − a_u1)/(2R), with Su = a_u1 + a_u2,
    /// Sv = a_v1 + a_v2.
    pub fn as_trig_sum(&self) -> TrigSum<f64, U5, U4> {
        let e = |i| unit(U5, i);
        let zero = Vector5::zeros();
        let half_pi = std::f64::consts::FRAC_PI_2;
        let su = (e(0) + e(2)) * 0.5;
        let sv = (e(1) + e(3)) * 0.5;
        let term = |b: Vector5<f64>, a: Vector5<f64>, phase| Term {
            c0: 0.0,
            b,
            a,
            phase,
        };
        let ir = 1.0 / (2.0 * self.r);
        TrigSum {
            m: U4,
            outputs: vec![
                vec![term(su, e(4), 0.0), term(sv, e(4), half_pi)],
                vec![term(su, e(4), -half_pi), term(sv, e(4), 0.0)],
                vec![term((e(1) - e(3)) * ir, zero, 0.0)],
                vec![term((e(2) - e(0)) * ir, zero, 0.0)],
            ],
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Sampling standard errors
// ---------------------------------------------------------------------------------------------

/// Standard errors of the Monte Carlo estimates of a [`estim_core::Sampled`] run.
#[derive(Clone, Debug)]
pub struct SamplingError<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Of the mean: √(var yₖ / N).
    pub mean: OVector<f64, M>,
    /// Of the sample covariance: √(var[(yₖ − ȳₖ)(yₗ − ȳₗ)] / N).
    pub cov: OMatrix<f64, M, M>,
    /// Of the sample cross-covariance: √(var[(xᵢ − μᵢ)(yₖ − ȳₖ)] / N).
    pub cross: OMatrix<f64, N, M>,
}

impl<N: Dim, M: Dim> SamplingError<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Every standard error times `z`.
    pub fn scaled(&self, z: f64) -> Self {
        Self {
            mean: &self.mean * z,
            cov: &self.cov * z,
            cross: &self.cross * z,
        }
    }
}

/// Estimates the standard errors of a `samples`-draw Monte Carlo run from an independent
/// pilot run of `pilot` draws (own seed): the variance of each product (yₖ − ȳₖ)(yₗ − ȳₗ),
/// divided by N, is the variance of the corresponding sample-covariance entry to leading
/// order in 1/N, for any distribution with finite fourth moments. With `pilot` = 2·10⁴
/// the estimated standard errors are themselves accurate to a few percent, which the
/// z-factor absorbs. Deviations use g's `difference_into`, like the propagators.
pub fn sampling_error<N: Dim, M: Dim, G: VectorFunction<f64, N, M>>(
    g: &G,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    samples: usize,
    pilot: usize,
    seed: u64,
) -> SamplingError<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let lower = psd_factor(c, Stage::Propagation).expect("PSD covariance");
    let y0 = g.eval(mu);
    let (n_dim, m_dim) = (mu.shape_generic().0, y0.shape_generic().0);
    let mut rng = StdRng::seed_from_u64(seed);
    let mut dxs = Vec::with_capacity(pilot);
    let mut ds = Vec::with_capacity(pilot);
    for _ in 0..pilot {
        let z =
            OVector::<f64, N>::from_fn_generic(n_dim, U1, |_, _| StandardNormal.sample(&mut rng));
        let dx = &lower * z;
        let y = g.eval(&(mu + &dx));
        let mut d = y.clone();
        g.difference_into(&y, &y0, &mut d);
        ds.push(d);
        dxs.push(dx);
    }
    let count = pilot as f64;
    let dbar = ds
        .iter()
        .fold(OVector::<f64, M>::zeros_generic(m_dim, U1), |s, d| s + d)
        / count;
    let var_of = |f: &dyn Fn(usize) -> f64| {
        let vals: Vec<f64> = (0..pilot).map(f).collect();
        let mean = vals.iter().sum::<f64>() / count;
        vals.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (count - 1.0)
    };
    let n_ref = samples as f64;
    let mean = OVector::from_fn_generic(m_dim, U1, |k, _| {
        (var_of(&|i| ds[i][k] - dbar[k]) / n_ref).sqrt()
    });
    let cov = OMatrix::from_fn_generic(m_dim, m_dim, |k, l| {
        (var_of(&|i| (ds[i][k] - dbar[k]) * (ds[i][l] - dbar[l])) / n_ref).sqrt()
    });
    let cross = OMatrix::from_fn_generic(n_dim, m_dim, |i, k| {
        (var_of(&|s| dxs[s][i] * (ds[s][k] - dbar[k])) / n_ref).sqrt()
    });
    SamplingError { mean, cov, cross }
}

/// f32 round-off allowance for a [`estim_core::Sampled`] run, added to its sampling error:
/// (a) each deviation d = g(x) − g(μ) is off by at most `dev` (the caller's per-output bound,
/// e.g. 2γ₃₂(k) times the size of g's values), which moves the mean by `dev`, a covariance
/// entry by ≤ 2(devₖ σₗ + σₖ devₗ) and a cross entry by ≤ 2σₓᵢ devₖ (the factor 2 covers the
/// spread of |d| around σ); (b) the library's running sums of N terms are off by at most
/// γ₃₂(N + n + 2) Σ|terms| (naive summation), with Σ|dₖ|/N ≲ 2(σₖ + |E dₖ|) and
/// Σ|dₖdₗ|/N ≲ 2(σₖ + |E dₖ|)(σₗ + |E dₗ|), deviations being taken from g(μ).
pub fn sampled_f32_roundoff<N: Dim, M: Dim>(
    exact: &Moments<f64, N, M>,
    y_at_mean: &OVector<f64, M>,
    c: &OMatrix<f64, N, N>,
    dev: &OVector<f64, M>,
    samples: usize,
) -> ApproxBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = c.nrows();
    let sd_x = std_devs(c);
    let sd_y = exact.covariance.diagonal().map(|v| v.max(0.0).sqrt());
    let size = &sd_y + abs(&(&exact.mean - y_at_mean));
    let sums = 2.0 * gamma32(samples + n + 2);
    ApproxBounds {
        mean: dev + &size * sums,
        cov: (dev * sd_y.transpose() + &sd_y * dev.transpose()) * 2.0
            + &size * size.transpose() * sums,
        cross: &sd_x * dev.transpose() * 2.0 + &sd_x * size.transpose() * sums,
    }
}

impl<N: Dim, M: Dim> ApproxBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Entrywise sum of two bounds.
    pub fn plus(&self, other: &Self) -> Self {
        Self {
            mean: &self.mean + &other.mean,
            cov: &self.cov + &other.cov,
            cross: &self.cross + &other.cross,
        }
    }

    /// The standard errors as bounds.
    pub fn from_sampling(se: &SamplingError<N, M>) -> Self {
        Self {
            mean: se.mean.clone(),
            cov: se.cov.clone(),
            cross: se.cross.clone(),
        }
    }
}

/// Asserts every part of `got` is within `tol` of `want`.
#[track_caller]
pub fn assert_moments<N: Dim, M: Dim>(
    what: &str,
    got: &Moments<f64, N, M>,
    want: &Moments<f64, N, M>,
    tol: &ApproxBounds<N, M>,
) where
    DefaultAllocator: Alloc<N, M>,
{
    assert_within(&format!("{what} mean"), &got.mean, &want.mean, &tol.mean);
    assert_within(
        &format!("{what} covariance"),
        &got.covariance,
        &want.covariance,
        &tol.cov,
    );
    assert_within(
        &format!("{what} cross-covariance"),
        &got.cross_covariance,
        &want.cross_covariance,
        &tol.cross,
    );
}

/// Runs a propagator that must succeed.
#[track_caller]
pub fn propagate<T, P, G, N: Dim, M: Dim>(
    p: &P,
    mu: &OVector<T, N>,
    c: &OMatrix<T, N, N>,
    g: &G,
) -> Moments<T, N, M>
where
    T: Real,
    G: estim_core::VectorFunction<T, N, M>,
    P: estim_core::MomentPropagator<T, N, M, G>,
    DefaultAllocator: Alloc<N, M>,
{
    p.propagate(mu, c, g).expect("propagation succeeds")
}
