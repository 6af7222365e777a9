//! The particle filter's counter-based random streams.
//!
//! Every random number a [`ParticleFilter`](super::ParticleFilter) draws comes from a stream
//! named by (seed, step, index): the process noise of particle i at step k from (seed, k, i),
//! the resampling uniforms of step k from (seed, k, [`RESAMPLE`]). A stream is SplitMix64
//! (Steele, Lea & Flood 2014: passes BigCrush) started at a hash of its name, so
//!
//! - the filter's whole random state is the step counter (a snapshot or a checkpoint holds one
//!   integer, and a restore replays the same bits);
//! - each particle's draws depend only on its own name, not on the order the particles are
//!   visited, so a later parallel loop gives the same bits on any number of threads.

use estim_core::rand::RngCore;
use estim_core::rand::rand_core::impls::fill_bytes_via_next;

/// The index of the resampling stream of a step (no particle has it).
pub const RESAMPLE: u64 = u64::MAX;

/// The golden-ratio increment of SplitMix64.
const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function (a bijective 64-bit mixer).
#[cfg_attr(not(debug_assertions), inline(always))]
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// One random stream: SplitMix64, xₖ = mix(s + k·φ) for the golden-ratio increment φ, with
/// the start s a chained hash of (seed, step, index). Implements [`RngCore`], so `rand` and
/// `rand_distr` distributions draw from it (a [`ProcessSampler`](super::ProcessSampler) gets
/// one per particle).
///
/// ```
/// use estim_filters::particle::ParticleRng;
/// use estim_core::rand::RngCore;
///
/// let mut a = ParticleRng::stream(7, 3, 0);
/// let mut b = ParticleRng::stream(7, 3, 0);
/// assert_eq!(a.next_u64(), b.next_u64()); // a stream is a function of its name
/// assert_ne!(ParticleRng::stream(7, 3, 1).next_u64(), ParticleRng::stream(7, 4, 0).next_u64());
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParticleRng {
    state: u64,
}

impl ParticleRng {
    /// The stream named (seed, step, index).
    #[inline]
    pub fn stream(seed: u64, step: u64, index: u64) -> Self {
        let key = mix(mix(mix(seed).wrapping_add(step).wrapping_add(GOLDEN)).wrapping_add(index));
        Self { state: key }
    }

    /// A uniform draw in the open interval (0, 1): 53 random bits, offset by half a step.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
    }
}

impl RngCore for ParticleRng {
    #[inline]
    fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    #[inline]
    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN);
        mix(self.state)
    }

    fn fill_bytes(&mut self, dst: &mut [u8]) {
        fill_bytes_via_next(self, dst)
    }
}
