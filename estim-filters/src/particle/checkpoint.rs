//! Checkpoints (feature `serde`): a [`ParticleFilter`] serialises its configuration (seed,
//! resampling scheme and trigger) and everything its steps change (particles, log-weights,
//! random step counter, moments, running log-likelihood, and the weights Wᵢ in f64, which the
//! update derives from its log-sum-exp terms rather than as exp(log Wᵢ)), and resumes
//! bit-identically. On the way in every shape must agree, every number be finite (log-weights
//! may be −∞, not NaN or +∞), the log-weights normalised (log Σ Wᵢ = 0 to √ε) and each weight
//! within √ε (relative) of exp(log Wᵢ): a typed error otherwise, never a panic. A checkpoint
//! without weights (written before they were stored) in a self-describing format (JSON, CBOR,
//! MessagePack) is read with Wᵢ = exp(log Wᵢ), and then resumes to within round-off, not bit
//! for bit; positional formats (bincode, postcard) refuse it with a typed error.
//!
//! ```
//! use estim_core::nalgebra::{Matrix1, Vector1, U1};
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_filters::particle::ParticleFilter;
//! use estim_filters::{Predict, Update};
//!
//! let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
//! let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
//! let mut pf = ParticleFilter::new(Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?, 50, 8)?;
//! let step = |f: &mut ParticleFilter<f64, U1>, k: usize| -> Result<(), estim_core::Error> {
//!     f.predict(&process, &(), 1.0)?;
//!     f.update(&sensor, &Vector1::new(0.1 * k as f64))?;
//!     Ok(())
//! };
//! for k in 0..5 { step(&mut pf, k)?; }
//! let saved = serde_json::to_string(&pf)?;
//! let mut resumed: ParticleFilter<f64, U1> = serde_json::from_str(&saved)?;
//! for k in 5..10 { step(&mut pf, k)?; step(&mut resumed, k)?; }
//! assert_eq!(resumed, pf); // to the bit
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use estim_core::checks::{all_finite, ensure_finite, ensure_shape};
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::serialize::ShapeChecked;
use estim_core::{Alloc, Error, Parameter, Quantity, Real, Stage};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::step::Work;
use super::{ParticleFilter, ParticleSnapshot, ResampleWhen, Resampling, check_trigger};

/// What a checkpoint holds, borrowed to write it or owned when read.
#[derive(Serialize, Deserialize)]
#[serde(rename = "ParticleFilter")]
struct Fields<Pa, L, W, V, C, T> {
    seed: u64,
    resampling: Resampling,
    trigger: ResampleWhen,
    particles: Pa,
    log_weights: L,
    #[serde(default)]
    weights: W,
    step: u64,
    state: V,
    covariance: C,
    log_likelihood: T,
}

impl<T: Real, N: Dim> Serialize for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Serialize,
    OMatrix<T, N, N>: Serialize,
    OMatrix<T, N, Dyn>: Serialize,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        let c = &self.cloud;
        Fields {
            seed: self.seed,
            resampling: self.scheme,
            trigger: self.when,
            particles: &c.particles,
            log_weights: &c.log_weights,
            weights: Some(&c.weights),
            step: c.step,
            state: &c.mean,
            covariance: &c.covariance,
            log_likelihood: c.log_likelihood,
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real, N: Dim> Deserialize<'de> for ParticleFilter<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
    OMatrix<T, N, Dyn>: Deserialize<'de>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        // The matrices through `ShapeChecked`: a corrupted runtime shape is an error before
        // nalgebra multiplies rows × columns unchecked (issue 41).
        type Checked<T, N> = Fields<
            ShapeChecked<T, N, Dyn>,
            Vec<T>,
            Option<Vec<f64>>,
            ShapeChecked<T, N, U1>,
            ShapeChecked<T, N, N>,
            T,
        >;
        let f = Checked::<T, N>::deserialize(deserializer)?;
        let f = Fields {
            seed: f.seed,
            resampling: f.resampling,
            trigger: f.trigger,
            particles: f.particles.0,
            log_weights: f.log_weights,
            weights: f.weights,
            step: f.step,
            state: f.state.0,
            covariance: f.covariance.0,
            log_likelihood: f.log_likelihood,
        };
        validate(&f).map_err(D::Error::custom)?;
        let (n, _) = f.state.shape_generic();
        let count = f.log_weights.len();
        let stored = f.weights.is_some();
        let mut cloud = ParticleSnapshot {
            particles: f.particles,
            log_weights: f.log_weights,
            weights: f.weights.unwrap_or_else(|| Vec::with_capacity(count)),
            step: f.step,
            mean: f.state,
            covariance: f.covariance,
            log_likelihood: f.log_likelihood,
        };
        if !stored {
            cloud.refresh_weights();
        }
        Ok(ParticleFilter {
            seed: f.seed,
            scheme: f.resampling,
            when: f.trigger,
            cloud,
            work: Work::new(n, count),
        })
    }
}

/// A checkpoint as read.
type Owned<T, N> =
    Fields<OMatrix<T, N, Dyn>, Vec<T>, Option<Vec<f64>>, OVector<T, N>, OMatrix<T, N, N>, T>;

/// The checks on a checkpoint read back (see the module documentation).
fn validate<T: Real, N: Dim>(f: &Owned<T, N>) -> Result<(), Error>
where
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Construction;
    let count = f.log_weights.len();
    if count == 0 {
        return Err(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: 0.0,
        });
    }
    let n = f.state.nrows();
    ensure_shape(&f.particles, n, count, stage, Quantity::Mean)?;
    ensure_shape(&f.covariance, n, n, stage, Quantity::Covariance)?;
    ensure_finite(&f.particles, stage, Quantity::Mean)?;
    ensure_finite(&f.state, stage, Quantity::Mean)?;
    ensure_finite(&f.covariance, stage, Quantity::Covariance)?;
    check_trigger(f.trigger)?;
    let weights_error = Error::NonFinite {
        stage,
        quantity: Quantity::Weights,
    };
    #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
    let bad = f
        .log_weights
        .iter()
        .any(|&lw| lw != lw || lw == T::one() / T::zero());
    let total = super::log_sum_exp(&f.log_weights);
    if bad || !(total.abs() <= T::default_epsilon().sqrt()) {
        return Err(weights_error);
    }
    if let Some(weights) = &f.weights {
        // Both are the true weight to a relative error ≈ ε |log Wᵢ| ≤ 745 ε (far below √ε);
        // below the smallest normal f64 either may have underflowed.
        let tolerance = super::resample::to_f64(T::default_epsilon().sqrt());
        let agrees = |(&w, &lw): (&f64, &T)| {
            let exact = super::resample::to_f64(lw).exp();
            w.is_finite()
                && w >= 0.0
                && (w - exact).abs() <= tolerance * w.max(exact) + f64::MIN_POSITIVE
        };
        if weights.len() != count || !weights.iter().zip(&f.log_weights).all(agrees) {
            return Err(weights_error);
        }
    }
    if !all_finite(&OVector::<T, estim_core::nalgebra::U1>::new(
        f.log_likelihood,
    )) {
        return Err(Error::NonFinite {
            stage,
            quantity: Quantity::FunctionValue,
        });
    }
    Ok(())
}
