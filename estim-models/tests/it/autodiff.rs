//! Every paper model's analytic Jacobian and Hessians against automatic derivatives
//! (estim-core's `AutoDiff`) of the same equations, written a second time here generically
//! over the scalar, at random points: a sharper check than finite differences (no truncation
//! error), and the values are compared too, so the rewrite is the same function.
//!
//! Tolerance: `is_accurate(1e-12)`, |analytic − AD| ≤ 10⁻¹² · max(1, |AD|) per entry. The two
//! sides evaluate the same expressions in a different order; each entry is a sum of at most ~10
//! products of inputs bounded by 10 (|x|, |u| ≤ 10, Δt ≤ 0.5, R ≥ 0.1), so rounding differs by
//! ≲ 10 · 2ε · 10² ≈ 4·10⁻¹³ absolute (and ≈ 10⁻¹⁵ relative for the larger entries): the
//! issue's ~10⁻¹² relative. A wrong analytic term is O(Δt²) ≥ 10⁻⁴ off.

use estim_core::autodiff::{
    AdScalar, AutoDiff, AutoDiffFunction, AutoDiffMeasurement, AutoDiffProcess,
};
use estim_core::derivative::{
    DerivativeReport, compare_derivatives, compare_measurement_models, compare_process_models,
};
use estim_core::nalgebra::{
    Matrix1, Matrix2, Matrix3, Matrix6, OMatrix, U1, U2, U3, U5, U6, Vector1, Vector2, Vector3,
    Vector4, Vector5, Vector6,
};
use estim_core::{MeasurementJacobian, MeasurementModel};
use estim_models::boje::{
    self, AccelerometerInversion, ChannelVariances, NonlinearPlanarProcess, PlanarInput,
    PlanarProcess, PositionHeadingMeasurement, RateSquaredMeasurement, ScalarRateProcess,
    ScalarRateSquared,
};
use estim_models::lee_huang::{
    AttitudeMeasurement, CkfInput, CkfProcess, Discretization, InsProcess, Plane,
};
use estim_models::lu::{self, BiasCoupling, ErrorStateProcess, GpsMeasurement};
use estim_models::lv2::XyqModel;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

/// See the module docs.
const TOL: f64 = 1e-12;

fn config(seed: u64) -> Config {
    Config {
        cases: 48,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..Config::default()
    }
}

fn assert_accurate(report: DerivativeReport<f64>) {
    assert!(report.is_accurate(TOL), "{report}");
}

fn lift<D: AdScalar<f64>, const R: usize, const C: usize>(
    m: &OMatrix<f64, estim_core::nalgebra::Const<R>, estim_core::nalgebra::Const<C>>,
) -> OMatrix<D, estim_core::nalgebra::Const<R>, estim_core::nalgebra::Const<C>> {
    m.map(D::from)
}

// ---------------------------------------------------------------------------------------------
// Boje
// ---------------------------------------------------------------------------------------------

/// Eq 5 rows 1–3: (ẍ, ÿ, θ̈) from θ and the four accelerometer channels.
fn invert_generic<D: AdScalar<f64>>(theta: D, a: [D; 4], half_separation: f64) -> [D; 4] {
    let (s, c) = theta.sin_cos();
    let (su, sv) = (a[0] + a[2], a[1] + a[3]);
    [
        (c * su - s * sv) * 0.5,
        (s * su + c * sv) * 0.5,
        (a[1] - a[3]) / (2.0 * half_separation),
        (a[2] - a[0]) / (2.0 * half_separation),
    ]
}

struct GenericNonlinearPlanar(NonlinearPlanarProcess);

impl AutoDiffProcess<f64, U6> for GenericNonlinearPlanar {
    type Input = Vector4<f64>;
    fn transition<D: AdScalar<f64>>(
        &self,
        x: &Vector6<D>,
        a: &Vector4<f64>,
        dt: f64,
    ) -> Vector6<D> {
        let a = [0, 1, 2, 3].map(|i| D::from(a[i]));
        let g = invert_generic(x[boje::filter::HEADING], a, self.0.half_separation);
        let b: OMatrix<D, U6, U3> = lift(&boje::filter::input_matrix(dt));
        lift::<D, 6, 6>(&boje::filter::transition_matrix(dt)) * x
            + b * Vector3::new(g[0], g[1], g[2])
    }
    fn process_noise(&self, x: &Vector6<f64>, a: &Vector4<f64>, dt: f64) -> Matrix6<f64> {
        estim_core::ProcessModel::process_noise(&self.0, x, a, dt)
    }
}

struct GenericPlanar;

impl AutoDiffProcess<f64, U6> for GenericPlanar {
    type Input = Vector3<f64>;
    fn transition<D: AdScalar<f64>>(
        &self,
        x: &Vector6<D>,
        u: &Vector3<f64>,
        dt: f64,
    ) -> Vector6<D> {
        // x⁺ = A x + B u written out: v += Δt u, p += Δt v + ½Δt² u.
        let mut y = *x;
        for i in 0..3 {
            y[i] = x[i] + u[i] * dt;
            y[i + 3] = x[i + 3] + x[i] * dt + u[i] * (0.5 * dt * dt);
        }
        y
    }
    fn process_noise(&self, _: &Vector6<f64>, _: &Vector3<f64>, _: f64) -> Matrix6<f64> {
        Matrix6::identity()
    }
}

struct GenericRateSquared;

impl AutoDiffMeasurement<f64, U6, U1> for GenericRateSquared {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector6<D>) -> Vector1<D> {
        Vector1::new(x[boje::filter::RATE].powi(2))
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix1<f64> {
        Matrix1::identity()
    }
}

struct GenericPositionHeading;

impl AutoDiffMeasurement<f64, U6, U3> for GenericPositionHeading {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector6<D>) -> Vector3<D> {
        Vector3::new(
            x[boje::filter::X],
            x[boje::filter::Y],
            x[boje::filter::HEADING],
        )
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix3<f64> {
        Matrix3::identity()
    }
}

struct GenericInversion(f64);

impl AutoDiffFunction<f64, U5, estim_core::nalgebra::U4> for GenericInversion {
    fn eval<D: AdScalar<f64>>(&self, z: &Vector5<D>) -> estim_core::nalgebra::Vector4<D> {
        Vector4::from(invert_generic(z[0], [z[1], z[2], z[3], z[4]], self.0))
    }
}

struct GenericScalarRate;

impl AutoDiffProcess<f64, U1> for GenericScalarRate {
    type Input = f64;
    fn transition<D: AdScalar<f64>>(&self, x: &Vector1<D>, u: &f64, dt: f64) -> Vector1<D> {
        Vector1::new(x[0] + dt * u)
    }
    fn process_noise(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        Matrix1::identity()
    }
}

struct GenericScalarRateSquared;

impl AutoDiffMeasurement<f64, U1, U1> for GenericScalarRateSquared {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector1<D>) -> Vector1<D> {
        Vector1::new(x[0] * x[0])
    }
    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::identity()
    }
}

fn variances() -> ChannelVariances {
    ChannelVariances {
        u1: 0.01,
        v1: 0.02,
        u2: 0.03,
        v2: 0.04,
    }
}

fn values(len: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-10.0..10.0f64, len)
}

proptest! {
    #![proptest_config(config(0xb0e))]

    #[test]
    fn boje_models(p in values(6 + 4 + 5), dt in 0.001..0.5f64, r in 0.1..2.0f64) {
        let x = Vector6::from_column_slice(&p[..6]);
        let a = Vector4::from_column_slice(&p[6..10]);
        let nonlinear = NonlinearPlanarProcess { half_separation: r, variances: variances() };
        let ad = AutoDiff::new(GenericNonlinearPlanar(nonlinear));
        assert_accurate(compare_process_models(&nonlinear, &ad, &x, &a, &a, dt)?);

        let planar = PlanarProcess { half_separation: r, variances: variances() };
        let input = PlanarInput { accel_mean: Vector3::new(p[6], p[7], p[8]), lambda: Default::default() };
        let ad = AutoDiff::new(GenericPlanar);
        assert_accurate(compare_process_models(&planar, &ad, &x, &input, &input.accel_mean, dt)?);

        let rate = RateSquaredMeasurement { noise: 0.1 };
        assert_accurate(compare_measurement_models(&rate, &AutoDiff::new(GenericRateSquared), &x)?);
        let position = PositionHeadingMeasurement { sigma_xy: 1.0, sigma_theta: 0.1 };
        assert_accurate(compare_measurement_models(&position, &AutoDiff::new(GenericPositionHeading), &x)?);

        let z = Vector5::from_column_slice(&p[10..15]);
        let inversion = AccelerometerInversion { half_separation: r };
        assert_accurate(compare_derivatives(&inversion, &AutoDiff::new(GenericInversion(r)), &z)?);

        let scalar = ScalarRateProcess { angular_accel_variance: 0.1 };
        let w = Vector1::new(p[0]);
        assert_accurate(compare_process_models(&scalar, &AutoDiff::new(GenericScalarRate), &w, &p[1], &p[1], dt)?);
        let squared = ScalarRateSquared { noise: 0.1 };
        assert_accurate(compare_measurement_models(&squared, &AutoDiff::new(GenericScalarRateSquared), &w)?);
    }
}

// ---------------------------------------------------------------------------------------------
// Lee & Huang
// ---------------------------------------------------------------------------------------------

/// D⁺ = Ψ D + G_d(θ) u + gravity, with θ = the state's attitude (`InsProcess`) or a given one.
fn ins_transition<D: AdScalar<f64>>(
    x: &Vector6<D>,
    theta: D,
    u: &Vector3<f64>,
    dt: f64,
    discretization: Discretization,
    plane: Plane,
) -> Vector6<D> {
    let (s, c) = theta.sin_cos();
    // R(θ) (u_x, u_y) plus gravity: the inertial acceleration.
    let g = plane.gravity();
    let ax = c * u.x - s * u.y + g.x;
    let ay = s * u.x + c * u.y + g.y;
    let zoh = if discretization == Discretization::ZeroOrderHold {
        0.5 * dt * dt
    } else {
        0.0
    };
    Vector6::new(
        x[0] + x[2] * dt + ax * zoh,
        x[1] + x[3] * dt + ay * zoh,
        x[2] + ax * dt,
        x[3] + ay * dt,
        x[4] + x[5] * dt + D::from(u.z * zoh),
        x[5] + D::from(u.z * dt),
    )
}

struct GenericIns(InsProcess);

impl AutoDiffProcess<f64, U6> for GenericIns {
    type Input = Vector3<f64>;
    fn transition<D: AdScalar<f64>>(
        &self,
        x: &Vector6<D>,
        u: &Vector3<f64>,
        dt: f64,
    ) -> Vector6<D> {
        ins_transition(x, x[4], u, dt, self.0.discretization, self.0.plane)
    }
    fn process_noise(&self, _: &Vector6<f64>, _: &Vector3<f64>, _: f64) -> Matrix6<f64> {
        Matrix6::identity()
    }
}

struct GenericCkf(CkfProcess);

impl AutoDiffProcess<f64, U6> for GenericCkf {
    /// (signals, attitude θ̂).
    type Input = (Vector3<f64>, f64);
    fn transition<D: AdScalar<f64>>(
        &self,
        x: &Vector6<D>,
        u: &(Vector3<f64>, f64),
        dt: f64,
    ) -> Vector6<D> {
        ins_transition(
            x,
            D::from(u.1),
            &u.0,
            dt,
            self.0.discretization,
            self.0.plane,
        )
    }
    fn process_noise(&self, _: &Vector6<f64>, _: &(Vector3<f64>, f64), _: f64) -> Matrix6<f64> {
        Matrix6::identity()
    }
}

struct GenericAttitude;

impl AutoDiffMeasurement<f64, U6, U1> for GenericAttitude {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector6<D>) -> Vector1<D> {
        Vector1::new(x[4])
    }
    fn measurement_noise(&self, _: &Vector6<f64>) -> Matrix1<f64> {
        Matrix1::identity()
    }
}

proptest! {
    #![proptest_config(config(0x1ee))]

    #[test]
    fn lee_huang_models(p in values(6 + 3 + 1), dt in 0.001..0.5f64, zoh in any::<bool>(), vertical in any::<bool>()) {
        let x = Vector6::from_column_slice(&p[..6]);
        let u = Vector3::new(p[6], p[7], p[8]);
        let discretization = if zoh { Discretization::ZeroOrderHold } else { Discretization::Euler };
        let plane = if vertical { Plane::Vertical } else { Plane::Horizontal };
        let ins = InsProcess { input_noise: Matrix3::identity(), discretization, plane };
        assert_accurate(compare_process_models(&ins, &AutoDiff::new(GenericIns(ins)), &x, &u, &u, dt)?);
        let ckf = ins.ckf();
        let input = CkfInput { signals: u, attitude: p[9] };
        let ad = AutoDiff::new(GenericCkf(ckf));
        assert_accurate(compare_process_models(&ckf, &ad, &x, &input, &(u, p[9]), dt)?);
        let attitude = AttitudeMeasurement { variance: 0.1 };
        assert_accurate(compare_measurement_models(&attitude, &AutoDiff::new(GenericAttitude), &x)?);
    }
}

// ---------------------------------------------------------------------------------------------
// Lu and LV2
// ---------------------------------------------------------------------------------------------

struct GenericErrorState(ErrorStateProcess);

impl AutoDiffProcess<f64, U3> for GenericErrorState {
    type Input = ();
    fn transition<D: AdScalar<f64>>(&self, x: &Vector3<D>, _: &(), dt: f64) -> Vector3<D> {
        // δp⁺ = δp + Δt δv ∓ ½Δt² b, δv⁺ = δv − Δt b, b⁺ = b.
        let half = match self.0.coupling {
            BiasCoupling::Derived => -0.5 * dt * dt,
            BiasCoupling::Printed => 0.5 * dt * dt,
        };
        Vector3::new(x[0] + x[1] * dt + x[2] * half, x[1] - x[2] * dt, x[2])
    }
    fn process_noise(&self, _: &Vector3<f64>, _: &(), _: f64) -> Matrix3<f64> {
        Matrix3::identity()
    }
}

struct GenericGps;

impl AutoDiffMeasurement<f64, U3, U2> for GenericGps {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector3<D>) -> Vector2<D> {
        Vector2::new(x[0], x[1])
    }
    fn measurement_noise(&self, _: &Vector3<f64>) -> Matrix2<f64> {
        Matrix2::identity()
    }
}

struct GenericXyq;

impl AutoDiffMeasurement<f64, U2, U3> for GenericXyq {
    fn measure<D: AdScalar<f64>>(&self, x: &Vector2<D>) -> Vector3<D> {
        // x, y and q = (x + y)/√2.
        Vector3::new(x[0], x[1], (x[0] + x[1]) * core::f64::consts::FRAC_1_SQRT_2)
    }
    fn measurement_noise(&self, _: &Vector2<f64>) -> Matrix3<f64> {
        Matrix3::identity()
    }
}

proptest! {
    #![proptest_config(config(0x1b2))]

    #[test]
    fn lu_and_lv2_models(p in values(3), dt in 0.001..0.5f64, printed in any::<bool>()) {
        let x = Vector3::from_column_slice(&p);
        let coupling = if printed { BiasCoupling::Printed } else { BiasCoupling::Derived };
        let error_state = ErrorStateProcess { accel_noise_variance: 0.1, coupling };
        let ad = AutoDiff::new(GenericErrorState(error_state));
        assert_accurate(compare_process_models(&error_state, &ad, &x, &(), &(), dt)?);
        prop_assert_eq!(lu::transition_matrix(dt, coupling), estim_core::ProcessJacobian::transition_jacobian(&ad, &x, &(), dt));

        // The GPS model has no Hessian implementation (it is linear): value and Jacobian.
        let gps = GpsMeasurement { position_variance: 1.0, velocity_variance: 0.1 };
        let ad = AutoDiff::new(GenericGps);
        prop_assert_eq!(gps.measure(&x), ad.measure(&x));
        prop_assert_eq!(gps.measurement_jacobian(&x), ad.measurement_jacobian(&x));

        let xyq = XyqModel::xyq(&estim_models::lv2::xyq::XyqSigmas { x: 1.0, y: 1.0, q: 1.0 }).unwrap();
        let theta = Vector2::new(p[0], p[1]);
        assert_accurate(compare_measurement_models(&xyq, &AutoDiff::new(GenericXyq), &theta)?);
    }
}
