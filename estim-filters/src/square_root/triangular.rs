//! The two factor kernels of the square-root filters: lower-triangularising a pre-array by
//! orthogonal rotations, and a rank-one Cholesky downdate that reports failure.
//!
//! Both work on column-major slices, so one code path serves static and runtime sizes and
//! a pre-array can be assembled from blocks of different static shapes (an (m + n)-row
//! array has no static type for generic m and n on stable Rust, which is why nalgebra's
//! `QR`, which needs the stacked matrix as one `OMatrix`, is not used; it would also allocate
//! its Householder coefficients and its R at runtime sizes).

use estim_core::Real;

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

/// Column `j` of `block` from global row `row` on: its top part (rows row..p) and bottom part.
#[inline(always)]
fn column_from<'b, T>(
    block: &'b mut Block<'_, T>,
    j: usize,
    row: usize,
    (p, r): (usize, usize),
) -> Column<'b, T> {
    let top = &mut block.top[j * p..(j + 1) * p];
    let bottom = &mut block.bottom[j * r..(j + 1) * r];
    let (top_from, bottom_from) = if row < p { (row, 0) } else { (p, row - p) };
    (&mut top[top_from..], &mut bottom[bottom_from..])
}

/// (x, y) ← (c x + s y, −s x + c y), elementwise.
#[inline(always)]
fn rotate<T: Real>(x: &mut [T], y: &mut [T], c: T, s: T) {
    for (xi, yi) in x.iter_mut().zip(y.iter_mut()) {
        let (a, b) = (*xi, *yi);
        *xi = c * a + s * b;
        *yi = c * b - s * a;
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

/// One column of a pre-array from some row on: its top and bottom parts.
type Column<'b, T> = (&'b mut [T], &'b mut [T]);

/// Columns `a` < `b` of the pre-array, from row `row` on, as two disjoint mutable pairs.
#[inline(always)]
fn column_pair<'b, T>(
    blocks: &'b mut [Block<'_, T>],
    a: usize,
    b: usize,
    row: usize,
    pr: (usize, usize),
) -> (Column<'b, T>, Column<'b, T>) {
    let ((ba, ja), (bb, jb)) = (locate(blocks, a), locate(blocks, b));
    let (p, r) = pr;
    if ba == bb {
        let block = &mut blocks[ba];
        // ja < jb: split each part between the two columns.
        let (top_a, top_b) = block.top.split_at_mut(jb * p);
        let (bottom_a, bottom_b) = block.bottom.split_at_mut(jb * r);
        let (top_from, bottom_from) = if row < p { (row, 0) } else { (p, row - p) };
        let col_a = (
            &mut top_a[ja * p + top_from..(ja + 1) * p],
            &mut bottom_a[ja * r + bottom_from..(ja + 1) * r],
        );
        let col_b = (&mut top_b[top_from..p], &mut bottom_b[bottom_from..r]);
        (col_a, col_b)
    } else {
        let (first, second) = blocks.split_at_mut(bb);
        (
            column_from(&mut first[ba], ja, row, pr),
            column_from(&mut second[0], jb, row, pr),
        )
    }
}

/// Lower-triangularises the pre-array A (p + r rows, the blocks' columns side by side) in
/// place by Givens rotations from the right: A Θ = [L 0] with Θ orthogonal, so
/// L Lᵀ = A Aᵀ, L lower triangular (trapezoidal if A has fewer columns than rows) with a
/// non-negative diagonal. This is the R factor of the QR factorisation of Aᵀ, transposed.
///
/// Row i is finished by rotating column i against each later column j with aᵢⱼ ≠ 0:
/// with h = hypot(aᵢᵢ, aᵢⱼ), c = aᵢᵢ/h, s = aᵢⱼ/h, (colᵢ, colⱼ) ← (c colᵢ + s colⱼ,
/// c colⱼ − s colᵢ), which makes aᵢⱼ = 0 and aᵢᵢ = h ≥ 0. Rows above i are already zero in
/// both columns, so only rows ≥ i are touched, and zero entries cost nothing (the zero block
/// and triangular factors of the filters' pre-arrays). Backward stable: the computed L is the
/// exact factor of A Aᵀ + E with ‖E‖ = O(ε‖A‖²), never of an indefinite matrix; the
/// hypotenuse avoids overflow and underflow in the squares. Non-finite entries propagate
/// (the caller checks the result).
pub(crate) fn lower_triangularize<T: Real>(p: usize, r: usize, blocks: &mut [Block<'_, T>]) {
    let rows = p + r;
    let cols: usize = blocks.iter().map(|b| b.cols).sum();
    let pr = (p, r);
    let entry = |blocks: &[Block<'_, T>], i: usize, k: usize| -> T {
        let (b, j) = locate(blocks, k);
        if i < p {
            blocks[b].top[j * p + i]
        } else {
            blocks[b].bottom[j * r + i - p]
        }
    };
    for i in 0..rows.min(cols) {
        for j in i + 1..cols {
            let b = entry(blocks, i, j);
            if b == T::zero() {
                continue;
            }
            let a = entry(blocks, i, i);
            let h = a.hypot(b);
            let (c, s) = (a / h, b / h);
            let ((xt, xb), (yt, yb)) = column_pair(blocks, i, j, i, pr);
            rotate(xt, yt, c, s);
            rotate(xb, yb, c, s);
            // Exactly zero, not the rounding residue of c b − s a.
            let (bj, jj) = locate(blocks, j);
            if i < p {
                blocks[bj].top[jj * p + i] = T::zero();
            } else {
                blocks[bj].bottom[jj * r + i - p] = T::zero();
            }
        }
        if entry(blocks, i, i) < T::zero() {
            let (b, j) = locate(blocks, i);
            let (top, bottom) = column_from(&mut blocks[b], j, i, pr);
            top.iter_mut()
                .chain(bottom.iter_mut())
                .for_each(|v| *v = -*v);
        }
    }
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
        lower_triangularize(3, 0, &mut blocks);
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
