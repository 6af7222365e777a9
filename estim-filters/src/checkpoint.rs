//! Checkpoints (feature `serde`): a [`GaussianFilter`] serialises its estimate, propagator,
//! state space and update settings, and resumes bit-identically.
//!
//! What is written: the state x̂ and covariance P exactly as they are (every `f64` and `f32`
//! round-trips exactly through the binary formats, and through serde_json with its
//! `float_roundtrip` feature: without it, its parser may be one ulp off), the propagator's settings,
//! the state space, the covariance update form and the gate. What is not: the runtime-size
//! buffers (the resumed filter sizes its own at its first step; they hold no state). On the
//! way in, the shapes must agree and every entry be finite (an error otherwise); P is not
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
use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use estim_core::propagate::PropagatorWorkspace;
use estim_core::{Alloc, Gaussian, Quantity, Real, Stage, StateSpace};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::gaussian_filter::GaussianFilter;
use crate::traits::Estimator;
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
        let f =
            Fields::<OVector<T, N>, OMatrix<T, N, N>, Pr, S, Gate<T>>::deserialize(deserializer)?;
        let n = f.state.nrows();
        let stage = Stage::Construction;
        ensure_shape(&f.covariance, n, n, stage, Quantity::Covariance)
            .and_then(|()| ensure_finite(&f.state, stage, Quantity::Mean))
            .and_then(|()| ensure_finite(&f.covariance, stage, Quantity::Covariance))
            .map_err(D::Error::custom)?;
        let prior = Gaussian::new_unchecked(f.state, f.covariance);
        let filter = GaussianFilter::with_propagator(prior, f.propagator)
            .with_state_space(f.state_space)
            .with_covariance_update(f.covariance_update);
        match f.gate {
            Some(gate) => filter.with_gate(gate).map_err(D::Error::custom),
            None => Ok(filter),
        }
    }
}
