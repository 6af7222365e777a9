//! The two factor kernels of the square-root filters: lower-triangularising a pre-array by
//! Householder reflections, and a rank-one Cholesky downdate that reports failure.
//!
//! Both work on column-major slices, so one code path serves static and runtime sizes and
//! a pre-array can be assembled from blocks of different static shapes (an (m + n)-row
//! array has no static type for generic m and n on stable Rust, which is why nalgebra's
//! `QR`, which needs the stacked matrix as one `OMatrix`, is not used; it would also allocate
//! its Householder coefficients and its R at runtime sizes).

mod givens;

use estim_core::Real;
use estim_core::scalar::real;

/// One column block of a pre-array: `cols` columns, each made of `p` rows in `top` followed
/// by `r` rows in `bottom` (both column-major, `top.len() = p · cols`,
/// `bottom.len() = r · cols`). Every block of one pre-array has the same p and r.
pub(crate) struct Block<'a, T> {
    pub(crate) top: &'a mut [T],
    pub(crate) bottom: &'a mut [T],
    pub(crate) cols: usize,
}

impl<'a, T> Block<'a, T> {
    /// A block of `cols` columns with `bottom` rows below `top`.
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn new(top: &'a mut [T], bottom: &'a mut [T], cols: usize) -> Self {
        Self { top, bottom, cols }
    }
}

/// Where row i of the pre-array lives in every block: (in `top`, offset, stride): entry
/// (i, c) of a block is `top[c · p + i]` or `bottom[c · r + i − p]`.
#[cfg_attr(not(debug_assertions), inline(always))]
fn slot(i: usize, p: usize, r: usize) -> (bool, usize, usize) {
    if i < p {
        (true, i, p)
    } else {
        (false, i - p, r)
    }
}

/// The part (`top` or `bottom`) of `block` that holds a row.
#[cfg_attr(not(debug_assertions), inline(always))]
fn part<'b, T>(block: &'b Block<'_, T>, top: bool) -> &'b [T] {
    if top { block.top } else { block.bottom }
}

/// [`part`], mutably.
#[cfg_attr(not(debug_assertions), inline(always))]
fn part_mut<'b, T>(block: &'b mut Block<'_, T>, top: bool) -> &'b mut [T] {
    if top { block.top } else { block.bottom }
}

/// The squared norm below which (or at ∞) a row's norm is recomputed with scaling: the
/// smallest normal number over ε, so that no square that matters has underflowed.
#[cfg_attr(not(debug_assertions), inline(always))]
fn scaling_threshold<T: Real>() -> T {
    if T::default_epsilon() < real(1e-10) {
        real(f64::MIN_POSITIVE / f64::EPSILON)
    } else {
        real(f64::from(f32::MIN_POSITIVE) / f64::from(f32::EPSILON))
    }
}

/// The most blocks a pre-array has (the SR-UKF update's).
const MAX_BLOCKS: usize = 4;

/// The most rows a pre-array is triangularised by Householder reflections
/// ([`householder`]); larger ones go to the Givens form ([`givens`]). Measured by
/// instruction counts (`square_root_counted.sh`): at 6/4 (10 rows) the reflections take the
/// SR-KF step from 32.5k to 29.0k instructions and the SR-UKF's from 54.0k to 41.7k; at 20/10
/// (30 rows) they took it from 414k to 481k, at 50/20 from 3.3M to 5.2M: they walk rows
/// across column-major blocks, strided, where the rotations move contiguous columns.
const HOUSEHOLDER_ROWS: usize = 16;

/// Lower-triangularises the pre-array A (p + r rows, the blocks' columns side by side) in
/// place: A Θ = [L 0] with Θ orthogonal, so L Lᵀ = A Aᵀ, L lower triangular (trapezoidal if A
/// has fewer columns than rows) with a non-negative diagonal; the R factor of the QR
/// factorisation of Aᵀ, transposed. By Householder reflections up to [`HOUSEHOLDER_ROWS`]
/// rows, by Givens rotations above (both backward stable: the computed L is the exact factor
/// of A Aᵀ + E with ‖E‖ = O(ε‖A‖²), never of an indefinite matrix). Non-finite entries
/// propagate (the caller checks the result).
///
/// # Panics
///
/// With more than four blocks, or a block whose slices are shorter than its `cols` columns of
/// p (r) rows.
#[track_caller]
pub(crate) fn lower_triangularize<T: Real>(p: usize, r: usize, blocks: &mut [Block<'_, T>]) {
    if p + r <= HOUSEHOLDER_ROWS {
        householder(p, r, blocks);
    } else {
        givens::lower_triangularize(p, r, blocks);
    }
}

/// [`lower_triangularize`] by Householder reflections from the right.
///
/// Row i is finished by one reflection of the columns i.. : with v = A[i, i..],
/// σ = ‖v‖, u = v + sign(v₀) σ e₀ and H = I − 2 u uᵀ/(uᵀu), v H = −sign(v₀) σ e₀ᵀ. Stored as
/// ũ = u/u₀ (|ũⱼ| ≤ 1, kept in row i while the reflection is applied) and τ = 1 + |v₀|/σ,
/// H = I − τ ũ ũᵀ, so each row k below i takes wₖ = τ A[k, i..] ũ and A[k, i..] −= wₖ ũᵀ.
/// Column i is negated when −sign(v₀) σ < 0, for a non-negative diagonal. Only the columns
/// from i to the last nonzero ũⱼ of each block are visited, so the zero blocks and triangular
/// factors of the filters' pre-arrays (and the triangular fill-in of [F S | S_Q]) cost nothing.
/// Backward stable (Golub & Van Loan §5.2): the computed L is the exact factor of
/// A Aᵀ + E with ‖E‖ = O(ε‖A‖²), never of an indefinite matrix. σ is computed as √(Σ vⱼ²)
/// unless that sum under- or overflows, then as m √(Σ (vⱼ/m)²) with m = maxⱼ |vⱼ|.
/// Non-finite entries propagate (the caller checks the result).
///
/// # Panics
///
/// With more than four blocks, or a block whose slices are shorter than its `cols` columns of
/// p (r) rows.
#[track_caller]
fn householder<T: Real>(p: usize, r: usize, blocks: &mut [Block<'_, T>]) {
    assert!(blocks.len() <= MAX_BLOCKS, "at most {MAX_BLOCKS} blocks");
    let rows = p + r;
    let cols: usize = blocks.iter().map(|b| b.cols).sum();
    let threshold = scaling_threshold::<T>();
    for i in 0..rows.min(cols) {
        let (ti, oi, si) = slot(i, p, r);
        // Per block, the columns [lo, hi) from i to the last nonzero entry of row i.
        let mut range = [(0usize, 0usize); MAX_BLOCKS];
        let (mut diagonal, mut rest) = (T::zero(), T::zero());
        // Whether row i has a nonzero right of the diagonal (its squares may underflow to 0).
        let mut off_diagonal = false;
        let mut base = 0;
        for (b, block) in blocks.iter().enumerate() {
            let lo = i.saturating_sub(base).min(block.cols);
            let row = part(block, ti);
            let mut hi = lo;
            for c in lo..block.cols {
                let v = row[c * si + oi];
                if base + c == i {
                    diagonal = v;
                    hi = c + 1;
                } else if v != T::zero() {
                    rest += v * v;
                    hi = c + 1;
                    off_diagonal = true;
                }
            }
            range[b] = (lo, hi);
            base += block.cols;
        }
        let (bi, ci) = locate(blocks, i);
        if !off_diagonal {
            if diagonal < T::zero() {
                let block = &mut blocks[bi];
                for k in i..rows {
                    let (tk, ok, sk) = slot(k, p, r);
                    let e = &mut part_mut(block, tk)[ci * sk + ok];
                    *e = -*e;
                }
            }
            continue;
        }
        let total = diagonal * diagonal + rest;
        let sigma = if total >= threshold && total.is_finite() {
            total.sqrt()
        } else {
            let mut largest = T::zero();
            for (b, block) in blocks.iter().enumerate() {
                let row = part(block, ti);
                for c in range[b].0..range[b].1 {
                    largest = largest.max(row[c * si + oi].abs());
                }
            }
            let inverse = T::one() / largest;
            let mut sum = T::zero();
            for (b, block) in blocks.iter().enumerate() {
                let row = part(block, ti);
                for c in range[b].0..range[b].1 {
                    let v = row[c * si + oi] * inverse;
                    sum += v * v;
                }
            }
            largest * sum.sqrt()
        };
        // u₀ = v₀ + sign(v₀) σ (no cancellation): the reflection maps v to −sign(v₀) σ e₀.
        let positive = diagonal >= T::zero();
        let u0 = if positive {
            diagonal + sigma
        } else {
            diagonal - sigma
        };
        let tau = T::one() + diagonal.abs() / sigma;
        let inverse = T::one() / u0;
        // Row i becomes ũ (ũ₀ = 1).
        for (b, block) in blocks.iter_mut().enumerate() {
            let row = part_mut(block, ti);
            for c in range[b].0..range[b].1 {
                row[c * si + oi] *= inverse;
            }
        }
        let diagonal_entry = ci * si + oi;
        part_mut(&mut blocks[bi], ti)[diagonal_entry] = T::one();
        for k in i + 1..rows {
            let (tk, ok, sk) = slot(k, p, r);
            let mut w = T::zero();
            for (b, block) in blocks.iter().enumerate() {
                let (u, a) = (part(block, ti), part(block, tk));
                for c in range[b].0..range[b].1 {
                    w += a[c * sk + ok] * u[c * si + oi];
                }
            }
            let w = tau * w;
            for (b, block) in blocks.iter_mut().enumerate() {
                let (lo, hi) = range[b];
                if ti == tk {
                    let row = part_mut(block, tk);
                    for c in lo..hi {
                        let u = row[c * si + oi];
                        row[c * sk + ok] -= w * u;
                    }
                } else {
                    // Row i in the top, row k in the bottom.
                    let (u, a) = (&*block.top, &mut *block.bottom);
                    for c in lo..hi {
                        a[c * sk + ok] -= w * u[c * si + oi];
                    }
                }
            }
            if positive {
                let e = &mut part_mut(&mut blocks[bi], tk)[ci * sk + ok];
                *e = -*e;
            }
        }
        // Row i becomes (σ, 0, …, 0).
        for (b, block) in blocks.iter_mut().enumerate() {
            let row = part_mut(block, ti);
            for c in range[b].0..range[b].1 {
                row[c * si + oi] = T::zero();
            }
        }
        part_mut(&mut blocks[bi], ti)[diagonal_entry] = sigma;
    }
}

/// The (global) column `k` as (block, column within it).
#[cfg_attr(not(debug_assertions), inline(always))]
fn locate<T>(blocks: &[Block<'_, T>], mut k: usize) -> (usize, usize) {
    for (b, block) in blocks.iter().enumerate() {
        if k < block.cols {
            return (b, k);
        }
        k -= block.cols;
    }
    unreachable!("column beyond the pre-array")
}

/// A rank-one downdate that says when it fails: L ← L′ with L′ L′ᵀ = L Lᵀ − v vᵀ, for L
/// lower triangular (n × n, column-major, non-negative diagonal); `v` is overwritten.
///
/// Column k (LINPACK `dchdd`; Golub & Van Loan §6.5.4), with hyperbolic rotations:
///
/// ```text
/// r = √((lₖₖ − vₖ)(lₖₖ + vₖ)),  c = r / lₖₖ,  s = vₖ / lₖₖ,  lₖₖ ← r,
/// lᵢₖ ← (lᵢₖ − s vᵢ) / c,  vᵢ ← c vᵢ − s lᵢₖ   (i > k)
/// ```
///
/// A column with vₖ = 0 is unchanged. Fails (`Err(())`, L and v then unspecified: work on a
/// copy) when some (lₖₖ − vₖ)(lₖₖ + vₖ) ≤ 0 with vₖ ≠ 0, i.e. when L Lᵀ − v vᵀ is not positive
/// definite on the directions v touches, or when a result is not finite. nalgebra's
/// `Cholesky::rank_one_update` with σ = −1 computes the same recursion but returns NaN
/// entries instead of failing (and clones v, an allocation at runtime sizes).
pub(crate) fn rank_one_downdate<T: Real>(
    l: &mut [T],
    v: &mut [T],
    n: usize,
) -> core::result::Result<(), ()> {
    for k in 0..n {
        let vk = v[k];
        if vk == T::zero() {
            continue;
        }
        let lkk = l[k * n + k];
        let r2 = (lkk - vk) * (lkk + vk);
        if !(r2 > T::zero() && r2.is_finite()) {
            return Err(());
        }
        let r = r2.sqrt();
        let (c, s) = (r / lkk, vk / lkk);
        l[k * n + k] = r;
        let column = &mut l[k * n + k + 1..(k + 1) * n];
        for (lik, vi) in column.iter_mut().zip(v[k + 1..].iter_mut()) {
            let new = (*lik - s * *vi) / c;
            *lik = new;
            *vi = c * *vi - s * new;
        }
    }
    if l.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use estim_core::nalgebra::{DMatrix, Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector3};

    /// L Lᵀ = A Aᵀ for a 3 × 5 pre-array in two blocks (3 + 2 columns), L lower triangular
    /// with a non-negative diagonal. Tolerance: backward error O(ε ‖A‖²) with ‖A‖² ≈ 30;
    /// 1e-13 leaves a factor ≈ 30 of room.
    #[test]
    fn triangularises_two_blocks() {
        let a = Matrix3::new(1.0, 2.0, 0.5, -1.0, 0.3, 2.0, 0.0, 1.0, -3.0);
        let b = Matrix3x2::new(0.2, -1.0, 1.5, 0.0, 0.7, 0.1);
        let expected = a * a.transpose() + b * b.transpose();
        let (mut l, mut z) = (a, b);
        let mut empty: [f64; 0] = [];
        let mut empty2: [f64; 0] = [];
        let mut blocks = [
            Block::new(l.as_mut_slice(), &mut empty, 3),
            Block::new(z.as_mut_slice(), &mut empty2, 2),
        ];
        lower_triangularize(3, 0, &mut blocks);
        assert!((l * l.transpose() - expected).abs().max() < 1e-13);
        assert_eq!(z, Matrix3x2::zeros());
        assert!(
            (0..3).all(|i| l[(i, i)] >= 0.0)
                && l.upper_triangle() == Matrix3::from_diagonal(&l.diagonal())
        );
    }

    /// Entries whose squares under- or overflow (×10∓²⁰⁰ in f64, ×10∓²⁵ in f32) take the scaled
    /// norm and give the factor of the unscaled array, scaled: L(s A) = s L(A). Tolerance:
    /// both factors carry a backward error O(ε ‖A‖²) with ‖A‖² ≈ 30, plus ε from forming s A;
    /// 1e-13 (f64) and 1e-4 (f32, ε ≈ 1.2e-7) leave a factor ≈ 30 of room.
    #[test]
    fn extreme_scales_neither_underflow_nor_overflow() {
        fn factor<T: Real>(a: &Matrix3<T>, b: &Matrix3x2<T>) -> Matrix3<T> {
            let (mut l, mut z) = (*a, *b);
            let mut blocks = [
                Block::new(l.as_mut_slice(), &mut [], 3),
                Block::new(z.as_mut_slice(), &mut [], 2),
            ];
            householder(3, 0, &mut blocks);
            l
        }
        fn check<T: Real>(scales: [f64; 2], tol: f64) {
            let a = Matrix3::new(1.0, 2.0, 0.5, -1.0, 0.3, 2.0, 0.0, 1.0, -3.0).map(real::<T>);
            let b = Matrix3x2::new(0.2, -1.0, 1.5, 0.0, 0.7, 0.1).map(real::<T>);
            let unscaled = factor(&a, &b);
            for scale in scales.map(real::<T>) {
                let scaled = factor(&(a * scale), &(b * scale)) / scale;
                assert!(scaled.iter().all(|v| v.is_finite()));
                assert!(
                    (scaled - unscaled).abs().max() < real(tol),
                    "scale {scale:?}"
                );
            }
        }
        check::<f64>([1e-200, 1e200], 1e-13);
        check::<f32>([1e-25, 1e25], 1e-4);
    }

    /// The update's shape, rows in a top (p = 2) and a bottom (r = 3) part:
    /// [[S_R, H S], [0, S]] Θ = [[L, 0], [K̄, S⁺]] with the same A Aᵀ, L and S⁺ lower
    /// triangular with non-negative diagonals, the (1, 2) block zero. Tolerance: backward
    /// error O(ε ‖A‖²) with ‖A‖² ≈ 15; 1e-13 leaves a factor ≈ 30 of room.
    #[test]
    fn triangularises_a_two_part_array() {
        two_part_array(false);
        two_part_array(true);
    }

    fn two_part_array(givens_form: bool) {
        let sr = Matrix2::new(0.7, 0.0, -0.2, 0.4);
        let hs = Matrix2x3::new(1.0, -0.5, 2.0, 0.3, 1.2, -0.7);
        let s = Matrix3::new(1.5, 0.0, 0.0, 0.4, 0.9, 0.0, -0.3, 0.2, 1.1);
        let mut a = DMatrix::<f64>::zeros(5, 5);
        a.view_mut((0, 0), (2, 2)).copy_from(&sr);
        a.view_mut((0, 2), (2, 3)).copy_from(&hs);
        a.view_mut((2, 2), (3, 3)).copy_from(&s);
        let (mut l, mut kbar, mut top, mut posterior) = (sr, Matrix3x2::zeros(), hs, s);
        let mut blocks = [
            Block::new(l.as_mut_slice(), kbar.as_mut_slice(), 2),
            Block::new(top.as_mut_slice(), posterior.as_mut_slice(), 3),
        ];
        if givens_form {
            givens::lower_triangularize(2, 3, &mut blocks);
        } else {
            householder(2, 3, &mut blocks);
        }
        let mut full = DMatrix::<f64>::zeros(5, 5);
        full.view_mut((0, 0), (2, 2)).copy_from(&l);
        full.view_mut((2, 0), (3, 2)).copy_from(&kbar);
        full.view_mut((2, 2), (3, 3)).copy_from(&posterior);
        assert_eq!(top, Matrix2x3::zeros());
        assert!((&full * full.transpose() - &a * a.transpose()).abs().max() < 1e-13);
        assert!((0..5).all(|i| full[(i, i)] >= 0.0 && (i + 1..5).all(|j| full[(i, j)] == 0.0)));
    }

    /// The downdate inverts an update: L₀ Lᵀ₀ − v vᵀ with L₀ the factor of A + v vᵀ gives
    /// A's factor. Tolerance: the recursion's error is O(ε κ) with κ(A) ≈ 10 here.
    #[test]
    fn downdate_inverts_an_update_and_fails_past_zero() {
        let a = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
        let v = Vector3::new(0.5, -1.0, 0.25);
        let up = (a + v * v.transpose()).cholesky().unwrap().l();
        let mut l = up;
        let mut w = v;
        rank_one_downdate(l.as_mut_slice(), w.as_mut_slice(), 3).unwrap();
        assert!((l * l.transpose() - a).abs().max() < 1e-13);
        // Removing 2 v vᵀ from A + v vᵀ leaves A − v vᵀ, indefinite for v = 3 e₁ (4 − 9 < 0).
        let big = Vector3::new(3.0, 0.0, 0.0);
        let mut l = a.cholesky().unwrap().l();
        let mut w = big;
        assert!(rank_one_downdate(l.as_mut_slice(), w.as_mut_slice(), 3).is_err());
    }
}
