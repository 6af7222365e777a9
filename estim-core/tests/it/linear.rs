//! Affine g(x) = A x + b: every propagator is exact (the Monte Carlo one within its standard
//! error), for random A, b, μ and SPD C, static (3 → 2, 6 → 4) and dynamic sizes, f64 and f32.
//!
//! Exact: E y = Aμ + b, cov y = ACAᵀ, cov(x, y) = CAᵀ. The deterministic propagators must
//! reproduce these to round-off, with the round-off bound derived from Higham's model
//! |fl(Σᵢ aᵢbᵢ) − Σᵢ aᵢbᵢ| ≤ γₖ Σᵢ|aᵢbᵢ| (k the number of terms; see `common::gamma`).

use crate::common;

use common::*;
use estim_core::linalg::psd_factor;
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1, U2, U3, U4, U6};
use estim_core::{
    Affine, Alloc, Linearized, MomentPropagator, Moments, Sampled, SecondOrder,
    SecondOrderGaussian, Stage, Unscented, VectorFunction,
};
use proptest::prelude::*;

/// Monte Carlo draws for the Sampled checks (f64).
const SAMPLES: usize = 100_000;
/// Monte Carlo draws in f32: few enough that the worst-case f32 accumulation error of the
/// library's running sums, γ_N ≈ N ε₃₂ = 1.2·10⁻³ relative, stays far below the sampling error
/// Z/√N = 5·10⁻².
const SAMPLES_F32: usize = 10_000;

/// The unscented parameter sets tried: the default (α = 10⁻³, β = 2, κ = 0), cubature
/// (α = 1, κ = 0), Julier's κ = 1, and a moderate α = 0.5 with κ = 1.
fn unscented_sets() -> [(f64, f64, f64); 4] {
    [
        (1e-3, 2.0, 0.0),
        (1.0, 0.0, 0.0),
        (1.0, 0.0, 1.0),
        (0.5, 2.0, 1.0),
    ]
}

/// Round-off bound for the derivative-based propagators, whose arithmetic is g(μ), (JC)Jᵀ and
/// (JC)ᵀ, against the reference computed the same way; `g` is γ in the precision used.
/// - mean Aμ + b: γ_{n+1} (|A||μ| + |b|) per side;
/// - ACAᵀ: two nested n-term products, γ_{2n} |A||C||A|ᵀ per side (symmetrising averages two
///   such values and adds one rounding: γ_{2n+1});
/// - CAᵀ: γ_n |C||A|ᵀ per side.
///
/// "Per side": both the library and the reference round, so each bound is doubled.
fn derivative_roundoff<N: Dim, M: Dim>(
    f: &AffineMap<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    g: fn(usize) -> f64,
) -> ApproxBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = mu.nrows();
    let (aa, ca) = (abs(&f.a), abs(c));
    ApproxBounds {
        mean: (&aa * abs(mu) + abs(&f.b)) * (2.0 * g(n + 1)),
        cov: &aa * &ca * aa.transpose() * (2.0 * g(2 * n + 1)),
        cross: &ca * aa.transpose() * (2.0 * g(n)),
    }
}

/// Round-off bound for the unscented transform on an affine g, in the precision whose γ is
/// `g` (first order in ε). With c = α²(n + κ), w = 1/(2c), L the computed Cholesky factor,
/// S = √c|L| (column j bounds |sⱼ|) and Y = |A|(|μ| + S·1) + |b| (the size of every value
/// g(χ) takes):
///
/// - each deviation dᵢ = fl(g(fl(μ + sᵢ))) − fl(g(μ)) is off by at most e = 2γ_{n+3} Y (two
///   evaluations of n + 1 terms, the rounding of χ = μ + sᵢ seen through |A|, the subtraction);
/// - mean g(μ) + w Σᵢ dᵢ: the 2n errors add, w·2n·e = n e / c, plus the summation
///   γ_{2n} w Σ|dᵢ| ≤ γ_{2n} |A||L|1/√c, plus the reference's γ_{n+1}(|A||μ| + |b|). This is why
///   a small α costs precision: n e / c grows like 1/α²;
/// - covariance w Σᵢ dᵢdᵢᵀ: w Σᵢ(|dᵢ|eᵀ + e|dᵢ|ᵀ) ≤ (|A||L|1 eᵀ + e (|A||L|1)ᵀ)/√c, the
///   product sums γ_{2n+1}(|A||L|)(|A||L|)ᵀ, the Cholesky backward error
///   |LLᵀ − C| ≤ γ_{n+1}|L||L|ᵀ seen through A, (β − α²)d̄d̄ᵀ with |d̄| ≤ n e / c, and the
///   reference's γ_{2n+1}|A||C||A|ᵀ;
/// - cross-covariance w Σᵢ sᵢdᵢᵀ: (|L|1) eᵀ/√c, plus γ_{2n+1}|L||L|ᵀ|A|ᵀ for the sums and
///   the Cholesky error, plus the reference's γ_n|C||A|ᵀ.
fn unscented_roundoff<N: Dim, M: Dim>(
    f: &AffineMap<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    (alpha, beta, kappa): (f64, f64, f64),
    g: fn(usize) -> f64,
) -> ApproxBounds<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = mu.nrows();
    let n_dim = mu.shape_generic().0;
    let scale = alpha * alpha * (n as f64 + kappa);
    let root = scale.sqrt();
    let lower = abs(&psd_factor(c, Stage::Propagation).expect("SPD"));
    let ones = OVector::<f64, N>::from_element_generic(n_dim, U1, 1.0);
    let aa = abs(&f.a);
    let spread = &lower * &ones * root;
    let y = &aa * (abs(mu) + &spread) + abs(&f.b);
    let e = &y * (2.0 * g(n + 3));
    let al = &aa * &lower;
    let al1 = &al * &ones;
    let l1 = &lower * &ones;
    let mean_dev = &e * (n as f64 / scale);
    let mean = &mean_dev + &al1 * (g(2 * n) / root) + (&aa * abs(mu) + abs(&f.b)) * g(n + 1);
    let cov = (&al1 * e.transpose() + &e * al1.transpose()) / root
        + &al * al.transpose() * (g(2 * n + 1) + g(n + 1))
        + &mean_dev * mean_dev.transpose() * (beta - alpha * alpha).abs()
        + &aa * abs(c) * aa.transpose() * g(2 * n + 1);
    let cross = &l1 * e.transpose() / root
        + &lower * lower.transpose() * aa.transpose() * (g(2 * n + 1) + g(n + 1))
        + abs(c) * aa.transpose() * g(n);
    ApproxBounds { mean, cov, cross }
}

/// Standard errors of an N-sample Monte Carlo estimate when y (and x) are Gaussian: the sample
/// covariance of jointly Gaussian u, v has variance (σᵤ² σᵥ² + σᵤᵥ²)/(N − 1) (Wishart).
fn gaussian_sampling_error<N: Dim, M: Dim>(
    exact: &Moments<f64, N, M>,
    c: &OMatrix<f64, N, N>,
    samples: usize,
) -> SamplingError<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let cy = &exact.covariance;
    let cxy = &exact.cross_covariance;
    let n = samples as f64;
    SamplingError {
        mean: cy.diagonal().map(|v| (v / n).sqrt()),
        cov: OMatrix::from_fn_generic(cy.shape_generic().0, cy.shape_generic().1, |k, l| {
            ((cy[(k, k)] * cy[(l, l)] + cy[(k, l)] * cy[(k, l)]) / (n - 1.0)).sqrt()
        }),
        cross: OMatrix::from_fn_generic(cxy.shape_generic().0, cxy.shape_generic().1, |i, k| {
            ((c[(i, i)] * cy[(k, k)] + cxy[(i, k)] * cxy[(i, k)]) / (n - 1.0)).sqrt()
        }),
    }
}

/// All propagators on one affine problem, f64.
fn check_affine<N: Dim, M: Dim>(
    f: &AffineMap<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    seed: u64,
) where
    DefaultAllocator: Alloc<N, M>,
{
    let exact = f.exact(mu, c);
    let tol = derivative_roundoff(f, mu, c, gamma);
    assert_moments(
        "Linearized",
        &propagate(&Linearized, mu, c, f),
        &exact,
        &tol,
    );
    assert_moments("Affine", &propagate(&Affine, mu, c, f), &exact, &tol);
    assert_moments(
        "SecondOrder",
        &propagate(&SecondOrder, mu, c, f),
        &exact,
        &tol,
    );
    assert_moments(
        "SecondOrderGaussian",
        &propagate(&SecondOrderGaussian, mu, c, f),
        &exact,
        &tol,
    );
    for set in unscented_sets() {
        let ut = Unscented::new(set.0, set.1, set.2).unwrap();
        let tol = unscented_roundoff(f, mu, c, set, gamma);
        assert_moments(
            &format!("Unscented{set:?}"),
            &propagate(&ut, mu, c, f),
            &exact,
            &tol,
        );
    }
    let sampled = propagate(&Sampled::new(SAMPLES, seed).unwrap(), mu, c, f);
    let se = gaussian_sampling_error(&exact, c, SAMPLES).scaled(Z);
    assert_moments(
        "Sampled",
        &sampled,
        &exact,
        &ApproxBounds::from_sampling(&se),
    );
}

/// All propagators on the f32 version of the problem. The reference is the exact f64 result
/// for the f32-rounded inputs, so only f32 arithmetic is measured: the round-off bounds of the
/// f64 check with γ₃₂ (plus γ₆₄ for the reference, negligible and covered by the doubling).
fn check_affine_f32<N: Dim, M: Dim>(
    f64_map: &AffineMap<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    seed: u64,
) where
    DefaultAllocator: Alloc<N, M>,
{
    let f = f64_map.to_f32();
    let (mu32, c32) = (to32(mu), to32(c));
    // The problem as f32 sees it, in f64.
    let (fr, mur, cr) = (
        AffineMap {
            a: to64(&f.a),
            b: to64(&f.b),
        },
        to64(&mu32),
        to64(&c32),
    );
    let exact = fr.exact(&mur, &cr);
    let run = |m: Result<Moments<f32, N, M>, _>| moments_f64(&m.expect("f32 propagation succeeds"));
    let tol = derivative_roundoff(&fr, &mur, &cr, gamma32);
    assert_moments(
        "f32 Linearized",
        &run(Linearized.propagate(&mu32, &c32, &f)),
        &exact,
        &tol,
    );
    assert_moments(
        "f32 Affine",
        &run(Affine.propagate(&mu32, &c32, &f)),
        &exact,
        &tol,
    );
    assert_moments(
        "f32 SecondOrder",
        &run(SecondOrder.propagate(&mu32, &c32, &f)),
        &exact,
        &tol,
    );
    assert_moments(
        "f32 SecondOrderGaussian",
        &run(SecondOrderGaussian.propagate(&mu32, &c32, &f)),
        &exact,
        &tol,
    );
    // The default α = 10⁻³ is covered by its own test (its f32 mean round-off is ~ n ε₃₂/α²).
    for set in unscented_sets().into_iter().skip(1) {
        let ut = Unscented::<f32>::new(set.0 as f32, set.1 as f32, set.2 as f32).unwrap();
        let tol = unscented_roundoff(&fr, &mur, &cr, set, gamma32);
        assert_moments(
            &format!("f32 Unscented{set:?}"),
            &run(ut.propagate(&mu32, &c32, &f)),
            &exact,
            &tol,
        );
    }
    // Sampled: sampling error plus the f32 errors of `sampled_f32_roundoff`, with each
    // deviation off by ≤ 2γ₃₂(n+3) Y (as in the unscented bound; Y the size of g's values
    // over ±8σ, which holds every draw of the 10⁴ with overwhelming probability).
    let sampled = run(Sampled::new(SAMPLES_F32, seed)
        .unwrap()
        .propagate(&mu32, &c32, &f));
    let se = gaussian_sampling_error(&exact, &cr, SAMPLES_F32).scaled(Z);
    let n = mu.nrows();
    let y_size = abs(&fr.a) * (abs(&mur) + std_devs(&cr) * 8.0) + abs(&fr.b);
    let dev = &y_size * (2.0 * gamma32(n + 3));
    let tol = ApproxBounds::from_sampling(&se).plus(&sampled_f32_roundoff(
        &exact,
        &fr.eval(&mur),
        &cr,
        &dev,
        SAMPLES_F32,
    ));
    assert_moments("f32 Sampled", &sampled, &exact, &tol);
}

/// Builds the problem from flat parameter vectors: A (m × n, entries in [−2, 2]), b, μ and
/// C = scale² (B Bᵀ/n + 0.1 I).
/// An affine map with the mean and covariance of its input.
type Problem<N, M> = (AffineMap<f64, N, M>, OVector<f64, N>, OMatrix<f64, N, N>);

fn problem<N: Dim, M: Dim>(
    n: N,
    m: M,
    a: &[f64],
    b: &[f64],
    mu: &[f64],
    cb: &[f64],
    scale: f64,
) -> Problem<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    (
        AffineMap {
            a: mat(m, n, a),
            b: vector(m, b),
        },
        vector(n, mu),
        spd(n, cb, scale),
    )
}

fn params(
    n: usize,
    m: usize,
) -> impl Strategy<Value = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, f64, u64)> {
    (
        prop::collection::vec(-2.0..2.0f64, n * m),
        prop::collection::vec(-5.0..5.0f64, m),
        prop::collection::vec(-3.0..3.0f64, n),
        prop::collection::vec(-1.0..1.0f64, n * n),
        0.05..3.0f64,
        any::<u64>(),
    )
}

proptest! {
    #![proptest_config(config(32, 0x11))]

    #[test]
    fn affine_3_to_2_all_propagators_exact((a, b, mu, cb, scale, seed) in params(3, 2)) {
        let (f, mu, c) = problem(U3, U2, &a, &b, &mu, &cb, scale);
        check_affine(&f, &mu, &c, seed);
    }

    #[test]
    fn affine_6_to_4_all_propagators_exact((a, b, mu, cb, scale, seed) in params(6, 4)) {
        let (f, mu, c) = problem(U6, U4, &a, &b, &mu, &cb, scale);
        check_affine(&f, &mu, &c, seed);
    }

    #[test]
    fn affine_dynamic_5_to_3_all_propagators_exact((a, b, mu, cb, scale, seed) in params(5, 3)) {
        let (f, mu, c) = problem(Dyn(5), Dyn(3), &a, &b, &mu, &cb, scale);
        check_affine(&f, &mu, &c, seed);
    }

    #[test]
    fn affine_dynamic_1_to_4_all_propagators_exact((a, b, mu, cb, scale, seed) in params(1, 4)) {
        let (f, mu, c) = problem(Dyn(1), Dyn(4), &a, &b, &mu, &cb, scale);
        check_affine(&f, &mu, &c, seed);
    }

    #[test]
    fn affine_f32_3_to_2((a, b, mu, cb, scale, seed) in params(3, 2)) {
        let (f, mu, c) = problem(U3, U2, &a, &b, &mu, &cb, scale);
        check_affine_f32(&f, &mu, &c, seed);
    }

    #[test]
    fn affine_f32_6_to_4((a, b, mu, cb, scale, seed) in params(6, 4)) {
        let (f, mu, c) = problem(U6, U4, &a, &b, &mu, &cb, scale);
        check_affine_f32(&f, &mu, &c, seed);
    }

    #[test]
    fn affine_f32_dynamic_4_to_3((a, b, mu, cb, scale, seed) in params(4, 3)) {
        let (f, mu, c) = problem(Dyn(4), Dyn(3), &a, &b, &mu, &cb, scale);
        check_affine_f32(&f, &mu, &c, seed);
    }

    /// Static and dynamic storage run the same arithmetic: identical results to round-off.
    #[test]
    fn static_and_dynamic_agree((a, b, mu, cb, scale, _seed) in params(6, 4)) {
        let (fs, mus, cs) = problem(U6, U4, &a, &b, &mu, &cb, scale);
        let (fd, mud, cd) = problem(Dyn(6), Dyn(4), &a, &b, &mu, &cb, scale);
        let tol = derivative_roundoff(&fd, &mud, &cd, gamma);
        let check = |what: &str, s: Moments<f64, U6, U4>, d: Moments<f64, Dyn, Dyn>| {
            let s = Moments {
                mean: OVector::<f64, Dyn>::from_column_slice(s.mean.as_slice()),
                covariance: OMatrix::<f64, Dyn, Dyn>::from_column_slice(4, 4, s.covariance.as_slice()),
                cross_covariance: OMatrix::<f64, Dyn, Dyn>::from_column_slice(6, 4, s.cross_covariance.as_slice()),
            };
            assert_moments(what, &d, &s, &tol);
        };
        check("Linearized", propagate(&Linearized, &mus, &cs, &fs), propagate(&Linearized, &mud, &cd, &fd));
        check("SecondOrderGaussian", propagate(&SecondOrderGaussian, &mus, &cs, &fs), propagate(&SecondOrderGaussian, &mud, &cd, &fd));
        let ut = Unscented::cubature();
        let ut_tol = unscented_roundoff(&fd, &mud, &cd, (1.0, 0.0, 0.0), gamma);
        let s = propagate(&ut, &mus, &cs, &fs);
        let d = propagate(&ut, &mud, &cd, &fd);
        assert_within("Unscented static vs dynamic mean", &d.mean, &OVector::<f64, Dyn>::from_column_slice(s.mean.as_slice()), &ut_tol.mean);
        // Same seed, same draws: the Monte Carlo estimates agree to round-off too.
        let s = propagate(&Sampled::new(1000, 7).unwrap(), &mus, &cs, &fs);
        let d = propagate(&Sampled::new(1000, 7).unwrap(), &mud, &cd, &fd);
        for k in 0..4 {
            let scale = d.covariance[(k, k)].sqrt() + d.mean[k].abs();
            prop_assert!((s.mean[k] - d.mean[k]).abs() <= gamma(1000 + 8) * scale * 4.0);
        }
    }
}

/// α = 10⁻³ (the f64 default) in f32. The unscented mean is g(μ) + w Σᵢ dᵢ with
/// w = 1/(2α²n): the round-off of each deviation (≈ ε₃₂ |g|) is multiplied by 1/α² = 10⁶, so
/// for an affine g the mean is off by up to n e/c ≈ ε₃₂/α² |g| ≈ 0.1 |g| (see
/// `unscented_roundoff`). This test pins the behaviour to that model (and shows it is real):
/// the mean error exceeds what cubature (α = 1) and the f32 default (α = 0.5) give by orders
/// of magnitude, yet stays within the derived round-off bound.
#[test]
fn small_alpha_unscented_in_f32_loses_mean_precision_as_modelled() {
    let f = AffineMap {
        a: mat(U3, U3, &[1.0, 0.3, -0.2, 0.5, 2.0, 0.1, -0.7, 0.4, 1.5]),
        b: vector(U3, &[10.0, -20.0, 5.0]),
    };
    let mu = vector(U3, &[3.0, -2.0, 7.0]);
    let c = spd(U3, &[0.3, -0.5, 0.9, 0.1, 0.7, -0.2, 0.4, 0.6, -0.8], 0.5);
    let (f32_map, mu32, c32) = (f.to_f32(), to32(&mu), to32(&c));
    let fr = AffineMap {
        a: to64(&f32_map.a),
        b: to64(&f32_map.b),
    };
    let (mur, cr) = (to64(&mu32), to64(&c32));
    let exact = fr.exact(&mur, &cr);
    let run = |ut: Unscented<f32>| moments_f64(&ut.propagate(&mu32, &c32, &f32_map).unwrap());
    let small = run(Unscented::new(1e-3, 2.0, 0.0).unwrap());
    let default = run(Unscented::default());
    let cubature = run(Unscented::cubature());
    let tol = unscented_roundoff(&fr, &mur, &cr, (1e-3, 2.0, 0.0), gamma32);
    assert_moments("f32 Unscented α = 1e-3", &small, &exact, &tol);
    let tol = unscented_roundoff(&fr, &mur, &cr, (0.5, 2.0, 0.0), gamma32);
    assert_moments("f32 default Unscented", &default, &exact, &tol);
    let err = |m: &Moments<f64, U3, U3>| (m.mean - exact.mean).amax();
    eprintln!(
        "f32 unscented mean error: α=1e-3 {:e}, default α=0.5 {:e}, cubature {:e} (|y| ≈ {:e})",
        err(&small),
        err(&default),
        err(&cubature),
        exact.mean.amax()
    );
    assert!(
        err(&default) <= 1e-4 * exact.mean.amax(),
        "the f32 default keeps f32 precision"
    );
    assert!(
        err(&cubature) <= 1e-4 * exact.mean.amax(),
        "cubature keeps f32 precision"
    );
}
