//! Helpers shared by the particle-filter test modules (`particle`, `particle_algorithms`,
//! `rbpf_contract`): the AR(1) model and its seeded readings, sample moments, and the fusion
//! driver's late-reading replay check.

use core::fmt::Debug;

use estim_core::error::Result;
use estim_core::nalgebra::{
    DMatrix, DefaultAllocator, Dim, Dyn, Matrix1, Matrix1x2, Matrix2, U0, U1, Vector1,
};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess, NoInput};
use estim_filters::fusion::{FusionDriver, FusionSettings, Innovation, SensorSet, SensorSettings};
use estim_filters::{Predict, ProcessInput, Rollback, Update};

use crate::common::{normal, rng};

/// x⁺ = 0.9 x + w, Q = 0.5.
pub(crate) type Ar1 = NoInput<LinearProcess<f64, U1, U0>>;

/// The model's position sensor.
pub(crate) type Sensor = LinearMeasurement<f64, U1, U1>;

/// x⁺ = 0.9 x + w, Q = 0.5; z = x + v, R = 1; x₀ ~ N(0, 1).
pub(crate) fn ar1() -> (Ar1, Sensor, Gaussian<f64, U1>) {
    (
        LinearProcess::without_input(Matrix1::new(0.9), Matrix1::new(0.5)),
        LinearMeasurement {
            observation: Matrix1::new(1.0),
            noise: Matrix1::new(1.0),
        },
        Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap(),
    )
}

/// T readings simulated from the model (seeded).
pub(crate) fn readings(steps: usize, seed: u64) -> Vec<f64> {
    let mut g = rng(seed);
    let mut x = normal(&mut g);
    (0..steps)
        .map(|_| {
            x = 0.9 * x + 0.5f64.sqrt() * normal(&mut g);
            x + normal(&mut g)
        })
        .collect()
}

/// A runtime-size linear process without input.
pub(crate) type DynProcess = NoInput<LinearProcess<f64, Dyn, U0>>;

/// Runtime-size copies of a 2-state linear process x⁺ = F x + w (Q, no input) and its 1-D
/// sensor z = H x + v (R = `r`), the same numbers in `DMatrix`es.
pub(crate) fn dyn_linear(
    f: &Matrix2<f64>,
    q: &Matrix2<f64>,
    h: &Matrix1x2<f64>,
    r: f64,
) -> (DynProcess, LinearMeasurement<f64, Dyn, Dyn>) {
    (
        LinearProcess::without_input(
            DMatrix::from_column_slice(2, 2, f.as_slice()),
            DMatrix::from_column_slice(2, 2, q.as_slice()),
        ),
        LinearMeasurement {
            observation: DMatrix::from_column_slice(1, 2, h.as_slice()),
            noise: DMatrix::from_element(1, 1, r),
        },
    )
}

/// The sample mean and the unbiased sample variance (divisor n − 1).
pub(crate) fn mean_and_variance(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    (
        mean,
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0),
    )
}

/// One sensor, the measurement model `H`, reading 1-vectors.
pub(crate) struct OneSensor<H>(pub(crate) H);

impl<N: Dim, H, F: Update<f64, N, U1, H>> SensorSet<f64, N, F> for OneSensor<H>
where
    DefaultAllocator: Alloc<N, U1>,
{
    type Reading = Vector1<f64>;
    fn count(&self) -> usize {
        1
    }
    fn sensor(&self, _: &Vector1<f64>) -> usize {
        0
    }
    fn dimension(&self, _: usize) -> usize {
        1
    }
    fn update(&self, f: &mut F, z: &Vector1<f64>) -> Result<Innovation<f64>> {
        f.update(&self.0, z).map(|r| Innovation::of(&r))
    }
}

/// The fusion driver rolls `start` back for a late reading (max step 0.02 s): 0.3 at 0.05 s
/// and −0.2 at 0.10 s fused in time order and in reverse give the same filter to the bit
/// (one replayed reading), and a filter that moved.
pub(crate) fn assert_late_reading_replays_bit_identically<N, F, P, H>(
    start: F,
    process: P,
    sensor: H,
) where
    N: Dim,
    F: Predict<f64, N, P> + Update<f64, N, U1, H> + Rollback + Clone + PartialEq + Debug,
    P: ProcessInput<f64, N, Input = ()> + Clone,
    H: Clone,
    DefaultAllocator: Alloc<N, U1>,
{
    let settings = FusionSettings {
        max_step: 0.02,
        ..FusionSettings::default()
    };
    let driver = || {
        FusionDriver::new(
            start.clone(),
            process.clone(),
            (),
            OneSensor(sensor.clone()),
            0.0,
            settings,
            SensorSettings::default(),
        )
        .unwrap()
    };
    let mut ordered = driver();
    ordered.fuse(0.05, Vector1::new(0.3)).unwrap();
    ordered.fuse(0.10, Vector1::new(-0.2)).unwrap();
    let mut late = driver();
    late.fuse(0.10, Vector1::new(-0.2)).unwrap();
    let fused = late.fuse(0.05, Vector1::new(0.3)).unwrap();
    assert_eq!(fused.replayed, 1);
    assert_eq!(late.filter(), ordered.filter());
    assert_ne!(late.filter(), &start);
}
