//! The independent weighted least squares the lv2 tests compare against.

use estim_core::nalgebra::{DMatrix, DVector};

/// WLS by Householder QR of the whitened system, with no normal equations: with
/// A = R^{-1/2} H = Q U (U upper triangular), θ̂ = U⁻¹ Qᵀ R^{-1/2} z and P = U⁻¹ U⁻ᵀ;
/// χ² = |R^{-1/2}(z − H θ̂)|². Its round-off grows like cond(A) = √cond(HᵀR⁻¹H), so it is
/// the more accurate of the two routes whenever they disagree.
///
/// Returns (θ̂, P, χ²). Panics if H is rank deficient (the tests only call it on full-rank H).
pub fn qr_wls(h: &DMatrix<f64>, sigmas: &[f64], z: &[f64]) -> (DVector<f64>, DMatrix<f64>, f64) {
    let m = h.nrows();
    let n = h.ncols();
    let a = DMatrix::from_fn(m, n, |r, c| h[(r, c)] / sigmas[r]);
    let b = DVector::from_fn(m, |r, _| z[r] / sigmas[r]);
    let qr = a.clone().qr();
    let (q, u) = (qr.q(), qr.r());
    let est = u
        .solve_upper_triangular(&(q.transpose() * &b))
        .expect("full rank");
    let u_inv = u
        .solve_upper_triangular(&DMatrix::identity(n, n))
        .expect("full rank");
    let p = &u_inv * u_inv.transpose();
    let r = &b - &a * &est;
    (est, p, r.norm_squared())
}
