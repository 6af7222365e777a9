//! Runtime-size products as plain loops over the column-major storage: the route of small
//! runtime sizes, where faer's per-call set-up costs more than the arithmetic, and of every
//! runtime size without the `dense` feature (no faer). Column j of dst (+)= α a op(b) is a sum
//! of a's columns, Σₖ aₖ bₖⱼ, taken four rows at a time in registers (the loop over those rows
//! unrolled), then scaled and stored or added: dst ← (dst +) α (a op(b)), the product first,
//! as the static-size and faer routes do (so `Replace` into a temporary then an addition gives
//! the bits of `Add`).

use crate::dense::{Accum, Operand};
use crate::scalar::Real;

/// dst (+)= α a op(b) on column-major slices: dst `rows × cols`, a `rows × inner`, b
/// `inner × cols` (or `cols × inner` for [`Operand::Transposed`]). Each entry is
/// s = Σₖ aᵢₖ op(b)ₖⱼ summed in order k = 0, 1, …, then dᵢⱼ ← α s, or dᵢⱼ + α s for
/// [`Accum::Add`] (α s is s when α = 1); with [`Accum::Replace`] dst is never read. With
/// `cols = 1` this is also the matrix × vector product.
///
/// # Panics
/// If the slices' lengths disagree with the shapes (a programmer error; the callers check the
/// matrices' shapes first).
#[track_caller]
pub(super) fn product<T: Real>(
    dst: &mut [T],
    (rows, cols): (usize, usize),
    accum: Accum,
    alpha: T,
    a: &[T],
    inner: usize,
    b: &[T],
    b_as: Operand,
) {
    assert!(
        dst.len() == rows * cols && a.len() == rows * inner && b.len() == inner * cols,
        "kernel product: shapes differ ({rows}×{cols} ← {rows}×{inner} × {inner}×{cols})"
    );
    let b = Coefficients {
        b,
        inner,
        cols,
        b_as,
    };
    let store = Store { accum, alpha };
    // Whole blocks of four rows, then the remaining one to three.
    let blocks = rows / 4;
    for block in 0..blocks {
        rows_block::<T, 4>(dst, rows, 4 * block, a, &b, store);
    }
    match rows % 4 {
        1 => rows_block::<T, 1>(dst, rows, 4 * blocks, a, &b, store),
        2 => rows_block::<T, 2>(dst, rows, 4 * blocks, a, &b, store),
        3 => rows_block::<T, 3>(dst, rows, 4 * blocks, a, &b, store),
        _ => {}
    }
}

/// The entries op(b)ₖⱼ of a product's second operand (b as it is or transposed).
struct Coefficients<'a, T> {
    b: &'a [T],
    inner: usize,
    cols: usize,
    b_as: Operand,
}

impl<T: Real> Coefficients<'_, T> {
    /// op(b)ₖⱼ.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn at(&self, k: usize, j: usize) -> T {
        match self.b_as {
            Operand::AsIs => self.b[k + j * self.inner],
            Operand::Transposed => self.b[j + k * self.cols],
        }
    }
}

/// How a sum reaches dst: scaled by α, stored or added.
#[derive(Clone, Copy)]
struct Store<T> {
    accum: Accum,
    alpha: T,
}

impl<T: Real> Store<T> {
    /// d ← α s, or d + α s (α s = s when α = 1, as the static route's `store`).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn apply(self, d: &mut T, s: T) {
        let v = if self.alpha == T::one() {
            s
        } else {
            s * self.alpha
        };
        *d = match self.accum {
            Accum::Add => *d + v,
            Accum::Replace => v,
        };
    }
}

/// Rows `first..first + R` of every column of [`product`]'s dst: the R sums of a column held
/// in an `[T; R]` (registers) over k, then stored.
#[cfg_attr(not(debug_assertions), inline(always))]
fn rows_block<T: Real, const R: usize>(
    dst: &mut [T],
    rows: usize,
    first: usize,
    a: &[T],
    b: &Coefficients<'_, T>,
    store: Store<T>,
) {
    for (j, d) in dst.chunks_exact_mut(rows).enumerate() {
        let mut sum = [T::zero(); R];
        for (k, ak) in a.chunks_exact(rows).enumerate() {
            let bkj = b.at(k, j);
            let ak: &[T; R] = ak[first..first + R].try_into().expect("R rows");
            for (si, &aik) in sum.iter_mut().zip(ak) {
                *si += aik * bkj;
            }
        }
        for (di, si) in d[first..first + R].iter_mut().zip(sum) {
            store.apply(di, si);
        }
    }
}
