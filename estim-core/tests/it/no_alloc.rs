//! With static sizes, propagating moments does not touch the heap: a counting global allocator
//! (per-thread counter, so the parallel test threads do not see each other's allocations)
//! observes zero allocations for every propagator on 6 → 4 functions, for the derivative
//! checker, for `Gaussian::new`, and on error paths.
//!
//! The test functions (`common::TrigSum`, `common::Quadratic`) keep their coefficients in a
//! `Vec`, allocated once before measuring; evaluating them only reads it.

use crate::common;
// The counting global allocator (shared with estim-filters' allocation tests).
use crate::counting::allocations;

use common::*;
use estim_core::nalgebra::{Matrix4x6, Matrix6, U4, U5, U6, Vector4, Vector5, Vector6};
use estim_core::{
    Error, Gaussian, Linearized, MomentPropagator, Sampled, SecondOrder, SecondOrderGaussian,
    Unscented, derivative,
};

#[test]
fn the_counter_sees_heap_allocations() {
    let (v, n) = allocations(|| vec![1.0f64; 100]);
    assert_eq!(v.len(), 100);
    assert_eq!(n, 1);
    let (s, n) = allocations(|| {
        let mut s = String::new();
        for _ in 0..100 {
            s.push_str("grow");
        }
        s
    });
    assert_eq!(s.len(), 400);
    assert!(n >= 2, "growing a String reallocates ({n})");
    let (_, n) = allocations(|| Vector6::<f64>::repeat(1.0) * 2.0);
    assert_eq!(n, 0, "static nalgebra arithmetic is on the stack");
}

fn problem() -> (Vector6<f64>, Matrix6<f64>) {
    let mu = Vector6::new(0.3, -1.2, 0.8, 2.0, -0.5, 1.1);
    let c = spd(
        U6,
        &(0..36)
            .map(|i| ((i * 7 % 11) as f64 - 5.0) / 5.0)
            .collect::<Vec<_>>(),
        0.3,
    );
    (mu, c)
}

/// Asserts that every propagator, including the first call (no lazy initialisation), makes
/// zero allocations on `g`.
fn assert_propagators_do_not_allocate<G>(what: &str, g: &G, mu: &Vector6<f64>, c: &Matrix6<f64>)
where
    G: estim_core::TwiceDifferentiable<f64, U6, U4>,
{
    macro_rules! check {
        ($name:expr, $p:expr) => {{
            let p = $p;
            let (r, n) = allocations(|| p.propagate(mu, c, g));
            assert!(r.is_ok(), "{what} {}: {r:?}", $name);
            assert_eq!(n, 0, "{what} {}: {n} heap allocations", $name);
        }};
    }
    check!("Linearized", Linearized);
    check!("SecondOrder", SecondOrder);
    check!("SecondOrderGaussian", SecondOrderGaussian);
    check!("Unscented::default", Unscented::<f64>::default());
    check!("Unscented::cubature", Unscented::<f64>::cubature());
    // A negative κ (accepted with β = 1: α²κ + nβ = 3 ≥ 0 for n = 6).
    check!("Unscented κ = −3", Unscented::new(1.0, 1.0, -3.0).unwrap());
    // Sampled seeds a StdRng (ChaCha12, state inline) and draws with the ziggurat tables
    // (statics): it does not allocate either.
    check!("Sampled", Sampled::new(1000, 7).unwrap());
}

#[test]
fn propagators_do_not_allocate_for_static_sizes() {
    let (mu, c) = problem();
    let params: Vec<f64> = (0..TrigSum::<f64, U6, U4>::random_len(6, 4))
        .map(|i| ((i * 13 % 17) as f64 - 8.0) / 8.0)
        .collect();
    let trig = TrigSum::random(U6, U4, &params);
    assert_propagators_do_not_allocate("TrigSum 6 → 4", &trig, &mu, &c);

    let q: Vec<Matrix6<f64>> = (0..4)
        .map(|k| {
            let r = Matrix6::from_fn(|i, j| ((i + 2 * j + k) % 5) as f64 - 2.0);
            (r + r.transpose()) * 0.5
        })
        .collect();
    let quad = Quadratic {
        q,
        a: Matrix4x6::from_fn(|i, j| (i as f64) - (j as f64) * 0.5),
        c: Vector4::new(1.0, 2.0, 3.0, 4.0),
    };
    assert_propagators_do_not_allocate("Quadratic 6 → 4", &quad, &mu, &c);

    let affine = AffineMap {
        a: Matrix4x6::from_fn(|i, j| ((i * j) % 3) as f64 - 1.0),
        b: Vector4::new(0.5, -0.5, 1.0, 0.0),
    };
    assert_propagators_do_not_allocate("AffineMap 6 → 4", &affine, &mu, &c);
    let (r, n) = allocations(|| estim_core::Affine.propagate(&mu, &c, &affine));
    assert!(r.is_ok());
    assert_eq!(n, 0, "Affine: {n} heap allocations");
}

#[test]
fn boje_eq5_does_not_allocate() {
    let boje = Boje { r: 0.1 };
    let mu = Vector5::new(1.0, -0.5, 2.0, 0.3, 0.7);
    let c =
        estim_core::nalgebra::Matrix5::from_diagonal(&Vector5::new(0.01, 0.01, 0.02, 0.02, 0.04));
    let g = Gaussian::new(mu, c).unwrap();
    macro_rules! check {
        ($name:expr, $p:expr) => {{
            let p = $p;
            let (r, n) = allocations(|| p.propagate_gaussian(&g, &boje));
            let _: estim_core::Moments<f64, U5, U4> = r.unwrap();
            assert_eq!(n, 0, "{}: {n} heap allocations", $name);
        }};
    }
    check!("Linearized", Linearized);
    check!("SecondOrder", SecondOrder);
    check!("SecondOrderGaussian", SecondOrderGaussian);
    check!("Unscented", Unscented::<f64>::default());
    check!("Sampled", Sampled::new(100, 1).unwrap());
    // f32 too.
    let boje32 = Boje { r: 0.1f32 };
    let (mu32, c32) = (to32(&mu), to32(&c));
    let (r, n) = allocations(|| SecondOrderGaussian.propagate(&mu32, &c32, &boje32));
    assert!(r.is_ok());
    assert_eq!(n, 0);
    let (r, n) = allocations(|| Unscented::<f32>::cubature().propagate(&mu32, &c32, &boje32));
    assert!(r.is_ok());
    assert_eq!(n, 0);
}

#[test]
fn checks_and_errors_do_not_allocate() {
    let (mu, c) = problem();
    let (g, n) = allocations(|| Gaussian::new(mu, c));
    assert!(g.is_ok());
    assert_eq!(n, 0, "Gaussian::new");
    let (g, n) = allocations(|| Gaussian::new(mu, -c));
    assert!(matches!(g, Err(Error::NotPositiveSemiDefinite { .. })));
    assert_eq!(n, 0, "Gaussian::new error path");

    let products = TrigSum::products(estim_core::nalgebra::U3, estim_core::nalgebra::U3);
    let x = estim_core::nalgebra::Vector3::new(0.1, 0.2, 0.3);
    let (report, n) = allocations(|| derivative::check_derivatives(&products, &x));
    assert!(report.unwrap().is_accurate(1e-6));
    assert_eq!(n, 0, "derivative check");

    let params: Vec<f64> = (0..TrigSum::<f64, U6, U4>::random_len(6, 4))
        .map(|i| (i % 5) as f64 * 0.2)
        .collect();
    let trig = TrigSum::random(U6, U4, &params);
    let (r, n) = allocations(|| Unscented::<f64>::default().propagate(&mu, &(-c), &trig));
    assert!(matches!(r, Err(Error::NotPositiveSemiDefinite { .. })));
    assert_eq!(n, 0, "unscented error path");
    // n + κ = 0 for n = 6, refused at propagation.
    let ut = Unscented::new(1.0, 2.0, -6.0).unwrap();
    let (r, n) = allocations(|| ut.propagate(&mu, &c, &trig));
    assert!(matches!(r, Err(Error::InvalidParameter { .. })));
    assert_eq!(n, 0, "unscented parameter error path");
}
