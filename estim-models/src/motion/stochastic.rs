//! Random-walk and first-order Gauss-Markov states (biases, drifts, slowly varying offsets).

use estim_core::nalgebra::{Const, SMatrix, SVector};
use estim_core::{LinearProcessModel, ProcessHessian, ProcessJacobian, ProcessModel, Real};

/// N independent random walks: x⁺ = x, Q = diag(q) Δt, qᵢ the power spectral density of
/// component i's white-noise derivative (units²/s). Exact for any Δt.
///
/// ```
/// use estim_core::nalgebra::Vector2;
/// use estim_core::ProcessModel;
/// use estim_models::motion::RandomWalk;
///
/// let walk = RandomWalk { psd: Vector2::new(1e-4, 4e-4) };
/// let x = Vector2::new(0.3, -0.1);
/// assert_eq!(walk.transition(&x, &(), 2.0), x);
/// assert_eq!(walk.process_noise(&x, &(), 2.0)[(1, 1)], 8e-4);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RandomWalk<T, const N: usize> {
    /// qᵢ ≥ 0 per component, units²/s.
    pub psd: SVector<T, N>,
}

impl<T: Real, const N: usize> ProcessModel<T, Const<N>> for RandomWalk<T, N> {
    type Input = ();

    fn transition(&self, x: &SVector<T, N>, _: &(), _: T) -> SVector<T, N> {
        *x
    }

    fn process_noise(&self, _: &SVector<T, N>, _: &(), dt: T) -> SMatrix<T, N, N> {
        SMatrix::from_diagonal(&(self.psd * dt))
    }
}

impl<T: Real, const N: usize> ProcessJacobian<T, Const<N>> for RandomWalk<T, N> {
    fn transition_jacobian(&self, _: &SVector<T, N>, _: &(), _: T) -> SMatrix<T, N, N> {
        SMatrix::identity()
    }
}

impl<T: Real, const N: usize> ProcessHessian<T, Const<N>> for RandomWalk<T, N> {
    fn transition_hessian(
        &self,
        _: &SVector<T, N>,
        _: &(),
        _: T,
        _: usize,
    ) -> Option<SMatrix<T, N, N>> {
        None
    }
}

impl<T: Real, const N: usize> LinearProcessModel<T, Const<N>> for RandomWalk<T, N> {}

/// N independent first-order Gauss-Markov processes ẋᵢ = −xᵢ/τᵢ + wᵢ, with correlation
/// time τᵢ > 0 and steady-state variance σᵢ² (so wᵢ has density 2σᵢ²/τᵢ). Exactly discretised:
///
/// ```text
/// xᵢ⁺ = e^{−Δt/τᵢ} xᵢ,    Qᵢᵢ = σᵢ² (1 − e^{−2Δt/τᵢ})   (computed with exp_m1: exact for small Δt)
/// ```
///
/// τ → ∞ tends to a constant, τ → 0 to white noise of variance σ²; the autocorrelation is
/// σ² e^{−|t−s|/τ}, the same for any sampling of the times.
///
/// ```
/// use estim_core::nalgebra::Vector1;
/// use estim_core::ProcessModel;
/// use estim_models::motion::GaussMarkov;
///
/// let bias = GaussMarkov { time_constant: Vector1::new(100.0), variance: Vector1::new(0.04) };
/// let x = bias.transition(&Vector1::new(1.0), &(), 100.0);
/// assert!((x[0] - (-1.0f64).exp()).abs() < 1e-16);
/// let q = bias.process_noise(&x, &(), 100.0);
/// assert!((q[(0, 0)] - 0.04 * (1.0 - (-2.0f64).exp())).abs() < 1e-17);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussMarkov<T, const N: usize> {
    /// τᵢ > 0 per component, seconds.
    pub time_constant: SVector<T, N>,
    /// σᵢ² ≥ 0, the steady-state variance per component.
    pub variance: SVector<T, N>,
}

impl<T: Real, const N: usize> GaussMarkov<T, N> {
    /// The decay factors e^{−Δt/τᵢ}.
    fn decay(&self, dt: T) -> SVector<T, N> {
        self.time_constant.map(|tau| (-dt / tau).exp())
    }
}

impl<T: Real, const N: usize> ProcessModel<T, Const<N>> for GaussMarkov<T, N> {
    type Input = ();

    fn transition(&self, x: &SVector<T, N>, _: &(), dt: T) -> SVector<T, N> {
        self.decay(dt).component_mul(x)
    }

    fn process_noise(&self, _: &SVector<T, N>, _: &(), dt: T) -> SMatrix<T, N, N> {
        let two = T::one() + T::one();
        SMatrix::from_fn(|i, j| {
            if i == j {
                -self.variance[i] * (-two * dt / self.time_constant[i]).exp_m1()
            } else {
                T::zero()
            }
        })
    }
}

impl<T: Real, const N: usize> ProcessJacobian<T, Const<N>> for GaussMarkov<T, N> {
    fn transition_jacobian(&self, _: &SVector<T, N>, _: &(), dt: T) -> SMatrix<T, N, N> {
        SMatrix::from_diagonal(&self.decay(dt))
    }
}

impl<T: Real, const N: usize> ProcessHessian<T, Const<N>> for GaussMarkov<T, N> {
    fn transition_hessian(
        &self,
        _: &SVector<T, N>,
        _: &(),
        _: T,
        _: usize,
    ) -> Option<SMatrix<T, N, N>> {
        None
    }
}

impl<T: Real, const N: usize> LinearProcessModel<T, Const<N>> for GaussMarkov<T, N> {}
