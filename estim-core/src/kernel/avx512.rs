//! y (+)= α A x for `f64` on AVX-512, with `std::arch`: the [`Matvec`](super::Matvec) panel
//! kernel with 8-lane vectors and panels of 8 vectors (64 rows; 2 × 8 accumulators of the 32
//! registers), the last `rows mod 8` rows in the last panel's pass. Used from 16 rows (and
//! below [`SWEEP_MIN_ROWS`](super::SWEEP_MIN_ROWS) for whole matrices), for the products and
//! the Cholesky factor's column updates. Also the lower triangle of C (+)= α A Bᵀ (the
//! covariance sums w D Dᵀ and J C Jᵀ) for 16 ≤ n ≤ [`LOWER_MAX`], in blocks of 4 columns.
//! pulp reaches AVX-512 only through its `x86-v4` feature, which also gives every pulp
//! dispatch in faer an AVX-512 copy and made the optimised test build ~1.5× slower
//! (BENCHMARKS.md); this module is compiled once, in estim-core (`.ci/run` on a fresh clone
//! with it: 16 min 6 s).
//!
//! The workspace denies `unsafe_code`; this module is the exception, for two kinds of
//! operation only: calling the `#[target_feature]` function after the CPU was checked for the
//! feature, and unaligned loads and stores of exactly one vector through a reference to an
//! array of eight values.
#![allow(unsafe_code)]

use super::Accum;
use core::arch::x86_64::{
    __m512d, _mm512_add_pd, _mm512_fmadd_pd, _mm512_loadu_pd, _mm512_mask_blend_pd, _mm512_mul_pd,
    _mm512_set1_pd, _mm512_setzero_pd, _mm512_storeu_pd,
};

/// Rows per vector.
const LANES: usize = 8;

/// Fewer rows are left to the AVX2 kernel: with 8–15 rows the last `rows mod 8` take a second,
/// overlapping vector and pass over the columns, and 12 × 12 measured 9.8 ns on AVX2 against
/// 14.3 on AVX-512 (24 × 24: 27.9 against 18.4).
const MIN_ROWS: usize = 16;

/// The matrix A of a product: rows `first..first + rows` of the column-major `a` with
/// `stride` rows.
#[derive(Clone, Copy)]
pub(super) struct Block<'a> {
    pub(super) a: &'a [f64],
    pub(super) stride: usize,
    pub(super) first: usize,
}

/// `true` if this CPU has AVX-512F (the answer is cached by `std`).
#[inline]
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
}

/// y (+)= α A x on AVX-512 and `true`, or `false` (nothing done) if the CPU lacks it or y has
/// fewer than [`MIN_ROWS`] rows.
///
/// # Panics
/// If A's columns do not fit in `a` (a programmer error).
#[inline]
pub(super) fn matvec(y: &mut [f64], accum: Accum, alpha: f64, block: Block<'_>, x: &[f64]) -> bool {
    if y.len() < MIN_ROWS || !available() {
        return false;
    }
    let Block { a, stride, first } = block;
    let fits = x.is_empty()
        || (first + y.len() <= stride && (x.len() - 1) * stride + first + y.len() <= a.len());
    assert!(fits, "matvec: A does not fit in its storage");
    // SAFETY: the CPU has AVX-512F (checked above), the one precondition of `on_avx512`.
    unsafe { on_avx512(y, accum, alpha, block, x) };
    true
}

/// One vector from `v`.
#[inline]
#[target_feature(enable = "avx512f")]
fn load(v: &[f64; LANES]) -> __m512d {
    // SAFETY: `v` is eight readable f64; the load is unaligned.
    unsafe { _mm512_loadu_pd(v.as_ptr()) }
}

/// One vector into `out`.
#[inline]
#[target_feature(enable = "avx512f")]
fn store(out: &mut [f64; LANES], v: __m512d) {
    // SAFETY: `out` is eight writable f64; the store is unaligned.
    unsafe { _mm512_storeu_pd(out.as_mut_ptr(), v) }
}

/// Eight values of `s` from `start`.
#[inline]
fn lanes(s: &[f64], start: usize) -> &[f64; LANES] {
    s[start..start + LANES].try_into().expect("eight values")
}

/// The same, mutable.
#[inline]
fn lanes_mut(s: &mut [f64], start: usize) -> &mut [f64; LANES] {
    (&mut s[start..start + LANES])
        .try_into()
        .expect("eight values")
}

/// (y (+)) α A x on the rows of V vectors, as `Matvec`'s panels: V accumulators per column
/// parity. Without `TAIL` the vectors are rows `start..start + 8V`; with it the first V − 1
/// are rows `start..start + 8(V − 1)` and the last is rows `last..last + 8` (the overlapping
/// vector that ends at the last row), all in one pass over the columns.
#[inline]
#[target_feature(enable = "avx512f")]
fn sums<const V: usize, const TAIL: bool>(
    y: &[f64],
    accum: Accum,
    alpha: f64,
    block: Block<'_>,
    x: &[f64],
    (start, last): (usize, usize),
) -> [__m512d; V] {
    let Block { a, stride, first } = block;
    let whole = if TAIL { V - 1 } else { V };
    let mut even = [_mm512_setzero_pd(); V];
    let mut odd = even;
    // The whole vectors' rows of column j, and the tail's.
    let piece = |j: usize| {
        let top = j * stride + first + start;
        &a[top..top + LANES * whole]
    };
    let tail = |j: usize| lanes(a, j * stride + first + last);
    let mut j = 0;
    while j + 1 < x.len() {
        let (s0, s1) = (
            _mm512_set1_pd(alpha * x[j]),
            _mm512_set1_pd(alpha * x[j + 1]),
        );
        let (c0, c1) = (piece(j), piece(j + 1));
        for v in 0..whole {
            even[v] = _mm512_fmadd_pd(load(lanes(c0, LANES * v)), s0, even[v]);
            odd[v] = _mm512_fmadd_pd(load(lanes(c1, LANES * v)), s1, odd[v]);
        }
        if TAIL {
            even[V - 1] = _mm512_fmadd_pd(load(tail(j)), s0, even[V - 1]);
            odd[V - 1] = _mm512_fmadd_pd(load(tail(j + 1)), s1, odd[V - 1]);
        }
        j += 2;
    }
    if j < x.len() {
        let (s0, c0) = (_mm512_set1_pd(alpha * x[j]), piece(j));
        for v in 0..whole {
            even[v] = _mm512_fmadd_pd(load(lanes(c0, LANES * v)), s0, even[v]);
        }
        if TAIL {
            even[V - 1] = _mm512_fmadd_pd(load(tail(j)), s0, even[V - 1]);
        }
    }
    for v in 0..V {
        even[v] = _mm512_add_pd(even[v], odd[v]);
        if accum == Accum::Add {
            let row = vector_row::<V, TAIL>(v, (start, last));
            even[v] = _mm512_add_pd(load(lanes(y, row)), even[v]);
        }
    }
    even
}

/// The first row of vector `v` of a [`sums`] panel: `start + 8v`, or `last` for the tail.
#[inline(always)]
fn vector_row<const V: usize, const TAIL: bool>(v: usize, (start, last): (usize, usize)) -> usize {
    if TAIL && v + 1 == V {
        last
    } else {
        start + LANES * v
    }
}

/// y ← (y +) α A x on the rows of [`sums`] (with `TAIL`, the whole vectors first, then the
/// tail: in the rows they share both hold the same sums, same operations in the same order).
#[inline]
#[target_feature(enable = "avx512f")]
fn panel<const V: usize, const TAIL: bool>(
    y: &mut [f64],
    accum: Accum,
    alpha: f64,
    block: Block<'_>,
    x: &[f64],
    (start, last): (usize, usize),
) {
    let sums = sums::<V, TAIL>(y, accum, alpha, block, x, (start, last));
    for (v, s) in sums.into_iter().enumerate() {
        store(lanes_mut(y, vector_row::<V, TAIL>(v, (start, last))), s);
    }
}

/// The product, y having at least one vector of rows: panels of 8 vectors, then one panel of
/// the remaining whole vectors and, if the rows are not a multiple of 8, the vector ending at
/// the last row (at most 8 vectors: 16 accumulators of the 32 registers). If no whole vectors
/// remain, that last vector overlaps the last 8-vector panel: it is computed before the panels
/// overwrite the y it reads, and stored after them.
#[target_feature(enable = "avx512f")]
fn on_avx512(y: &mut [f64], accum: Accum, alpha: f64, block: Block<'_>, x: &[f64]) {
    let rows = y.len();
    let vectors = rows / LANES;
    let tail_alone = vectors.is_multiple_of(8) && !rows.is_multiple_of(LANES);
    let tail = (rows - LANES, 0);
    // A closure here inherits this function's target features (unlike the one that was in
    // `Matvec::run`): 65 × 65 measured the same either way.
    let early = tail_alone.then(|| sums::<1, false>(y, accum, alpha, block, x, tail));
    let mut start = 0;
    for _ in 0..vectors / 8 {
        panel::<8, false>(y, accum, alpha, block, x, (start, 0));
        start += 8 * LANES;
    }
    let rest = (start, rows - LANES);
    match (vectors % 8, !rows.is_multiple_of(LANES)) {
        (7, true) => panel::<8, true>(y, accum, alpha, block, x, rest),
        (7, false) => panel::<7, false>(y, accum, alpha, block, x, rest),
        (6, true) => panel::<7, true>(y, accum, alpha, block, x, rest),
        (6, false) => panel::<6, false>(y, accum, alpha, block, x, rest),
        (5, true) => panel::<6, true>(y, accum, alpha, block, x, rest),
        (5, false) => panel::<5, false>(y, accum, alpha, block, x, rest),
        (4, true) => panel::<5, true>(y, accum, alpha, block, x, rest),
        (4, false) => panel::<4, false>(y, accum, alpha, block, x, rest),
        (3, true) => panel::<4, true>(y, accum, alpha, block, x, rest),
        (3, false) => panel::<3, false>(y, accum, alpha, block, x, rest),
        (2, true) => panel::<3, true>(y, accum, alpha, block, x, rest),
        (2, false) => panel::<2, false>(y, accum, alpha, block, x, rest),
        (1, true) => panel::<2, true>(y, accum, alpha, block, x, rest),
        (1, false) => panel::<1, false>(y, accum, alpha, block, x, rest),
        _ => {}
    }
    if let Some([v]) = early {
        store(lanes_mut(y, rows - LANES), v);
    }
}

/// Vectors per panel of [`lower_product_tr`]: 6 × 4 accumulators, 4 broadcasts and a load in
/// the 32 registers.
const LOWER_PANEL: usize = 6;

/// Up to this order [`lower_product_tr`] runs here; above it faer's blocked product. Measured
/// against faer's lower-triangle product (`kernel::mul_tr_lower` in a loop, best of 5, three
/// alternating runs of the two builds in a scratch crate; n × k, ours / faer's): 25 × 50 0.69,
/// 50 × 50 0.58 (2.80 → 1.62 µs), 50 × 25 0.56, 64 × 64 0.69, 100 × 50 0.67, 100 × 100 0.69,
/// 128 × 128 0.99. faer's triangular product costs as much as its full one at these orders.
pub(super) const LOWER_MAX: usize = 128;

/// The lower triangle of C (+)= α A Bᵀ on AVX-512 and `true`, for the column-major n × n `c`
/// and n × k `a` and `b`; `false` (nothing done) if the CPU lacks AVX-512 or n is outside
/// [`MIN_ROWS`]..=[`LOWER_MAX`]. Entries above the diagonal may be overwritten (as by the
/// whole-matrix product used below `LOWER_TRIANGLE_MIN`).
///
/// # Panics
/// If the lengths do not fit these shapes (a programmer error).
#[inline]
pub(super) fn lower_product_tr(
    c: &mut [f64],
    n: usize,
    accum: Accum,
    alpha: f64,
    a: &[f64],
    b: &[f64],
) -> bool {
    if !(MIN_ROWS..=LOWER_MAX).contains(&n) || !available() {
        return false;
    }
    let fits = c.len() == n * n && a.len() == b.len() && a.len().is_multiple_of(n);
    assert!(fits, "lower_product_tr: shapes differ");
    // SAFETY: the CPU has AVX-512F (checked above), the one precondition of `lower_on_avx512`.
    unsafe { lower_on_avx512(c, n, accum, alpha, a, b) };
    true
}

/// [`lower_product_tr`] in blocks of 4 columns j..j + 4, each over rows j..n.
#[target_feature(enable = "avx512f")]
fn lower_on_avx512(c: &mut [f64], n: usize, accum: Accum, alpha: f64, a: &[f64], b: &[f64]) {
    let product = Lower {
        n,
        accum,
        alpha,
        a,
        b,
    };
    let mut j = 0;
    while j < n {
        match n - j {
            1 => product.columns::<1>(c, j),
            2 => product.columns::<2>(c, j),
            3 => product.columns::<3>(c, j),
            _ => product.columns::<4>(c, j),
        }
        j += 4;
    }
}

/// The operands of [`lower_product_tr`].
#[derive(Clone, Copy)]
struct Lower<'a> {
    n: usize,
    accum: Accum,
    alpha: f64,
    a: &'a [f64],
    b: &'a [f64],
}

impl Lower<'_> {
    /// Columns j..j + C over rows j..n: the whole vectors from row j in panels of up to
    /// [`LOWER_PANEL`], then the vector ending at row n if the rows are not a multiple of 8,
    /// which writes only the rows the panels did not.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn columns<const C: usize>(self, c: &mut [f64], j: usize) {
        let n = self.n;
        let whole = (n - j) / LANES;
        let mut start = j;
        let mut left = whole;
        while left > 0 {
            let v = left.min(LOWER_PANEL);
            match v {
                6 => self.panel::<6, C>(c, j, start, None),
                5 => self.panel::<5, C>(c, j, start, None),
                4 => self.panel::<4, C>(c, j, start, None),
                3 => self.panel::<3, C>(c, j, start, None),
                2 => self.panel::<2, C>(c, j, start, None),
                _ => self.panel::<1, C>(c, j, start, None),
            }
            start += LANES * v;
            left -= v;
        }
        if start < n {
            self.panel::<1, C>(c, j, n - LANES, Some(start));
        }
    }

    /// Rows `start..start + 8V` of columns j..j + C of C (+)= α A Bᵀ; with `from`, only the
    /// rows from `from` on are written.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn panel<const V: usize, const C: usize>(
        self,
        c: &mut [f64],
        j: usize,
        start: usize,
        from: Option<usize>,
    ) {
        let n = self.n;
        let mut sums = [[_mm512_setzero_pd(); C]; V];
        for (a_k, b_k) in self.a.chunks_exact(n).zip(self.b.chunks_exact(n)) {
            let piece = &a_k[start..start + LANES * V];
            let b_row: &[f64; C] = b_k[j..j + C].try_into().expect("C values");
            let scales: [__m512d; C] = core::array::from_fn(|q| _mm512_set1_pd(b_row[q]));
            for (v, sum) in sums.iter_mut().enumerate() {
                let column = load(lanes(piece, LANES * v));
                for (s, &scale) in sum.iter_mut().zip(&scales) {
                    *s = _mm512_fmadd_pd(column, scale, *s);
                }
            }
        }
        let alpha = _mm512_set1_pd(self.alpha);
        // Rows `from..` of a vector starting at row `start`: the lanes from `from − start` on.
        let keep = from.map(|from| 0xffu8.checked_shl((from - start) as u32).unwrap_or(0));
        for q in 0..C {
            let out = &mut c[(j + q) * n..(j + q + 1) * n];
            for (v, sum) in sums.iter().enumerate() {
                let row = start + LANES * v;
                let old = load(lanes(out, row));
                let mut value = _mm512_mul_pd(sum[q], alpha);
                if self.accum == Accum::Add {
                    value = _mm512_add_pd(old, value);
                }
                if let Some(mask) = keep {
                    value = _mm512_mask_blend_pd(mask, old, value);
                }
                store(lanes_mut(out, row), value);
            }
        }
    }
}
