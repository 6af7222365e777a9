//! Constant velocity and constant acceleration in 1, 2 and 3 dimensions.
//!
//! One type per model, generic over the dimension D ∈ {1, 2, 3}
//! ([`ConstantVelocity<T, D>`], [`ConstantAcceleration<T, D>`]); the state size (2D or 3D)
//! is a static `Const`, so the models live on the stack. The state is ordered **by block**:
//!
//! ```text
//! CV: x = (p₁..p_D, v₁..v_D)             CA: x = (p₁..p_D, v₁..v_D, a₁..a_D)
//! ```
//!
//! so position is always the first D components (the [`sensors`](crate::sensors) read it
//! there). Per axis the model is a chain of K integrators (K = 2 for CV, 3 for CA):
//!
//! ```text
//! x⁺ = F x,   F = F₁ ⊗ I_D,   (F₁)ᵢⱼ = Δt^{j−i}/(j−i)!  (j ≥ i),   e.g. CV: F₁ = [1 Δt; 0 1]
//! Q  = Q₁ ⊗ I_D   (the axes independent, with the same intensity)
//! ```
//!
//! with Q₁ from [`Noise`]: continuous white noise on the highest derivative (exact for any
//! Δt, [`continuous_white_noise`](super::continuous_white_noise)) or FilterPy's discrete form
//! ([`discrete_white_noise`](super::discrete_white_noise)). The models are linear: the linear
//! Kalman filter takes them, and their Hessians are `None` (no cost in the second-order
//! filters).

use estim_core::nalgebra::{SMatrix, SVector, U2, U3, U4, U6, U9};
use estim_core::{LinearProcessModel, ProcessHessian, ProcessJacobian, ProcessModel, Real};

use super::discretize::{continuous_white_noise_unchecked, discrete_white_noise_unchecked};

/// How the noise of a kinematic model enters, per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Noise<T> {
    /// Continuous white noise on the highest derivative, of power spectral density q (CV:
    /// white acceleration, m²/s³; CA: white jerk, m²/s⁵). Exact for any Δt: the intensity does
    /// not depend on the step, so irregular steps need no retuning.
    Continuous(T),
    /// FilterPy's `Q_discrete_white_noise(K, Δt, σ²)` with this variance σ² (CV: the
    /// acceleration held constant over each step, m²/s⁴; CA: the acceleration's increment per
    /// step, m²/s⁴).
    Discrete(T),
}

impl<T: Real> Noise<T> {
    /// Q₁ of one axis of a K-integrator chain.
    fn per_axis<const K: usize>(&self, dt: T) -> SMatrix<T, K, K> {
        match *self {
            Noise::Continuous(q) => continuous_white_noise_unchecked::<T, K>(dt, q),
            Noise::Discrete(v) => discrete_white_noise_unchecked::<T, K>(dt, v),
        }
    }
}

/// Constant velocity in D dimensions (D = 1, 2, 3): state (p, v), 2D components, by block.
///
/// ```text
/// p⁺ = p + Δt v,   v⁺ = v,   Q = Q₁ ⊗ I_D  (Noise::Continuous(q): Q₁ = q [Δt³/3 Δt²/2; Δt²/2 Δt])
/// ```
///
/// ```
/// use estim_core::nalgebra::Vector4;
/// use estim_core::ProcessModel;
/// use estim_models::motion::{ConstantVelocity, Noise};
///
/// let cv = ConstantVelocity::<f64, 2>::new(Noise::Continuous(0.1));
/// let x = Vector4::new(0.0, 1.0, 2.0, -1.0); // p = (0, 1), v = (2, −1)
/// assert_eq!(cv.transition(&x, &(), 0.5), Vector4::new(1.0, 0.5, 2.0, -1.0));
/// let q = cv.process_noise(&x, &(), 0.5);
/// assert!((q[(0, 2)] - 0.1 * 0.125).abs() < 1e-16); // q Δt²/2, position–velocity, axis 1
/// assert_eq!(q[(0, 3)], 0.0); // the axes are independent
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantVelocity<T, const D: usize> {
    /// The noise on the acceleration.
    pub noise: Noise<T>,
}

impl<T, const D: usize> ConstantVelocity<T, D> {
    /// A constant-velocity model with this acceleration noise.
    pub fn new(noise: Noise<T>) -> Self {
        Self { noise }
    }
}

/// Constant acceleration in D dimensions (D = 1, 2, 3): state (p, v, a), 3D components, by
/// block.
///
/// ```text
/// p⁺ = p + Δt v + Δt²/2 a,   v⁺ = v + Δt a,   a⁺ = a,   Q = Q₁ ⊗ I_D
/// Noise::Continuous(q): Q₁ = q [Δt⁵/20 Δt⁴/8 Δt³/6; Δt⁴/8 Δt³/3 Δt²/2; Δt³/6 Δt²/2 Δt]
/// ```
///
/// ```
/// use estim_core::nalgebra::Vector3;
/// use estim_core::ProcessModel;
/// use estim_models::motion::{ConstantAcceleration, Noise};
///
/// let ca = ConstantAcceleration::<f64, 1>::new(Noise::Continuous(0.1));
/// let x = Vector3::new(0.0, 1.0, 2.0); // p, v, a
/// assert_eq!(ca.transition(&x, &(), 1.0), Vector3::new(2.0, 3.0, 2.0));
/// assert!((ca.process_noise(&x, &(), 1.0)[(0, 0)] - 0.1 / 20.0).abs() < 1e-17);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantAcceleration<T, const D: usize> {
    /// The noise on the jerk.
    pub noise: Noise<T>,
}

impl<T, const D: usize> ConstantAcceleration<T, D> {
    /// A constant-acceleration model with this jerk noise.
    pub fn new(noise: Noise<T>) -> Self {
        Self { noise }
    }
}

/// F₁ ⊗ I_D for a K-chain, state of N = K·D components by block.
fn chain_transition_matrix<T: Real, const K: usize, const D: usize, const N: usize>(
    dt: T,
) -> SMatrix<T, N, N> {
    const { assert!(N == K * D) };
    let mut f = SMatrix::<T, N, N>::zeros();
    let mut coeff = [T::one(); K];
    // coeff[k] = Δt^k / k!
    for k in 1..K {
        coeff[k] = coeff[k - 1] * dt / estim_core::scalar::real::<T>(k as f64);
    }
    for i in 0..K {
        for j in i..K {
            for a in 0..D {
                f[(i * D + a, j * D + a)] = coeff[j - i];
            }
        }
    }
    f
}

/// Q₁ ⊗ I_D.
fn per_axis_to_state<T: Real, const K: usize, const D: usize, const N: usize>(
    q1: &SMatrix<T, K, K>,
) -> SMatrix<T, N, N> {
    const { assert!(N == K * D) };
    let mut q = SMatrix::<T, N, N>::zeros();
    for i in 0..K {
        for j in 0..K {
            for a in 0..D {
                q[(i * D + a, j * D + a)] = q1[(i, j)];
            }
        }
    }
    q
}

macro_rules! chain_model {
    ($ty:ident, $k:literal, $d:literal, $n:literal, $dim:ty) => {
        impl<T: Real> ProcessModel<T, $dim> for $ty<T, $d> {
            type Input = ();

            fn transition(&self, x: &SVector<T, $n>, _: &(), dt: T) -> SVector<T, $n> {
                chain_transition_matrix::<T, $k, $d, $n>(dt) * x
            }

            fn process_noise(&self, _: &SVector<T, $n>, _: &(), dt: T) -> SMatrix<T, $n, $n> {
                per_axis_to_state::<T, $k, $d, $n>(&self.noise.per_axis::<$k>(dt))
            }
        }

        impl<T: Real> ProcessJacobian<T, $dim> for $ty<T, $d> {
            fn transition_jacobian(&self, _: &SVector<T, $n>, _: &(), dt: T) -> SMatrix<T, $n, $n> {
                chain_transition_matrix::<T, $k, $d, $n>(dt)
            }
        }

        impl<T: Real> ProcessHessian<T, $dim> for $ty<T, $d> {
            fn transition_hessian(
                &self,
                _: &SVector<T, $n>,
                _: &(),
                _: T,
                _: usize,
            ) -> Option<SMatrix<T, $n, $n>> {
                None
            }
        }

        impl<T: Real> LinearProcessModel<T, $dim> for $ty<T, $d> {}
    };
}

chain_model!(ConstantVelocity, 2, 1, 2, U2);
chain_model!(ConstantVelocity, 2, 2, 4, U4);
chain_model!(ConstantVelocity, 2, 3, 6, U6);
chain_model!(ConstantAcceleration, 3, 1, 3, U3);
chain_model!(ConstantAcceleration, 3, 2, 6, U6);
chain_model!(ConstantAcceleration, 3, 3, 9, U9);
