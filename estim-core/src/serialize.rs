//! serde support (feature `serde`): what is checked on the way in.
//!
//! A [`Gaussian`] deserialises through [`Gaussian::new`], so a corrupt or hand-edited file
//! gives an error (shape, finiteness, symmetry, definiteness), never an invalid Gaussian;
//! [`Unscented`] and [`Sampled`] through their checked constructors. The unit propagators and
//! [`Euclidean`](crate::Euclidean) derive both directions.
//!
//! ```
//! use estim_core::Gaussian;
//! use estim_core::nalgebra::{Matrix2, Vector2};
//!
//! let g = Gaussian::new(Vector2::new(1.0, -2.0), Matrix2::new(2.0, 0.5, 0.5, 1.0))?;
//! let json = serde_json::to_string(&g)?;
//! assert_eq!(serde_json::from_str::<Gaussian<f64, _>>(&json)?, g);
//! // An indefinite covariance is refused.
//! let bad = r#"{"mean":[0.0,0.0],"covariance":[1.0,2.0,2.0,1.0]}"#;
//! assert!(serde_json::from_str::<Gaussian<f64, estim_core::nalgebra::U2>>(bad).is_err());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::alloc::Alloc;
use crate::gaussian::Gaussian;
use crate::propagate::{Sampled, Unscented};
use crate::scalar::Real;

/// The fields of a [`Gaussian`], borrowed to serialise or owned when deserialised.
#[derive(Serialize, Deserialize)]
#[serde(rename = "Gaussian")]
struct GaussianFields<V, M> {
    mean: V,
    covariance: M,
}

impl<T: Real, N: Dim> Serialize for Gaussian<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Serialize,
    OMatrix<T, N, N>: Serialize,
{
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        GaussianFields {
            mean: self.mean(),
            covariance: self.covariance(),
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real, N: Dim> Deserialize<'de> for Gaussian<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let fields = GaussianFields::<OVector<T, N>, OMatrix<T, N, N>>::deserialize(deserializer)?;
        Gaussian::new(fields.mean, fields.covariance).map_err(D::Error::custom)
    }
}

/// α, β, κ of [`Unscented`].
#[derive(Serialize, Deserialize)]
#[serde(rename = "Unscented")]
struct UnscentedFields<T> {
    alpha: T,
    beta: T,
    kappa: T,
}

impl<T: Real + Serialize> Serialize for Unscented<T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        UnscentedFields {
            alpha: self.alpha(),
            beta: self.beta(),
            kappa: self.kappa(),
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real + Deserialize<'de>> Deserialize<'de> for Unscented<T> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = UnscentedFields::<T>::deserialize(deserializer)?;
        Unscented::new(f.alpha, f.beta, f.kappa).map_err(D::Error::custom)
    }
}

/// The sample count and seed of [`Sampled`].
#[derive(Serialize, Deserialize)]
#[serde(rename = "Sampled")]
struct SampledFields {
    samples: usize,
    seed: u64,
}

impl Serialize for Sampled {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        SampledFields {
            samples: self.samples(),
            seed: self.seed(),
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for Sampled {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = SampledFields::deserialize(deserializer)?;
        Sampled::new(f.samples, f.seed).map_err(D::Error::custom)
    }
}
