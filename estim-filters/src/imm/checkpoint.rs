//! Checkpoints (feature `serde`) of an [`ImmSmoother`] and a [`GaussianSum`] (their impls'
//! docs say what is written), and of an [`Imm`]: the mode filters (each as its own type
//! serialises, e.g. a [`GaussianFilter`](crate::GaussianFilter) as in
//! [`checkpoint`](crate::checkpoint)), Π, the [`Mixing`](super::Mixing), μ and the initial μ₀. The combined estimate is not
//! written: it is a function of the modes and μ, recomputed on the way in to the same bits.
//! On the way in Π and μ are read through [`ShapeChecked`] (a corrupted runtime shape is an
//! error before nalgebra builds the matrix) and checked as by [`Imm::new`] (an error
//! otherwise).

use estim_core::checks::{ensure_finite, ensure_shape};
use estim_core::nalgebra::{DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1};
use estim_core::serialize::ShapeChecked;
use estim_core::{Alloc, Gaussian, Quantity, Real, Stage};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::smoother::{Method, Record};
use super::{GaussianSum, Imm, ImmSmoother, Modes, Prediction, mixture};
use crate::traits::Estimator;

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

/// A mean and covariance as written in a checkpoint (not through [`Gaussian`]'s own serde,
/// which re-checks definiteness: a recorded covariance is written and read as it is).
#[derive(Serialize, Deserialize)]
#[serde(rename = "Moments")]
struct MomentFields<V, M> {
    mean: V,
    covariance: M,
}

/// A recorded pair prediction ([`Prediction`]).
#[derive(Serialize, Deserialize)]
#[serde(rename = "Prediction")]
struct PredictionFields<V, M> {
    state: V,
    covariance: M,
    cross: M,
}

/// One recorded prediction of an [`ImmSmoother`].
#[derive(Serialize, Deserialize)]
#[serde(rename = "Record")]
struct RecordFields<Pi, Mu, G, P> {
    transition: Pi,
    probabilities: Mu,
    modes: Vec<G>,
    pairs: Vec<Option<P>>,
    predicted: Vec<G>,
}

/// An [`ImmSmoother`]'s checkpoint.
#[derive(Serialize, Deserialize)]
#[serde(rename = "ImmSmoother")]
struct SmootherFields<R> {
    method: Method,
    records: Vec<R>,
}

type Borrowed<'a, T, N> = MomentFields<&'a OVector<T, N>, &'a OMatrix<T, N, N>>;

fn borrowed<T: Real, N: Dim>(g: &Gaussian<T, N>) -> Borrowed<'_, T, N>
where
    DefaultAllocator: Alloc<N>,
{
    MomentFields {
        mean: g.mean(),
        covariance: g.covariance(),
    }
}

/// The smoother's record (every prediction's Π, μ, mode estimates, pair predictions and
/// the IMM's own predictions, each matrix exactly as it is) and its [`Method`]: a smoother
/// resumed from it goes on recording and smooths to the same bits as the original.
///
/// On the way in every matrix is read through [`ShapeChecked`] and must be finite; Π and μ
/// are checked as by [`Imm::new`]; every record must have the first one's number of modes m
/// (m mode estimates, m own predictions, m² pairs) and every Gaussian the first one's state
/// size; a pair must be present exactly where πᵢⱼ μᵢ > 0 (where the forward pass made one).
/// Anything else is the deserialiser's error, never a panic at [`ImmSmoother::smooth`].
///
/// ```
/// use estim_core::nalgebra::{DMatrix, DVector, Matrix1, Matrix1x2, Matrix2, U2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::imm::{Imm, ImmSmoother};
/// use estim_filters::KalmanFilter;
///
/// let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
/// let models = vec![
///     LinearProcess::without_input(f, Matrix2::identity() * 1e-4),
///     LinearProcess::without_input(f, Matrix2::identity() * 1e-1),
/// ];
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.25) };
/// let prior = Gaussian::new(Vector2::zeros(), Matrix2::identity())?;
/// let pi = DMatrix::from_row_slice(2, 2, &[0.95, 0.05, 0.10, 0.90]);
/// let mut imm = Imm::new(vec![KalmanFilter::new(prior.clone()); 2], pi, DVector::from_element(2, 0.5))?;
/// let mut smoother = ImmSmoother::new();
/// for k in 0..8 {
///     if k == 4 {
///         // Stop here, save both, carry on from the saved copies.
///         imm = serde_json::from_str(&serde_json::to_string(&imm)?)?;
///         smoother = serde_json::from_str::<ImmSmoother<f64, U2>>(&serde_json::to_string(&smoother)?)?;
///     }
///     smoother.predict(&mut imm, &models, &(), 1.0)?;
///     imm.update_modes(&sensor, &Vector1::new(k as f64))?;
/// }
/// assert_eq!(smoother.smooth(&imm)?.len(), 9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
impl<T: Real, N: Dim> Serialize for ImmSmoother<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Serialize,
    OMatrix<T, N, N>: Serialize,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        let records: Vec<_> = (self.records.iter())
            .map(|r| RecordFields {
                transition: &r.transition,
                probabilities: &r.probabilities,
                modes: r.modes.iter().map(borrowed).collect(),
                pairs: (r.pairs.iter())
                    .map(|p| {
                        p.as_ref().map(|p| PredictionFields {
                            state: &p.state,
                            covariance: &p.covariance,
                            cross: &p.cross,
                        })
                    })
                    .collect(),
                predicted: r.predicted.iter().map(borrowed).collect(),
            })
            .collect();
        SmootherFields {
            method: self.method,
            records,
        }
        .serialize(serializer)
    }
}

type Vector<T, N> = ShapeChecked<T, N, U1>;
type Square<T, N> = ShapeChecked<T, N, N>;
type ReadRecord<T, N> = RecordFields<
    ShapeChecked<T, Dyn, Dyn>,
    ShapeChecked<T, Dyn, U1>,
    MomentFields<Vector<T, N>, Square<T, N>>,
    PredictionFields<Vector<T, N>, Square<T, N>>,
>;

/// Checks a mean and the matrices that go with it: `size` rows (the first Gaussian read sets
/// it), square, finite.
fn check_moments<T: Real, N: Dim>(
    size: &mut Option<usize>,
    mean: &OVector<T, N>,
    matrices: &[&OMatrix<T, N, N>],
) -> estim_core::error::Result<()>
where
    DefaultAllocator: Alloc<N>,
{
    let stage = Stage::Construction;
    let n = *size.get_or_insert(mean.nrows());
    ensure_shape(mean, n, 1, stage, Quantity::Mean)?;
    ensure_finite(mean, stage, Quantity::Mean)?;
    for m in matrices {
        ensure_shape(*m, n, n, stage, Quantity::Covariance)?;
        ensure_finite(*m, stage, Quantity::Covariance)?;
    }
    Ok(())
}

/// A recorded Gaussian, checked by [`check_moments`].
fn read_moments<T: Real, N: Dim>(
    size: &mut Option<usize>,
    g: MomentFields<Vector<T, N>, Square<T, N>>,
) -> estim_core::error::Result<Gaussian<T, N>>
where
    DefaultAllocator: Alloc<N>,
{
    check_moments(size, &g.mean.0, &[&g.covariance.0])?;
    Ok(Gaussian::new_unchecked(g.mean.0, g.covariance.0))
}

/// One record read back and checked (see the `Serialize` impl's docs); `modes` is the first
/// record's mode count.
fn read_record<T: Real, N: Dim>(
    f: ReadRecord<T, N>,
    modes: &mut Option<usize>,
    size: &mut Option<usize>,
) -> core::result::Result<Record<T, N>, String>
where
    DefaultAllocator: Alloc<N>,
{
    let m = *modes.get_or_insert(f.probabilities.0.nrows());
    let (transition, probabilities) = (f.transition.0, f.probabilities.0);
    mixture::check_transition(&transition, m, Stage::Construction)
        .and_then(|()| mixture::check_probabilities(&probabilities, m))
        .map_err(|e| e.to_string())?;
    if f.modes.len() != m || f.predicted.len() != m || f.pairs.len() != m * m {
        return Err(format!(
            "a record of {m} modes holds {} mode estimates, {} predictions and {} pairs",
            f.modes.len(),
            f.predicted.len(),
            f.pairs.len()
        ));
    }
    let read = |size: &mut Option<usize>, list: Vec<_>| -> core::result::Result<Vec<_>, String> {
        (list.into_iter())
            .map(|g| read_moments(size, g).map_err(|e| e.to_string()))
            .collect()
    };
    let mode_estimates = read(size, f.modes)?;
    let predicted = read(size, f.predicted)?;
    let mut pairs = Vec::with_capacity(m * m);
    for (k, pair) in f.pairs.into_iter().enumerate() {
        let (i, j) = (k / m, k % m);
        let made = transition[(i, j)] * probabilities[i] != T::zero();
        if made != pair.is_some() {
            return Err(format!(
                "the pair ({i}, {j}) is {} but πᵢⱼ μᵢ {}",
                if made { "missing" } else { "present" },
                if made { "> 0" } else { "= 0" }
            ));
        }
        pairs.push(match pair {
            None => None,
            Some(p) => {
                let (state, covariance, cross) = (p.state.0, p.covariance.0, p.cross.0);
                check_moments(size, &state, &[&covariance, &cross]).map_err(|e| e.to_string())?;
                Some(Prediction {
                    state,
                    covariance,
                    cross,
                })
            }
        });
    }
    Ok(Record {
        transition,
        probabilities,
        modes: mode_estimates,
        pairs,
        predicted,
    })
}

impl<'de, T: Real, N: Dim> Deserialize<'de> for ImmSmoother<T, N>
where
    DefaultAllocator: Alloc<N>,
    OVector<T, N>: Deserialize<'de>,
    OMatrix<T, N, N>: Deserialize<'de>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = SmootherFields::<ReadRecord<T, N>>::deserialize(deserializer)?;
        let (mut modes, mut size) = (None, None);
        let records = (f.records.into_iter())
            .map(|r| read_record(r, &mut modes, &mut size))
            .collect::<core::result::Result<_, _>>()
            .map_err(D::Error::custom)?;
        Ok(ImmSmoother {
            records,
            method: f.method,
        })
    }
}

/// A [`GaussianSum`]'s checkpoint.
#[derive(Serialize, Deserialize)]
#[serde(rename = "GaussianSum")]
struct SumFields<C, V> {
    components: C,
    weights: V,
    max_components: usize,
}

/// The components (each as its filter type serialises), the weights and the bound on their
/// number; the combined estimate is recomputed on the way in, to the same bits. On the way
/// in the weights are read through [`ShapeChecked`] and checked as by [`GaussianSum::new`]
/// (one per component, in [0, 1], summing to 1), the components must have one state size,
/// and there must be at least one and at most `max_components` of them (a checkpoint is taken
/// after merging): anything else is the deserialiser's error.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, U2, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
/// use estim_filters::imm::GaussianSum;
/// use estim_filters::KalmanFilter;
///
/// let model = LinearProcess::without_input(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity() * 1e-3);
/// let sensor = LinearMeasurement { observation: Matrix1x2::new(1.0, 0.0), noise: Matrix1::new(0.5) };
/// let at = |p: f64| KalmanFilter::new(Gaussian::new(Vector2::new(p, 0.0), Matrix2::identity()).unwrap());
/// let mut gsf = GaussianSum::new(vec![(0.5, at(0.0)), (0.5, at(10.0))], 2)?;
/// gsf.predict(&model, &(), 1.0)?;
/// gsf.update(&sensor, &Vector1::new(9.8))?;
/// type Sum = GaussianSum<f64, U2, KalmanFilter<f64, U2>>;
/// let mut resumed: Sum = serde_json::from_str(&serde_json::to_string(&gsf)?)?;
/// for g in [&mut gsf, &mut resumed] {
///     g.predict(&model, &(), 1.0)?;
///     g.update(&sensor, &Vector1::new(10.1))?;
/// }
/// assert_eq!(resumed.weights(), gsf.weights()); // to the bit
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
impl<T: Real, N: Dim, F> Serialize for GaussianSum<T, N, F>
where
    DefaultAllocator: Alloc<N>,
    F: Serialize,
    T: Serialize,
{
    fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
        SumFields {
            components: &self.components,
            weights: &self.weights,
            max_components: self.max_components,
        }
        .serialize(serializer)
    }
}

impl<'de, T: Real, N: Dim, F> Deserialize<'de> for GaussianSum<T, N, F>
where
    DefaultAllocator: Alloc<N>,
    F: Estimator<T, N> + Clone + Deserialize<'de>,
    T: Deserialize<'de>,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let f = SumFields::<Vec<F>, ShapeChecked<T, Dyn, U1>>::deserialize(deserializer)?;
        let k = f.components.len();
        if k > f.max_components {
            return Err(D::Error::custom(format_args!(
                "{k} components, more than the bound {}",
                f.max_components
            )));
        }
        mixture::check_probabilities(&f.weights.0, k).map_err(D::Error::custom)?;
        let components = f.weights.0.iter().copied().zip(f.components).collect();
        // `new` checks the sizes and the bound; with k ≤ max_components it merges nothing.
        GaussianSum::new(components, f.max_components).map_err(D::Error::custom)
    }
}
