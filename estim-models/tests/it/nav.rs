//! The navigation model set (`estim_models::nav`, issue 38):
//!
//! - the mechanisation against an independent route, the closed form of a constant-rate
//!   coordinated turn;
//! - the process and sensor Jacobians against automatic derivatives **on the manifold**:
//!   δ ↦ f(x ⊞ δ) ⊟ f(x) written a second time over the dual-number scalar with
//!   `estim_core::autodiff`'s generic rotations, earth and transport rates on;
//! - gravity, geodesy and alignment inputs, and their errors.

use core::f64::consts::PI;

use estim_core::autodiff::{
    AdScalar, AutoDiff, AutoDiffFunction, quaternion_conjugate, quaternion_lift,
    quaternion_product, quaternion_rotate, so3_exp, so3_log,
};
use estim_core::derivative::check_measurement_jacobian_on;
use estim_core::manifold;
use estim_core::nalgebra::{Const, Matrix3, Quaternion, SVector, UnitQuaternion, Vector3};
use estim_core::{
    Differentiable, MeasurementJacobian, MeasurementModel, ProcessJacobian, ProcessModel,
    VectorFunction,
};
use estim_models::nav::{
    ACCEL_BIAS, ATTITUDE, BaroHeight, GYRO_BIAS, GnssPosition, GnssVelocity, Heading, Imu,
    InsSettings, Magnetometer, NavError, Origin, POSITION, STATE, Strapdown, VELOCITY, attitude,
    normal_gravity, normal_gravity_gradient, state_space, static_alignment,
};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

type State = SVector<f64, STATE>;
type S15 = Const<STATE>;

fn config(cases: u32, seed: u64) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..Config::default()
    }
}

fn origin() -> Origin {
    Origin::from_degrees(51.642, -2.526, 60.0).unwrap()
}

// ---------------------------------------------------------------------------------------------
// The coordinated turn.

#[test]
fn coordinated_turn_matches_its_closed_form() {
    // Speed V, turn rate ω, bank β = atan(V ω / g), pitch 0, level: the attitude is
    // Rz(ψ₀ + ω t) Rx(β), the body rate (0, ω sin β, ω cos β) and the specific force
    // (0, 0, −√((V ω)² + g²)) are constant, v = V (cos ψ, sin ψ, 0) and
    // p = (V/ω)(sin ψ − sin ψ₀, cos ψ₀ − cos ψ, 0).
    let o = origin();
    let ins = Strapdown::new(o, InsSettings::default()).unwrap();
    let (speed, rate, psi0) = (20.0, 0.1, 0.3);
    let g = o.gravity(0.0);
    let bank = (speed * rate / g).atan();
    let imu = Imu {
        gyro: Vector3::new(0.0, rate * bank.sin(), rate * bank.cos()),
        accel: Vector3::new(0.0, 0.0, -(speed * speed * rate * rate + g * g).sqrt()),
    };
    let q0 = UnitQuaternion::from_euler_angles(bank, 0.0, psi0);
    let mut x = State::zeros();
    x.fixed_rows_mut::<3>(ATTITUDE)
        .copy_from(&manifold::so3_log(&q0));
    x.fixed_rows_mut::<3>(VELOCITY).copy_from(&Vector3::new(
        speed * psi0.cos(),
        speed * psi0.sin(),
        0.0,
    ));
    let (dt, steps) = (0.01, 6283); // one full turn, 2π/ω ≈ 62.83 s
    for _ in 0..steps {
        x = ins.transition(&x, &imu, dt);
    }
    let t = dt * steps as f64;
    let psi = psi0 + rate * t;
    let q = UnitQuaternion::from_euler_angles(bank, 0.0, psi);
    let v = Vector3::new(speed * psi.cos(), speed * psi.sin(), 0.0);
    let p = Vector3::new(psi.sin() - psi0.sin(), psi0.cos() - psi.cos(), 0.0) * (speed / rate);

    // Attitude: the body rate is constant, so q ⊗ Exp(φ) is exact; only rounding, ≈ 4ε per
    // step over 6283 steps ≈ 6·10⁻¹² rad.
    let attitude_error = attitude(&x).angle_to(&q);
    assert!(attitude_error < 1e-9, "attitude {attitude_error} rad");
    // Velocity: R(q Exp(φ/2)) f Δt against ∫ R(q Exp(ω s)) f ds differs by Δt |φ|² |f| / 24
    // per step (φ = ω Δt = 10⁻³, |f| ≈ 10): 4.2·10⁻⁹ m/s, at most N times that, 2.6·10⁻⁵.
    let velocity_error = (x.fixed_rows::<3>(VELOCITY) - v).norm();
    assert!(velocity_error < 3e-5, "velocity {velocity_error} m/s");
    // Position: the trapezoid's Δt³ |v''| / 12 per step (|v''| = V ω² = 0.2): 1.7·10⁻⁸, times
    // N = 10⁻⁴ m, plus the velocity error integrated, ≤ T · 2.6·10⁻⁵ = 1.6·10⁻³ m.
    let position_error = (x.fixed_rows::<3>(POSITION) - p).norm();
    assert!(position_error < 2e-3, "position {position_error} m");
}

/// At rest on the rotating earth, the earth rate on: the gyros read ω_ie in the body frame and
/// the accelerometer −γ (normal gravity holds the centrifugal term), and the closed form is
/// "nothing changes". The body turns with the earth at q ⊗ Exp(Rᵀω_ie Δt) and the navigation
/// frame at Exp(−ω_ie Δt) ⊗ q: if either sign were wrong, the attitude would drift at 2ω_ie,
/// 1.5·10⁻⁴ rad/s, 0.52 rad over the hour run here.
#[test]
fn at_rest_on_the_rotating_earth_nothing_moves() {
    let o = origin();
    let settings = InsSettings {
        earth_rate: true,
        ..InsSettings::default()
    };
    let ins = Strapdown::new(o, settings).unwrap();
    let q0 = UnitQuaternion::from_euler_angles(0.2, -0.1, 2.0);
    let imu = Imu {
        gyro: q0.inverse() * o.earth_rate(),
        accel: q0.inverse() * Vector3::new(0.0, 0.0, -o.gravity(0.0)),
    };
    let mut x = State::zeros();
    x.fixed_rows_mut::<3>(ATTITUDE)
        .copy_from(&manifold::so3_log(&q0));
    let (dt, steps) = (0.02, 180_000); // one hour at 50 Hz
    for _ in 0..steps {
        x = ins.transition(&x, &imu, dt);
    }
    // Attitude: Exp(−ω Δt) q Exp(qᵀω Δt) = q exactly; rounding ≈ 4ε per step over 1.8·10⁵
    // steps ≈ 1.6·10⁻¹⁰ rad.
    let attitude_error = attitude(&x).angle_to(&q0);
    assert!(attitude_error < 1e-8, "attitude {attitude_error} rad");
    // Velocity and position: the specific force cancels γ to rounding (|f| ε ≈ 2·10⁻¹⁵ m/s² per
    // step, at most 4·10⁻¹⁰ m/s after the hour), and the Coriolis term is zero at v = 0.
    let velocity = x.fixed_rows::<3>(VELOCITY).norm();
    assert!(velocity < 1e-8, "velocity {velocity} m/s");
    let position = x.fixed_rows::<3>(POSITION).norm();
    assert!(position < 1e-4, "position {position} m");
}

// ---------------------------------------------------------------------------------------------
// Jacobians against automatic derivatives on the manifold.

/// The mechanisation again, over the dual scalar, from the same public constants.
struct Generic {
    earth: Vector3<f64>,
    transport: Matrix3<f64>,
    height: f64,
    /// γ(h) = g₀ + g₁ h + g₂ h² / 2 (the WGS-84 height formula is quadratic in h).
    gravity: (f64, f64, f64),
}

impl Generic {
    fn new(o: &Origin) -> Self {
        let (rm, rn) = o.radii();
        let (rm, rn) = (rm + o.height(), rn + o.height());
        let tan = o.latitude().tan();
        let g1 = normal_gravity_gradient(o.latitude(), 0.0);
        Self {
            earth: o.earth_rate(),
            transport: Matrix3::new(0.0, 1.0 / rn, 0.0, -1.0 / rm, 0.0, 0.0, 0.0, -tan / rn, 0.0),
            height: o.height(),
            gravity: (
                normal_gravity(o.latitude(), 0.0),
                g1,
                normal_gravity_gradient(o.latitude(), 1.0) - g1,
            ),
        }
    }

    /// (q⁺, v⁺, p⁺) from (q, v, p, b_g, b_a).
    #[allow(clippy::type_complexity)]
    fn step<D: AdScalar<f64>>(
        &self,
        q: &Quaternion<D>,
        x: &SVector<D, STATE>,
        imu: &Imu,
        dt: f64,
    ) -> (Quaternion<D>, Vector3<D>, Vector3<D>) {
        let c = |v: &Vector3<f64>| v.map(D::from);
        let v: Vector3<D> = x.fixed_rows::<3>(VELOCITY).into_owned();
        let p: Vector3<D> = x.fixed_rows::<3>(POSITION).into_owned();
        let d = D::from(dt);
        let phi = (c(&imu.gyro) - x.fixed_rows::<3>(GYRO_BIAS)) * d;
        let f = c(&imu.accel) - x.fixed_rows::<3>(ACCEL_BIAS);
        let transport = self.transport.map(D::from) * v;
        let nav = c(&self.earth) + transport;
        let coriolis = c(&self.earth) * D::from(2.0) + transport;
        let q_next = quaternion_product(
            &quaternion_product(&so3_exp::<f64, D>(&(-nav * d)), q),
            &so3_exp(&phi),
        );
        let mid = quaternion_product(
            &quaternion_product(&so3_exp::<f64, D>(&(-nav * D::from(dt / 2.0))), q),
            &so3_exp(&(phi * D::from(0.5))),
        );
        let h = D::from(self.height) - p[2];
        let (g0, g1, g2) = self.gravity;
        let gamma = h * h * D::from(g2 / 2.0) + h * D::from(g1) + D::from(g0);
        let gravity = Vector3::new(D::zero(), D::zero(), gamma);
        let v_next = v + (quaternion_rotate(&mid, &f) - coriolis.cross(&v) + gravity) * d;
        let p_next = p + (v + v_next) * D::from(dt / 2.0);
        (q_next, v_next, p_next)
    }
}

/// δ ↦ f(x ⊞ δ) ⊟ f(x).
struct ProcessOnManifold {
    generic: Generic,
    x: State,
    next: State,
    imu: Imu,
    dt: f64,
}

impl AutoDiffFunction<f64, S15, S15> for ProcessOnManifold {
    fn eval<D: AdScalar<f64>>(&self, delta: &SVector<D, STATE>) -> SVector<D, STATE> {
        let mut x: SVector<D, STATE> = self.x.map(D::from) + delta;
        let q = quaternion_product(
            &quaternion_lift::<f64, D>(&attitude(&self.x)),
            &so3_exp(&delta.fixed_rows::<3>(ATTITUDE).into_owned()),
        );
        x.fixed_rows_mut::<3>(ATTITUDE).fill(D::zero());
        let (q_next, v, p) = self.generic.step(&q, &x, &self.imu, self.dt);
        let error = so3_log::<f64, D>(&quaternion_product(
            &quaternion_conjugate(&quaternion_lift(&attitude(&self.next))),
            &q_next,
        ));
        let mut out = x - self.next.map(D::from);
        out.fixed_rows_mut::<3>(ATTITUDE).copy_from(&error);
        out.fixed_rows_mut::<3>(VELOCITY)
            .copy_from(&(v - self.next.fixed_rows::<3>(VELOCITY).map(D::from)));
        out.fixed_rows_mut::<3>(POSITION)
            .copy_from(&(p - self.next.fixed_rows::<3>(POSITION).map(D::from)));
        out
    }
}

/// δθ ↦ a generic sensor of the attitude at x ⊞ δ (magnetometer and heading).
struct SensorOnManifold {
    x: State,
    field: Vector3<f64>,
}

impl AutoDiffFunction<f64, S15, Const<4>> for SensorOnManifold {
    fn eval<D: AdScalar<f64>>(&self, delta: &SVector<D, STATE>) -> SVector<D, 4> {
        let q = quaternion_product(
            &quaternion_lift::<f64, D>(&attitude(&self.x)),
            &so3_exp(&delta.fixed_rows::<3>(ATTITUDE).into_owned()),
        );
        let m = quaternion_rotate(&quaternion_conjugate(&q), &self.field.map(D::from));
        let c = quaternion_rotate(&q, &Vector3::x().map(D::from));
        SVector::<D, 4>::new(m[0], m[1], m[2], c[1].atan2(c[0]))
    }
}

fn ball(radius: f64) -> impl Strategy<Value = Vector3<f64>> {
    prop::array::uniform3(-1.0..1.0f64)
        .prop_filter("inside the unit ball", |v| Vector3::from(*v).norm() <= 1.0)
        .prop_map(move |v| Vector3::from(v) * radius)
}

fn state() -> impl Strategy<Value = State> {
    (ball(2.5), ball(40.0), ball(500.0), ball(0.05), ball(0.5)).prop_map(|(t, v, p, bg, ba)| {
        let mut x = State::zeros();
        for (at, b) in [
            (ATTITUDE, t),
            (VELOCITY, v),
            (POSITION, p),
            (GYRO_BIAS, bg),
            (ACCEL_BIAS, ba),
        ] {
            x.fixed_rows_mut::<3>(at).copy_from(&b);
        }
        x
    })
}

/// Mixed tolerance |analytic − AD| ≤ TOL · max(1, |AD|): both sides evaluate the same
/// expressions (rotations, a few products) in a different order on values ≤ 500 (positions)
/// and rates ≤ 5 rad/s over Δt ≤ 0.05, so they differ by rounding, ≲ 100 ε · 500 ≈ 10⁻¹¹
/// absolute; a wrong term is at least γ' Δt ≈ 3·10⁻⁸ (the smallest entry, the free-air
/// gradient: checked separately below) or Ω Δt ≈ 4·10⁻⁷.
const TOL: f64 = 1e-11;

fn mixed(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1.0)
}

proptest! {
    #![proptest_config(config(48, 0x38a9))]

    #[test]
    fn process_jacobian_is_the_ad_one_on_the_manifold(
        x in state(), w in ball(5.0), f in ball(40.0), dt in 0.005..0.05f64,
        earth in any::<bool>(), transport in any::<bool>(),
    ) {
        let o = origin();
        let settings = InsSettings { earth_rate: earth, transport_rate: transport, ..InsSettings::default() };
        let ins = Strapdown::new(o, settings).unwrap();
        let imu = Imu { gyro: w, accel: f };
        let mut generic = Generic::new(&o);
        if !earth { generic.earth = Vector3::zeros(); }
        if !transport { generic.transport = Matrix3::zeros(); }
        let next = ins.transition(&x, &imu, dt);
        let ad = AutoDiff::new(ProcessOnManifold { generic, x, next, imu, dt });
        let zero = State::zeros();
        // The rewrite is the same function: f(x ⊞ 0) ⊟ f(x) = 0.
        prop_assert!(ad.eval(&zero).norm() < 1e-9, "{}", ad.eval(&zero));
        let want = ad.jacobian(&zero);
        let got = ins.transition_jacobian(&x, &imu, dt);
        for i in 0..STATE {
            for j in 0..STATE {
                prop_assert!(mixed(got[(i, j)], want[(i, j)]) < TOL,
                    "F[{i}, {j}] analytic {} AD {}", got[(i, j)], want[(i, j)]);
            }
        }
        // The gravity gradient (below TOL · 1 in absolute size) on its own, relatively.
        let (a, b) = (got[(VELOCITY + 2, POSITION + 2)], want[(VELOCITY + 2, POSITION + 2)]);
        prop_assert!((a - b).abs() <= 1e-6 * b.abs(), "γ' Δt: {a} vs {b}");
    }

    #[test]
    fn sensor_jacobians_are_the_ad_ones_on_the_manifold(x in state()) {
        let field = Vector3::new(0.19, -0.005, 0.45);
        let mag = Magnetometer { field, noise: Matrix3::identity() * 1e-4 };
        let heading = Heading { variance: 1e-3 };
        let ad = AutoDiff::new(SensorOnManifold { x, field });
        let zero = State::zeros();
        let value = ad.eval(&zero);
        prop_assert!((value.fixed_rows::<3>(0) - mag.measure(&x)).norm() < 1e-14);
        prop_assert!((value[3] - heading.measure(&x)[0]).abs() < 1e-14);
        let want = ad.jacobian(&zero);
        let got_mag = mag.measurement_jacobian(&x);
        let got_heading = heading.measurement_jacobian(&x);
        // O(1) entries through a few rotations: rounding ≲ 10⁻¹⁵; near-vertical body x axes
        // (c₀² + c₁² small) amplify the heading's, so 10⁻¹⁰ relative to the entry's size.
        let scale = want.row(3).amax().max(1.0);
        for j in 0..STATE {
            for i in 0..3 {
                prop_assert!((got_mag[(i, j)] - want[(i, j)]).abs() < 1e-13, "mag H[{i}, {j}]");
            }
            prop_assert!((got_heading[(0, j)] - want[(3, j)]).abs() < 1e-10 * scale, "heading H[0, {j}]");
        }
        // The linear ones by finite differences on the state space (exact for linear maps up to
        // rounding of the differences: 10⁻⁶ is the checker's documented f64 level).
        let space = state_space();
        let r3 = Matrix3::identity();
        let reports = [
            check_measurement_jacobian_on(&space, &GnssPosition { noise: r3 }, &x).unwrap(),
            check_measurement_jacobian_on(&space, &GnssVelocity { noise: r3 }, &x).unwrap(),
            check_measurement_jacobian_on(&space, &BaroHeight { variance: 1.0 }, &x).unwrap(),
        ];
        for report in reports {
            prop_assert!(report.is_accurate(1e-6), "{}", report);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Gravity, geodesy, alignment.

#[test]
fn gravity_and_geodesy() {
    // WGS-84 (NIMA TR8350.2, table 3.4): γ_e = 9.7803253359, γ_p = 9.8321849378 m/s².
    assert!((normal_gravity(0.0, 0.0) - 9.780_325_335_9).abs() < 1e-10);
    assert!((normal_gravity(PI / 2.0, 0.0) - 9.832_184_937_8).abs() < 1e-9);
    // The free-air gradient ≈ −3.086·10⁻⁶ s⁻² (mid-latitude), and it is the derivative:
    // γ is quadratic in h, so the central difference over ±100 m is exact up to rounding
    // (10⁻¹⁵ · 10 / 200 ≈ 5·10⁻¹⁷, relative 10⁻¹¹).
    let lat = 51.642f64.to_radians();
    let gradient = normal_gravity_gradient(lat, 300.0);
    let numeric = (normal_gravity(lat, 400.0) - normal_gravity(lat, 200.0)) / 200.0;
    assert!(
        (gradient - numeric).abs() < 1e-10 * gradient.abs(),
        "{gradient} vs {numeric}"
    );
    assert!((gradient + 3.086e-6).abs() < 0.01e-6, "{gradient}");
    // Local NED for small offsets: Δφ (R_M + h), Δλ (R_N + h) cos φ, to the curvature terms
    // (offset² / R ≈ 10⁻³ m for 100 m).
    let o = origin();
    let (rm, rn) = o.radii();
    let (dlat, dlon) = (
        100.0 / (rm + 60.0),
        50.0 / ((rn + 60.0) * o.latitude().cos()),
    );
    let ned = o.ned(
        (o.latitude() + dlat).to_degrees(),
        (o.longitude() + dlon).to_degrees(),
        60.0,
    );
    assert!(
        (ned - Vector3::new(100.0, 50.0, 0.0)).norm() < 2e-3,
        "{ned}"
    );
    // Bad inputs are typed errors.
    assert_eq!(
        Origin::from_degrees(90.0, 0.0, 0.0),
        Err(NavError::Latitude(90.0))
    );
    assert_eq!(
        Origin::from_degrees(f64::NAN, 0.0, 0.0),
        Err(NavError::NonFinite("latitude"))
    );
    let bad = InsSettings {
        gyro_noise: -1.0,
        ..InsSettings::default()
    };
    assert_eq!(
        Strapdown::new(o, bad),
        Err(NavError::NonFinite("gyro noise"))
    );
}

proptest! {
    #![proptest_config(config(64, 0x38aa))]

    #[test]
    fn static_alignment_recovers_the_attitude(
        roll in -1.2..1.2f64, pitch in -1.2..1.2f64, yaw in -PI..PI,
    ) {
        let truth = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        let field = Vector3::new(0.19, -0.005, 0.45);
        let accel = truth.inverse() * Vector3::new(0.0, 0.0, -9.81);
        let q = static_alignment(&accel, &(truth.inverse() * field), &field).unwrap();
        // A few atan2 and rotations on unit-size values: 10⁻¹² rad with margin.
        prop_assert!(q.angle_to(&truth) < 1e-12, "{}", q.angle_to(&truth));
    }
}

#[test]
fn static_alignment_refuses_degenerate_inputs() {
    let field = Vector3::new(0.19, -0.005, 0.45);
    let down = Vector3::new(0.0, 0.0, -9.81);
    assert_eq!(
        static_alignment(&Vector3::zeros(), &field, &field),
        Err(NavError::Degenerate("specific force"))
    );
    assert_eq!(
        static_alignment(&down, &Vector3::new(0.0, 0.0, 0.4), &field),
        Err(NavError::Degenerate("horizontal magnetometer reading"))
    );
    assert_eq!(
        static_alignment(&Vector3::new(f64::NAN, 0.0, 0.0), &field, &field),
        Err(NavError::NonFinite("specific force"))
    );
}
