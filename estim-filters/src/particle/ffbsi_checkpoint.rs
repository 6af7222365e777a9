//! Checkpoints (feature `serde`) of the [`Ffbsi`] smoother: its record, one entry per
//! recorded step (the filtering cloud {xₖⁱ}, its log-weights log Wₖⁱ, and the input uₖ and
//! Δtₖ of the transition that leaves it). Nothing else is kept, so a restored smoother that
//! records the same forward steps smooths to the same bits. On the way in every cloud must
//! have the first one's shape (n × N, N ≥ 1, N log-weights), every particle be finite, every
//! Δt finite and ≥ 0, and every log-weight set normalised (no NaN or +∞, log Σ Wᵢ = 0 to
//! √ε): a typed error otherwise, never a panic.

use estim_core::checks::ensure_finite;
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix};
use estim_core::serialize::ShapeChecked;
use estim_core::{Alloc, Error, Parameter, Quantity, Real, Stage};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::ffbsi::{Ffbsi, Record, check_cloud};
use crate::gaussian_filter::ensure_time_step;

/// One record as written (borrowed) or read (owned).
#[derive(Serialize, Deserialize)]
#[serde(rename = "FfbsiRecord")]
struct RecordFields<Pa, L, U, T> {
    particles: Pa,
    log_weights: L,
    input: U,
    dt: T,
}

/// What a checkpoint holds.
#[derive(Serialize, Deserialize)]
#[serde(rename = "Ffbsi")]
struct Fields<R> {
    records: Vec<R>,
}

/// A checkpoint (feature `serde`): the recorded clouds, log-weights, inputs and time steps.
impl<T: Real, N: Dim, U: Serialize> Serialize for Ffbsi<T, N, U>
where
    DefaultAllocator: Alloc<N>,
    OMatrix<T, N, Dyn>: Serialize,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        Fields {
            records: self
                .records
                .iter()
                .map(|r| RecordFields {
                    particles: &r.particles,
                    log_weights: &r.log_weights,
                    input: &r.input,
                    dt: r.dt,
                })
                .collect(),
        }
        .serialize(serializer)
    }
}

/// Reads a checkpoint written by the [`Serialize`] impl, checking it (shapes, finiteness,
/// time steps, normalised log-weights).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::particle::{Ffbsi, ParticleFilter};
/// use estim_filters::Update;
///
/// let process = LinearProcess::without_input(Matrix1::new(0.9f64), Matrix1::new(0.5));
/// let sensor = LinearMeasurement { observation: Matrix1::new(1.0), noise: Matrix1::new(1.0) };
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let mut pf = ParticleFilter::new(prior, 50, 8)?;
/// let mut ffbsi: Ffbsi<f64, U1> = Ffbsi::new();
/// let zs = [0.4, -0.3, 1.1, 0.8, 0.2, -0.5];
/// for &z in &zs[..3] {
///     ffbsi.predict(&mut pf, &process, &(), 1.0)?;
///     pf.update(&sensor, &Vector1::new(z))?;
/// }
/// // Save the smoother with the filter, resume both.
/// let saved = (serde_json::to_string(&ffbsi)?, serde_json::to_string(&pf)?);
/// let mut resumed: Ffbsi<f64, U1> = serde_json::from_str(&saved.0)?;
/// let mut resumed_pf: ParticleFilter<f64, U1> = serde_json::from_str(&saved.1)?;
/// for &z in &zs[3..] {
///     ffbsi.predict(&mut pf, &process, &(), 1.0)?;
///     pf.update(&sensor, &Vector1::new(z))?;
///     resumed.predict(&mut resumed_pf, &process, &(), 1.0)?;
///     resumed_pf.update(&sensor, &Vector1::new(z))?;
/// }
/// assert_eq!(resumed, ffbsi); // to the bit
/// let paths = ffbsi.smooth(&pf, &process, 20, 3)?;
/// assert_eq!(resumed.smooth(&resumed_pf, &process, 20, 3)?, paths);
/// // A negative time step: a typed error on the way in, not a panic.
/// let mut v: serde_json::Value = serde_json::from_str(&saved.0)?;
/// v["records"][1]["dt"] = serde_json::json!(-1.0);
/// assert!(serde_json::from_value::<Ffbsi<f64, U1>>(v).is_err());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
impl<'de, T: Real, N: Dim, U: Deserialize<'de>> Deserialize<'de> for Ffbsi<T, N, U>
where
    DefaultAllocator: Alloc<N>,
    OMatrix<T, N, Dyn>: Deserialize<'de>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        // The clouds through `ShapeChecked`: a corrupted runtime shape is an error before
        // nalgebra multiplies rows × columns unchecked (issue 41).
        let f = Fields::<RecordFields<ShapeChecked<T, N, Dyn>, Vec<T>, U, T>>::deserialize(
            deserializer,
        )?;
        let records: Vec<Record<T, N, U>> = f
            .records
            .into_iter()
            .map(|r| Record {
                particles: r.particles.0,
                log_weights: r.log_weights,
                input: r.input,
                dt: r.dt,
            })
            .collect();
        validate(&records).map_err(D::Error::custom)?;
        Ok(Ffbsi { records })
    }
}

/// The checks on a checkpoint read back (see the module documentation).
fn validate<T: Real, N: Dim, U>(records: &[Record<T, N, U>]) -> Result<(), Error>
where
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Construction;
    let Some(first) = records.first() else {
        return Ok(());
    };
    if first.particles.ncols() == 0 {
        return Err(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: 0.0,
        });
    }
    for r in records {
        check_cloud(&first.particles, &r.particles, stage)?;
        let count = r.particles.ncols();
        ensure_finite(&r.particles, stage, Quantity::Mean)?;
        if r.log_weights.len() != count {
            return Err(Error::DimensionMismatch {
                stage,
                quantity: Quantity::Weights,
                expected_rows: count,
                expected_cols: 1,
                found_rows: r.log_weights.len(),
                found_cols: 1,
            });
        }
        #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
        let bad = r
            .log_weights
            .iter()
            .any(|&lw| lw != lw || lw == T::one() / T::zero());
        let total = super::log_sum_exp(&r.log_weights);
        if bad || !(total.abs() <= T::default_epsilon().sqrt()) {
            return Err(Error::NonFinite {
                stage,
                quantity: Quantity::Weights,
            });
        }
        ensure_time_step(r.dt)?;
    }
    Ok(())
}
