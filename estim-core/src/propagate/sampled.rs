//! Monte Carlo moments: the reference the approximations are tested against.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use super::{MomentPropagator, Outputs, PropagatorWorkspace, check_inputs};
use crate::alloc::Alloc;
use crate::checks::{ensure_shape, symmetrize};
use crate::error::{Error, Parameter, Quantity, Result, Stage};
use crate::function::VectorFunction;
use crate::linalg::psd_factor;
use crate::scalar::{Real, real};

/// Seeded Monte Carlo: draws `samples` points xᵢ = μ + L zᵢ (L Lᵀ = C, zᵢ ~ N(0, I)) and
/// returns the sample mean, the unbiased sample covariance of yᵢ = g(xᵢ), and the sample
/// cross-covariance.
///
/// Deviations are accumulated relative to g(μ) through the function's
/// [`difference_into`](VectorFunction::difference_into), which avoids cancellation and handles
/// wrapped outputs. The same seed gives the same result. The standard error of each mean component
/// is √(cov(y)ₖₖ / N); use it to set test tolerances. Requirements on g: [`VectorFunction`]. Vector
/// states only: the draws are μ + L zᵢ, not μ ⊞ L zᵢ (the input's ⊞ is not used).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sampled {
    samples: usize,
    seed: u64,
}

impl Sampled {
    /// `samples` ≥ 2 draws from a generator seeded with `seed`.
    pub fn new(samples: usize, seed: u64) -> Result<Self> {
        if samples < 2 {
            return Err(Error::InvalidParameter {
                parameter: Parameter::SampleCount,
                value: samples as f64,
            });
        }
        Ok(Self { samples, seed })
    }

    /// The number of samples N.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// The seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }
}

impl<T: Real> PropagatorWorkspace<T> for Sampled {
    type Workspace<N: Dim, M: Dim>
        = ()
    where
        DefaultAllocator: Alloc<N, M>;
}

impl<T, N, M, G> MomentPropagator<T, N, M, G> for Sampled
where
    T: Real,
    N: Dim,
    M: Dim,
    G: VectorFunction<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M>,
{
    /// The reference propagator allocates its accumulators on every call (it is for tests,
    /// not for filter steps); the workspace only fixes the dimensions.
    fn propagate_into(
        &self,
        mean: &OVector<T, N>,
        covariance: &OMatrix<T, N, N>,
        g: &G,
        mut out: Outputs<'_, T, N, M>,
        _: &mut (),
    ) -> Result<()> {
        let (n_dim, m_dim) = check_inputs(mean, covariance, &mut out)?;
        let m = m_dim.value();
        let l = psd_factor(covariance, Stage::Propagation)?;
        let y0 = g.eval(mean);
        ensure_shape(&y0, m, 1, Stage::Propagation, Quantity::FunctionValue)?;

        let mut rng = StdRng::seed_from_u64(self.seed);
        let mut z = OVector::<T, N>::zeros_generic(n_dim, U1);
        let mut dx = z.clone();
        let mut x = mean.clone();
        let mut sum_dx = z.clone();
        let mut sum_d = OVector::<T, M>::zeros_generic(m_dim, U1);
        let mut sum_dd = OMatrix::<T, M, M>::zeros_generic(m_dim, m_dim);
        let mut sum_xd = OMatrix::<T, N, M>::zeros_generic(n_dim, m_dim);
        for _ in 0..self.samples {
            for zi in z.iter_mut() {
                let s: f64 = StandardNormal.sample(&mut rng);
                *zi = real(s);
            }
            dx.gemv(T::one(), &l, &z, T::zero());
            x.copy_from(mean);
            x += &dx;
            let y = g.eval(&x);
            ensure_shape(&y, m, 1, Stage::Propagation, Quantity::FunctionValue)?;
            let mut d = y.clone();
            g.difference_into(&y, &y0, &mut d);
            ensure_shape(&d, m, 1, Stage::Propagation, Quantity::FunctionValue)?;
            sum_dx += &dx;
            sum_d += &d;
            sum_dd.ger(T::one(), &d, &d, T::one());
            sum_xd.ger(T::one(), &dx, &d, T::one());
        }
        let count = real::<T>(self.samples as f64);
        let d_bar = sum_d / count;
        let dx_bar = sum_dx / count;
        // Unbiased: (Σ d dᵀ − N d̄ d̄ᵀ) / (N − 1), and likewise for the cross term.
        let scale = T::one() / (count - T::one());
        let mut covariance_y = sum_dd * scale;
        covariance_y.ger(-count * scale, &d_bar, &d_bar, T::one());
        let mut cross = sum_xd * scale;
        cross.ger(-count * scale, &dx_bar, &d_bar, T::one());
        *out.mean = y0 + d_bar;
        *out.covariance = covariance_y;
        // Σ d dᵀ is symmetric only up to round-off: average the triangles before `finish`
        // takes the lower one.
        symmetrize(out.covariance);
        if let Some(out_cross) = out.cross_covariance.as_deref_mut() {
            *out_cross = cross;
        }
        out.finish()
    }
}
