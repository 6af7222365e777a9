//! The scaled unscented transform.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use super::{MomentPropagator, Moments, finish};
use crate::alloc::Alloc;
use crate::error::{Error, Parameter, Quantity, Result, Stage};
use crate::function::VectorFunction;
use crate::linalg::{ensure_shape, psd_factor};
use crate::scalar::{Real, real};

/// The scaled unscented transform (Julier 2002; Wan & van der Merwe 2000).
///
/// With c = α²(n + κ) and L Lᵀ = C, the 2n + 1 sigma points are χ₀ = μ and
/// χ±ⱼ = μ ± √c Lⱼ (Lⱼ the j-th column of L), with weights w = 1/(2c) for χ±ⱼ. Writing
/// dᵢ = g(χᵢ) ⊖ g(μ) (so d₀ = 0) and d̄ = w Σᵢ dᵢ:
///
/// ```text
/// ȳ        = g(μ) + d̄
/// cov(y)   = w Σᵢ dᵢ dᵢᵀ + (β − α²) d̄ d̄ᵀ
/// cov(x,y) = w Σᵢ (χᵢ − μ) dᵢᵀ
/// ```
///
/// This is algebraically the textbook form with W₀ᵐ = 1 − n/c and W₀ᶜ = W₀ᵐ + 1 − α² + β, but it
/// never multiplies by the centre weight (≈ −10⁶ for α = 10⁻³), so the covariance keeps full
/// precision for small α. The mean cannot: it is g(μ) plus w Σᵢ dᵢ, and the round-off ε‖y‖ in
/// each function value is multiplied by nw = 1/(2α²), so the mean carries an error of about
/// ε‖y‖/α² (any formulation does). In `f64` with α = 10⁻³ that is ≈ 10⁻¹⁰ ‖y‖; in `f32` it is of
/// the order of ‖y‖ itself, so with `f32` use α ≳ 0.3 or [`Unscented::cubature`].
/// Deviations go through the function's [`difference`](VectorFunction::difference), so
/// wrapped outputs (angles) are handled. The factor L is a semi-definite square root
/// ([`psd_factor`]), so directions with zero variance are allowed. Each sigma point is built,
/// evaluated and accumulated on the fly: for static sizes nothing is allocated.
///
/// Requirements on g: [`VectorFunction`] only.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unscented<T> {
    alpha: T,
    beta: T,
    kappa: T,
}

impl<T: Real> Unscented<T> {
    /// The scaled transform with spread α > 0, prior-knowledge weight β and secondary scaling
    /// κ, all finite. (n + κ > 0 is checked when the dimension n is known, at propagation.)
    pub fn new(alpha: T, beta: T, kappa: T) -> Result<Self> {
        let invalid = |parameter, value: T| Error::InvalidParameter {
            parameter,
            value: nalgebra::try_convert::<T, f64>(value).unwrap_or(f64::NAN),
        };
        if !(alpha.is_finite() && alpha > T::zero()) {
            return Err(invalid(Parameter::UnscentedAlpha, alpha));
        }
        if !beta.is_finite() {
            return Err(invalid(Parameter::UnscentedBeta, beta));
        }
        if !kappa.is_finite() {
            return Err(invalid(Parameter::UnscentedKappa, kappa));
        }
        Ok(Self { alpha, beta, kappa })
    }

    /// The classic Julier–Uhlmann (1997) set: α = 1, β = 0, centre weight κ/(n + κ).
    /// κ = 3 − n matches the fourth moment of a Gaussian in each direction.
    pub fn julier(kappa: T) -> Result<Self> {
        Self::new(T::one(), T::zero(), kappa)
    }

    /// The third-degree spherical–radial cubature rule (Arasaratnam & Haykin 2009):
    /// α = 1, β = 0, κ = 0, i.e. 2n equally weighted points at μ ± √n Lⱼ.
    pub fn cubature() -> Self {
        Self {
            alpha: T::one(),
            beta: T::zero(),
            kappa: T::zero(),
        }
    }

    /// α.
    pub fn alpha(&self) -> T {
        self.alpha
    }

    /// β.
    pub fn beta(&self) -> T {
        self.beta
    }

    /// κ.
    pub fn kappa(&self) -> T {
        self.kappa
    }
}

impl<T: Real> Default for Unscented<T> {
    /// α = 10⁻³, β = 2, κ = 0 (Wan & van der Merwe's recommendation for Gaussian priors).
    fn default() -> Self {
        Self {
            alpha: real(1e-3),
            beta: real(2.0),
            kappa: T::zero(),
        }
    }
}

impl<T: Real> Unscented<T> {
    /// The transform; the cross-covariance is accumulated only when `CROSS` (zero otherwise).
    #[inline(always)]
    fn transform<N, M, G, const CROSS: bool>(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<Moments<T, N, M>>
    where
        N: Dim,
        M: Dim,
        G: VectorFunction<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        let n = mean.nrows();
        ensure_shape(covariance, n, n, Stage::Propagation, Quantity::Covariance)?;
        let c = self.alpha * self.alpha * (real::<T>(n as f64) + self.kappa);
        if !(c > T::zero()) {
            return Err(Error::InvalidParameter {
                parameter: Parameter::UnscentedKappa,
                value: nalgebra::try_convert::<T, f64>(self.kappa).unwrap_or(f64::NAN),
            });
        }
        let mut l = psd_factor(covariance, Stage::Propagation)?;
        l *= c.sqrt();

        let y0 = g.eval(mean);
        let m = y0.nrows();
        let (n_dim, m_dim) = (mean.shape_generic().0, y0.shape_generic().0);
        let mut sum_d = OVector::<T, M>::zeros_generic(m_dim, nalgebra::U1);
        let mut sum_dd = OMatrix::<T, M, M>::zeros_generic(m_dim, m_dim);
        let mut sum_xd = OMatrix::<T, N, M>::zeros_generic(n_dim, m_dim);
        let mut x = mean.clone();
        for j in 0..n {
            for sign in [T::one(), -T::one()] {
                let dx = l.column(j) * sign;
                x.copy_from(mean);
                x += &dx;
                let y = g.eval(&x);
                ensure_shape(&y, m, 1, Stage::Propagation, Quantity::FunctionValue)?;
                let d = g.difference(&y, &y0);
                ensure_shape(&d, m, 1, Stage::Propagation, Quantity::FunctionValue)?;
                sum_d += &d;
                // Operator forms: for small static sizes they unroll, where nalgebra's generic
                // `ger` loops column by column (measured: the filters bench).
                sum_dd += &d * d.transpose();
                if CROSS {
                    sum_xd += &dx * d.transpose();
                }
            }
        }
        let w = T::one() / (real::<T>(2.0) * c);
        let d_bar = sum_d * w;
        let mut covariance_y = sum_dd * w;
        covariance_y.ger(
            self.beta - self.alpha * self.alpha,
            &d_bar,
            &d_bar,
            T::one(),
        );
        finish(Moments {
            mean: y0 + d_bar,
            covariance: covariance_y,
            cross_covariance: sum_xd * w,
        })
    }
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Unscented<T>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    #[inline(always)]
    fn propagate(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<Moments<T, N, M>> {
        self.transform::<N, M, G, true>(mean, covariance, g)
    }

    #[inline(always)]
    fn propagate_mean_covariance(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
    ) -> Result<super::MeanCovariance<T, M>> {
        self.transform::<N, M, G, false>(mean, covariance, g)
            .map(|m| (m.mean, m.covariance))
    }
}
