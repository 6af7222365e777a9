//! Small numerical kernels shared by the estim crates: finiteness and shape checks, a
//! semi-definite Cholesky factor, symmetrisation.
//!
//! All of them work in place or on the stack for static sizes: none allocates unless the
//! matrix type itself lives on the heap (`Dyn`).

use nalgebra::{
    DefaultAllocator, Dim, IsContiguous, Matrix, OMatrix, OVector, RawStorage, U1,
    allocator::Allocator,
};

use crate::error::{Error, Quantity, Result, Stage};
use crate::kernel::{CholeskyScratch, cholesky_in_place, copy, is_static};
use crate::scalar::{Real, real};

/// Whether every entry of `m` is finite. A branch-free scan of the contiguous storage
/// ([`slice_finite`]; an early-exit `iter().all()` over nalgebra's generic iterator costs ≈ 4×
/// more, which is a fifth of a small filter step). Needs contiguous storage (owned matrices and
/// vectors); for a strided view use `view.iter().all(|v| v.is_finite())`.
#[inline(always)]
pub fn all_finite<T: Real, R: Dim, C: Dim, S: RawStorage<T, R, C> + IsContiguous>(
    m: &Matrix<T, R, C, S>,
) -> bool {
    slice_finite(m.as_slice())
}

/// Whether every value is finite, without branching: Σ (v − v) over the values is 0 when all
/// are finite and NaN otherwise (v − v is 0 for a finite v, NaN for ±∞ and NaN), summed in 8
/// independent lanes so that it vectorises. Two flops per value, where `is_finite` costs an
/// absolute value, two comparisons and two masks.
#[inline(always)]
#[allow(clippy::eq_op)] // v − v is the test: it is not 0 for ±∞ and NaN.
pub fn slice_finite<T: Real>(values: &[T]) -> bool {
    const LANES: usize = 8;
    if values.len() < 2 * LANES {
        // Short (mostly static-size) scans: the plain fold unrolls into less code (the lanes
        // cost the 3/2 static KF step 12 %).
        return values.iter().fold(true, |ok, v| ok & v.is_finite());
    }
    let mut lanes = [T::zero(); LANES];
    let mut chunks = values.chunks_exact(LANES);
    for chunk in &mut chunks {
        for (lane, &v) in lanes.iter_mut().zip(chunk) {
            *lane += v - v;
        }
    }
    for (lane, &v) in lanes.iter_mut().zip(chunks.remainder()) {
        *lane += v - v;
    }
    lanes.iter().fold(T::zero(), |sum, &lane| sum + lane) == T::zero()
}

/// `Ok(())` if every entry of `m` is finite, else [`Error::NonFinite`].
#[inline(always)]
pub fn ensure_finite<T: Real, R: Dim, C: Dim, S: RawStorage<T, R, C> + IsContiguous>(
    m: &Matrix<T, R, C, S>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()> {
    finite_or_error(all_finite(m), stage, quantity)
}

/// `Ok(())` if `finite`, else [`Error::NonFinite`]: for passes that check finiteness as they
/// write (e.g. [`symmetric_map`]).
#[inline(always)]
pub fn finite_or_error(finite: bool, stage: Stage, quantity: Quantity) -> Result<()> {
    if finite {
        Ok(())
    } else {
        Err(Error::NonFinite { stage, quantity })
    }
}

/// `Ok(())` if `m` is `rows × cols`, else [`Error::DimensionMismatch`].
///
/// Static sizes always pass; the check matters for runtime (`Dyn`) sizes.
#[inline]
pub fn ensure_shape<T, R: Dim, C: Dim, S: RawStorage<T, R, C>>(
    m: &Matrix<T, R, C, S>,
    rows: usize,
    cols: usize,
    stage: Stage,
    quantity: Quantity,
) -> Result<()> {
    let (found_rows, found_cols) = m.shape();
    if (found_rows, found_cols) == (rows, cols) {
        Ok(())
    } else {
        Err(Error::DimensionMismatch {
            stage,
            quantity,
            expected_rows: rows,
            expected_cols: cols,
            found_rows,
            found_cols,
        })
    }
}

/// The tolerance below which a pivot of a covariance factorisation counts as zero:
/// `16 n ε max|Cᵢᵢ|`. Round-off in forming a rank-deficient covariance stays below it.
#[inline]
pub fn psd_tolerance<T: Real, D: Dim>(c: &OMatrix<T, D, D>) -> T
where
    DefaultAllocator: Allocator<D, D>,
{
    tolerance_for(c.nrows(), max_abs_diagonal(c))
}

/// max |Cᵢᵢ|.
fn max_abs_diagonal<T: Real, D: Dim>(c: &OMatrix<T, D, D>) -> T
where
    DefaultAllocator: Allocator<D, D>,
{
    (0..c.nrows()).fold(T::zero(), |m, i| m.max(c[(i, i)].abs()))
}

/// 16 n ε max|Cᵢᵢ| (see [`psd_tolerance`]).
fn tolerance_for<T: Real>(n: usize, max_diag: T) -> T {
    real::<T>(16.0 * n as f64) * T::default_epsilon() * max_diag
}

/// A square root S with S Sᵀ = C of a symmetric positive **semi**-definite C.
///
/// First a Cholesky factorisation that accepts zero pivots: a pivot within [`psd_tolerance`] of
/// zero gives a zero column (that direction has no variance). This is the ordinary lower
/// Cholesky factor whenever C is positive definite, so sigma points are the textbook ones.
/// Without pivoting, round-off in an ill-conditioned leading block can push a later pivot of an
/// exactly singular C below −tolerance; then the factorisation is repeated with diagonal
/// pivoting (as LAPACK's `dpstrf`), which takes the largest remaining pivot first and so stops
/// cleanly at the rank: S = Pᵀ L, no longer triangular. Only if that also finds a clearly
/// negative direction is C rejected. Either way the unscented and sampled propagators get a
/// valid square root, and states that are known exactly (zero variance) are allowed.
pub fn psd_factor<T: Real, D: Dim>(c: &OMatrix<T, D, D>, stage: Stage) -> Result<OMatrix<T, D, D>>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    unpivoted_psd_factor(c)
        .or_else(|()| pivoted_psd_factor(c))
        .map_err(|()| Error::NotPositiveSemiDefinite {
            stage,
            quantity: Quantity::Covariance,
        })
}

/// [`psd_factor`] into `out`. For runtime sizes it first tries the Cholesky factorisation in
/// place ([`cholesky_in_place`]: faer's, or our own column kernel below n = 96;
/// allocation-free with a sized `scratch`), which succeeds for every positive definite C
/// and gives the same lower factor up to round-off; only a semi-definite C falls back to
/// [`psd_factor`] (which allocates). Static sizes use [`psd_factor`] directly.
pub fn psd_factor_into<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
    out: &mut OMatrix<T, D, D>,
    scratch: &mut CholeskyScratch,
    stage: Stage,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    if !is_static::<D>() && out.shape() == c.shape() {
        copy(out, c);
        if cholesky_in_place(out, scratch) {
            out.fill_upper_triangle(T::zero(), 1);
            return Ok(());
        }
    }
    *out = psd_factor(c, stage)?;
    Ok(())
}

/// Largest |Cᵢᵢ| and the entry bound for a zero-variance direction: |cᵢⱼ|² ≤ dᵢ dⱼ, so with a
/// pivot within `tol` of zero the remaining covariances must be within √(tol · max Cᵢᵢ).
fn zero_pivot_bounds<T: Real, D: Dim>(c: &OMatrix<T, D, D>) -> (T, T)
where
    DefaultAllocator: Allocator<D, D>,
{
    let max_diag = max_abs_diagonal(c);
    let tol = tolerance_for(c.nrows(), max_diag);
    (tol, (tol * max_diag).sqrt() + tol)
}

/// Lower Cholesky factor accepting zero pivots; `Err(())` on a pivot below −tolerance.
fn unpivoted_psd_factor<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
) -> core::result::Result<OMatrix<T, D, D>, ()>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = c.nrows();
    let (tol, off_tol) = zero_pivot_bounds(c);
    let mut l = c.clone_owned();
    l.fill(T::zero());
    for j in 0..n {
        let mut d = c[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if d < -tol || !d.is_finite() {
            return Err(());
        }
        let zero_pivot = d <= tol;
        let ljj = d.sqrt();
        if !zero_pivot {
            l[(j, j)] = ljj;
        }
        for i in (j + 1)..n {
            let mut s = c[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            if zero_pivot {
                // The column stays zero: consistent only if these covariances vanish too.
                if s.abs() > off_tol || !s.is_finite() {
                    return Err(());
                }
            } else {
                l[(i, j)] = s / ljj;
            }
        }
    }
    Ok(l)
}

/// S = Pᵀ L from the diagonally pivoted factorisation P C Pᵀ = L Lᵀ; `Err(())` if C has a
/// direction with variance below −tolerance or is not finite.
fn pivoted_psd_factor<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
) -> core::result::Result<OMatrix<T, D, D>, ()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    let n = c.nrows();
    let (tol, off_tol) = zero_pivot_bounds(c);
    // `a` holds L in columns < j and the symmetric Schur complement in rows/columns ≥ j;
    // `perm[i]` is the row of C that row i of `a` came from.
    let mut a = c.clone_owned();
    let mut perm = OVector::<usize, D>::from_fn_generic(c.shape_generic().0, U1, |i, _| i);
    let mut rank = n;
    for j in 0..n {
        let mut p = j;
        for i in j..n {
            let d = a[(i, i)];
            if !d.is_finite() || d < -tol {
                return Err(());
            }
            if d > a[(p, p)] {
                p = i;
            }
        }
        if a[(p, p)] <= tol {
            // The rest has (numerically) zero variance: every remaining covariance must vanish.
            // Negated so that a NaN covariance fails too.
            for k in j..n {
                for i in k..n {
                    if !(a[(i, k)].abs() <= off_tol) {
                        return Err(());
                    }
                }
            }
            rank = j;
            break;
        }
        if p != j {
            a.swap_rows(j, p);
            a.swap_columns(j, p);
            perm.swap_rows(j, p);
        }
        let ljj = a[(j, j)].sqrt();
        a[(j, j)] = ljj;
        for i in (j + 1)..n {
            a[(i, j)] /= ljj;
        }
        for k in (j + 1)..n {
            for i in k..n {
                let v = a[(i, k)] - a[(i, j)] * a[(k, j)];
                a[(i, k)] = v;
                a[(k, i)] = v;
            }
        }
    }
    // Row i of L is row perm[i] of S; columns ≥ rank and the upper triangle are zero.
    let mut root = c.clone_owned();
    root.fill(T::zero());
    for i in 0..n {
        for k in 0..rank.min(i + 1) {
            root[(perm[i], k)] = a[(i, k)];
        }
    }
    Ok(root)
}

/// Replaces `m` by (m + mᵀ)/2, in place.
#[inline]
pub fn symmetrize<T: Real, D: Dim>(m: &mut OMatrix<T, D, D>)
where
    DefaultAllocator: Allocator<D, D>,
{
    let half = real::<T>(0.5);
    let n = m.nrows();
    for j in 0..n {
        for i in (j + 1)..n {
            let v = (m[(i, j)] + m[(j, i)]) * half;
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

/// Side of the square tiles [`symmetric_map`] works in: 8 `f64` are one 64-byte cache line.
const TILE: usize = 8;

/// One symmetric pass over n × n column-major matrices: for every i ≥ j,
///
/// ```text
/// dst[i,j] = dst[j,i] = f(dst[i,j], (srcₖ[i,j])ₖ, dst[j,i], (srcₖ[j,i])ₖ)
/// ```
///
/// with the old values of `dst` read before any is written; true if every written value is
/// finite. One pass where a symmetrisation, an addition and a finiteness scan would otherwise
/// each sweep the matrix (a separate scan measured 2× slower in the n = 50 KF step); e.g.
/// `f = |d, [a], dt, [at]| ((d + a) + (dt + at)) / 2` is `dst += a` then
/// `dst ← (dst + dstᵀ)/2`.
///
/// The pairs are visited in 8 × 8 tiles and a tile's mirror image: both are loaded into local
/// arrays (each tile column is one contiguous run of the column-major storage), combined there,
/// and stored back, so the strided half of every pair costs no more than the contiguous half.
/// (Measured with `perf record` on the n = 50 KF step of `benches/dynamic.rs`: an element-wise
/// pair loop with a finiteness flag per element was ~40 % of the step; see BENCHMARKS.md.)
/// From n = 16 the tile loop is compiled for AVX2 where the CPU has it (pulp's runtime
/// dispatch; AVX-512 measured slower), with the same arithmetic in the same order, so the same
/// results.
#[inline(always)]
#[track_caller]
pub fn symmetric_map<T: Real, const K: usize>(
    n: usize,
    dst: &mut [T],
    sources: [&[T]; K],
    f: impl Fn(T, [T; K], T, [T; K]) -> T,
) -> bool {
    assert_eq!(dst.len(), n * n, "symmetric_map: dst is not n × n");
    assert!(
        sources.iter().all(|s| s.len() == n * n),
        "symmetric_map: a source is not n × n"
    );
    // Dispatched from two tiles on (doc above): KF step at n = 24 14 % faster, at n = 50
    // 12 %, at n = 200 6 %; no difference at n = 12 (dynamic bench, A/B runs).
    if n < 2 * TILE {
        return symmetric_tiles(n, dst, &sources, &f);
    }
    let tiles = SymmetricTiles { n, dst, sources, f };
    // AVX2 at most: compiled for AVX-512 the tile loop measured slower (KF step at n = 50
    // +4 %, its share of the step 17 → 23 %).
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        return pulp::Simd::vectorize(simd, tiles);
    }
    pulp::Arch::new().dispatch(tiles)
}

/// The operands of [`symmetric_tiles`], as the `pulp` operation compiled per instruction set.
struct SymmetricTiles<'a, T, const K: usize, F> {
    n: usize,
    dst: &'a mut [T],
    sources: [&'a [T]; K],
    f: F,
}

impl<T: Real, const K: usize, F: Fn(T, [T; K], T, [T; K]) -> T> pulp::WithSimd
    for SymmetricTiles<'_, T, K, F>
{
    type Output = bool;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> bool {
        symmetric_tiles(self.n, self.dst, &self.sources, &self.f)
    }
}

/// [`symmetric_map`]'s tile loop.
#[inline(always)]
fn symmetric_tiles<T: Real, const K: usize>(
    n: usize,
    dst: &mut [T],
    sources: &[&[T]; K],
    f: &impl Fn(T, [T; K], T, [T; K]) -> T,
) -> bool {
    let mut finite = true;
    for jb in (0..n).step_by(TILE) {
        let jw = TILE.min(n - jb);
        finite &= if jw == TILE {
            diagonal_tile::<T, K, TILE>(n, jb, dst, sources, f)
        } else {
            tile_pair_partial(n, jb, jb, jw, jw, dst, sources, f)
        };
        // The tiles below it and their mirror images to its right.
        for ib in (jb + jw..n).step_by(TILE) {
            let iw = TILE.min(n - ib);
            finite &= if iw == TILE && jw == TILE {
                tile_pair::<T, K, TILE, TILE>(n, ib, jb, dst, sources, f)
            } else {
                tile_pair_partial(n, ib, jb, iw, jw, dst, sources, f)
            };
        }
    }
    finite
}

/// The W × W diagonal tile at (jb, jb), through local arrays like [`tile_pair`].
#[inline(always)]
fn diagonal_tile<T: Real, const K: usize, const W: usize>(
    n: usize,
    jb: usize,
    dst: &mut [T],
    sources: &[&[T]; K],
    f: &impl Fn(T, [T; K], T, [T; K]) -> T,
) -> bool {
    // d[c][r] = M[jb + r, jb + c].
    let mut d = [[T::zero(); W]; W];
    let mut s = [[[T::zero(); W]; W]; K];
    for c in 0..W {
        let at = (jb + c) * n + jb;
        d[c].copy_from_slice(&dst[at..at + W]);
        for k in 0..K {
            s[k][c].copy_from_slice(&sources[k][at..at + W]);
        }
    }
    for c in 0..W {
        for r in c..W {
            let (mut lower, mut upper) = ([T::zero(); K], [T::zero(); K]);
            for k in 0..K {
                lower[k] = s[k][c][r];
                upper[k] = s[k][r][c];
            }
            let v = f(d[c][r], lower, d[r][c], upper);
            d[c][r] = v;
            d[r][c] = v;
        }
    }
    let finite = slice_finite(d.as_flattened());
    for c in 0..W {
        let at = (jb + c) * n + jb;
        dst[at..at + W].copy_from_slice(&d[c]);
    }
    finite
}

/// The off-diagonal tile rows ib..ib+IW × columns jb..jb+JW (ib ≥ jb + JW) and its mirror
/// image, with compile-time tile sizes (the common case: the compiler unrolls and vectorises).
#[inline(always)]
fn tile_pair<T: Real, const K: usize, const IW: usize, const JW: usize>(
    n: usize,
    ib: usize,
    jb: usize,
    dst: &mut [T],
    sources: &[&[T]; K],
    f: &impl Fn(T, [T; K], T, [T; K]) -> T,
) -> bool {
    // lower[c][r] = M[ib + r, jb + c] (column runs); upper[r][c] = M[jb + c, ib + r] (the
    // mirror image's column runs).
    let mut d_lower = [[T::zero(); IW]; JW];
    let mut d_upper = [[T::zero(); JW]; IW];
    let mut s_lower = [[[T::zero(); IW]; JW]; K];
    let mut s_upper = [[[T::zero(); JW]; IW]; K];
    for c in 0..JW {
        let at = (jb + c) * n + ib;
        d_lower[c].copy_from_slice(&dst[at..at + IW]);
        for k in 0..K {
            s_lower[k][c].copy_from_slice(&sources[k][at..at + IW]);
        }
    }
    for r in 0..IW {
        let at = (ib + r) * n + jb;
        d_upper[r].copy_from_slice(&dst[at..at + JW]);
        for k in 0..K {
            s_upper[k][r].copy_from_slice(&sources[k][at..at + JW]);
        }
    }
    for c in 0..JW {
        for r in 0..IW {
            let (mut lower, mut upper) = ([T::zero(); K], [T::zero(); K]);
            for k in 0..K {
                lower[k] = s_lower[k][c][r];
                upper[k] = s_upper[k][r][c];
            }
            let v = f(d_lower[c][r], lower, d_upper[r][c], upper);
            d_lower[c][r] = v;
            d_upper[r][c] = v;
        }
    }
    let finite = slice_finite(d_lower.as_flattened());
    for c in 0..JW {
        let at = (jb + c) * n + ib;
        dst[at..at + IW].copy_from_slice(&d_lower[c]);
    }
    for r in 0..IW {
        let at = (ib + r) * n + jb;
        dst[at..at + JW].copy_from_slice(&d_upper[r]);
    }
    finite
}

/// [`tile_pair`] (or, with `ib == jb`, [`diagonal_tile`]) for a tile cut short by the matrix
/// edge (`iw` × `jw`), pair by pair.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn tile_pair_partial<T: Real, const K: usize>(
    n: usize,
    ib: usize,
    jb: usize,
    iw: usize,
    jw: usize,
    dst: &mut [T],
    sources: &[&[T]; K],
    f: &impl Fn(T, [T; K], T, [T; K]) -> T,
) -> bool {
    let mut finite = true;
    for j in jb..jb + jw {
        for i in ib.max(j)..ib + iw {
            let (ij, ji) = (i + j * n, j + i * n);
            let v = f(
                dst[ij],
                sources.map(|s| s[ij]),
                dst[ji],
                sources.map(|s| s[ji]),
            );
            dst[ij] = v;
            dst[ji] = v;
            finite &= v.is_finite();
        }
    }
    finite
}

/// Copies the lower triangle of `m` to its upper triangle (after a product that computed only
/// the lower one, [`crate::kernel::mul_lower`]); true if the result is finite.
#[inline(always)]
pub fn mirror_lower_checked<T: Real, D: Dim>(m: &mut OMatrix<T, D, D>) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    symmetric_map(n, m.as_mut_slice(), [], |lower, [], _, []| lower)
}

/// m ← ((m + a) + (m + a)ᵀ)/2 in one pass (the same arithmetic as `m += a` then
/// [`symmetrize`]); true if the result is finite.
#[inline(always)]
#[track_caller]
pub fn symmetrize_add_checked<T: Real, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    a: &OMatrix<T, D, D>,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    assert_eq!(
        m.shape(),
        a.shape(),
        "symmetrize_add_checked: shapes differ"
    );
    let half = real::<T>(0.5);
    let n = m.nrows();
    symmetric_map(
        n,
        m.as_mut_slice(),
        [a.as_slice()],
        |m_ij, [a_ij], m_ji, [a_ji]| ((m_ij + a_ij) + (m_ji + a_ji)) * half,
    )
}

/// dst ← ((a + b) + (a + b)ᵀ)/2 in one pass; true if the result is finite.
#[inline(always)]
#[track_caller]
pub fn symmetric_sum_into_checked<T: Real, D: Dim>(
    dst: &mut OMatrix<T, D, D>,
    a: &OMatrix<T, D, D>,
    b: &OMatrix<T, D, D>,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    assert!(
        dst.shape() == a.shape() && a.shape() == b.shape(),
        "symmetric_sum_into_checked: shapes differ"
    );
    let half = real::<T>(0.5);
    let n = dst.nrows();
    symmetric_map(
        n,
        dst.as_mut_slice(),
        [a.as_slice(), b.as_slice()],
        |_, [a_ij, b_ij], _, [a_ji, b_ji]| ((a_ij + b_ij) + (a_ji + b_ji)) * half,
    )
}

/// `Ok(())` if `m` is symmetric within `√ε · max|mᵢⱼ|` (the largest finite entry), else
/// [`Error::NotSymmetric`] naming the worst pair. A pair is symmetric if equal (±∞ included)
/// or within that tolerance; a pair with a NaN never is, and is the worst.
pub fn ensure_symmetric<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    let scale = m
        .iter()
        .filter(|v| v.is_finite())
        .fold(T::zero(), |a, v| a.max(v.abs()));
    let tol = T::default_epsilon().sqrt() * scale;
    // The worst asymmetric pair so far: its gap and position; a NaN gap (a NaN entry)
    // outranks every other, ∞ included.
    let is_nan = |x: T| x.partial_cmp(&x).is_none();
    let mut worst: Option<(T, usize, usize)> = None;
    for j in 0..n {
        for i in (j + 1)..n {
            let (lower, upper) = (m[(i, j)], m[(j, i)]);
            let gap = (lower - upper).abs();
            if lower == upper || gap <= tol {
                continue;
            }
            let worse = worst.is_none_or(|(w, _, _)| !is_nan(w) && (is_nan(gap) || gap > w));
            if worse {
                worst = Some((gap, i, j));
            }
        }
    }
    match worst {
        Some((_, row, col)) => Err(Error::NotSymmetric {
            stage,
            quantity,
            row,
            col,
        }),
        None => Ok(()),
    }
}

/// `Ok(())` unless a diagonal entry of the square `m` is below −[`psd_tolerance`], else
/// [`Error::NotPositiveSemiDefinite`]. A necessary condition for positive semi-definiteness
/// (variances are not negative) in O(n): for noise matrices met every step, where
/// [`ensure_psd`] would cost a factorisation. NaN entries pass (finiteness is checked
/// separately).
pub fn ensure_nonnegative_diagonal<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D, D>,
{
    /// The rare case: some variance is negative; is it beyond round-off?
    #[cold]
    fn beyond_round_off<T: Real, D: Dim>(m: &OMatrix<T, D, D>) -> bool
    where
        DefaultAllocator: Allocator<D, D>,
    {
        let floor = -psd_tolerance(m);
        (0..m.nrows()).any(|i| m[(i, i)] < floor)
    }
    let negative = (0..m.nrows()).any(|i| m[(i, i)] < T::zero());
    if negative && beyond_round_off(m) {
        Err(Error::NotPositiveSemiDefinite { stage, quantity })
    } else {
        Ok(())
    }
}

/// `Ok(())` if the symmetric `m` is positive semi-definite within [`psd_tolerance`].
pub fn ensure_psd<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    psd_factor(m, stage)
        .map(|_| ())
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// Deterministic, distinct, non-symmetric entries.
    fn matrix(n: usize, salt: f64) -> DMatrix<f64> {
        DMatrix::from_fn(n, n, |i, j| ((i * 31 + j * 17) as f64 * 0.37 + salt).sin())
    }

    /// The tiled pass against the plain pair loop, bit for bit, on sizes around the tile
    /// (partial tiles on both edges, a single partial tile, n = 0).
    #[test]
    fn symmetric_map_matches_the_pair_loop() {
        for n in [0, 1, 3, 7, 8, 9, 15, 16, 17, 24, 50] {
            let (a, b) = (matrix(n, 0.1), matrix(n, 0.7));
            let f = |d: f64, [x, y]: [f64; 2], dt: f64, [xt, yt]: [f64; 2]| {
                ((d + x) * y + dt) - (xt * 0.5 + yt)
            };
            let mut tiled = matrix(n, 0.3);
            let mut expected = tiled.clone();
            for j in 0..n {
                for i in j..n {
                    let (old, old_t) = (expected[(i, j)], expected[(j, i)]);
                    let v = f(old, [a[(i, j)], b[(i, j)]], old_t, [a[(j, i)], b[(j, i)]]);
                    expected[(i, j)] = v;
                    expected[(j, i)] = v;
                }
            }
            assert!(symmetric_map(
                n,
                tiled.as_mut_slice(),
                [a.as_slice(), b.as_slice()],
                f
            ));
            for (x, y) in tiled.iter().zip(expected.iter()) {
                assert_eq!(x.to_bits(), y.to_bits(), "n = {n}");
            }
        }
    }

    /// NaN covariances are rejected on every route of `psd_factor`, also where the pivoted
    /// fallback meets a zero-variance block (whose covariances must vanish: a NaN does not),
    /// and by the in-place route of `psd_factor_into` (Cholesky first, then the fallback).
    #[test]
    fn psd_factor_rejects_nan_covariances() {
        let nan = f64::NAN;
        let two = DMatrix::from_row_slice(2, 2, &[0.0, nan, nan, 0.0]);
        let three = DMatrix::from_row_slice(3, 3, &[1.0, 0.0, 0.0, 0.0, 0.0, nan, 0.0, nan, 0.0]);
        let diagonal = DMatrix::from_row_slice(2, 2, &[nan, 0.0, 0.0, 1.0]);
        let dense = DMatrix::from_row_slice(2, 2, &[2.0, nan, nan, 2.0]);
        for c in [two, three, diagonal, dense] {
            let stage = Stage::Propagation;
            assert!(psd_factor(&c, stage).is_err(), "{c}");
            let mut out = DMatrix::zeros(c.nrows(), c.ncols());
            let mut scratch = CholeskyScratch::default();
            assert!(
                psd_factor_into(&c, &mut out, &mut scratch, stage).is_err(),
                "{c}"
            );
            assert!(ensure_psd(&c, stage, Quantity::Covariance).is_err(), "{c}");
        }
    }

    /// Negative variances are rejected, round-off below the PSD tolerance and NaN are not.
    #[test]
    fn ensure_nonnegative_diagonal_rejects_negative_variances() {
        let check = |d: &[f64]| {
            let m = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(d));
            ensure_nonnegative_diagonal(&m, Stage::Update, Quantity::MeasurementNoise)
        };
        let rejected = Err(Error::NotPositiveSemiDefinite {
            stage: Stage::Update,
            quantity: Quantity::MeasurementNoise,
        });
        assert_eq!(check(&[-0.5, 0.09]), rejected);
        assert_eq!(check(&[1.0, 2.0, -1e-6]), rejected);
        assert_eq!(check(&[1.0, 2.0, -1e-17]), Ok(()));
        assert_eq!(check(&[1.0, 0.0, f64::NAN]), Ok(()));
        assert_eq!(check(&[]), Ok(()));
    }

    /// A NaN or an infinite entry makes a pair asymmetric unless both entries are the same
    /// infinity; a NaN pair is named before a larger finite or infinite gap.
    #[test]
    fn ensure_symmetric_sees_non_finite_pairs() {
        let check = |rows: &[f64]| {
            let m = DMatrix::from_row_slice(3, 3, rows);
            match ensure_symmetric(&m, Stage::Construction, Quantity::Covariance) {
                Ok(()) => None,
                Err(Error::NotSymmetric { row, col, .. }) => Some((row, col)),
                Err(e) => panic!("unexpected {e:?}"),
            }
        };
        let (nan, inf) = (f64::NAN, f64::INFINITY);
        assert_eq!(
            check(&[1.0, 0.0, 0.0, nan, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((1, 0))
        );
        assert_eq!(
            check(&[1.0, 5.0, 0.0, inf, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((1, 0))
        );
        assert_eq!(
            check(&[1.0, 9.0, nan, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((2, 0))
        );
        assert_eq!(
            check(&[1.0, inf, 0.0, 0.0, 1.0, nan, 0.0, 0.0, 1.0]),
            Some((2, 1))
        );
        assert_eq!(check(&[1.0, inf, 0.0, inf, 1.0, 0.0, 0.0, 0.0, 1.0]), None);
        assert_eq!(check(&[inf, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0]), None);
        // Finite gaps: still against √ε of the largest (finite) entry.
        assert_eq!(
            check(&[4.0, 1.0, 0.0, 1.0 + 1e-9, 1.0, 0.0, 0.0, 0.0, 1.0]),
            None
        );
        assert_eq!(
            check(&[4.0, 1.0, 0.0, 1.0 + 1e-6, 1.0, 0.0, 0.0, 0.0, 1.0]),
            Some((1, 0))
        );
    }

    #[test]
    fn symmetric_map_reports_non_finite_values_anywhere() {
        for (i, j) in [(0, 0), (12, 3), (3, 12), (16, 16), (17, 0)] {
            let mut m = matrix(18, 0.2);
            m[(i, j)] = f64::INFINITY;
            assert!(
                !mirror_lower_checked(&mut m.clone()) || i < j,
                "({i}, {j}) mirrored"
            );
            let zeros = DMatrix::zeros(18, 18);
            assert!(!symmetrize_add_checked(&mut m, &zeros), "({i}, {j})");
        }
    }

    /// Every length around the 8 lanes, every position, each kind of non-finite value; the
    /// extreme finite values (whose sum would overflow) still count as finite.
    #[test]
    fn slice_finite_finds_any_non_finite_value() {
        for len in 0..=19 {
            let finite: Vec<f64> = (0..len)
                .map(|k| [f64::MAX, -f64::MAX, f64::MIN_POSITIVE, -0.0, 1.5][k % 5])
                .collect();
            assert!(slice_finite(&finite), "len {len}");
            for at in 0..len {
                for bad in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
                    let mut values = finite.clone();
                    values[at] = bad;
                    assert!(!slice_finite(&values), "len {len}, {bad} at {at}");
                }
            }
        }
    }
}
