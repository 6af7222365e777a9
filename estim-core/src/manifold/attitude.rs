//! Attitude as a unit quaternion with a 3-dimensional tangent: the multiplicative error state.
//!
//! A filter's state and its tangent have one dimension N ([`StateSpace`]), and a unit
//! quaternion has four numbers but three degrees of freedom. So, as navigation filters do
//! (the multiplicative EKF, Markley 2003; Hertzberg et al. 2013, §IV), the filter keeps the
//! **attitude error** δθ ∈ ℝ³ in its state, and the attitude is
//!
//! q = q_ref ⊗ Exp(δθ),  Exp(v) = (cos ½|v|, sin ½|v| · v/|v|),
//!
//! with the reference q_ref held next to the filter ([`AttitudeReference`]). The state space
//! [`AttitudeError`] makes the filter's ⊞ compose rotations on that block,
//! δθ ⊞ ε = Log(Exp(δθ) ⊗ Exp(ε)), and its ⊟ the body-frame rotation vector between two
//! attitudes, a ⊟ b = Log(Exp(b)⁻¹ ⊗ Exp(a)), so sigma points, deviations and the update
//! x ⊞ K ν are rotations, and P is the covariance of a body-frame rotation vector.
//!
//! After a step, [`AttitudeReference::recentre`] folds the estimate into the reference
//! (q_ref ← q_ref ⊗ Exp(δθ̂), δθ̂ ← 0). That changes no covariance: with ⊞ the composition
//! above, P already describes perturbations q̂ ⊗ Exp(ε) of the estimate, which are the new
//! chart's coordinates. Recentring every step keeps δθ̂ near zero, where linearisations in
//! δθ (the EKF's Jacobians) are those of the tangent.
//!
//! The quaternion stays unit: Exp and the products are renormalised, and recentring means
//! the estimate is never accumulated in a non-unit form.
//!
//! **Keep the attitude in the filter's state when something rolls the filter back.** A
//! reference held next to the filter is state the filter's snapshots do not contain: the
//! fusion driver (estim-filters' `fusion::FusionDriver`), which restores snapshots to reject
//! a measurement or to replay late ones, would restore the filter but not q_ref. Use the
//! block as the attitude itself instead: q_ref = identity, never recentred, so
//! q = Exp(δθ) and δθ is the rotation vector of the attitude (|δθ| ≤ π; ⊞ and ⊟ above keep
//! it there and stay smooth across the fold). P is still the covariance of the body-frame
//! error q̂⁻¹ ⊗ q, because ⊞ composes on the right; only the Jacobians must be those of the
//! tangent, which [`check_process_jacobian_on`](crate::derivative::check_process_jacobian_on)
//! checks. Everything the estimate depends on is then in the filter, and a replay is
//! bit-identical to time-ordered processing (tested in estim-filters, `fusion_inputs`).

use nalgebra::{DefaultAllocator, Dim, OVector, Quaternion, UnitQuaternion, Vector3};

use super::{StateSpace, add_into, subtract_into};
use crate::alloc::Alloc;
use crate::error::{Error, Quantity, Result, Stage};
use crate::scalar::{Real, real};

/// Exp: the unit quaternion of the rotation vector v (angle |v| about v/|v|).
///
/// Accurate to rounding for every |v| (a series for |v|² below √ε, where sin ½|v| / |v|
/// would lose digits). For a model written over a dual-number scalar (automatic
/// derivatives), use its generic twin `estim_core::autodiff::so3_exp` (feature `autodiff`).
///
/// ```
/// use estim_core::manifold::{so3_exp, so3_log};
/// use estim_core::nalgebra::Vector3;
///
/// let v = Vector3::new(0.3, -1.2, 2.0);
/// assert!((so3_log(&so3_exp(&v)) - v).norm() < 1e-14);
/// assert_eq!(so3_exp(&Vector3::<f64>::zeros()).w, 1.0);
/// ```
pub fn so3_exp<T: Real>(v: &Vector3<T>) -> UnitQuaternion<T> {
    let theta2 = v.norm_squared();
    let (w, k) = if theta2 < T::default_epsilon().sqrt() {
        // cos ½θ = 1 − θ²/8 + …, sin ½θ / θ = ½ − θ²/48 + …: the next terms are below ε.
        (
            T::one() - theta2 / real(8.0),
            real::<T>(0.5) - theta2 / real(48.0),
        )
    } else {
        let theta = theta2.sqrt();
        let (s, c) = (theta * real(0.5)).sin_cos();
        (c, s / theta)
    };
    UnitQuaternion::new_normalize(Quaternion::from_parts(w, v * k))
}

/// Log: the rotation vector of q (angle in [0, π]), the inverse of [`so3_exp`]. q and −q
/// give the same vector. Generic twin over a dual-number scalar: `estim_core::autodiff::so3_log`
/// (feature `autodiff`).
///
/// ```
/// use estim_core::manifold::{so3_exp, so3_log};
/// use estim_core::nalgebra::{UnitQuaternion, Vector3};
///
/// let q = UnitQuaternion::from_euler_angles(0.1, -0.2, 3.0);
/// assert!(so3_exp(&so3_log(&q)).angle_to(&q) < 1e-14);
/// ```
pub fn so3_log<T: Real>(q: &UnitQuaternion<T>) -> Vector3<T> {
    let (mut w, mut v) = (q.w, q.imag());
    if w < T::zero() {
        (w, v) = (-w, -v);
    }
    let s2 = v.norm_squared();
    // θ = 2 atan2(s, w): atan2 keeps full precision at small angles (acos would not).
    if s2 < T::default_epsilon() * w * w {
        // 2 atan(s/w)/s = (2/w)(1 − s²/(3w²) + …).
        v * (real::<T>(2.0) / w)
    } else {
        let s = s2.sqrt();
        v * (real::<T>(2.0) * s.atan2(w) / s)
    }
}

/// The state space of a state whose components `offset..offset + 3` are an attitude error
/// δθ (see the [module docs](self)): on that block x ⊞ ε = Log(Exp(δθ) ⊗ Exp(ε)) and
/// a ⊟ b = Log(Exp(b)⁻¹ ⊗ Exp(a)); + and − on the other components.
///
/// A state with fewer than `offset + 3` components has no attitude block: ⊞ and ⊟ then give
/// NaN in every component, which a filter reports as [`Error::NonFinite`] (its step fails and
/// leaves it unchanged), never a panic. [`check`](Self::check) says so up front, as a
/// [`Error::DimensionMismatch`].
///
/// ```
/// use estim_core::manifold::{AttitudeError, so3_exp, so3_log};
/// use estim_core::StateSpace;
/// use estim_core::nalgebra::{Vector3, Vector4};
///
/// // (δθ, a clock bias).
/// let space = AttitudeError::at(0);
/// let (x, e) = (Vector4::new(3.0, 0.0, 0.0, 1.0), Vector4::new(0.5, 0.0, 0.0, 0.25));
/// let mut y = Vector4::zeros();
/// space.plus_into(&x, &e, &mut y);
/// // 3 + 0.5 rad about x is 3.5 − 2π: the rotation vector stays in the ball |δθ| ≤ π.
/// assert!((y[0] - (3.5 - 2.0 * core::f64::consts::PI)).abs() < 1e-12 && y[3] == 1.25);
/// let mut d = Vector4::zeros();
/// space.minus_into(&y, &x, &mut d);
/// assert!((d - e).norm() < 1e-12);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct AttitudeError {
    offset: usize,
}

impl AttitudeError {
    /// The attitude error at components `offset..offset + 3`.
    pub const fn at(offset: usize) -> Self {
        Self { offset }
    }

    /// The first component of the attitude block.
    pub fn offset(&self) -> usize {
        self.offset
    }

    /// `Ok(())` if a state of `n` components holds the block `offset..offset + 3`, else
    /// [`Error::DimensionMismatch`] ([`Quantity::Mean`], at [`Stage::Construction`]: a state
    /// of at least `offset + 3` rows expected).
    ///
    /// ```
    /// use estim_core::manifold::AttitudeError;
    /// use estim_core::{Error, Quantity, Stage};
    ///
    /// assert!(AttitudeError::at(3).check(6).is_ok());
    /// assert_eq!(
    ///     AttitudeError::at(3).check(5),
    ///     Err(Error::DimensionMismatch {
    ///         stage: Stage::Construction,
    ///         quantity: Quantity::Mean,
    ///         expected_rows: 6,
    ///         expected_cols: 1,
    ///         found_rows: 5,
    ///         found_cols: 1,
    ///     })
    /// );
    /// ```
    pub fn check(&self, n: usize) -> Result<()> {
        let needed = self.offset.saturating_add(3);
        if n >= needed {
            Ok(())
        } else {
            Err(Error::DimensionMismatch {
                stage: Stage::Construction,
                quantity: Quantity::Mean,
                expected_rows: needed,
                expected_cols: 1,
                found_rows: n,
                found_cols: 1,
            })
        }
    }

    /// δθ, the components `offset..offset + 3` of `x`, if `x` has them.
    fn block<T: Real, N: Dim>(&self, x: &OVector<T, N>) -> Option<Vector3<T>>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.check(x.nrows()).ok()?;
        Some(x.fixed_rows::<3>(self.offset).into_owned())
    }
}

/// out ← NaN in every component, shaped like `x`: a state without the attitude block.
fn not_a_state<T: Real, N: Dim>(x: &OVector<T, N>, out: &mut OVector<T, N>)
where
    DefaultAllocator: Alloc<N>,
{
    if out.shape() != x.shape() {
        *out = x.clone();
    }
    out.fill(real(f64::NAN));
}

impl<T: Real, N: Dim> StateSpace<T, N> for AttitudeError
where
    DefaultAllocator: Alloc<N>,
{
    fn plus_into(&self, x: &OVector<T, N>, delta: &OVector<T, N>, out: &mut OVector<T, N>) {
        let (Some(a), Some(e)) = (self.block(x), self.block(delta)) else {
            return not_a_state(x, out);
        };
        add_into(x, delta, out);
        let composed = so3_log(&(so3_exp(&a) * so3_exp(&e)));
        out.fixed_rows_mut::<3>(self.offset).copy_from(&composed);
    }

    fn minus_into(&self, a: &OVector<T, N>, b: &OVector<T, N>, out: &mut OVector<T, N>) {
        let (Some(da), Some(db)) = (self.block(a), self.block(b)) else {
            return not_a_state(a, out);
        };
        let (qa, qb) = (so3_exp(&da), so3_exp(&db));
        subtract_into(a, b, out);
        let between = so3_log(&(qb.inverse() * qa));
        out.fixed_rows_mut::<3>(self.offset).copy_from(&between);
    }
}

/// The reference attitude q_ref of a multiplicative error state (see the
/// [module docs](self)): the attitude is q = q_ref ⊗ Exp(δθ).
///
/// It lives outside the filter: a component that restores the filter's snapshots (the fusion
/// driver) does not restore it. With such a component, keep the attitude in the state instead
/// (q_ref = identity, no recentring; see the [module docs](self)).
///
/// ```
/// use estim_core::manifold::{AttitudeReference, so3_exp};
/// use estim_core::nalgebra::{UnitQuaternion, Vector3};
///
/// let mut reference = AttitudeReference::new(UnitQuaternion::identity());
/// // The filter's estimate after an update: δθ̂ = (0, 0, 0.1).
/// let mut x = Vector3::new(0.0, 0.0, 0.1);
/// let q = reference.attitude(&x, 0)?;
/// reference.recentre(&mut x, 0)?;
/// assert_eq!(x, Vector3::zeros());
/// assert!(reference.quaternion().angle_to(&q) < 1e-15);
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudeReference<T: Real> {
    q: UnitQuaternion<T>,
}

impl<T: Real> AttitudeReference<T> {
    /// The reference `q`.
    pub fn new(q: UnitQuaternion<T>) -> Self {
        Self { q }
    }

    /// q_ref.
    pub fn quaternion(&self) -> &UnitQuaternion<T> {
        &self.q
    }

    /// q = q_ref ⊗ Exp(δθ), δθ the components `offset..offset + 3` of `x`.
    ///
    /// Errors: `x` has fewer than `offset + 3` components (as [`AttitudeError::check`]).
    pub fn attitude<N: Dim>(&self, x: &OVector<T, N>, offset: usize) -> Result<UnitQuaternion<T>>
    where
        DefaultAllocator: Alloc<N>,
    {
        let space = AttitudeError::at(offset);
        space.check(x.nrows())?;
        Ok(self.q * so3_exp(&x.fixed_rows::<3>(offset).into_owned()))
    }

    /// q_ref ← q_ref ⊗ Exp(δθ) and δθ ← 0 in `x` (the estimate is unchanged): call it with the
    /// filter's state after a step, then give the filter the recentred state (with its
    /// covariance unchanged, e.g. `Estimator::reset` in estim-filters).
    ///
    /// Errors: `x` has fewer than `offset + 3` components (as [`AttitudeError::check`]); then
    /// neither q_ref nor `x` changes.
    pub fn recentre<N: Dim>(&mut self, x: &mut OVector<T, N>, offset: usize) -> Result<()>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.q = self.attitude(x, offset)?;
        self.q.renormalize();
        x.fixed_rows_mut::<3>(offset).fill(T::zero());
        Ok(())
    }

    /// q_ref ← q_ref ⊗ Exp(ω Δt) (a body rate ω held over Δt), renormalised.
    pub fn rotate(&mut self, omega: &Vector3<T>, dt: T) {
        self.q *= so3_exp(&(omega * dt));
        self.q.renormalize();
    }
}
