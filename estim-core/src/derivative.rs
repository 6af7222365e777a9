//! Checks analytic derivatives against central finite differences.
//!
//! - The Jacobian is compared with (g(x + hⱼeⱼ) − g(x − hⱼeⱼ)) / (2hⱼ).
//! - Each Hessian Hₖ is compared with central differences of the **analytic Jacobian**:
//!   column j of Hₖ against (∇gₖ(x + hⱼeⱼ) − ∇gₖ(x − hⱼeⱼ)) / (2hⱼ). Together with the
//!   Jacobian check this ties the Hessian to the values, with one differencing (error O(h²))
//!   instead of two; a component declared affine (`None`) is compared with zero.
//!
//! The step is hⱼ = ε^⅓ · max(1, |xⱼ|) by default (the central-difference optimum for smooth
//! functions: truncation O(h²) and round-off O(ε/h) balance at ε^⅔ ≈ 4·10⁻¹¹ relative for
//! `f64`, ≈ 2·10⁻⁵ for `f32`).
//!
//! With a **reference model** instead of finite differences ([`compare_derivatives`],
//! [`compare_process_models`], [`compare_measurement_models`]): the analytic derivatives are
//! compared entry by entry with another implementation of the same function, typically the
//! same equations written once over a dual-number scalar and wrapped in
//! `estim_core::autodiff::AutoDiff` (feature `autodiff`). Automatic derivatives have no
//! truncation error, so correct analytic derivatives agree to rounding (`is_accurate(1e-12)`
//! for well-scaled `f64` models), a far sharper test than finite differences. The values are
//! compared too ([`Entry::Value`]): a reference that computes another function is caught.
//!
//! Use it from a test, including a downstream crate's proptest:
//!
//! ```
//! use estim_core::{derivative, Differentiable, VectorFunction, nalgebra::{Matrix1x2, Vector1, Vector2}};
//! struct Product;
//! impl VectorFunction<f64, nalgebra::U2, nalgebra::U1> for Product {
//!     fn eval(&self, x: &Vector2<f64>) -> Vector1<f64> { Vector1::new(x[0] * x[1]) }
//! }
//! impl Differentiable<f64, nalgebra::U2, nalgebra::U1> for Product {
//!     fn jacobian(&self, x: &Vector2<f64>) -> Matrix1x2<f64> { Matrix1x2::new(x[1], x[0]) }
//! }
//! # use estim_core::nalgebra;
//! let report = derivative::check_jacobian(&Product, &Vector2::new(2.0, 3.0))?;
//! assert!(report.is_accurate(1e-8), "{report}");
//! # Ok::<(), estim_core::Error>(())
//! ```

use core::fmt;

use nalgebra::{DefaultAllocator, Dim, OVector};

use crate::alloc::Alloc;
use crate::checks::{ensure_finite, ensure_shape};
use crate::error::{Error, Parameter, Quantity, Result, Stage};
use crate::function::{Differentiable, TwiceDifferentiable};
use crate::manifold::StateSpace;
use crate::model::{
    MeasurementHessian, MeasurementJacobian, Observation, ProcessHessian, ProcessJacobian,
    Transition,
};
use crate::scalar::{Real, real};

/// Which derivative entry a comparison refers to (0-based indices).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Entry {
    /// Value gᵣₒᵥᵥ (compared only against a reference model).
    Value {
        /// Output component.
        row: usize,
    },
    /// Jacobian entry ∂gᵣₒᵥᵥ/∂x_col.
    Jacobian {
        /// Output component.
        row: usize,
        /// State component.
        col: usize,
    },
    /// Hessian entry ∂²g_component/∂x_row∂x_col.
    Hessian {
        /// Output component.
        component: usize,
        /// First state component.
        row: usize,
        /// Second state component.
        col: usize,
    },
}

/// One comparison of an analytic derivative entry with its finite-difference estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Comparison<T> {
    /// Which entry.
    pub entry: Entry,
    /// The analytic value.
    pub analytic: T,
    /// The finite-difference value, or the reference model's.
    pub numeric: T,
}

impl<T: Real> Comparison<T> {
    /// |analytic − numeric|.
    pub fn abs_error(&self) -> T {
        (self.analytic - self.numeric).abs()
    }

    /// |analytic − numeric| / max(|analytic|, |numeric|), and 0 when both are 0.
    pub fn rel_error(&self) -> T {
        let scale = self.analytic.abs().max(self.numeric.abs());
        if scale > T::zero() {
            self.abs_error() / scale
        } else {
            T::zero()
        }
    }

    /// |analytic − numeric| / max(1, |numeric|): absolute for small entries, relative for
    /// large ones. This is what [`DerivativeReport::is_accurate`] bounds.
    pub fn mixed_error(&self) -> T {
        self.abs_error() / T::one().max(self.numeric.abs())
    }
}

/// The outcome of a derivative check: the worst entries by absolute, relative and mixed error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DerivativeReport<T> {
    /// How many entries were compared.
    pub entries: usize,
    /// The entry with the largest absolute error (`None` if nothing was compared).
    pub worst_abs: Option<Comparison<T>>,
    /// The entry with the largest relative error.
    pub worst_rel: Option<Comparison<T>>,
    /// The entry with the largest mixed error (see [`Comparison::mixed_error`]).
    pub worst_mixed: Option<Comparison<T>>,
}

impl<T: Real> DerivativeReport<T> {
    fn empty() -> Self {
        Self {
            entries: 0,
            worst_abs: None,
            worst_rel: None,
            worst_mixed: None,
        }
    }

    fn record(&mut self, c: Comparison<T>) {
        self.entries += 1;
        let worse = |old: &Option<Comparison<T>>, f: fn(&Comparison<T>) -> T| {
            old.as_ref().is_none_or(|o| f(&c) > f(o))
        };
        if worse(&self.worst_abs, Comparison::abs_error) {
            self.worst_abs = Some(c);
        }
        if worse(&self.worst_rel, Comparison::rel_error) {
            self.worst_rel = Some(c);
        }
        if worse(&self.worst_mixed, Comparison::mixed_error) {
            self.worst_mixed = Some(c);
        }
    }

    /// Combines two reports (e.g. a Jacobian and a Hessian check).
    pub fn merge(mut self, other: Self) -> Self {
        for c in [other.worst_abs, other.worst_rel, other.worst_mixed]
            .into_iter()
            .flatten()
        {
            let entries = self.entries;
            self.record(c);
            self.entries = entries;
        }
        self.entries += other.entries;
        self
    }

    /// The largest absolute error.
    pub fn max_abs_error(&self) -> T {
        self.worst_abs.map_or(T::zero(), |c| c.abs_error())
    }

    /// The largest relative error.
    pub fn max_rel_error(&self) -> T {
        self.worst_rel.map_or(T::zero(), |c| c.rel_error())
    }

    /// The largest mixed error |a − n| / max(1, |n|).
    pub fn max_mixed_error(&self) -> T {
        self.worst_mixed.map_or(T::zero(), |c| c.mixed_error())
    }

    /// Whether every entry satisfies |analytic − numeric| ≤ `tol` · max(1, |numeric|).
    ///
    /// With the default step, correct `f64` derivatives of smooth, well-scaled functions pass
    /// with `tol` ≈ 10⁻⁶ (the finite-difference error is ≈ 10⁻¹⁰ times the third derivative);
    /// `f32` needs ≈ 10⁻².
    pub fn is_accurate(&self, tol: T) -> bool {
        self.max_mixed_error() <= tol
    }
}

/// `g[row]`, `J[row, col]` or `H_component[row, col]`.
impl fmt::Display for Entry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Entry::Value { row } => write!(f, "g[{row}]"),
            Entry::Jacobian { row, col } => write!(f, "J[{row}, {col}]"),
            Entry::Hessian {
                component,
                row,
                col,
            } => write!(f, "H{component}[{row}, {col}]"),
        }
    }
}

/// One line per distinct worst entry, naming which errors it is worst by:
///
/// ```
/// use estim_core::derivative::{Comparison, DerivativeReport, Entry};
///
/// let c = Comparison { entry: Entry::Jacobian { row: 1, col: 0 }, analytic: 2.0, numeric: 2.5 };
/// let report = DerivativeReport { entries: 4, worst_abs: Some(c), worst_rel: Some(c), worst_mixed: Some(c) };
/// assert_eq!(
///     report.to_string(),
///     "4 entries compared; worst by abs, rel, mixed error: J[1, 0] analytic 2 numeric 2.5 \
///      (abs error 0.5, rel 0.2)"
/// );
/// ```
impl<T: Real + fmt::Display> fmt::Display for DerivativeReport<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} entries compared", self.entries)?;
        let worst = [
            ("abs", self.worst_abs),
            ("rel", self.worst_rel),
            ("mixed", self.worst_mixed),
        ];
        for (i, (_, c)) in worst.iter().enumerate() {
            let Some(c) = c else { continue };
            if worst[..i]
                .iter()
                .any(|(_, earlier)| earlier.as_ref() == Some(c))
            {
                continue; // printed already, under the first error it is worst by
            }
            f.write_str("; worst by ")?;
            let by = worst[i..]
                .iter()
                .filter(|(_, other)| other.as_ref() == Some(c));
            for (k, (name, _)) in by.enumerate() {
                write!(f, "{}{name}", if k > 0 { ", " } else { "" })?;
            }
            write!(
                f,
                " error: {} analytic {} numeric {} (abs error {}, rel {})",
                c.entry,
                c.analytic,
                c.numeric,
                c.abs_error(),
                c.rel_error()
            )?;
        }
        Ok(())
    }
}

/// Finite-difference settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DerivativeCheck<T> {
    relative_step: T,
}

impl<T: Real> Default for DerivativeCheck<T> {
    /// hⱼ = ε^⅓ · max(1, |xⱼ|).
    fn default() -> Self {
        Self {
            relative_step: T::default_epsilon().powf(real(1.0 / 3.0)),
        }
    }
}

impl<T: Real> DerivativeCheck<T> {
    /// Steps hⱼ = `relative_step` · max(1, |xⱼ|); `relative_step` must be finite and > 0.
    pub fn with_relative_step(relative_step: T) -> Result<Self> {
        if relative_step.is_finite() && relative_step > T::zero() {
            Ok(Self { relative_step })
        } else {
            Err(Error::InvalidParameter {
                parameter: Parameter::StepSize,
                value: nalgebra::try_convert::<T, f64>(relative_step).unwrap_or(f64::NAN),
            })
        }
    }

    fn step<N: Dim>(&self, x: &OVector<T, N>, j: usize) -> T
    where
        DefaultAllocator: Alloc<N>,
    {
        self.relative_step * T::one().max(x[j].abs())
    }

    /// Compares g's analytic Jacobian at `x` with central differences of its values.
    ///
    /// On a state space (a function whose [`input_plus_into`](crate::VectorFunction::input_plus_into)
    /// is not +, such as [`Transition::on`] or [`Observation::on`] with an
    /// [`AttitudeError`](crate::manifold::AttitudeError)), the differences are taken on the
    /// manifold, as the filters use the Jacobian: column j against
    /// ((g(x ⊞ hⱼeⱼ) ⊟ g(x)) − (g(x ⊞ (−hⱼeⱼ)) ⊟ g(x))) / (2hⱼ), ⊟ the function's
    /// [`difference_into`](crate::VectorFunction::difference_into). A Jacobian that is correct
    /// on the manifold is then not flagged for differing from the derivative of the coordinates.
    ///
    /// Errors: non-finite values or a runtime shape mismatch.
    pub fn jacobian<N, M, G>(&self, g: &G, x: &OVector<T, N>) -> Result<DerivativeReport<T>>
    where
        N: Dim,
        M: Dim,
        G: Differentiable<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        let stage = Stage::DerivativeCheck;
        ensure_finite(x, stage, Quantity::Mean)?;
        let n = x.nrows();
        let y = g.eval(x);
        let m = y.nrows();
        let jac = g.jacobian(x);
        ensure_shape(&jac, m, n, stage, Quantity::Jacobian)?;
        ensure_finite(&jac, stage, Quantity::Jacobian)?;
        let mut report = DerivativeReport::empty();
        if !G::VECTOR_SPACES.get() {
            self.manifold_columns(g, x, &y, &jac, &mut report)?;
            return Ok(report);
        }
        let mut xp = x.clone();
        for j in 0..n {
            let h = self.step(x, j);
            xp[j] = x[j] + h;
            let yp = g.eval(&xp);
            xp[j] = x[j] - h;
            let ym = g.eval(&xp);
            xp[j] = x[j];
            ensure_shape(&yp, m, 1, stage, Quantity::FunctionValue)?;
            ensure_shape(&ym, m, 1, stage, Quantity::FunctionValue)?;
            // Through the function's ⊖ so wrapped outputs (angles) difference correctly.
            let mut dy = yp.clone();
            g.difference_into(&yp, &ym, &mut dy);
            ensure_shape(&dy, m, 1, stage, Quantity::FunctionValue)?;
            ensure_finite(&dy, stage, Quantity::FunctionValue)?;
            for i in 0..m {
                report.record(Comparison {
                    entry: Entry::Jacobian { row: i, col: j },
                    analytic: jac[(i, j)],
                    numeric: dy[i] / (h + h),
                });
            }
        }
        Ok(report)
    }

    /// The Jacobian columns of a function on a state space (see [`jacobian`](Self::jacobian)):
    /// column j against ((g(x ⊞ hⱼeⱼ) ⊟ g(x)) − (g(x ⊞ (−hⱼeⱼ)) ⊟ g(x))) / (2hⱼ).
    fn manifold_columns<N, M, G>(
        &self,
        g: &G,
        x: &OVector<T, N>,
        y: &OVector<T, M>,
        jac: &nalgebra::OMatrix<T, M, N>,
        report: &mut DerivativeReport<T>,
    ) -> Result<()>
    where
        N: Dim,
        M: Dim,
        G: Differentiable<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        let stage = Stage::DerivativeCheck;
        let (n, m) = (x.nrows(), y.nrows());
        let (mut delta, mut xp) = (x.clone(), x.clone());
        let mut side = |h: T, j: usize| -> Result<OVector<T, M>> {
            delta.fill(T::zero());
            delta[j] = h;
            g.input_plus_into(x, &delta, &mut xp);
            let value = g.eval(&xp);
            ensure_shape(&value, m, 1, stage, Quantity::FunctionValue)?;
            let mut d = value.clone();
            g.difference_into(&value, y, &mut d);
            ensure_shape(&d, m, 1, stage, Quantity::FunctionValue)?;
            ensure_finite(&d, stage, Quantity::FunctionValue)?;
            Ok(d)
        };
        for j in 0..n {
            let h = self.step(x, j);
            let (dp, dm) = (side(h, j)?, side(-h, j)?);
            for i in 0..m {
                report.record(Comparison {
                    entry: Entry::Jacobian { row: i, col: j },
                    analytic: jac[(i, j)],
                    numeric: (dp[i] - dm[i]) / (h + h),
                });
            }
        }
        Ok(())
    }

    /// Compares g's analytic Hessians at `x` with central differences of its analytic
    /// Jacobian. Run [`jacobian`](Self::jacobian) too (or use [`derivatives`](Self::derivatives)):
    /// this check trusts the Jacobian. The Hessians are differenced in the coordinates of x,
    /// whatever the function's state space.
    pub fn hessian<N, M, G>(&self, g: &G, x: &OVector<T, N>) -> Result<DerivativeReport<T>>
    where
        N: Dim,
        M: Dim,
        G: TwiceDifferentiable<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        let stage = Stage::DerivativeCheck;
        ensure_finite(x, stage, Quantity::Mean)?;
        let n = x.nrows();
        let m = g.eval(x).nrows();
        let mut report = DerivativeReport::empty();
        let mut xp = x.clone();
        for k in 0..m {
            let hk = g.hessian(x, k);
            if let Some(hk) = &hk {
                ensure_shape(hk, n, n, stage, Quantity::Hessian)?;
                ensure_finite(hk, stage, Quantity::Hessian)?;
            }
            for j in 0..n {
                let h = self.step(x, j);
                xp[j] = x[j] + h;
                let jp = g.jacobian(&xp);
                xp[j] = x[j] - h;
                let jm = g.jacobian(&xp);
                xp[j] = x[j];
                ensure_shape(&jp, m, n, stage, Quantity::Jacobian)?;
                ensure_shape(&jm, m, n, stage, Quantity::Jacobian)?;
                for i in 0..n {
                    let numeric = (jp[(k, i)] - jm[(k, i)]) / (h + h);
                    if !numeric.is_finite() {
                        return Err(Error::NonFinite {
                            stage,
                            quantity: Quantity::Jacobian,
                        });
                    }
                    report.record(Comparison {
                        entry: Entry::Hessian {
                            component: k,
                            row: i,
                            col: j,
                        },
                        analytic: hk.as_ref().map_or(T::zero(), |hk| hk[(i, j)]),
                        numeric,
                    });
                }
            }
        }
        Ok(report)
    }

    /// [`jacobian`](Self::jacobian) and [`hessian`](Self::hessian) merged.
    pub fn derivatives<N, M, G>(&self, g: &G, x: &OVector<T, N>) -> Result<DerivativeReport<T>>
    where
        N: Dim,
        M: Dim,
        G: TwiceDifferentiable<T, N, M> + ?Sized,
        DefaultAllocator: Alloc<N, M>,
    {
        Ok(self.jacobian(g, x)?.merge(self.hessian(g, x)?))
    }
}

/// [`DerivativeCheck::jacobian`] with the default step.
pub fn check_jacobian<T, N, M, G>(g: &G, x: &OVector<T, N>) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: Differentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    DerivativeCheck::default().jacobian(g, x)
}

/// [`DerivativeCheck::derivatives`] (Jacobian and Hessians) with the default step.
pub fn check_derivatives<T, N, M, G>(g: &G, x: &OVector<T, N>) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    DerivativeCheck::default().derivatives(g, x)
}

/// Checks a process model's Jacobian ∂f/∂x at (x, u, Δt).
pub fn check_process_jacobian<T, N, P>(
    model: &P,
    x: &OVector<T, N>,
    u: &P::Input,
    dt: T,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    P: ProcessJacobian<T, N>,
    DefaultAllocator: Alloc<N>,
{
    check_jacobian(&Transition::new(model, u, dt), x)
}

/// Checks a process model's Jacobian and Hessians at (x, u, Δt).
pub fn check_process_model<T, N, P>(
    model: &P,
    x: &OVector<T, N>,
    u: &P::Input,
    dt: T,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    P: ProcessHessian<T, N>,
    DefaultAllocator: Alloc<N>,
{
    check_derivatives(&Transition::new(model, u, dt), x)
}

/// Checks a measurement model's Jacobian ∂h/∂x at x.
pub fn check_measurement_jacobian<T, N, M, H>(
    model: &H,
    x: &OVector<T, N>,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    check_jacobian(&Observation::new(model), x)
}

/// Checks a measurement model's Jacobian and Hessians at x.
pub fn check_measurement_model<T, N, M, H>(
    model: &H,
    x: &OVector<T, N>,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    check_derivatives(&Observation::new(model), x)
}

/// Checks a process model's Jacobian ∂f/∂x at (x, u, Δt) on the state space `space`: the
/// Jacobian a filter built with that space uses, F = ∂(f(x ⊞ δ) ⊟ f(x))/∂δ at δ = 0 (see
/// [`DerivativeCheck::jacobian`]). With [`Euclidean`](crate::Euclidean) this is
/// [`check_process_jacobian`].
///
/// ```
/// use estim_core::derivative::{check_process_jacobian, check_process_jacobian_on};
/// use estim_core::manifold::{AttitudeError, so3_exp, so3_log};
/// use estim_core::nalgebra::{Matrix3, U3, Vector3};
/// use estim_core::{ProcessJacobian, ProcessModel};
///
/// /// The attitude (its rotation vector) turned by a body rate ω over Δt: Log(Exp(θ) Exp(ω Δt)).
/// struct Gyro;
/// impl ProcessModel<f64, U3> for Gyro {
///     type Input = Vector3<f64>;
///     fn transition(&self, x: &Vector3<f64>, w: &Vector3<f64>, dt: f64) -> Vector3<f64> {
///         so3_log(&(so3_exp(x) * so3_exp(&(w * dt))))
///     }
///     fn process_noise(&self, _: &Vector3<f64>, _: &Vector3<f64>, dt: f64) -> Matrix3<f64> {
///         Matrix3::identity() * (1e-6 * dt)
///     }
/// }
/// impl ProcessJacobian<f64, U3> for Gyro {
///     // A body-frame error δ before the step is R(ω Δt)ᵀ δ after it.
///     fn transition_jacobian(&self, _: &Vector3<f64>, w: &Vector3<f64>, dt: f64) -> Matrix3<f64> {
///         so3_exp(&(w * dt)).inverse().to_rotation_matrix().into_inner()
///     }
/// }
/// let (x, w) = (Vector3::new(0.4, -1.0, 2.0), Vector3::new(3.0, 0.5, -1.0));
/// let space = AttitudeError::at(0);
/// assert!(check_process_jacobian_on(&space, &Gyro, &x, &w, 0.1)?.is_accurate(1e-6));
/// // In the coordinates (the embedding) the same, correct, Jacobian is flagged.
/// assert!(!check_process_jacobian(&Gyro, &x, &w, 0.1)?.is_accurate(1e-2));
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn check_process_jacobian_on<T, N, P, S>(
    space: &S,
    model: &P,
    x: &OVector<T, N>,
    u: &P::Input,
    dt: T,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    P: ProcessJacobian<T, N>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N>,
{
    check_jacobian(&Transition::on(space, model, u, dt), x)
}

/// Checks a measurement model's Jacobian ∂h/∂x at x on the state space `space`:
/// H = ∂(h(x ⊞ δ) ⊖ h(x))/∂δ at δ = 0, ⊖ the model's residual (see
/// [`DerivativeCheck::jacobian`], and [`check_process_jacobian_on`] for an example).
pub fn check_measurement_jacobian_on<T, N, M, H, S>(
    space: &S,
    model: &H,
    x: &OVector<T, N>,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M>,
    S: StateSpace<T, N>,
    DefaultAllocator: Alloc<N, M>,
{
    check_jacobian(&Observation::on(space, model), x)
}

/// Compares g's value, Jacobian and Hessians at `x` with those of `reference`, an independent
/// implementation of the same function (automatic derivatives, say): every entry, with the
/// reference's in [`Comparison::numeric`]. A component that either side declares affine
/// (`None`) counts as a zero Hessian.
///
/// ```
/// use estim_core::{derivative, Differentiable, TwiceDifferentiable, VectorFunction};
/// use estim_core::nalgebra::{Matrix1x2, Matrix2, U1, U2, Vector1, Vector2};
///
/// /// g(x) = x₀ x₁, analytic; `Expanded` is ((x₀ + x₁)² − (x₀ − x₁)²)/4, the same function.
/// struct Product;
/// struct Expanded;
/// impl VectorFunction<f64, U2, U1> for Product {
///     fn eval(&self, x: &Vector2<f64>) -> Vector1<f64> { Vector1::new(x[0] * x[1]) }
/// }
/// impl Differentiable<f64, U2, U1> for Product {
///     fn jacobian(&self, x: &Vector2<f64>) -> Matrix1x2<f64> { Matrix1x2::new(x[1], x[0]) }
/// }
/// impl TwiceDifferentiable<f64, U2, U1> for Product {
///     fn hessian(&self, _: &Vector2<f64>, _: usize) -> Option<Matrix2<f64>> {
///         Some(Matrix2::new(0.0, 1.0, 1.0, 0.0))
///     }
/// }
/// impl VectorFunction<f64, U2, U1> for Expanded {
///     fn eval(&self, x: &Vector2<f64>) -> Vector1<f64> {
///         Vector1::new(((x[0] + x[1]).powi(2) - (x[0] - x[1]).powi(2)) / 4.0)
///     }
/// }
/// impl Differentiable<f64, U2, U1> for Expanded {
///     fn jacobian(&self, x: &Vector2<f64>) -> Matrix1x2<f64> { Matrix1x2::new(x[1], x[0]) }
/// }
/// impl TwiceDifferentiable<f64, U2, U1> for Expanded {
///     fn hessian(&self, _: &Vector2<f64>, _: usize) -> Option<Matrix2<f64>> {
///         Some(Matrix2::new(0.0, 1.0, 1.0, 0.0))
///     }
/// }
/// let report = derivative::compare_derivatives(&Product, &Expanded, &Vector2::new(1.5, -2.0))?;
/// assert!(report.is_accurate(1e-12), "{report}");
/// # Ok::<(), estim_core::Error>(())
/// ```
///
/// Errors: non-finite x, values or derivatives, or shapes that differ between the two.
pub fn compare_derivatives<T, N, M, G, R>(
    g: &G,
    reference: &R,
    x: &OVector<T, N>,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    M: Dim,
    G: TwiceDifferentiable<T, N, M> + ?Sized,
    R: TwiceDifferentiable<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    let stage = Stage::DerivativeCheck;
    ensure_finite(x, stage, Quantity::Mean)?;
    let n = x.nrows();
    let mut report = DerivativeReport::empty();
    let (y, y_ref) = (g.eval(x), reference.eval(x));
    let m = y.nrows();
    ensure_shape(&y_ref, m, 1, stage, Quantity::FunctionValue)?;
    ensure_finite(&y, stage, Quantity::FunctionValue)?;
    ensure_finite(&y_ref, stage, Quantity::FunctionValue)?;
    for row in 0..m {
        report.record(Comparison {
            entry: Entry::Value { row },
            analytic: y[row],
            numeric: y_ref[row],
        });
    }
    let (jac, jac_ref) = (g.jacobian(x), reference.jacobian(x));
    for j in [&jac, &jac_ref] {
        ensure_shape(j, m, n, stage, Quantity::Jacobian)?;
        ensure_finite(j, stage, Quantity::Jacobian)?;
    }
    for col in 0..n {
        for row in 0..m {
            report.record(Comparison {
                entry: Entry::Jacobian { row, col },
                analytic: jac[(row, col)],
                numeric: jac_ref[(row, col)],
            });
        }
    }
    for component in 0..m {
        let (h, h_ref) = (g.hessian(x, component), reference.hessian(x, component));
        for h in [&h, &h_ref].into_iter().flatten() {
            ensure_shape(h, n, n, stage, Quantity::Hessian)?;
            ensure_finite(h, stage, Quantity::Hessian)?;
        }
        let entry = |h: &Option<_>, i, j| {
            h.as_ref()
                .map_or(T::zero(), |h: &nalgebra::OMatrix<T, N, N>| h[(i, j)])
        };
        for col in 0..n {
            for row in 0..n {
                report.record(Comparison {
                    entry: Entry::Hessian {
                        component,
                        row,
                        col,
                    },
                    analytic: entry(&h, row, col),
                    numeric: entry(&h_ref, row, col),
                });
            }
        }
    }
    Ok(report)
}

/// [`compare_derivatives`] for two process models at (x, Δt), each with its own input (the
/// two may type the input differently).
pub fn compare_process_models<T, N, P, R>(
    model: &P,
    reference: &R,
    x: &OVector<T, N>,
    u: &P::Input,
    u_reference: &R::Input,
    dt: T,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    P: ProcessHessian<T, N>,
    R: ProcessHessian<T, N>,
    DefaultAllocator: Alloc<N>,
{
    compare_derivatives(
        &Transition::new(model, u, dt),
        &Transition::new(reference, u_reference, dt),
        x,
    )
}

/// [`compare_derivatives`] for two measurement models at x.
pub fn compare_measurement_models<T, N, M, H, R>(
    model: &H,
    reference: &R,
    x: &OVector<T, N>,
) -> Result<DerivativeReport<T>>
where
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementHessian<T, N, M>,
    R: MeasurementHessian<T, N, M>,
    DefaultAllocator: Alloc<N, M>,
{
    compare_derivatives(&Observation::new(model), &Observation::new(reference), x)
}
