//! Seeded sensor simulation: truth, noisy (biased, clipped, dropped) axis readings.
//!
//! The note gives no noise levels, sample rate or scenario; the `lv2_fusion` example chooses
//! its own and says so (`examples/reproductions/lv2_fusion.rs`).

use core::f64::consts::{PI, SQRT_2};

use estim_core::Alloc;
use estim_core::nalgebra::{DefaultAllocator, Dim, OVector, Vector2};
use rand::Rng;
use rand_distr::StandardNormal;

use super::model::RedundantAxes;
use super::xyq::{XyqReading, XyqSigmas};

/// A set of sensing axes with the error sources the note mentions: white Gaussian noise (σ of
/// each axis), a constant bias per axis, a full-scale range (readings clip at ±full scale),
/// and random drop-outs.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorArray<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The axes (directions and σ's).
    pub axes: RedundantAxes<f64, N, M>,
    /// Constant bias added to each axis (m/s²).
    pub bias: OVector<f64, M>,
    /// Readings clip to ±`full_scale` (m/s²); `None`: unlimited.
    pub full_scale: Option<f64>,
    /// Probability that an axis's sample is lost (reading NaN, flagged missing).
    pub dropout: f64,
}

/// One simulated sample of all axes.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorSample<M: Dim>
where
    DefaultAllocator: estim_core::nalgebra::allocator::Allocator<M>,
{
    /// The readings (NaN where missing).
    pub reading: OVector<f64, M>,
    /// Which axes dropped out.
    pub missing: Vec<bool>,
    /// Which axes clipped at full scale.
    pub clipped: Vec<bool>,
}

impl<N: Dim, M: Dim> SensorArray<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Ideal axes apart from their noise: no bias, no range limit, no drop-outs.
    pub fn new(axes: RedundantAxes<f64, N, M>) -> Self {
        let (mdim, _) = axes.directions().shape_generic();
        Self {
            bias: OVector::zeros_generic(mdim, estim_core::nalgebra::U1),
            axes,
            full_scale: None,
            dropout: 0.0,
        }
    }

    /// Samples all axes at the true vector `truth`: reading = clip(uᵢ·θ + bᵢ + σᵢ nᵢ), NaN when
    /// dropped.
    ///
    /// # Panics
    /// When the public `bias` has fewer entries than there are axes (a runtime-sized array
    /// whose bias was replaced by a shorter vector).
    #[track_caller]
    pub fn sample<R: Rng + ?Sized>(&self, truth: &OVector<f64, N>, rng: &mut R) -> SensorSample<M> {
        let mut reading = self.axes.ideal_reading(truth);
        let m = reading.nrows();
        // Checked here, not by the index below, so that the panic names the caller.
        assert!(
            self.bias.nrows() >= m,
            "SensorArray::sample: {} biases for {m} axes",
            self.bias.nrows()
        );
        let mut missing = vec![false; m];
        let mut clipped = vec![false; m];
        for i in 0..m {
            let n: f64 = rng.sample(StandardNormal);
            let mut v = reading[i] + self.bias[i] + self.axes.sigmas()[i] * n;
            if let Some(fs) = self.full_scale
                && v.abs() >= fs
            {
                v = fs.copysign(v);
                clipped[i] = true;
            }
            if self.dropout > 0.0 && rng.random_bool(self.dropout.min(1.0)) {
                v = f64::NAN;
                missing[i] = true;
            }
            reading[i] = v;
        }
        SensorSample {
            reading,
            missing,
            clipped,
        }
    }
}

/// One reading of the LV2 x, y, q channels at true acceleration `truth` = (x, y), with biases
/// `bias` = (bx, by, bq) and white Gaussian noise (no clipping): the fast path of the Monte
/// Carlo. Draws three standard normals, in the order x, y, q.
pub fn sample_xyq<R: Rng + ?Sized>(
    truth: &Vector2<f64>,
    sigmas: &XyqSigmas,
    bias: [f64; 3],
    rng: &mut R,
) -> XyqReading {
    let nx: f64 = rng.sample(StandardNormal);
    let ny: f64 = rng.sample(StandardNormal);
    let nq: f64 = rng.sample(StandardNormal);
    XyqReading {
        x: truth[0] + bias[0] + sigmas.x * nx,
        y: truth[1] + bias[1] + sigmas.y * ny,
        q: (truth[0] + truth[1]) / SQRT_2 + bias[2] + sigmas.q * nq,
    }
}

/// An in-plane acceleration of constant magnitude turning at a constant rate (a vibration
/// or spin): a(t) = offset + A (cos 2πft, sin 2πft). Each axis sees a sinusoid, the three
/// peaks 45° apart in phase, so with A a little above full scale the axes saturate in turn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotatingAcceleration {
    /// Constant part (m/s²).
    pub offset: Vector2<f64>,
    /// Magnitude A of the turning part (m/s²).
    pub magnitude: f64,
    /// Turning rate f (Hz).
    pub frequency_hz: f64,
}

impl RotatingAcceleration {
    /// a(t).
    pub fn at(&self, t: f64) -> Vector2<f64> {
        let phase = 2.0 * PI * self.frequency_hz * t;
        self.offset + Vector2::new(phase.cos(), phase.sin()) * self.magnitude
    }
}
