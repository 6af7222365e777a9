//! Checkpoints (feature `serde`) of the [`RaoBlackwellised`] filter: its configuration (seed,
//! resampling scheme and trigger) and everything its steps change (nonlinear particles, the
//! per-particle Kalman filters, log-weights, random step counter, running log-likelihood).
//! The joint moments are recomputed on the way in (the same deterministic sums as after a
//! step, so a resumed filter is bit-identical). On the way in the shapes must agree (one
//! filter per particle, every filter of the same size), every number be finite (log-weights
//! may be −∞, not NaN or +∞) and the log-weights normalised (log Σ Wᵢ = 0 to √ε): a typed
//! error otherwise, never a panic.

use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::nalgebra::{DefaultAllocator, Dim, DimAdd, DimSum, Dyn, OMatrix, OVector, U1};
use estim_core::serialize::ShapeChecked;
use estim_core::{Alloc, Error, Parameter, Quantity, Real, Stage};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::rbpf::{RaoBlackwellised, RaoBlackwellisedSnapshot, RbWork};
use super::{ResampleWhen, Resampling, check_trigger};
use crate::gaussian_filter::KalmanFilter;
use crate::traits::Estimator;

/// What a checkpoint holds, borrowed to write it or owned when read.
#[derive(Serialize, Deserialize)]
#[serde(rename = "RaoBlackwellised")]
struct Fields<Pa, F, L, T> {
    seed: u64,
    resampling: Resampling,
    trigger: ResampleWhen,
    nonlinear: Pa,
    linear: F,
    log_weights: L,
    step: u64,
    log_likelihood: T,
}

/// A checkpoint (feature `serde`): the configuration (seed, resampling scheme and trigger)
/// and everything the steps change (nonlinear particles, the per-particle Kalman filters,
/// log-weights, random step counter, running log-likelihood). The joint moments are not
/// written: reading recomputes them by the same sums as a step, so a resumed filter is
/// bit-identical. Reading checks that the shapes agree (one filter per particle, all of one
/// size), every number is finite (log-weights may be −∞, not NaN or +∞) and the log-weights
/// are normalised (log Σ Wᵢ = 0 to √ε): a typed error otherwise, never a panic.
impl<T: Real, Nn: DimAdd<Nl>, Nl: Dim> Serialize for RaoBlackwellised<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
    OMatrix<T, Nn, Dyn>: Serialize,
    KalmanFilter<T, Nl>: Serialize,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        let s = &self.state;
        Fields {
            seed: self.seed,
            resampling: self.scheme,
            trigger: self.when,
            nonlinear: &s.nonlinear,
            linear: &s.linear,
            log_weights: &s.log_weights,
            step: s.step,
            log_likelihood: s.log_likelihood,
        }
        .serialize(serializer)
    }
}

/// Reads a checkpoint written by the [`Serialize`] impl, checking it (shapes, finiteness,
/// normalised log-weights).
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Vector1, U1};
/// use estim_core::Gaussian;
/// use estim_filters::particle::{
///     ConditionalMeasurement, ConditionalTransition, ConditionallyLinearMeasurement,
///     ConditionallyLinearProcess, RaoBlackwellised,
/// };
///
/// /// Position xn, velocity xl: xn⁺ = xn + xl + wn, xl⁺ = xl + wl; z = xn + v.
/// struct Cv;
/// impl ConditionallyLinearProcess<f64, U1, U1> for Cv {
///     type Input = ();
///     fn conditional_transition(&self, xn: &Vector1<f64>, _: &(), dt: f64) -> ConditionalTransition<f64, U1, U1> {
///         ConditionalTransition {
///             nonlinear_mean: *xn,
///             coupling: Matrix1::new(dt),
///             nonlinear_noise: Matrix1::new(0.1),
///             linear_mean: Vector1::zeros(),
///             linear_transition: Matrix1::new(1.0),
///             linear_noise: Matrix1::new(0.01),
///         }
///     }
/// }
/// struct Position;
/// impl ConditionallyLinearMeasurement<f64, U1, U1, U1> for Position {
///     fn conditional_measurement(&self, xn: &Vector1<f64>) -> ConditionalMeasurement<f64, U1, U1> {
///         ConditionalMeasurement { offset: *xn, observation: Matrix1::zeros(), noise: Matrix1::new(0.25) }
///     }
/// }
/// type Rbpf = RaoBlackwellised<f64, U1, U1>;
/// let step = |f: &mut Rbpf, k: usize| -> Result<(), estim_core::Error> {
///     f.predict(&Cv, &(), 1.0)?;
///     f.update(&Position, &Vector1::new(0.5 * k as f64))?;
///     Ok(())
/// };
/// let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0))?;
/// let mut rbpf = RaoBlackwellised::new(prior.clone(), prior, 40, 8)?;
/// for k in 0..5 { step(&mut rbpf, k)?; }
/// let saved = serde_json::to_string(&rbpf)?;
/// let mut resumed: Rbpf = serde_json::from_str(&saved)?;
/// for k in 5..10 { step(&mut rbpf, k)?; step(&mut resumed, k)?; }
/// assert_eq!(resumed, rbpf); // to the bit
/// // A filter missing: a typed error on the way in, not a panic.
/// let mut v: serde_json::Value = serde_json::from_str(&saved)?;
/// v["linear"].as_array_mut().unwrap().pop();
/// assert!(serde_json::from_value::<Rbpf>(v).is_err());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
impl<'de, T: Real, Nn: DimAdd<Nl>, Nl: Dim> Deserialize<'de> for RaoBlackwellised<T, Nn, Nl>
where
    DefaultAllocator: Alloc<Nn, Nl> + Alloc<DimSum<Nn, Nl>, Nn>,
    OMatrix<T, Nn, Dyn>: Deserialize<'de>,
    KalmanFilter<T, Nl>: Deserialize<'de>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        // The particles through `ShapeChecked`: a corrupted runtime shape is an error before
        // nalgebra multiplies rows × columns unchecked (issue 41). The filters check their own.
        let f =
            Fields::<ShapeChecked<T, Nn, Dyn>, Vec<KalmanFilter<T, Nl>>, Vec<T>, T>::deserialize(
                deserializer,
            )?;
        let nonlinear: OMatrix<T, Nn, Dyn> = f.nonlinear.0;
        validate(
            &nonlinear,
            &f.linear,
            &f.log_weights,
            f.log_likelihood,
            f.trigger,
        )
        .map_err(D::Error::custom)?;
        let (n, _) = nonlinear.shape_generic();
        let (l, _) = f.linear[0].state().shape_generic();
        let joint = n.add(l);
        let mut filter = RaoBlackwellised {
            seed: f.seed,
            scheme: f.resampling,
            when: f.trigger,
            work: RbWork::new(n, l, &f.linear),
            state: RaoBlackwellisedSnapshot {
                nonlinear,
                linear: f.linear,
                log_weights: f.log_weights,
                step: f.step,
                log_likelihood: f.log_likelihood,
                mean: OVector::zeros_generic(joint, U1),
                covariance: OMatrix::zeros_generic(joint, joint),
            },
        };
        filter.update_moments();
        Ok(filter)
    }
}

/// The checks on a checkpoint read back (see the `Serialize` impl).
fn validate<T: Real, Nn: Dim, Nl: Dim>(
    nonlinear: &OMatrix<T, Nn, Dyn>,
    linear: &[KalmanFilter<T, Nl>],
    log_weights: &[T],
    log_likelihood: T,
    trigger: ResampleWhen,
) -> Result<(), Error>
where
    DefaultAllocator: Alloc<Nn, Nl>,
{
    let stage = Stage::Construction;
    let count = log_weights.len();
    if count == 0 {
        return Err(Error::InvalidParameter {
            parameter: Parameter::SampleCount,
            value: 0.0,
        });
    }
    ensure_shape(nonlinear, nonlinear.nrows(), count, stage, Quantity::Mean)?;
    ensure_finite(nonlinear, stage, Quantity::Mean)?;
    let mismatch = |found| Error::DimensionMismatch {
        stage,
        quantity: Quantity::Covariance,
        expected_rows: count,
        expected_cols: 1,
        found_rows: found,
        found_cols: 1,
    };
    if linear.len() != count {
        return Err(mismatch(linear.len()));
    }
    let l = linear[0].state().nrows();
    for kf in linear {
        ensure_shape(kf.state(), l, 1, stage, Quantity::Mean)?;
    }
    check_trigger(trigger)?;
    #[allow(clippy::eq_op)] // NaN is the one value unequal to itself
    let bad = log_weights
        .iter()
        .any(|&lw| lw != lw || lw == T::one() / T::zero());
    let total = super::log_sum_exp(log_weights);
    if bad || !(total.abs() <= T::default_epsilon().sqrt()) {
        return Err(Error::NonFinite {
            stage,
            quantity: Quantity::Weights,
        });
    }
    if !log_likelihood.is_finite() {
        return Err(Error::NonFinite {
            stage,
            quantity: Quantity::FunctionValue,
        });
    }
    Ok(())
}
