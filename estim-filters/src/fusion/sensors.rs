//! How a user registers sensors with the driver: one type for all of them.

use estim_core::nalgebra::{DefaultAllocator, Dim};
use estim_core::{Alloc, Real, error::Result};

use super::outcome::Innovation;

/// The sensors of a [`FusionDriver`](super::FusionDriver) over filters of type `F`: their
/// reading type, which sensor a reading comes from, each sensor's dimension, and how a reading
/// updates the filter (with the filters' own per-call `update(&model, &z)`). See the
/// [module docs](super) for an example and for why sensors are registered this way.
///
/// Sensors are numbered `0..count()`. An implementation usually holds one measurement model
/// per sensor and is generic over `F` bounded by the `Update` traits its models need.
pub trait SensorSet<T: Real, N: Dim, F>
where
    DefaultAllocator: Alloc<N>,
{
    /// One measurement of any of the sensors, e.g. an enum with a static-size vector per
    /// variant. Stored in the history, so prefer static sizes (no allocation when cloned).
    type Reading: Clone;

    /// The number of sensors.
    fn count(&self) -> usize;

    /// The sensor a reading comes from. An index ≥ [`count`](Self::count) is refused as
    /// [`FusionError::UnknownSensor`](super::FusionError::UnknownSensor).
    fn sensor(&self, reading: &Self::Reading) -> usize;

    /// The number of components m of `sensor`'s measurements (its gate and monitor thresholds
    /// are χ²ₘ quantiles). At least 1.
    fn dimension(&self, sensor: usize) -> usize;

    /// Updates `filter` with `reading` and summarises the report ([`Innovation::of`]). On
    /// error the filter must be unchanged (as the filters' own `update` guarantees).
    fn update(&self, filter: &mut F, reading: &Self::Reading) -> Result<Innovation<T>>;
}
