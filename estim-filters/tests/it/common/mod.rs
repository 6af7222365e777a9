//! Shared helpers for the estim-filters integration tests: random stable linear systems
//! (static and dynamic sizes), a simulator, hand-written reference Kalman equations and
//! comparison helpers.
//!
//! Each test binary uses a subset of these, hence the `dead_code` allowance.
#![allow(dead_code)]

use estim_core::nalgebra::{
    Const, DMatrix, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1, allocator::Allocator,
};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::{Predict, Update};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// A seeded generator (rand 0.9 `StdRng`): every test is deterministic.
pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

/// One standard normal draw.
pub fn normal(rng: &mut StdRng) -> f64 {
    rng.sample(StandardNormal)
}

/// An `r × c` matrix of independent standard normal entries.
pub fn gaussian_matrix<R: Dim, C: Dim>(rng: &mut StdRng, r: R, c: C) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    OMatrix::from_fn_generic(r, c, |_, _| normal(rng))
}

/// A random symmetric positive definite matrix A Aᵀ · scale / d + floor · I. The floor bounds
/// the smallest eigenvalue away from zero, so the matrix is well conditioned enough that
/// round-off differences between algebraically equal filters stay near machine precision.
pub fn random_spd<D: Dim>(rng: &mut StdRng, d: D, scale: f64, floor: f64) -> OMatrix<f64, D, D>
where
    DefaultAllocator: Allocator<D, D>,
{
    let a = gaussian_matrix(rng, d, d);
    let n = d.value().max(1) as f64;
    let mut spd = &a * a.transpose() * (scale / n);
    for i in 0..d.value() {
        spd[(i, i)] += floor;
    }
    // A Aᵀ is symmetric up to round-off in the product; make it exactly symmetric.
    let t = spd.transpose();
    (spd + t) * 0.5
}

/// The spectral radius max |λᵢ| of a square matrix.
pub fn spectral_radius<D: Dim>(f: &OMatrix<f64, D, D>) -> f64
where
    DefaultAllocator: Allocator<D, D>,
{
    if f.nrows() == 0 {
        return 0.0;
    }
    let d = DMatrix::from_iterator(f.nrows(), f.ncols(), f.iter().copied());
    d.complex_eigenvalues()
        .iter()
        .fold(0.0_f64, |m, l| m.max(l.norm()))
}

/// A random matrix rescaled to spectral radius `radius` (< 1: a stable, in general non-normal,
/// transition matrix).
pub fn random_stable<D: Dim>(rng: &mut StdRng, d: D, radius: f64) -> OMatrix<f64, D, D>
where
    DefaultAllocator: Allocator<D, D>,
{
    loop {
        let a = gaussian_matrix(rng, d, d);
        let rho = spectral_radius(&a);
        if rho > 1e-3 {
            let f = a * (radius / rho);
            debug_assert!(spectral_radius(&f) < 1.0);
            return f;
        }
    }
}

/// A linear-Gaussian system x⁺ = F x + B u + w, z = H x + v, with a prior on x₀.
#[derive(Clone, Debug)]
pub struct LinearSystem<N: Dim, M: Dim, U: Dim>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    pub process: LinearProcess<f64, N, U>,
    pub measurement: LinearMeasurement<f64, N, M>,
    pub prior: Gaussian<f64, N>,
}

/// A random stable system: F with spectral radius in [0.5, 0.97], random B, full-rank (almost
/// surely) Gaussian H, SPD Q and R with eigenvalues bounded below, a random prior.
pub fn random_system<N: Dim, M: Dim, U: Dim>(
    rng: &mut StdRng,
    n: N,
    m: M,
    u: U,
) -> LinearSystem<N, M, U>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    let radius = rng.random_range(0.5..0.97);
    let transition = random_stable(rng, n, radius);
    let input = gaussian_matrix(rng, n, u);
    let noise = random_spd(rng, n, 0.1, 0.01);
    let observation = gaussian_matrix(rng, m, n);
    let meas_noise = random_spd(rng, m, 0.2, 0.05);
    let mean = gaussian_matrix(rng, n, U1);
    let cov = random_spd(rng, n, 1.0, 0.1);
    LinearSystem {
        process: LinearProcess {
            transition,
            input,
            noise,
        },
        measurement: LinearMeasurement {
            observation,
            noise: meas_noise,
        },
        prior: Gaussian::new(mean, cov).expect("random prior is SPD"),
    }
}

/// The static 4-state, 2-measurement, 1-input system used by most tests.
pub type StaticSystem = LinearSystem<Const<4>, Const<2>, Const<1>>;
/// A runtime-sized system.
pub type DynSystem = LinearSystem<Dyn, Dyn, Dyn>;

/// A random [`StaticSystem`].
pub fn random_static_system(rng: &mut StdRng) -> StaticSystem {
    random_system(rng, Const::<4>, Const::<2>, Const::<1>)
}

/// A random [`DynSystem`] with n states, m measurements and p inputs.
pub fn random_dyn_system(rng: &mut StdRng, n: usize, m: usize, p: usize) -> DynSystem {
    random_system(rng, Dyn(n), Dyn(m), Dyn(p))
}

/// A draw from N(mean, cov) (cov positive definite).
pub fn sample<D: Dim>(
    rng: &mut StdRng,
    mean: &OVector<f64, D>,
    cov: &OMatrix<f64, D, D>,
) -> OVector<f64, D>
where
    DefaultAllocator: Allocator<D> + Allocator<D, D>,
{
    let l = cov
        .clone()
        .cholesky()
        .expect("sampling covariance must be positive definite")
        .unpack();
    let z = gaussian_matrix(rng, mean.shape_generic().0, U1);
    mean + l * z
}

/// One simulated run: inputs uₖ, true states xₖ₊₁ = F xₖ + B uₖ + wₖ and measurements
/// zₖ₊₁ = H xₖ₊₁ + vₖ₊₁, for k = 0..steps (x₀ drawn from the prior).
#[derive(Clone, Debug)]
pub struct Trajectory<N: Dim, M: Dim, U: Dim>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    pub inputs: Vec<OVector<f64, U>>,
    /// xₖ₊₁ after step k (the state the k-th measurement observes).
    pub truth: Vec<OVector<f64, N>>,
    pub measurements: Vec<OVector<f64, M>>,
}

/// Simulates `steps` steps of `system` with its true noises.
pub fn simulate<N: Dim, M: Dim, U: Dim>(
    rng: &mut StdRng,
    system: &LinearSystem<N, M, U>,
    steps: usize,
) -> Trajectory<N, M, U>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    let p = &system.process;
    let h = &system.measurement;
    let n_dim = system.prior.mean().shape_generic().0;
    let m_dim = h.observation.shape_generic().0;
    let u_dim = p.input.shape_generic().1;
    let zero_n = OVector::<f64, N>::zeros_generic(n_dim, U1);
    let zero_m = OVector::<f64, M>::zeros_generic(m_dim, U1);
    let mut x = sample(rng, system.prior.mean(), system.prior.covariance());
    let mut out = Trajectory {
        inputs: Vec::with_capacity(steps),
        truth: Vec::with_capacity(steps),
        measurements: Vec::with_capacity(steps),
    };
    for _ in 0..steps {
        let u = gaussian_matrix(rng, u_dim, U1);
        x = &p.transition * &x + &p.input * &u + sample(rng, &zero_n, &p.noise);
        let z = &h.observation * &x + sample(rng, &zero_m, &h.noise);
        out.inputs.push(u);
        out.truth.push(x.clone());
        out.measurements.push(z);
    }
    out
}

/// The textbook Kalman equations, written out with explicit matrices, as an independent
/// reference (explicit inverse of S, Joseph form (I − K H) P (I − K H)ᵀ + K R Kᵀ).
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceKf<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub x: OVector<f64, N>,
    pub p: OMatrix<f64, N, N>,
}

impl<N: Dim> ReferenceKf<N>
where
    DefaultAllocator: Alloc<N>,
{
    pub fn new(prior: &Gaussian<f64, N>) -> Self {
        Self {
            x: prior.mean().clone(),
            p: prior.covariance().clone(),
        }
    }

    /// x = F x + B u, P = F P Fᵀ + Q.
    pub fn predict<U: Dim>(&mut self, process: &LinearProcess<f64, N, U>, u: &OVector<f64, U>)
    where
        DefaultAllocator: Alloc<N, U>,
    {
        let f = &process.transition;
        self.x = f * &self.x + &process.input * u;
        self.p = f * &self.p * f.transpose() + &process.noise;
    }

    /// S = H P Hᵀ + R, K = P Hᵀ S⁻¹, x += K (z − H x), Joseph covariance.
    ///
    /// K comes from solving S Kᵀ = H P by LU with partial pivoting: independent of the
    /// library's Cholesky route, and backward stable. Forming S⁻¹ and multiplying, as a
    /// textbook would write it, has error ε κ(S) |P Hᵀ| |S⁻¹| rather than ε κ(S) |K|: when the
    /// prior is ~10³ wider than the posterior those differ by orders of magnitude, and the
    /// reference (not the library) was off by 4·10⁻⁸ (see
    /// `family_agrees_when_the_prior_is_much_wider_than_the_measurement` in equivalence.rs).
    pub fn update<M: Dim>(&mut self, meas: &LinearMeasurement<f64, N, M>, z: &OVector<f64, M>)
    where
        DefaultAllocator: Alloc<N, M>,
    {
        let h = &meas.observation;
        let s = h * &self.p * h.transpose() + &meas.noise;
        // On runtime sizes (nalgebra's LU needs `DimMin` bounds that generic M lacks).
        let (m, n) = (s.nrows(), self.p.nrows());
        let hp = h * &self.p;
        let kt = DMatrix::from_column_slice(m, m, s.as_slice())
            .lu()
            .solve(&DMatrix::from_column_slice(m, n, hp.as_slice()))
            .expect("S invertible");
        let k = OMatrix::<f64, M, N>::from_column_slice_generic(
            hp.shape_generic().0,
            hp.shape_generic().1,
            kt.as_slice(),
        )
        .transpose();
        self.x = &self.x + &k * (z - h * &self.x);
        let n_dim = self.x.shape_generic().0;
        let i_kh = OMatrix::<f64, N, N>::identity_generic(n_dim, n_dim) - &k * h;
        self.p = &i_kh * &self.p * i_kh.transpose() + &k * &meas.noise * k.transpose();
    }
}

/// max |aᵢⱼ|.
pub fn max_abs<R: Dim, C: Dim>(m: &OMatrix<f64, R, C>) -> f64
where
    DefaultAllocator: Allocator<R, C>,
{
    m.iter().fold(0.0, |a, v| a.max(v.abs()))
}

/// Relative differences of two estimates (xₐ, Pₐ) and (x_b, P_b), b being the reference:
///
/// - state: max |xₐ − x_b| / max(max |x_b|, √max (P_b)ᵢᵢ). State round-off enters through the
///   gain times the innovation, whose size is that of the state's standard deviation, so the
///   state is compared on the scale of its magnitude or its uncertainty, whichever is larger
///   (a pure relative error would blow up for a state that happens to be near 0).
/// - covariance: max |Pₐ − P_b| / max |P_b|.
pub fn estimate_rel_diff<N: Dim>(
    xa: &OVector<f64, N>,
    pa: &OMatrix<f64, N, N>,
    xb: &OVector<f64, N>,
    pb: &OMatrix<f64, N, N>,
) -> (f64, f64)
where
    DefaultAllocator: Alloc<N>,
{
    let x_scale = state_scale(xb, pb);
    let p_scale = max_abs(pb).max(f64::MIN_POSITIVE);
    (max_abs(&(xa - xb)) / x_scale, max_abs(&(pa - pb)) / p_scale)
}

/// The scale [`estimate_rel_diff`] compares a state on: max(max |x|, √max Pᵢᵢ).
pub fn state_scale<N: Dim>(x: &OVector<f64, N>, p: &OMatrix<f64, N, N>) -> f64
where
    DefaultAllocator: Alloc<N>,
{
    let sigma = p.diagonal().iter().fold(0.0_f64, |m, v| m.max(*v)).sqrt();
    max_abs(x).max(sigma).max(f64::MIN_POSITIVE)
}

/// Asserts two estimates agree to `tol` in the sense of [`estimate_rel_diff`].
#[track_caller]
pub fn assert_estimates_close<N: Dim>(
    xa: &OVector<f64, N>,
    pa: &OMatrix<f64, N, N>,
    xb: &OVector<f64, N>,
    pb: &OMatrix<f64, N, N>,
    tol: f64,
    context: &str,
) where
    DefaultAllocator: Alloc<N>,
{
    let (dx, dp) = estimate_rel_diff(xa, pa, xb, pb);
    assert!(
        dx <= tol && dp <= tol,
        "{context}: relative state diff {dx:e}, covariance diff {dp:e} > {tol:e}\n\
         xa = {xa}xb = {xb}Pa = {pa}Pb = {pb}"
    );
}

/// Asserts two matrices are identical bit for bit (stronger than `==`, which equates 0.0 and
/// −0.0).
#[track_caller]
pub fn assert_bitwise_eq<R: Dim, C: Dim>(a: &OMatrix<f64, R, C>, b: &OMatrix<f64, R, C>, what: &str)
where
    DefaultAllocator: Allocator<R, C>,
{
    assert_eq!(a.shape(), b.shape(), "{what}: shapes differ");
    for (i, (x, y)) in a.iter().zip(b.iter()).enumerate() {
        assert_eq!(
            x.to_bits(),
            y.to_bits(),
            "{what}: entry {i} differs: {x:e} vs {y:e}"
        );
    }
}

/// State tolerance for the UKF with the default α = 10⁻³ only (its covariance is compared at
/// the tighter tolerance of each test), relative to the largest state scale of the run so far
/// (equivalence.rs, `assert_runs_agree_to`: the error made on a larger earlier scale decays
/// only through the loop; comparing on each step's own scale gave 2.6·10⁻⁸ for a trajectory
/// shrinking from |x| = 19 to 1.6, seed 6742016220725902189).
///
/// The sigma-point mean is ȳ = g(μ) + (1/2c) Σᵢ dᵢ with c = α² n. For linear g the 2n
/// deviations cancel exactly in exact arithmetic, but each carries the round-off ε |g(χᵢ)| of
/// evaluating g, which the weight 1/(2c) = 1/(2α²n) amplifies: ≈ ½ √(2/n) · ε/α² · |y| per
/// propagation. That is inherent to a value-only rule with spread α (the textbook form
/// W₀ y₀ + Σ wᵢ yᵢ has the same ε/α²; the shifted form removes it from the covariance, not
/// from the mean). Budget relative to the state scale: ½ √(2/n) ≤ 0.71, |y|/scale ≲ 5 (a
/// Gaussian H with m ≤ 4, n ≤ 7), and accumulation through the closed loop ≤ 1/(1 − ρ) ≈ 30
/// for spectral radius ρ ≤ 0.97: ≈ 100 ε/α² ≈ 2.2·10⁻⁸. Measured worst case over 60 000
/// random systems: 5.9·10⁻⁹ (the covariance, by contrast: 5·10⁻¹¹).
pub const UKF_SMALL_ALPHA_STATE_TOL: f64 = 100.0 * f64::EPSILON / (1e-3 * 1e-3);

/// The upper α-quantile approximation of the χ² distribution with `k` degrees of freedom,
/// by Wilson–Hilferty (1931): (χ²ₖ/k)^⅓ is nearly normal with mean 1 − 2/(9k) and variance
/// 2/(9k), so χ²ₖ(p) ≈ k (1 − 2/(9k) + zₚ √(2/(9k)))³. Its relative error is below 1% for
/// k ≥ 100 at the 2.5% and 97.5% points (and ~10⁻⁴ at k in the hundreds), which is all the
/// NEES test needs. `z` is the standard normal quantile of the wanted probability.
pub fn chi2_quantile_wilson_hilferty(k: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// The standard normal 97.5% quantile.
pub const Z_975: f64 = 1.959_963_984_540_054;

/// Runs `filter` over the trajectory (predict with uₖ, then update with zₖ₊₁) and returns the
/// estimate after each update.
pub fn run<F, N, M, U>(
    mut filter: F,
    system: &LinearSystem<N, M, U>,
    traj: &Trajectory<N, M, U>,
) -> Run<N>
where
    N: Dim,
    M: Dim,
    U: Dim,
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
    F: Predict<f64, N, LinearProcess<f64, N, U>> + Update<f64, N, M, LinearMeasurement<f64, N, M>>,
{
    let mut out = Vec::with_capacity(traj.inputs.len());
    for (u, z) in traj.inputs.iter().zip(&traj.measurements) {
        filter
            .predict(&system.process, u, 1.0)
            .expect("predict on a well-posed linear system");
        let report = filter
            .update(&system.measurement, z)
            .expect("update on a well-posed linear system");
        assert!(report.applied());
        out.push((filter.state().clone(), filter.covariance().clone()));
    }
    out
}

/// The hand-written Kalman equations over the same trajectory.
pub fn run_reference<N, M, U>(system: &LinearSystem<N, M, U>, traj: &Trajectory<N, M, U>) -> Run<N>
where
    N: Dim,
    M: Dim,
    U: Dim,
    DefaultAllocator: Alloc<N, M> + Alloc<N, U>,
{
    let mut kf = ReferenceKf::new(&system.prior);
    traj.inputs
        .iter()
        .zip(&traj.measurements)
        .map(|(u, z)| {
            kf.predict(&system.process, u);
            kf.update(&system.measurement, z);
            (kf.x.clone(), kf.p.clone())
        })
        .collect()
}

/// The estimate after each update of a run.
pub type Run<N> = Vec<(OVector<f64, N>, OMatrix<f64, N, N>)>;

/// Asserts two runs agree at every step: state to `tol_x`, covariance to `tol_p` (relative).
///
/// The state is compared on the largest state scale the reference has had so far (see
/// `estimate_rel_diff` for one step's scale): round-off enters the state in
/// proportion to the values computed at each step and then decays through the closed loop, so
/// a trajectory that shrinks (|x| from 19 to 1.6 in four steps, seed 6742016220725902189)
/// still carries, for a few steps, the error made on the larger scale.
pub fn assert_runs_agree_to<N: Dim>(a: &Run<N>, b: &Run<N>, tol_x: f64, tol_p: f64, what: &str)
where
    DefaultAllocator: Alloc<N>,
{
    assert_eq!(a.len(), b.len());
    let mut largest_scale = 0.0_f64;
    for (k, ((xa, pa), (xb, pb))) in a.iter().zip(b).enumerate() {
        let (dx, dp) = estimate_rel_diff(xa, pa, xb, pb);
        let scale = state_scale(xb, pb);
        largest_scale = largest_scale.max(scale);
        let dx = dx * scale / largest_scale;
        assert!(
            dx <= tol_x && dp <= tol_p,
            "{what}, step {k}: relative state diff {dx:e} (tol {tol_x:e}), covariance diff \
             {dp:e} (tol {tol_p:e})\nxa = {xa}xb = {xb}Pa = {pa}Pb = {pb}"
        );
    }
}
