//! The motion and sensor models' analytic Jacobians and Hessians against automatic derivatives
//! (estim-core's `AutoDiff`) of the same equations written a second time here, generically over
//! the scalar, at random points; the values are compared too, so the rewrite is the same
//! function.
//!
//! The turn functions are rewritten independently: closed forms for |θ| ≥ 0.3, and below it a
//! Taylor polynomial with literal coefficients up to θ¹⁰ (truncation ≤ 0.3¹²/13! ≈ 10⁻¹⁶), which
//! AD differentiates: the library's own series for the *derivatives* are thus checked, on both
//! sides of its series limit (|θ| = 1), and near ω = 0 (rates scaled by 10⁻³).
//!
//! Tolerance: `is_accurate(1e-11)`, |analytic − AD| ≤ 10⁻¹¹ · max(1, |AD|) per entry. Entries
//! are sums of a few products of inputs bounded by 10 (|x| ≤ 10, Δt ≤ 0.5, so θ ≤ 5); the two
//! sides evaluate different expressions, the worst being the closed forms' cancellation at
//! θ = 0.3, ≲ 30ε/θ⁴ ≈ 10⁻¹² relative, times entries ≲ 10. A wrong term is ≳ Δt³ ≥ 10⁻⁹ off.

use estim_core::autodiff::{
    AdScalar, AutoDiff, AutoDiffFunction, AutoDiffMeasurement, AutoDiffProcess,
};
use estim_core::derivative::{
    DerivativeReport, compare_measurement_models, compare_process_models,
};
use estim_core::nalgebra::{
    Const, Matrix1, Matrix2, SMatrix, SVector, U1, U2, U3, U4, U5, Vector1, Vector2, Vector3,
    Vector4, Vector5,
};
use estim_core::{Differentiable, ProcessModel};
use estim_models::motion::{
    ConstantAcceleration, ConstantVelocity, CoordinatedTurn, CoordinatedTurnRate, GaussMarkov,
    Noise, RandomWalk, Unicycle,
};
use estim_models::sensors::{Bearing, Position, Range, RangeBearing};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

/// See the module docs.
const TOL: f64 = 1e-11;

fn config(seed: u64) -> Config {
    Config {
        cases: 64,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..Config::default()
    }
}

fn assert_accurate(report: DerivativeReport<f64>) {
    assert!(report.is_accurate(TOL), "{report}");
}

fn values(len: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-10.0..10.0f64, len)
}

/// Σ cₖ t^{2k} by Horner.
fn even_poly<D: AdScalar<f64>>(t: D, c: &[f64]) -> D {
    let t2 = t * t;
    c.iter()
        .rev()
        .fold(D::from(0.0), |acc, &ck| acc * t2 + D::from(ck))
}

/// sin θ/θ.
fn sinc<D: AdScalar<f64>>(t: D) -> D {
    if t.re().abs() < 0.3 {
        let c = [
            1.0,
            -1.0 / 6.0,
            1.0 / 120.0,
            -1.0 / 5040.0,
            1.0 / 362880.0,
            -1.0 / 39916800.0,
        ];
        even_poly(t, &c)
    } else {
        t.sin() / t
    }
}

/// (1 − cos θ)/θ.
fn versinc<D: AdScalar<f64>>(t: D) -> D {
    if t.re().abs() < 0.3 {
        let c = [
            0.5,
            -1.0 / 24.0,
            1.0 / 720.0,
            -1.0 / 40320.0,
            1.0 / 3628800.0,
            -1.0 / 479001600.0,
        ];
        t * even_poly(t, &c)
    } else {
        (D::from(1.0) - t.cos()) / t
    }
}

// ---------------------------------------------------------------------------------------------
// Kinematic chains
// ---------------------------------------------------------------------------------------------

/// A K-integrator chain in D dimensions written out: component (i, a) of the state (block i,
/// axis a) moves by Σ_{j>i} Δt^{j−i}/(j−i)! x_{j,a}.
struct GenericChain<P, const K: usize, const D: usize>(P);

impl<P: ProcessModel<f64, Const<N>, Input = ()>, const K: usize, const D: usize, const N: usize>
    AutoDiffProcess<f64, Const<N>> for GenericChain<P, K, D>
{
    type Input = ();
    fn transition<E: AdScalar<f64>>(&self, x: &SVector<E, N>, _: &(), dt: f64) -> SVector<E, N> {
        let mut y = *x;
        for i in 0..K {
            for j in i + 1..K {
                let k = j - i;
                let c = dt.powi(k as i32) / (1..=k).product::<usize>() as f64;
                for a in 0..D {
                    y[i * D + a] += x[j * D + a] * c;
                }
            }
        }
        y
    }
    fn process_noise(&self, x: &SVector<f64, N>, u: &(), dt: f64) -> SMatrix<f64, N, N> {
        self.0.process_noise(x, u, dt)
    }
}

fn check_chain<P, const K: usize, const D: usize, const N: usize>(model: P, p: &[f64], dt: f64)
where
    P: estim_core::ProcessHessian<f64, Const<N>, Input = ()> + Copy,
{
    let x = SVector::<f64, N>::from_column_slice(&p[..N]);
    let ad = AutoDiff::new(GenericChain::<P, K, D>(model));
    assert_accurate(compare_process_models(&model, &ad, &x, &(), &(), dt).unwrap());
}

proptest! {
    #![proptest_config(config(0xc7))]

    #[test]
    fn kinematic_models(p in values(9), dt in 0.001..0.5f64, q in 0.0..2.0f64) {
        for noise in [Noise::Continuous(q), Noise::Discrete(q)] {
            check_chain::<_, 2, 1, 2>(ConstantVelocity::<f64, 1>::new(noise), &p, dt);
            check_chain::<_, 2, 2, 4>(ConstantVelocity::<f64, 2>::new(noise), &p, dt);
            check_chain::<_, 2, 3, 6>(ConstantVelocity::<f64, 3>::new(noise), &p, dt);
            check_chain::<_, 3, 1, 3>(ConstantAcceleration::<f64, 1>::new(noise), &p, dt);
            check_chain::<_, 3, 2, 6>(ConstantAcceleration::<f64, 2>::new(noise), &p, dt);
            check_chain::<_, 3, 3, 9>(ConstantAcceleration::<f64, 3>::new(noise), &p, dt);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Coordinated turn, unicycle, random walk, Gauss-Markov
// ---------------------------------------------------------------------------------------------

/// (x, y, vₓ, v_y) after a turn at rate ω (a scalar of any kind).
fn turn<E: AdScalar<f64>>(p: [E; 4], w: E, dt: f64) -> [E; 4] {
    let t = w * dt;
    let (a, b) = (sinc(t) * dt, versinc(t) * dt);
    let (s, c) = t.sin_cos();
    [
        p[0] + a * p[2] - b * p[3],
        p[1] + b * p[2] + a * p[3],
        c * p[2] - s * p[3],
        s * p[2] + c * p[3],
    ]
}

struct GenericTurn(CoordinatedTurn<f64>);

impl AutoDiffProcess<f64, U4> for GenericTurn {
    type Input = ();
    fn transition<E: AdScalar<f64>>(&self, x: &Vector4<E>, _: &(), dt: f64) -> Vector4<E> {
        Vector4::from(turn([x[0], x[1], x[2], x[3]], E::from(self.0.rate), dt))
    }
    fn process_noise(&self, x: &Vector4<f64>, u: &(), dt: f64) -> SMatrix<f64, 4, 4> {
        self.0.process_noise(x, u, dt)
    }
}

struct GenericTurnRate(CoordinatedTurnRate<f64>);

impl AutoDiffProcess<f64, U5> for GenericTurnRate {
    type Input = ();
    fn transition<E: AdScalar<f64>>(&self, x: &Vector5<E>, _: &(), dt: f64) -> Vector5<E> {
        let y = turn([x[0], x[1], x[2], x[3]], x[4], dt);
        Vector5::new(y[0], y[1], y[2], y[3], x[4])
    }
    fn process_noise(&self, x: &Vector5<f64>, u: &(), dt: f64) -> SMatrix<f64, 5, 5> {
        self.0.process_noise(x, u, dt)
    }
}

/// The unicycle's pose after the step, any scalar for the state and the input.
fn unicycle<E: AdScalar<f64>>(x: [E; 3], v: E, w: E, dt: f64) -> [E; 3] {
    let phi = w * (0.5 * dt);
    let l = v * dt * sinc(phi);
    let (s, c) = (x[2] + phi).sin_cos();
    [x[0] + l * c, x[1] + l * s, x[2] + w * dt]
}

struct GenericUnicycle(Unicycle<f64>);

impl AutoDiffProcess<f64, U3> for GenericUnicycle {
    type Input = Vector2<f64>;
    fn transition<E: AdScalar<f64>>(
        &self,
        x: &Vector3<E>,
        u: &Vector2<f64>,
        dt: f64,
    ) -> Vector3<E> {
        Vector3::from(unicycle(
            [x[0], x[1], x[2]],
            E::from(u[0]),
            E::from(u[1]),
            dt,
        ))
    }
    fn process_noise(&self, x: &Vector3<f64>, u: &Vector2<f64>, dt: f64) -> SMatrix<f64, 3, 3> {
        self.0.process_noise(x, u, dt)
    }
}

/// u ↦ f(x, u, Δt) at a fixed pose, for the input Jacobian.
struct UnicycleOfInput(Vector3<f64>, f64);

impl AutoDiffFunction<f64, U2, U3> for UnicycleOfInput {
    fn eval<E: AdScalar<f64>>(&self, u: &Vector2<E>) -> Vector3<E> {
        let x = [0, 1, 2].map(|i| E::from(self.0[i]));
        Vector3::from(unicycle(x, u[0], u[1], self.1))
    }
}

struct GenericWalk(RandomWalk<f64, 3>);

impl AutoDiffProcess<f64, U3> for GenericWalk {
    type Input = ();
    fn transition<E: AdScalar<f64>>(&self, x: &Vector3<E>, _: &(), _: f64) -> Vector3<E> {
        *x
    }
    fn process_noise(&self, x: &Vector3<f64>, u: &(), dt: f64) -> SMatrix<f64, 3, 3> {
        self.0.process_noise(x, u, dt)
    }
}

struct GenericGaussMarkov(GaussMarkov<f64, 2>);

impl AutoDiffProcess<f64, U2> for GenericGaussMarkov {
    type Input = ();
    fn transition<E: AdScalar<f64>>(&self, x: &Vector2<E>, _: &(), dt: f64) -> Vector2<E> {
        let tau = self.0.time_constant;
        Vector2::new(x[0] * (-dt / tau[0]).exp(), x[1] * (-dt / tau[1]).exp())
    }
    fn process_noise(&self, x: &Vector2<f64>, u: &(), dt: f64) -> SMatrix<f64, 2, 2> {
        self.0.process_noise(x, u, dt)
    }
}

proptest! {
    #![proptest_config(config(0x7a))]

    #[test]
    fn turning_models(p in values(7), dt in 0.001..0.5f64, small in any::<bool>()) {
        // Rates up to 10 rad/s, or up to 10⁻² (θ ≤ 5·10⁻³: the series near ω = 0).
        let w = if small { p[4] * 1e-3 } else { p[4] };
        let ct = CoordinatedTurn { rate: w, accel_psd: 0.3 };
        let x4 = Vector4::new(p[0], p[1], p[2], p[3]);
        assert_accurate(compare_process_models(&ct, &AutoDiff::new(GenericTurn(ct)), &x4, &(), &(), dt)?);
        let ctr = CoordinatedTurnRate { accel_psd: 0.3, rate_psd: 0.01 };
        let x5 = Vector5::new(p[0], p[1], p[2], p[3], w);
        assert_accurate(compare_process_models(&ctr, &AutoDiff::new(GenericTurnRate(ctr)), &x5, &(), &(), dt)?);

        let odometry = Unicycle { speed_variance: 0.04, rate_variance: 0.01 };
        let x3 = Vector3::new(p[0], p[1], p[2]);
        let u = Vector2::new(p[3], w);
        assert_accurate(compare_process_models(&odometry, &AutoDiff::new(GenericUnicycle(odometry)), &x3, &u, &u, dt)?);
        let ad_input = AutoDiff::new(UnicycleOfInput(x3, dt)).jacobian(&u);
        let analytic = odometry.input_jacobian(&x3, &u, dt);
        for (a, b) in analytic.iter().zip(ad_input.iter()) {
            prop_assert!((a - b).abs() <= TOL * b.abs().max(1.0), "{analytic} vs {ad_input}");
        }

        let walk = RandomWalk { psd: Vector3::new(0.1, 0.2, 0.3) };
        assert_accurate(compare_process_models(&walk, &AutoDiff::new(GenericWalk(walk)), &x3, &(), &(), dt)?);
        let gm = GaussMarkov { time_constant: Vector2::new(p[5].abs() + 0.1, 50.0), variance: Vector2::new(1.0, 0.5) };
        let x2 = Vector2::new(p[0], p[6]);
        assert_accurate(compare_process_models(&gm, &AutoDiff::new(GenericGaussMarkov(gm)), &x2, &(), &(), dt)?);
    }
}

// ---------------------------------------------------------------------------------------------
// Sensors
// ---------------------------------------------------------------------------------------------

struct GenericPosition;

impl AutoDiffMeasurement<f64, U5, U2> for GenericPosition {
    fn measure<E: AdScalar<f64>>(&self, x: &Vector5<E>) -> Vector2<E> {
        Vector2::new(x[0], x[1])
    }
    fn measurement_noise(&self, _: &Vector5<f64>) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

struct GenericRange<const D: usize>(SVector<f64, D>);

impl<const D: usize> AutoDiffMeasurement<f64, U5, U1> for GenericRange<D> {
    fn measure<E: AdScalar<f64>>(&self, x: &Vector5<E>) -> Vector1<E> {
        let mut s = E::from(0.0);
        for i in 0..D {
            let d = x[i] - self.0[i];
            s += d * d;
        }
        Vector1::new(s.sqrt())
    }
    fn measurement_noise(&self, _: &Vector5<f64>) -> Matrix1<f64> {
        Matrix1::identity()
    }
}

struct GenericBearing(Vector2<f64>);

impl AutoDiffMeasurement<f64, U5, U1> for GenericBearing {
    fn measure<E: AdScalar<f64>>(&self, x: &Vector5<E>) -> Vector1<E> {
        Vector1::new((x[1] - self.0[1]).atan2(x[0] - self.0[0]))
    }
    fn measurement_noise(&self, _: &Vector5<f64>) -> Matrix1<f64> {
        Matrix1::identity()
    }
}

struct GenericRangeBearing(Vector2<f64>);

impl AutoDiffMeasurement<f64, U5, U2> for GenericRangeBearing {
    fn measure<E: AdScalar<f64>>(&self, x: &Vector5<E>) -> Vector2<E> {
        let (dx, dy) = (x[0] - self.0[0], x[1] - self.0[1]);
        Vector2::new((dx * dx + dy * dy).sqrt(), dy.atan2(dx))
    }
    fn measurement_noise(&self, _: &Vector5<f64>) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

proptest! {
    #![proptest_config(config(0x5e))]

    #[test]
    fn sensor_models(p in values(8)) {
        let x = Vector5::from_column_slice(&p[..5]);
        let o2 = Vector2::new(p[5], p[6]);
        let o3 = Vector3::new(p[5], p[6], p[7]);
        // Keep the target ≥ 0.5 from the sensor: the derivatives scale as 1/r and 1/r².
        prop_assume!((x.fixed_rows::<2>(0) - o2).norm() > 0.5);
        let gps = Position::<f64, 2> { noise: Matrix2::identity() };
        assert_accurate(compare_measurement_models(&gps, &AutoDiff::new(GenericPosition), &x)?);
        let r2 = Range { origin: o2, variance: 1.0 };
        assert_accurate(compare_measurement_models(&r2, &AutoDiff::new(GenericRange(o2)), &x)?);
        let r3 = Range { origin: o3, variance: 1.0 };
        assert_accurate(compare_measurement_models(&r3, &AutoDiff::new(GenericRange(o3)), &x)?);
        let b = Bearing { origin: o2, variance: 1.0 };
        assert_accurate(compare_measurement_models(&b, &AutoDiff::new(GenericBearing(o2)), &x)?);
        let rb = RangeBearing { origin: o2, range_variance: 1.0, bearing_variance: 1.0 };
        assert_accurate(compare_measurement_models(&rb, &AutoDiff::new(GenericRangeBearing(o2)), &x)?);
    }
}

/// At the sensor's own position the derivatives are zero (finite), not NaN; the bearing
/// residual wraps across ±π (exact: the wrap subtracts 2π from a value near π).
#[test]
fn sensors_at_their_origin_and_across_pi() {
    use estim_core::{MeasurementHessian, MeasurementJacobian, MeasurementModel};
    let o = Vector2::new(1.0, 2.0);
    let x = Vector4::new(1.0, 2.0, 5.0, 5.0);
    let rb = RangeBearing {
        origin: o,
        range_variance: 1.0,
        bearing_variance: 1.0,
    };
    assert_eq!(rb.measure(&x), Vector2::new(0.0, 0.0));
    assert_eq!(rb.measurement_jacobian(&x), SMatrix::<f64, 2, 4>::zeros());
    for k in 0..2 {
        assert_eq!(
            rb.measurement_hessian(&x, k),
            Some(SMatrix::<f64, 4, 4>::zeros())
        );
    }
    let r = Range {
        origin: Vector3::new(1.0, 2.0, 5.0),
        variance: 1.0,
    };
    assert_eq!(r.measurement_jacobian(&x), SMatrix::<f64, 1, 4>::zeros());
    let a = Vector2::new(3.0, 3.1);
    let b = Vector2::new(3.0, -3.1);
    let mut d = Vector2::zeros();
    MeasurementModel::<f64, U4, U2>::residual_into(&rb, &a, &b, &mut d);
    assert!((d[1] - (6.2 - 2.0 * std::f64::consts::PI)).abs() < 1e-15);
    assert_eq!(d[0], 0.0);
}

// ---------------------------------------------------------------------------------------------
// Augmentation
// ---------------------------------------------------------------------------------------------

use estim_core::nalgebra::{SVector as Sv, U7};
use estim_models::augment::{Augmented, Biased};

type TurnWithBiases = Augmented<CoordinatedTurnRate<f64>, GaussMarkov<f64, 2>, 5, 2>;

/// The coordinated turn (5 states) with two Gauss-Markov biases appended, written out.
struct GenericAugmented(TurnWithBiases);

impl AutoDiffProcess<f64, U7> for GenericAugmented {
    type Input = ();
    fn transition<E: AdScalar<f64>>(&self, x: &Sv<E, 7>, _: &(), dt: f64) -> Sv<E, 7> {
        let y = turn([x[0], x[1], x[2], x[3]], x[4], dt);
        let tau = self.0.augment.time_constant;
        Sv::<E, 7>::from_column_slice(&[
            y[0],
            y[1],
            y[2],
            y[3],
            x[4],
            x[5] * (-dt / tau[0]).exp(),
            x[6] * (-dt / tau[1]).exp(),
        ])
    }
    fn process_noise(&self, x: &Sv<f64, 7>, u: &(), dt: f64) -> SMatrix<f64, 7, 7> {
        self.0.process_noise(x, u, dt)
    }
}

/// Range and bearing with the two biases added: z = (r + b₁, β + b₂).
struct GenericBiasedRangeBearing(Vector2<f64>);

impl AutoDiffMeasurement<f64, U7, U2> for GenericBiasedRangeBearing {
    fn measure<E: AdScalar<f64>>(&self, x: &Sv<E, 7>) -> Vector2<E> {
        let (dx, dy) = (x[0] - self.0[0], x[1] - self.0[1]);
        Vector2::new((dx * dx + dy * dy).sqrt() + x[5], dy.atan2(dx) + x[6])
    }
    fn measurement_noise(&self, _: &Sv<f64, 7>) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

proptest! {
    #![proptest_config(config(0xa6))]

    /// The augmented models' derivatives are the blocks' (the same tolerance as above).
    #[test]
    fn augmented_models(p in values(9), dt in 0.001..0.5f64) {
        let model: TurnWithBiases = Augmented {
            model: CoordinatedTurnRate { accel_psd: 0.3, rate_psd: 0.01 },
            augment: GaussMarkov { time_constant: Vector2::new(5.0, 60.0), variance: Vector2::new(0.1, 0.01) },
        };
        let x = Sv::<f64, 7>::from_column_slice(&p[..7]);
        assert_accurate(compare_process_models(&model, &AutoDiff::new(GenericAugmented(model)), &x, &(), &(), dt)?);
        let o = Vector2::new(p[7], p[8]);
        prop_assume!((x.fixed_rows::<2>(0) - o).norm() > 0.5);
        let sensor = Biased::<_, f64, 5, 2, 2> {
            model: RangeBearing { origin: o, range_variance: 1.0, bearing_variance: 1.0 },
            coupling: Matrix2::identity(),
        };
        assert_accurate(compare_measurement_models(&sensor, &AutoDiff::new(GenericBiasedRangeBearing(o)), &x)?);
    }
}

/// ω = 0 exactly (θ = 0: where a closed form would divide 0 by 0): the turn models' values,
/// Jacobians and Hessians are finite and equal the automatic derivatives of the series, and
/// the unicycle's input Jacobian too (same tolerance as above).
#[test]
fn turns_at_zero_rate() {
    let x5 = Vector5::new(1.0, -2.0, 3.0, 0.5, 0.0);
    let ctr = CoordinatedTurnRate {
        accel_psd: 0.3,
        rate_psd: 0.01,
    };
    let ad = AutoDiff::new(GenericTurnRate(ctr));
    for dt in [0.0, 0.1, 2.0] {
        assert_accurate(compare_process_models(&ctr, &ad, &x5, &(), &(), dt).unwrap());
    }
    let odometry = Unicycle {
        speed_variance: 0.04,
        rate_variance: 0.01,
    };
    let x3 = Vector3::new(1.0, -2.0, 0.3);
    let u = Vector2::new(2.0, 0.0);
    let ad = AutoDiff::new(GenericUnicycle(odometry));
    assert_accurate(compare_process_models(&odometry, &ad, &x3, &u, &u, 0.5).unwrap());
    let ad_input = AutoDiff::new(UnicycleOfInput(x3, 0.5)).jacobian(&u);
    assert!((odometry.input_jacobian(&x3, &u, 0.5) - ad_input).amax() <= TOL);
}

/// The models are generic over the scalar: an f32 constant-velocity filter with a range
/// sensor runs and stays finite.
#[test]
fn models_run_in_single_precision() {
    use estim_core::Gaussian;
    use estim_core::nalgebra::Matrix4;
    use estim_filters::{Ekf, Estimator, Predict, Update};
    let cv = ConstantVelocity::<f32, 2>::new(Noise::Continuous(0.01));
    let beacon = Range {
        origin: Vector2::new(10.0f32, 0.0),
        variance: 0.01,
    };
    let prior = Gaussian::new(Vector4::new(0.0f32, 0.0, 1.0, 0.0), Matrix4::identity()).unwrap();
    let mut ekf = Ekf::new(prior);
    for k in 1..=20 {
        ekf.predict(&cv, &(), 0.1).unwrap();
        let z = Vector1::new(10.0 - 0.1 * k as f32);
        ekf.update(&beacon, &z).unwrap();
    }
    // Noise-free ranges of a target moving at 1 m/s toward the beacon, 2 m covered: one
    // realisation of a consistent filter, so the error sits inside 3σ of the posterior.
    let sigma = ekf.covariance()[(0, 0)].sqrt();
    assert!(sigma < 0.1, "σ = {sigma}");
    assert!(
        (ekf.state()[0] - 2.0).abs() <= 3.0 * sigma,
        "{}",
        ekf.state()
    );
}
