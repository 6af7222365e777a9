//! Quickstart: one tracking loop, five filters, one line changed between them.
//!
//! A target moves at near-constant velocity in the plane; a radar at the origin measures range
//! and bearing (nonlinear, bearing wraps). The loop `track` is written once, generic over any
//! filter that can predict with the process model and update with the radar; the filters
//! differ only in their constructor. A second run uses a linear position sensor, where the
//! Kalman filter applies and all Gaussian filters agree. Last, a parameter-estimation problem
//! where the fading-memory RLS swaps in.
//!
//! `cargo run --release --example quickstart`

use estim::nalgebra::{Matrix2, Matrix2x4, Matrix4, U2, U4, Vector2, Vector4};
use estim::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

/// Constant velocity, state (x, y, vx, vy), white-acceleration noise of intensity `q`.
struct ConstantVelocity {
    q: f64,
}

impl ProcessModel<f64, U4> for ConstantVelocity {
    type Input = ();
    fn transition(&self, x: &Vector4<f64>, _: &(), dt: f64) -> Vector4<f64> {
        Vector4::new(x[0] + dt * x[2], x[1] + dt * x[3], x[2], x[3])
    }
    fn process_noise(&self, _: &Vector4<f64>, _: &(), dt: f64) -> Matrix4<f64> {
        let (a, b, c) = (dt.powi(3) / 3.0, dt.powi(2) / 2.0, dt);
        Matrix4::new(
            a, 0.0, b, 0.0, 0.0, a, 0.0, b, b, 0.0, c, 0.0, 0.0, b, 0.0, c,
        ) * self.q
    }
}
impl ProcessJacobian<f64, U4> for ConstantVelocity {
    fn transition_jacobian(&self, _: &Vector4<f64>, _: &(), dt: f64) -> Matrix4<f64> {
        let mut f = Matrix4::identity();
        f[(0, 2)] = dt;
        f[(1, 3)] = dt;
        f
    }
}
impl LinearProcessModel<f64, U4> for ConstantVelocity {}
// The second-order filters ask for Hessians; an affine model says so with `None`.
impl ProcessHessian<f64, U4> for ConstantVelocity {
    fn transition_hessian(
        &self,
        _: &Vector4<f64>,
        _: &(),
        _: f64,
        _: usize,
    ) -> Option<Matrix4<f64>> {
        None
    }
}

/// Range and bearing from a radar at the origin.
struct Radar {
    sigma_range: f64,
    sigma_bearing: f64,
}

impl MeasurementModel<f64, U4, U2> for Radar {
    fn measure(&self, x: &Vector4<f64>) -> Vector2<f64> {
        Vector2::new(x[0].hypot(x[1]), x[1].atan2(x[0]))
    }
    fn measurement_noise(&self, _: &Vector4<f64>) -> Matrix2<f64> {
        Matrix2::from_diagonal(&Vector2::new(
            self.sigma_range.powi(2),
            self.sigma_bearing.powi(2),
        ))
    }
    fn residual_into(&self, a: &Vector2<f64>, b: &Vector2<f64>, out: &mut Vector2<f64>) {
        // The bearing (component 1) is an angle: wrap its difference into (−π, π].
        *out = a - b;
        estim::core::wrap_components(out, &[1]);
    }
}
impl MeasurementJacobian<f64, U4, U2> for Radar {
    fn measurement_jacobian(&self, x: &Vector4<f64>) -> Matrix2x4<f64> {
        let (px, py) = (x[0], x[1]);
        let r2 = px * px + py * py;
        let r = r2.sqrt();
        Matrix2x4::new(px / r, py / r, 0.0, 0.0, -py / r2, px / r2, 0.0, 0.0)
    }
}
impl MeasurementHessian<f64, U4, U2> for Radar {
    fn measurement_hessian(&self, x: &Vector4<f64>, k: usize) -> Option<Matrix4<f64>> {
        let (px, py) = (x[0], x[1]);
        let r2 = px * px + py * py;
        let mut h = Matrix4::zeros();
        let (a, b, c) = if k == 0 {
            let r3 = r2 * r2.sqrt();
            (py * py / r3, -px * py / r3, px * px / r3)
        } else {
            let r4 = r2 * r2;
            (
                2.0 * px * py / r4,
                (py * py - px * px) / r4,
                -2.0 * px * py / r4,
            )
        };
        h[(0, 0)] = a;
        h[(0, 1)] = b;
        h[(1, 0)] = b;
        h[(1, 1)] = c;
        Some(h)
    }
}

/// Any filter that can run the radar problem. Object safe, so the filter can be picked at run
/// time and boxed.
trait RadarTracker: Predict<f64, U4, ConstantVelocity> + Update<f64, U4, U2, Radar> {}
impl<F: Predict<f64, U4, ConstantVelocity> + Update<f64, U4, U2, Radar>> RadarTracker for F {}

/// A constructor of a boxed filter from a prior.
type MakeTracker = fn(Gaussian<f64, U4>) -> Box<dyn RadarTracker>;

/// A data set: true states and measurements at each step.
struct Run<const M: usize> {
    truth: Vec<Vector4<f64>>,
    z: Vec<estim::nalgebra::SVector<f64, M>>,
}

fn normal(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

fn simulate<H, const M: usize>(
    process: &ConstantVelocity,
    sensor: &H,
    x0: Vector4<f64>,
    dt: f64,
    steps: usize,
    seed: u64,
) -> Run<M>
where
    H: MeasurementModel<f64, U4, estim::nalgebra::Const<M>>,
{
    let mut rng = StdRng::seed_from_u64(seed);
    let q = estim::core::psd_factor(
        &process.process_noise(&x0, &(), dt),
        estim::core::Stage::Construction,
    )
    .expect("Q is PSD");
    let (mut x, mut run) = (
        x0,
        Run {
            truth: vec![],
            z: vec![],
        },
    );
    for _ in 0..steps {
        x = process.transition(&x, &(), dt) + q * Vector4::from_fn(|_, _| normal(&mut rng));
        let r = sensor
            .measurement_noise(&x)
            .cholesky()
            .expect("R is PD")
            .l();
        let v = r * estim::nalgebra::SVector::<f64, M>::from_fn(|_, _| normal(&mut rng));
        run.truth.push(x);
        run.z.push(sensor.measure(&x) + v);
    }
    run
}

/// The one tracking loop, for any filter that can predict with `process` and update with `sensor`.
/// Returns (position RMS error, mean NIS).
fn track<F, H, const M: usize>(
    filter: &mut F,
    process: &ConstantVelocity,
    sensor: &H,
    run: &Run<M>,
    dt: f64,
) -> Result<(f64, f64), Error>
where
    F: Predict<f64, U4, ConstantVelocity> + Update<f64, U4, estim::nalgebra::Const<M>, H> + ?Sized,
    H: MeasurementModel<f64, U4, estim::nalgebra::Const<M>>,
{
    let (mut sq, mut nis) = (0.0, 0.0);
    for (truth, z) in run.truth.iter().zip(&run.z) {
        filter.predict(process, &(), dt)?;
        nis += filter.update(sensor, z)?.nis;
        let e = filter.state() - truth;
        sq += e[0] * e[0] + e[1] * e[1];
    }
    let n = run.truth.len() as f64;
    Ok(((sq / n).sqrt(), nis / n))
}

fn main() -> Result<(), Error> {
    let dt = 1.0;
    let process = ConstantVelocity { q: 0.05 };
    let radar = Radar {
        sigma_range: 0.5,
        sigma_bearing: 0.15,
    };
    let x0 = Vector4::new(-40.0, 5.0, 1.0, 0.0);
    let prior = Gaussian::new(
        x0 + Vector4::new(10.0, -10.0, 1.0, 0.5),
        Matrix4::from_diagonal(&Vector4::new(200.0, 200.0, 4.0, 4.0)),
    )?;
    let runs: Vec<Run<2>> = (0..50)
        .map(|s| simulate(&process, &radar, x0, dt, 100, s))
        .collect();

    println!(
        "Radar (range, bearing) tracking, 50 runs x 100 steps: position RMS and mean NIS (expected 2)"
    );
    println!("{:<26} {:>10} {:>10}", "filter", "RMS [m]", "mean NIS");
    let constructors: [(&str, MakeTracker); 4] = [
        ("Ekf", |p| Box::new(Ekf::new(p))),
        ("SecondOrderEkf", |p| Box::new(SecondOrderEkf::new(p))),
        ("Ukf", |p| Box::new(Ukf::new(p))),
        ("Ukf (cubature)", |p| {
            Box::new(GaussianFilter::with_propagator(p, Unscented::cubature()))
        }),
    ];
    for (name, make) in constructors {
        let (mut rms, mut nis) = (0.0, 0.0);
        for r in &runs {
            let (a, b) = track(make(prior.clone()).as_mut(), &process, &radar, r, dt)?;
            rms += a * a;
            nis += b;
        }
        println!(
            "{name:<26} {:>10.3} {:>10.3}",
            (rms / runs.len() as f64).sqrt(),
            nis / runs.len() as f64
        );
    }

    // A linear position sensor: now the Kalman filter applies, and every Gaussian filter agrees.
    let gps = LinearMeasurement {
        observation: Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0),
        noise: Matrix2::identity() * 4.0,
    };
    let run = simulate(&process, &gps, x0, dt, 100, 7);
    println!("\nLinear position sensor, one run: every filter gives the same estimate");
    for (name, result) in [
        (
            "KalmanFilter",
            track(
                &mut KalmanFilter::new(prior.clone()),
                &process,
                &gps,
                &run,
                dt,
            )?,
        ),
        (
            "Ekf",
            track(&mut Ekf::new(prior.clone()), &process, &gps, &run, dt)?,
        ),
        (
            "SecondOrderEkf",
            track(
                &mut SecondOrderEkf::new(prior.clone()),
                &process,
                &gps,
                &run,
                dt,
            )?,
        ),
        (
            "Ukf",
            track(&mut Ukf::new(prior.clone()), &process, &gps, &run, dt)?,
        ),
    ] {
        println!("{name:<26} {:>10.6} {:>10.6}", result.0, result.1);
    }

    // Parameter estimation: a sensor's scale and bias from z = s·a + b + noise with known a.
    // With γ = 1 the RLS is ordinary least squares (and equals a Kalman filter with no process
    // noise); with γ < 1 it tracks a scale that drifts.
    println!("\nRLS: scale/bias calibration, the scale drifts from 1.00 to 1.10 over 2000 samples");
    let mut rng = StdRng::seed_from_u64(11);
    let theta0 = Gaussian::new(Vector2::new(1.0, 0.0), Matrix2::identity())?;
    let mut rls_ols = FadingMemoryRls::new(theta0.clone(), 1.0)?;
    let mut rls_fading = FadingMemoryRls::new(theta0.clone(), 0.99)?;
    let mut kf_static = KalmanFilter::new(theta0);
    let (mut truth_scale, bias) = (1.0, 0.2);
    for k in 0..2000 {
        truth_scale = 1.0 + 0.1 * k as f64 / 2000.0;
        let a = 3.0 * (0.01 * k as f64).sin();
        let regressor = LinearMeasurement {
            observation: estim::nalgebra::Matrix1x2::new(a, 1.0),
            noise: estim::nalgebra::Matrix1::new(0.01),
        };
        let z = estim::nalgebra::Vector1::new(truth_scale * a + bias + 0.1 * normal(&mut rng));
        rls_ols.update(&regressor, &z)?;
        rls_fading.update(&regressor, &z)?;
        kf_static.update(&regressor, &z)?;
    }
    println!("true (scale, bias) at the end: ({truth_scale:.4}, {bias:.4})");
    for (name, est) in [
        ("RLS γ = 1", rls_ols.state()),
        ("RLS γ = 0.99", rls_fading.state()),
        ("KalmanFilter, Q = 0", kf_static.state()),
    ] {
        println!("{name:<26} ({:.4}, {:.4})", est[0], est[1]);
    }
    Ok(())
}
