//! The two factor kernels of the square-root filters: lower-triangularising a pre-array by
//! Householder reflections, and a rank-one Cholesky downdate that reports failure.
//!
//! Both work on column-major slices, so one code path serves static and runtime sizes and
//! a pre-array can be assembled from blocks of different static shapes (an (m + n)-row
//! array has no static type for generic m and n on stable Rust, which is why nalgebra's
//! `QR`, which needs the stacked matrix as one `OMatrix`, is not used; it would also allocate
//! its Householder coefficients and its R at runtime sizes).

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
    #[inline(always)]
    pub(crate) fn new(top: &'a mut [T], bottom: &'a mut [T], cols: usize) -> Self {
        Self { top, bottom, cols }
    }
}

/// Calls `f(top, bottom)` with the whole of every column of the pre-array from (global)
/// column `from` on, left to right.
#[inline(always)]
fn for_columns<T>(
    blocks: &mut [Block<'_, T>],
    from: usize,
    (p, r): (usize, usize),
    mut f: impl FnMut(&mut [T], &mut [T]),
) {
    let mut base = 0;
    for block in blocks.iter_mut() {
        for c in from.saturating_sub(base)..block.cols {
            f(
                &mut block.top[c * p..(c + 1) * p],
                &mut block.bottom[c * r..(c + 1) * r],
            );
        }
        base += block.cols;
    }
}

/// Row `i` of a column given as (top, bottom).
#[inline(always)]
fn at<'b, T>(top: &'b mut [T], bottom: &'b mut [T], i: usize, p: usize) -> &'b mut T {
    if i < p {
        &mut top[i]
    } else {
        &mut bottom[i - p]
    }
}

/// The rows below `i` of a column given as (top, bottom).
#[inline(always)]
fn below<'b, T>(top: &'b mut [T], bottom: &'b mut [T], i: usize, p: usize) -> Column<'b, T> {
    if i < p {
        (&mut top[i + 1..], bottom)
    } else {
        (&mut top[p..], &mut bottom[i - p + 1..])
    }
}

/// y ← y + a x.
#[inline(always)]
fn axpy<T: Real>(y: &mut [T], a: T, x: &[T]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * *xi;
    }
}

/// One column of a pre-array from some row on: its top and bottom parts.
type Column<'b, T> = (&'b mut [T], &'b mut [T]);

/// The squared norm below which (or at ∞) a row's norm is recomputed with scaling: the
/// smallest normal number over ε, so that no square that matters has underflowed.
#[inline(always)]
fn scaling_threshold<T: Real>() -> T {
    if T::default_epsilon() < real(1e-10) {
        real(f64::MIN_POSITIVE / f64::EPSILON)
    } else {
        real(f64::from(f32::MIN_POSITIVE) / f64::from(f32::EPSILON))
    }
}

/// Lower-triangularises the pre-array A (p + r rows, the blocks' columns side by side) in
/// place by Householder reflections from the right: A Θ = [L 0] with Θ orthogonal, so
/// L Lᵀ = A Aᵀ, L lower triangular (trapezoidal if A has fewer columns than rows) with a
/// non-negative diagonal. This is the R factor of the QR factorisation of Aᵀ, transposed.
/// `work` is (p, r) entries of scratch.
///
/// Row i is finished by one reflection of the columns i.. : with v = A[i, i..],
/// σ = ‖v‖, u = v + sign(v₀) σ e₀ and H = I − 2 u uᵀ/(uᵀu), v H = −sign(v₀) σ e₀ᵀ. Stored as
/// ũ = u/u₀ (|ũⱼ| ≤ 1) and τ = 1 + |v₀|/σ, H = I − τ ũ ũᵀ, so the rows below i take
/// w = A[k, i..] ũ and A[k, i..] ← A[k, i..] − τ w ũᵀ: two passes of column `axpy`s over
/// contiguous columns. Column i is negated when −sign(v₀) σ < 0, for a non-negative
/// diagonal. Columns with ũⱼ = 0 cost nothing, so the zero blocks and triangular factors
/// of the filters' pre-arrays (and the triangular fill-in of [F S | S_Q]) are skipped.
/// Backward stable (Golub & Van Loan §5.2): the computed L is the exact factor of
/// A Aᵀ + E with ‖E‖ = O(ε‖A‖²), never of an indefinite matrix. σ is computed as √(Σ vⱼ²)
/// unless that sum under- or overflows, then as m √(Σ (vⱼ/m)²) with m = maxⱼ |vⱼ|.
/// Non-finite entries propagate (the caller checks the result).
///
/// # Panics
///
/// If a block's slices are shorter than its `cols` columns of p (r) rows, or `work` is
/// shorter than (p, r).
#[track_caller]
pub(crate) fn lower_triangularize<T: Real>(
    p: usize,
    r: usize,
    blocks: &mut [Block<'_, T>],
    work: (&mut [T], &mut [T]),
) {
    let (work_top, work_bottom) = (&mut work.0[..p], &mut work.1[..r]);
    let rows = p + r;
    let cols: usize = blocks.iter().map(|b| b.cols).sum();
    let pr = (p, r);
    let threshold = scaling_threshold::<T>();
    for i in 0..rows.min(cols) {
        let (bi, ci) = locate(blocks, i);
        let diagonal = {
            let block = &mut blocks[bi];
            *at(
                &mut block.top[ci * p..(ci + 1) * p],
                &mut block.bottom[ci * r..(ci + 1) * r],
                i,
                p,
            )
        };
        let mut rest = T::zero();
        for_columns(blocks, i + 1, pr, |top, bottom| {
            let v = *at(top, bottom, i, p);
            rest += v * v;
        });
        if rest == T::zero() {
            if diagonal < T::zero() {
                let block = &mut blocks[bi];
                let top = &mut block.top[ci * p..(ci + 1) * p];
                let bottom = &mut block.bottom[ci * r..(ci + 1) * r];
                let (t, b) = if i < p {
                    (&mut top[i..], bottom)
                } else {
                    (&mut top[p..], &mut bottom[i - p..])
                };
                t.iter_mut().chain(b.iter_mut()).for_each(|v| *v = -*v);
            }
            continue;
        }
        let total = diagonal * diagonal + rest;
        let sigma = if total >= threshold && total.is_finite() {
            total.sqrt()
        } else {
            let mut largest = diagonal.abs();
            for_columns(blocks, i + 1, pr, |top, bottom| {
                largest = largest.max(at(top, bottom, i, p).abs());
            });
            let inverse = T::one() / largest;
            let d = diagonal * inverse;
            let mut sum = d * d;
            for_columns(blocks, i + 1, pr, |top, bottom| {
                let v = *at(top, bottom, i, p) * inverse;
                sum += v * v;
            });
            largest * sum.sqrt()
        };
        // u₀ = v₀ + sign(v₀) σ (no cancellation), the reflection maps v to −sign(v₀) σ e₀.
        let positive = diagonal >= T::zero();
        let u0 = if positive {
            diagonal + sigma
        } else {
            diagonal - sigma
        };
        let tau = T::one() + diagonal.abs() / sigma;
        let inverse = T::one() / u0;
        // w = A[k, i..] ũ for the rows k below i, into `work` (column i first: ũ₀ = 1).
        {
            let block = &mut blocks[bi];
            let (t, b) = below(
                &mut block.top[ci * p..(ci + 1) * p],
                &mut block.bottom[ci * r..(ci + 1) * r],
                i,
                p,
            );
            let (wt, wb) = below(work_top, work_bottom, i, p);
            wt.copy_from_slice(t);
            wb.copy_from_slice(b);
        }
        for_columns(blocks, i + 1, pr, |top, bottom| {
            let entry = at(top, bottom, i, p);
            let u = *entry * inverse;
            *entry = u;
            if u != T::zero() {
                let (t, b) = below(top, bottom, i, p);
                let (wt, wb) = below(work_top, work_bottom, i, p);
                axpy(wt, u, t);
                axpy(wb, u, b);
            }
        });
        // A[k, j] −= τ wₖ ũⱼ; row i becomes (±σ, 0, …, 0).
        for_columns(blocks, i + 1, pr, |top, bottom| {
            let entry = at(top, bottom, i, p);
            let u = *entry;
            *entry = T::zero();
            if u != T::zero() {
                let (t, b) = below(top, bottom, i, p);
                let (wt, wb) = below(work_top, work_bottom, i, p);
                axpy(t, -(tau * u), wt);
                axpy(b, -(tau * u), wb);
            }
        });
        let block = &mut blocks[bi];
        let top = &mut block.top[ci * p..(ci + 1) * p];
        let bottom = &mut block.bottom[ci * r..(ci + 1) * r];
        *at(top, bottom, i, p) = sigma;
        let (t, b) = below(top, bottom, i, p);
        let (wt, wb) = below(work_top, work_bottom, i, p);
        // Column i: a − τ w, negated when v₀ ≥ 0 (the reflection gave −σ there).
        if positive {
            for (a, w) in t
                .iter_mut()
                .zip(wt.iter())
                .chain(b.iter_mut().zip(wb.iter()))
            {
                *a = tau * *w - *a;
            }
        } else {
            for (a, w) in t
                .iter_mut()
                .zip(wt.iter())
                .chain(b.iter_mut().zip(wb.iter()))
            {
                *a -= tau * *w;
            }
        }
    }
}

/// The (global) column `k` as (block, column within it).
#[inline(always)]
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
    use estim_core::nalgebra::{Matrix3, Matrix3x2, Vector3};

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
        lower_triangularize(3, 0, &mut blocks, (&mut [0.0; 3], &mut []));
        assert!((l * l.transpose() - expected).abs().max() < 1e-13);
        assert_eq!(z, Matrix3x2::zeros());
        assert!(
            (0..3).all(|i| l[(i, i)] >= 0.0)
                && l.upper_triangle() == Matrix3::from_diagonal(&l.diagonal())
        );
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
