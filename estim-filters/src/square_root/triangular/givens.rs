//! The Givens form of the triangularisation, for the larger pre-arrays: it rotates pairs of
//! whole columns, contiguous in the blocks' column-major storage, where the Householder form
//! of [`triangular`](super) walks rows across the columns (strided), which is cheaper only
//! while the rows are short (BENCHMARKS.md, "Square-root filters").

use estim_core::Real;

use super::{Block, locate};

/// Column `j` of `block` from global row `row` on: its top part (rows row..p) and bottom part.
#[cfg_attr(not(debug_assertions), inline(always))]
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
#[cfg_attr(not(debug_assertions), inline(always))]
fn rotate<T: Real>(x: &mut [T], y: &mut [T], c: T, s: T) {
    for (xi, yi) in x.iter_mut().zip(y.iter_mut()) {
        let (a, b) = (*xi, *yi);
        *xi = c * a + s * b;
        *yi = c * b - s * a;
    }
}

/// One column of a pre-array from some row on: its top and bottom parts.
type Column<'b, T> = (&'b mut [T], &'b mut [T]);

/// Columns `a` < `b` of the pre-array, from row `row` on, as two disjoint mutable pairs.
#[cfg_attr(not(debug_assertions), inline(always))]
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

/// [`lower_triangularize`](super::lower_triangularize) for the larger pre-arrays: A (p + r
/// rows, the blocks' columns side by side) lower-triangularised in
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
pub(super) fn lower_triangularize<T: Real>(p: usize, r: usize, blocks: &mut [Block<'_, T>]) {
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
