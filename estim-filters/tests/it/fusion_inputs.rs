//! Sampled inputs and rollback of everything an estimate depends on (issue 38).
//!
//! 1. [`InputConvention::Preceding`]: an IMU-style stream (sample k covers (t_{k−1}, t_k])
//!    goes straight into the driver. Without measurements it gives the closed-form
//!    propagation of the piecewise-constant input; with position fixes taken between samples
//!    and delivered late, early (ahead of the samples) or in time order, it gives, bit for bit,
//!    the hold-forward driver fed by a hand-written queue (each sample stamped with the start
//!    of its interval) — the queue is no longer needed.
//! 2. An attitude held in the filter's own state (the rotation vector of the attitude under
//!    [`AttitudeError`], no reference outside the filter) with a gyro bias, gyro samples as
//!    preceding inputs, accelerometer and magnetometer directions as measurements: out-of-order
//!    delivery through the driver equals time-ordered delivery bit for bit, because the
//!    driver's snapshots hold everything the estimate depends on.

use estim_core::derivative::{check_measurement_jacobian_on, check_process_jacobian_on};
use estim_core::manifold::{AttitudeError, so3_exp, so3_log};
use estim_core::nalgebra::{
    Matrix2, Matrix3, Matrix3x6, Matrix6, U2, U3, U6, UnitQuaternion, Vector1, Vector2, Vector3,
    Vector6,
};
use estim_core::{
    Gaussian, Linearized, MeasurementJacobian, MeasurementModel, ProcessJacobian, ProcessModel,
    error::Result,
};
use estim_filters::fusion::{
    FusionDriver, FusionError, FusionSetting, FusionSettings, Innovation, InputConvention,
    SensorSet, SensorSettings,
};
use estim_filters::{Ekf, Estimator, GaussianFilter, Update};

use crate::common::{normal, rng};
use crate::fusion_support::{Cart, Reading, noise};

// ---------------------------------------------------------------------------------------------
// 1. The input conventions on a cart driven by its acceleration.

/// x = (p, v), u = a held over the step: p⁺ = p + v Δt + a Δt²/2, v⁺ = v + a Δt (exact for a
/// piecewise-constant a, so sub-steps change nothing but rounding).
#[derive(Clone, Copy, Debug)]
struct Accelerated;

impl ProcessModel<f64, U2> for Accelerated {
    type Input = Vector1<f64>;
    fn transition(&self, x: &Vector2<f64>, a: &Vector1<f64>, dt: f64) -> Vector2<f64> {
        Vector2::new(x[0] + x[1] * dt + a[0] * dt * dt / 2.0, x[1] + a[0] * dt)
    }
    fn process_noise(&self, _: &Vector2<f64>, _: &Vector1<f64>, dt: f64) -> Matrix2<f64> {
        noise(0.01, dt)
    }
}

impl ProcessJacobian<f64, U2> for Accelerated {
    fn transition_jacobian(&self, _: &Vector2<f64>, _: &Vector1<f64>, dt: f64) -> Matrix2<f64> {
        Matrix2::new(1.0, dt, 0.0, 1.0)
    }
}

const PERIOD: f64 = 0.02;
const SAMPLES: usize = 150;

fn sample_time(k: usize) -> f64 {
    k as f64 * PERIOD
}

/// Sample k (1-based) is the acceleration over (t_{k−1}, t_k].
fn samples() -> Vec<f64> {
    let mut r = rng(0x1a5);
    (1..=SAMPLES)
        .map(|k| (0.3 * k as f64).sin() + 0.1 * normal(&mut r))
        .collect()
}

/// Position fixes 7 ms before every 5th sample (inside an interval), from the exact track.
fn fixes(a: &[f64]) -> Vec<(f64, f64)> {
    let mut r = rng(0x1a6);
    let mut out = Vec::new();
    let (mut p, mut v) = (0.0, 1.0);
    for (i, &ak) in a.iter().enumerate() {
        let k = i + 1;
        if k % 5 == 0 {
            let h = PERIOD - 0.007;
            out.push((
                sample_time(k) - 0.007,
                p + v * h + ak * h * h / 2.0 + 0.1 * normal(&mut r),
            ));
        }
        (p, v) = (p + v * PERIOD + ak * PERIOD * PERIOD / 2.0, v + ak * PERIOD);
    }
    out
}

type CartDriver = FusionDriver<f64, U2, Ekf<f64, U2>, Accelerated, Cart>;

fn cart_driver(convention: InputConvention) -> CartDriver {
    let prior = Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::identity() * 0.01).unwrap();
    let settings = FusionSettings {
        horizon: 0.5,
        capacity: 128,
        max_step: PERIOD,
        ..FusionSettings::default()
    };
    FusionDriver::new(
        Ekf::new(prior),
        Accelerated,
        Vector1::zeros(),
        Cart::new(),
        0.0,
        settings,
        SensorSettings::default(),
    )
    .unwrap()
    .with_input_convention(convention)
    .unwrap()
}

enum Delivery {
    Sample(usize),
    Fix(f64, f64),
}

/// Samples at their times, fixes at their time plus `delay(i)`, in arrival order (stable).
fn arrivals(a: &[f64], delay: impl Fn(usize) -> f64) -> Vec<Delivery> {
    let mut events: Vec<(f64, Delivery)> = (1..=a.len())
        .map(|k| (sample_time(k), Delivery::Sample(k)))
        .collect();
    for (i, (t, z)) in fixes(a).into_iter().enumerate() {
        events.push((t + delay(i), Delivery::Fix(t, z)));
    }
    events.sort_by(|x, y| x.0.total_cmp(&y.0));
    events.into_iter().map(|(_, d)| d).collect()
}

fn run_preceding(a: &[f64], delay: Option<fn(usize) -> f64>) -> CartDriver {
    let mut d = cart_driver(InputConvention::Preceding);
    let events = match delay {
        Some(delay) => arrivals(a, delay),
        None => (1..=a.len()).map(Delivery::Sample).collect(),
    };
    for event in events {
        match event {
            Delivery::Sample(k) => d.set_input(sample_time(k), Vector1::new(a[k - 1])).unwrap(),
            Delivery::Fix(t, z) => {
                d.fuse(t, Reading::Position(Vector1::new(z))).unwrap();
            }
        }
    }
    d
}

fn bits(d: &CartDriver) -> (Vec<u64>, f64) {
    let f = d.filter();
    let v = f
        .state()
        .iter()
        .chain(f.covariance().iter())
        .map(|x| x.to_bits())
        .collect();
    (v, d.time())
}

#[test]
fn preceding_samples_give_the_closed_form_propagation() {
    let a = samples();
    let d = run_preceding(&a, None); // no fixes
    // p(t_K) = p₀ + v₀ t_K + Σ_k a_k (Δt²/2 + Δt (t_K − t_k)), v(t_K) = v₀ + Σ_k a_k Δt.
    let t_end = sample_time(a.len());
    let (mut p, mut v) = (t_end, 1.0);
    for (i, &ak) in a.iter().enumerate() {
        p += ak * (PERIOD * PERIOD / 2.0 + PERIOD * (t_end - sample_time(i + 1)));
        v += ak * PERIOD;
    }
    let x = d.filter().state();
    // 150 steps, each a few roundings of O(10) values: 150 · 10 · 4ε ≈ 10⁻¹², with margin.
    assert!(
        (x[0] - p).abs() < 1e-9 && (x[1] - v).abs() < 1e-9,
        "{x} vs ({p}, {v})"
    );
    assert_eq!(d.time(), t_end);

    // The same stream held forward from each sample's time is one sample late: off by about
    // Σ (a_k − a_{k−1}) Δt ≈ 10⁻² in v, far above the rounding above.
    let mut late = cart_driver(InputConvention::HoldForward);
    for (i, &ak) in a.iter().enumerate() {
        late.set_input(sample_time(i + 1), Vector1::new(ak))
            .unwrap();
    }
    let y = late.filter().state();
    assert!((y[1] - v).abs() > 1e-3, "{y} vs ({p}, {v})");
}

#[test]
fn preceding_samples_replay_bit_for_bit_like_a_hand_written_queue() {
    let a = samples();
    // The queue: each sample stamped with the start of its interval, held forward, and the
    // fixes in time order; the last interval closed by advancing to its end.
    let mut queued = cart_driver(InputConvention::HoldForward);
    let mut events: Vec<(f64, Option<f64>, f64)> = (1..=a.len())
        .map(|k| (sample_time(k - 1), None, a[k - 1]))
        .collect();
    events.extend(fixes(&a).into_iter().map(|(t, z)| (t, Some(z), 0.0)));
    events.sort_by(|x, y| x.0.total_cmp(&y.0));
    for (t, fix, ak) in events {
        match fix {
            Some(z) => {
                queued.fuse(t, Reading::Position(Vector1::new(z))).unwrap();
            }
            None => queued.set_input(t, Vector1::new(ak)).unwrap(),
        }
    }
    queued.advance_to(sample_time(a.len())).unwrap();

    let in_order = run_preceding(&a, Some(|_| 0.0));
    // Late by 0.15 s (a GPS's latency), and every third one 12 ms early: ahead of the sample
    // that covers it, which hold-forward refuses ("before the latest event").
    let mixed = run_preceding(&a, Some(|i| if i % 3 == 0 { -0.012 } else { 0.15 }));
    assert_eq!(bits(&in_order), bits(&queued));
    assert_eq!(bits(&mixed), bits(&queued));
    let decisions = |d: &CartDriver| d.decisions().collect::<Vec<_>>();
    assert_eq!(decisions(&mixed), decisions(&queued));
    assert!(!decisions(&mixed).is_empty());
}

#[test]
fn preceding_samples_come_in_order_and_the_convention_is_set_first() {
    let mut d = cart_driver(InputConvention::Preceding);
    d.set_input(0.04, Vector1::new(1.0)).unwrap();
    d.fuse(0.05, Reading::Position(Vector1::new(0.05))).unwrap();
    let before = bits(&d);
    assert!(matches!(
        d.set_input(0.03, Vector1::new(1.0)),
        Err(FusionError::NotMonotone { latest, .. }) if latest == 0.04
    ));
    assert!(matches!(
        d.set_input(f64::NAN, Vector1::new(1.0)),
        Err(FusionError::NonFiniteTime { .. })
    ));
    assert_eq!(bits(&d), before);
    // Inside (0.04, 0.05]: before the fix, accepted, and the fix re-run after it.
    d.set_input(0.045, Vector1::new(2.0)).unwrap();
    assert_eq!(d.time(), 0.05);
    let changed = cart_driver(InputConvention::HoldForward);
    let mut started = changed;
    started.advance_to(0.01).unwrap();
    assert!(matches!(
        started.with_input_convention(InputConvention::Preceding),
        Err(FusionError::InvalidSetting {
            setting: FusionSetting::InputConvention,
            ..
        })
    ));
}

// ---------------------------------------------------------------------------------------------
// 2. An attitude in the filter's state, replayed.

/// x = (θ, b): q = Exp(θ) the attitude body → level frame, b the gyro bias; u = the gyro
/// sample ω over the step: θ⁺ = Log(Exp(θ) Exp((ω − b) Δt)), b⁺ = b.
#[derive(Clone, Copy, Debug)]
struct Gyro;

const GYRO_NOISE: f64 = 0.01; // rad/s/√Hz
const BIAS_WALK: f64 = 1e-4; // rad/s²/√Hz

/// J_r(φ) = I − (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×², the right Jacobian of SO(3).
fn right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    if theta < 1e-6 {
        return Matrix3::identity() - k * 0.5 + k * k / 6.0;
    }
    let t2 = theta * theta;
    Matrix3::identity() - k * ((1.0 - theta.cos()) / t2)
        + k * k * ((theta - theta.sin()) / (t2 * theta))
}

impl ProcessModel<f64, U6> for Gyro {
    type Input = Vector3<f64>;
    fn transition(&self, x: &Vector6<f64>, w: &Vector3<f64>, dt: f64) -> Vector6<f64> {
        let turn = (w - x.fixed_rows::<3>(3)) * dt;
        let theta = so3_log(&(so3_exp(&x.xyz()) * so3_exp(&turn)));
        let mut out = *x;
        out.fixed_rows_mut::<3>(0).copy_from(&theta);
        out
    }
    fn process_noise(&self, _: &Vector6<f64>, _: &Vector3<f64>, dt: f64) -> Matrix6<f64> {
        let mut q = Matrix6::zeros();
        for i in 0..3 {
            q[(i, i)] = GYRO_NOISE * GYRO_NOISE * dt;
            q[(i + 3, i + 3)] = BIAS_WALK * BIAS_WALK * dt;
        }
        q
    }
}

impl ProcessJacobian<f64, U6> for Gyro {
    /// On the manifold: δθ⁺ = R(φ)ᵀ δθ − J_r(φ) Δt δb, φ = (ω − b) Δt.
    fn transition_jacobian(&self, x: &Vector6<f64>, w: &Vector3<f64>, dt: f64) -> Matrix6<f64> {
        let phi = (w - x.fixed_rows::<3>(3)) * dt;
        let mut f = Matrix6::identity();
        let r = so3_exp(&phi).to_rotation_matrix().into_inner();
        f.fixed_view_mut::<3, 3>(0, 0).copy_from(&r.transpose());
        f.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-right_jacobian(&phi) * dt));
        f
    }
}

/// A direction known in the level frame, seen in the body frame: z = R(q)ᵀ d.
#[derive(Clone, Copy, Debug)]
struct Direction {
    d: Vector3<f64>,
    sigma: f64,
}

impl MeasurementModel<f64, U6, U3> for Direction {
    fn measure(&self, x: &Vector6<f64>) -> Vector3<f64> {
        so3_exp(&x.xyz()).inverse() * self.d
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix3<f64> {
        Matrix3::identity() * (self.sigma * self.sigma)
    }
}

impl MeasurementJacobian<f64, U6, U3> for Direction {
    /// (R Exp(δθ))ᵀ d ≈ Rᵀ d + [Rᵀ d]× δθ.
    fn measurement_jacobian(&self, x: &Vector6<f64>) -> Matrix3x6<f64> {
        let mut h = Matrix3x6::zeros();
        h.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&self.measure(x).cross_matrix());
        h
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Vane {
    Gravity(Vector3<f64>),
    Field(Vector3<f64>),
}

struct Vanes {
    gravity: Direction,
    field: Direction,
}

impl<F: Update<f64, U6, U3, Direction>> SensorSet<f64, U6, F> for Vanes {
    type Reading = Vane;
    fn count(&self) -> usize {
        2
    }
    fn sensor(&self, r: &Vane) -> usize {
        match r {
            Vane::Gravity(_) => 0,
            Vane::Field(_) => 1,
        }
    }
    fn dimension(&self, _: usize) -> usize {
        3
    }
    fn update(&self, filter: &mut F, r: &Vane) -> Result<Innovation<f64>> {
        let (model, z) = match r {
            Vane::Gravity(z) => (&self.gravity, z),
            Vane::Field(z) => (&self.field, z),
        };
        filter.update(model, z).map(|r| Innovation::of(&r))
    }
}

fn vanes() -> Vanes {
    Vanes {
        gravity: Direction {
            d: Vector3::new(0.0, 0.0, -1.0),
            sigma: 0.05,
        },
        field: Direction {
            d: Vector3::new(0.4, 0.05, 0.9).normalize(),
            sigma: 0.05,
        },
    }
}

fn true_rate(t: f64) -> Vector3<f64> {
    Vector3::new(0.8 * (1.3 * t).sin(), 0.5, -0.6 * (0.7 * t).cos())
}

const BIAS: Vector3<f64> = Vector3::new(0.01, -0.02, 0.005);

/// The truth at every gyro sample (integrated in 20 sub-steps per 20 ms), the gyro samples
/// (the mean rate over the interval, plus bias and noise), and the direction readings at
/// 10 Hz (gravity) and 10 Hz offset by 13 ms (field).
#[allow(clippy::type_complexity)]
fn attitude_run(
    seconds: f64,
) -> (
    Vec<UnitQuaternion<f64>>,
    Vec<Vector3<f64>>,
    Vec<(f64, Vane)>,
) {
    let mut r = rng(0x38a7);
    let n = (seconds / PERIOD).round() as usize;
    let sub = 20;
    let h = PERIOD / sub as f64;
    let mut q = UnitQuaternion::from_euler_angles(0.2, -0.1, 1.0);
    let (mut truth, mut gyro, mut readings) = (vec![q], Vec::new(), Vec::new());
    let sigma = GYRO_NOISE / PERIOD.sqrt();
    let v = vanes();
    for k in 1..=n {
        let mut mean = Vector3::zeros();
        for s in 0..sub {
            let t = sample_time(k - 1) + (s as f64 + 0.5) * h;
            let w = true_rate(t);
            q *= so3_exp(&(w * h));
            mean += w / sub as f64;
        }
        truth.push(q);
        gyro.push(mean + BIAS + Vector3::from_fn(|_, _| sigma * normal(&mut r)));
        let t = sample_time(k);
        let noisy = |d: &Direction, q: &UnitQuaternion<f64>, r: &mut rand::rngs::StdRng| {
            q.inverse() * d.d + Vector3::from_fn(|_, _| d.sigma * normal(r))
        };
        if k % 5 == 0 {
            readings.push((t, Vane::Gravity(noisy(&v.gravity, &q, &mut r))));
        }
        if k % 5 == 2 {
            // 13 ms before the sample: the truth there, to first order in ω (|ω| 13 ms ≤ 0.02).
            let back = q * so3_exp(&(-true_rate(t) * 0.013));
            readings.push((t - 0.013, Vane::Field(noisy(&v.field, &back, &mut r))));
        }
    }
    (truth, gyro, readings)
}

type AttitudeDriver =
    FusionDriver<f64, U6, GaussianFilter<f64, U6, Linearized, AttitudeError>, Gyro, Vanes>;

fn attitude_driver() -> AttitudeDriver {
    // Start 0.1 rad off the truth, the bias unknown.
    let start = so3_log(
        &(UnitQuaternion::from_euler_angles(0.2, -0.1, 1.0)
            * so3_exp(&Vector3::new(0.05, -0.05, 0.07))),
    );
    let mut p = Matrix6::identity() * 0.01;
    for i in 3..6 {
        p[(i, i)] = 1e-3;
    }
    let prior =
        Gaussian::new(Vector6::new(start[0], start[1], start[2], 0.0, 0.0, 0.0), p).unwrap();
    let settings = FusionSettings {
        horizon: 0.5,
        capacity: 128,
        max_step: PERIOD,
        ..FusionSettings::default()
    };
    FusionDriver::new(
        Ekf::new(prior).with_state_space(AttitudeError::at(0)),
        Gyro,
        Vector3::zeros(),
        vanes(),
        0.0,
        settings,
        SensorSettings::gated(0.9999),
    )
    .unwrap()
    .with_input_convention(InputConvention::Preceding)
    .unwrap()
}

fn run_attitude(gyro: &[Vector3<f64>], readings: &[(f64, Vane)], late: f64) -> AttitudeDriver {
    let mut events: Vec<(f64, usize, bool)> = (1..=gyro.len())
        .map(|k| (sample_time(k), k, true))
        .collect();
    for (i, (t, reading)) in readings.iter().enumerate() {
        let delay = match reading {
            Vane::Field(_) => late,
            Vane::Gravity(_) => 0.0,
        };
        events.push((t + delay, i, false));
    }
    events.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut d = attitude_driver();
    for (_, i, sample) in events {
        if sample {
            d.set_input(sample_time(i), gyro[i - 1]).unwrap();
        } else {
            d.fuse(readings[i].0, readings[i].1).unwrap();
        }
    }
    d
}

#[test]
fn attitude_jacobians_are_right_on_the_manifold() {
    let space = AttitudeError::at(0);
    let x = Vector6::new(0.9, -1.4, 1.1, 0.02, -0.01, 0.03);
    let report =
        check_process_jacobian_on(&space, &Gyro, &x, &Vector3::new(2.0, -1.0, 3.0), 0.1).unwrap();
    // Central differences of O(1) smooth functions: ≈ 10⁻¹⁰ (see derivative.rs' tolerance).
    assert!(report.is_accurate(1e-6), "{report}");
    let report = check_measurement_jacobian_on(&space, &vanes().field, &x).unwrap();
    assert!(report.is_accurate(1e-6), "{report}");
}

#[test]
fn attitude_in_the_state_replays_bit_for_bit() {
    let (truth, gyro, readings) = attitude_run(6.0);
    let in_order = run_attitude(&gyro, &readings, 0.0);
    let late = run_attitude(&gyro, &readings, 0.17);
    let f = |d: &AttitudeDriver| {
        let f = d.filter();
        f.state()
            .iter()
            .chain(f.covariance().iter())
            .map(|x| x.to_bits())
            .collect::<Vec<_>>()
    };
    assert_eq!(f(&late), f(&in_order));
    assert_eq!(
        late.decisions().collect::<Vec<_>>(),
        in_order.decisions().collect::<Vec<_>>()
    );
    assert_eq!(late.time(), in_order.time());

    // And it tracks: the attitude error within its own covariance. For a Gaussian error e ~
    // N(0, P), |e|² = Σ λᵢ zᵢ² with tr P = Σ λᵢ; at a fixed trace the tail is widest when P
    // has rank one, so P(|e|² > c tr P) ≤ P(χ²₁ > c) = 10⁻³ at c = 10.83, whatever P's shape.
    let x = in_order.filter().state();
    let error = so3_log(&(truth.last().unwrap().inverse() * so3_exp(&x.xyz()))).norm();
    let trace = in_order
        .filter()
        .covariance()
        .fixed_view::<3, 3>(0, 0)
        .trace();
    assert!(
        error * error <= 10.83 * trace,
        "error {error} rad, tr P {trace}"
    );
    // Consistent: the 0.9999 gate rejects about one clean reading in 10⁴.
    let accepted = in_order.health(0).accepted + in_order.health(1).accepted;
    assert!(
        accepted + 2 >= readings.len() as u64,
        "{accepted} of {}",
        readings.len()
    );
}
