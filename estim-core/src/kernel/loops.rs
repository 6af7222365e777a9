//! Runtime-size products as plain loops over the column-major storage: the route of small
//! runtime sizes, where faer's per-call set-up costs more than the arithmetic, and of every
//! runtime size without the `dense` feature (no faer). Column j of dst (+)= α a op(b) is a sum
//! of a's columns, dⱼ (+)= Σₖ (α bₖⱼ) aₖ: for up to four rows the column is an array held in
//! registers (the loop over its rows unrolled), for more each term is one pass over two
//! contiguous columns that the compiler vectorises.

use crate::dense::{Accum, Operand};
use crate::scalar::Real;

/// dst (+)= α a op(b) on column-major slices: dst `rows × cols`, a `rows × inner`, b
/// `inner × cols` (or `cols × inner` for [`Operand::Transposed`]). For each column j,
/// dⱼ ← (dⱼ +) Σₖ (α bₖⱼ) aₖ summed in order k = 0, 1, …; with [`Accum::Replace`] dst is never
/// read. With `cols = 1` this is also the matrix × vector product.
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
        alpha,
    };
    match rows {
        0 => {}
        1 => few_rows::<T, 1>(dst, accum, a, &b),
        2 => few_rows::<T, 2>(dst, accum, a, &b),
        3 => few_rows::<T, 3>(dst, accum, a, &b),
        4 => few_rows::<T, 4>(dst, accum, a, &b),
        _ => many_rows(dst, rows, accum, a, &b),
    }
}

/// The coefficients α bₖⱼ of a product's columns (b as it is or transposed).
struct Coefficients<'a, T> {
    b: &'a [T],
    inner: usize,
    cols: usize,
    b_as: Operand,
    alpha: T,
}

impl<T: Real> Coefficients<'_, T> {
    /// α op(b)ₖⱼ.
    #[inline(always)]
    fn at(&self, k: usize, j: usize) -> T {
        let bkj = match self.b_as {
            Operand::AsIs => self.b[k + j * self.inner],
            Operand::Transposed => self.b[j + k * self.cols],
        };
        self.alpha * bkj
    }
}

/// [`product`] for R ≤ 4 rows: each column of dst an `[T; R]` accumulated in registers.
#[inline(always)]
fn few_rows<T: Real, const R: usize>(
    dst: &mut [T],
    accum: Accum,
    a: &[T],
    b: &Coefficients<'_, T>,
) {
    let (a_columns, _) = a.as_chunks::<R>();
    let (d_columns, _) = dst.as_chunks_mut::<R>();
    for (j, d) in d_columns.iter_mut().enumerate() {
        let mut sum = match accum {
            Accum::Add => *d,
            Accum::Replace => [T::zero(); R],
        };
        for (k, ak) in a_columns.iter().enumerate() {
            let s = b.at(k, j);
            for (si, &aik) in sum.iter_mut().zip(ak) {
                *si += aik * s;
            }
        }
        *d = sum;
    }
}

/// [`product`] for more rows: one pass over dst's column per term (the first term writes it
/// for [`Accum::Replace`]; zeros if there is none).
#[inline(always)]
fn many_rows<T: Real>(dst: &mut [T], rows: usize, accum: Accum, a: &[T], b: &Coefficients<'_, T>) {
    for (j, d) in dst.chunks_exact_mut(rows).enumerate() {
        let mut terms = a.chunks_exact(rows).enumerate();
        if accum == Accum::Replace {
            match terms.next() {
                Some((k, ak)) => {
                    let s = b.at(k, j);
                    for (di, &aik) in d.iter_mut().zip(ak) {
                        *di = aik * s;
                    }
                }
                None => d.fill(T::zero()),
            }
        }
        for (k, ak) in terms {
            let s = b.at(k, j);
            for (di, &aik) in d.iter_mut().zip(ak) {
                *di += aik * s;
            }
        }
    }
}
