//! The Rauch–Tung–Striebel smoother against an independent route: the exact joint posterior
//! of all states of a linear-Gaussian system, formed by stacking x₀ … x_K into one vector and
//! solving the normal equations of its information form (batch least squares).

use estim_core::nalgebra::{
    DMatrix, DVector, Dyn, Matrix1, Matrix1x2, Matrix2, Matrix2x1, SymmetricEigen, U2, Vector1,
    Vector2,
};
use estim_core::propagate::Unscented;
use estim_core::{Error, Gaussian, LinearMeasurement, LinearProcess, Quantity, Stage};
use estim_filters::smoother::{
    Rts, Smoothed, SmootherError, filter_sequence, smooth_sequence,
    smooth_sequence_with_cross_covariances,
};
use estim_filters::{
    Ekf, GaussianFilter, KalmanFilter, PredictCross, SrEkf, SrKalmanFilter, SrUkf, Update,
};

/// A time-varying 2-state system: Δt changes each step (so does F), Q scales with Δt, an input
/// drives the velocity, and the position is measured at some steps only.
struct Scenario {
    dts: Vec<f64>,
    inputs: Vec<f64>,
    measurements: Vec<Option<f64>>,
    prior: (Vector2<f64>, Matrix2<f64>),
    r: f64,
}

impl Scenario {
    fn new() -> Self {
        let steps = 12;
        let dts = (0..steps).map(|k| 0.5 + 0.1 * (k % 4) as f64).collect();
        let inputs = (0..steps).map(|k| (k as f64 * 0.7).sin()).collect();
        // K + 1 measurement times; a gap at 2, 5, 6 and 9.
        let measurements = (0..=steps)
            .map(|k| (![2, 5, 6, 9].contains(&k)).then(|| 0.3 * k as f64 + (k as f64 * 1.3).cos()))
            .collect();
        let prior = (Vector2::new(0.5, -0.2), Matrix2::new(2.0, 0.3, 0.3, 1.0));
        Self {
            dts,
            inputs,
            measurements,
            prior,
            r: 0.4,
        }
    }

    fn process(dt: f64) -> LinearProcess<f64, U2, estim_core::nalgebra::U1> {
        LinearProcess {
            transition: Matrix2::new(1.0, dt, 0.0, 1.0),
            input: Matrix2x1::new(0.5 * dt * dt, dt),
            noise: Matrix2::new(0.02, 0.005, 0.005, 0.03) * dt,
        }
    }

    fn sensor(&self) -> LinearMeasurement<f64, U2, estim_core::nalgebra::U1> {
        LinearMeasurement {
            observation: Matrix1x2::new(1.0, 0.0),
            noise: Matrix1::new(self.r),
        }
    }

    /// The forward pass through `Rts::predict`, then the backward pass with the lag-one
    /// cross-covariances (whose estimates must be `Rts::smooth`'s, bit for bit).
    fn smooth<F>(&self, mut filter: F) -> Smoothed<f64, U2>
    where
        F: PredictCross<f64, U2, LinearProcess<f64, U2, estim_core::nalgebra::U1>>
            + Update<
                f64,
                U2,
                estim_core::nalgebra::U1,
                LinearMeasurement<f64, U2, estim_core::nalgebra::U1>,
            >,
    {
        let sensor = self.sensor();
        let mut rts = Rts::new();
        for k in 0..=self.dts.len() {
            if k > 0 {
                let process = Self::process(self.dts[k - 1]);
                let u = Vector1::new(self.inputs[k - 1]);
                rts.predict(&mut filter, &process, &u, self.dts[k - 1])
                    .unwrap();
            }
            if let Some(z) = self.measurements[k] {
                filter.update(&sensor, &Vector1::new(z)).unwrap();
            }
        }
        let pass = rts.smooth_with_cross_covariances(&filter).unwrap();
        assert_eq!(pass.estimates, rts.smooth(&filter).unwrap());
        pass
    }

    /// The batch problem of this scenario (`with_measurements = false`: the joint prior).
    fn batch_problem(&self, with_measurements: bool) -> BatchProblem {
        let to_dyn = |m: &Matrix2<f64>| DMatrix::from_column_slice(2, 2, m.as_slice());
        let transitions = self
            .dts
            .iter()
            .zip(&self.inputs)
            .map(|(&dt, &u)| {
                let p = Self::process(dt);
                let bu = DVector::from_column_slice((p.input * u).as_slice());
                (to_dyn(&p.transition), bu, to_dyn(&p.noise))
            })
            .collect();
        let h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let r = DMatrix::from_element(1, 1, self.r);
        let measurements = self
            .measurements
            .iter()
            .map(|z| {
                z.filter(|_| with_measurements)
                    .map(|z| (h.clone(), r.clone(), DVector::from_element(1, z)))
            })
            .collect();
        BatchProblem {
            prior: (
                DVector::from_column_slice(self.prior.0.as_slice()),
                to_dyn(&self.prior.1),
            ),
            transitions,
            measurements,
        }
    }

    /// The joint posterior's mean, covariance and κ(Λ) ([`batch_posterior`]).
    fn batch(&self, with_measurements: bool) -> (DVector<f64>, DMatrix<f64>, f64) {
        let b = batch_posterior(&self.batch_problem(with_measurements));
        (b.mean, b.covariance, b.condition)
    }
}

/// (Hₖ, Rₖ, zₖ): one measurement of a [`BatchProblem`].
pub(crate) type BatchMeasurement = (DMatrix<f64>, DMatrix<f64>, DVector<f64>);

/// A linear-Gaussian state-space problem over times 0 … K, in dense runtime-size form: the
/// prior N(m₀, P₀) of x₀; K transitions xₖ₊₁ = Fₖ xₖ + bₖ + wₖ, wₖ ~ N(0, Qₖ) (bₖ = Bₖ uₖ);
/// K + 1 optional measurements zₖ = Hₖ xₖ + vₖ, vₖ ~ N(0, Rₖ).
pub(crate) struct BatchProblem {
    /// (m₀, P₀).
    pub prior: (DVector<f64>, DMatrix<f64>),
    /// (Fₖ, bₖ, Qₖ) for k = 0 … K − 1.
    pub transitions: Vec<(DMatrix<f64>, DVector<f64>, DMatrix<f64>)>,
    /// (Hₖ, Rₖ, zₖ) or `None` for k = 0 … K.
    pub measurements: Vec<Option<BatchMeasurement>>,
}

/// The exact joint posterior of X = (x₀, …, x_K) of a [`BatchProblem`].
pub(crate) struct BatchPosterior {
    /// E[X | z] = Λ⁻¹ η.
    pub mean: DVector<f64>,
    /// cov(X | z) = Λ⁻¹.
    pub covariance: DMatrix<f64>,
    /// κ₂(Λ) = λmax / λmin.
    pub condition: f64,
    /// ‖η‖₂, for the error bound of the mean: ‖ΔX‖ ≲ κ ε ‖Λ⁻¹‖ ‖η‖.
    pub rhs_norm: f64,
}

/// The joint posterior from the information form: Λ X = η with Λ = Σ Aᵀ W⁻¹ A over the prior
/// (A = [I, 0, …]), dynamics (A = [… −Fₖ, I …] on blocks k, k + 1) and measurement
/// (A = [… Hₖ …]) terms, η = Σ Aᵀ W⁻¹ (their right-hand sides); solved with nalgebra's dense
/// Cholesky of Λ: no recursion in time, nothing shared with the smoother.
pub(crate) fn batch_posterior(problem: &BatchProblem) -> BatchPosterior {
    let (m0, p0) = &problem.prior;
    let n = m0.len();
    let dim = n * problem.measurements.len();
    let mut info = DMatrix::zeros(dim, dim);
    let mut eta = DVector::zeros(dim);
    let mut add = |a: DMatrix<f64>, w: &DMatrix<f64>, rhs: &DVector<f64>| {
        let w_inv = w
            .clone()
            .cholesky()
            .expect("noise covariances are SPD")
            .inverse();
        info += a.transpose() * &w_inv * &a;
        eta += a.transpose() * &w_inv * rhs;
    };
    let mut a = DMatrix::zeros(n, dim);
    a.view_mut((0, 0), (n, n)).fill_with_identity();
    add(a, p0, m0);
    for (k, (f, b, q)) in problem.transitions.iter().enumerate() {
        let mut a = DMatrix::zeros(n, dim);
        a.view_mut((0, n * k), (n, n)).copy_from(&(-f));
        a.view_mut((0, n * k + n), (n, n)).fill_with_identity();
        add(a, q, b);
    }
    for (k, z) in problem.measurements.iter().enumerate() {
        if let Some((h, r, z)) = z {
            let mut a = DMatrix::zeros(h.nrows(), dim);
            a.view_mut((0, n * k), (h.nrows(), n)).copy_from(h);
            add(a, r, z);
        }
    }
    let eigen = SymmetricEigen::new(info.clone());
    let condition = eigen.eigenvalues.max() / eigen.eigenvalues.min();
    let covariance = info.cholesky().expect("Λ is SPD").inverse();
    BatchPosterior {
        mean: &covariance * &eta,
        covariance,
        condition,
        rhs_norm: eta.norm(),
    }
}

/// |a − b| ≤ tol · scale entrywise.
fn assert_close(a: &[f64], b: &[f64], tol: f64, what: &str) {
    let scale = b.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol * scale,
            "{what}[{i}]: {x} vs {y} (tolerance {:e})",
            tol * scale
        );
    }
}

/// KF, EKF and cubature-UKF RTS, full-covariance and square-root, on a linear-Gaussian system
/// equal the batch posterior: every smoothed mean and covariance block. Tolerance: backward-stable solves of both routes give
/// relative errors of order κ(Λ) ε times the number of operations along a chain; we allow
/// 100 K κ(Λ) ε (K = steps).
#[test]
fn rts_equals_the_batch_posterior_of_a_linear_gaussian_system() {
    let s = Scenario::new();
    let (mean, covariance, condition) = s.batch(true);
    let steps = s.dts.len() as f64;
    let tol = 100.0 * steps * condition * f64::EPSILON;
    assert!(tol < 1e-8, "the check would be too weak: κ = {condition:e}");
    let prior = || Gaussian::new(s.prior.0, s.prior.1).unwrap();
    let runs = [
        ("KF", s.smooth(KalmanFilter::new(prior()))),
        ("EKF", s.smooth(Ekf::new(prior()))),
        (
            "UKF",
            s.smooth(GaussianFilter::with_propagator(
                prior(),
                Unscented::cubature(),
            )),
        ),
        ("SR-KF", s.smooth(SrKalmanFilter::new(prior()))),
        ("SR-EKF", s.smooth(SrEkf::new(prior()))),
        (
            "SR-UKF",
            s.smooth(SrUkf::with_propagator(prior(), Unscented::cubature())),
        ),
    ];
    for (name, pass) in runs {
        let smoothed = &pass.estimates;
        assert_eq!(smoothed.len(), s.dts.len() + 1);
        assert_eq!(pass.cross_covariances.len(), s.dts.len());
        // Lag-one cross-covariances: the off-diagonal blocks cov(x_{k+1}, x_k) of Λ⁻¹.
        for (k, c) in pass.cross_covariances.iter().enumerate() {
            let block = covariance.view((2 * k + 2, 2 * k), (2, 2)).clone_owned();
            assert_close(
                c.as_slice(),
                block.as_slice(),
                tol,
                &format!("{name} cross {k}"),
            );
        }
        for (k, g) in smoothed.iter().enumerate() {
            let batch_mean = mean.rows(2 * k, 2);
            let batch_cov = covariance.view((2 * k, 2 * k), (2, 2)).clone_owned();
            assert_close(
                g.mean().as_slice(),
                batch_mean.as_slice(),
                tol,
                &format!("{name} mean {k}"),
            );
            assert_close(
                g.covariance().as_slice(),
                batch_cov.as_slice(),
                tol,
                &format!("{name} cov {k}"),
            );
        }
    }
}

/// The smoother also runs on runtime sizes, to the same answer.
#[test]
fn rts_on_runtime_sizes_matches_static_sizes() {
    let s = Scenario::new();
    let smoothed = s
        .smooth(KalmanFilter::new(
            Gaussian::new(s.prior.0, s.prior.1).unwrap(),
        ))
        .estimates;
    let to_dyn = |m: &Matrix2<f64>| DMatrix::from_column_slice(2, 2, m.as_slice());
    let mut kf = KalmanFilter::<f64, Dyn>::new(
        Gaussian::new(
            DVector::from_column_slice(s.prior.0.as_slice()),
            to_dyn(&s.prior.1),
        )
        .unwrap(),
    );
    let sensor = LinearMeasurement {
        observation: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        noise: DMatrix::from_element(1, 1, s.r),
    };
    let mut rts = Rts::new();
    for k in 0..=s.dts.len() {
        if k > 0 {
            let p = Scenario::process(s.dts[k - 1]);
            let process = LinearProcess {
                transition: to_dyn(&p.transition),
                input: DMatrix::from_column_slice(2, 1, p.input.as_slice()),
                noise: to_dyn(&p.noise),
            };
            let u = DVector::from_element(1, s.inputs[k - 1]);
            rts.predict(&mut kf, &process, &u, s.dts[k - 1]).unwrap();
        }
        if let Some(z) = s.measurements[k] {
            kf.update(&sensor, &DVector::from_element(1, z)).unwrap();
        }
    }
    let dynamic = rts.smooth(&kf).unwrap();
    for (a, b) in smoothed.iter().zip(&dynamic) {
        assert_close(b.mean().as_slice(), a.mean().as_slice(), 1e-12, "mean");
        assert_close(
            b.covariance().as_slice(),
            a.covariance().as_slice(),
            1e-12,
            "covariance",
        );
    }
}

/// A predicted covariance that is not positive definite is reported with the index of the
/// estimate being smoothed, and the record is left as it was (smoothing again fails the same).
#[test]
fn an_indefinite_prediction_is_a_typed_error_naming_the_step() {
    let s = Scenario::new();
    let mut kf = KalmanFilter::new(Gaussian::new(s.prior.0, s.prior.1).unwrap());
    let mut rts = Rts::new();
    let u = Vector1::new(0.0);
    rts.predict(&mut kf, &Scenario::process(0.5), &u, 0.5)
        .unwrap();
    // A singular step: F = [[1, 0], [1, 0]] and Q = 0 make P⁻ singular along state 1 with
    // both variances positive (no fixed state to set aside).
    let collapse = LinearProcess {
        transition: Matrix2::new(1.0, 0.0, 1.0, 0.0),
        input: Matrix2x1::zeros(),
        noise: Matrix2::zeros(),
    };
    rts.predict(&mut kf, &collapse, &u, 0.5).unwrap();
    rts.predict(&mut kf, &Scenario::process(0.5), &u, 0.5)
        .unwrap();
    let expected = SmootherError {
        step: 1,
        error: Error::NotPositiveDefinite {
            stage: Stage::Smoothing,
            quantity: Quantity::Covariance,
        },
        state: Some(1),
    };
    assert!(expected.to_string().contains("at state 1"));
    assert_eq!(rts.smooth(&kf).unwrap_err(), expected);
    assert_eq!(rts.smooth(&kf).unwrap_err(), expected);
    assert_eq!(rts.len(), 3);
}

/// The fixed-lag smoother: at every time t its first estimate equals the full RTS over the
/// data up to t at time t − L (the same arithmetic on the same records, so bit for bit), and
/// it never holds more than L records; with L at least the sequence length it is the full RTS.
#[test]
fn fixed_lag_equals_rts_over_the_data_so_far_with_bounded_memory() {
    let s = Scenario::new();
    let sensor = s.sensor();
    let lag = 3;
    let prior = Gaussian::new(s.prior.0, s.prior.1).unwrap();
    let (mut kf, mut lagged, mut long, mut full) = (
        KalmanFilter::new(prior),
        Rts::with_lag(lag),
        Rts::with_lag(100),
        Rts::new(),
    );
    let mut kf_full = kf.clone();
    for k in 0..=s.dts.len() {
        if k > 0 {
            let process = Scenario::process(s.dts[k - 1]);
            let u = Vector1::new(s.inputs[k - 1]);
            let mut kf_long = kf.clone();
            lagged.predict(&mut kf, &process, &u, s.dts[k - 1]).unwrap();
            long.predict(&mut kf_long, &process, &u, s.dts[k - 1])
                .unwrap();
            full.predict(&mut kf_full, &process, &u, s.dts[k - 1])
                .unwrap();
        }
        if let Some(z) = s.measurements[k] {
            kf.update(&sensor, &Vector1::new(z)).unwrap();
            kf_full.update(&sensor, &Vector1::new(z)).unwrap();
        }
        assert!(lagged.len() <= lag);
        let window = lagged.smooth(&kf).unwrap();
        let everything = full.smooth(&kf_full).unwrap();
        assert_eq!(window.len(), k.min(lag) + 1);
        assert_eq!(window[0], everything[k - k.min(lag)], "t = {k}");
        assert_eq!(long.smooth(&kf).unwrap(), everything, "t = {k}");
    }
}

/// The batch API on a constant-Δt version of the scenario: `smooth_sequence` equals the batch
/// posterior, and `filter_sequence`'s log-likelihood equals the marginal likelihood of the
/// stacked measurements, N(z; Φ m, Φ Σ Φᵀ + r I) with (m, Σ) the joint prior of the states
/// (the information form without the measurement terms).
#[test]
fn sequences_match_the_batch_posterior_and_the_marginal_likelihood() {
    let mut s = Scenario::new();
    s.dts = vec![0.5; s.dts.len()];
    let process = Scenario::process(0.5);
    let inputs: Vec<_> = s.inputs.iter().map(|&u| Vector1::new(u)).collect();
    let zs: Vec<_> = s.measurements.iter().map(|z| z.map(Vector1::new)).collect();
    let prior = Gaussian::new(s.prior.0, s.prior.1).unwrap();

    let (mean, covariance, condition) = s.batch(true);
    let tol = 100.0 * s.dts.len() as f64 * condition * f64::EPSILON;
    let mut kf = KalmanFilter::new(prior.clone());
    let smoothed = smooth_sequence(&mut kf, &process, &inputs, 0.5, &s.sensor(), &zs).unwrap();
    let mut kf = KalmanFilter::new(prior.clone());
    let (with_cross, cross) =
        smooth_sequence_with_cross_covariances(&mut kf, &process, &inputs, 0.5, &s.sensor(), &zs)
            .unwrap();
    assert_eq!(with_cross, smoothed);
    assert_eq!(cross.len(), s.dts.len());
    for (k, c) in cross.iter().enumerate() {
        let block = covariance.view((2 * k + 2, 2 * k), (2, 2)).clone_owned();
        assert_close(c.as_slice(), block.as_slice(), tol, "cross");
    }
    for (k, g) in smoothed.estimates.iter().enumerate() {
        assert_close(
            g.mean().as_slice(),
            mean.rows(2 * k, 2).as_slice(),
            tol,
            "mean",
        );
        let block = covariance.view((2 * k, 2 * k), (2, 2)).clone_owned();
        assert_close(
            g.covariance().as_slice(),
            block.as_slice(),
            tol,
            "covariance",
        );
    }

    // The sequence functions take any filter that can be smoothed: the square-root KF too.
    let mut sr = SrKalmanFilter::new(prior.clone());
    let sr_smoothed = smooth_sequence(&mut sr, &process, &inputs, 0.5, &s.sensor(), &zs).unwrap();
    for (k, g) in sr_smoothed.estimates.iter().enumerate() {
        let block = covariance.view((2 * k, 2 * k), (2, 2)).clone_owned();
        let batch_mean = mean.rows(2 * k, 2);
        assert_close(g.mean().as_slice(), batch_mean.as_slice(), tol, "SR mean");
        assert_close(g.covariance().as_slice(), block.as_slice(), tol, "SR cov");
    }

    let (prior_mean, prior_cov, prior_condition) = s.batch(false);
    let measured: Vec<usize> = (0..zs.len()).filter(|&k| zs[k].is_some()).collect();
    let m = measured.len();
    let phi = DMatrix::from_fn(m, prior_mean.len(), |i, j| f64::from(j == 2 * measured[i]));
    let z = DVector::from_iterator(m, measured.iter().map(|&k| s.measurements[k].unwrap()));
    let cov_z = &phi * &prior_cov * phi.transpose() + DMatrix::identity(m, m) * s.r;
    let residual = z - &phi * &prior_mean;
    let chol = cov_z.clone().cholesky().unwrap();
    let quadratic = residual.dot(&chol.solve(&residual));
    let log_det = 2.0 * chol.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
    let expected = -0.5 * (quadratic + log_det + m as f64 * (2.0 * std::f64::consts::PI).ln());

    let mut kf = KalmanFilter::new(prior);
    let run = filter_sequence(&mut kf, &process, &inputs, 0.5, &s.sensor(), &zs).unwrap();
    let tol = 100.0 * s.dts.len() as f64 * prior_condition * f64::EPSILON;
    assert!(
        tol < 1e-6,
        "the check would be too weak: κ = {prior_condition:e}"
    );
    assert_close(&[run.log_likelihood], &[expected], tol, "log-likelihood");
    let mut sr = SrKalmanFilter::new(Gaussian::new(s.prior.0, s.prior.1).unwrap());
    let sr_run = filter_sequence(&mut sr, &process, &inputs, 0.5, &s.sensor(), &zs).unwrap();
    assert_close(
        &[sr_run.log_likelihood],
        &[expected],
        tol,
        "SR log-likelihood",
    );
    assert_eq!(run.updates.iter().filter(|u| u.is_none()).count(), 4);
    // The filtered estimates are the smoother's forward pass: the last ones agree.
    assert_eq!(run.estimates.last(), smoothed.estimates.last());
}

/// Consistency over a Monte Carlo run of the time-varying scenario (truth simulated with the
/// model's own noise, seeded): at every time the average smoothed NEES over 300 runs lies in
/// its two-sided χ² band (99.9 % each, so the family of 13 times fails by chance with
/// probability ≈ 1.3 %; the seed is fixed, so the test is deterministic), and the smoothed
/// covariance is below the filtered one (Pᶠ − Pˢ positive semi-definite) at every time.
#[test]
fn smoothed_nees_is_in_its_chi_square_band_and_smoothing_only_shrinks_covariances() {
    use estim_filters::consistency::ChiSquareBand;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    let s = Scenario::new();
    let runs = 300;
    let times = s.dts.len() + 1;
    let mut rng = StdRng::seed_from_u64(17);
    let normal2 =
        |rng: &mut StdRng| Vector2::new(rng.sample(StandardNormal), rng.sample(StandardNormal));
    let mut nees = vec![0.0; times];
    for _ in 0..runs {
        // Truth: x₀ ~ N(m₀, P₀), x_{k+1} = F x_k + B u + w, z_k = x_k[0] + v.
        let l0 = s.prior.1.cholesky().unwrap().l();
        let mut truth = vec![s.prior.0 + l0 * normal2(&mut rng)];
        for k in 0..s.dts.len() {
            let p = Scenario::process(s.dts[k]);
            let lq = p.noise.cholesky().unwrap().l();
            let next = p.transition * truth[k] + p.input * s.inputs[k] + lq * normal2(&mut rng);
            truth.push(next);
        }
        let mut run = Scenario {
            measurements: s.measurements.clone(),
            ..Scenario::new()
        };
        for (k, z) in run.measurements.iter_mut().enumerate() {
            if z.is_some() {
                let v: f64 = rng.sample(StandardNormal);
                *z = Some(truth[k][0] + s.r.sqrt() * v);
            }
        }
        let smoothed = run
            .smooth(KalmanFilter::new(
                Gaussian::new(s.prior.0, s.prior.1).unwrap(),
            ))
            .estimates;
        for (k, g) in smoothed.iter().enumerate() {
            let e = truth[k] - g.mean();
            nees[k] += (e.transpose() * g.covariance().try_inverse().unwrap() * e)[0] / runs as f64;
        }
    }
    let band = ChiSquareBand::two_sided(2, runs, 0.999).unwrap();
    for (k, &average) in nees.iter().enumerate() {
        assert!(
            band.contains(average),
            "time {k}: average NEES {average} outside {band:?}"
        );
    }

    // Smoothing never adds uncertainty: the filtered covariances from the same forward pass.
    let mut kf = KalmanFilter::new(Gaussian::new(s.prior.0, s.prior.1).unwrap());
    let mut rts = Rts::new();
    let mut filtered = Vec::new();
    for k in 0..times {
        if k > 0 {
            let u = Vector1::new(s.inputs[k - 1]);
            rts.predict(&mut kf, &Scenario::process(s.dts[k - 1]), &u, s.dts[k - 1])
                .unwrap();
        }
        if let Some(z) = s.measurements[k] {
            kf.update(&s.sensor(), &Vector1::new(z)).unwrap();
        }
        filtered.push(*estim_filters::Estimator::covariance(&kf));
    }
    for (k, (pf, g)) in filtered.iter().zip(rts.smooth(&kf).unwrap()).enumerate() {
        let shrink = SymmetricEigen::new(pf - g.covariance()).eigenvalues.min();
        assert!(
            shrink >= -1e-12 * pf.norm(),
            "time {k}: Pᶠ − Pˢ has eigenvalue {shrink}"
        );
    }
}

/// A fixed offset b (zero prior variance, no process noise) in z = position + b used to fail
/// the backward pass (P⁻ singular along b). It is smoothed as a constant of the model: the
/// position and velocity equal the smoothed 2-state model fed z − b, and b keeps its value and
/// zero variance. Tolerance: the two routes differ only by exact zeros in the forward pass and
/// by the Cholesky code of the backward gain (the plain one against the fixed-state one), so
/// round-off of a few ε on O(1) moments; 1e-10 leaves a wide margin.
#[test]
fn a_fixed_state_is_smoothed_as_a_constant() {
    use estim_core::nalgebra::{Matrix1x3, Matrix3, Matrix3x1, Vector3};
    let offset = 0.7;
    let with_offset = LinearProcess {
        transition: Matrix3::new(1.0, 0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        input: Matrix3x1::zeros(),
        noise: Matrix3::new(1e-3, 0.0, 0.0, 0.0, 1e-2, 0.0, 0.0, 0.0, 0.0),
    };
    let sensor3 = LinearMeasurement {
        observation: Matrix1x3::new(1.0, 0.0, 1.0),
        noise: Matrix1::new(0.2),
    };
    let prior3 = Gaussian::new(
        Vector3::new(0.0, 1.0, offset),
        Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0),
    )
    .unwrap();
    let without = LinearProcess {
        transition: Matrix2::new(1.0, 0.5, 0.0, 1.0),
        input: Matrix2x1::zeros(),
        noise: Matrix2::new(1e-3, 0.0, 0.0, 1e-2),
    };
    let sensor2 = LinearMeasurement {
        observation: Matrix1x2::new(1.0, 0.0),
        noise: Matrix1::new(0.2),
    };
    let prior2 = Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::new(1.0, 0.0, 0.0, 0.5)).unwrap();
    let zs: Vec<f64> = (0..12)
        .map(|k| 0.5 * k as f64 + offset + 0.1 * (k % 3) as f64)
        .collect();
    let z3: Vec<_> = zs.iter().map(|&z| Some(Vector1::new(z))).collect();
    let z2: Vec<_> = zs.iter().map(|&z| Some(Vector1::new(z - offset))).collect();
    let run3 = smooth_sequence(
        &mut KalmanFilter::new(prior3),
        &with_offset,
        &[Vector1::zeros(); 11],
        0.5,
        &sensor3,
        &z3,
    )
    .unwrap();
    let run2 = smooth_sequence(
        &mut KalmanFilter::new(prior2),
        &without,
        &[Vector1::zeros(); 11],
        0.5,
        &sensor2,
        &z2,
    )
    .unwrap();
    for (a, b) in run3.estimates.iter().zip(&run2.estimates) {
        let (x, p) = (a.mean(), a.covariance());
        assert_close(&[x[0], x[1]], b.mean().as_slice(), 1e-10, "mean");
        let block = [p[(0, 0)], p[(1, 0)], p[(0, 1)], p[(1, 1)]];
        assert_close(&block, b.covariance().as_slice(), 1e-10, "covariance");
        assert_eq!((x[2], p[(2, 2)]), (offset, 0.0));
    }
}
