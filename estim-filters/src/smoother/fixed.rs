//! The smoother gain when the predicted covariance has fixed (zero-variance) states: the
//! Moore–Penrose form G = C (P⁻)⁺ (module docs of [`super`], "Fixed states").

use estim_core::nalgebra::{DMatrix, DefaultAllocator, Dim, Dyn, OMatrix};
use estim_core::{Alloc, Real};

/// Writes G = C (P⁻)⁺ into `gain`, where P⁻ = `predicted` is positive definite once the states
/// of zero predicted variance are set aside; their columns of G are zero. Returns the state
/// index at which the factorisation broke down otherwise (a negative or NaN variance, or a
/// singular block of states that are not fixed). Allocates (the reduced problem): it runs
/// only when the plain factorisation failed.
pub(super) fn gain<T: Real, N: Dim>(
    predicted: &OMatrix<T, N, N>,
    cross: &OMatrix<T, N, N>,
    gain: &mut OMatrix<T, N, N>,
) -> Result<(), usize>
where
    DefaultAllocator: Alloc<N>,
{
    let n = predicted.nrows();
    let scale = (0..n)
        .map(|i| predicted[(i, i)])
        .fold(T::zero(), |m, v| if v > m { v } else { m });
    let tolerance = scale * T::default_epsilon() * estim_core::nalgebra::convert(n as f64);
    let mut free = Vec::with_capacity(n);
    for i in 0..n {
        let v = predicted[(i, i)];
        if !(v >= -tolerance) {
            return Err(i); // negative or NaN: not a fixed state
        }
        if v > tolerance {
            free.push(i);
        }
    }
    let k = free.len();
    let pivot_margin: T = estim_core::nalgebra::convert(16.0);
    // The Cholesky factor of P⁻ on the free states, column by column, to name the state
    // where it breaks down.
    let mut l = DMatrix::<T>::zeros(k, k);
    for j in 0..k {
        let mut d = predicted[(free[j], free[j])];
        for p in 0..j {
            d -= l[(j, p)] * l[(j, p)];
        }
        // A pivot within round-off of the factorisation (a few ε per term, n terms, relative
        // to the largest variance) is singular: the plain factorisation already failed.
        if !(d > tolerance * pivot_margin) {
            return Err(free[j]);
        }
        l[(j, j)] = d.sqrt();
        for i in (j + 1)..k {
            let mut s = predicted[(free[i], free[j])];
            for p in 0..j {
                s -= l[(i, p)] * l[(j, p)];
            }
            l[(i, j)] = s / l[(j, j)];
        }
    }
    // Gᵀ on the free columns = A⁻¹ C_Fᵀ (A = P⁻ on the free states, symmetric).
    let mut rhs = DMatrix::<T>::from_fn(k, n, |j, r| cross[(r, free[j])]);
    let factor = estim_core::nalgebra::Cholesky::<T, Dyn>::pack_dirty(l);
    factor.solve_mut(&mut rhs);
    gain.fill(T::zero());
    for (j, &c) in free.iter().enumerate() {
        for r in 0..n {
            gain[(r, c)] = rhs[(j, r)];
        }
    }
    Ok(())
}
