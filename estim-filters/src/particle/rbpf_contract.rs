//! The estimator contract of the Rao-Blackwellised filter: the joint mixture moments
//! ([`Estimator`]), bit-exact snapshots ([`Rollback`]) and the step traits ([`Predict`],
//! [`Update`]) on the joint state x = (xn, xl), so the filter runs in the fusion driver and
//! the sequence functions.

use estim_core::nalgebra::{DefaultAllocator, Dim, DimAdd, DimSum, OMatrix, OVector, U1};
use estim_core::{Alloc, Gaussian, Real, Stage, error::Result, psd_factor};

use super::fill_normals;
use super::rbpf::{
    ConditionallyLinearMeasurement, ConditionallyLinearProcess, RaoBlackwellised,
    RaoBlackwellisedSnapshot,
};
use super::rng::ParticleRng;
use crate::report::UpdateReport;
use crate::traits::{Estimator, Predict, ProcessInput, Rollback, Update};

impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> RaoBlackwellisedSnapshot<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    /// Copies `other` into `self`, reusing the buffers when the shapes agree.
    fn copy_from(&mut self, other: &Self) {
        if self.nonlinear.shape() == other.nonlinear.shape() {
            self.nonlinear.copy_from(&other.nonlinear);
        } else {
            self.nonlinear = other.nonlinear.clone();
        }
        self.linear.clone_from(&other.linear);
        self.log_weights.clone_from(&other.log_weights);
        self.step = other.step;
        self.log_likelihood = other.log_likelihood;
        if self.mean.shape() == other.mean.shape() {
            self.mean.copy_from(&other.mean);
            self.covariance.copy_from(&other.covariance);
        } else {
            self.mean = other.mean.clone();
            self.covariance = other.covariance.clone();
        }
    }
}

impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> RaoBlackwellised<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    /// The joint mixture moments of x = (xn, xl) from the particles and their filters:
    /// x̂ = Σ Wⁱ (xnⁱ, x̂lⁱ) and P = Σ Wⁱ (dⁱdⁱᵀ + diag(0, Plⁱ)), dⁱ = (xnⁱ, x̂lⁱ) − x̂
    /// (xnⁱ is a point given the particle, so its own covariance and cross-covariance with
    /// xl are zero), made exactly symmetric. Allocates nothing.
    pub(super) fn update_moments(&mut self) {
        let s = &mut self.state;
        let d = &mut self.work.d;
        let nn = s.nonlinear.nrows();
        let nl = s.linear[0].state().nrows();
        s.mean.fill(T::zero());
        for (i, &lw) in s.log_weights.iter().enumerate() {
            let w = lw.exp();
            for r in 0..nn {
                s.mean[r] += w * s.nonlinear[(r, i)];
            }
            let xl = s.linear[i].state();
            for r in 0..nl {
                s.mean[nn + r] += w * xl[r];
            }
        }
        s.covariance.fill(T::zero());
        for (i, &lw) in s.log_weights.iter().enumerate() {
            let w = lw.exp();
            for r in 0..nn {
                d[r] = s.nonlinear[(r, i)] - s.mean[r];
            }
            let kf = &s.linear[i];
            for r in 0..nl {
                d[nn + r] = kf.state()[r] - s.mean[nn + r];
            }
            s.covariance.ger(w, d, d, T::one());
            let p = kf.covariance();
            for c in 0..nl {
                for r in 0..nl {
                    s.covariance[(nn + r, nn + c)] += w * p[(r, c)];
                }
            }
        }
        estim_core::checks::symmetrize(&mut s.covariance);
    }
}

impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> PartialEq for RaoBlackwellised<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    /// Equal configuration and equal state (to the bit, NaN aside); the work buffers are
    /// ignored.
    fn eq(&self, other: &Self) -> bool {
        self.seed == other.seed
            && self.scheme == other.scheme
            && self.when == other.when
            && self.state == other.state
    }
}

/// The estimate of the joint state x = (xn, xl) (xn first): the mixture moments
/// x̂ = (x̂n, x̂l) and P = Σ Wⁱ (dⁱdⁱᵀ + diag(0, Plⁱ)), whose blocks are
/// [`nonlinear_covariance`](RaoBlackwellised::nonlinear_covariance),
/// [`linear_covariance`](RaoBlackwellised::linear_covariance) and the cross-covariance
/// Σ Wⁱ (xnⁱ − x̂n)(x̂lⁱ − x̂l)ᵀ.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix2, Vector1, Vector2};
/// use estim_core::Gaussian;
/// use estim_filters::Estimator;
/// use estim_filters::particle::RaoBlackwellised;
///
/// let xn = Gaussian::new(Vector1::new(1.0f64), Matrix1::new(0.5))?;
/// let xl = Gaussian::new(Vector1::new(2.0), Matrix1::new(3.0))?;
/// let mut rbpf = RaoBlackwellised::new(xn, xl, 2000, 3)?;
/// assert_eq!(rbpf.state()[1], rbpf.linear_mean()[0]);
/// assert!((rbpf.covariance()[(1, 1)] - 3.0).abs() < 1e-12); // every filter holds Pl = 3
/// assert!(rbpf.covariance()[(0, 1)].abs() < 1e-12); // independent a priori
/// // A reset conditions xl on each drawn xn: here x̂lⁱ = 2 + 0.5 (xnⁱ − 1) / 0.5.
/// rbpf.reset(Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::new(0.5, 0.5, 0.5, 3.0))?);
/// let p = rbpf.covariance();
/// assert!((p[(0, 1)] - p[(0, 0)]).abs() < 1e-12); // cov(xn, xl) = Pnn · 1
/// # Ok::<(), estim_core::Error>(())
/// ```
impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> Estimator<T, DimSum<Nn, Nl>> for RaoBlackwellised<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    fn state(&self) -> &OVector<T, DimSum<Nn, Nl>> {
        &self.state.mean
    }

    fn covariance(&self) -> &OMatrix<T, DimSum<Nn, Nl>, DimSum<Nn, Nl>> {
        &self.state.covariance
    }

    /// Restarts from the joint prior N(μ, P) on (xn, xl), with this filter's seed, count
    /// and split: xnⁱ drawn from N(μn, Pnn) on the streams (seed, 0, i) as in
    /// [`RaoBlackwellised::new`], each Kalman filter started at the conditional
    /// N(μl + G (xnⁱ − μn), Pll − G Pnl), G = Pln Pnn⁻¹; equal weights, step 1,
    /// log-likelihood 0. With independent blocks this is exactly `new(N(μn, Pnn), N(μl, Pll))`.
    /// A singular Pnn (no G) drops the xn–xl correlation (G = 0); a Pnn that is not positive
    /// semi-definite (only possible with [`Gaussian::new_unchecked`]) puts every xnⁱ at μn.
    ///
    /// # Panics
    ///
    /// If the prior's dimension is not nn + nl (the split of this filter).
    #[track_caller]
    fn reset(&mut self, prior: Gaussian<T, DimSum<Nn, Nl>>) {
        let (n, _) = self.state.nonlinear.shape_generic();
        let (l, _) = self.state.linear[0].state().shape_generic();
        let (nn, nl) = (n.value(), l.value());
        assert_eq!(
            prior.mean().nrows(),
            nn + nl,
            "RaoBlackwellised::reset: the prior must have nn + nl = {} components",
            nn + nl
        );
        let mu_n = prior.mean().generic_view((0, 0), (n, U1)).clone_owned();
        let mu_l = prior.mean().generic_view((nn, 0), (l, U1)).clone_owned();
        let p = prior.covariance();
        let pnn = p.generic_view((0, 0), (n, n)).clone_owned();
        let pnl = p.generic_view((0, nn), (n, l)).clone_owned();
        let pll = p.generic_view((nn, nn), (l, l)).clone_owned();
        // Gᵀ = Pnn⁻¹ Pnl.
        let gain_t = match pnn.clone().cholesky() {
            Some(chol) if pnl.iter().any(|&v| v != T::zero()) => chol.solve(&pnl),
            _ => OMatrix::zeros_generic(n, l),
        };
        let mut conditional = pll;
        conditional.gemm_tr(-T::one(), &gain_t, &pnl, T::one());
        estim_core::checks::symmetrize(&mut conditional);
        let factor =
            psd_factor(&pnn, Stage::Construction).unwrap_or_else(|_| OMatrix::zeros_generic(n, n));
        let seed = self.seed;
        let s = &mut self.state;
        let normals = &mut self.work.normals;
        for i in 0..s.log_weights.len() {
            fill_normals(normals, &mut ParticleRng::stream(seed, 0, i as u64));
            let mut column = s.nonlinear.column_mut(i);
            column.copy_from(&mu_n);
            column.gemv(T::one(), &factor, normals, T::one());
            let offset = s.nonlinear.column(i) - &mu_n;
            let mut mean = mu_l.clone();
            mean.gemv_tr(T::one(), &gain_t, &offset, T::one());
            s.linear[i].reset(Gaussian::new_unchecked(mean, conditional.clone()));
        }
        let uniform = -estim_core::scalar::real::<T>(s.log_weights.len() as f64).ln();
        s.log_weights.fill(uniform);
        s.step = 1;
        s.log_likelihood = T::zero();
        self.update_moments();
    }
}

/// The snapshot is the particles, their Kalman filters and log-weights, the random step
/// counter (so a restore replays the same random bits), the running log-likelihood and the
/// joint moments; not the configuration (seed, scheme, trigger).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::Gaussian;
/// use estim_filters::Rollback;
/// use estim_filters::particle::{
///     ConditionalMeasurement, ConditionalTransition, ConditionallyLinearMeasurement,
///     ConditionallyLinearProcess, RaoBlackwellised,
/// };
///
/// /// Position xn, velocity xl: xn⁺ = xn + xl + wn, xl⁺ = xl + wl; z = xn + v.
/// struct Cv;
/// impl ConditionallyLinearProcess<f64, U1, U1> for Cv {
///     type Input = ();
///     fn conditional_transition(&self, xn: &Vector1<f64>, _: &(), dt: f64) -> ConditionalTransition<f64, U1, U1> {
///         ConditionalTransition {
///             nonlinear_mean: *xn,
///             coupling: Matrix1::new(dt),
///             nonlinear_noise: Matrix1::new(0.1),
///             linear_mean: Vector1::zeros(),
///             linear_transition: Matrix1::new(1.0),
///             linear_noise: Matrix1::new(0.01),
///         }
///     }
/// }
/// struct Position;
/// impl ConditionallyLinearMeasurement<f64, U1, U1, U1> for Position {
///     fn conditional_measurement(&self, xn: &Vector1<f64>) -> ConditionalMeasurement<f64, U1, U1> {
///         ConditionalMeasurement { offset: *xn, observation: Matrix1::zeros(), noise: Matrix1::new(0.25) }
///     }
/// }
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let mut rbpf = RaoBlackwellised::new(prior.clone(), prior, 100, 3)?;
/// let saved = rbpf.snapshot();
/// rbpf.predict(&Cv, &(), 1.0)?;
/// rbpf.update(&Position, &Vector1::new(0.4))?;
/// let first = rbpf.clone();
/// rbpf.restore(&saved);
/// rbpf.predict(&Cv, &(), 1.0)?;
/// rbpf.update(&Position, &Vector1::new(0.4))?;
/// assert_eq!(rbpf, first); // the same bits, resampling and noise included
/// # Ok::<(), estim_core::Error>(())
/// ```
impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> Rollback for RaoBlackwellised<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    type Snapshot = RaoBlackwellisedSnapshot<T, Nn, Nl>;

    fn snapshot(&self) -> Self::Snapshot {
        self.state.clone()
    }

    /// Reuses the snapshot's buffers when the shapes agree.
    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        snapshot.copy_from(&self.state);
    }

    /// A snapshot of another particle count or size (from another filter) also restores:
    /// the work buffers are resized (allocating) to match it.
    fn restore(&mut self, snapshot: &Self::Snapshot) {
        self.state.copy_from(snapshot);
        let s = &self.state;
        if self.work.linear.len() != s.linear.len()
            || self.work.nonlinear.shape() != s.nonlinear.shape()
            || self.work.d.nrows() != s.mean.nrows()
        {
            let (n, _) = s.nonlinear.shape_generic();
            let (l, _) = s.linear[0].state().shape_generic();
            self.work = super::rbpf::RbWork::new(n, l, &s.linear);
        }
    }
}

/// [`RaoBlackwellised::predict`] through the step trait. The joint state has no
/// [`ProcessModel`](estim_core::ProcessModel), so the process names its input on the joint
/// dimension itself (one line, for a type with a concrete scalar and sizes, as for the
/// IMM's [`ModeModels`](crate::imm::ModeModels)):
///
/// ```
/// # use estim_core::nalgebra::{Matrix1, Vector1, U1, U2};
/// # use estim_filters::particle::{ConditionalTransition, ConditionallyLinearProcess};
/// use estim_filters::ProcessInput;
/// struct Cv;
/// # impl ConditionallyLinearProcess<f64, U1, U1> for Cv {
/// #     type Input = ();
/// #     fn conditional_transition(&self, xn: &Vector1<f64>, _: &(), dt: f64) -> ConditionalTransition<f64, U1, U1> {
/// #         ConditionalTransition { nonlinear_mean: *xn, coupling: Matrix1::new(dt), nonlinear_noise: Matrix1::new(0.1),
/// #             linear_mean: Vector1::zeros(), linear_transition: Matrix1::new(1.0), linear_noise: Matrix1::new(0.01) }
/// #     }
/// # }
/// impl ProcessInput<f64, U2> for Cv {
///     type Input = (); // the same as its ConditionallyLinearProcess::Input
/// }
/// ```
impl<T, Nn, Nl, P> Predict<T, DimSum<Nn, Nl>, P> for RaoBlackwellised<T, Nn, Nl>
where
    T: Real,
    Nn: DimAdd<Nl>,
    Nl: Dim,
    P: ConditionallyLinearProcess<T, Nn, Nl>
        + ProcessInput<T, DimSum<Nn, Nl>, Input = <P as ConditionallyLinearProcess<T, Nn, Nl>>::Input>
        + ?Sized,
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    fn predict(
        &mut self,
        model: &P,
        input: &<P as ProcessInput<T, DimSum<Nn, Nl>>>::Input,
        dt: T,
    ) -> Result<()> {
        RaoBlackwellised::predict(self, model, input, dt)
    }
}

/// [`RaoBlackwellised::update_into`] through the step trait.
impl<T, Nn, Nl, M, H> Update<T, DimSum<Nn, Nl>, M, H> for RaoBlackwellised<T, Nn, Nl>
where
    T: Real,
    Nn: DimAdd<Nl>,
    Nl: Dim,
    M: Dim,
    H: ConditionallyLinearMeasurement<T, Nn, Nl, M> + ?Sized,
    DefaultAllocator: Alloc<Nn, Nl>
        + Alloc<DimSum<Nn, Nl>, Nn>
        + Alloc<DimSum<Nn, Nl>, M>
        + Alloc<Nl, M>
        + Alloc<Nn, M>,
{
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        RaoBlackwellised::update_into(self, model, z, report)
    }
}
