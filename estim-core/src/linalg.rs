//! Internal, not public API (hidden from the docs; the estim crates use it): finiteness and
//! shape checks, the positive semi-definite factor of a covariance ([`psd_factor`], public as
//! `estim_core::psd_factor`), symmetrisation.
//!
//! All of them work in place or on the stack for static sizes: none allocates unless the
//! matrix type itself lives on the heap (`Dyn`).

use nalgebra::{
    DefaultAllocator, Dim, IsContiguous, Matrix, OMatrix, OVector, RawStorage, StorageMut, U1,
    allocator::Allocator,
};

use crate::error::{Error, Quantity, Result, Stage};
use crate::kernel::{CholeskyScratch, cholesky_in_place, copy};
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

/// A square root S with S Sᵀ = C of a symmetric positive **semi**-definite C (its lower
/// triangle is read).
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
///
/// This is the one semi-definite factorisation of a covariance in the library
/// (`lower_factor_in_place`); the fast path of [`psd_factor_into`] and the update's innovation
/// covariance use the plain Cholesky factor ([`cholesky_in_place`]: the same loop without the
/// tolerance at small sizes, bit for bit the same when every pivot exceeds it; faer's at larger
/// ones, equal up to round-off).
///
/// ```
/// use estim_core::{psd_factor, Stage};
/// use estim_core::nalgebra::Matrix2;
///
/// // A covariance of rank one: x₂ = 2 x₁ exactly.
/// let c = Matrix2::new(1.0, 2.0, 2.0, 4.0);
/// let s = psd_factor(&c, Stage::Propagation)?;
/// assert!((s * s.transpose() - c).abs().max() < 1e-12);
/// assert_eq!(s[(1, 1)], 0.0); // the second direction adds no variance
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn psd_factor<T: Real, D: Dim>(c: &OMatrix<T, D, D>, stage: Stage) -> Result<OMatrix<T, D, D>>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    let bounds = zero_pivot_bounds(c);
    let mut l = c.clone_owned();
    if lower_factor_in_place(&mut l, bounds, None).is_ok() {
        l.fill_upper_triangle(T::zero(), 1);
        return Ok(l);
    }
    let error = Error::NotPositiveSemiDefinite {
        stage,
        quantity: Quantity::Covariance,
    };
    // `perm[i]` is the row of C that row i of L came from.
    let mut perm = OVector::<usize, D>::from_fn_generic(c.shape_generic().0, U1, |i, _| i);
    l.copy_from(c);
    let rank =
        lower_factor_in_place(&mut l, bounds, Some(perm.as_mut_slice())).map_err(|()| error)?;
    // Row i of L is row perm[i] of S; columns ≥ rank and the upper triangle are zero.
    let mut root = c.clone_owned();
    root.fill(T::zero());
    for (i, &row) in perm.iter().enumerate() {
        for k in 0..rank.min(i + 1) {
            root[(row, k)] = l[(i, k)];
        }
    }
    Ok(root)
}

/// [`psd_factor`] into `out`. It first tries the plain Cholesky factor in place
/// ([`cholesky_in_place`], allocation-free with a sized `scratch`), which succeeds for every
/// positive definite C and gives the same lower factor up to round-off; only a semi-definite C
/// falls back to [`psd_factor`] (which allocates for runtime sizes). For small static sizes
/// the plain factor is [`psd_factor`]'s own loop inlined, without its tolerance (trying it
/// first took the UKF 6/4 step from 15,233 to 14,600 instructions, commit
/// `b1972b9`).
pub fn psd_factor_into<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
    out: &mut OMatrix<T, D, D>,
    scratch: &mut CholeskyScratch,
    stage: Stage,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    if out.shape() == c.shape() {
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

/// The factorisation behind [`psd_factor`] and [`inverse_quadratic_form`]: P A Pᵀ = L Lᵀ in
/// place by the left-looking (Crout) Cholesky algorithm, L in the lower triangle of `a` (only
/// the lower triangle is read; the strict upper triangle is left unspecified). Column j is
/// formed from the finished columns as lᵢⱼ = (aᵢⱼ − Σₖ₍ⱼ lᵢₖ lⱼₖ) / lⱼⱼ, accumulated in a
/// register: the same operations in the same order as the right-looking form (so the same
/// rounding), at half the instructions on small matrices, where the right-looking form's
/// stores into the trailing block each went back through memory.
///
/// Without `perm`, P = I and pivot j is the updated aⱼⱼ. With `perm`, pivot j is the largest
/// remaining updated diagonal entry (diagonal pivoting, as LAPACK's `dpstrf`; the swaps
/// recorded in `perm`, which must start as the identity). A pivot within `tol` of zero
/// (`bounds = (tol, off_tol)`) is a direction without variance: its column of L is zero and
/// its remaining updated covariances must be within `off_tol` (|cᵢⱼ|² ≤ cᵢᵢ cⱼⱼ); with
/// pivoting every later pivot is then as small, so the factorisation stops there. Returns the
/// rank (the number of nonzero pivots), or `Err(())` at a pivot below −`tol`, a non-finite
/// pivot, or a covariance of a zero-variance direction beyond `off_tol` (a NaN included); then
/// `a` is unspecified.
#[inline]
pub(crate) fn lower_factor_in_place<T, D, S>(
    a: &mut Matrix<T, D, D, S>,
    (tol, off_tol): (T, T),
    mut perm: Option<&mut [usize]>,
) -> core::result::Result<usize, ()>
where
    T: Real,
    D: Dim,
    S: StorageMut<T, D, D>,
{
    // Entry (i, k), i ≥ k ≥ j, of the trailing block after j finished columns.
    let updated = |a: &Matrix<T, D, D, S>, i: usize, k: usize, j: usize| {
        (0..j).fold(a[(i, k)], |s, m| s - a[(i, m)] * a[(k, m)])
    };
    let n = a.nrows();
    let mut rank = 0;
    for j in 0..n {
        if let Some(perm) = perm.as_deref_mut() {
            let (mut p, mut largest) = (j, T::zero());
            for i in j..n {
                let d = updated(a, i, i, j);
                if !d.is_finite() || d < -tol {
                    return Err(());
                }
                if i == j || d > largest {
                    (p, largest) = (i, d);
                }
            }
            if largest <= tol {
                // The rest has (numerically) zero variance: every remaining covariance must
                // vanish. Negated so that a NaN covariance fails too.
                let vanish = (j..n).all(|k| (k..n).all(|i| updated(a, i, k, j).abs() <= off_tol));
                return if vanish { Ok(rank) } else { Err(()) };
            }
            if p != j {
                symmetric_swap(a, j, p);
                perm.swap(j, p);
            }
        }
        let d = updated(a, j, j, j);
        if d < -tol || !d.is_finite() {
            return Err(());
        }
        if d <= tol {
            // A zero column: consistent only if these covariances vanish too.
            for i in (j + 1)..n {
                if !(updated(a, i, j, j).abs() <= off_tol) {
                    return Err(());
                }
                a[(i, j)] = T::zero();
            }
            a[(j, j)] = T::zero();
            continue;
        }
        rank += 1;
        let ljj = d.sqrt();
        a[(j, j)] = ljj;
        for i in (j + 1)..n {
            a[(i, j)] = updated(a, i, j, j) / ljj;
        }
    }
    Ok(rank)
}

/// Swaps rows and columns j < p of the symmetric matrix whose lower triangle is `a`'s, within
/// that lower triangle (rows/columns before j hold finished columns of L and swap as rows).
fn symmetric_swap<T: Real, D: Dim, S: StorageMut<T, D, D>>(
    a: &mut Matrix<T, D, D, S>,
    j: usize,
    p: usize,
) {
    let n = a.nrows();
    for k in 0..j {
        a.swap((j, k), (p, k));
    }
    a.swap((j, j), (p, p));
    for i in (j + 1)..p {
        a.swap((i, j), (p, i));
    }
    for i in (p + 1)..n {
        a.swap((i, j), (i, p));
    }
}

/// vᵀ C⁻¹ v = |L⁻¹ v|² for a symmetric positive definite C (its lower triangle is read), by
/// the factorisation of [`psd_factor`] with a zero tolerance: `None` if C is not positive
/// definite (a pivot ≤ 0 or not finite). `c` is overwritten by L and `v` by L⁻¹ v. Allocates
/// nothing (views over caller buffers work).
pub fn inverse_quadratic_form<T, D, S, SV>(
    c: &mut Matrix<T, D, D, S>,
    v: &mut Matrix<T, D, U1, SV>,
) -> Option<T>
where
    T: Real,
    D: Dim,
    S: StorageMut<T, D, D>,
    SV: StorageMut<T, D, U1>,
{
    let n = c.nrows();
    assert_eq!(v.nrows(), n, "inverse_quadratic_form: shapes differ");
    let rank = lower_factor_in_place(c, (T::zero(), T::zero()), None).ok()?;
    if rank < n {
        return None;
    }
    c.solve_lower_triangular_unchecked_mut(v);
    Some(v.norm_squared())
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

/// One symmetric pass over n × n column-major matrices: for every i ≥ j,
///
/// ```text
/// dst[i,j] = dst[j,i] = f(dst[i,j], (srcₖ[i,j])ₖ, dst[j,i], (srcₖ[j,i])ₖ)
/// ```
///
/// with the old values of `dst` read before any is written; true if every written value is
/// finite. One pass where a symmetrisation, an addition and a finiteness scan would otherwise
/// each sweep the matrix; e.g. `f = |d, [a], dt, [at]| ((d + a) + (dt + at)) / 2` is
/// `dst += a` then `dst ← (dst + dstᵀ)/2`.
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
    // `array::from_fn`: `sources.map(..)` per entry was compiled as an out-of-line call
    // (`array::try_map`), a tenth of a 6/4 EKF step (filters bench, instruction counts).
    let gather = |at: usize| -> [T; K] { core::array::from_fn(|k| sources[k][at]) };
    let mut finite = true;
    for j in 0..n {
        for i in j..n {
            let (ij, ji) = (i + j * n, j + i * n);
            let v = f(dst[ij], gather(ij), dst[ji], gather(ji));
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

/// `Ok(())` if the noise covariance `m` (a Q(x, u, Δt) or R(x) evaluated at a step) is
/// positive semi-definite by [`psd_factor`]'s rule, else [`Error::NotPositiveSemiDefinite`]
/// naming `quantity`. The rule, with τ = 16 n ε max|sᵢᵢ| ([`psd_tolerance`]): every pivot of
/// S = L D Lᵀ is ≥ −τ, and where a pivot is within τ of zero (a direction without variance)
/// its remaining covariances are within √(τ max|sᵢᵢ|) + τ. That second bound is of order
/// √ε max|sᵢᵢ|, so where the diagonal has zeros an eigenvalue about that negative can pass
/// (S with s₁₂ = s₂₁ = 10⁻⁸, s₃₃ = 1 and zeros elsewhere, eigenvalue −10⁻⁸ against
/// √(τ · 1) ≈ 10⁻⁷); the filters' own covariance factorisations use the same rule.
/// Non-finite entries pass, as in [`ensure_nonnegative_diagonal`]: the filters check
/// finiteness where it costs nothing extra and name the culprit then. The filters use the
/// symmetric part S = (M + Mᵀ)/2, so that is what is checked (formed as M/2 + Mᵀ/2, which
/// does not overflow). Cheapest test first:
///
/// 1. **Diagonally dominant** (Gershgorin: every eigenvalue of S lies in some disc
///    [sᵢᵢ − rᵢ, sᵢᵢ + rᵢ], rᵢ = Σⱼ≠ᵢ |sᵢⱼ|, so sᵢᵢ ≥ rᵢ for all i gives λ ≥ 0): O(n²) additions
///    and comparisons, no factorisation. Every diagonal noise passes here.
/// 2. Otherwise S = L D Lᵀ without pivoting or square roots, in `work` (its shape is made
///    m's, allocating only if it differs), with [`psd_factor`]'s rule for a pivot within the
///    tolerance of zero: a direction without variance, whose remaining covariances must
///    vanish (|sᵢⱼ|² ≤ sᵢᵢ sⱼⱼ). A rank-deficient Γ W Γᵀ (white-acceleration noise) passes
///    here; n³/6 multiply-adds, inlined.
/// 3. Only if a pivot is below −tolerance or a zero-variance column does not vanish (which
///    round-off in an unpivoted order can cause for a singular S), [`psd_factor`] with
///    diagonal pivoting decides (it allocates for runtime sizes: the rare case).
///
/// Semi-definite noise is legitimate (a bias without process noise, a component measured
/// exactly); the filters check S = cov ẑ + R positive definite separately. `work` is
/// unspecified afterwards.
///
/// ```
/// use estim_core::linalg::ensure_semidefinite_noise;
/// use estim_core::nalgebra::Matrix2;
/// use estim_core::{Error, Quantity, Stage};
///
/// let mut work = Matrix2::zeros();
/// let stage = Stage::Prediction;
/// let q = Quantity::ProcessNoise;
/// // Rank one: x₂ = 2 x₁ exactly. Semi-definite, accepted.
/// assert!(ensure_semidefinite_noise(&Matrix2::new(1.0, 2.0, 2.0, 4.0), &mut work, stage, q).is_ok());
/// // A positive diagonal but an eigenvalue of −1: refused.
/// assert_eq!(
///     ensure_semidefinite_noise(&Matrix2::new(1.0, 2.0, 2.0, 1.0), &mut work, stage, q),
///     Err(Error::NotPositiveSemiDefinite { stage, quantity: q })
/// );
/// ```
#[inline(always)]
pub fn ensure_semidefinite_noise<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    work: &mut OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    let n = m.nrows();
    let (mut dominant, mut max_diag) = (true, T::zero());
    for i in 0..n {
        let mut radius = T::zero();
        for j in 0..n {
            if j != i {
                radius += symmetric_entry(m, i, j).abs();
            }
        }
        dominant &= m[(i, i)] >= radius;
        max_diag = max_diag.max(m[(i, i)].abs());
    }
    if dominant {
        return Ok(());
    }
    if work.shape() != m.shape() {
        *work = m.clone_owned();
    }
    if semidefinite_ldl(m, work, max_diag) {
        return Ok(());
    }
    pivoted_noise_check(m, work, stage, quantity)
}

/// sᵢⱼ = (mᵢⱼ + mⱼᵢ)/2, formed as mᵢⱼ/2 + mⱼᵢ/2 so that finite entries cannot overflow.
#[inline(always)]
fn symmetric_entry<T: Real, D: Dim>(m: &OMatrix<T, D, D>, i: usize, j: usize) -> T
where
    DefaultAllocator: Allocator<D, D>,
{
    let half = real::<T>(0.5);
    m[(i, j)] * half + m[(j, i)] * half
}

/// Tier 2 of [`ensure_semidefinite_noise`]: S = (M + Mᵀ)/2 = L D Lᵀ, dⱼ = sⱼⱼ − Σₖ₍ⱼ lⱼₖ² dₖ
/// and lᵢⱼ = (sᵢⱼ − Σₖ₍ⱼ lᵢₖ lⱼₖ dₖ) / dⱼ, with lᵢⱼ below the diagonal of `work` and dⱼ on it.
/// `true` if every pivot is above the tolerance or within it with a vanishing column (then
/// set to zero, as [`lower_factor_in_place`] does); `false` at a pivot below −tolerance, a
/// non-vanishing zero-variance column, or a NaN.
#[inline(always)]
fn semidefinite_ldl<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    work: &mut OMatrix<T, D, D>,
    max_diag: T,
) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    let tol = tolerance_for(n, max_diag);
    let off_tol = (tol * max_diag).sqrt() + tol;
    for j in 0..n {
        let d = (0..j).fold(m[(j, j)], |d, k| {
            let l = work[(j, k)];
            d - l * l * work[(k, k)]
        });
        if !(d >= -tol) {
            return false;
        }
        let zero = d <= tol;
        let scale = if zero { T::zero() } else { T::one() / d };
        work[(j, j)] = if zero { T::zero() } else { d };
        for i in (j + 1)..n {
            let s = symmetric_entry(m, i, j);
            let w = (0..j).fold(s, |w, k| w - work[(i, k)] * work[(j, k)] * work[(k, k)]);
            // A zero-variance direction: its covariances must vanish (negated: NaN fails).
            if zero && !(w.abs() <= off_tol) {
                return false;
            }
            work[(i, j)] = w * scale;
        }
    }
    true
}

/// Tier 3 of [`ensure_semidefinite_noise`], out of line (the rare case): non-finite entries
/// pass (left to the finiteness checks); otherwise [`psd_factor`] decides (its Cholesky with
/// zero pivots, then, if that fails, with diagonal pivoting).
#[cold]
#[inline(never)]
fn pivoted_noise_check<T: Real, D: Dim>(
    m: &OMatrix<T, D, D>,
    work: &mut OMatrix<T, D, D>,
    stage: Stage,
    quantity: Quantity,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    if !all_finite(m) {
        return Ok(());
    }
    let n = m.nrows();
    for j in 0..n {
        for i in 0..n {
            work[(i, j)] = symmetric_entry(m, i, j);
        }
    }
    psd_factor(work, stage)
        .map(|_| ())
        .map_err(|_| Error::NotPositiveSemiDefinite { stage, quantity })
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
    use nalgebra::{DMatrix, DVector};

    /// Deterministic, distinct, non-symmetric entries.
    fn matrix(n: usize, salt: f64) -> DMatrix<f64> {
        DMatrix::from_fn(n, n, |i, j| ((i * 31 + j * 17) as f64 * 0.37 + salt).sin())
    }

    /// The pass against a plain pair loop, bit for bit, on sizes around 8 and 16 (where a
    /// tiled version of it had partial tiles), n = 0 included.
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

    /// C = G Gᵀ/n + I: well conditioned (κ < 10), so factors agree to a few ε.
    fn definite(n: usize) -> DMatrix<f64> {
        let g = DMatrix::from_fn(n, n, |i, j| ((i * 13 + j * 7) as f64 * 0.37).sin());
        &g * g.transpose() / n.max(1) as f64 + DMatrix::identity(n, n)
    }

    /// On a positive definite C, `psd_factor` (and `psd_factor_into`, faer's factor first) is
    /// the Cholesky factor: lower triangular, equal to nalgebra's within 8 n ε max|L| (C is
    /// well conditioned), f64 and f32, runtime and static sizes.
    #[test]
    fn psd_factor_is_the_cholesky_factor_of_a_definite_matrix() {
        for n in [1, 2, 3, 5, 8, 13, 40] {
            let c = definite(n);
            let expected = c.clone().cholesky().unwrap().l();
            let bound = |eps: f64| 8.0 * n as f64 * eps * expected.amax();
            let s = psd_factor(&c, Stage::Propagation).unwrap();
            assert!((&s - &expected).amax() <= bound(f64::EPSILON), "n = {n}");
            let mut into = DMatrix::zeros(n, n);
            let mut scratch = CholeskyScratch::default();
            psd_factor_into(&c, &mut into, &mut scratch, Stage::Propagation).unwrap();
            assert!(
                (&into - &expected).amax() <= bound(f64::EPSILON),
                "into n = {n}"
            );
            let s32 = psd_factor(&c.map(|v| v as f32), Stage::Propagation).unwrap();
            let gap = (s32.map(f64::from) - &expected).amax();
            assert!(gap <= bound(f32::EPSILON as f64), "f32 n = {n}: {gap:e}");
        }
        let c = nalgebra::Matrix4::from_iterator(definite(4).iter().copied());
        let s = psd_factor(&c, Stage::Propagation).unwrap();
        let expected = c.cholesky().unwrap().l();
        assert!((s - expected).amax() <= 32.0 * f64::EPSILON * expected.amax());
    }

    /// The pivoted factorisation of C = B Bᵀ (B n × r of rank r) for every rank, with
    /// diagonal entries spread so that the pivots are swapped around: it reports rank r and
    /// S = Pᵀ L reproduces C within 16 n ε max(1, max Cᵢᵢ) (f64; f32 through `psd_factor`).
    #[test]
    fn pivoted_factor_reproduces_every_rank() {
        for n in [1, 2, 3, 5, 9] {
            for r in 0..=n {
                // Orthogonal (cosine-transform) columns, rows scaled by 1 to n out of order.
                let b = DMatrix::from_fn(n, r, |i, j| {
                    let angle = core::f64::consts::PI * (i as f64 + 0.5) * j as f64 / n as f64;
                    angle.cos() * (1.0 + (i * 7 % n) as f64)
                });
                let c = &b * b.transpose();
                let tol = 16.0 * n as f64 * c.diagonal().amax().max(1.0);
                let mut l = c.clone();
                let mut perm: Vec<usize> = (0..n).collect();
                let bounds = zero_pivot_bounds(&c);
                let rank = lower_factor_in_place(&mut l, bounds, Some(&mut perm)).unwrap();
                assert_eq!(rank, r, "n = {n}");
                let mut s = DMatrix::zeros(n, n);
                for (i, &row) in perm.iter().enumerate() {
                    for k in 0..rank.min(i + 1) {
                        s[(row, k)] = l[(i, k)];
                    }
                }
                let gap = (&s * s.transpose() - &c).amax();
                assert!(gap <= tol * f64::EPSILON, "n = {n} r = {r}: {gap:e}");
                let c32 = c.map(|v| v as f32);
                let s32 = psd_factor(&c32, Stage::Propagation).unwrap();
                let gap = (&s32 * s32.transpose() - &c32).amax() as f64;
                // Rounded to f32, C is no longer of rank r: the pivots left within the zero
                // tolerance (16 n ε max Cᵢᵢ each) are dropped, so 4× the f64 bound.
                let bound = 4.0 * tol * f32::EPSILON as f64;
                assert!(gap <= bound, "f32 n = {n} r = {r}: {gap:e}");
            }
        }
    }

    /// vᵀ C⁻¹ v against nalgebra's Cholesky solve (f64, f32, static size); a semi-definite, an
    /// indefinite and a NaN C give `None`.
    #[test]
    fn inverse_quadratic_form_matches_nalgebra() {
        for n in [1, 2, 6, 17] {
            let c = definite(n);
            let v = nalgebra::DVector::from_fn(n, |i, _| (i as f64 * 0.9).cos());
            let expected = v.dot(&c.clone().cholesky().unwrap().solve(&v));
            let q = inverse_quadratic_form(&mut c.clone(), &mut v.clone()).unwrap();
            assert!((q - expected).abs() <= 8.0 * n as f64 * f64::EPSILON * expected);
            let (mut c32, mut v32) = (c.map(|x| x as f32), v.map(|x| x as f32));
            let q32 = inverse_quadratic_form(&mut c32, &mut v32).unwrap() as f64;
            assert!((q32 - expected).abs() <= 64.0 * n as f64 * f32::EPSILON as f64 * expected);
        }
        let mut c = nalgebra::Matrix2::new(4.0_f64, 2.0, 2.0, 3.0);
        let mut v = nalgebra::Vector2::new(1.0, 2.0);
        let q = inverse_quadratic_form(&mut c, &mut v).unwrap();
        assert!((q - 11.0 / 8.0).abs() < 1e-15);
        for rows in [
            [1.0, 1.0, 1.0, 1.0],
            [1.0, 2.0, 2.0, 1.0],
            [f64::NAN, 0.0, 0.0, 1.0],
        ] {
            let mut c = nalgebra::Matrix2::from_row_slice(&rows);
            let mut v = nalgebra::Vector2::new(1.0, 0.0);
            assert_eq!(inverse_quadratic_form(&mut c, &mut v), None, "{rows:?}");
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

    /// The per-step noise check against the eigenvalues of the symmetric part, through each
    /// tier: diagonally dominant (with an asymmetric matrix), rank-deficient Γ Γᵀ (the
    /// factorisation tier), a rank-deficient matrix whose unpivoted factorisation stops at a
    /// zero pivot, indefinite with a positive diagonal, and a negative variance beyond
    /// round-off; runtime and static sizes, f64 and f32, and a `work` of the wrong size.
    #[test]
    fn ensure_semidefinite_noise_agrees_with_the_eigenvalues() {
        let (stage, q) = (Stage::Prediction, Quantity::ProcessNoise);
        let refused = Err(Error::NotPositiveSemiDefinite { stage, quantity: q });
        let g = DMatrix::from_row_slice(3, 1, &[0.3, -1.2, 0.7]);
        let cases: Vec<(DMatrix<f64>, bool)> = vec![
            (DMatrix::from_diagonal_element(3, 3, 0.0), true),
            (
                DMatrix::from_row_slice(3, 3, &[2.0, 0.5, -1.0, 0.3, 1.0, 0.2, -1.0, 0.4, 1.5]),
                true,
            ),
            (&g * g.transpose(), true),
            // Zero first pivot with a vanishing column, then a rank-one block.
            (
                DMatrix::from_row_slice(3, 3, &[0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 2.0, 4.0]),
                true,
            ),
            (
                DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
                false,
            ),
            // Zero pivot whose column does not vanish: indefinite.
            (
                DMatrix::from_row_slice(3, 3, &[0.0, 0.1, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0, 1.0]),
                false,
            ),
            (
                DMatrix::from_diagonal(&DVector::from_row_slice(&[1.0, -1e-3, 1.0])),
                false,
            ),
        ];
        for (m, psd) in cases {
            let sym = (&m + m.transpose()) * 0.5;
            let lambda = sym.clone().symmetric_eigenvalues().min();
            assert_eq!(lambda >= -1e-12, psd, "{m}: λ_min {lambda}");
            let expected = if psd { Ok(()) } else { refused };
            assert_eq!(
                ensure_semidefinite_noise(&m, &mut m.clone(), stage, q),
                expected
            );
            assert_eq!(
                ensure_semidefinite_noise(&m, &mut DMatrix::zeros(1, 1), stage, q),
                expected
            );
            let fixed = nalgebra::Matrix3::from_iterator(m.iter().copied());
            assert_eq!(
                ensure_semidefinite_noise(&fixed, &mut nalgebra::Matrix3::zeros(), stage, q),
                expected
            );
            let single = m.map(|v| v as f32);
            assert_eq!(
                ensure_semidefinite_noise(&single, &mut single.clone(), stage, q),
                expected
            );
        }
        // Rank one with entries near the largest finite value (2 × 2 and 3 × 3: tiers 2 and 3
        // after Gershgorin fails on the asymmetric one): the symmetric part is formed as
        // M/2 + Mᵀ/2, so it does not overflow into a refusal.
        let huge = DMatrix::from_element(2, 2, 1e308);
        assert_eq!(
            ensure_semidefinite_noise(&huge, &mut huge.clone(), stage, q),
            Ok(())
        );
        let huge = nalgebra::Matrix3::new(1e308, 1e308, 0.0, 1e308, 1e308, 0.0, 0.0, 0.0, 1.0);
        assert_eq!(
            ensure_semidefinite_noise(&huge, &mut nalgebra::Matrix3::zeros(), stage, q),
            Ok(())
        );
        // A A ᵀ of rank 2 with columns of very different scales (found by a random search):
        // round-off in the unpivoted L D Lᵀ leaves a non-vanishing zero-variance column, so
        // tier 2 fails it and the pivoted factorisation (tier 3) accepts it.
        let singular = DMatrix::<f64>::from_column_slice(
            3,
            3,
            &[
                916.5783855043492,
                -641611.052442303,
                -0.7516908505295964,
                -641611.052442303,
                449132098.4113805,
                0.1123807364296523,
                -0.7516908505295964,
                0.1123807364296523,
                8176.54452238597,
            ],
        );
        let lambda = singular.clone().symmetric_eigenvalues();
        assert!(lambda.min().abs() < 1e-6 * lambda.max(), "{lambda}");
        let max_diag = 449132098.4113805;
        assert!(!semidefinite_ldl(
            &singular,
            &mut singular.clone(),
            max_diag
        ));
        assert_eq!(
            ensure_semidefinite_noise(&singular, &mut singular.clone(), stage, q),
            Ok(())
        );
        // Non-finite entries are left to the finiteness checks.
        let nan = DMatrix::from_row_slice(2, 2, &[1.0, f64::NAN, f64::NAN, 1.0]);
        assert_eq!(
            ensure_semidefinite_noise(&nan, &mut nan.clone(), stage, q),
            Ok(())
        );
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
