//! Quadratic gₖ(x) = xᵀQₖx + aₖᵀx + cₖ with Gaussian x: where each propagator is exact and
//! where it is not, against closed forms (derived in `common::Quadratic::exact`):
//!
//! - E gₖ = gₖ(μ) + tr(QₖC): `SecondOrder` (and `SecondOrderGaussian`, and every unscented
//!   set) reproduce it to round-off; `Linearized` misses tr(QₖC).
//! - cov(gₖ, gₗ) = bₖᵀCbₗ + 2 tr(QₖCQₗC), bₖ = 2Qₖμ + aₖ: `SecondOrderGaussian` reproduces
//!   it to round-off; `Linearized`/`SecondOrder` give exactly bₖᵀCbₗ (missing the trace term).
//! - cov(x, gₖ) = C bₖ: all derivative-based propagators.
//! - The unscented transform of a quadratic has its own closed form (below), checked to
//!   round-off; in one dimension with κ = 3 − n it is the exact covariance.
//! - `Sampled` with 10⁵ draws agrees with the exact moments within Z standard errors.
//!
//! Static (3 → 2, 6 → 4) and dynamic sizes, f64 and f32.

use crate::common;

use common::*;
use estim_core::linalg::psd_factor;
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1, U2, U3, U4, U6};
use estim_core::{
    Alloc, Linearized, MomentPropagator, Moments, Sampled, SecondOrder, SecondOrderGaussian, Stage,
    Unscented, VectorFunction,
};
use proptest::prelude::*;

const SAMPLES: usize = 100_000;
const SAMPLES_F32: usize = 10_000;
/// Pilot draws for the standard-error estimates (see `common::sampling_error`).
const PILOT: usize = 20_000;

/// Entrywise magnitudes of a quadratic problem, used by the round-off bounds:
/// `jh` = |a| + 2|Qₖ||μ| (majorant of the Jacobian rows), `mean` = |c| + |a||μ| + |μ|ᵀ|Qₖ||μ|
/// + ⟨|Qₖ|, |C|⟩, `qcqc[k][l]` = 2 tr(|Qₖ||C||Qₗ||C|).
struct Sizes<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    jh: OMatrix<f64, M, N>,
    mean: OVector<f64, M>,
    qcqc: OMatrix<f64, M, M>,
}

fn sizes<N: Dim, M: Dim>(
    f: &Quadratic<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
) -> Sizes<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (m_dim, mua, ca) = (f.c.shape_generic().0, abs(mu), abs(c));
    let qa: Vec<_> = f.q.iter().map(abs).collect();
    let mut jh = abs(&f.a);
    for (k, q) in qa.iter().enumerate() {
        let row = (q * &mua * 2.0).transpose();
        let mut target = jh.row_mut(k);
        target += row;
    }
    let mean = OVector::from_fn_generic(m_dim, U1, |k, _| {
        f.c[k].abs()
            + f.a.row(k).abs().dot(&mua.transpose())
            + mua.dot(&(&qa[k] * &mua))
            + qa[k].dot(&ca)
    });
    let qcqc = OMatrix::from_fn_generic(m_dim, m_dim, |k, l| {
        2.0 * (&qa[k] * &ca * &qa[l] * &ca).trace()
    });
    Sizes { jh, mean, qcqc }
}

/// Round-off bound of the derivative-based propagators against the closed forms (γ of the
/// working precision; each bound doubled because both sides round):
/// - mean: c + aμ + μᵀ(Qμ) + ⟨Q, C⟩ is a chain of at most n² + 2n + 3 roundings, each
///   relative to the magnitudes in `Sizes::mean`;
/// - covariance: J = a + 2Qμ is off by γ_{n+1} jh, and (JC)Jᵀ adds γ_{2n+1}: together
///   γ_{3n+3} jh|C|jhᵀ; the trace term ½tr(HₖCHₗC) (H = 2Q exact) is two n-term products and
///   an n²-term trace: γ_{n²+2n+2} · 2tr(|Qₖ||C||Qₗ||C|);
/// - cross-covariance: C Jᵀ, γ_{2n+1} |C| jhᵀ.
fn derivative_roundoff<N: Dim, M: Dim>(
    s: &Sizes<N, M>,
    c: &OMatrix<f64, N, N>,
    g: fn(usize) -> f64,
) -> ApproxBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = c.nrows();
    let ca = abs(c);
    ApproxBounds {
        mean: &s.mean * (2.0 * g(n * n + 2 * n + 3)),
        cov: (&s.jh * &ca * s.jh.transpose() * g(3 * n + 3) + &s.qcqc * g(n * n + 2 * n + 2)) * 2.0,
        cross: &ca * s.jh.transpose() * (2.0 * g(2 * n + 1)),
    }
}

/// The unscented transform of a quadratic, in closed form. With sⱼ = √c Lⱼ the deviations are
/// d±ⱼ = ±Jsⱼ + sⱼᵀQsⱼ exactly, so with qⱼₖ = LⱼᵀQₖLⱼ and w = 1/(2c):
///
/// ```text
/// mean  = g(μ) + w Σⱼ 2c qⱼ        = g(μ) + tr(Q LLᵀ)           (= exact mean)
/// cov   = J LLᵀ Jᵀ + c Σⱼ qⱼ qⱼᵀ + (β − α²) d̄ d̄ᵀ,  d̄ = tr(Q LLᵀ)
/// cross = w Σⱼ sⱼ (2Jsⱼ)ᵀ          = LLᵀ Jᵀ                     (= exact cross-covariance)
/// ```
///
/// The covariance is not the exact 2tr(QₖCQₗC) in general; in one dimension with c = 3
/// (κ = 3 − n, α = 1, β = 0) it is: 3q² − q² = 2q² = 2Q²C².
fn unscented_closed_form<N: Dim, M: Dim>(
    f: &Quadratic<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    (alpha, beta, kappa): (f64, f64, f64),
) -> Moments<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = mu.nrows();
    let scale = alpha * alpha * (n as f64 + kappa);
    let lower = psd_factor(c, Stage::Propagation).expect("SPD");
    let llt = &lower * lower.transpose();
    let j = f.gradients(mu);
    let m_dim = f.c.shape_generic().0;
    let dbar = OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| (&f.q[k] * &llt).trace());
    let mut cov = &j * &llt * j.transpose() + &dbar * dbar.transpose() * (beta - alpha * alpha);
    for col in 0..n {
        let l = lower.column(col);
        let q = OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| l.dot(&(&f.q[k] * l)));
        cov += &q * q.transpose() * scale;
    }
    Moments {
        mean: f.eval(mu) + dbar,
        covariance: cov,
        cross_covariance: &llt * j.transpose(),
    }
}

/// Round-off of the unscented transform against `unscented_closed_form` (same L), first order
/// in ε. With S = √c|L|, X = |μ| + S1 and Yₖ = |cₖ| + |aₖ|X + Xᵀ|Qₖ|X (the size of gₖ at the
/// sigma points), each deviation is off by ≤ e = 2γ_{2n+3} Y. Let
/// q̂ⱼₖ = |Lⱼ|ᵀ|Qₖ||Lⱼ| and wDₖ = w Σᵢ|dᵢₖ| ≤ jhₖ|L|1/√c + Σⱼ q̂ⱼₖ. Then:
/// - mean: n e/c (the 2n deviation errors times w) + γ_{2n} wD (the sum) + the closed
///   form's own γ_{n²+2n+3} mean size + γ_{n+1} tr(|Q||L||L|ᵀ) (Cholesky: the exact mean uses C,
///   not LLᵀ);
/// - covariance: wDₖeₗ + eₖwDₗ, plus γ_{2n+1} (product sums) + γ_{3n+3} (closed form) times
///   Σⱼ (jhₖ|Lⱼ| + √c q̂ⱼₖ)(jhₗ|Lⱼ| + √c q̂ⱼₗ) ≥ w Σᵢ|dᵢₖ||dᵢₗ|, plus the error of
///   (β − α²)d̄d̄ᵀ: |β − α²| (δₖ|d̄ₗ| + |d̄ₖ|δₗ + δₖδₗ) with δ the deviation part of the mean
///   error and |d̄ₖ| ≤ tr(|Qₖ||L||L|ᵀ), and the closed form's γ_{n²+n} |d̄ₖ||d̄ₗ|;
/// - cross: (|L|1) eᵀ/√c, plus γ_{2n+1} Σⱼ |Lⱼ|(jh|Lⱼ| + √c q̂ⱼ)ᵀ, plus Cholesky and the
///   closed form's γ_{2n+1}|L||L|ᵀjhᵀ (and γ_{2n+1}|C|jhᵀ when compared with the exact CJᵀ).
fn unscented_roundoff<N: Dim, M: Dim>(
    f: &Quadratic<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    (alpha, beta, kappa): (f64, f64, f64),
    g: fn(usize) -> f64,
) -> ApproxBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = mu.nrows();
    let (n_dim, m_dim) = (mu.shape_generic().0, f.c.shape_generic().0);
    let scale = alpha * alpha * (n as f64 + kappa);
    let root = scale.sqrt();
    let la = abs(&psd_factor(c, Stage::Propagation).expect("SPD"));
    let ones = OVector::<f64, N>::from_element_generic(n_dim, U1, 1.0);
    let s = sizes(f, mu, c);
    let qa: Vec<_> = f.q.iter().map(abs).collect();
    let x = abs(mu) + &la * &ones * root;
    let y = OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| {
        f.c[k].abs() + f.a.row(k).abs().dot(&x.transpose()) + x.dot(&(&qa[k] * &x))
    });
    let e = &y * (2.0 * g(2 * n + 3));
    let qh = |j: usize, k: usize| la.column(j).dot(&(&qa[k] * la.column(j)));
    let wd = OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| {
        (s.jh.row(k) * &la * &ones)[(0, 0)] / root + (0..n).map(|j| qh(j, k)).sum::<f64>()
    });
    let llt = &la * la.transpose();
    let chol =
        OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| g(n + 1) * (&qa[k] * &llt).trace());
    let mean_dev = &e * (n as f64 / scale);
    let mean = &mean_dev + &wd * g(2 * n) + &s.mean * g(n * n + 2 * n + 3) + &chol;
    let mut products = OMatrix::<f64, M, M>::zeros_generic(m_dim, m_dim);
    let mut cross_products = OMatrix::<f64, N, M>::zeros_generic(n_dim, m_dim);
    for j in 0..n {
        let lj = la.column(j);
        let v = OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| {
            s.jh.row(k).dot(&lj.transpose()) + root * qh(j, k)
        });
        products += &v * v.transpose();
        cross_products += lj * v.transpose();
    }
    let dbar = OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| (&qa[k] * &llt).trace());
    let cov = &wd * e.transpose()
        + &e * wd.transpose()
        + products * (g(2 * n + 1) + g(3 * n + 3))
        + (&mean_dev * mean_dev.transpose()
            + &mean_dev * dbar.transpose()
            + &dbar * mean_dev.transpose())
            * (beta - alpha * alpha).abs()
        + &dbar * dbar.transpose() * g(n * n + n);
    let cross = &la * &ones * e.transpose() / root
        + cross_products * g(2 * n + 1)
        + &llt * s.jh.transpose() * (g(n + 1) + g(2 * n + 1))
        + abs(c) * s.jh.transpose() * g(2 * n + 1);
    ApproxBounds { mean, cov, cross }
}

fn unscented_sets() -> [(f64, f64, f64); 4] {
    [
        (1e-3, 2.0, 0.0),
        (1.0, 0.0, 0.0),
        (1.0, 0.0, 1.0),
        (0.5, 2.0, 1.0),
    ]
}

fn check_quadratic<N: Dim, M: Dim>(
    f: &Quadratic<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    seed: u64,
) where
    DefaultAllocator: Alloc<N, M>,
{
    let exact = f.exact(mu, c);
    let s = sizes(f, mu, c);
    let tol = derivative_roundoff(&s, c, gamma);
    let b = f.gradients(mu);
    // The first-order covariance bᵀCb: exact minus 2tr(QₖCQₗC).
    let first_order_cov = &b * c * b.transpose();

    let sog = propagate(&SecondOrderGaussian, mu, c, f);
    assert_moments(
        "SecondOrderGaussian (exact for quadratics)",
        &sog,
        &exact,
        &tol,
    );

    let so = propagate(&SecondOrder, mu, c, f);
    assert_within("SecondOrder mean (exact)", &so.mean, &exact.mean, &tol.mean);
    assert_within(
        "SecondOrder covariance = bᵀCb",
        &so.covariance,
        &first_order_cov,
        &tol.cov,
    );
    assert_within(
        "SecondOrder cross",
        &so.cross_covariance,
        &exact.cross_covariance,
        &tol.cross,
    );

    let lin = propagate(&Linearized, mu, c, f);
    assert_within("Linearized mean = g(μ)", &lin.mean, &f.eval(mu), &tol.mean);
    assert_within(
        "Linearized covariance = bᵀCb",
        &lin.covariance,
        &first_order_cov,
        &tol.cov,
    );
    assert_within(
        "Linearized cross",
        &lin.cross_covariance,
        &exact.cross_covariance,
        &tol.cross,
    );

    for set in unscented_sets() {
        let ut = propagate(&Unscented::new(set.0, set.1, set.2).unwrap(), mu, c, f);
        let closed = unscented_closed_form(f, mu, c, set);
        let tol = unscented_roundoff(f, mu, c, set, gamma);
        assert_within(
            &format!("Unscented{set:?} mean (exact)"),
            &ut.mean,
            &exact.mean,
            &tol.mean,
        );
        assert_within(
            &format!("Unscented{set:?} covariance (closed form)"),
            &ut.covariance,
            &closed.covariance,
            &tol.cov,
        );
        assert_within(
            &format!("Unscented{set:?} cross (exact)"),
            &ut.cross_covariance,
            &exact.cross_covariance,
            &tol.cross,
        );
    }

    let sampled = propagate(&Sampled::new(SAMPLES, seed).unwrap(), mu, c, f);
    let se = sampling_error(f, mu, c, SAMPLES, PILOT, seed ^ 0x5eed).scaled(Z);
    assert_moments(
        "Sampled (1e5)",
        &sampled,
        &exact,
        &ApproxBounds::from_sampling(&se),
    );
}

/// The f32 versions against the f64 results for the f32-rounded inputs (so only f32
/// arithmetic is measured), with the round-off bounds above in γ₃₂.
fn check_quadratic_f32<N: Dim, M: Dim>(
    f: &Quadratic<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    seed: u64,
) where
    DefaultAllocator: Alloc<N, M>,
{
    let (f32q, mu32, c32) = (f.to_f32(), to32(mu), to32(c));
    let fr = Quadratic {
        q: f32q.q.iter().map(to64).collect(),
        a: to64(&f32q.a),
        c: to64(&f32q.c),
    };
    let (mur, cr) = (to64(&mu32), to64(&c32));
    let exact = fr.exact(&mur, &cr);
    let s = sizes(&fr, &mur, &cr);
    let tol = derivative_roundoff(&s, &cr, gamma32);
    let run = |m: Result<Moments<f32, N, M>, _>| moments_f64(&m.expect("f32 propagation succeeds"));
    assert_moments(
        "f32 SecondOrderGaussian",
        &run(SecondOrderGaussian.propagate(&mu32, &c32, &f32q)),
        &exact,
        &tol,
    );
    let so = run(SecondOrder.propagate(&mu32, &c32, &f32q));
    assert_within("f32 SecondOrder mean", &so.mean, &exact.mean, &tol.mean);
    // Unscented::default() in f32 is covered in linear.rs (mean round-off ~ ε₃₂/α²).
    for set in unscented_sets().into_iter().skip(1) {
        let ut = run(
            Unscented::<f32>::new(set.0 as f32, set.1 as f32, set.2 as f32)
                .unwrap()
                .propagate(&mu32, &c32, &f32q),
        );
        let closed = unscented_closed_form(&fr, &mur, &cr, set);
        let tol = unscented_roundoff(&fr, &mur, &cr, set, gamma32);
        assert_within(
            &format!("f32 Unscented{set:?} mean"),
            &ut.mean,
            &exact.mean,
            &tol.mean,
        );
        assert_within(
            &format!("f32 Unscented{set:?} covariance"),
            &ut.covariance,
            &closed.covariance,
            &tol.cov,
        );
    }
    let sampled = run(Sampled::new(SAMPLES_F32, seed)
        .unwrap()
        .propagate(&mu32, &c32, &f32q));
    let se = sampling_error(&fr, &mur, &cr, SAMPLES_F32, PILOT, seed ^ 0x5eed).scaled(Z);
    // Each f32 deviation is off by ≤ 2γ₃₂(2n+3) Y, Y the size of g over ±8σ (see
    // `unscented_roundoff`).
    let n = mu.nrows();
    let x = abs(&mur) + std_devs(&cr) * 8.0;
    let m_dim = f.c.shape_generic().0;
    let dev = OVector::<f64, M>::from_fn_generic(m_dim, U1, |k, _| {
        2.0 * gamma32(2 * n + 3)
            * (fr.c[k].abs() + fr.a.row(k).abs().dot(&x.transpose()) + x.dot(&(abs(&fr.q[k]) * &x)))
    });
    let tol = ApproxBounds::from_sampling(&se).plus(&sampled_f32_roundoff(
        &exact,
        &fr.eval(&mur),
        &cr,
        &dev,
        SAMPLES_F32,
    ));
    assert_moments("f32 Sampled", &sampled, &exact, &tol);
}

/// A random quadratic: Qₖ = (Rₖ + Rₖᵀ)/2 with entries of R in [−1, 1], except that Q₀ is
/// zero when `affine_first` (exercising the `None` Hessian next to real ones).
/// A quadratic function with the mean and covariance of its input.
type Problem<N, M> = (Quadratic<f64, N, M>, OVector<f64, N>, OMatrix<f64, N, N>);

fn problem<N: Dim, M: Dim>(n: N, m: M, p: &QuadParams) -> Problem<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let nn = n.value() * n.value();
    let q = (0..m.value())
        .map(|k| {
            let r = mat(n, n, &p.q[k * nn..(k + 1) * nn]);
            if k == 0 && p.affine_first {
                r * 0.0
            } else {
                (&r + r.transpose()) * 0.5
            }
        })
        .collect();
    (
        Quadratic {
            q,
            a: mat(m, n, &p.a),
            c: vector(m, &p.c),
        },
        vector(n, &p.mu),
        spd(n, &p.cb, p.scale),
    )
}

#[derive(Clone, Debug)]
struct QuadParams {
    q: Vec<f64>,
    a: Vec<f64>,
    c: Vec<f64>,
    mu: Vec<f64>,
    cb: Vec<f64>,
    scale: f64,
    affine_first: bool,
    seed: u64,
}

fn params(n: usize, m: usize) -> impl Strategy<Value = QuadParams> {
    (
        prop::collection::vec(-1.0..1.0f64, m * n * n),
        prop::collection::vec(-2.0..2.0f64, m * n),
        prop::collection::vec(-3.0..3.0f64, m),
        prop::collection::vec(-2.0..2.0f64, n),
        prop::collection::vec(-1.0..1.0f64, n * n),
        0.1..2.0f64,
        any::<bool>(),
        any::<u64>(),
    )
        .prop_map(|(q, a, c, mu, cb, scale, affine_first, seed)| QuadParams {
            q,
            a,
            c,
            mu,
            cb,
            scale,
            affine_first,
            seed,
        })
}

proptest! {
    #![proptest_config(config(32, 0x22))]

    #[test]
    fn quadratic_3_to_2(p in params(3, 2)) {
        let (f, mu, c) = problem(U3, U2, &p);
        check_quadratic(&f, &mu, &c, p.seed);
    }

    #[test]
    fn quadratic_6_to_4(p in params(6, 4)) {
        let (f, mu, c) = problem(U6, U4, &p);
        check_quadratic(&f, &mu, &c, p.seed);
    }

    #[test]
    fn quadratic_dynamic_4_to_3(p in params(4, 3)) {
        let (f, mu, c) = problem(Dyn(4), Dyn(3), &p);
        check_quadratic(&f, &mu, &c, p.seed);
    }

    #[test]
    fn quadratic_f32_3_to_2(p in params(3, 2)) {
        let (f, mu, c) = problem(U3, U2, &p);
        check_quadratic_f32(&f, &mu, &c, p.seed);
    }

    #[test]
    fn quadratic_f32_dynamic_5_to_2(p in params(5, 2)) {
        let (f, mu, c) = problem(Dyn(5), Dyn(2), &p);
        check_quadratic_f32(&f, &mu, &c, p.seed);
    }
}

/// One dimension, g = q x² + a x + c: the Julier set with κ = 3 − n = 2 matches the Gaussian
/// fourth moment, so its covariance is the exact b²C + 2q²C² (see `unscented_closed_form`).
#[test]
fn julier_kappa_3_minus_n_is_exact_for_1d_quadratic() {
    for (q, a, c0, mu, var) in [
        (0.7, -1.2, 0.3, 0.4, 0.25),
        (-2.0, 0.5, 1.0, -1.5, 2.0),
        (1.0, 0.0, 0.0, 0.0, 1.0),
    ] {
        let f = Quadratic {
            q: vec![vector(U1, &[q])],
            a: vector(U1, &[a]),
            c: vector(U1, &[c0]),
        };
        let (mu, c) = (vector(U1, &[mu]), vector(U1, &[var]));
        let exact = f.exact(&mu, &c);
        let ut = propagate(&Unscented::julier(2.0).unwrap(), &mu, &c, &f);
        let tol = unscented_roundoff(&f, &mu, &c, (1.0, 0.0, 2.0), gamma);
        assert_moments("Julier κ = 2, n = 1", &ut, &exact, &tol);
        // And the closed form says what cubature (c = 1, β − α² = −1) does instead:
        // q²C² − q²C² = 0, so it misses the whole 2q²C².
        let cub = propagate(&Unscented::cubature(), &mu, &c, &f);
        let missing = 2.0 * q * q * var * var;
        approx::assert_relative_eq!(
            exact.covariance[(0, 0)] - cub.covariance[(0, 0)],
            missing,
            max_relative = 1e-12
        );
    }
}

/// Boje's footnote to eq 8: E{x₁x₂} ≈ x̄₁x̄₂ + cov(x₁, x₂). It is exact (x₁x₂ is quadratic), and
/// the generic SecondOrder propagator gives it to round-off, for any correlation.
#[test]
fn product_mean_is_exact() {
    for (m1, m2, s11, s12, s22) in [
        (1.0, 2.0, 0.5, 0.3, 0.4),
        (-3.0, 0.5, 2.0, -1.9, 2.0),
        (0.0, 0.0, 1.0, 0.0, 1.0),
    ] {
        let q = mat(U2, U2, &[0.0, 0.5, 0.5, 0.0]);
        let f = Quadratic {
            q: vec![q],
            a: mat(U1, U2, &[0.0, 0.0]),
            c: vector(U1, &[0.0]),
        };
        let (mu, c) = (vector(U2, &[m1, m2]), mat(U2, U2, &[s11, s12, s12, s22]));
        let so = propagate(&SecondOrder, &mu, &c, &f);
        approx::assert_abs_diff_eq!(
            so.mean[0],
            m1 * m2 + s12,
            epsilon = 8.0 * EPS * (m1 * m2).abs().max(s12.abs()).max(1.0)
        );
        // var(x₁x₂) for jointly Gaussian: m₁²s₂₂ + m₂²s₁₁ + 2m₁m₂s₁₂ + s₁₁s₂₂ + s₁₂².
        let sog = propagate(&SecondOrderGaussian, &mu, &c, &f);
        let var = m1 * m1 * s22 + m2 * m2 * s11 + 2.0 * m1 * m2 * s12 + s11 * s22 + s12 * s12;
        approx::assert_relative_eq!(sog.covariance[(0, 0)], var, max_relative = 64.0 * EPS);
    }
}
