//! Augmenting a model with bias or Gauss-Markov states.
//!
//! [`Augmented`] appends K states with their own dynamics (typically a
//! [`RandomWalk`](crate::motion::RandomWalk) or [`GaussMarkov`](crate::motion::GaussMarkov))
//! to a process model of N states; [`Biased`] adds those states, through a coupling matrix
//! C, to a sensor's reading. The augmented state is x = (s, b), s the model's N states and b
//! the K appended ones:
//!
//! ```text
//! s⁺ = f(s, u, Δt),   b⁺ = g(b, Δt),    F = diag(∂f/∂s, ∂g/∂b),   Q = diag(Q_f, Q_g)
//! z  = h(s) + C b,                       H = [∂h/∂s  C],           R = R_h
//! ```
//!
//! The Hessians are the blocks' own, embedded (C b is linear). Static sizes: the augmented
//! size N + K is a third const parameter of the impl, checked at compile time (stable Rust
//! cannot write `Const<{N + K}>`), so a filter's `SVector<f64, 6>` state picks it.
//!
//! To keep such states out of the correction (carried, not estimated), update with
//! `estim_filters::consider::schmidt_update` and list their indices (N..N+K).

use estim_core::nalgebra::{Const, SMatrix, SVector};
use estim_core::{
    LinearMeasurementModel, LinearProcessModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel, Real,
};

/// The process model `model` (N states) with the K states of `augment` appended (see the
/// [module docs](self)).
///
/// ```
/// use estim_core::nalgebra::{Vector1, Vector3};
/// use estim_core::ProcessModel;
/// use estim_models::augment::Augmented;
/// use estim_models::motion::{ConstantVelocity, GaussMarkov, Noise};
///
/// // A 1-D constant-velocity target and a Gauss-Markov sensor bias: state (p, v, b).
/// let model = Augmented::<_, _, 2, 1> {
///     model: ConstantVelocity::<f64, 1>::new(Noise::Continuous(0.1)),
///     augment: GaussMarkov { time_constant: Vector1::new(10.0), variance: Vector1::new(0.04) },
/// };
/// let x = model.transition(&Vector3::new(0.0, 1.0, 0.2), &(), 10.0);
/// assert_eq!(x[0], 10.0);
/// assert!((x[2] - 0.2 * (-1.0f64).exp()).abs() < 1e-16);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Augmented<P, B, const N: usize, const K: usize> {
    /// The model of the first N states.
    pub model: P,
    /// The dynamics of the K appended states (no input).
    pub augment: B,
}

/// Checked at compile time: the augmented size is N + K.
const fn assert_sizes(n: usize, k: usize, nk: usize) {
    assert!(
        n + k == nk,
        "the augmented state must have N + K components"
    );
}

fn split<T: Real, const N: usize, const K: usize, const NK: usize>(
    x: &SVector<T, NK>,
) -> (SVector<T, N>, SVector<T, K>) {
    const { assert_sizes(N, K, NK) };
    (
        x.fixed_rows::<N>(0).into_owned(),
        x.fixed_rows::<K>(N).into_owned(),
    )
}

fn block_diag<T: Real, const N: usize, const K: usize, const NK: usize>(
    a: &SMatrix<T, N, N>,
    b: &SMatrix<T, K, K>,
) -> SMatrix<T, NK, NK> {
    const { assert_sizes(N, K, NK) };
    let mut m = SMatrix::<T, NK, NK>::zeros();
    m.fixed_view_mut::<N, N>(0, 0).copy_from(a);
    m.fixed_view_mut::<K, K>(N, N).copy_from(b);
    m
}

impl<T, P, B, const N: usize, const K: usize, const NK: usize> ProcessModel<T, Const<NK>>
    for Augmented<P, B, N, K>
where
    T: Real,
    P: ProcessModel<T, Const<N>>,
    B: ProcessModel<T, Const<K>, Input = ()>,
{
    type Input = P::Input;

    fn transition(&self, x: &SVector<T, NK>, u: &P::Input, dt: T) -> SVector<T, NK> {
        let (s, b) = split::<T, N, K, NK>(x);
        let mut y = SVector::<T, NK>::zeros();
        y.fixed_rows_mut::<N>(0)
            .copy_from(&self.model.transition(&s, u, dt));
        y.fixed_rows_mut::<K>(N)
            .copy_from(&self.augment.transition(&b, &(), dt));
        y
    }

    fn process_noise(&self, x: &SVector<T, NK>, u: &P::Input, dt: T) -> SMatrix<T, NK, NK> {
        let (s, b) = split::<T, N, K, NK>(x);
        block_diag(
            &self.model.process_noise(&s, u, dt),
            &self.augment.process_noise(&b, &(), dt),
        )
    }
}

impl<T, P, B, const N: usize, const K: usize, const NK: usize> ProcessJacobian<T, Const<NK>>
    for Augmented<P, B, N, K>
where
    T: Real,
    P: ProcessJacobian<T, Const<N>>,
    B: ProcessJacobian<T, Const<K>, Input = ()>,
{
    fn transition_jacobian(&self, x: &SVector<T, NK>, u: &P::Input, dt: T) -> SMatrix<T, NK, NK> {
        let (s, b) = split::<T, N, K, NK>(x);
        block_diag(
            &self.model.transition_jacobian(&s, u, dt),
            &self.augment.transition_jacobian(&b, &(), dt),
        )
    }
}

impl<T, P, B, const N: usize, const K: usize, const NK: usize> ProcessHessian<T, Const<NK>>
    for Augmented<P, B, N, K>
where
    T: Real,
    P: ProcessHessian<T, Const<N>>,
    B: ProcessHessian<T, Const<K>, Input = ()>,
{
    fn transition_hessian(
        &self,
        x: &SVector<T, NK>,
        u: &P::Input,
        dt: T,
        k: usize,
    ) -> Option<SMatrix<T, NK, NK>> {
        let (s, b) = split::<T, N, K, NK>(x);
        let mut h = SMatrix::<T, NK, NK>::zeros();
        if k < N {
            h.fixed_view_mut::<N, N>(0, 0)
                .copy_from(&self.model.transition_hessian(&s, u, dt, k)?);
        } else {
            h.fixed_view_mut::<K, K>(N, N)
                .copy_from(&self.augment.transition_hessian(&b, &(), dt, k - N)?);
        }
        Some(h)
    }
}

/// The sensor `model` (reading the first N states) with the appended states b added to its
/// reading through `coupling`: z = h(s) + C b (see the [module docs](self)).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, Vector2, Vector3};
/// use estim_core::{MeasurementJacobian, MeasurementModel};
/// use estim_models::augment::Biased;
/// use estim_models::sensors::Range;
///
/// // A range with an unknown offset b: state (x, y, b), z = ‖(x, y) − o‖ + b.
/// let ranging = Biased::<_, f64, 2, 1, 1> {
///     model: Range { origin: Vector2::zeros(), variance: 0.01 },
///     coupling: Matrix1::new(1.0),
/// };
/// let x = Vector3::new(3.0, 4.0, 0.5);
/// assert_eq!(ranging.measure(&x), Vector1::new(5.5));
/// assert_eq!(ranging.measurement_jacobian(&x)[(0, 2)], 1.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Biased<H, T, const N: usize, const M: usize, const K: usize> {
    /// The sensor, on the first N states.
    pub model: H,
    /// C, how the K appended states enter the M components of the reading.
    pub coupling: SMatrix<T, M, K>,
}

impl<T, H, const N: usize, const M: usize, const K: usize, const NK: usize>
    MeasurementModel<T, Const<NK>, Const<M>> for Biased<H, T, N, M, K>
where
    T: Real,
    H: MeasurementModel<T, Const<N>, Const<M>>,
{
    fn measure(&self, x: &SVector<T, NK>) -> SVector<T, M> {
        let (s, b) = split::<T, N, K, NK>(x);
        self.model.measure(&s) + self.coupling * b
    }

    fn measurement_noise(&self, x: &SVector<T, NK>) -> SMatrix<T, M, M> {
        self.model.measurement_noise(&split::<T, N, K, NK>(x).0)
    }

    fn residual_into(&self, a: &SVector<T, M>, b: &SVector<T, M>, out: &mut SVector<T, M>) {
        self.model.residual_into(a, b, out);
    }
}

impl<T, H, const N: usize, const M: usize, const K: usize, const NK: usize>
    MeasurementJacobian<T, Const<NK>, Const<M>> for Biased<H, T, N, M, K>
where
    T: Real,
    H: MeasurementJacobian<T, Const<N>, Const<M>>,
{
    fn measurement_jacobian(&self, x: &SVector<T, NK>) -> SMatrix<T, M, NK> {
        let (s, _) = split::<T, N, K, NK>(x);
        let mut j = SMatrix::<T, M, NK>::zeros();
        j.fixed_view_mut::<M, N>(0, 0)
            .copy_from(&self.model.measurement_jacobian(&s));
        j.fixed_view_mut::<M, K>(0, N).copy_from(&self.coupling);
        j
    }
}

impl<T, H, const N: usize, const M: usize, const K: usize, const NK: usize>
    MeasurementHessian<T, Const<NK>, Const<M>> for Biased<H, T, N, M, K>
where
    T: Real,
    H: MeasurementHessian<T, Const<N>, Const<M>>,
{
    fn measurement_hessian(&self, x: &SVector<T, NK>, k: usize) -> Option<SMatrix<T, NK, NK>> {
        let (s, _) = split::<T, N, K, NK>(x);
        let mut h = SMatrix::<T, NK, NK>::zeros();
        h.fixed_view_mut::<N, N>(0, 0)
            .copy_from(&self.model.measurement_hessian(&s, k)?);
        Some(h)
    }
}

impl<T, P, B, const N: usize, const K: usize, const NK: usize> LinearProcessModel<T, Const<NK>>
    for Augmented<P, B, N, K>
where
    T: Real,
    P: LinearProcessModel<T, Const<N>>,
    B: LinearProcessModel<T, Const<K>, Input = ()>,
{
}

impl<T, H, const N: usize, const M: usize, const K: usize, const NK: usize>
    LinearMeasurementModel<T, Const<NK>, Const<M>> for Biased<H, T, N, M, K>
where
    T: Real,
    H: LinearMeasurementModel<T, Const<N>, Const<M>>,
{
}
