//! The scaled unscented transform.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};

use super::workspace::buffer;
use super::{MomentPropagator, Outputs, PropagatorWorkspace, check_inputs};
use crate::alloc::Alloc;
use crate::checks::ensure_shape;
use crate::error::{Error, Parameter, Quantity, Result, Stage};
use crate::function::VectorFunction;
use crate::function::eval_into;
use crate::kernel::{self, Accum, CholeskyScratch, mul_tr, mul_tr_lower};
use crate::linalg::psd_factor_into;
use crate::scalar::{Real, real};

/// The scaled unscented transform (Julier 2002; Wan & van der Merwe 2000).
///
/// With c = α²(n + κ) and L Lᵀ = C, the 2n + 1 sigma points are χ₀ = μ and
/// χ±ⱼ = μ ⊞ ±√c Lⱼ (Lⱼ the j-th column of L), with weights w = 1/(2c) for χ±ⱼ. Writing
/// dᵢ = g(χᵢ) ⊖ g(μ) (so d₀ = 0) and d̄ = w Σᵢ dᵢ:
///
/// ```text
/// ȳ        = g(μ) ⊞ d̄
/// cov(y)   = w Σᵢ dᵢ dᵢᵀ + (β − α²) d̄ d̄ᵀ
/// cov(x,y) = w Σᵢ (χᵢ ⊟ μ) dᵢᵀ,   χ±ⱼ ⊟ μ = ±√c Lⱼ
/// ```
///
/// ⊞ in the input is the function's [`input_plus_into`](VectorFunction::input_plus_into), in the
/// output its [`output_plus_into`](VectorFunction::output_plus_into), ⊖ its
/// [`difference_into`](VectorFunction::difference_into) (Hertzberg et al. 2013); by default +, +
/// and −, and then this is the plain transform to the bit.
///
/// This is algebraically the textbook form with W₀ᵐ = 1 − n/c and W₀ᶜ = W₀ᵐ + 1 − α² + β, but it
/// never multiplies by the centre weight (≈ −10⁶ for α = 10⁻³), so the covariance keeps full
/// precision for small α. The mean cannot: it is g(μ) plus w Σᵢ dᵢ, and the round-off ε‖y‖ in
/// each function value is multiplied by nw = 1/(2α²), so the mean carries an error of about
/// ε‖y‖/α² (any formulation does). In `f64` with α = 10⁻³ that is ≈ 10⁻¹⁰ ‖y‖; in `f32` it is of
/// the order of ‖y‖ itself, so with `f32` use α ≳ 0.3 (the `f32` [`Default`] takes 0.5) or
/// [`Unscented::cubature`].
/// Deviations go through the function's [`difference_into`](VectorFunction::difference_into), so
/// wrapped outputs (angles) are handled. The factor L is a semi-definite square root
/// ([`psd_factor`](crate::linalg::psd_factor); for runtime sizes a plain Cholesky factor first), so directions with zero variance
/// are allowed. The deviations are collected as the columns of two m × n matrices and the sums
/// are matrix products (faer for runtime sizes); all buffers live in the caller's
/// [`UnscentedWorkspace`], so nothing is allocated for static sizes, nor for runtime sizes after the
/// first call.
///
/// Requirements on g: [`VectorFunction`] only.
///
/// # Accepted parameters
///
/// Exactly those for which cov(y) as computed above is positive semi-definite for *every*
/// function g (so a prediction never makes P⁻ indefinite, whatever the model): with the
/// deviations as the columns of D (m × 2n) and 𝟙 the vector of 2n ones, d̄ = w D 𝟙 and
///
/// ```text
/// cov(y) = D A Dᵀ,   A = w I + (β − α²) w² 𝟙 𝟙ᵀ,
/// ```
///
/// whose eigenvalues are w (2n − 1 times, > 0) and w (1 + 2n (β − α²) w) along 𝟙. A
/// function can make D any matrix (g is evaluated at 2n distinct points), e.g. D = d 𝟙ᵀ for
/// a g that is even about μ, so cov(y) is PSD for every g if and only if
/// 1 + 2n (β − α²) w ≥ 0, i.e. (with w = 1/(2c), c = α²(n + κ) > 0)
///
/// ```text
/// c + n (β − α²) ≥ 0   ⟺   α² κ + n β ≥ 0     (and n + κ > 0).
/// ```
///
/// The textbook condition, a non-negative centre weight W₀ᶜ = 1 − n/c + 1 − α² + β, is
/// stricter: this form never multiplies by W₀ᶜ and is PSD whenever the centre-and-mean
/// combination along 𝟙 is, so the Wan–van der Merwe default (α = 10⁻³, β = 2, κ = 0:
/// W₀ᶜ ≈ −10⁶, α²κ + nβ = 2n) is accepted, and so are α up to 10³ with κ = 10⁶. Refused:
/// β = 0 with κ < 0 (the classic Julier κ = 3 − n for n > 3), and a negative β unless
/// α²κ ≥ n|β|. The cross-covariance adds nothing: the joint deviations (χᵢ ⊟ μ, dᵢ) have the
/// same A and the χ deviations sum to zero, so the joint covariance of (x, y) is PSD too, and
/// so is the Kalman posterior built from it. Round-off can still leave eigenvalues of order
/// ε‖cov(y)‖ below zero at the boundary itself (A singular), as for any computed covariance.
///
/// [`Unscented::new`] refuses sets outside the region for every n; the rest is checked in
/// O(1) when n is known ([`check_dimension`](Self::check_dimension), run first by every
/// propagation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unscented<T> {
    alpha: T,
    beta: T,
    kappa: T,
}

impl<T: Real> Unscented<T> {
    /// The scaled transform with spread α > 0, prior-knowledge weight β and secondary scaling
    /// κ, all finite, refused if no state dimension n ≥ 1 is in the [accepted
    /// region](Self#accepted-parameters): β = 0 with κ < 0 ([`Parameter::UnscentedKappa`]), or
    /// β < 0 with α²κ < −β ([`Parameter::UnscentedBeta`]). The conditions that depend on n
    /// are checked at propagation, when n is known, or ahead of time with
    /// [`check_dimension`](Self::check_dimension).
    ///
    /// ```
    /// use estim_core::{Error, Parameter, propagate::Unscented};
    /// assert!(Unscented::new(1e-3, 2.0, 0.0).is_ok());
    /// // A negative β with α²κ + nβ < 0 for every n ≥ 1: refused.
    /// assert!(matches!(
    ///     Unscented::new(1e-3, -1.0, 0.0),
    ///     Err(Error::InvalidParameter { parameter: Parameter::UnscentedBeta, .. })
    /// ));
    /// # Ok::<(), Error>(())
    /// ```
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
        // Some n ≥ 1 must have α²κ + nβ ≥ 0: any n for β > 0 (take n large), κ ≥ 0 for β = 0,
        // and α²κ + β ≥ 0 (n = 1 is the best) for β < 0.
        let a2k = alpha * alpha * kappa;
        if beta == T::zero() && kappa < T::zero() {
            return Err(invalid(Parameter::UnscentedKappa, kappa));
        }
        if beta < T::zero() && a2k + beta < T::zero() {
            return Err(invalid(Parameter::UnscentedBeta, beta));
        }
        Ok(Self { alpha, beta, kappa })
    }

    /// `Ok(())` if the parameters are in the [accepted region](Self#accepted-parameters) for
    /// an `n`-dimensional input, O(1): c = α²(n + κ) > 0 ([`Parameter::UnscentedKappa`]
    /// otherwise) and α²κ + nβ ≥ 0 (otherwise [`Parameter::UnscentedBeta`] if β < 0, else
    /// [`Parameter::UnscentedKappa`]). Every propagation runs it first, so a failing step
    /// changes nothing.
    ///
    /// ```
    /// use estim_core::{Error, Parameter, propagate::Unscented};
    /// // α = 1, β = 1, κ = −3: fine for n ≥ 3 (α²κ + nβ = n − 3 ≥ 0 and n + κ > 0 for n > 3).
    /// let ut = Unscented::new(1.0, 1.0, -3.0)?;
    /// assert!(ut.check_dimension(4).is_ok() && ut.check_dimension(30).is_ok());
    /// assert!(matches!(
    ///     ut.check_dimension(3),
    ///     Err(Error::InvalidParameter { parameter: Parameter::UnscentedKappa, .. })
    /// ));
    /// # Ok::<(), Error>(())
    /// ```
    pub fn check_dimension(&self, n: usize) -> Result<()> {
        let (alpha, beta, kappa) = (self.alpha, self.beta, self.kappa);
        let n = real::<T>(n as f64);
        let invalid = |parameter, value: T| Error::InvalidParameter {
            parameter,
            value: nalgebra::try_convert::<T, f64>(value).unwrap_or(f64::NAN),
        };
        let a2 = alpha * alpha;
        if !(a2 * (n + kappa) > T::zero()) {
            return Err(invalid(Parameter::UnscentedKappa, kappa));
        }
        if !(a2 * kappa + n * beta >= T::zero()) {
            return Err(if beta < T::zero() {
                invalid(Parameter::UnscentedBeta, beta)
            } else {
                invalid(Parameter::UnscentedKappa, kappa)
            });
        }
        Ok(())
    }

    /// The classic Julier–Uhlmann (1997) set: α = 1, β = 0, centre weight κ/(n + κ), for
    /// κ ≥ 0 ([`Parameter::UnscentedKappa`] otherwise). κ = 3 − n matches the fourth moment of
    /// a Gaussian in each direction, but for n > 3 that κ is negative, and with β = 0 a
    /// negative κ makes the covariance indefinite for some functions (see the [accepted
    /// region](Self#accepted-parameters)); `Unscented::new(1.0, β, 3 − n)` with
    /// β ≥ (n − 3)/n is the nearest accepted set.
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
    /// β = 2, κ = 0 and α = 10⁻³ (Wan & van der Merwe's recommendation for Gaussian priors)
    /// in `f64`. In a scalar with less than 10 significant digits (`f32`), α = 0.5: the mean's
    /// round-off grows as ε/α² (type docs), which for α = 10⁻³ in `f32` is of the order of
    /// the mean itself, for α = 0.5 about 4 ε.
    ///
    /// ```
    /// use estim_core::propagate::Unscented;
    /// assert_eq!(Unscented::<f64>::default().alpha(), 1e-3);
    /// assert_eq!(Unscented::<f32>::default().alpha(), 0.5);
    /// ```
    fn default() -> Self {
        let low_precision = T::default_epsilon() > real(1e-10);
        Self {
            alpha: real(if low_precision { 0.5 } else { 1e-3 }),
            beta: real(2.0),
            kappa: T::zero(),
        }
    }
}

/// [`Unscented`]'s buffers: the scaled factor √c L, the deviations D₊ and D₋, their mean, and
/// the sigma-point buffers ([`SigmaDeviations`]).
#[derive(Debug)]
pub struct UnscentedWorkspace<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    factor: Option<OMatrix<T, N, N>>,
    cholesky: CholeskyScratch,
    mean_deviation: Option<OMatrix<T, M, U1>>,
    plus: Option<OMatrix<T, M, N>>,
    minus: Option<OMatrix<T, M, N>>,
    points: SigmaDeviations<T, N, M>,
}

impl<T: Real, N: Dim, M: Dim> Default for UnscentedWorkspace<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn default() -> Self {
        Self {
            factor: None,
            cholesky: CholeskyScratch::default(),
            mean_deviation: None,
            plus: None,
            minus: None,
            points: SigmaDeviations::default(),
        }
    }
}

/// The crate's one sigma-point generator: g at the 2n points χ±ⱼ = μ ⊞ ±Lⱼ of a scaled factor L
/// (√c times a square root of the covariance) and their deviations dᵢ = g(χᵢ) ⊖ g(μ), with the
/// tangent, point and value buffers it works in (sized on first use, so nothing is allocated
/// after the first call). [`Unscented`]'s propagation and the square-root UKF both use it.
///
/// ```
/// use estim_core::nalgebra::{Const, Matrix2, Matrix1x2, Vector1, Vector2};
/// use estim_core::{Stage, VectorFunction, propagate::SigmaDeviations};
///
/// struct Sum;
/// impl VectorFunction<f64, Const<2>, Const<1>> for Sum {
///     fn eval(&self, x: &Vector2<f64>) -> Vector1<f64> {
///         Vector1::new(x.sum())
///     }
/// }
/// let (mut plus, mut minus, mut value) = (Matrix1x2::zeros(), Matrix1x2::zeros(), Vector1::zeros());
/// let mut points = SigmaDeviations::default();
/// let mean = Vector2::new(1.0, 2.0);
/// points.deviations_into(&Sum, &mean, &Matrix2::identity(), &mut value, &mut plus, &mut minus, Stage::Propagation)?;
/// // g(μ) = 3; g(μ ± eⱼ) − g(μ) = ±1.
/// assert_eq!((value[0], plus, minus), (3.0, Matrix1x2::new(1.0, 1.0), Matrix1x2::new(-1.0, -1.0)));
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Debug)]
pub struct SigmaDeviations<T: Real, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    tangent: Option<OMatrix<T, N, U1>>,
    point: Option<OMatrix<T, N, U1>>,
    value: Option<OMatrix<T, M, U1>>,
    deviation: Option<OMatrix<T, M, U1>>,
}

impl<T: Real, N: Dim, M: Dim> Default for SigmaDeviations<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn default() -> Self {
        Self {
            tangent: None,
            point: None,
            value: None,
            deviation: None,
        }
    }
}

impl<T: Real, N: Dim, M: Dim> SigmaDeviations<T, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// g(μ) into `value`, D₊ = [g(μ ⊞ Lⱼ) ⊖ g(μ)]ⱼ into `plus` and D₋ = [g(μ ⊞ −Lⱼ) ⊖ g(μ)]ⱼ into
    /// `minus` (m × n each), L = `offsets`; ⊞ is g's
    /// [`input_plus_into`](VectorFunction::input_plus_into), ⊖ its
    /// [`difference_into`](VectorFunction::difference_into). The 2n points go through g one at a
    /// time. A value or deviation of the wrong length is a dimension error (quantity
    /// `FunctionValue`, at `stage`).
    #[cfg_attr(not(debug_assertions), inline(always))]
    #[allow(clippy::too_many_arguments)]
    pub fn deviations_into<G>(
        &mut self,
        g: &G,
        mean: &OVector<T, N>,
        offsets: &OMatrix<T, N, N>,
        value: &mut OVector<T, M>,
        plus: &mut OMatrix<T, M, N>,
        minus: &mut OMatrix<T, M, N>,
        stage: Stage,
    ) -> Result<()>
    where
        G: VectorFunction<T, N, M> + ?Sized,
    {
        let n_dim = mean.shape_generic().0;
        let m_dim = plus.shape_generic().0;
        let (n, m) = (n_dim.value(), m_dim.value());
        eval_into(g, mean, value);
        ensure_shape(value, m, 1, stage, Quantity::FunctionValue)?;
        // The tangent ±Lⱼ, needed apart from the point only off vector spaces.
        let mut delta = (!G::VECTOR_SPACES.get()).then(|| buffer(&mut self.tangent, n_dim, U1));
        let x = buffer(&mut self.point, n_dim, U1);
        let y = buffer(&mut self.value, m_dim, U1);
        let d = buffer(&mut self.deviation, m_dim, U1);
        // One at a time. Columns of column-major storage are contiguous slices: plain slice
        // loops here, where nalgebra's generic column views cost measurably on small static
        // sizes.
        for j in 0..n {
            let column = &offsets.as_slice()[j * n..(j + 1) * n];
            for (sign, deviations) in [(T::one(), &mut *plus), (-T::one(), &mut *minus)] {
                // χ = μ ⊞ ±Lⱼ; with + the bits of μ ± Lⱼ (−Lⱼ is exact).
                if let Some(delta) = delta.as_deref_mut() {
                    for (di, &li) in delta.as_mut_slice().iter_mut().zip(column) {
                        *di = sign * li;
                    }
                    g.input_plus_into(mean, delta, x);
                } else {
                    let pairs = x.as_mut_slice().iter_mut().zip(mean.as_slice());
                    for ((xi, &mi), &li) in pairs.zip(column) {
                        *xi = mi + sign * li;
                    }
                }
                eval_into(g, x, y);
                ensure_shape(y, m, 1, stage, Quantity::FunctionValue)?;
                g.difference_into(y, value, d);
                ensure_shape(d, m, 1, stage, Quantity::FunctionValue)?;
                deviations.as_mut_slice()[j * m..(j + 1) * m].copy_from_slice(d.as_slice());
            }
        }
        Ok(())
    }
}

impl<T: Real> PropagatorWorkspace<T> for Unscented<T> {
    type Workspace<N: Dim, M: Dim>
        = UnscentedWorkspace<T, N, M>
    where
        DefaultAllocator: Alloc<N, M>;
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Unscented<T>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    /// The deviations are stored column by column in D₊ and D₋ (m × n, in the workspace), so
    /// the sums are matrix products: cov(y) = w (D₊D₊ᵀ + D₋D₋ᵀ) + (β − α²) d̄ d̄ᵀ and, since
    /// χ±ⱼ − μ = ±√c Lⱼ, cov(x, y) = w √c L (D₊ − D₋)ᵀ. The 2n points go through g one at a
    /// time.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn propagate_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        mut out: Outputs<'_, T, N, M>,
        workspace: &mut UnscentedWorkspace<T, N, M>,
    ) -> Result<()> {
        let (n_dim, m_dim) = check_inputs(mean, covariance, &mut out)?;
        let (n, m) = (n_dim.value(), m_dim.value());
        let stage = Stage::Propagation;
        self.check_dimension(n)?;
        let c = self.alpha * self.alpha * (real::<T>(n as f64) + self.kappa);
        let l = buffer(&mut workspace.factor, n_dim, n_dim);
        psd_factor_into(covariance, l, &mut workspace.cholesky, stage)?;
        *l *= c.sqrt();

        // ȳ is formed as g(μ) ⊞ d̄: out.mean holds g(μ) until the end.
        let out_mean = &mut *out.mean;
        let plus = buffer(&mut workspace.plus, m_dim, n_dim);
        let minus = buffer(&mut workspace.minus, m_dim, n_dim);
        workspace
            .points
            .deviations_into(g, mean, l, out_mean, plus, minus, stage)?;
        let w = T::one() / (real::<T>(2.0) * c);
        let d_bar = buffer(&mut workspace.mean_deviation, m_dim, U1);
        d_bar.fill(T::zero());
        for deviations in [&*plus, &*minus] {
            for column in deviations.as_slice().chunks_exact(m.max(1)) {
                for (s, &v) in d_bar.as_mut_slice().iter_mut().zip(column) {
                    *s += v;
                }
            }
        }
        *d_bar *= w;
        // The lower triangle of the symmetric sums only (`finish` mirrors it).
        let out_covariance = &mut *out.covariance;
        mul_tr_lower(out_covariance, Accum::Replace, w, plus, plus);
        mul_tr_lower(out_covariance, Accum::Add, w, minus, minus);
        let centre = self.beta - self.alpha * self.alpha;
        for j in 0..m {
            let dj = centre * d_bar[j];
            for i in j..m {
                out_covariance[(i, j)] += d_bar[i] * dj;
            }
        }
        if let Some(cross) = out.cross_covariance.as_deref_mut() {
            // D₋ ← D₊ − D₋; l already carries the √c.
            minus.zip_apply(plus, |dm, dp| *dm = dp - *dm);
            mul_tr(cross, Accum::Replace, w, l, minus);
        }
        // ȳ = g(μ) ⊞ d̄, with g(μ) moved aside (with + the bits of g(μ) + d̄ in place).
        if G::VECTOR_SPACES.get() {
            *out.mean += &*d_bar;
        } else {
            let y = buffer(&mut workspace.points.value, m_dim, U1);
            kernel::copy(y, out.mean);
            g.output_plus_into(y, d_bar, out.mean);
            ensure_shape(out.mean, m, 1, stage, Quantity::FunctionValue)?;
        }
        out.finish()
    }
}
