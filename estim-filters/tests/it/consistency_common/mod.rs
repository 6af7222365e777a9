//! Shared scenario of the consistency tests: a Lu-style accelerometer/GPS calibration problem.
//!
//! x = (p, v, b): position, velocity, accelerometer bias. The accelerometer reading u drives
//! the model, p⁺ = p + Δt v + ½Δt² (u − b), v⁺ = v + Δt (u − b), b⁺ = b, with white
//! accelerometer noise (σ_a) and a bias random walk (σ_b); GPS measures p and v.
#![allow(dead_code)]

use estim_core::nalgebra::{
    Matrix2, Matrix2x3, Matrix3, Matrix3x1, U1, U2, U3, Vector1, Vector2, Vector3,
};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess, ProcessJacobian, ProcessModel};
use estim_filters::ValidationError;
use estim_filters::monte_carlo::Recorder;
use estim_filters::{Estimator, Predict, Update, UpdateReport};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

pub const DT: f64 = 0.1;

/// The Lu-style system: the truth and what a filter is told.
#[derive(Clone, Debug)]
pub struct Lu {
    pub process: LinearProcess<f64, U3, U1>,
    pub sensor: LinearMeasurement<f64, U3, U2>,
    pub prior: Gaussian<f64, U3>,
    /// Lower Cholesky factors of the true Q, R and P₀, for sampling.
    q_factor: Matrix3<f64>,
    r_factor: Matrix2<f64>,
    p0_factor: Matrix3<f64>,
}

pub fn transition() -> Matrix3<f64> {
    Matrix3::new(1.0, DT, -0.5 * DT * DT, 0.0, 1.0, -DT, 0.0, 0.0, 1.0)
}

impl Lu {
    pub fn new() -> Self {
        let (sa, sb) = (0.05, 0.01);
        let q = Matrix3::new(
            DT.powi(3) / 3.0,
            DT * DT / 2.0,
            0.0,
            DT * DT / 2.0,
            DT,
            0.0,
            0.0,
            0.0,
            0.0,
        ) * (sa * sa)
            + Matrix3::from_diagonal(&Vector3::new(0.0, 0.0, sb * sb * DT));
        let r = Matrix2::from_diagonal(&Vector2::new(1.0, 0.01));
        let p0 = Matrix3::from_diagonal(&Vector3::new(100.0, 1.0, 0.01));
        Self {
            process: LinearProcess {
                transition: transition(),
                input: Matrix3x1::new(0.5 * DT * DT, DT, 0.0),
                noise: q,
            },
            sensor: LinearMeasurement {
                observation: Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
                noise: r,
            },
            prior: Gaussian::new(Vector3::zeros(), p0).unwrap(),
            q_factor: q.cholesky().unwrap().l(),
            r_factor: r.cholesky().unwrap().l(),
            p0_factor: p0.cholesky().unwrap().l(),
        }
    }

    /// The same truth, but the filter is told Q·`q_factor` and R·`r_factor`.
    pub fn mistuned(
        &self,
        q_factor: f64,
        r_factor: f64,
    ) -> (LinearProcess<f64, U3, U1>, LinearMeasurement<f64, U3, U2>) {
        let mut p = self.process.clone();
        p.noise *= q_factor;
        let mut s = self.sensor.clone();
        s.noise *= r_factor;
        (p, s)
    }
}

/// The accelerometer reading at step k (a known manoeuvre).
pub fn input(k: usize) -> Vector1<f64> {
    Vector1::new((0.5 * k as f64 * DT).sin())
}

fn normal3(rng: &mut StdRng) -> Vector3<f64> {
    Vector3::from_fn(|_, _| rng.sample(StandardNormal))
}

fn normal2(rng: &mut StdRng) -> Vector2<f64> {
    Vector2::from_fn(|_, _| rng.sample(StandardNormal))
}

/// One realization: truth from the true model (x₀ drawn from the prior), the filter made by
/// `make` from the prior predicting with `process` and updating with `sensor`, every step;
/// at slot s = the update of step (s+1)·`every` − 1, `on_slot(s, truth, filter, report)`.
pub fn simulate<P, F>(
    lu: &Lu,
    process: &P,
    sensor: &LinearMeasurement<f64, U3, U2>,
    make: impl Fn(Gaussian<f64, U3>) -> F,
    steps: usize,
    every: usize,
    seed: u64,
    mut on_slot: impl FnMut(
        usize,
        &Vector3<f64>,
        &F,
        &UpdateReport<f64, U2>,
    ) -> Result<(), ValidationError>,
) -> Result<(), ValidationError>
where
    P: ProcessModel<f64, U3, Input = Vector1<f64>>,
    F: Estimator<f64, U3>
        + Predict<f64, U3, P>
        + Update<f64, U3, U2, LinearMeasurement<f64, U3, U2>>,
{
    let mut rng = StdRng::seed_from_u64(seed);
    let mut x = lu.prior.mean() + lu.p0_factor * normal3(&mut rng);
    let mut filter = make(lu.prior.clone());
    for k in 0..steps {
        let u = input(k);
        x = lu.process.transition * x + lu.process.input * u + lu.q_factor * normal3(&mut rng);
        let z = lu.sensor.observation * x + lu.r_factor * normal2(&mut rng);
        filter.predict(process, &u, DT)?;
        let report = filter.update(sensor, &z)?;
        if (k + 1) % every == 0 {
            on_slot((k + 1) / every - 1, &x, &filter, &report)?;
        }
    }
    Ok(())
}

/// [`simulate`] recording, at each slot, the innovation (NIS), the residual (the innovation)
/// and the estimate.
pub fn realization<P, F>(
    lu: &Lu,
    process: &P,
    sensor: &LinearMeasurement<f64, U3, U2>,
    make: impl Fn(Gaussian<f64, U3>) -> F,
    steps: usize,
    every: usize,
    seed: u64,
    rec: &mut Recorder,
) -> Result<(), ValidationError>
where
    P: ProcessModel<f64, U3, Input = Vector1<f64>>,
    F: Estimator<f64, U3>
        + Predict<f64, U3, P>
        + Update<f64, U3, U2, LinearMeasurement<f64, U3, U2>>,
{
    simulate(
        lu,
        process,
        sensor,
        make,
        steps,
        every,
        seed,
        |slot, x, filter, report| {
            rec.record_innovation(slot, report)?;
            rec.record_residual(slot, &report.innovation)?;
            rec.record_filter(slot, x, filter)
        },
    )
}

/// The Lu dynamics as a hand-written model whose Jacobian can be made wrong: with
/// `forget_bias_coupling` the Jacobian leaves out ∂v⁺/∂b = −Δt (and ∂p⁺/∂b), a typical slip.
#[derive(Clone, Debug)]
pub struct HandWritten {
    pub inner: LinearProcess<f64, U3, U1>,
    pub forget_bias_coupling: bool,
}

impl ProcessModel<f64, U3> for HandWritten {
    type Input = Vector1<f64>;
    fn transition(&self, x: &Vector3<f64>, u: &Vector1<f64>, dt: f64) -> Vector3<f64> {
        self.inner.transition(x, u, dt)
    }
    fn process_noise(&self, x: &Vector3<f64>, u: &Vector1<f64>, dt: f64) -> Matrix3<f64> {
        self.inner.process_noise(x, u, dt)
    }
}

impl ProcessJacobian<f64, U3> for HandWritten {
    fn transition_jacobian(&self, _: &Vector3<f64>, _: &Vector1<f64>, _: f64) -> Matrix3<f64> {
        let mut f = self.inner.transition;
        if self.forget_bias_coupling {
            f[(0, 2)] = 0.0;
            f[(1, 2)] = 0.0;
        }
        f
    }
}
