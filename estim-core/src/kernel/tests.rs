//! Tests of the kernels: products, Cholesky factor and solves, against nalgebra, each on the
//! routes of the full build and on those of a build without `dense` (`on_both_routes`), so
//! that the one test build (every feature on) tests the lean build's kernels too. Compiled with
//! `dense` only: without it there is only the second set of routes, tested here already.

use super::cholesky::{FAER_STATIC_CHOLESKY_MIN, left_looking_cholesky};
use super::*;
use crate::dense::{LOWER_TRIANGLE_MIN, Matvec};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x2};

/// Runs `check` on the routes of the full build (`lean` false), then on those of a build
/// without `dense` (`lean` true: every static size on nalgebra's fixed-size code and our
/// Cholesky loop, every runtime size on the loops).
fn on_both_routes(check: impl Fn(bool)) {
    check(false);
    // Each test runs on a thread of its own: the setting ends with it.
    super::LEAN_ROUTES.with(|lean| lean.set(true));
    check(true);
}

fn spd(n: usize) -> DMatrix<f64> {
    let g = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 5) as f64 - 2.0);
    &g * g.transpose() + DMatrix::identity(n, n)
}

#[test]
fn dynamic_products_match_nalgebra() {
    on_both_routes(|_| {
        let a = DMatrix::from_fn(4, 3, |i, j| (i as f64) - 0.5 * j as f64);
        let b = DMatrix::from_fn(3, 5, |i, j| 1.0 + (i * j) as f64);
        let mut dst = DMatrix::from_element(4, 5, 1.0);
        mul(&mut dst, Accum::Add, 2.0, &a, &b);
        let expected = DMatrix::from_element(4, 5, 1.0) + 2.0 * &a * &b;
        assert!((dst - expected).amax() < 1e-12);

        let bt = b.transpose();
        let mut dst = DMatrix::zeros(4, 5);
        mul_tr(&mut dst, Accum::Replace, 1.0, &a, &bt);
        assert!((dst - &a * &b).amax() < 1e-12);
    });
}

/// `Matvec` on one instruction set, as `kernel::mul` runs it on the best one.
fn matvec_on<S: pulp::Simd>(
    simd: S,
    y: &mut [f64],
    accum: Accum,
    alpha: f64,
    a: &[f64],
    x: &[f64],
) {
    pulp::WithSimd::with_simd(
        Matvec {
            y,
            accum,
            alpha,
            a,
            x,
        },
        simd,
    );
}

/// The matrix–vector kernel against nalgebra's product, on the instruction set `mul`
/// dispatches to and on scalar and AVX2 code if the CPU has it, on shapes around its panels
/// (1–8 vectors and a remainder of rows, empty ones), both accumulations, α = 1 and not;
/// the bound is the usual dot-product one, |error| ≤ k ε Σ |α aᵢⱼ xⱼ| (+ |y| ε for the
/// accumulation).
#[test]
fn matrix_vector_products_match_nalgebra_on_every_instruction_set() {
    on_both_routes(|lean| {
        let mut row_counts: Vec<usize> = (0..=9).collect();
        row_counts.extend([
            15, 16, 17, 31, 32, 33, 47, 63, 64, 65, 71, 130, 256, 263, 300,
        ]);
        for &rows in &row_counts {
            for cols in [0, 1, 2, 3, 4, 5, 9, 13] {
                let a = DMatrix::from_fn(rows, cols, |i, j| ((i * 5 + j * 3) as f64 * 0.7).sin());
                let x = DVector::from_fn(cols, |i, _| (i as f64 * 1.3).cos() * 1e3);
                let y0 = DVector::from_fn(rows, |i, _| 0.25 * i as f64 - 1.0);
                for (accum, alpha) in [(Accum::Replace, 1.0), (Accum::Add, -0.3)] {
                    let base = if accum == Accum::Add {
                        y0.clone()
                    } else {
                        y0.map(|_| 0.0)
                    };
                    let expected = &base + alpha * (&a * &x);
                    let scale = base.abs() + (alpha.abs() * a.abs() * x.abs());
                    let k = (cols + 2) as f64;
                    let check = |y: &DVector<f64>, set: &str| {
                        for i in 0..rows {
                            let bound = k * f64::EPSILON * scale[i];
                            assert!(
                                (y[i] - expected[i]).abs() <= bound,
                                "{set} {rows}×{cols} row {i}: {} vs {} bound {bound}",
                                y[i],
                                expected[i]
                            );
                        }
                    };
                    let mut y = y0.clone();
                    mul(&mut y, accum, alpha, &a, &x);
                    check(&y, "dispatched");
                    if !lean {
                        let (a_, x_) = (a.as_slice(), x.as_slice());
                        let mut y = y0.clone();
                        matvec_on(pulp::Scalar::new(), y.as_mut_slice(), accum, alpha, a_, x_);
                        check(&y, "scalar");
                        #[cfg(target_arch = "x86_64")]
                        if let Some(simd) = pulp::x86::V3::try_new() {
                            let mut y = y0.clone();
                            matvec_on(simd, y.as_mut_slice(), accum, alpha, a_, x_);
                            check(&y, "AVX2");
                        }
                    }
                }
            }
        }
    });
}

#[test]
fn cholesky_and_solves_agree_static_and_dynamic() {
    on_both_routes(|_| {
        let s = spd(3);
        let b = DMatrix::from_fn(3, 2, |i, j| (i + 2 * j) as f64);
        let mut scratch = CholeskyScratch::default();

        let mut l = s.clone();
        assert!(cholesky_in_place(&mut l, &mut scratch));
        let mut x = b.clone();
        solve_lower_in_place(&l, &mut x);
        assert!((l.lower_triangle() * &x - &b).amax() < 1e-10);
        assert!((l.lower_triangle() * l.lower_triangle().transpose() - &s).amax() < 1e-10);

        let mut ls = Matrix3::from_iterator(s.iter().copied());
        assert!(cholesky_in_place(&mut ls, &mut scratch));
        let mut xs = Matrix3x2::from_iterator(b.iter().copied());
        solve_lower_in_place(&ls, &mut xs);
        for i in 0..3 {
            for j in 0..2 {
                assert!((xs[(i, j)] - x[(i, j)]).abs() < 1e-12);
            }
        }
    });
}

/// The runtime-size Cholesky factor (faer's) on orders from 0 to past 96 (where our own
/// column kernel used to hand over to faer's), f64 and f32: lower triangular with a positive
/// diagonal, and a backward error within Higham's bound |L Lᵀ − A| ≤ γₙ₊₁ |L| |L|ᵀ
/// (elementwise, γₖ = kε / (1 − kε)); a matrix that fails the pivot test at its first,
/// middle or last column, or holds a NaN or infinity below the diagonal, is refused.
#[test]
fn cholesky_factors_have_a_small_backward_error() {
    on_both_routes(|_| {
        let mut scratch = CholeskyScratch::default();
        let below = 96;
        for n in [
            0,
            1,
            2,
            3,
            4,
            5,
            7,
            8,
            9,
            17,
            33,
            50,
            below - 1,
            below,
            below + 5,
        ] {
            // A spread-out spectrum: eigenvalues of G Gᵀ / n plus 10⁻³.
            let g = DMatrix::from_fn(n, n, |i, j| ((i * 13 + j * 7) as f64 * 0.37).sin());
            let a = &g * g.transpose() / n.max(1) as f64 + DMatrix::identity(n, n) * 1e-3;
            let mut l = a.clone();
            assert!(cholesky_in_place(&mut l, &mut scratch), "n = {n}");
            let l = l.lower_triangle();
            let gamma = |eps: f64| (n + 1) as f64 * eps / (1.0 - (n + 1) as f64 * eps);
            let residual = &l * l.transpose() - &a;
            let scale = l.abs() * l.abs().transpose();
            for i in 0..n {
                assert!(l[(i, i)] > 0.0);
                for j in 0..n {
                    let bound = gamma(f64::EPSILON) * scale[(i, j)];
                    assert!(residual[(i, j)].abs() <= bound, "n = {n} ({i}, {j})");
                }
            }
            let a32 = a.map(|v| v as f32);
            let mut l32 = a32.clone();
            assert!(cholesky_in_place(&mut l32, &mut scratch), "f32 n = {n}");
            let l32 = l32.lower_triangle().map(f64::from);
            let residual = &l32 * l32.transpose() - a32.map(f64::from);
            let scale = l32.abs() * l32.abs().transpose();
            for (r, s) in residual.iter().zip(scale.iter()) {
                assert!(r.abs() <= gamma(f32::EPSILON as f64) * s, "f32 n = {n}");
            }
            if n < 2 {
                continue;
            }
            for k in [0, n / 2, n - 1] {
                // Pivot k non-positive: a_kk lowered to the sum of squares it must exceed.
                let mut bad = a.clone();
                bad[(k, k)] = l.row(k).columns(0, k).norm_squared() - 1e-3;
                assert!(
                    !cholesky_in_place(&mut bad, &mut scratch),
                    "n = {n} pivot {k}"
                );
            }
            for v in [f64::NAN, f64::INFINITY] {
                let mut bad = a.clone();
                bad[(n - 1, n / 2 - 1)] = v;
                assert!(!cholesky_in_place(&mut bad, &mut scratch), "n = {n} {v}");
            }
        }
    });
}

#[test]
fn lower_products_match_the_full_product_on_the_lower_triangle() {
    on_both_routes(|_| {
        // Below and above LOWER_TRIANGLE_MIN: full product, triangular kernel.
        for n in [5, LOWER_TRIANGLE_MIN + 7] {
            lower_products_match_at(n);
        }
    });
}

/// `mul_tr_lower` on orders around [`LOWER_TRIANGLE_MIN`] and beyond, k = 0, 1, 7, 50,
/// both accumulations, f64 and f32, against nalgebra's full product on the lower
/// triangle: |error| ≤ (k + 2) ε (|start| + |α| |A| |B|ᵀ).
#[test]
fn lower_triangle_products_match_nalgebra() {
    on_both_routes(|_| {
        let orders = [
            15, 16, 17, 20, 23, 24, 25, 31, 32, 33, 47, 48, 49, 50, 55, 63, 64, 65, 100, 127, 128,
            129,
        ];
        for n in orders {
            for k in [0, 1, 7, 50] {
                let a = DMatrix::from_fn(n, k, |i, j| ((i * 3 + j * 5) as f64 * 0.61).sin());
                let b = DMatrix::from_fn(n, k, |i, j| ((i * 7 + j * 2) as f64 * 0.37).cos());
                let start = DMatrix::from_fn(n, n, |i, j| 0.5 * i as f64 - 0.25 * j as f64);
                for (accum, alpha) in [(Accum::Replace, 1.0), (Accum::Add, -0.7)] {
                    let base = match accum {
                        Accum::Replace => DMatrix::zeros(n, n),
                        Accum::Add => start.clone(),
                    };
                    let expected = &base + alpha * &a * b.transpose();
                    let scale = base.abs() + alpha.abs() * a.abs() * b.abs().transpose();
                    let check = |dst: &DMatrix<f64>, eps: f64, set: &str| {
                        for j in 0..n {
                            for i in j..n {
                                let bound = (k + 2) as f64 * eps * scale[(i, j)];
                                let error = (dst[(i, j)] - expected[(i, j)]).abs();
                                assert!(error <= bound, "{set} n = {n} k = {k} ({i}, {j})");
                            }
                        }
                    };
                    let mut dst = start.clone();
                    mul_tr_lower(&mut dst, accum, alpha, &a, &b);
                    check(&dst, f64::EPSILON, "mul_tr_lower");
                    // f32: the inputs rounded to f32 first, so the bound is in f32's ε.
                    let (a32, b32) = (a.map(|v| v as f32), b.map(|v| v as f32));
                    let mut dst32 = start.map(|v| v as f32);
                    mul_tr_lower(&mut dst32, accum, alpha as f32, &a32, &b32);
                    check(&dst32.map(f64::from), 2.0 * f32::EPSILON as f64, "f32");
                }
            }
        }
    });
}

fn lower_products_match_at(n: usize) {
    let a = DMatrix::from_fn(n, 3, |i, j| (i as f64) - 0.7 * j as f64 + 0.1);
    let b = DMatrix::from_fn(3, n, |i, j| 1.0 + (i * j) as f64 - 0.3 * i as f64);
    let full = &a * &b;
    for accum in [Accum::Replace, Accum::Add] {
        let start = DMatrix::from_fn(n, n, |i, j| (i + 2 * j) as f64);
        let expected = match accum {
            Accum::Replace => 2.0 * &full,
            Accum::Add => &start + 2.0 * &full,
        };
        let mut dst = start.clone();
        mul_lower(&mut dst, accum, 2.0, &a, &b);
        let mut dst_tr = start.clone();
        mul_tr_lower(&mut dst_tr, accum, 2.0, &a, &b.transpose());
        // Each entry sums 3 products (plus the start value): a few ulps of the largest.
        let tol = 8.0 * f64::EPSILON * expected.amax();
        for j in 0..n {
            for i in j..n {
                assert!(
                    (dst[(i, j)] - expected[(i, j)]).abs() <= tol,
                    "n = {n}, ({i}, {j})"
                );
                assert!(
                    (dst_tr[(i, j)] - expected[(i, j)]).abs() <= tol,
                    "n = {n}, ({i}, {j})"
                );
            }
        }
    }
}

/// A static size above [`STATIC_NALGEBRA_MAX`] (12 × 12, 12 × 5) takes the runtime-size
/// kernels on its own storage: products, the Cholesky factor and the solves agree with
/// nalgebra's own fixed-size operators and `Cholesky` to round-off.
#[test]
fn large_static_sizes_match_nalgebra() {
    on_both_routes(|_| {
        use nalgebra::{SMatrix, SVector};
        let a = SMatrix::<f64, 12, 12>::from_fn(|i, j| ((i * 5 + j * 3) as f64 * 0.7).sin());
        let b = SMatrix::<f64, 12, 5>::from_fn(|i, j| ((i * 2 + j * 7) as f64 * 0.3).cos());
        let s = a * a.transpose() + SMatrix::<f64, 12, 12>::identity();
        let mut dst = SMatrix::<f64, 12, 5>::from_element(1.0);
        mul(&mut dst, Accum::Add, 2.0, &a, &b);
        let expected = SMatrix::<f64, 12, 5>::from_element(1.0) + 2.0 * a * b;
        assert!((dst - expected).amax() < 1e-12);
        let mut aat = SMatrix::<f64, 12, 12>::zeros();
        mul_tr(&mut aat, Accum::Replace, 1.0, &a, &a);
        assert!((aat - a * a.transpose()).amax() < 1e-12);
        let mut x = SVector::<f64, 12>::zeros();
        let v = SVector::<f64, 12>::from_fn(|i, _| i as f64 - 5.5);
        mul(&mut x, Accum::Replace, 1.0, &a, &v);
        assert!((x - a * v).amax() < 1e-12);
        let mut l = s;
        let mut scratch = CholeskyScratch::default();
        assert!(cholesky_in_place(&mut l, &mut scratch));
        let reference = s.cholesky().expect("positive definite").unpack();
        assert!((l.lower_triangle() - reference).amax() < 1e-12);
        let mut y = b;
        solve_lower_in_place(&l, &mut y);
        assert!((reference * y - b).amax() < 1e-10);
        let mut bad = s;
        bad[(11, 11)] = -1.0;
        assert!(!cholesky_in_place(&mut bad, &mut scratch));
    });
}

#[test]
fn right_solves_agree_static_and_dynamic() {
    on_both_routes(|_| {
        let s = spd(4);
        let b = DMatrix::from_fn(3, 4, |i, j| (i + 2 * j) as f64 - 1.5);
        let mut scratch = CholeskyScratch::default();
        let mut l = s.clone();
        assert!(cholesky_in_place(&mut l, &mut scratch));
        // B S⁻¹ = B L⁻ᵀ L⁻¹.
        let mut x = b.clone();
        solve_right_lower_transpose_in_place(&l, &mut x);
        solve_right_lower_in_place(&l, &mut x);
        assert!((&x * &s - &b).amax() < 1e-10);

        let ls = nalgebra::Matrix4::from_iterator(l.iter().copied());
        let mut xs = nalgebra::Matrix3x4::from_iterator(b.iter().copied());
        solve_right_lower_transpose_in_place(&ls, &mut xs);
        let mut half = b.clone();
        solve_right_lower_transpose_in_place(&l, &mut half);
        let lower = l.lower_triangle();
        assert!((&half * lower.transpose() - &b).amax() < 1e-10);
        solve_right_lower_in_place(&ls, &mut xs);
        for i in 0..3 {
            for j in 0..4 {
                assert!((xs[(i, j)] - x[(i, j)]).abs() < 1e-12);
            }
        }
    });
}

/// A runtime-size matrix times a vector whose shapes disagree but whose entry counts
/// match (4 × 6 times 4 into 6) panics, as every other product does, instead of running.
#[test]
#[should_panic(expected = "matrix × vector")]
fn matrix_vector_shape_mismatch_panics() {
    let a = DMatrix::<f64>::zeros(4, 6);
    let x = DVector::<f64>::zeros(4);
    let mut y = DVector::<f64>::zeros(6);
    mul(&mut y, Accum::Replace, 1.0, &a, &x);
}

#[test]
fn cholesky_rejects_indefinite_and_non_finite() {
    on_both_routes(|_| {
        let mut scratch = CholeskyScratch::default();
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(!cholesky_in_place(&mut a, &mut scratch));
        let mut a = DMatrix::from_row_slice(2, 2, &[f64::NAN, 0.0, 0.0, 1.0]);
        assert!(!cholesky_in_place(&mut a, &mut scratch));
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, f64::NAN]);
        assert!(!cholesky_in_place(&mut a, &mut scratch));
    });
}

/// Static sizes above 16 factorise by faer's Cholesky (scratch on the stack): the same
/// factor as the inlined loop to round-off, with the same refusals; at 16 (and at every size
/// on the lean routes) the loop's bits.
#[test]
fn large_static_cholesky_is_faers_and_agrees_with_the_loop() {
    on_both_routes(|lean| {
        use nalgebra::{Const, SMatrix};
        fn at<const N: usize>(lean: bool) {
            let g = SMatrix::<f64, N, N>::from_fn(|i, j| {
                (((i * 7 + j * 3) % 11) as f64 - 5.0) / 3.0 + 0.01 * (i * j) as f64
            });
            let spd = g * g.transpose() + SMatrix::<f64, N, N>::identity() * 1e-3;
            let mut scratch = CholeskyScratch::default();
            let (mut library, mut rows) = (spd, spd);
            assert!(cholesky_in_place(&mut library, &mut scratch));
            assert!(left_looking_cholesky::<f64, Const<N>>(&mut rows));
            let (library, rows) = (library.lower_triangle(), rows.lower_triangle());
            if lean || N <= FAER_STATIC_CHOLESKY_MIN {
                assert_eq!(library, rows, "{N}");
            }
            // Backward stable: L Lᵀ = A + E with |E| ≲ n ε |L| |L|ᵀ; ‖A‖ ≈ 25 n here.
            let bound = 4.0 * N as f64 * f64::EPSILON * (rows.abs() * rows.abs().transpose()).max();
            assert!(
                (library * library.transpose() - spd).abs().max() < bound,
                "{N}"
            );
            assert!((rows * rows.transpose() - spd).abs().max() < bound, "{N}");
            // Indefinite (a large negative shift) and NaN: refused by both.
            for bad in [spd - SMatrix::<f64, N, N>::identity() * 1e3, {
                let mut m = spd;
                m[(N - 1, N - 1)] = f64::NAN;
                m
            }] {
                let (mut l, mut r) = (bad, bad);
                assert!(!cholesky_in_place(&mut l, &mut scratch), "{N}");
                assert!(!left_looking_cholesky::<f64, Const<N>>(&mut r), "{N}");
            }
        }
        at::<3>(lean);
        at::<16>(lean);
        at::<17>(lean);
        at::<24>(lean);
        at::<50>(lean);
    });
}

/// Every product form on runtime sizes around [`SMALL_RUNTIME_WORK`] (the loops below it, faer
/// above it with `dense`; the loops at every size without), empty shapes included, both
/// accumulations, α = 1 and not, f64 and f32, against nalgebra's allocating product:
/// |error| ≤ (k + 2) ε (|start| + |α| |A| |B|), the dot-product bound (ε of f32 for f32, on
/// inputs rounded to f32 first). `Replace` never reads the destination (NaN there is
/// overwritten), `Add` adds to it.
#[test]
fn runtime_products_match_nalgebra_on_both_sides_of_the_small_route() {
    on_both_routes(|_| {
        // (rows, inner, cols): empty, 1-5 rows (the register and the pass-per-term loops),
        // UKF-like (n, 2n + 1, n), at and just above the threshold, larger.
        let at = SMALL_RUNTIME_WORK / 16;
        let shapes = [
            (0, 3, 2),
            (3, 0, 2),
            (2, 3, 0),
            (1, 1, 1),
            (2, 2, 2),
            (3, 4, 2),
            (2, 5, 2),
            (4, 9, 4),
            (5, 3, 5),
            (4, 4, at),
            (4, 4, at + 1),
            (6, 13, 6),
            (9, 9, 9),
            (12, 25, 12),
            (6, 1, 1),
            (3, 7, 1),
            (40, 13, 1),
        ];
        assert!(4 * 4 * at <= SMALL_RUNTIME_WORK && 4 * 4 * (at + 1) > SMALL_RUNTIME_WORK);
        for (rows, inner, cols) in shapes {
            let a = DMatrix::from_fn(rows, inner, |i, j| ((i * 3 + j * 5) as f64 * 0.61).sin());
            let b = DMatrix::from_fn(inner, cols, |i, j| ((i * 7 + j * 2) as f64 * 0.37).cos());
            let bt = b.transpose();
            let start = DMatrix::from_fn(rows, cols, |i, j| 0.5 * i as f64 - 0.25 * j as f64);
            for (accum, alpha) in [(Accum::Replace, 1.0), (Accum::Add, -0.7)] {
                let base = match accum {
                    Accum::Replace => DMatrix::zeros(rows, cols),
                    Accum::Add => start.clone(),
                };
                let expected = &base + alpha * &a * &b;
                let scale = base.abs() + alpha.abs() * a.abs() * b.abs();
                let what = format!("{rows}×{inner}×{cols} {accum:?}");
                let check = |dst: &DMatrix<f64>, eps: f64, lower_only: bool, form: &str| {
                    for j in 0..cols {
                        let first = if lower_only { j } else { 0 };
                        for i in first..rows {
                            let bound = (inner + 2) as f64 * eps * scale[(i, j)];
                            let error = (dst[(i, j)] - expected[(i, j)]).abs();
                            assert!(
                                error <= bound,
                                "{form} {what} ({i}, {j}): {error} > {bound}"
                            );
                        }
                    }
                };
                // Replace must not read dst: start it at NaN then.
                let initial = match accum {
                    Accum::Replace => DMatrix::from_element(rows, cols, f64::NAN),
                    Accum::Add => start.clone(),
                };
                let mut dst = initial.clone();
                mul(&mut dst, accum, alpha, &a, &b);
                check(&dst, f64::EPSILON, false, "mul");
                let mut dst = initial.clone();
                mul_tr(&mut dst, accum, alpha, &a, &bt);
                check(&dst, f64::EPSILON, false, "mul_tr");
                if rows == cols {
                    let mut dst = initial.clone();
                    mul_lower(&mut dst, accum, alpha, &a, &b);
                    check(&dst, f64::EPSILON, true, "mul_lower");
                    let mut dst = initial.clone();
                    mul_tr_lower(&mut dst, accum, alpha, &a, &bt);
                    check(&dst, f64::EPSILON, true, "mul_tr_lower");
                }
                let (a32, b32) = (a.map(|v| v as f32), b.map(|v| v as f32));
                let mut dst32 = initial.map(|v| v as f32);
                mul(&mut dst32, accum, alpha as f32, &a32, &b32);
                check(
                    &dst32.map(f64::from),
                    2.0 * f32::EPSILON as f64,
                    false,
                    "f32",
                );
            }
        }
    });
}

/// Runtime-size Cholesky factors and solves on both sides of [`SMALL_RUNTIME_CHOLESKY`] (our
/// loop up to it, faer above with `dense`): L Lᵀ = A to the backward-error bound
/// 4 n ε max(|L| |L|ᵀ), the solves' residuals to 1e-9 (well-conditioned matrices of entries
/// ≤ 25 n), and the same refusals (a negative pivot, NaN).
#[test]
fn runtime_cholesky_and_solves_on_both_sides_of_the_small_route() {
    on_both_routes(|_| {
        for n in [
            1,
            2,
            6,
            SMALL_RUNTIME_CHOLESKY,
            SMALL_RUNTIME_CHOLESKY + 1,
            13,
        ] {
            let a = spd(n);
            let mut scratch = CholeskyScratch::default();
            let mut l = a.clone();
            assert!(cholesky_in_place(&mut l, &mut scratch), "n = {n}");
            let l = l.lower_triangle();
            let bound = 4.0 * n as f64 * f64::EPSILON * (l.abs() * l.abs().transpose()).max();
            assert!((&l * l.transpose() - &a).amax() <= bound, "n = {n}");
            let b = DMatrix::from_fn(n, 3, |i, j| (i + 2 * j) as f64 - 1.5);
            let mut x = b.clone();
            solve_lower_in_place(&l, &mut x);
            assert!((&l * &x - &b).amax() < 1e-9, "n = {n}");
            let bt = b.transpose();
            let mut y = bt.clone();
            solve_right_lower_transpose_in_place(&l, &mut y);
            solve_right_lower_in_place(&l, &mut y);
            assert!((&y * &a - &bt).amax() < 1e-9, "n = {n}");
            let mut bad = a.clone();
            bad[(n - 1, n - 1)] = -1.0;
            assert!(!cholesky_in_place(&mut bad, &mut scratch), "n = {n}");
            let mut bad = a.clone();
            bad[(n - 1, 0)] = f64::NAN;
            assert!(!cholesky_in_place(&mut bad, &mut scratch), "n = {n}");
        }
    });
}
