//! Checkpoints of an [`Imm`] (feature `serde`): the mode filters (each as its own type
//! serialises, e.g. a [`GaussianFilter`](crate::GaussianFilter) as in
//! [`checkpoint`](crate::checkpoint)), Π, the [`Mixing`](super::Mixing), μ and the initial μ₀. The combined estimate is not
//! written: it is a function of the modes and μ, recomputed on the way in to the same bits.
//! On the way in Π and μ are read through [`ShapeChecked`] (a corrupted runtime shape is an
//! error before nalgebra builds the matrix) and checked as by [`Imm::new`] (an error
//! otherwise).

use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, U1};
use estim_core::serialize::ShapeChecked;
use estim_core::{Alloc, Real};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::{Imm, Modes, mixture};

/// What a checkpoint holds, borrowed to write it or owned when read.
#[derive(Serialize, Deserialize)]
#[serde(rename = "Imm")]
struct Fields<F, M, V> {
    modes: F,
    transition: M,
    mixing: super::Mixing,
    probabilities: V,
    initial_probabilities: V,
}

impl<T: Real, N: Dim, F: Modes<T, N> + Serialize> Serialize for Imm<T, N, F>
where
    DefaultAllocator: Alloc<N>,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        Fields {
            modes: &self.modes,
            transition: &self.transition,
            mixing: self.mixing,
            probabilities: &self.probabilities,
            initial_probabilities: &self.initial,
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real, N: Dim, F: Modes<T, N> + Deserialize<'de>> Deserialize<'de> for Imm<T, N, F>
where
    DefaultAllocator: Alloc<N>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = Fields::<F, ShapeChecked<T, Dyn, Dyn>, ShapeChecked<T, Dyn, U1>>::deserialize(
            deserializer,
        )?;
        let mut imm = Imm::new(f.modes, f.transition.0, f.initial_probabilities.0)
            .map_err(D::Error::custom)?
            .with_mixing(f.mixing);
        mixture::check_probabilities(&f.probabilities.0, imm.modes.count())
            .map_err(D::Error::custom)?;
        imm.probabilities = f.probabilities.0;
        imm.combine();
        Ok(imm)
    }
}
