//! Shared fixtures of the fusion-driver tests: a 1-D cart with a constant-velocity model
//! (exactly discretised, so any sub-stepping gives the same moments), a position sensor and a
//! velocity sensor, a seeded truth, and a snapshot of everything a driver exposes.
#![allow(dead_code)]

use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, U1, U2, Vector1, Vector2};
use estim_core::{
    Gaussian, LinearMeasurement, LinearProcessModel, ProcessJacobian, ProcessModel, error::Result,
};
use estim_filters::fusion::{
    DuplicatePolicy, FusionDriver, FusionSettings, Innovation, Outcome, SensorHealth, SensorSet,
    SensorSettings,
};
use estim_filters::{KalmanFilter, Predict, Rollback, Update};
use rand::rngs::StdRng;

use crate::common::{normal, rng};

/// x = (position, velocity), white-noise acceleration of spectral density `q`:
/// F(Δt) = [[1, Δt], [0, 1]], Q(Δt) = q [[Δt³/3, Δt²/2], [Δt²/2, Δt]] (exact discretisation:
/// two steps of Δt/2 give the moments of one of Δt).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantVelocity {
    pub q: f64,
}

impl ProcessModel<f64, U2> for ConstantVelocity {
    type Input = ();
    fn transition(&self, x: &Vector2<f64>, _: &(), dt: f64) -> Vector2<f64> {
        Vector2::new(x[0] + dt * x[1], x[1])
    }
    fn process_noise(&self, _: &Vector2<f64>, _: &(), dt: f64) -> Matrix2<f64> {
        noise(self.q, dt)
    }
}

impl ProcessJacobian<f64, U2> for ConstantVelocity {
    fn transition_jacobian(&self, _: &Vector2<f64>, _: &(), dt: f64) -> Matrix2<f64> {
        Matrix2::new(1.0, dt, 0.0, 1.0)
    }
}

impl LinearProcessModel<f64, U2> for ConstantVelocity {}

pub fn noise(q: f64, dt: f64) -> Matrix2<f64> {
    Matrix2::new(dt.powi(3) / 3.0, dt * dt / 2.0, dt * dt / 2.0, dt) * q
}

/// A reading of the cart's sensors (or of a sensor it does not have).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reading {
    Position(Vector1<f64>),
    Velocity(Vector1<f64>),
    /// Names sensor 5, which the cart does not have.
    Unknown,
}

/// Sensor 0: position (σ = 0.1 m); sensor 1: velocity (σ = 0.05 m/s).
pub struct Cart {
    pub position: LinearMeasurement<f64, U2, U1>,
    pub velocity: LinearMeasurement<f64, U2, U1>,
}

pub const POSITION_SIGMA: f64 = 0.1;
pub const VELOCITY_SIGMA: f64 = 0.05;

impl Cart {
    pub fn new() -> Self {
        Self {
            position: LinearMeasurement {
                observation: Matrix1x2::new(1.0, 0.0),
                noise: Matrix1::new(POSITION_SIGMA * POSITION_SIGMA),
            },
            velocity: LinearMeasurement {
                observation: Matrix1x2::new(0.0, 1.0),
                noise: Matrix1::new(VELOCITY_SIGMA * VELOCITY_SIGMA),
            },
        }
    }
}

impl<F: Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>> SensorSet<f64, U2, F> for Cart {
    type Reading = Reading;
    fn count(&self) -> usize {
        2
    }
    fn sensor(&self, r: &Reading) -> usize {
        match r {
            Reading::Position(_) => 0,
            Reading::Velocity(_) => 1,
            Reading::Unknown => 5,
        }
    }
    fn dimension(&self, _: usize) -> usize {
        1
    }
    fn update(&self, filter: &mut F, r: &Reading) -> Result<Innovation<f64>> {
        match r {
            Reading::Position(z) => filter.update(&self.position, z).map(|r| Innovation::of(&r)),
            Reading::Velocity(z) => filter.update(&self.velocity, z).map(|r| Innovation::of(&r)),
            Reading::Unknown => unreachable!("the driver refuses unknown sensors"),
        }
    }
}

pub const Q: f64 = 0.01;
pub const GRID: f64 = 0.01;

pub fn prior() -> Gaussian<f64, U2> {
    Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::new(1.0, 0.0, 0.0, 0.25)).unwrap()
}

pub type CartDriver<F> = FusionDriver<f64, U2, F, ConstantVelocity, Cart>;

pub fn settings() -> FusionSettings {
    FusionSettings {
        horizon: 0.5,
        capacity: 128,
        max_step: GRID,
        max_substeps: 100_000,
        // The replay and error tests hold a second fix of a sensor at one time as an error.
        duplicates: DuplicatePolicy::Refuse,
    }
}

pub fn driver<F>(filter: F, sensor: SensorSettings) -> CartDriver<F>
where
    F: Predict<f64, U2, ConstantVelocity>
        + Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>
        + Rollback,
{
    FusionDriver::new(
        filter,
        ConstantVelocity { q: Q },
        (),
        Cart::new(),
        0.0,
        settings(),
        sensor,
    )
    .unwrap()
}

pub fn kf_driver(sensor: SensorSettings) -> CartDriver<KalmanFilter<f64, U2>> {
    driver(KalmanFilter::new(prior()), sensor)
}

/// The truth on the grid t = i·GRID, i = 0..=steps, drawn from the prior and the model.
pub fn truth(rng: &mut StdRng, steps: usize) -> Vec<Vector2<f64>> {
    let p = prior();
    let l0 = p.covariance().cholesky().unwrap().l();
    let mut x = p.mean() + l0 * Vector2::new(normal(rng), normal(rng));
    let lq = noise(Q, GRID).cholesky().unwrap().l();
    let mut out = Vec::with_capacity(steps + 1);
    out.push(x);
    for _ in 0..steps {
        x = Vector2::new(x[0] + GRID * x[1], x[1]) + lq * Vector2::new(normal(rng), normal(rng));
        out.push(x);
    }
    out
}

/// A noisy reading of `sensor` (0 position, 1 velocity) of the state `x`.
pub fn read(rng: &mut StdRng, sensor: usize, x: &Vector2<f64>) -> Reading {
    if sensor == 0 {
        Reading::Position(Vector1::new(x[0] + POSITION_SIGMA * normal(rng)))
    } else {
        Reading::Velocity(Vector1::new(x[1] + VELOCITY_SIGMA * normal(rng)))
    }
}

/// A measurement: taken at grid step `step`, its reading.
#[derive(Clone, Copy, Debug)]
pub struct Taken {
    pub step: usize,
    pub reading: Reading,
}

impl Taken {
    pub fn time(&self) -> f64 {
        self.step as f64 * GRID
    }
}

/// Position fixes every 10 grid steps, velocity fixes every 7, over `steps`, from `seed`.
pub fn measurements(seed: u64, steps: usize) -> (Vec<Vector2<f64>>, Vec<Taken>) {
    let mut rng = rng(seed);
    let x = truth(&mut rng, steps);
    let mut out = Vec::new();
    for step in 1..=steps {
        for (sensor, every) in [(0, 10), (1, 7)] {
            if step % every == 0 {
                out.push(Taken {
                    step,
                    reading: read(&mut rng, sensor, &x[step]),
                });
            }
        }
    }
    (x, out)
}

/// Everything a driver exposes, to compare two drivers (or one before and after a call).
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    pub state: Vector2<f64>,
    pub covariance: Matrix2<f64>,
    pub time: f64,
    pub oldest: f64,
    pub records: usize,
    pub health: Vec<SensorHealth<f64>>,
    pub decisions: Vec<(f64, usize, Outcome<f64>)>,
}

pub fn snapshot<F>(d: &CartDriver<F>) -> Snapshot
where
    F: Predict<f64, U2, ConstantVelocity>
        + Update<f64, U2, U1, LinearMeasurement<f64, U2, U1>>
        + Rollback,
{
    Snapshot {
        state: *d.filter().state(),
        covariance: *d.filter().covariance(),
        time: d.time(),
        oldest: d.oldest_time(),
        records: d.history_len(),
        health: (0..d.sensor_count()).map(|s| d.health(s)).collect(),
        decisions: d.decisions().collect(),
    }
}
