//! Modes of different state sizes: each mode filter runs in its own state, and the
//! multiple-model estimator mixes and combines in a common state through maps the user gives
//! (the IMM of Bar-Shalom, Li & Kirubarajan §11.6.6 over modes augmented to one state, as
//! MATLAB's `trackingIMM` does through its `ModelConversionFcn`).
//!
//! A [`StateMap`] says where each of a mode's nₘ components sits in the common state of n
//! components (an injective index list, e.g. a constant-velocity mode's [px, vx, py, vy]
//! inside a constant-acceleration state [px, vx, ax, py, vy, ay] at places 0, 1, 3, 4), and
//! what the mode's estimate says about the components it lacks: a default mean d and
//! variance σ², independent of the rest. With Eₘ the n × nₘ selection of those places and
//! Dₘ = Eₘᵀ:
//!
//! ```text
//! lift:     x = Eₘ xₘ + (I − Eₘ Dₘ) d,   P = Eₘ Pₘ Eₘᵀ + (I − Eₘ Dₘ) diag(σ²)   (common state)
//! project:  xₘ = Dₘ x,                   Pₘ = Dₘ P Dₘᵀ                          (mode state)
//! measure:  the mode updates with h(lift(xₘ)): Jacobian H Eₘ, Hessians Eₘᵀ ∇²hₖ Eₘ
//! ```
//!
//! An [`Embedded`] mode is a filter plus its map. It shows the IMM the lifted estimate
//! (read, mixed, combined in the common state), restarts from the projection of a mixed
//! Gaussian, predicts with its own process model at its own size, and updates with the
//! common-state measurement model seen through the map ([`LiftedMeasurement`]). The mode
//! set is [`EmbeddedModes`], a tuple of up to six embedded modes, each of its own filter
//! type and state size; a mode of the full common state takes [`StateMap::identity`].
//!
//! ```text
//! modes:    EmbeddedModes((Embedded::new(cv_filter, cv_map)?, Embedded::new(ca_filter, StateMap::identity(U6))?))
//! predict:  imm.predict_modes(&(cv_model, ca_model), &u, dt)   (each at its own size)
//! update:   imm.update_modes(&sensor_over_the_common_state, &z)
//! ```
//!
//! # Why this design
//!
//! - **Simple to call.** The user writes each mode's process model at its own size, as for
//!   the mode filter alone, and one measurement model per sensor over the common state: a
//!   sensor does not depend on the mode, so it is written once. The map is a list of places
//!   and two vectors, not two functions to keep consistent.
//! - **Statically sized where possible.** The mode size nₘ and the common size n are type
//!   parameters of [`StateMap`]: a 4-state mode in a 6-state IMM is `StateMap<f64, U4, U6>`
//!   and every lifted vector and matrix is a stack value. Runtime sizes (`Dyn`) work too.
//! - **No panics.** A map is checked when it is made ([`StateMap::new`]) and against its
//!   filter when the mode is made ([`Embedded::new`]): typed errors, quantity
//!   [`StateMap`](Quantity::StateMap). A mode set whose lifted sizes differ is refused by
//!   [`Imm::new`](super::Imm::new) as before.
//! - **Why a mode set of its own and not a wrapper filter in the tuple of
//!   [`modes`](super::modes).** A 4-state mode inside a 6-state IMM would have to
//!   implement `Predict<T, U6, P>` for its 4-state model `P`, which requires
//!   `P: ProcessInput<T, U6>`; every process model implements `ProcessInput` at its own size
//!   by a blanket impl, and a wrapper of the model generic over the scalar cannot implement
//!   it beside that impl (E0119: a downstream crate could make the wrapper a process model).
//!   [`EmbeddedModes`] implements [`PredictModes`] itself, mode i predicting with model i at
//!   its own size, so no model needs to pass for a common-state one. The update side has no
//!   such wall: [`LiftedMeasurement`] is a measurement model of the mode's state.
//! - **Why defaults for the missing components.** Filling them from the other modes'
//!   estimates (unbiased mixing, Granström, Willett & Bar-Shalom 2015) changes the mixing
//!   itself; the default mean and variance keep the IMM's mixing as it is, and a CV mode
//!   with a zero default acceleration of variance σ² lifted this way is exactly the 6-state
//!   CV model with zero acceleration rows and σ² of acceleration process noise (the tests
//!   check this).
//!
//! Scope: the [`Imm`](super::Imm) (IMM or GPB1 mixing) with its checkpoints, the step
//! traits and so the fusion driver, and the [`ImmSmoother`](super::ImmSmoother) (each mode's
//! prediction cross-covariance carried through its map: C = P Dₘᵀ (Dₘ P Dₘᵀ)⁻¹ Cₘ Eₘᵀ, exact
//! for a Gaussian start). Not [`Gpb2`](super::Gpb2) and [`GaussianSum`](super::GaussianSum),
//! whose hypotheses are one filter type in a `Vec`.
//!
//! One embedded mode with the identity map is that filter bit for bit: lifting and
//! projecting through the identity copy every entry, and the lifted measurement model
//! evaluates h, its Jacobian and its Hessians at a copy of the same state. Checkpoints
//! (feature `serde`) write each mode's filter and map, and read them back through
//! [`StateMap::new`] and [`Embedded::new`].
//!
//! ```
//! use estim_core::nalgebra::{DMatrix, DVector, Matrix1, Matrix1x3, Matrix2, Matrix3, U3, Vector1, Vector2, Vector3};
//! use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
//! use estim_filters::imm::{Embedded, EmbeddedModes, Imm, ImmSmoother, StateMap};
//! use estim_filters::{Estimator, KalmanFilter};
//!
//! // Constant velocity [p, v] inside constant acceleration [p, v, a].
//! let cv = LinearProcess::without_input(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity() * 1e-3);
//! let ca_f = Matrix3::new(1.0, 1.0, 0.5, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0);
//! let ca = LinearProcess::without_input(ca_f, Matrix3::identity() * 1e-2);
//! // The CV mode's a is 0 with variance 0.1 when lifted.
//! let map = StateMap::new(&[0, 1], Vector3::zeros(), Vector3::new(0.0, 0.0, 0.1))?;
//! let modes = EmbeddedModes((
//!     Embedded::new(KalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?), map)?,
//!     Embedded::new(KalmanFilter::new(Gaussian::new(Vector3::zeros(), Matrix3::identity())?), StateMap::identity(U3))?,
//! ));
//! let pi = DMatrix::from_row_slice(2, 2, &[0.95, 0.05, 0.05, 0.95]);
//! let mut imm = Imm::new(modes, pi, DVector::from_element(2, 0.5))?;
//! let sensor = LinearMeasurement { observation: Matrix1x3::new(1.0, 0.0, 0.0), noise: Matrix1::new(0.01) };
//! let mut smoother = ImmSmoother::new(); // records the forward pass to smooth it after
//! for k in 1..=15 {
//!     smoother.predict(&mut imm, &(cv.clone(), ca.clone()), &(), 1.0)?; // imm.predict_modes + record
//!     imm.update_modes(&sensor, &Vector1::new(0.5 * f64::from(k * k)))?; // it accelerates
//! }
//! assert!(imm.probabilities()[1] > 0.95); // the accelerating mode explains the data
//! assert_eq!(imm.state().len(), 3); // the combined estimate is in the common state
//! assert!((imm.state()[2] - 1.0).abs() < 0.1);
//! let smoothed = smoother.smooth(&imm).map_err(|e| e.error)?;
//! assert_eq!(smoothed.len(), 16);
//! assert_eq!(smoothed[15].estimate.mean(), imm.state()); // the last one is the filter's
//! assert!((smoothed[8].estimate.mean()[2] - 1.0).abs() < 0.1); // a = 1 all along
//! // A map whose place list does not fit the mode is a typed error.
//! let wrong = StateMap::<f64, estim_core::nalgebra::U2, U3>::new(&[0, 1, 2], Vector3::zeros(), Vector3::zeros());
//! assert!(matches!(wrong, Err(estim_core::Error::DimensionMismatch { .. })));
//! # Ok::<(), estim_core::Error>(())
//! ```

use estim_core::nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};
use estim_core::{
    Alloc, Error, Gaussian, LinearMeasurementModel, MeasurementHessian, MeasurementJacobian,
    MeasurementModel, Quantity, Real, Stage, error::Result,
};

use super::modes::{Modes, PredictModes, UpdateModes, no_mode};
use crate::report::UpdateReport;
use crate::traits::{Estimator, Predict, ProcessInput, Rollback, Update};

mod cross;

/// Where a mode's `Nm` components sit in the common state of `N` components, and the default
/// mean and variance of the common components the mode lacks (see the [module docs](self)).
#[derive(Clone, Debug, PartialEq)]
pub struct StateMap<T: Real, Nm: Dim, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    places: Vec<usize>,
    mode: Nm,
    mean: OVector<T, N>,
    variance: OVector<T, N>,
}

impl<T: Real, Nm: Dim, N: Dim> StateMap<T, Nm, N>
where
    DefaultAllocator: Alloc<N> + Alloc<Nm>,
{
    /// The map putting mode component a at common component `places[a]`; the common
    /// components in no place take `mean` and `variance` (independent of the rest) when the
    /// mode's estimate is lifted. The entries of `mean` and `variance` at the places are not
    /// used (the mode's estimate is there).
    ///
    /// Errors (quantity [`StateMap`](Quantity::StateMap)): `places` not of the mode's size
    /// (`Nm`; any length for `Dyn`), a place outside the common state, or a place twice
    /// ([`Error::DimensionMismatch`]: the found rows are the places' count, one more than the
    /// largest place, or the distinct places); `mean` and `variance` of different lengths
    /// ([`Error::DimensionMismatch`]); an entry not finite ([`Error::NonFinite`]) or a
    /// negative variance ([`Error::NotPositiveSemiDefinite`]).
    ///
    /// ```
    /// use estim_core::nalgebra::{U4, U6, Vector6};
    /// use estim_core::{Error, Quantity};
    /// use estim_filters::imm::StateMap;
    ///
    /// // [px, vx, py, vy] inside [px, vx, ax, py, vy, ay]; ax, ay default to N(0, 0.5²).
    /// let sigma2 = Vector6::new(0.0, 0.0, 0.25, 0.0, 0.0, 0.25);
    /// let map = StateMap::<f64, U4, U6>::new(&[0, 1, 3, 4], Vector6::zeros(), sigma2)?;
    /// assert_eq!(map.places(), &[0, 1, 3, 4]);
    /// let twice = StateMap::<f64, U4, U6>::new(&[0, 1, 1, 4], Vector6::zeros(), sigma2);
    /// assert!(matches!(twice, Err(Error::DimensionMismatch { quantity: Quantity::StateMap, .. })));
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn new(places: &[usize], mean: OVector<T, N>, variance: OVector<T, N>) -> Result<Self> {
        let mismatch = |expected: usize, found: usize| Error::DimensionMismatch {
            stage: Stage::Construction,
            quantity: Quantity::StateMap,
            expected_rows: expected,
            expected_cols: 1,
            found_rows: found,
            found_cols: 1,
        };
        let n = mean.nrows();
        if variance.nrows() != n {
            return Err(mismatch(n, variance.nrows()));
        }
        if let Some(size) = Nm::try_to_usize()
            && places.len() != size
        {
            return Err(mismatch(size, places.len()));
        }
        if let Some(&outside) = places.iter().find(|&&i| i >= n) {
            return Err(mismatch(n, outside + 1));
        }
        let mut seen = vec![false; n];
        let mut distinct = 0;
        for &i in places {
            distinct += usize::from(!seen[i]);
            seen[i] = true;
        }
        if distinct != places.len() {
            return Err(mismatch(places.len(), distinct));
        }
        if mean.iter().chain(variance.iter()).any(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                stage: Stage::Construction,
                quantity: Quantity::StateMap,
            });
        }
        if variance.iter().any(|&v| v < T::zero()) {
            return Err(Error::NotPositiveSemiDefinite {
                stage: Stage::Construction,
                quantity: Quantity::StateMap,
            });
        }
        Ok(Self {
            places: places.to_vec(),
            mode: Nm::from_usize(places.len()),
            mean,
            variance,
        })
    }

    /// Mode component a's place in the common state, for every a.
    pub fn places(&self) -> &[usize] {
        &self.places
    }

    /// The default mean d of the common state (read where no mode component sits).
    pub fn mean(&self) -> &OVector<T, N> {
        &self.mean
    }

    /// The default variances σ² of the common state (read where no mode component sits).
    pub fn variance(&self) -> &OVector<T, N> {
        &self.variance
    }

    /// The mode's state size nₘ.
    pub fn mode_size(&self) -> usize {
        self.places.len()
    }

    /// The common state size n.
    pub fn common_size(&self) -> usize {
        self.mean.nrows()
    }

    /// lift(xₘ) = Eₘ xₘ + (I − Eₘ Dₘ) d: the mode's mean in the common state.
    ///
    /// # Panics
    /// If `x` does not have the mode's size (a runtime size only).
    #[track_caller]
    pub fn lift_mean(&self, x: &OVector<T, Nm>) -> OVector<T, N> {
        let mut lifted = self.mean.clone();
        for (a, &i) in self.places.iter().enumerate() {
            lifted[i] = x[a];
        }
        lifted
    }

    /// The lifted mean and covariance into `x` and `p` (see the [module docs](self)).
    fn lift_into(
        &self,
        mode_x: &OVector<T, Nm>,
        mode_p: &OMatrix<T, Nm, Nm>,
        x: &mut OVector<T, N>,
        p: &mut OMatrix<T, N, N>,
    ) {
        x.copy_from(&self.mean);
        p.fill(T::zero());
        for (i, &v) in self.variance.iter().enumerate() {
            p[(i, i)] = v;
        }
        for (a, &i) in self.places.iter().enumerate() {
            x[i] = mode_x[a];
            for (b, &j) in self.places.iter().enumerate() {
                p[(i, j)] = mode_p[(a, b)];
            }
        }
    }

    /// The projection (Dₘ x, Dₘ P Dₘᵀ) of a common-state Gaussian onto the mode's state.
    ///
    /// # Panics
    /// If `g` does not have the common size (a runtime size only).
    #[track_caller]
    pub fn project(&self, g: &Gaussian<T, N>) -> Gaussian<T, Nm> {
        let (x, p) = (g.mean(), g.covariance());
        let places = &self.places;
        Gaussian::new_unchecked(
            OVector::from_fn_generic(self.mode, U1, |a, _| x[places[a]]),
            OMatrix::from_fn_generic(self.mode, self.mode, |a, b| p[(places[a], places[b])]),
        )
    }
}

impl<T: Real, N: Dim> StateMap<T, N, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The identity map of a mode over the whole common state of size `n` (`U6`, say, or
    /// `Dyn(6)`): lifting and projecting copy every entry.
    ///
    /// ```
    /// use estim_core::nalgebra::U3;
    /// use estim_filters::imm::StateMap;
    ///
    /// let map = StateMap::<f64, U3, U3>::identity(U3);
    /// assert_eq!(map.places(), &[0, 1, 2]);
    /// ```
    pub fn identity(n: N) -> Self {
        Self {
            places: (0..n.value()).collect(),
            mode: n,
            mean: OVector::zeros_generic(n, U1),
            variance: OVector::zeros_generic(n, U1),
        }
    }
}

/// A common-state measurement model `H` seen from a mode's state through its [`StateMap`]:
/// h(lift(xₘ)), R(lift(xₘ)), Jacobian H Eₘ, Hessians Eₘᵀ ∇²hₖ Eₘ; linear when `H` is.
/// [`Embedded`] updates its filter with it.
///
/// ```
/// use estim_core::nalgebra::{Matrix1, Matrix1x3, U2, U3, Vector2, Vector3};
/// use estim_core::{LinearMeasurement, MeasurementJacobian, MeasurementModel};
/// use estim_filters::imm::{LiftedMeasurement, StateMap};
///
/// let map = StateMap::<f64, U2, U3>::new(&[0, 2], Vector3::new(0.0, 7.0, 0.0), Vector3::zeros())?;
/// let h = LinearMeasurement { observation: Matrix1x3::new(1.0, 1.0, 0.0), noise: Matrix1::new(0.1) };
/// let lifted = LiftedMeasurement::new(&h, &map);
/// let x = Vector2::new(2.0, 5.0);
/// assert_eq!(lifted.measure(&x)[0], 9.0); // 2 + the default 7
/// assert_eq!(lifted.measurement_jacobian(&x), estim_core::nalgebra::Matrix1x2::new(1.0, 0.0));
/// # Ok::<(), estim_core::Error>(())
/// ```
#[derive(Debug)]
pub struct LiftedMeasurement<'a, T: Real, Nm: Dim, N: Dim, H: ?Sized>
where
    DefaultAllocator: Alloc<N>,
{
    model: &'a H,
    map: &'a StateMap<T, Nm, N>,
}

impl<'a, T: Real, Nm: Dim, N: Dim, H: ?Sized> LiftedMeasurement<'a, T, Nm, N, H>
where
    DefaultAllocator: Alloc<N>,
{
    /// `model` seen through `map`.
    pub fn new(model: &'a H, map: &'a StateMap<T, Nm, N>) -> Self {
        Self { model, map }
    }
}

impl<T, Nm, N, M, H> MeasurementModel<T, Nm, M> for LiftedMeasurement<'_, T, Nm, N, H>
where
    T: Real,
    Nm: Dim,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M> + Alloc<Nm, M>,
{
    fn measure(&self, x: &OVector<T, Nm>) -> OVector<T, M> {
        self.model.measure(&self.map.lift_mean(x))
    }

    fn measurement_noise(&self, x: &OVector<T, Nm>) -> OMatrix<T, M, M> {
        self.model.measurement_noise(&self.map.lift_mean(x))
    }

    fn residual_into(&self, a: &OVector<T, M>, b: &OVector<T, M>, out: &mut OVector<T, M>) {
        self.model.residual_into(a, b, out);
    }
}

impl<T, Nm, N, M, H> MeasurementJacobian<T, Nm, M> for LiftedMeasurement<'_, T, Nm, N, H>
where
    T: Real,
    Nm: Dim,
    N: Dim,
    M: Dim,
    H: MeasurementJacobian<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M> + Alloc<Nm, M>,
{
    fn measurement_jacobian(&self, x: &OVector<T, Nm>) -> OMatrix<T, M, Nm> {
        let j = self.model.measurement_jacobian(&self.map.lift_mean(x));
        let places = &self.map.places;
        OMatrix::from_fn_generic(j.shape_generic().0, self.map.mode, |r, c| j[(r, places[c])])
    }
}

impl<T, Nm, N, M, H> MeasurementHessian<T, Nm, M> for LiftedMeasurement<'_, T, Nm, N, H>
where
    T: Real,
    Nm: Dim,
    N: Dim,
    M: Dim,
    H: MeasurementHessian<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M> + Alloc<Nm, M>,
{
    fn measurement_hessian(&self, x: &OVector<T, Nm>, k: usize) -> Option<OMatrix<T, Nm, Nm>> {
        let h = self.model.measurement_hessian(&self.map.lift_mean(x), k)?;
        let (places, nm) = (&self.map.places, self.map.mode);
        Some(OMatrix::from_fn_generic(nm, nm, |a, b| {
            h[(places[a], places[b])]
        }))
    }
}

impl<T, Nm, N, M, H> LinearMeasurementModel<T, Nm, M> for LiftedMeasurement<'_, T, Nm, N, H>
where
    T: Real,
    Nm: Dim,
    N: Dim,
    M: Dim,
    H: LinearMeasurementModel<T, N, M> + ?Sized,
    DefaultAllocator: Alloc<N, M> + Alloc<Nm, M>,
{
}

/// A mode filter `F` of an `Nm`-dimensional state inside a multiple-model estimator of an
/// `N`-dimensional common state, through its [`StateMap`] (see the [module docs](self)).
/// As an [`Estimator`] it reads the lifted estimate and restarts from the projection of
/// the prior; [`Update`] updates the filter with the measurement model through the map
/// ([`LiftedMeasurement`]), [`predict`](Self::predict) with the filter's own process model.
#[derive(Clone, Debug)]
pub struct Embedded<T: Real, Nm: Dim, N: Dim, F>
where
    DefaultAllocator: Alloc<N>,
{
    filter: F,
    map: StateMap<T, Nm, N>,
    state: OVector<T, N>,
    covariance: OMatrix<T, N, N>,
}

impl<T: Real, Nm: Dim, N: Dim, F: Estimator<T, Nm>> Embedded<T, Nm, N, F>
where
    DefaultAllocator: Alloc<N> + Alloc<Nm>,
{
    /// `filter` as a mode of the common state through `map`.
    ///
    /// Errors: the filter's state size is not the map's mode size
    /// ([`Error::DimensionMismatch`], quantity [`StateMap`](Quantity::StateMap); possible with
    /// runtime sizes only, static ones are checked by the compiler).
    ///
    /// ```
    /// use estim_core::nalgebra::{DMatrix, DVector, Dyn};
    /// use estim_core::{Error, Gaussian, Quantity};
    /// use estim_filters::imm::{Embedded, StateMap};
    /// use estim_filters::KalmanFilter;
    ///
    /// let filter = KalmanFilter::new(Gaussian::new(DVector::zeros(2), DMatrix::identity(2, 2))?);
    /// let three = StateMap::<f64, Dyn, Dyn>::new(&[0, 1, 2], DVector::zeros(4), DVector::zeros(4))?;
    /// assert!(matches!(
    ///     Embedded::new(filter.clone(), three),
    ///     Err(Error::DimensionMismatch { quantity: Quantity::StateMap, expected_rows: 3, found_rows: 2, .. })
    /// ));
    /// let two = StateMap::<f64, Dyn, Dyn>::new(&[0, 3], DVector::zeros(4), DVector::from_element(4, 1.0))?;
    /// let mode = Embedded::new(filter, two)?;
    /// assert_eq!(mode.state_in_common().len(), 4);
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn new(filter: F, map: StateMap<T, Nm, N>) -> Result<Self> {
        if filter.state().nrows() != map.mode_size() {
            return Err(Error::DimensionMismatch {
                stage: Stage::Construction,
                quantity: Quantity::StateMap,
                expected_rows: map.mode_size(),
                expected_cols: 1,
                found_rows: filter.state().nrows(),
                found_cols: 1,
            });
        }
        let (n, one) = map.mean.shape_generic();
        let mut mode = Self {
            state: OVector::zeros_generic(n, one),
            covariance: OMatrix::zeros_generic(n, n),
            filter,
            map,
        };
        mode.refresh();
        Ok(mode)
    }

    /// The mode filter.
    pub fn filter(&self) -> &F {
        &self.filter
    }

    /// The map.
    pub fn map(&self) -> &StateMap<T, Nm, N> {
        &self.map
    }

    /// The filter and the map, given back.
    pub fn into_parts(self) -> (F, StateMap<T, Nm, N>) {
        (self.filter, self.map)
    }

    /// The lifted mean (the same as [`Estimator::state`]).
    pub fn state_in_common(&self) -> &OVector<T, N> {
        &self.state
    }

    /// The lifted estimate from the filter's.
    fn refresh(&mut self) {
        self.map.lift_into(
            self.filter.state(),
            self.filter.covariance(),
            &mut self.state,
            &mut self.covariance,
        );
    }

    /// The filter's own prediction through its process model `model` (at the mode's size);
    /// unchanged on an error (the filter's contract).
    pub fn predict<P: ProcessInput<T, Nm> + ?Sized>(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<()>
    where
        F: Predict<T, Nm, P>,
    {
        self.filter.predict(model, input, dt)?;
        self.refresh();
        Ok(())
    }
}

/// The lifted estimate; [`reset`](Estimator::reset) restarts the filter from the prior's
/// projection.
///
/// # Panics
/// `reset` with a prior not of the common size (a runtime size only).
impl<T: Real, Nm: Dim, N: Dim, F: Estimator<T, Nm>> Estimator<T, N> for Embedded<T, Nm, N, F>
where
    DefaultAllocator: Alloc<N> + Alloc<Nm>,
{
    fn state(&self) -> &OVector<T, N> {
        &self.state
    }

    fn covariance(&self) -> &OMatrix<T, N, N> {
        &self.covariance
    }

    #[track_caller]
    fn reset(&mut self, prior: Gaussian<T, N>) {
        self.filter.reset(self.map.project(&prior));
        self.refresh();
    }
}

/// The filter's snapshot; the lifted estimate is recomputed on a restore (to the same bits).
impl<T, Nm, N, F> Rollback for Embedded<T, Nm, N, F>
where
    T: Real,
    Nm: Dim,
    N: Dim,
    F: Estimator<T, Nm> + Rollback,
    DefaultAllocator: Alloc<N> + Alloc<Nm>,
{
    type Snapshot = F::Snapshot;

    fn snapshot(&self) -> F::Snapshot {
        self.filter.snapshot()
    }

    fn snapshot_into(&self, snapshot: &mut F::Snapshot) {
        self.filter.snapshot_into(snapshot);
    }

    fn restore(&mut self, snapshot: &F::Snapshot) {
        self.filter.restore(snapshot);
        self.refresh();
    }
}

/// The filter's update with `model` seen through the map ([`LiftedMeasurement`]).
impl<T, Nm, N, M, H, F> Update<T, N, M, H> for Embedded<T, Nm, N, F>
where
    T: Real,
    Nm: Dim,
    N: Dim,
    M: Dim,
    H: ?Sized,
    F: Estimator<T, Nm> + for<'a> Update<T, Nm, M, LiftedMeasurement<'a, T, Nm, N, H>>,
    DefaultAllocator: Alloc<N, M> + Alloc<Nm, M>,
{
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        let lifted = LiftedMeasurement::new(model, &self.map);
        self.filter.update_into(&lifted, z, report)?;
        self.refresh();
        Ok(())
    }
}

/// A set of [`Embedded`] modes (a tuple of up to six, each of its own filter type and state
/// size, all of one common state) as the modes of an [`Imm`](super::Imm) (either
/// [`Mixing`](super::Mixing)). The prediction takes the tuple of per-mode process models,
/// each at its mode's own size; the update one measurement model of the common state.
#[derive(Clone, Debug)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EmbeddedModes<L>(pub L);

// An `Embedded` mode is an estimator of the common state, so the tuple's own `Modes` and
// `UpdateModes` serve: the set only adds the prediction, each mode with its own-size model.
impl<T: Real, N: Dim, L: Modes<T, N>> Modes<T, N> for EmbeddedModes<L>
where
    DefaultAllocator: Alloc<N>,
{
    type Snapshot = L::Snapshot;

    fn count(&self) -> usize {
        self.0.count()
    }

    #[track_caller]
    fn mode(&self, i: usize) -> &dyn Estimator<T, N> {
        self.0.mode(i)
    }

    #[track_caller]
    fn reset_mode(&mut self, i: usize, prior: Gaussian<T, N>) {
        self.0.reset_mode(i, prior);
    }

    fn snapshot(&self) -> Self::Snapshot {
        self.0.snapshot()
    }

    fn snapshot_into(&self, snapshot: &mut Self::Snapshot) {
        self.0.snapshot_into(snapshot);
    }

    fn restore(&mut self, snapshot: &Self::Snapshot) {
        self.0.restore(snapshot);
    }
}

impl<T: Real, N: Dim, M: Dim, H: ?Sized, L: UpdateModes<T, N, M, H>> UpdateModes<T, N, M, H>
    for EmbeddedModes<L>
where
    DefaultAllocator: Alloc<N, M>,
{
    #[track_caller]
    fn update_mode(
        &mut self,
        i: usize,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.0.update_mode(i, model, z, report)
    }
}

macro_rules! embedded_modes {
    ($count:literal; $($F:ident $D:ident $P:ident $idx:tt),+) => {
        impl<T: Real, N: Dim, U, $($D: Dim, $F, $P),+> PredictModes<T, N, ($($P,)+)>
            for EmbeddedModes<($(Embedded<T, $D, N, $F>,)+)>
        where
            $($F: Predict<T, $D, $P> + Rollback, $P: ProcessInput<T, $D, Input = U>,)+
            DefaultAllocator: Alloc<N> $(+ Alloc<$D>)+,
        {
            type Input = U;

            #[track_caller]
            fn predict_mode(&mut self, i: usize, models: &($($P,)+), input: &U, dt: T) -> Result<()> {
                match i {
                    $($idx => (self.0).$idx.predict(&models.$idx, input, dt),)+
                    _ => no_mode(i, $count),
                }
            }
        }

    };
}

embedded_modes!(1; F0 D0 P0 0);
embedded_modes!(2; F0 D0 P0 0, F1 D1 P1 1);
embedded_modes!(3; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2);
embedded_modes!(4; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2, F3 D3 P3 3);
embedded_modes!(5; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2, F3 D3 P3 3, F4 D4 P4 4);
embedded_modes!(6; F0 D0 P0 0, F1 D1 P1 1, F2 D2 P2 2, F3 D3 P3 3, F4 D4 P4 4, F5 D5 P5 5);

#[cfg(feature = "serde")]
mod serde_impls {
    //! Checkpoints: a map as its places, default mean and variances (read back through
    //! [`StateMap::new`]); an embedded mode as its filter and map (through
    //! [`Embedded::new`]); the lifted estimate is recomputed.

    use estim_core::nalgebra::{DefaultAllocator, Dim, OVector, U1};
    use estim_core::serialize::ShapeChecked;
    use estim_core::{Alloc, Real};
    use serde::de::Error as _;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use super::{Embedded, StateMap};
    use crate::traits::Estimator;

    #[derive(Serialize, Deserialize)]
    #[serde(rename = "StateMap")]
    struct MapFields<V> {
        places: Vec<usize>,
        mean: V,
        variance: V,
    }

    #[derive(Serialize, Deserialize)]
    #[serde(rename = "Embedded")]
    struct ModeFields<F, S> {
        filter: F,
        map: S,
    }

    impl<T: Real + Serialize, Nm: Dim, N: Dim> Serialize for StateMap<T, Nm, N>
    where
        DefaultAllocator: Alloc<N>,
        OVector<T, N>: Serialize,
    {
        fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
            MapFields::<&OVector<T, N>> {
                places: self.places.clone(),
                mean: &self.mean,
                variance: &self.variance,
            }
            .serialize(serializer)
        }
    }

    impl<'de, T: Real + Deserialize<'de>, Nm: Dim, N: Dim> Deserialize<'de> for StateMap<T, Nm, N>
    where
        DefaultAllocator: Alloc<N> + Alloc<Nm>,
        ShapeChecked<T, N, U1>: Deserialize<'de>,
    {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
            let f = MapFields::<ShapeChecked<T, N, U1>>::deserialize(deserializer)?;
            StateMap::new(&f.places, f.mean.0, f.variance.0).map_err(D::Error::custom)
        }
    }

    impl<T: Real + Serialize, Nm: Dim, N: Dim, F: Serialize> Serialize for Embedded<T, Nm, N, F>
    where
        DefaultAllocator: Alloc<N>,
        OVector<T, N>: Serialize,
    {
        fn serialize<Se: Serializer>(&self, serializer: Se) -> Result<Se::Ok, Se::Error> {
            ModeFields {
                filter: &self.filter,
                map: &self.map,
            }
            .serialize(serializer)
        }
    }

    impl<'de, T, Nm, N, F> Deserialize<'de> for Embedded<T, Nm, N, F>
    where
        T: Real + Deserialize<'de>,
        Nm: Dim,
        N: Dim,
        F: Estimator<T, Nm> + Deserialize<'de>,
        DefaultAllocator: Alloc<N> + Alloc<Nm>,
        ShapeChecked<T, N, U1>: Deserialize<'de>,
    {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
            let f = ModeFields::<F, StateMap<T, Nm, N>>::deserialize(deserializer)?;
            Embedded::new(f.filter, f.map).map_err(D::Error::custom)
        }
    }
}

#[cfg(test)]
mod tests {
    //! The map's index arithmetic against the matrix formulas of the module docs, with the
    //! selection matrix Eₘ written out.

    use estim_core::nalgebra::{Matrix1, Matrix1x3, Matrix2, Matrix3, Matrix3x2, U1, U2, U3};
    use estim_core::nalgebra::{Vector1, Vector2, Vector3};

    use super::*;

    /// h(x) = x₀ x₁ + x₂², with its Jacobian and Hessian.
    struct Bilinear;

    impl MeasurementModel<f64, U3, U1> for Bilinear {
        fn measure(&self, x: &Vector3<f64>) -> Vector1<f64> {
            Vector1::new(x[0] * x[1] + x[2] * x[2])
        }
        fn measurement_noise(&self, x: &Vector3<f64>) -> Matrix1<f64> {
            Matrix1::new(0.1 + x[1].abs())
        }
    }

    impl MeasurementJacobian<f64, U3, U1> for Bilinear {
        fn measurement_jacobian(&self, x: &Vector3<f64>) -> Matrix1x3<f64> {
            Matrix1x3::new(x[1], x[0], 2.0 * x[2])
        }
    }

    impl MeasurementHessian<f64, U3, U1> for Bilinear {
        fn measurement_hessian(&self, _: &Vector3<f64>, _: usize) -> Option<Matrix3<f64>> {
            Some(Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 2.0))
        }
    }

    #[test]
    fn lifting_projecting_and_the_lifted_model_are_the_selection_matrix_formulas() {
        // Mode component 0 at common place 2, component 1 at place 0; place 1 defaults to
        // N(5, 0.7).
        let map = StateMap::<f64, U2, U3>::new(
            &[2, 0],
            Vector3::new(9.0, 5.0, 9.0),
            Vector3::new(9.0, 0.7, 9.0),
        )
        .unwrap();
        let e = Matrix3x2::new(0.0, 1.0, 0.0, 0.0, 1.0, 0.0);
        let d = Vector3::new(0.0, 5.0, 0.0);
        let rest = Matrix3::from_diagonal(&Vector3::new(0.0, 0.7, 0.0));
        let (x, p) = (Vector2::new(1.5, -2.0), Matrix2::new(2.0, 0.3, 0.3, 1.0));
        let (mut lx, mut lp) = (Vector3::zeros(), Matrix3::zeros());
        map.lift_into(&x, &p, &mut lx, &mut lp);
        // Selections and sums of one nonzero term: exact.
        assert_eq!(lx, e * x + d);
        assert_eq!(lp, e * p * e.transpose() + rest);
        let back = map.project(&Gaussian::new_unchecked(lx, lp));
        assert_eq!((back.mean(), back.covariance()), (&x, &p));
        let lifted = LiftedMeasurement::new(&Bilinear, &map);
        assert_eq!(lifted.measure(&x), Bilinear.measure(&lx));
        assert_eq!(lifted.measurement_noise(&x), Matrix1::new(5.1));
        assert_eq!(
            lifted.measurement_jacobian(&x),
            Bilinear.measurement_jacobian(&lx) * e
        );
        assert_eq!(
            lifted.measurement_hessian(&x, 0),
            Some(e.transpose() * Bilinear.measurement_hessian(&lx, 0).unwrap() * e)
        );
    }
}
