//! Exact discretisation of continuous-time noise: closed forms for integrator chains and Van
//! Loan's method for any linear time-invariant system.
//!
//! A continuous-time linear system ẋ = F x + G w, with w white of power spectral density
//! Q_c (E[w(t) w(s)ᵀ] = Q_c δ(t − s)), sampled Δt apart, is exactly the discrete system
//!
//! ```text
//! x⁺ = Φ x + w_d,   Φ = e^{F Δt},   w_d ~ N(0, Q_d),   Q_d = ∫₀^Δt e^{F s} G Q_c Gᵀ e^{Fᵀ s} ds.
//! ```
//!
//! No step size enters but Δt itself: irregular steps are exact, one Q_d per step.
//!
//! - [`continuous_white_noise`]: Q_d in closed form for a chain of K integrators (position,
//!   velocity, …) driven by white noise on the K-th derivative (FilterPy's
//!   `Q_continuous_white_noise`, any K ≥ 1: random walk, CV, CA, jerk, …).
//! - [`discrete_white_noise`]: FilterPy's `Q_discrete_white_noise` (K = 2, 3, 4), the
//!   *piecewise-constant* noise model: not a discretisation of continuous noise, but the
//!   common textbook alternative (Bar-Shalom's DWNA / DWPA).
//! - [`van_loan`]: Φ and Q_d for any (F, G, Q_c), by one matrix exponential of the 2n × 2n
//!   block matrix (Van Loan 1978):
//!
//! ```text
//! M = [ −F   G Q_c Gᵀ ] Δt,   e^M = [ ·   Φ⁻¹ Q_d ],   so Φ = (e^M)₂₂ᵀ,  Q_d = Φ (e^M)₁₂.
//!     [  0   Fᵀ       ]             [ 0   Φᵀ      ]
//! ```
//!
//! The exponential is nalgebra's `Matrix::exp` (scaling and squaring with a Padé
//! approximant), computed on a runtime-sized 2n × 2n matrix whatever the sizes of F and G; it
//! needs the `std` feature (the closed forms do not).

use estim_core::nalgebra::SMatrix;
use estim_core::scalar::real;
use estim_core::{Error, Parameter, Quantity, Real, Stage};
// What van_loan's runtime-sized matrix needs.
#[cfg(feature = "std")]
use estim_core::{
    Alloc,
    checks::all_finite,
    nalgebra::{DMatrix, DefaultAllocator, Dim, OMatrix},
};

/// k! as `T` (k ≤ 170 is exact enough for `f64`; the chains here use k ≤ 2K).
fn factorial<T: Real>(k: usize) -> T {
    (1..=k).fold(T::one(), |acc, i| acc * real::<T>(i as f64))
}

/// Rejects a step that is negative or not finite.
pub(crate) fn check_step<T: Real>(dt: T) -> Result<(), Error> {
    if dt.is_finite() && dt >= T::zero() {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            parameter: Parameter::TimeStep,
            value: nalgebra_to_f64(dt),
        })
    }
}

/// Rejects a noise intensity that is negative or not finite.
fn check_intensity<T: Real>(q: T) -> Result<(), Error> {
    let (stage, quantity) = (Stage::Construction, Quantity::ProcessNoise);
    if !q.is_finite() {
        Err(Error::NonFinite { stage, quantity })
    } else if q < T::zero() {
        Err(Error::NotPositiveSemiDefinite { stage, quantity })
    } else {
        Ok(())
    }
}

fn nalgebra_to_f64<T: Real>(x: T) -> f64 {
    // `RealField` has no lossless `to_f64`; `SupersetOf<f64>` gives the nearest f64.
    estim_core::nalgebra::try_convert::<T, f64>(x).unwrap_or(f64::NAN)
}

/// The unchecked closed form behind [`continuous_white_noise`] (the models call it with
/// their own step; the filters check the Q they return).
pub(crate) fn continuous_white_noise_unchecked<T: Real, const K: usize>(
    dt: T,
    psd: T,
) -> SMatrix<T, K, K> {
    SMatrix::from_fn(|i, j| {
        // p, r: how many integrations separate component i (j) from the driven derivative.
        let (p, r) = (K - 1 - i, K - 1 - j);
        let e = p + r + 1;
        psd * dt.powi(e as i32) / (factorial::<T>(p) * factorial::<T>(r) * real::<T>(e as f64))
    })
}

/// Q_d of a chain of K integrators (component 0 the position, component K − 1 the derivative
/// driven by continuous white noise of power spectral density `psd`), over a step Δt:
///
/// ```text
/// (Q_d)ᵢⱼ = q Δt^{p+r+1} / (p! r! (p + r + 1)),   p = K−1−i, r = K−1−j,
/// ```
///
/// exact for any Δt (the integral ∫₀^Δt of the chain's impulse responses s^p/p! · s^r/r!).
/// K = 1: a random walk, q Δt. K = 2: constant velocity, q [Δt³/3, Δt²/2; Δt²/2, Δt]
/// (white acceleration, q in m²/s³). K = 3: constant acceleration (white jerk). FilterPy's
/// `Q_continuous_white_noise(dim=K, dt, spectral_density=q)`, for any K.
///
/// # Errors
///
/// [`Error::InvalidParameter`] (`TimeStep`) for a negative or non-finite Δt;
/// [`Error::NonFinite`] / [`Error::NotPositiveSemiDefinite`] (process noise) for a
/// non-finite or negative q.
///
/// ```
/// use estim_models::motion::continuous_white_noise;
///
/// let q = continuous_white_noise::<f64, 2>(0.5, 2.0)?;
/// assert!((q[(0, 0)] - 2.0 * 0.5f64.powi(3) / 3.0).abs() < 1e-15);
/// assert!((q[(0, 1)] - 2.0 * 0.25 / 2.0).abs() < 1e-15);
/// assert_eq!(q[(1, 1)], 1.0);
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn continuous_white_noise<T: Real, const K: usize>(
    dt: T,
    psd: T,
) -> Result<SMatrix<T, K, K>, Error> {
    check_step(dt)?;
    check_intensity(psd)?;
    Ok(continuous_white_noise_unchecked(dt, psd))
}

/// The unchecked form behind [`discrete_white_noise`].
pub(crate) fn discrete_white_noise_unchecked<T: Real, const K: usize>(
    dt: T,
    variance: T,
) -> SMatrix<T, K, K> {
    const {
        assert!(
            K >= 2 && K <= 4,
            "discrete_white_noise: K must be 2, 3 or 4"
        )
    };
    // Γ: how one step's noise sample enters each component.
    let gamma = SMatrix::<T, K, 1>::from_fn(|i, _| {
        let power = if K == 2 { K - i } else { K - 1 - i };
        dt.powi(power as i32) / factorial::<T>(power)
    });
    gamma * gamma.transpose() * variance
}

/// FilterPy's `Q_discrete_white_noise(dim=K, dt, var)`: Q = Γ Γᵀ σ², the noise of a
/// K-component chain whose driving noise is constant over each step (piecewise-constant
/// white noise), with
///
/// ```text
/// K = 2:  Γ = (Δt²/2, Δt)               σ² the acceleration's variance (DWNA)
/// K = 3:  Γ = (Δt²/2, Δt, 1)            σ² the variance of the acceleration's increment (DWPA)
/// K = 4:  Γ = (Δt³/6, Δt²/2, Δt, 1)     σ² the variance of the jerk's increment
/// ```
///
/// Rank one: the components move together. Prefer [`continuous_white_noise`] when steps are
/// irregular (its intensity does not depend on the step); this form is here to match FilterPy
/// and textbook examples. Other K do not compile.
///
/// # Errors
///
/// As [`continuous_white_noise`], with `variance` for the intensity.
///
/// ```
/// use estim_models::motion::discrete_white_noise;
///
/// let q = discrete_white_noise::<f64, 2>(0.1, 3.0)?;
/// // FilterPy: [[.25 dt⁴, .5 dt³], [.5 dt³, dt²]] · var
/// assert!((q[(0, 0)] - 0.25e-4 * 3.0).abs() < 1e-18);
/// assert!((q[(0, 1)] - 0.5e-3 * 3.0).abs() < 1e-17);
/// assert!((q[(1, 1)] - 1e-2 * 3.0).abs() < 1e-16);
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn discrete_white_noise<T: Real, const K: usize>(
    dt: T,
    variance: T,
) -> Result<SMatrix<T, K, K>, Error> {
    check_step(dt)?;
    check_intensity(variance)?;
    Ok(discrete_white_noise_unchecked(dt, variance))
}

/// Φ = e^{FΔt} and Q_d = ∫₀^Δt e^{Fs} G Q_c Gᵀ e^{Fᵀs} ds for the continuous system
/// ẋ = F x + G w, E[w(t) w(s)ᵀ] = Q_c δ(t − s), by Van Loan's method (1978), one matrix
/// exponential of a 2n × 2n block matrix:
///
/// ```text
/// M = [ −F   G Q_c Gᵀ ] Δt,   e^M = [ ·   Φ⁻¹ Q_d ],   so Φ = (e^M)₂₂ᵀ,  Q_d = Φ (e^M)₁₂.
///     [  0   Fᵀ       ]             [ 0   Φᵀ      ]
/// ```
///
/// Q_d is returned symmetrised, (Q + Qᵀ)/2. The exponential is nalgebra's `Matrix::exp`
/// (scaling and squaring with a Padé approximant).
///
/// Works for any sizes, static or runtime: the 2n × 2n exponential is computed on a
/// runtime-sized matrix (one allocation per call). For a time-invariant system with a fixed
/// step, call it once and keep the result.
///
/// # Errors
///
/// - [`Error::InvalidParameter`] (`TimeStep`) for a negative or non-finite Δt;
/// - [`Error::DimensionMismatch`] when F is not square, G has not n rows or Q_c is not square
///   with G's column count (runtime sizes only);
/// - [`Error::NonFinite`] for a non-finite F (`Jacobian`), G or Q_c (`ProcessNoise`), or a
///   result that overflowed.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix2, Vector2};
/// use estim_models::motion::{continuous_white_noise, van_loan};
///
/// // Constant velocity: F = [0 1; 0 0], G = (0, 1), Q_c = q.
/// let f = Matrix2::new(0.0, 1.0, 0.0, 0.0);
/// let g = Vector2::new(0.0, 1.0);
/// let (phi, q) = van_loan(&f, &g, &Matrix1::new(0.7), 0.3)?;
/// assert!((phi - Matrix2::new(1.0, 0.3, 0.0, 1.0)).amax() < 1e-15);
/// assert!((q - continuous_white_noise::<f64, 2>(0.3, 0.7)?).amax() < 1e-15);
/// # Ok::<(), estim_core::Error>(())
/// ```
// (Φ, Q_d) reads as the math does; a named pair type would only rename it.
#[allow(clippy::type_complexity)]
#[cfg(feature = "std")]
pub fn van_loan<T: Real, N: Dim, W: Dim>(
    f: &OMatrix<T, N, N>,
    g: &OMatrix<T, N, W>,
    qc: &OMatrix<T, W, W>,
    dt: T,
) -> Result<(OMatrix<T, N, N>, OMatrix<T, N, N>), Error>
where
    DefaultAllocator: Alloc<N, W>,
{
    check_step(dt)?;
    let n = f.nrows();
    if f.ncols() != n {
        return Err(Error::DimensionMismatch {
            stage: Stage::Construction,
            quantity: Quantity::Jacobian,
            expected_rows: n,
            expected_cols: n,
            found_rows: n,
            found_cols: f.ncols(),
        });
    }
    let w = g.ncols();
    if g.nrows() != n || qc.nrows() != w || qc.ncols() != w {
        let (rows, cols) = if g.nrows() != n {
            (g.nrows(), g.ncols())
        } else {
            (qc.nrows(), qc.ncols())
        };
        return Err(Error::DimensionMismatch {
            stage: Stage::Construction,
            quantity: Quantity::ProcessNoise,
            expected_rows: if g.nrows() != n { n } else { w },
            expected_cols: w,
            found_rows: rows,
            found_cols: cols,
        });
    }
    let stage = Stage::Construction;
    let finite = |ok: bool, quantity| {
        if ok {
            Ok(())
        } else {
            Err(Error::NonFinite { stage, quantity })
        }
    };
    finite(f.iter().all(|v| v.is_finite()), Quantity::Jacobian)?;
    finite(
        g.iter().chain(qc.iter()).all(|v| v.is_finite()),
        Quantity::ProcessNoise,
    )?;
    let gqg = g * qc * g.transpose();
    let mut m = DMatrix::<T>::zeros(2 * n, 2 * n);
    for i in 0..n {
        for j in 0..n {
            m[(i, j)] = -f[(i, j)] * dt;
            m[(i, n + j)] = gqg[(i, j)] * dt;
            m[(n + i, n + j)] = f[(j, i)] * dt;
        }
    }
    let e = exp_scaled(m).ok_or(Error::NonFinite {
        stage,
        quantity: Quantity::ProcessNoise,
    })?;
    let shape = f.shape_generic();
    let phi = OMatrix::<T, N, N>::from_fn_generic(shape.0, shape.1, |i, j| e[(n + j, n + i)]);
    let upper = OMatrix::<T, N, N>::from_fn_generic(shape.0, shape.1, |i, j| e[(i, n + j)]);
    let q = &phi * upper;
    let half: T = real(0.5);
    let q = (&q + q.transpose()) * half;
    finite(all_finite(&phi) && all_finite(&q), Quantity::ProcessNoise)?;
    Ok((phi, q))
}

/// e^M by nalgebra's `exp` after scaling M down to ‖M‖₁ ≤ B = (largest `T`)^(1/16), then
/// squaring back; `None` when M is not finite or ‖M‖₁ overflows. nalgebra chooses its own
/// scaling from ‖Mᵏ‖₁^(1/k) for k up to 10: when M⁸ overflows but M⁶ does not, it would square
/// 2⁶⁴ times (f32 with |F Δt| from 7·10⁴ to 3·10⁶, f64 from 3·10³⁸). Below B (2⁸ for f32,
/// 2⁶⁴ for f64) nothing changes; halving is exact, so the result is nalgebra's e^(M/2ˢ) squared
/// s times.
#[cfg(feature = "std")]
fn exp_scaled<T: Real>(mut m: DMatrix<T>) -> Option<DMatrix<T>> {
    let bound = T::max_value()?.powf(real(1.0 / 16.0));
    let mut norm = m
        .column_iter()
        .map(|c| c.iter().fold(T::zero(), |s, v| s + v.abs()))
        .fold(T::zero(), |a, b| if b > a { b } else { a });
    if !norm.is_finite() || m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let half: T = real(0.5);
    let mut squarings = 0;
    while norm > bound {
        m *= half;
        norm *= half;
        squarings += 1;
    }
    let mut e = m.exp();
    for _ in 0..squarings {
        e = &e * &e;
    }
    Some(e)
}
