//! Smooth nonlinear g: trigonometric products (x₀ cos x₁, sin x₀ cos x₁, …), random sums of
//! (c₀ + bᵀx) cos(aᵀx + φ), and Boje's eq 5 with every input random — each approximation
//! against the Monte Carlo reference (10⁵ draws) and against the exact Gaussian moments.
//!
//! Tolerances (what is assumed): x is Gaussian and g is a `common::TrigSum`, whose Taylor
//! remainders have the explicit L² bounds of `common::TrigSum::remainder_l2` (they use only
//! |cos⁽ʲ⁾| ≤ 1). From these, `common::taylor_bounds` and `common::unscented_bounds` give
//! rigorous bounds on |approximation − exact|: O(σ²) for the linearised mean, O(σ⁴) for every
//! other quantity (that is the truncation order of each method). The checks are
//!
//! - |Sampled − exact|        ≤ Z·SE                       (validates the reference)
//! - |approximation − exact|  ≤ truncation + round-off
//! - |approximation − Sampled| ≤ truncation + Z·SE + round-off
//!
//! with SE the standard error of the 10⁵-draw estimate (from a pilot run) and Z = 5.

use crate::common;

use common::*;
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U3, U4, U5, Vector5};
use estim_core::{
    Alloc, Linearized, MomentPropagator, Moments, Sampled, SecondOrder, SecondOrderGaussian,
    TwiceDifferentiable, Unscented,
};
use proptest::prelude::*;

const SAMPLES: usize = 100_000;
const SAMPLES_F32: usize = 10_000;
const PILOT: usize = 20_000;

fn unscented_sets() -> [(f64, f64, f64); 3] {
    [(1e-3, 2.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 1.0)]
}

/// Every propagator on g (analytic derivatives) whose TrigSum form is `rep`.
fn check_nonlinear<N: Dim, M: Dim, G>(
    g: &G,
    rep: &TrigSum<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    seed: u64,
) where
    G: TwiceDifferentiable<f64, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let exact = rep.exact(mu, c);
    let exact_roundoff = rep.roundoff_exact(mu, c, gamma);
    let bounds = taylor_bounds(rep, mu, c);
    let sampled = propagate(&Sampled::new(SAMPLES, seed).unwrap(), mu, c, g);
    let se = ApproxBounds::from_sampling(
        &sampling_error(g, mu, c, SAMPLES, PILOT, seed ^ 0x5eed).scaled(Z),
    );
    assert_moments(
        "Sampled vs exact",
        &sampled,
        &exact,
        &se.plus(&exact_roundoff),
    );

    let roundoff = rep.roundoff_derivative(mu, c, gamma).plus(&exact_roundoff);
    let derivative_based = [
        (
            "Linearized",
            propagate(&Linearized, mu, c, g),
            &bounds.linearized,
        ),
        (
            "SecondOrder",
            propagate(&SecondOrder, mu, c, g),
            &bounds.second_order,
        ),
        (
            "SecondOrderGaussian",
            propagate(&SecondOrderGaussian, mu, c, g),
            &bounds.gaussian,
        ),
    ];
    for (name, got, truncation) in &derivative_based {
        let tol = truncation.plus(&roundoff);
        assert_moments(&format!("{name} vs exact"), got, &exact, &tol);
        assert_moments(&format!("{name} vs Sampled"), got, &sampled, &tol.plus(&se));
    }
    for set in unscented_sets() {
        let ut = propagate(&Unscented::new(set.0, set.1, set.2).unwrap(), mu, c, g);
        let tol = unscented_bounds(rep, mu, c, set)
            .plus(&rep.roundoff_unscented(mu, c, set, gamma))
            .plus(&exact_roundoff);
        assert_moments(&format!("Unscented{set:?} vs exact"), &ut, &exact, &tol);
        assert_moments(
            &format!("Unscented{set:?} vs Sampled"),
            &ut,
            &sampled,
            &tol.plus(&se),
        );
    }
}

/// The f32 propagators against the f64 ones on the same (f32-rounded) inputs, within the
/// round-off allowances of both (γ₃₂ for the f32 side, γ for the f64 side); the f32 Monte
/// Carlo run against the exact moments within Z·SE plus its f32 round-off.
fn check_nonlinear_f32<N: Dim, M: Dim, G32>(
    g32: &G32,
    rep: &TrigSum<f64, N, M>,
    mu: &OVector<f64, N>,
    c: &OMatrix<f64, N, N>,
    seed: u64,
) where
    G32: TwiceDifferentiable<f32, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    let (mu32, c32) = (to32(mu), to32(c));
    let (mur, cr) = (to64(&mu32), to64(&c32));
    // The f64 function whose coefficients are the f32 ones.
    let rep_r = {
        let r32 = rep.to_f32();
        TrigSum {
            m: r32.m,
            outputs: r32
                .outputs
                .iter()
                .map(|ts| {
                    ts.iter()
                        .map(|t| Term {
                            c0: f64::from(t.c0),
                            b: to64(&t.b),
                            a: to64(&t.a),
                            phase: f64::from(t.phase),
                        })
                        .collect()
                })
                .collect(),
        }
    };
    let run = |m: Result<Moments<f32, N, M>, _>| moments_f64(&m.expect("f32 propagation succeeds"));
    let tol = rep_r
        .roundoff_derivative(&mur, &cr, gamma32)
        .plus(&rep_r.roundoff_derivative(&mur, &cr, gamma));
    assert_moments(
        "f32 Linearized",
        &run(Linearized.propagate(&mu32, &c32, g32)),
        &propagate(&Linearized, &mur, &cr, &rep_r),
        &tol,
    );
    assert_moments(
        "f32 SecondOrder",
        &run(SecondOrder.propagate(&mu32, &c32, g32)),
        &propagate(&SecondOrder, &mur, &cr, &rep_r),
        &tol,
    );
    assert_moments(
        "f32 SecondOrderGaussian",
        &run(SecondOrderGaussian.propagate(&mu32, &c32, g32)),
        &propagate(&SecondOrderGaussian, &mur, &cr, &rep_r),
        &tol,
    );
    // The default α = 10⁻³ is not usable in f32 (see linear.rs); the α = 1 sets are.
    for set in unscented_sets().into_iter().skip(1) {
        let ut32 = Unscented::<f32>::new(set.0 as f32, set.1 as f32, set.2 as f32).unwrap();
        let ut64 = Unscented::new(set.0, set.1, set.2).unwrap();
        let tol = rep_r
            .roundoff_unscented(&mur, &cr, set, gamma32)
            .plus(&rep_r.roundoff_unscented(&mur, &cr, set, gamma));
        assert_moments(
            &format!("f32 Unscented{set:?}"),
            &run(ut32.propagate(&mu32, &c32, g32)),
            &propagate(&ut64, &mur, &cr, &rep_r),
            &tol,
        );
    }
    let exact = rep_r.exact(&mur, &cr);
    let sampled = run(Sampled::new(SAMPLES_F32, seed)
        .unwrap()
        .propagate(&mu32, &c32, g32));
    let se = sampling_error(&rep_r, &mur, &cr, SAMPLES_F32, PILOT, seed ^ 0x5eed).scaled(Z);
    // Each f32 deviation is off by ≤ 2γ₃₂(K) times the value majorant over ±8σ.
    let dev = rep_r.majorants(&mur, &(std_devs(&cr) * 8.0)).value
        * (2.0 * gamma32(TrigSum::<f64, N, M>::chain(mu.nrows())));
    let tol = ApproxBounds::from_sampling(&se)
        .plus(&sampled_f32_roundoff(
            &exact,
            &estim_core::VectorFunction::eval(&rep_r, &mur),
            &cr,
            &dev,
            SAMPLES_F32,
        ))
        .plus(&rep_r.roundoff_exact(&mur, &cr, gamma));
    assert_moments("f32 Sampled vs exact", &sampled, &exact, &tol);
}

/// Boje's input x = (a_u1, a_v1, a_u2, a_v2, θ), independent: means, standard deviations.
fn boje_input(mean: &[f64], sd_a: &[f64], sd_theta: f64) -> (Vector5<f64>, OMatrix<f64, U5, U5>) {
    let mu = Vector5::from_column_slice(mean);
    let c = OMatrix::<f64, U5, U5>::from_diagonal(&Vector5::new(
        sd_a[0] * sd_a[0],
        sd_a[1] * sd_a[1],
        sd_a[2] * sd_a[2],
        sd_a[3] * sd_a[3],
        sd_theta * sd_theta,
    ));
    (mu, c)
}

fn boje_params() -> impl Strategy<Value = (Vec<f64>, Vec<f64>, f64, f64, u64)> {
    (
        // accelerations in m/s² (a few g at most) and a heading anywhere on the circle
        (prop::collection::vec(-5.0..5.0f64, 4), -3.2..3.2f64).prop_map(|(mut a, t)| {
            a.push(t);
            a
        }),
        prop::collection::vec(0.01..0.3f64, 4),
        0.01..0.5f64,
        // R, half the accelerometer spacing, in m
        0.05..1.0f64,
        any::<u64>(),
    )
}

proptest! {
    #![proptest_config(config(24, 0x33))]

    /// x₀ cos x₁, sin x₀ cos x₁, x₂ sin x₁ + ½x₀ with correlated Gaussian inputs.
    #[test]
    fn trigonometric_products(mu in prop::collection::vec(-2.0..2.0f64, 3), cb in prop::collection::vec(-1.0..1.0f64, 9), scale in 0.02..0.4f64, seed in any::<u64>()) {
        let f = TrigSum::products(U3, U3);
        check_nonlinear(&f, &f, &vector(U3, &mu), &spd(U3, &cb, scale), seed);
    }

    /// Random sums of (c₀ + bᵀx) cos(aᵀx + φ), ℝ⁴ → ℝ³.
    #[test]
    fn random_trigonometric_sums(p in prop::collection::vec(-1.0..1.0f64, TrigSum::<f64, U4, U3>::random_len(4, 3)), mu in prop::collection::vec(-2.0..2.0f64, 4), cb in prop::collection::vec(-1.0..1.0f64, 16), scale in 0.02..0.3f64, seed in any::<u64>()) {
        let f = TrigSum::random(U4, U3, &p);
        check_nonlinear(&f, &f, &vector(U4, &mu), &spd(U4, &cb, scale), seed);
    }

    /// Boje's eq 5 (hand-written derivatives in `common::Boje`), all five inputs random and
    /// independent.
    #[test]
    fn boje_eq5((mean, sd_a, sd_theta, r, seed) in boje_params()) {
        let boje = Boje { r };
        let (mu, c) = boje_input(&mean, &sd_a, sd_theta);
        check_nonlinear(&boje, &boje.as_trig_sum(), &mu, &c, seed);
    }

    /// The products function with dynamic sizes.
    #[test]
    fn trigonometric_products_dynamic(mu in prop::collection::vec(-2.0..2.0f64, 3), cb in prop::collection::vec(-1.0..1.0f64, 9), scale in 0.02..0.4f64, seed in any::<u64>()) {
        let f = TrigSum::products(Dyn(3), Dyn(3));
        check_nonlinear(&f, &f, &vector(Dyn(3), &mu), &spd(Dyn(3), &cb, scale), seed);
    }

    /// Random sums with dynamic sizes, ℝ⁵ → ℝ².
    #[test]
    fn random_trigonometric_sums_dynamic(p in prop::collection::vec(-1.0..1.0f64, TrigSum::<f64, Dyn, Dyn>::random_len(5, 2)), mu in prop::collection::vec(-2.0..2.0f64, 5), cb in prop::collection::vec(-1.0..1.0f64, 25), scale in 0.02..0.3f64, seed in any::<u64>()) {
        let f = TrigSum::random(Dyn(5), Dyn(2), &p);
        check_nonlinear(&f, &f, &vector(Dyn(5), &mu), &spd(Dyn(5), &cb, scale), seed);
    }

    #[test]
    fn trigonometric_products_f32(mu in prop::collection::vec(-2.0..2.0f64, 3), cb in prop::collection::vec(-1.0..1.0f64, 9), scale in 0.02..0.4f64, seed in any::<u64>()) {
        let f = TrigSum::products(U3, U3);
        check_nonlinear_f32(&f.to_f32(), &f, &vector(U3, &mu), &spd(U3, &cb, scale), seed);
    }

    #[test]
    fn boje_eq5_f32((mean, sd_a, sd_theta, r, seed) in boje_params()) {
        let boje = Boje { r };
        let (mu, c) = boje_input(&mean, &sd_a, sd_theta);
        check_nonlinear_f32(&Boje { r: r as f32 }, &boje.as_trig_sum(), &mu, &c, seed);
    }

    #[test]
    fn random_trigonometric_sums_f32_dynamic(p in prop::collection::vec(-1.0..1.0f64, TrigSum::<f64, Dyn, Dyn>::random_len(4, 3)), mu in prop::collection::vec(-2.0..2.0f64, 4), cb in prop::collection::vec(-1.0..1.0f64, 16), scale in 0.02..0.3f64, seed in any::<u64>()) {
        let f = TrigSum::random(Dyn(4), Dyn(3), &p);
        check_nonlinear_f32(&f.to_f32(), &f, &vector(Dyn(4), &mu), &spd(Dyn(4), &cb, scale), seed);
    }
}

/// When the curvature term ½⟨Hₖ, C⟩ dominates the sampling error, the second-order mean is
/// closer to the Monte Carlo mean than the linearised one — by a margin no sampling
/// fluctuation explains. For ẍ and ÿ of eq 5, ∂²/∂θ² gₖ = −gₖ, so the curvature term is
/// −½σθ² gₖ(μ): large for a large heading uncertainty and large accelerations.
///
/// Fixed case: a_u1 = 2, a_v1 = −1, a_u2 = 2.5, a_v2 = −0.5 m/s², θ = 0.7 rad, σ_a = 0.05 m/s²,
/// σθ = 0.6 rad (34°). Then the linearised mean of ẍ is off by (1 − e^{−σθ²/2})|ẍ(μ)| ≈ 0.36,
/// the second-order one by (e^{−σθ²/2} − 1 + σθ²/2)|ẍ(μ)| ≈ 0.034 (the next Taylor term,
/// σθ⁴/8 |ẍ|), and the standard error is ≈ 0.004.
#[test]
fn second_order_mean_beats_linearised_when_curvature_dominates() {
    let boje = Boje { r: 0.1 };
    let (mu, c) = boje_input(&[2.0, -1.0, 2.5, -0.5, 0.7], &[0.05; 4], 0.6);
    let sampled = propagate(&Sampled::new(SAMPLES, 2024).unwrap(), &mu, &c, &boje);
    let se = sampling_error(&boje, &mu, &c, SAMPLES, PILOT, 99);
    let lin = propagate(&Linearized, &mu, &c, &boje);
    let so = propagate(&SecondOrder, &mu, &c, &boje);
    let exact = boje.as_trig_sum().exact(&mu, &c);
    for k in 0..2 {
        let lin_err = (lin.mean[k] - sampled.mean[k]).abs();
        let so_err = (so.mean[k] - sampled.mean[k]).abs();
        eprintln!(
            "component {k}: exact {:.5}, sampled {:.5} ± {:.5}, second-order {:.5} (error {so_err:.5}), linearised {:.5} (error {lin_err:.5})",
            exact.mean[k], sampled.mean[k], se.mean[k], so.mean[k], lin.mean[k]
        );
        assert!(
            lin_err > so_err + 2.0 * Z * se.mean[k],
            "component {k}: linearised error {lin_err} not clearly above second-order error {so_err} (SE {})",
            se.mean[k]
        );
        // The second-order error is the predicted next term, (e^{−s²/2} − 1 + s²/2) gₖ(μ)
        // (exactly, since the θ-dependence is a pure sinusoid and the a's are independent).
        let s2 = c[(4, 4)];
        let predicted = ((-s2 / 2.0).exp() - 1.0 + s2 / 2.0) * lin.mean[k];
        approx::assert_abs_diff_eq!(exact.mean[k] - so.mean[k], predicted, epsilon = 1e-12);
    }
    // The linear rows (θ̈, θ̇²) are identical for both.
    approx::assert_abs_diff_eq!(
        lin.mean.fixed_rows::<2>(2),
        so.mean.fixed_rows::<2>(2),
        epsilon = 0.0
    );
}

proptest! {
    #![proptest_config(config(16, 0x34))]

    /// The same over random eq 5 inputs with a large heading uncertainty: wherever the
    /// curvature term ½σθ²|gₖ(μ)| exceeds 2(Z·SE + second-order bound), the second-order mean
    /// is the closer one.
    #[test]
    fn second_order_mean_closer_for_large_heading_uncertainty((mean, sd_a, _sd, r, seed) in boje_params(), sd_theta in 0.3..0.8f64) {
        let boje = Boje { r };
        let (mu, c) = boje_input(&mean, &sd_a, sd_theta);
        let sampled = propagate(&Sampled::new(SAMPLES, seed).unwrap(), &mu, &c, &boje);
        let se = sampling_error(&boje, &mu, &c, SAMPLES, PILOT, seed ^ 1);
        let lin = propagate(&Linearized, &mu, &c, &boje);
        let so = propagate(&SecondOrder, &mu, &c, &boje);
        let bounds = taylor_bounds(&boje.as_trig_sum(), &mu, &c);
        for k in 0..2 {
            let curvature = 0.5 * sd_theta * sd_theta * lin.mean[k].abs();
            if curvature > 2.0 * (Z * se.mean[k] + bounds.second_order.mean[k]) {
                prop_assert!((so.mean[k] - sampled.mean[k]).abs() < (lin.mean[k] - sampled.mean[k]).abs());
            }
        }
    }
}

/// The Boje struct (matrix form of eq 5) and its TrigSum form are the same function with the
/// same derivatives, so the exact moments and bounds of the latter apply to the former.
#[test]
fn boje_matrix_form_matches_trig_sum_form() {
    use estim_core::{Differentiable, VectorFunction};
    let boje = Boje { r: 0.3 };
    let rep = boje.as_trig_sum();
    for x in [
        Vector5::new(1.0, -2.0, 0.5, 3.0, 0.3),
        Vector5::new(-4.0, 0.1, 2.0, -1.0, 2.9),
        Vector5::new(0.0, 0.0, 0.0, 0.0, -1.7),
    ] {
        approx::assert_abs_diff_eq!(boje.eval(&x), rep.eval(&x), epsilon = 1e-14);
        approx::assert_abs_diff_eq!(boje.jacobian(&x), rep.jacobian(&x), epsilon = 1e-14);
        for k in 0..4 {
            let (a, b) = (boje.hessian(&x, k), rep.hessian(&x, k));
            assert_eq!(
                a.is_some(),
                b.is_some(),
                "component {k} affine in one form only"
            );
            if let (Some(a), Some(b)) = (a, b) {
                approx::assert_abs_diff_eq!(a, b, epsilon = 1e-14);
            }
        }
    }
}

/// `Outputs::with_noise`: the propagators add the noise in their symmetrising pass; that must
/// be the plain route (moments, then cov + Q symmetrised) bit for bit, and add exactly Q's
/// symmetric part.
#[test]
fn propagating_with_additive_noise_matches_the_default_route() {
    use estim_core::Outputs;
    use estim_core::nalgebra::Matrix3;

    fn check<P: MomentPropagator<f64, U3, U3, TrigSum<f64, U3, U3>>>(name: &str, p: &P) {
        let g = TrigSum::products(U3, U3);
        let mu = vector(U3, &[0.3, -0.7, 1.1]);
        let c = spd(U3, &[0.5, 0.1, -0.2, 0.3, 0.05, 0.4, -0.6, 0.9, 0.2], 1.0);
        // Not exactly symmetric, to see that only its symmetric part is added.
        let q = Matrix3::new(0.2, 0.01, 0.0, 0.011, 0.3, 0.02, 0.0, 0.019, 0.1);
        let mut ws = Default::default();
        let (mut mean, mut cov) = (OVector::<f64, U3>::zeros(), Matrix3::zeros());
        let out = Outputs::mean_covariance(&mut mean, &mut cov).with_noise(&q);
        p.propagate_into(&mu, &c, &g, out, &mut ws).unwrap();
        let (mean0, mut cov0) = p.propagate_mean_covariance(&mu, &c, &g).unwrap();
        assert!(estim_core::linalg::symmetrize_add_checked(&mut cov0, &q));
        for (a, b) in mean
            .iter()
            .chain(cov.iter())
            .zip(mean0.iter().chain(cov0.iter()))
        {
            assert_eq!(a.to_bits(), b.to_bits(), "{name}: {a:e} vs {b:e}");
        }
    }
    check("Linearized", &Linearized);
    check("SecondOrder", &SecondOrder);
    check("SecondOrderGaussian", &SecondOrderGaussian);
    check("Unscented", &Unscented::default());
    check("Sampled", &Sampled::new(2000, 5).unwrap());
}
