//! The Rao-Blackwellised particle filter (documented on [`RaoBlackwellised`]).

use estim_core::checks::{ensure_finite, ensure_shape, symmetrize};
use estim_core::linalg::inverse_quadratic_form;
use estim_core::nalgebra::{DefaultAllocator, Dim, DimAdd, DimSum, Dyn, OMatrix, OVector, U1};
use estim_core::{
    Alloc, Error, Gaussian, LinearMeasurement, LinearProcess, Quantity, Real, Stage, error::Result,
    psd_factor,
};

use super::resample::{effective_sample_size, normaliser, resample_with, to_f64};
use super::rng::{ParticleRng, RESAMPLE};
use super::{ResampleWhen, Resampling, check_count, check_trigger, fill_normals};
use crate::gaussian_filter::{KalmanFilter, ensure_time_step};
use crate::report::{UpdateOutcome, UpdateReport};
use crate::traits::{Estimator, Predict, Update};

/// The conditionally linear transition at one nonlinear state xn (see [`RaoBlackwellised`]): the
/// nonlinear part's mean fn(xn), its coupling An(xn) to xl and its noise Qn(xn); the linear
/// part's offset fl(xn), transition Al(xn) and noise Ql(xn).
#[derive(Clone, Debug, PartialEq)]
pub struct ConditionalTransition<T: Real, Nn: Dim, Nl: Dim>
where
    DefaultAllocator: Alloc<Nn, Nl>,
{
    /// fn(xn).
    pub nonlinear_mean: OVector<T, Nn>,
    /// An(xn) (nn × nl).
    pub coupling: OMatrix<T, Nn, Nl>,
    /// Qn(xn), positive semi-definite.
    pub nonlinear_noise: OMatrix<T, Nn, Nn>,
    /// fl(xn).
    pub linear_mean: OVector<T, Nl>,
    /// Al(xn).
    pub linear_transition: OMatrix<T, Nl, Nl>,
    /// Ql(xn), positive semi-definite.
    pub linear_noise: OMatrix<T, Nl, Nl>,
}

/// A process xn⁺ = fn + An xl + wn, xl⁺ = fl + Al xl + wl whose pieces depend on xn only
/// (see [`RaoBlackwellised`]).
pub trait ConditionallyLinearProcess<T: Real, Nn: Dim, Nl: Dim>
where
    DefaultAllocator: Alloc<Nn, Nl>,
{
    /// The input u (`()` for none).
    type Input;

    /// The transition's pieces at `xn`, with input `u` over `dt`.
    fn conditional_transition(
        &self,
        xn: &OVector<T, Nn>,
        u: &Self::Input,
        dt: T,
    ) -> ConditionalTransition<T, Nn, Nl>;
}

/// The conditionally linear measurement at one nonlinear state xn: z = h(xn) + C(xn) xl + v,
/// v ~ N(0, R(xn)).
#[derive(Clone, Debug, PartialEq)]
pub struct ConditionalMeasurement<T: Real, Nl: Dim, M: Dim>
where
    DefaultAllocator: Alloc<Nl, M>,
{
    /// h(xn).
    pub offset: OVector<T, M>,
    /// C(xn) (m × nl; zero when only xn is measured).
    pub observation: OMatrix<T, M, Nl>,
    /// R(xn), positive definite.
    pub noise: OMatrix<T, M, M>,
}

/// A sensor z = h(xn) + C(xn) xl + v (see [`RaoBlackwellised`]).
pub trait ConditionallyLinearMeasurement<T: Real, Nn: Dim, Nl: Dim, M: Dim>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<Nl, M>,
{
    /// The measurement's pieces at `xn`.
    fn conditional_measurement(&self, xn: &OVector<T, Nn>) -> ConditionalMeasurement<T, Nl, M>;
}

/// The Rao-Blackwellised (marginalised) particle filter for conditionally linear-Gaussian
/// models (Schön, Gustafsson & Nordlund 2005).
///
/// The state splits into a nonlinear part xn and a part xl that is linear-Gaussian given
/// the xn trajectory:
///
/// ```text
/// xn⁺ = fn(xn) + An(xn) xl + wn,   wn ~ N(0, Qn(xn))
/// xl⁺ = fl(xn) + Al(xn) xl + wl,   wl ~ N(0, Ql(xn))      (wn, wl independent)
/// z   = h(xn)  + C(xn) xl  + v,    v  ~ N(0, R(xn))
/// ```
///
/// Particles carry xn; each carries a Kalman filter ([`KalmanFilter`], the workspace's own
/// affine update, not a second implementation) for p(xl | xn₀..ₖ, z₁..ₖ) = N(x̂lⁱ, Plⁱ).
/// Given the particle's path, the only randomness left is Gaussian, so the filter computes
/// exactly what a plain particle filter would estimate by sampling xl: the Monte Carlo error
/// of the xl part disappears (the Rao-Blackwell theorem: conditional expectation never
/// increases variance).
///
/// ```text
/// update:   log gⁱ = log N(z; h(xnⁱ) + C x̂lⁱ, C Plⁱ Cᵀ + R)   (the KF update of xlⁱ on z − h(xnⁱ))
///           Δℓ = log Σ Wⁱ gⁱ,  log Wⁱ ← log Wⁱ + log gⁱ − Δℓ
/// predict:  if ESS < τN: resample (particles with their filters)
///           xnⁱ⁺ ~ N(fn + An x̂lⁱ, An Plⁱ Anᵀ + Qn)             (xl marginalised out)
///           KF update of xlⁱ on η = xnⁱ⁺ − fn = An xl + wn       (xn⁺ carries information on xl)
///           KF prediction xlⁱ⁺ = Al xlⁱ + fl + wl
/// ```
///
/// (Schön et al., Algorithm 1 and eq. 24–25 with Qln = 0.) Δℓ is the unbiased likelihood
/// estimate of the bootstrap filter, with the same resampling schemes, trigger and random
/// streams (seed, step, particle) as [`ParticleFilter`](super::ParticleFilter).
///
/// **Scope.** Generic over the scalar and the sizes (runtime-size pieces are shape-checked),
/// with the step atomic on error (the new cloud is built in work buffers and swapped in), and
/// allocation-free after construction at static sizes. It is an estimator of the joint state
/// x = (xn, xl) (dimension `DimSum<Nn, Nl>`): [`Estimator`] (the mixture moments),
/// [`Rollback`](crate::Rollback) (bit-exact), [`Predict`] (the process also names its input on
/// the joint state, [`ProcessInput`](crate::ProcessInput)) and [`Update`], so it runs in the
/// fusion driver and the sequence functions; serde checkpoints (feature `serde`). Not yet: a
/// cross-covariance Qln between wn and wl (decorrelate the model first, Schön et al. §III-B).
///
/// **Allocations at runtime sizes.** With `Dyn` parts a step allocates per particle, and the
/// [`InPlace`](estim_core::in_place::InPlace) opt-in of the Gaussian filters cannot carry it:
/// [`ConditionallyLinearProcess`] and [`ConditionallyLinearMeasurement`] return their pieces
/// ([`ConditionalTransition`]: fn, An, Qn, fl, Al, Ql; [`ConditionalMeasurement`]: h, C, R) by
/// value, and `InPlace` has slots only for a whole-state model's f, Q and derivatives, not for
/// these six; and each particle's Kalman steps run on a `LinearMeasurement` (An, Qn)
/// and a `LinearProcess` (Al, I, Ql) built from those pieces, with the products An x̂l and
/// An Pl Anᵀ and the factor of An Pl Anᵀ + Qn formed as new matrices. Making that
/// allocation-free would take an in-place form of both traits (a method writing the pieces
/// into buffers the filter keeps) and per-particle Kalman steps on borrowed pieces: new
/// public API, which the one-method-per-capability model traits do not have. What a user does
/// today: give the parts static sizes (`Vector2`, `Matrix2x3`, … with `Nn`, `Nl` type-level),
/// and every step after construction allocates nothing (tested); the sizes of a
/// Rao-Blackwellised split are usually small and known at compile time.
///
/// The moments: x̂n = Σ Wⁱ xnⁱ, Pn their weighted covariance; x̂l = Σ Wⁱ x̂lⁱ and
/// Pl = Σ Wⁱ (Plⁱ + (x̂lⁱ − x̂l)(x̂lⁱ − x̂l)ᵀ) (the mixture's covariance).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::Gaussian;
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
/// let position = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let velocity = Gaussian::new(Vector1::new(0.0), Matrix1::new(4.0))?;
/// let mut rbpf = RaoBlackwellised::new(position, velocity, 500, 1)?;
/// for k in 1..=10 {
///     rbpf.predict(&Cv, &(), 1.0)?;
///     rbpf.update(&Position, &Vector1::new(2.0 * k as f64))?; // moving at 2 per step
/// }
/// assert!((rbpf.linear_mean()[0] - 2.0).abs() < 0.5);
/// # Ok::<(), estim_core::Error>(())
/// ```
///
/// A Rao-Blackwellised particle filter: particles for xn, a [`KalmanFilter`] per particle
/// for xl (above).
#[derive(Clone, Debug)]
pub struct RaoBlackwellised<T: Real, Nn: DimAdd<Nl>, Nl: Dim>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    pub(super) seed: u64,
    pub(super) scheme: Resampling,
    pub(super) when: ResampleWhen,
    pub(super) state: RaoBlackwellisedSnapshot<T, Nn, Nl>,
    pub(super) work: RbWork<T, Nn, Nl>,
}

/// Everything a [`RaoBlackwellised`] filter's steps change: the nonlinear particles, their
/// Kalman filters and log-weights, the random step counter, the running log-likelihood and
/// the joint mixture moments. Restoring one gives the same bits afterwards as at the time it
/// was taken ([`Rollback`](crate::Rollback)).
#[derive(Clone, Debug, PartialEq)]
pub struct RaoBlackwellisedSnapshot<T: Real, Nn: DimAdd<Nl>, Nl: Dim>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    pub(super) nonlinear: OMatrix<T, Nn, Dyn>,
    pub(super) linear: Vec<KalmanFilter<T, Nl>>,
    pub(super) log_weights: Vec<T>,
    pub(super) step: u64,
    pub(super) log_likelihood: T,
    pub(super) mean: OVector<T, DimSum<Nn, Nl>>,
    pub(super) covariance: OMatrix<T, DimSum<Nn, Nl>, DimSum<Nn, Nl>>,
}

/// The buffers a step writes before it commits (swapped in on success), sized at
/// construction so steps at static sizes allocate nothing.
#[derive(Clone, Debug)]
pub(super) struct RbWork<T: Real, Nn: DimAdd<Nl>, Nl: Dim>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    pub(super) nonlinear: OMatrix<T, Nn, Dyn>,
    pub(super) linear: Vec<KalmanFilter<T, Nl>>,
    pub(super) log_w: Vec<T>,
    pub(super) ancestors: Vec<usize>,
    pub(super) weights: Vec<f64>,
    pub(super) scratch: Vec<f64>,
    pub(super) xn: OVector<T, Nn>,
    pub(super) normals: OVector<T, Nn>,
    pub(super) d: OVector<T, DimSum<Nn, Nl>>,
}

impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> RbWork<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    /// Buffers for `filters.len()` particles of sizes (n, l).
    pub(super) fn new(n: Nn, l: Nl, filters: &[KalmanFilter<T, Nl>]) -> Self {
        let count = filters.len();
        Self {
            nonlinear: OMatrix::zeros_generic(n, Dyn(count)),
            linear: filters.to_vec(),
            log_w: vec![T::zero(); count],
            ancestors: (0..count).collect(),
            weights: Vec::with_capacity(count),
            scratch: Vec::with_capacity(2 * count), // residual resampling: N + N
            xn: OVector::zeros_generic(n, U1),
            normals: OVector::zeros_generic(n, U1),
            d: OVector::zeros_generic(n.add(l), U1),
        }
    }
}

impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> RaoBlackwellised<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
{
    /// `count` particles xnⁱ drawn from `nonlinear` (streams (seed, 0, i), through a PSD
    /// factor, so a singular prior works), each with a Kalman filter started at `linear`
    /// (xn and xl independent a priori), equally weighted. Systematic resampling when the ESS
    /// falls below N/2, as [`ParticleFilter`](super::ParticleFilter).
    ///
    /// Errors: `count` = 0, or so large that the particles could not be allocated
    /// ([`SampleCount`](estim_core::Parameter::SampleCount)); a nonlinear prior covariance
    /// that is not positive semi-definite.
    ///
    /// ```
    /// use estim_core::nalgebra::{Matrix1, Matrix2, Vector1, Vector2};
    /// use estim_core::Gaussian;
    /// use estim_filters::particle::RaoBlackwellised;
    ///
    /// let xn = Gaussian::new(Vector1::new(1.0f64), Matrix1::new(0.5))?;
    /// let xl = Gaussian::new(Vector2::new(0.0, 2.0), Matrix2::identity())?;
    /// let rbpf = RaoBlackwellised::new(xn.clone(), xl.clone(), 1000, 3)?;
    /// // Every filter starts at the prior (the weights sum to 1 up to round-off).
    /// assert!((rbpf.linear_mean() - Vector2::new(0.0, 2.0)).norm() < 1e-12);
    /// assert!((rbpf.nonlinear_mean()[0] - 1.0).abs() < 0.1); // 4 standard errors √(0.5/1000)
    /// assert!(RaoBlackwellised::new(xn, xl, 0, 3).is_err());
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn new(
        nonlinear: Gaussian<T, Nn>,
        linear: Gaussian<T, Nl>,
        count: usize,
        seed: u64,
    ) -> Result<Self> {
        // The nonlinear cloud and one Kalman filter (mean and covariance) per particle.
        let nl = linear.mean().nrows();
        check_count::<T>(count, 2 * nonlinear.mean().nrows() + nl * (nl + 1) + 6)?;
        let factor = psd_factor(nonlinear.covariance(), Stage::Construction)?;
        let (n, _) = nonlinear.mean().shape_generic();
        let mut particles = OMatrix::zeros_generic(n, Dyn(count));
        let mut normals = OVector::zeros_generic(n, U1);
        for i in 0..count {
            fill_normals(&mut normals, &mut ParticleRng::stream(seed, 0, i as u64));
            let mut column = particles.column_mut(i);
            column.copy_from(nonlinear.mean());
            column.gemv(T::one(), &factor, &normals, T::one());
        }
        let uniform = -estim_core::scalar::real::<T>(count as f64).ln();
        let filters = vec![KalmanFilter::new(linear); count];
        let l = filters[0].state().shape_generic().0;
        let joint = n.add(l);
        let mut filter = Self {
            seed,
            scheme: Resampling::default(),
            when: ResampleWhen::default(),
            work: RbWork::new(n, l, &filters),
            state: RaoBlackwellisedSnapshot {
                nonlinear: particles,
                linear: filters,
                log_weights: vec![uniform; count],
                step: 1,
                log_likelihood: T::zero(),
                mean: OVector::zeros_generic(joint, U1),
                covariance: OMatrix::zeros_generic(joint, joint),
            },
        };
        filter.update_moments();
        Ok(filter)
    }

    /// The same filter resampling by `scheme`.
    pub fn with_resampling(mut self, scheme: Resampling) -> Self {
        self.scheme = scheme;
        self
    }

    /// The same filter resampling when `when` fires. Errors: an
    /// [`EssBelow`](ResampleWhen::EssBelow) fraction outside (0, 1]
    /// ([`Tolerance`](estim_core::Parameter::Tolerance)).
    pub fn with_trigger(mut self, when: ResampleWhen) -> Result<Self> {
        check_trigger(when)?;
        self.when = when;
        Ok(self)
    }

    /// The number of particles N.
    pub fn count(&self) -> usize {
        self.state.log_weights.len()
    }

    /// The seed of the random streams.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The random step counter (1 after construction, +1 per prediction).
    pub fn step(&self) -> u64 {
        self.state.step
    }

    /// The resampling scheme.
    pub fn resampling(&self) -> Resampling {
        self.scheme
    }

    /// When the prediction resamples.
    pub fn trigger(&self) -> ResampleWhen {
        self.when
    }

    /// The nonlinear particles xnⁱ, one per column.
    pub fn nonlinear_particles(&self) -> &OMatrix<T, Nn, Dyn> {
        &self.state.nonlinear
    }

    /// The per-particle Kalman filters of xl.
    pub fn linear_filters(&self) -> &[KalmanFilter<T, Nl>] {
        &self.state.linear
    }

    /// The normalised log-weights log Wⁱ.
    pub fn log_weights(&self) -> &[T] {
        &self.state.log_weights
    }

    /// The effective sample size 1 / Σ Wᵢ².
    pub fn effective_sample_size(&self) -> T {
        estim_core::scalar::real(effective_sample_size(&self.state.log_weights))
    }

    /// The running log-likelihood estimate Σ Δℓ (its exponential is unbiased for p(z₁..ₖ)).
    pub fn log_likelihood(&self) -> T {
        self.state.log_likelihood
    }

    /// x̂n = Σ Wⁱ xnⁱ.
    pub fn nonlinear_mean(&self) -> OVector<T, Nn> {
        let mut mean = OVector::zeros_generic(self.state.nonlinear.shape_generic().0, U1);
        for (i, &lw) in self.state.log_weights.iter().enumerate() {
            mean.axpy(lw.exp(), &self.state.nonlinear.column(i), T::one());
        }
        mean
    }

    /// Pn = Σ Wⁱ (xnⁱ − x̂n)(xnⁱ − x̂n)ᵀ.
    pub fn nonlinear_covariance(&self) -> OMatrix<T, Nn, Nn> {
        let mean = self.nonlinear_mean();
        let (n, _) = mean.shape_generic();
        let mut covariance = OMatrix::zeros_generic(n, n);
        for (i, &lw) in self.state.log_weights.iter().enumerate() {
            let d = self.state.nonlinear.column(i) - &mean;
            covariance.ger(lw.exp(), &d, &d, T::one());
        }
        covariance
    }

    /// x̂l = Σ Wⁱ x̂lⁱ.
    pub fn linear_mean(&self) -> OVector<T, Nl> {
        let s = &self.state;
        let mut mean = OVector::zeros_generic(s.linear[0].state().shape_generic().0, U1);
        for (kf, &lw) in s.linear.iter().zip(&s.log_weights) {
            mean.axpy(lw.exp(), kf.state(), T::one());
        }
        mean
    }

    /// Pl = Σ Wⁱ (Plⁱ + (x̂lⁱ − x̂l)(x̂lⁱ − x̂l)ᵀ).
    pub fn linear_covariance(&self) -> OMatrix<T, Nl, Nl> {
        let mean = self.linear_mean();
        let (n, _) = mean.shape_generic();
        let mut covariance = OMatrix::zeros_generic(n, n);
        for (kf, &lw) in self.state.linear.iter().zip(&self.state.log_weights) {
            let w = lw.exp();
            let d = kf.state() - &mean;
            covariance.ger(w, &d, &d, T::one());
            covariance.zip_apply(kf.covariance(), |acc, p| *acc += w * p);
        }
        covariance
    }

    /// The time update (see [`RaoBlackwellised`]): resample if the trigger fires, draw each
    /// xnⁱ⁺ from its xl-marginalised Gaussian, condition xlⁱ on it and predict xlⁱ. Also the
    /// [`Predict`] impl (for a process that names its input on the joint state,
    /// [`ProcessInput`](crate::ProcessInput)). Allocates nothing at static sizes.
    ///
    /// Errors (the filter unchanged): Δt negative or not finite; a transition piece of the
    /// wrong shape or not finite; An Pl Anᵀ + Qn not positive semi-definite; a Kalman step
    /// that fails (Qn singular where xn⁺ is coupled to xl: no innovation covariance to
    /// factor, or Ql not PSD).
    pub fn predict<P>(&mut self, process: &P, input: &P::Input, dt: T) -> Result<()>
    where
        P: ConditionallyLinearProcess<T, Nn, Nl> + ?Sized,
    {
        ensure_time_step(dt)?;
        let count = self.count();
        let state = &mut self.state;
        let work = &mut self.work;
        let step = state.step;
        let resample = self
            .when
            .fires(|| effective_sample_size(&state.log_weights), count);
        for (j, a) in work.ancestors.iter_mut().enumerate() {
            *a = j;
        }
        if resample {
            work.weights.clear();
            work.weights
                .extend(state.log_weights.iter().map(|&lw| to_f64(lw).exp()));
            let mut rng = ParticleRng::stream(self.seed, step, RESAMPLE);
            resample_with(
                self.scheme,
                &work.weights,
                &mut rng,
                &mut work.ancestors,
                &mut work.scratch,
            )?;
        }
        let (n, _) = state.nonlinear.shape_generic();
        let stage = Stage::Prediction;
        for (j, &a) in work.ancestors.iter().enumerate() {
            work.xn.copy_from(&state.nonlinear.column(a));
            let kf = &mut work.linear[j];
            kf.clone_from(&state.linear[a]);
            let t = process.conditional_transition(&work.xn, input, dt);
            check_transition(&t, n.value(), kf.state().nrows())?;
            // xn⁺ ~ N(fn + An x̂l, An Pl Anᵀ + Qn).
            let mut mean = &t.coupling * kf.state();
            mean += &t.nonlinear_mean;
            let mut spread = &t.coupling * kf.covariance() * t.coupling.transpose();
            spread += &t.nonlinear_noise;
            let factor =
                psd_factor(&spread, stage).map_err(|_| Error::NotPositiveSemiDefinite {
                    stage,
                    quantity: Quantity::ProcessNoise,
                })?;
            fill_normals(
                &mut work.normals,
                &mut ParticleRng::stream(self.seed, step, j as u64),
            );
            mean.gemv(T::one(), &factor, &work.normals, T::one());
            // Condition xl on η = xn⁺ − fn = An xl + wn (nothing to learn if An = 0).
            if t.coupling.iter().any(|&c| c != T::zero()) {
                let eta = &mean - &t.nonlinear_mean;
                let dynamics = LinearMeasurement::<T, Nl, Nn> {
                    observation: t.coupling,
                    noise: t.nonlinear_noise,
                };
                kf.update(&dynamics, &eta)?;
            }
            // xl⁺ = Al xl + fl + wl: a linear process with input fl through B = I.
            let (l, _) = t.linear_mean.shape_generic();
            let linear = LinearProcess::<T, Nl, Nl> {
                transition: t.linear_transition,
                input: OMatrix::<T, Nl, Nl>::identity_generic(l, l),
                noise: t.linear_noise,
            };
            kf.predict(&linear, &t.linear_mean, dt)?;
            work.nonlinear.set_column(j, &mean);
        }
        ensure_finite(&work.nonlinear, stage, Quantity::FunctionValue)?;
        // Committed.
        core::mem::swap(&mut state.nonlinear, &mut work.nonlinear);
        core::mem::swap(&mut state.linear, &mut work.linear);
        if resample {
            let uniform = -estim_core::scalar::real::<T>(count as f64).ln();
            state.log_weights.fill(uniform);
        }
        state.step = step.wrapping_add(1);
        self.update_moments();
        Ok(())
    }

    /// The measurement update (see [`RaoBlackwellised`]): each particle's Kalman filter is
    /// updated on z − h(xnⁱ) with observation C(xnⁱ), and its weight multiplied by the
    /// update's likelihood N(z; h + C x̂lⁱ, C Plⁱ Cᵀ + R). Also the [`Update`] impl.
    ///
    /// The report is the mixture predictive's: ν = Σ Wⁱ νⁱ (= z − ẑ), S = Σ Wⁱ (Sⁱ + νⁱνⁱᵀ)
    /// − ννᵀ, NIS = νᵀS⁻¹ν (infinite if S is singular), and as log-likelihood the step's
    /// estimate Δℓ = log Σ Wⁱ gⁱ (not a Gaussian's).
    ///
    /// Errors (the filter unchanged): z not finite; a measurement piece of the wrong shape or
    /// not finite; R such that an innovation covariance is not positive definite; every
    /// weight zero or NaN ([`Quantity::Weights`]).
    pub fn update<M, H>(&mut self, sensor: &H, z: &OVector<T, M>) -> Result<UpdateReport<T, M>>
    where
        M: Dim,
        H: ConditionallyLinearMeasurement<T, Nn, Nl, M> + ?Sized,
        DefaultAllocator: Alloc<Nl, M> + Alloc<Nn, M>,
    {
        let mut report = UpdateReport::zeros(z.shape_generic().0);
        self.update_into(sensor, z, &mut report)?;
        Ok(report)
    }

    /// [`update`](Self::update) writing the report into `report` (resized to z's length if
    /// needed). Allocates nothing at static sizes. On error the filter is unchanged and
    /// `report` unspecified.
    pub fn update_into<M, H>(
        &mut self,
        sensor: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()>
    where
        M: Dim,
        H: ConditionallyLinearMeasurement<T, Nn, Nl, M> + ?Sized,
        DefaultAllocator: Alloc<Nl, M> + Alloc<Nn, M>,
    {
        ensure_finite(z, Stage::Update, Quantity::Measurement)?;
        let (m, _) = z.shape_generic();
        let state = &mut self.state;
        let work = &mut self.work;
        let mut one = UpdateReport::zeros(m);
        let mut nu = OVector::<T, M>::zeros_generic(m, U1);
        let mut second = OMatrix::<T, M, M>::zeros_generic(m, m);
        for (i, &lw) in state.log_weights.iter().enumerate() {
            work.xn.copy_from(&state.nonlinear.column(i));
            let kf = &mut work.linear[i];
            kf.clone_from(&state.linear[i]);
            let piece = sensor.conditional_measurement(&work.xn);
            check_measurement(&piece, z.nrows(), kf.state().nrows())?;
            let shifted = z - &piece.offset;
            let model = LinearMeasurement::<T, Nl, M> {
                observation: piece.observation,
                noise: piece.noise,
            };
            kf.update_into(&model, &shifted, &mut one)?;
            work.log_w[i] = lw + one.log_likelihood;
            let w = lw.exp();
            nu.axpy(w, &one.innovation, T::one());
            second.ger(w, &one.innovation, &one.innovation, T::one());
            second.zip_apply(&one.innovation_covariance, |acc, s| *acc += w * s);
        }
        let increment = normaliser(&work.log_w)?;
        // Committed.
        for (lw, &new) in state.log_weights.iter_mut().zip(&work.log_w) {
            *lw = new - increment;
        }
        core::mem::swap(&mut state.linear, &mut work.linear);
        state.log_likelihood += increment;
        self.update_moments();
        report.fit(m);
        second.ger(-T::one(), &nu, &nu, T::one());
        symmetrize(&mut second);
        report.innovation.copy_from(&nu);
        report.innovation_covariance.copy_from(&second);
        report.nis = inverse_quadratic_form(&mut second, &mut nu).unwrap_or(T::one() / T::zero());
        report.log_likelihood = increment;
        report.outcome = UpdateOutcome::Applied;
        report.iterations = None;
        Ok(())
    }
}

/// Shapes (runtime sizes) and finiteness of a transition's pieces.
fn check_transition<T: Real, Nn: Dim, Nl: Dim>(
    t: &ConditionalTransition<T, Nn, Nl>,
    n: usize,
    l: usize,
) -> Result<()>
where
    DefaultAllocator: Alloc<Nn, Nl>,
{
    let stage = Stage::Prediction;
    ensure_shape(&t.nonlinear_mean, n, 1, stage, Quantity::FunctionValue)?;
    ensure_shape(&t.coupling, n, l, stage, Quantity::Jacobian)?;
    ensure_shape(&t.nonlinear_noise, n, n, stage, Quantity::ProcessNoise)?;
    ensure_shape(&t.linear_mean, l, 1, stage, Quantity::FunctionValue)?;
    ensure_shape(&t.linear_transition, l, l, stage, Quantity::Jacobian)?;
    ensure_shape(&t.linear_noise, l, l, stage, Quantity::ProcessNoise)?;
    ensure_finite(&t.nonlinear_mean, stage, Quantity::FunctionValue)?;
    ensure_finite(&t.coupling, stage, Quantity::Jacobian)?;
    ensure_finite(&t.nonlinear_noise, stage, Quantity::ProcessNoise)?;
    ensure_finite(&t.linear_mean, stage, Quantity::FunctionValue)?;
    ensure_finite(&t.linear_transition, stage, Quantity::Jacobian)?;
    ensure_finite(&t.linear_noise, stage, Quantity::ProcessNoise)
}

/// Shapes (runtime sizes) and finiteness of a measurement's pieces.
fn check_measurement<T: Real, Nl: Dim, M: Dim>(
    piece: &ConditionalMeasurement<T, Nl, M>,
    m: usize,
    l: usize,
) -> Result<()>
where
    DefaultAllocator: Alloc<Nl, M>,
{
    let stage = Stage::Update;
    ensure_shape(&piece.offset, m, 1, stage, Quantity::FunctionValue)?;
    ensure_shape(&piece.observation, m, l, stage, Quantity::Jacobian)?;
    ensure_shape(&piece.noise, m, m, stage, Quantity::MeasurementNoise)?;
    ensure_finite(&piece.offset, stage, Quantity::FunctionValue)?;
    ensure_finite(&piece.observation, stage, Quantity::Jacobian)?;
    ensure_finite(&piece.noise, stage, Quantity::MeasurementNoise)
}
