//! The step traits of [`SquareRootFilter`]: one impl each, through the factor-form propagator.

use super::*;

impl<T: Real, N: Dim, Pr, S: StateSpace<T, N>> SquareRootFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    /// The prediction (with C = cov(xₖ, xₖ₊₁) into `cross` if given), computed in the step's
    /// scratch (a local for static sizes, the cached one for `Dyn`) and committed if it
    /// succeeds and `step` applies it.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn predict_step<P>(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
        cross: Option<&mut OMatrix<T, N, N>>,
        step: Step,
    ) -> Result<()>
    where
        P: ProcessModel<T, N>,
        Pr: FactorPredict<T, N, P>,
    {
        ensure_time_step(dt)?;
        self.ensure_factored(Stage::Prediction)?;
        let Self {
            state,
            factor,
            covariance,
            propagator,
            space,
            scratch: cache,
            ..
        } = self;
        let n = state.shape_generic().0;
        let mut local;
        let (work, cached) = match cache.predict(n) {
            Some((work, _)) => (work, true),
            None => {
                local = FactorScratch::new(n, n);
                (&mut local, false)
            }
        };
        estim_core::model::process_noise_into(model, state, input, dt, &mut work.noise);
        let result = propagator
            .predict_factor(space, state, factor, model, input, dt, work, cross)
            .and_then(|()| match step {
                Step::Apply => commit(Stage::Prediction, state, factor, covariance, work),
                Step::Prepare => Ok(()),
            });
        if result.is_err() && cached {
            cache.discard_predict();
        }
        result
    }

    /// An update with `model` and `z` (or its preparation), computed in the step's scratch
    /// and committed if applied.
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn update_step<M, H>(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
        step: Step,
    ) -> Result<()>
    where
        M: Dim,
        H: MeasurementModel<T, N, M>,
        Pr: FactorUpdate<T, N, M, H>,
        DefaultAllocator: Alloc<N, M>,
    {
        self.ensure_factored(Stage::Update)?;
        let threshold = self.settings.threshold(z.nrows());
        let Self {
            state,
            factor,
            covariance,
            propagator,
            space,
            scratch: cache,
            ..
        } = self;
        let (n, m) = (state.shape_generic().0, z.shape_generic().0);
        let mut local;
        let (work, slot) = match cache.update(n, m) {
            Some((work, slot)) => (work, Some(slot)),
            None => {
                local = FactorScratch::new(n, m);
                (&mut local, None)
            }
        };
        let result = propagator
            .update_factor(space, state, factor, model, z, threshold, work, report)
            .and_then(|apply| match step {
                Step::Apply if apply => commit(Stage::Update, state, factor, covariance, work),
                _ => Ok(()),
            });
        if let (Err(_), Some(slot)) = (&result, slot) {
            cache.discard_update(slot);
        }
        result
    }
}

impl<T, N, P, Pr, S> Predict<T, N, P> for SquareRootFilter<T, N, Pr, S>
where
    S: StateSpace<T, N>,
    T: Real,
    N: Dim,
    P: ProcessModel<T, N>,
    Pr: FactorPredict<T, N, P>,
    DefaultAllocator: Alloc<N>,
{
    fn predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.predict_step(model, input, dt, None, Step::Apply)
    }

    /// Sizes the runtime-size prediction buffers by one prediction that is not committed.
    fn prepare_predict(&mut self, model: &P, input: &P::Input, dt: T) -> Result<()> {
        self.predict_step(model, input, dt, None, Step::Prepare)
    }
}

/// The state space the filter was given ([`with_state_space`](SquareRootFilter::with_state_space)).
impl<T: Real, N: Dim, Pr, S: StateSpace<T, N>> OnStateSpace<T, N> for SquareRootFilter<T, N, Pr, S>
where
    DefaultAllocator: Alloc<N>,
{
    type Space = S;

    fn state_space(&self) -> &S {
        &self.space
    }
}

/// The prediction's own path with C written out, so a square-root run can be smoothed by
/// [`Rts`](crate::smoother::Rts) (the RTS form on P = S Sᵀ: the backward pass factorises
/// P⁻, as it does for the full-covariance filters).
///
/// ```
/// use estim_core::nalgebra::{Matrix2, Matrix2x1, Vector1, Vector2};
/// use estim_core::{Gaussian, LinearProcess};
/// use estim_filters::{PredictCross, SrKalmanFilter};
///
/// let f = Matrix2::new(1.0, 0.1, 0.0, 1.0);
/// let process = LinearProcess { transition: f, input: Matrix2x1::zeros(), noise: Matrix2::identity() * 0.01 };
/// let mut kf = SrKalmanFilter::new(Gaussian::new(Vector2::zeros(), Matrix2::identity())?);
/// let c = kf.predict_with_cross_covariance(&process, &Vector1::zeros(), 0.1)?;
/// assert!((c - f.transpose()).abs().max() < 1e-15); // cov(x, F x) = P Fᵀ with P = I
/// # Ok::<(), estim_core::Error>(())
/// ```
impl<T, N, P, Pr, S> PredictCross<T, N, P> for SquareRootFilter<T, N, Pr, S>
where
    S: StateSpace<T, N>,
    T: Real,
    N: Dim,
    P: ProcessModel<T, N>,
    Pr: FactorPredict<T, N, P>,
    DefaultAllocator: Alloc<N>,
{
    fn predict_with_cross_covariance(
        &mut self,
        model: &P,
        input: &P::Input,
        dt: T,
    ) -> Result<OMatrix<T, N, N>> {
        let n = self.state.shape_generic().0;
        let mut cross = OMatrix::zeros_generic(n, n);
        self.predict_step(model, input, dt, Some(&mut cross), Step::Apply)?;
        Ok(cross)
    }
}

impl<T, N, M, H, Pr, S> Update<T, N, M, H> for SquareRootFilter<T, N, Pr, S>
where
    S: StateSpace<T, N>,
    T: Real,
    N: Dim,
    M: Dim,
    H: MeasurementModel<T, N, M>,
    Pr: FactorUpdate<T, N, M, H>,
    DefaultAllocator: Alloc<N, M>,
{
    fn update_into(
        &mut self,
        model: &H,
        z: &OVector<T, M>,
        report: &mut UpdateReport<T, M>,
    ) -> Result<()> {
        self.update_step(model, z, report, Step::Apply)
    }

    /// Sizes the runtime-size update buffers for this model's measurement length (and
    /// `report`) by one update with z = h(x̂) that is not committed.
    fn prepare_update(&mut self, model: &H, report: &mut UpdateReport<T, M>) -> Result<()> {
        let z = model.measure(&self.state);
        self.update_step(model, &z, report, Step::Prepare)
    }
}
