//! serde support (feature `serde`): what is checked on the way in.
//!
//! A [`Gaussian`] deserialises through [`Gaussian::new`], so a corrupt or hand-edited file
//! gives an error (shape, finiteness, symmetry, definiteness), never an invalid Gaussian. Its
//! matrices are read through [`ShapeChecked`], so a runtime-size matrix claiming a shape its
//! entries cannot fill (2⁶³ − 1 rows, where nalgebra would multiply rows × columns unchecked)
//! is an error too, in every build;
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

use core::fmt;
use core::marker::PhantomData;

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, Scalar};
use serde::de::{Error as _, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::alloc::Alloc;
use crate::gaussian::Gaussian;
use crate::propagate::{Sampled, Unscented};
use crate::scalar::Real;
use nalgebra::U1;

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

impl<'de, T: Real + Deserialize<'de>, N: Dim> Deserialize<'de> for Gaussian<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let fields = GaussianFields::<ShapeChecked<T, N, U1>, ShapeChecked<T, N, N>>::deserialize(
            deserializer,
        )?;
        Gaussian::new(fields.mean.0, fields.covariance.0).map_err(D::Error::custom)
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

/// A matrix read in nalgebra's serde format with its claimed shape checked before nalgebra
/// builds it: a runtime-size matrix is written as (entries, rows, columns), and nalgebra
/// 0.35 checks rows × columns = entries with an unchecked multiplication, which panics (with
/// overflow checks) or wraps (without: 2⁶³ × 2 = 0 accepts an empty matrix claiming 2⁶³
/// rows) on a corrupted file. Here rows × columns is computed checked and must equal the
/// number of entries read, else the deserialiser's error; static sizes are read as nalgebra
/// reads them (their shape is the type's). Estim's own `Deserialize` impls read every
/// matrix through it; use it for a field of yours the same way.
///
/// ```
/// use estim_core::nalgebra::{DMatrix, Dyn};
/// use estim_core::serialize::ShapeChecked;
///
/// let m: ShapeChecked<f64, Dyn, Dyn> = serde_json::from_str("[[1.0, 2.0, 3.0, 4.0], 2, 2]")?;
/// assert_eq!(m.0, DMatrix::from_column_slice(2, 2, &[1.0, 2.0, 3.0, 4.0]));
/// // 2⁶³ − 1 rows: an error, not a panic or a matrix larger than its entries.
/// let corrupted = "[[1.0, 2.0, 3.0, 4.0], 9223372036854775807, 2]";
/// assert!(serde_json::from_str::<ShapeChecked<f64, Dyn, Dyn>>(corrupted).is_err());
/// # Ok::<(), serde_json::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeChecked<T: Scalar, R: Dim, C: Dim>(pub OMatrix<T, R, C>)
where
    DefaultAllocator: Allocator<R, C>;

impl<'de, T, R, C> Deserialize<'de> for ShapeChecked<T, R, C>
where
    T: Scalar + Deserialize<'de>,
    R: Dim,
    C: Dim,
    DefaultAllocator: Allocator<R, C>,
    OMatrix<T, R, C>: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        if R::try_to_usize().is_some() && C::try_to_usize().is_some() {
            return OMatrix::<T, R, C>::deserialize(deserializer).map(ShapeChecked);
        }
        deserializer.deserialize_tuple(3, ShapeVisitor(PhantomData))
    }
}

/// [`ShapeChecked`] as a field attribute: `#[serde(deserialize_with =
/// "estim_core::serialize::checked_matrix")]` on an `OMatrix` field reads it with its
/// claimed shape checked.
///
/// ```
/// use estim_core::nalgebra::DMatrix;
///
/// #[derive(serde::Deserialize)]
/// struct Stats {
///     #[serde(deserialize_with = "estim_core::serialize::checked_matrix")]
///     covariance: DMatrix<f64>,
/// }
/// let ok: Stats = serde_json::from_str(r#"{"covariance": [[1.0], 1, 1]}"#)?;
/// assert_eq!(ok.covariance[(0, 0)], 1.0);
/// let corrupted = r#"{"covariance": [[1.0], 9223372036854775807, 2]}"#;
/// assert!(serde_json::from_str::<Stats>(corrupted).is_err());
/// # Ok::<(), serde_json::Error>(())
/// ```
pub fn checked_matrix<'de, D, T, R, C>(deserializer: D) -> Result<OMatrix<T, R, C>, D::Error>
where
    D: Deserializer<'de>,
    T: Scalar + Deserialize<'de>,
    R: Dim,
    C: Dim,
    DefaultAllocator: Allocator<R, C>,
    OMatrix<T, R, C>: Deserialize<'de>,
{
    ShapeChecked::deserialize(deserializer).map(|m| m.0)
}

/// Reads (entries, rows, columns) of a matrix with a runtime size.
struct ShapeVisitor<T, R, C>(PhantomData<(T, R, C)>);

impl<'de, T, R, C> Visitor<'de> for ShapeVisitor<T, R, C>
where
    T: Scalar + Deserialize<'de>,
    R: Dim,
    C: Dim,
    DefaultAllocator: Allocator<R, C>,
{
    type Value = ShapeChecked<T, R, C>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a matrix as (entries, rows, columns)")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let missing = |i| A::Error::invalid_length(i, &"a matrix as (entries, rows, columns)");
        let data: Vec<T> = seq.next_element()?.ok_or_else(|| missing(0))?;
        let rows = dimension::<R, A>(&mut seq)?.ok_or_else(|| missing(1))?;
        let cols = dimension::<C, A>(&mut seq)?.ok_or_else(|| missing(2))?;
        if rows.checked_mul(cols) != Some(data.len()) {
            return Err(A::Error::custom(format_args!(
                "a matrix claims {rows} × {cols} entries but holds {}",
                data.len()
            )));
        }
        Ok(ShapeChecked(OMatrix::from_vec_generic(
            R::from_usize(rows),
            C::from_usize(cols),
            data,
        )))
    }
}

/// One dimension of the (entries, rows, columns) tuple: a number for a runtime size, `()`
/// for a static one (as nalgebra writes them).
fn dimension<'de, D: Dim, A: SeqAccess<'de>>(seq: &mut A) -> Result<Option<usize>, A::Error> {
    match D::try_to_usize() {
        None => seq.next_element::<usize>(),
        Some(n) => Ok(seq.next_element::<()>()?.map(|()| n)),
    }
}
