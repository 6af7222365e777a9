//! Internal, not public API (hidden from the docs; the estim crates use it): the positive
//! semi-definite factor of a covariance ([`psd_factor`], public as `estim_core::psd_factor`),
//! the quadratic form through it, and the symmetrising passes of the filter steps. The checks
//! (finite, shape, symmetric, semi-definite) and `symmetrize` are the public module
//! [`checks`](crate::checks), which builds on this one.
//!
//! All of them work in place or on the stack for static sizes: none allocates unless the
//! matrix type itself lives on the heap (`Dyn`).

use nalgebra::{
    DefaultAllocator, Dim, Matrix, OMatrix, OVector, StorageMut, U1, allocator::Allocator,
};

use crate::error::{Error, Quantity, Result, Stage};
use crate::kernel::{CholeskyScratch, cholesky_in_place, copy};
use crate::scalar::{Real, real};

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
pub(crate) fn tolerance_for<T: Real>(n: usize, max_diag: T) -> T {
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

/// [`psd_factor`] into `out`, bit for bit: the same unpivoted factorisation (with its
/// zero-pivot tolerance) in `out`, so a positive definite C, or a semi-definite one whose zero
/// directions come without covariances, allocates nothing; only a C that needs pivoting takes
/// [`psd_factor`]'s pivoted route (which allocates for runtime sizes). The square-root
/// filters' noise factors.
///
/// ```
/// use estim_core::{psd_factor, Stage};
/// use estim_core::linalg::psd_factor_exact_into;
/// use estim_core::nalgebra::Matrix2;
///
/// let c = Matrix2::new(4.0, 2.0, 2.0, 2.0);
/// let mut s = Matrix2::zeros();
/// psd_factor_exact_into(&c, &mut s, Stage::Propagation)?;
/// assert_eq!(s, psd_factor(&c, Stage::Propagation)?); // the same bits
/// assert!(psd_factor_exact_into(&Matrix2::new(1.0, 2.0, 2.0, 1.0), &mut s, Stage::Propagation).is_err());
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn psd_factor_exact_into<T: Real, D: Dim>(
    c: &OMatrix<T, D, D>,
    out: &mut OMatrix<T, D, D>,
    stage: Stage,
) -> Result<()>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    if out.shape() == c.shape() {
        copy(out, c);
        if lower_factor_in_place(out, zero_pivot_bounds(c), None).is_ok() {
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
#[cfg_attr(not(debug_assertions), inline(always))]
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
#[cfg_attr(not(debug_assertions), inline(always))]
pub fn mirror_lower_checked<T: Real, D: Dim>(m: &mut OMatrix<T, D, D>) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    symmetric_map(n, m.as_mut_slice(), [], |lower, [], _, []| lower)
}

/// m ← ((m + a) + (m + a)ᵀ)/2 in one pass (the same arithmetic as `m += a` then
/// [`symmetrize`](crate::checks::symmetrize)); true if the result is finite.
#[cfg_attr(not(debug_assertions), inline(always))]
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
#[cfg_attr(not(debug_assertions), inline(always))]
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::checks::ensure_psd;
    use nalgebra::DMatrix;

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
}
