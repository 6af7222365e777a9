//! Checkpoints (feature `serde`): every single-Gaussian filter of the family serialises what
//! its steps carry and its settings, and resumes bit-identically (the particle filters and
//! the IMM, its smoother and the Gaussian sum have checkpoints of their own; GPB2 has none
//! yet). A [`GaussianFilter`] writes its estimate, propagator, state space and update
//! settings; a [`SquareRootFilter`] its state and factor S (not P, so nothing is
//! refactorised), propagator and gate; an [`Iekf`] and a
//! [`FadingMemoryRls`] their EKF's checkpoint and their own settings.
//!
//! What is written: the state x̂ and covariance P exactly as they are (every `f64` and `f32`
//! round-trips exactly through the binary formats, and through serde_json with its
//! `float_roundtrip` feature: without it, its parser may be one ulp off), the propagator's settings,
//! the state space, the covariance update form and the gate. What is not: the runtime-size
//! buffers (the resumed filter sizes its own at its first step; they hold no state). On the
//! way in, the shapes must agree (a runtime size is checked against its entries before
//! nalgebra builds the matrix: [`ShapeChecked`]) and every entry be finite (an error
//! otherwise); P is not
//! re-checked for definiteness, because a filter may legitimately carry a covariance that the
//! stricter [`Gaussian::new`] tolerance would refuse.
//!
//! ```
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, U2, Vector1, Vector2};
//! use estim_filters::{Estimator, Predict, Ukf, Update};
//!
//! let process = LinearProcess::without_input(Matrix2::new(1.0, 0.1, 0.0, 1.0), Matrix2::identity() * 1e-3);
//! let gps = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
//! let mut filter = Ukf::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
//! let step = |f: &mut Ukf<f64, U2>, k: usize| -> Result<(), estim_core::Error> {
//!     f.predict(&process, &(), 0.1)?;
//!     f.update(&gps, &Vector1::new(0.05 * k as f64))?;
//!     Ok(())
//! };
//! for k in 0..10 { step(&mut filter, k)?; }
//! let saved = serde_json::to_string(&filter)?;
//! let mut resumed: Ukf<f64, U2> = serde_json::from_str(&saved)?;
//! for k in 10..20 { step(&mut filter, k)?; step(&mut resumed, k)?; }
//! assert_eq!(resumed, filter); // to the bit
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::propagate::PropagatorWorkspace;
use estim_core::serialize::ShapeChecked;
use estim_core::{Alloc, Gaussian, Quantity, Real, Stage, StateSpace};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::gaussian_filter::{Ekf, GaussianFilter};
use crate::iterated::Iekf;
use crate::rls::FadingMemoryRls;
use crate::square_root::SquareRootFilter;
use crate::traits::{Estimator, Rollback};
use crate::update::{CovarianceUpdate, Gate};

/// What a checkpoint holds, borrowed to write it or owned when read.
#[derive(Serialize, Deserialize)]
#[serde(rename = "GaussianFilter")]
struct Fields<V, M, Pr, S, G> {
    state: V,
    covariance: M,
    propagator: Pr,
    state_space: S,
    covariance_update: CovarianceUpdate,
    gate: Option<G>,
}

impl<T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S> Serialize for GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Serialize,
    OMatrix<T, N, N>: Serialize,
    Pr: Serialize,
    S: StateSpace<T, N> + Serialize,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        Fields {
            state: self.state(),
            covariance: self.covariance(),
            propagator: self.propagator(),
            state_space: self.state_space(),
            covariance_update: self.covariance_update(),
            gate: self.gate(),
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real, N: Dim, Pr: PropagatorWorkspace<T>, S> Deserialize<'de>
    for GaussianFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
    Pr: Deserialize<'de>,
    S: StateSpace<T, N> + Deserialize<'de>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        // Both through `ShapeChecked`: a corrupted runtime shape is an error before nalgebra
        // sees it (issue 41).
        let f =
            Fields::<ShapeChecked<T, N, U1>, ShapeChecked<T, N, N>, Pr, S, Gate<T>>::deserialize(
                deserializer,
            )?;
        let (state, covariance) = (f.state.0, f.covariance.0);
        let n = state.nrows();
        let stage = Stage::Construction;
        ensure_shape(&covariance, n, n, stage, Quantity::Covariance)
            .and_then(|()| ensure_finite(&state, stage, Quantity::Mean))
            .and_then(|()| ensure_finite(&covariance, stage, Quantity::Covariance))
            .map_err(D::Error::custom)?;
        let prior = Gaussian::new_unchecked(state, covariance);
        let filter = GaussianFilter::with_propagator(prior, f.propagator)
            .with_state_space(f.state_space)
            .with_covariance_update(f.covariance_update);
        match f.gate {
            Some(gate) => filter.with_gate(gate).map_err(D::Error::custom),
            None => Ok(filter),
        }
    }
}

/// A square-root filter's checkpoint: x̂, the factor S (not P: resuming from S needs no
/// factorisation and loses no bit), the propagator and the gate.
#[derive(Serialize, Deserialize)]
#[serde(rename = "SquareRootFilter")]
struct FactorFields<V, M, Pr, G> {
    state: V,
    factor: M,
    propagator: Pr,
    gate: Option<G>,
}

/// A checkpoint of a square-root filter, read back bit for bit (module docs). A filter whose
/// prior could not be factorised (every step fails) has no factor to write: an error.
///
/// ```
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
/// use estim_filters::{Predict, SrUkf, Update};
///
/// let process = LinearProcess::without_input(Matrix2::new(1.0, 0.1, 0.0, 1.0), Matrix2::identity() * 1e-3);
/// let gps = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
/// let mut filter = SrUkf::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// filter.predict(&process, &(), 0.1)?;
/// filter.update(&gps, &Vector1::new(0.05))?;
/// let mut resumed: SrUkf<f64, _> = serde_json::from_str(&serde_json::to_string(&filter)?)?;
/// for f in [&mut filter, &mut resumed] {
///     f.predict(&process, &(), 0.1)?;
///     f.update(&gps, &Vector1::new(0.07))?;
/// }
/// assert_eq!(resumed, filter); // to the bit, factor included
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
impl<T: Real, N: Dim, Pr> Serialize for SquareRootFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Serialize,
    OMatrix<T, N, N>: Serialize,
    Pr: Serialize,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        let snapshot = self.snapshot();
        if !snapshot.factored {
            return Err(serde::ser::Error::custom(
                "the filter's prior could not be factorised: no factor to checkpoint",
            ));
        }
        FactorFields {
            state: snapshot.state(),
            factor: snapshot.factor(),
            propagator: self.propagator(),
            gate: self.gate(),
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real, N: Dim, Pr> Deserialize<'de> for SquareRootFilter<T, N, Pr>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
    Pr: Deserialize<'de>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = FactorFields::<ShapeChecked<T, N, U1>, ShapeChecked<T, N, N>, Pr, Gate<T>>::deserialize(
            deserializer,
        )?;
        let filter = SquareRootFilter::from_factor(f.state.0, f.factor.0, f.propagator)
            .map_err(D::Error::custom)?;
        match f.gate {
            Some(gate) => filter.with_gate(gate).map_err(D::Error::custom),
            None => Ok(filter),
        }
    }
}

/// An IEKF's checkpoint: its EKF's, and the iteration settings.
#[derive(Serialize, Deserialize)]
#[serde(rename = "Iekf")]
struct IteratedFields<E, T> {
    ekf: E,
    max_iterations: usize,
    tolerance: T,
}

/// A checkpoint of an IEKF: its EKF's (x̂, P and settings) and the iteration settings,
/// checked on the way in as [`Iekf::with_iterations`] checks them.
///
/// ```
/// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
/// use estim_filters::Iekf;
///
/// let iekf = Iekf::new(Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::identity())?).with_iterations(5, 1e-9)?;
/// let resumed: Iekf<f64, _> = serde_json::from_str(&serde_json::to_string(&iekf)?)?;
/// assert_eq!(resumed, iekf);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
impl<T: Real + Serialize, N: Dim> Serialize for Iekf<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Serialize,
    OMatrix<T, N, N>: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        let (max_iterations, tolerance) = self.iterations();
        IteratedFields {
            ekf: self.ekf(),
            max_iterations,
            tolerance,
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real + Deserialize<'de>, N: Dim> Deserialize<'de> for Iekf<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = IteratedFields::<Ekf<T, N>, T>::deserialize(deserializer)?;
        Iekf::from_ekf(f.ekf)
            .with_iterations(f.max_iterations, f.tolerance)
            .map_err(D::Error::custom)
    }
}

/// A fading-memory RLS checkpoint: its EKF's and γ.
#[derive(Serialize, Deserialize)]
#[serde(rename = "FadingMemoryRls")]
struct RlsFields<E, T> {
    ekf: E,
    forgetting: T,
}

/// A checkpoint of a fading-memory RLS: its EKF's (θ̂, P and settings) and γ, checked on the
/// way in as [`FadingMemoryRls::new`] checks it.
///
/// ```
/// use estim_core::{Gaussian, nalgebra::{Matrix2, Vector2}};
/// use estim_filters::FadingMemoryRls;
///
/// let rls = FadingMemoryRls::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?, 0.98)?;
/// let resumed: FadingMemoryRls<f64, _> = serde_json::from_str(&serde_json::to_string(&rls)?)?;
/// assert_eq!(resumed, rls);
/// assert!(serde_json::from_str::<FadingMemoryRls<f64, estim_core::nalgebra::U2>>(
///     &serde_json::to_string(&rls)?.replace("0.98", "1.5")).is_err());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
impl<T: Real + Serialize, N: Dim> Serialize for FadingMemoryRls<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Serialize,
    OMatrix<T, N, N>: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        RlsFields {
            ekf: self.ekf(),
            forgetting: self.forgetting_factor(),
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real + Deserialize<'de>, N: Dim> Deserialize<'de> for FadingMemoryRls<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = RlsFields::<Ekf<T, N>, T>::deserialize(deserializer)?;
        FadingMemoryRls::from_ekf(f.ekf, f.forgetting).map_err(D::Error::custom)
    }
}
