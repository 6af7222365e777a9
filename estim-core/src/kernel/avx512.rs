//! y (+)= α A x for `f64` on AVX-512, with `std::arch`: the [`Matvec`](super::Matvec) panel
//! kernel with 8-lane vectors and panels of 8 vectors (64 rows; 2 × 8 accumulators of the 32
//! registers). pulp reaches AVX-512 only through its `x86-v4` feature, which also gives every
//! pulp dispatch in faer an AVX-512 copy and made the optimised test build ~1.5× slower
//! (BENCHMARKS.md); this one function costs nothing of the kind.
//!
//! The workspace denies `unsafe_code`; this module is the exception, for two kinds of
//! operation only: calling the `#[target_feature]` function after the CPU was checked for the
//! feature, and unaligned loads and stores of exactly one vector through a reference to an
//! array of eight values.
#![allow(unsafe_code)]

use super::Accum;
use core::arch::x86_64::{
    __m512d, _mm512_add_pd, _mm512_fmadd_pd, _mm512_loadu_pd, _mm512_set1_pd, _mm512_setzero_pd,
    _mm512_storeu_pd,
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

/// (y (+)) α A x on rows `start..start + 8V`: V accumulators per column parity, as `Matvec`.
#[inline]
#[target_feature(enable = "avx512f")]
fn sums<const V: usize>(
    y: &[f64],
    accum: Accum,
    alpha: f64,
    block: Block<'_>,
    x: &[f64],
    start: usize,
) -> [__m512d; V] {
    let Block { a, stride, first } = block;
    let mut even = [_mm512_setzero_pd(); V];
    let mut odd = even;
    // Rows `start..start + 8V` of A in column j.
    let piece = |j: usize| {
        let top = j * stride + first + start;
        &a[top..top + LANES * V]
    };
    let mut j = 0;
    while j + 1 < x.len() {
        let (s0, s1) = (
            _mm512_set1_pd(alpha * x[j]),
            _mm512_set1_pd(alpha * x[j + 1]),
        );
        let (c0, c1) = (piece(j), piece(j + 1));
        for v in 0..V {
            even[v] = _mm512_fmadd_pd(load(lanes(c0, LANES * v)), s0, even[v]);
            odd[v] = _mm512_fmadd_pd(load(lanes(c1, LANES * v)), s1, odd[v]);
        }
        j += 2;
    }
    if j < x.len() {
        let (s0, c0) = (_mm512_set1_pd(alpha * x[j]), piece(j));
        for v in 0..V {
            even[v] = _mm512_fmadd_pd(load(lanes(c0, LANES * v)), s0, even[v]);
        }
    }
    for v in 0..V {
        even[v] = _mm512_add_pd(even[v], odd[v]);
        if accum == Accum::Add {
            even[v] = _mm512_add_pd(load(lanes(y, start + LANES * v)), even[v]);
        }
    }
    even
}

/// Rows `start..start + 8V` of y ← (y +) α A x.
#[inline]
#[target_feature(enable = "avx512f")]
fn panel<const V: usize>(
    y: &mut [f64],
    accum: Accum,
    alpha: f64,
    block: Block<'_>,
    x: &[f64],
    start: usize,
) {
    let sums = sums::<V>(y, accum, alpha, block, x, start);
    for (v, s) in sums.into_iter().enumerate() {
        store(lanes_mut(y, start + LANES * v), s);
    }
}

/// The product, y having at least one vector of rows: panels of 8 vectors, one of the
/// remaining whole vectors, and the last `rows mod 8` rows as one vector ending at the last
/// row (computed before the panels overwrite the y it reads).
#[target_feature(enable = "avx512f")]
fn on_avx512(y: &mut [f64], accum: Accum, alpha: f64, block: Block<'_>, x: &[f64]) {
    let rows = y.len();
    let vectors = rows / LANES;
    let last =
        (!rows.is_multiple_of(LANES)).then(|| sums::<1>(y, accum, alpha, block, x, rows - LANES));
    let mut start = 0;
    for _ in 0..vectors / 8 {
        panel::<8>(y, accum, alpha, block, x, start);
        start += 8 * LANES;
    }
    match vectors % 8 {
        7 => panel::<7>(y, accum, alpha, block, x, start),
        6 => panel::<6>(y, accum, alpha, block, x, start),
        5 => panel::<5>(y, accum, alpha, block, x, start),
        4 => panel::<4>(y, accum, alpha, block, x, start),
        3 => panel::<3>(y, accum, alpha, block, x, start),
        2 => panel::<2>(y, accum, alpha, block, x, start),
        1 => panel::<1>(y, accum, alpha, block, x, start),
        _ => {}
    }
    if let Some([v]) = last {
        store(lanes_mut(y, rows - LANES), v);
    }
}
