//! The state-space hook (⊞/⊟, Hertzberg et al. 2013): a generic space whose ⊞ and ⊟ are + and
//! − gives the default filters' results bit for bit (so the hook costs no accuracy, and is
//! called), and a wrapping ⊞ keeps a heading estimate right across ±π where plain vector
//! arithmetic does not.

use core::cell::Cell;
use core::f64::consts::PI;

use crate::common::{normal, rng};
use estim_core::manifold::AttitudeError;
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Dyn, Matrix1, Matrix2, OMatrix, OVector, U1, U2,
    Vector1, Vector2,
};
use estim_core::{
    Alloc, Error, Gaussian, LinearMeasurement, LinearProcess, MeasurementHessian,
    MeasurementJacobian, MeasurementModel, ProcessHessian, ProcessJacobian, ProcessModel,
    StateSpace, Unscented, wrap_angle,
};
use estim_filters::{
    Ekf, Estimator, GaussianFilter, GaussianSecondOrderEkf, Predict, SecondOrderEkf, Ukf, Update,
};

// ---------------------------------------------------------------------------------------------
// Bit-identity of the generic path.

/// ⊞ = +, ⊟ = −, but not declared a vector space (`VECTOR = false`), so every generic path
/// runs; counts its calls.
#[derive(Clone, Debug, Default, PartialEq)]
struct Identity {
    plus: Cell<usize>,
    minus: Cell<usize>,
}

impl<N: Dim> StateSpace<f64, N> for Identity
where
    DefaultAllocator: Alloc<N>,
{
    fn plus_into(&self, x: &OVector<f64, N>, delta: &OVector<f64, N>, out: &mut OVector<f64, N>) {
        self.plus.set(self.plus.get() + 1);
        *out = x + delta;
    }

    fn minus_into(&self, a: &OVector<f64, N>, b: &OVector<f64, N>, out: &mut OVector<f64, N>) {
        self.minus.set(self.minus.get() + 1);
        *out = a - b;
    }
}

/// A pendulum, x = (θ, ω): θ⁺ = θ + Δt ω, ω⁺ = ω − Δt g sin θ. Static (`U2`) or `Dyn` (length 2).
#[derive(Debug)]
struct Pendulum;

const G: f64 = 9.81;

impl<N: Dim> ProcessModel<f64, N> for Pendulum
where
    DefaultAllocator: Alloc<N>,
{
    type Input = ();

    fn transition(&self, x: &OVector<f64, N>, _: &(), dt: f64) -> OVector<f64, N> {
        let mut y = x.clone();
        y[0] = x[0] + dt * x[1];
        y[1] = x[1] - dt * G * x[0].sin();
        y
    }

    fn process_noise(&self, x: &OVector<f64, N>, _: &(), dt: f64) -> OMatrix<f64, N, N> {
        let d = x.shape_generic().0;
        let mut q = OMatrix::<f64, N, N>::zeros_generic(d, d);
        q[(0, 0)] = 1e-4 * dt;
        q[(1, 1)] = 1e-2 * dt;
        q
    }
}

impl<N: Dim> ProcessJacobian<f64, N> for Pendulum
where
    DefaultAllocator: Alloc<N>,
{
    fn transition_jacobian(&self, x: &OVector<f64, N>, _: &(), dt: f64) -> OMatrix<f64, N, N> {
        let d = x.shape_generic().0;
        let mut f = OMatrix::<f64, N, N>::identity_generic(d, d);
        f[(0, 1)] = dt;
        f[(1, 0)] = -dt * G * x[0].cos();
        f
    }
}

impl Pendulum {
    fn hessian<N: Dim>(x: &OVector<f64, N>, dt: f64, k: usize) -> Option<OMatrix<f64, N, N>>
    where
        DefaultAllocator: Alloc<N>,
    {
        (k == 1).then(|| {
            let d = x.shape_generic().0;
            let mut h = OMatrix::<f64, N, N>::zeros_generic(d, d);
            h[(0, 0)] = dt * G * x[0].sin();
            h
        })
    }
}

impl ProcessHessian<f64, U2> for Pendulum {
    fn transition_hessian(
        &self,
        x: &Vector2<f64>,
        _: &(),
        dt: f64,
        k: usize,
    ) -> Option<Matrix2<f64>> {
        Self::hessian(x, dt, k)
    }
}

impl ProcessHessian<f64, Dyn> for Pendulum {
    fn transition_hessian(
        &self,
        x: &DVector<f64>,
        _: &(),
        dt: f64,
        k: usize,
    ) -> Option<DMatrix<f64>> {
        Self::hessian(x, dt, k)
    }
}

/// The bob's position, z = (sin θ, 1 − cos θ) + v.
#[derive(Debug)]
struct Bob;

impl<N: Dim> MeasurementModel<f64, N, N> for Bob
where
    DefaultAllocator: Alloc<N>,
{
    fn measure(&self, x: &OVector<f64, N>) -> OVector<f64, N> {
        let mut z = x.clone();
        z[0] = x[0].sin();
        z[1] = 1.0 - x[0].cos();
        z
    }

    fn measurement_noise(&self, x: &OVector<f64, N>) -> OMatrix<f64, N, N> {
        let d = x.shape_generic().0;
        OMatrix::<f64, N, N>::identity_generic(d, d) * 1e-2
    }
}

impl<N: Dim> MeasurementJacobian<f64, N, N> for Bob
where
    DefaultAllocator: Alloc<N>,
{
    fn measurement_jacobian(&self, x: &OVector<f64, N>) -> OMatrix<f64, N, N> {
        let d = x.shape_generic().0;
        let mut h = OMatrix::<f64, N, N>::zeros_generic(d, d);
        h[(0, 0)] = x[0].cos();
        h[(1, 0)] = x[0].sin();
        h
    }
}

impl Bob {
    fn hessian<N: Dim>(x: &OVector<f64, N>, k: usize) -> Option<OMatrix<f64, N, N>>
    where
        DefaultAllocator: Alloc<N>,
    {
        let d = x.shape_generic().0;
        let mut h = OMatrix::<f64, N, N>::zeros_generic(d, d);
        h[(0, 0)] = if k == 0 { -x[0].sin() } else { x[0].cos() };
        Some(h)
    }
}

impl MeasurementHessian<f64, U2, U2> for Bob {
    fn measurement_hessian(&self, x: &Vector2<f64>, k: usize) -> Option<Matrix2<f64>> {
        Self::hessian(x, k)
    }
}

impl MeasurementHessian<f64, Dyn, Dyn> for Bob {
    fn measurement_hessian(&self, x: &DVector<f64>, k: usize) -> Option<DMatrix<f64>> {
        Self::hessian(x, k)
    }
}

/// Runs `plain` and `generic` (the same filter on [`Identity`]) through 60 predict/update
/// steps of a swinging pendulum and asserts equal estimates, bit for bit, after every step.
/// Returns the Identity's (⊞, ⊟) call counts.
fn assert_bit_identical<N, Pr>(
    mut plain: GaussianFilter<f64, N, Pr>,
    mut generic: GaussianFilter<f64, N, Pr, Identity>,
    vector: impl Fn(f64, f64) -> OVector<f64, N>,
) -> (usize, usize)
where
    N: Dim,
    Pr: estim_core::PropagatorWorkspace<f64>,
    GaussianFilter<f64, N, Pr>: Predict<f64, N, Pendulum> + Update<f64, N, N, Bob>,
    GaussianFilter<f64, N, Pr, Identity>: Predict<f64, N, Pendulum> + Update<f64, N, N, Bob>,
    DefaultAllocator: Alloc<N>,
{
    let mut rng = rng(0x5eed_b00b);
    let dt = 0.05;
    let mut truth = vector(1.2, 0.0);
    for step in 0..60 {
        truth = Pendulum.transition(&truth, &(), dt);
        let z = Bob.measure(&truth) + vector(0.1 * normal(&mut rng), 0.1 * normal(&mut rng));
        plain.predict(&Pendulum, &(), dt).unwrap();
        generic.predict(&Pendulum, &(), dt).unwrap();
        assert_eq!(
            plain.state(),
            generic.state(),
            "predicted state, step {step}"
        );
        assert_eq!(
            plain.covariance(),
            generic.covariance(),
            "predicted P, step {step}"
        );
        plain.update(&Bob, &z).unwrap();
        generic.update(&Bob, &z).unwrap();
        assert_eq!(plain.state(), generic.state(), "updated state, step {step}");
        assert_eq!(
            plain.covariance(),
            generic.covariance(),
            "updated P, step {step}"
        );
    }
    let space = generic.state_space();
    (space.plus.get(), space.minus.get())
}

fn static_prior() -> Gaussian<f64, U2> {
    Gaussian::new(Vector2::new(1.0, 0.2), Matrix2::new(0.2, 0.0, 0.0, 0.3)).unwrap()
}

fn dyn_prior() -> Gaussian<f64, Dyn> {
    let p = static_prior();
    Gaussian::new(
        DVector::from_column_slice(p.mean().as_slice()),
        DMatrix::from_column_slice(2, 2, p.covariance().as_slice()),
    )
    .unwrap()
}

fn static_vector(a: f64, b: f64) -> Vector2<f64> {
    Vector2::new(a, b)
}

fn dyn_vector(a: f64, b: f64) -> DVector<f64> {
    DVector::from_vec(vec![a, b])
}

#[test]
fn ekf_on_a_generic_identity_space_is_bit_identical() {
    for (plus, minus) in [
        assert_bit_identical(
            Ekf::new(static_prior()),
            Ekf::new(static_prior()).with_state_space(Identity::default()),
            static_vector,
        ),
        assert_bit_identical(
            Ekf::new(dyn_prior()),
            Ekf::new(dyn_prior()).with_state_space(Identity::default()),
            dyn_vector,
        ),
    ] {
        // One ⊞ per update (x ⊞ K ν); the linearisation needs no ⊟.
        assert_eq!((plus, minus), (60, 0));
    }
}

#[test]
fn second_order_ekf_on_a_generic_identity_space_is_bit_identical() {
    for (plus, minus) in [
        assert_bit_identical(
            SecondOrderEkf::new(static_prior()),
            SecondOrderEkf::new(static_prior()).with_state_space(Identity::default()),
            static_vector,
        ),
        assert_bit_identical(
            SecondOrderEkf::new(dyn_prior()),
            SecondOrderEkf::new(dyn_prior()).with_state_space(Identity::default()),
            dyn_vector,
        ),
    ] {
        // Per step: the predicted mean's bias correction f(x̂) ⊞ δ and the update's x ⊞ K ν.
        assert_eq!((plus, minus), (120, 0));
    }
}

#[test]
fn ukf_on_a_generic_identity_space_is_bit_identical() {
    for (plus, minus) in [
        assert_bit_identical(
            Ukf::new(static_prior()),
            Ukf::new(static_prior()).with_state_space(Identity::default()),
            static_vector,
        ),
        assert_bit_identical(
            Ukf::new(dyn_prior()),
            Ukf::new(dyn_prior()).with_state_space(Identity::default()),
            dyn_vector,
        ),
    ] {
        // Per step, n = 2: the prediction's 2n sigma points, the mean f(x̂) ⊞ d̄ and 2n
        // deviations ⊟; the update's 2n sigma points and x ⊞ K ν.
        assert_eq!((plus, minus), (60 * (4 + 1 + 4 + 1), 60 * 4));
    }
}

// ---------------------------------------------------------------------------------------------
// A heading across ±π.

/// θ⁺ = wrap(θ + ω Δt) + w, ω the input, w ~ N(0, q).
#[derive(Debug)]
struct Turning {
    q: f64,
}

impl ProcessModel<f64, U1> for Turning {
    type Input = f64;

    fn transition(&self, x: &Vector1<f64>, omega: &f64, dt: f64) -> Vector1<f64> {
        Vector1::new(wrap_angle(x[0] + omega * dt))
    }

    fn process_noise(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        Matrix1::new(self.q)
    }
}

impl ProcessJacobian<f64, U1> for Turning {
    fn transition_jacobian(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        Matrix1::new(1.0)
    }
}

/// A compass, z = θ + v (wrapped), v ~ N(0, r); the residual wraps.
#[derive(Debug)]
struct Compass {
    r: f64,
}

impl MeasurementModel<f64, U1, U1> for Compass {
    fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> {
        *x
    }

    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(self.r)
    }

    fn residual_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
        *out = Vector1::new(wrap_angle(a[0] - b[0]));
    }
}

impl MeasurementJacobian<f64, U1, U1> for Compass {
    fn measurement_jacobian(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(1.0)
    }
}

/// A heading in (−π, π]: ⊞ and ⊟ wrap.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct WrappedHeading;

impl StateSpace<f64, U1> for WrappedHeading {
    fn plus_into(&self, x: &Vector1<f64>, delta: &Vector1<f64>, out: &mut Vector1<f64>) {
        out[0] = wrap_angle(x[0] + delta[0]);
    }

    fn minus_into(&self, a: &Vector1<f64>, b: &Vector1<f64>, out: &mut Vector1<f64>) {
        out[0] = wrap_angle(a[0] - b[0]);
    }
}

/// What a run through the heading scenario measured.
#[derive(Debug)]
struct HeadingRun {
    /// The largest |wrap(θ̂ − θ)| / √P, over predicted and updated estimates.
    worst_sigmas: f64,
    /// The largest |wrap(θ̂ − θ)| (rad).
    worst_error: f64,
    /// Steps whose estimate left (−π, π].
    outside: usize,
}

const HEADING_STEPS: usize = 400;

/// The heading turns at ω = 1 rad/s, Δt = 0.25 s, through +π every 25 steps (16 crossings),
/// with process noise σ = 0.02 rad per step and compass noise σ = 0.05 rad; truth and
/// measurements drawn from one seeded generator.
fn run_heading<F>(mut filter: F) -> HeadingRun
where
    F: Predict<f64, U1, Turning> + Update<f64, U1, U1, Compass>,
{
    let (omega, dt) = (1.0, 0.25);
    let (process, compass) = (Turning { q: 0.02 * 0.02 }, Compass { r: 0.05 * 0.05 });
    let mut rng = rng(0x00ea_d1c9);
    let mut truth = 2.0;
    let mut run = HeadingRun {
        worst_sigmas: 0.0,
        worst_error: 0.0,
        outside: 0,
    };
    let mut check = |filter: &F, truth: f64| {
        let (x, p) = (filter.state()[0], filter.covariance()[(0, 0)]);
        let error = wrap_angle(x - truth).abs();
        run.worst_error = run.worst_error.max(error);
        run.worst_sigmas = run.worst_sigmas.max(error / p.sqrt());
        if !(x > -PI && x <= PI) {
            run.outside += 1;
        }
    };
    for _ in 0..HEADING_STEPS {
        truth = wrap_angle(truth + omega * dt + 0.02 * normal(&mut rng));
        let z = Vector1::new(wrap_angle(truth + 0.05 * normal(&mut rng)));
        filter.predict(&process, &omega, dt).unwrap();
        check(&filter, truth);
        filter.update(&compass, &z).unwrap();
        check(&filter, truth);
    }
    run
}

fn heading_prior() -> Gaussian<f64, U1> {
    Gaussian::new(Vector1::new(2.1), Matrix1::new(0.1 * 0.1)).unwrap()
}

#[test]
fn ukf_with_a_wrapping_state_space_tracks_a_heading_across_pi() {
    // The cubature spread (sigma points at ±√P) straddles ±π at every crossing, the case
    // that breaks plain vector arithmetic; the default α = 10⁻³ does too when it straddles.
    for propagator in [Unscented::cubature(), Unscented::default()] {
        let run = run_heading(
            Ukf::with_propagator(heading_prior(), propagator).with_state_space(WrappedHeading),
        );
        // Measured: 3.41 σ (0.109 rad) at worst over the 800 estimates, for both.
        assert!(run.worst_sigmas < 5.0, "{propagator:?}: {run:?}");
        assert_eq!(run.outside, 0, "{propagator:?}: {run:?}");
    }
    // Without ⊞ the deviation f(χ) − f(x̂) of a straddling sigma point is ≈ 2π: the
    // predicted mean jumps by ≈ π and P by ≈ 2π². Measured: worst error 3.13 rad.
    let run = run_heading(Ukf::with_propagator(heading_prior(), Unscented::cubature()));
    assert!(run.worst_error > 1.0, "{run:?}");
}

#[test]
fn ekf_with_a_wrapping_state_space_keeps_a_heading_in_range() {
    let run = run_heading(Ekf::new(heading_prior()).with_state_space(WrappedHeading));
    // Measured: 3.41 σ (0.109 rad) at worst.
    assert!(run.worst_sigmas < 5.0, "{run:?}");
    assert_eq!(run.outside, 0, "{run:?}");
    // Without ⊞, x̂ + K ν leaves (−π, π] after updates near the crossing (the model wraps it
    // back at the next prediction); the linearisation (F = 1) never sees the wrap, so the
    // wrapped error itself stays as small as with ⊞. Measured: one estimate out of range,
    // worst error 0.109 rad (3.41 σ), as with ⊞.
    let run = run_heading(Ekf::new(heading_prior()));
    assert!(run.outside > 0, "{run:?}");
}

#[test]
fn gaussian_second_order_ekf_on_a_generic_identity_space_is_bit_identical() {
    for (plus, minus) in [
        assert_bit_identical(
            GaussianSecondOrderEkf::new(static_prior()),
            GaussianSecondOrderEkf::new(static_prior()).with_state_space(Identity::default()),
            static_vector,
        ),
        assert_bit_identical(
            GaussianSecondOrderEkf::new(dyn_prior()),
            GaussianSecondOrderEkf::new(dyn_prior()).with_state_space(Identity::default()),
            dyn_vector,
        ),
    ] {
        // As the second-order EKF: the mean's bias correction and the update's x ⊞ K ν.
        assert_eq!((plus, minus), (120, 0));
    }
}

#[test]
fn ready_made_wrapped_angles_equal_the_hand_written_heading_space() {
    // estim-core's `WrappedAngles` is the `WrappedHeading` above for any angle index set:
    // through the whole heading scenario, the same worst-case statistics, bit for bit.
    let runs = |propagator: Unscented<f64>| {
        let hand = run_heading(
            Ukf::with_propagator(heading_prior(), propagator).with_state_space(WrappedHeading),
        );
        let ready = run_heading(
            Ukf::with_propagator(heading_prior(), propagator)
                .with_state_space(estim_core::WrappedAngles::new([0])),
        );
        (hand, ready)
    };
    for propagator in [Unscented::cubature(), Unscented::default()] {
        let (hand, ready) = runs(propagator);
        assert_eq!(hand.worst_sigmas.to_bits(), ready.worst_sigmas.to_bits());
        assert_eq!(hand.worst_error.to_bits(), ready.worst_error.to_bits());
        assert_eq!((hand.outside, ready.outside), (0, 0));
    }
}

/// An attitude error block beyond the state (`AttitudeError::at(0)` on 2 states): its ⊞ and
/// ⊟ give NaN, so the step that uses them fails with a typed error and leaves the filter
/// unchanged, in the UKF's prediction (sigma points x ⊞ δ) and the EKF's update (x ⊞ K ν).
/// Before, ⊞ and ⊟ panicked.
#[test]
fn an_attitude_block_beyond_the_state_is_a_typed_error() {
    let process = LinearProcess {
        transition: DMatrix::identity(2, 2),
        input: DMatrix::zeros(2, 1),
        noise: DMatrix::identity(2, 2) * 0.01,
    };
    let measurement = LinearMeasurement {
        observation: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        noise: DMatrix::identity(1, 1) * 0.1,
    };
    let space = AttitudeError::at(0);
    let non_finite = |e: &Error| matches!(e, Error::NonFinite { .. });

    let mut ukf = Ukf::new(dyn_prior()).with_state_space(space);
    let before = ukf.clone();
    let error = ukf.predict(&process, &DVector::zeros(1), 0.1).unwrap_err();
    assert!(non_finite(&error), "UKF prediction: {error:?}");
    assert!(ukf == before, "a failed UKF prediction changed the filter");

    let mut ekf = Ekf::new(dyn_prior()).with_state_space(space);
    let before = ekf.clone();
    let error = ekf
        .update(&measurement, &DVector::from_vec(vec![0.5]))
        .unwrap_err();
    assert!(non_finite(&error), "EKF update: {error:?}");
    assert!(ekf == before, "a failed EKF update changed the filter");
}

/// Runs `full` and `square_root` through the heading scenario side by side and returns the
/// largest |wrap(x̂ − x̂_SR)| and |P − S Sᵀ| over the 800 predicted and updated estimates,
/// with the number of square-root estimates on either side of ±π (|x̂| > 3, negative and
/// positive) and outside (−π, π].
fn side_by_side<F, G>(mut full: F, mut square_root: G) -> (f64, f64, usize, usize, usize)
where
    F: Predict<f64, U1, Turning> + Update<f64, U1, U1, Compass>,
    G: Predict<f64, U1, Turning> + Update<f64, U1, U1, Compass>,
{
    let (omega, dt) = (1.0, 0.25);
    let (process, compass) = (Turning { q: 0.02 * 0.02 }, Compass { r: 0.05 * 0.05 });
    let mut rng = rng(0x5eed_0035);
    let mut truth: f64 = 2.0;
    let (mut mean_gap, mut cov_gap, mut below, mut above, mut outside) =
        (0.0_f64, 0.0_f64, 0, 0, 0);
    let mut compare = |full: &F, square_root: &G| {
        let (a, b) = (full.state()[0], square_root.state()[0]);
        mean_gap = mean_gap.max(wrap_angle(a - b).abs());
        cov_gap = cov_gap.max((full.covariance()[(0, 0)] - square_root.covariance()[(0, 0)]).abs());
        below += usize::from(b < -3.0);
        above += usize::from(b > 3.0);
        outside += usize::from(!(b > -PI && b <= PI));
    };
    for _ in 0..HEADING_STEPS {
        truth = wrap_angle(truth + omega * dt + 0.02 * normal(&mut rng));
        let z = Vector1::new(wrap_angle(truth + 0.05 * normal(&mut rng)));
        full.predict(&process, &omega, dt).unwrap();
        square_root.predict(&process, &omega, dt).unwrap();
        compare(&full, &square_root);
        full.update(&compass, &z).unwrap();
        square_root.update(&compass, &z).unwrap();
        compare(&full, &square_root);
    }
    (mean_gap, cov_gap, below, above, outside)
}

#[test]
fn square_root_filters_on_wrapped_angles_match_the_full_covariance_filters() {
    use estim_filters::{SrEkf, SrUkf};
    let space = estim_core::WrappedAngles::new([0]);
    // Round-off: the two forms order their arithmetic differently (S Sᵀ against P), a few
    // ε per step on x̂ ≈ π and P ≈ 1e-3, and the filter contracts so the differences do not
    // accumulate. Measured: 4.4e-16 (2 ulp of π) on x̂ and 2.6e-18 on P at worst over the
    // 800 estimates; 1e-14 leaves a margin of 20 on x̂.
    let tolerance = 1e-14;
    for propagator in [Unscented::cubature(), Unscented::default()] {
        let (mean_gap, cov_gap, below, above, outside) = side_by_side(
            Ukf::with_propagator(heading_prior(), propagator).with_state_space(space),
            SrUkf::with_propagator(heading_prior(), propagator).with_state_space(space),
        );
        assert!(
            mean_gap < tolerance && cov_gap < tolerance,
            "{propagator:?}: {mean_gap:e} {cov_gap:e}"
        );
        // The run crosses ±π (16 crossings): estimates on both sides of it, none outside.
        assert!(
            below > 0 && above > 0 && outside == 0,
            "{below} {above} {outside}"
        );
    }
    let (mean_gap, cov_gap, below, above, outside) = side_by_side(
        Ekf::new(heading_prior()).with_state_space(space),
        SrEkf::new(heading_prior()).with_state_space(space),
    );
    assert!(
        mean_gap < tolerance && cov_gap < tolerance,
        "EKF: {mean_gap:e} {cov_gap:e}"
    );
    assert!(
        below > 0 && above > 0 && outside == 0,
        "{below} {above} {outside}"
    );
    // Without ⊞/⊟ the SR-UKF's straddling sigma points jump by ≈ 2π (as the UKF's do): the
    // space is what the square-root form uses.
    let (mean_gap, ..) = side_by_side(
        Ukf::with_propagator(heading_prior(), Unscented::cubature()).with_state_space(space),
        SrUkf::with_propagator(heading_prior(), Unscented::cubature()),
    );
    assert!(mean_gap > 1.0, "{mean_gap}");
}
