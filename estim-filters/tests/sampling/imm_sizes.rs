//! Modes of different state sizes (`imm::embed`): a constant-velocity (4-state) mode inside
//! a constant-acceleration (6-state) IMM against an independent route, the equal-size IMM in
//! which the CV mode is written by hand as a 6-state model with zero acceleration rows; one
//! embedded mode against its filter; bad maps; checkpoints, the fusion driver and the
//! smoother.

use estim_core::adapter::NoInput;
use estim_core::nalgebra::{
    DMatrix, DVector, Dyn, Matrix2, Matrix2x6, Matrix4, Matrix6, U2, U4, U6, Vector2, Vector4,
    Vector6,
};
use estim_core::{Error, Gaussian, LinearMeasurement, LinearProcess, Quantity};
use estim_filters::imm::{Embedded, EmbeddedModes, Imm, ImmSmoother, StateMap};
use estim_filters::{Estimator, KalmanFilter, Predict, Rollback, Update};

use crate::common::{assert_bitwise_eq, normal, rng};
use crate::imm::{DT, cv, position, prior, u0};

type Model<N> = NoInput<LinearProcess<f64, N, estim_core::nalgebra::U0>>;
type Cv4 = Model<U4>;
type Ca6 = Model<U6>;
type Sensor = LinearMeasurement<f64, U6, U2>;
type Modes = EmbeddedModes<(
    Embedded<f64, U4, U6, KalmanFilter<f64, U4>>,
    Embedded<f64, U6, U6, KalmanFilter<f64, U6>>,
)>;

type SixStates = (KalmanFilter<f64, U6>, KalmanFilter<f64, U6>);

/// The default variance of the CV mode's accelerations when lifted.
const SIGMA2: f64 = 0.3;
const Q_CV: f64 = 0.01;
const Q_CA: f64 = 0.5;

/// One axis of constant velocity, [p, v], white-acceleration noise (Bar-Shalom §6.3.2).
fn cv_axis() -> (Matrix2<f64>, Matrix2<f64>) {
    let f = Matrix2::new(1.0, DT, 0.0, 1.0);
    let q = Matrix2::new(DT.powi(3) / 3.0, DT * DT / 2.0, DT * DT / 2.0, DT) * Q_CV;
    (f, q)
}

/// [px, vx, py, vy].
fn cv4() -> Cv4 {
    let (f, q) = cv_axis();
    let mut f4 = Matrix4::zeros();
    let mut q4 = Matrix4::zeros();
    for k in [0, 2] {
        f4.fixed_view_mut::<2, 2>(k, k).copy_from(&f);
        q4.fixed_view_mut::<2, 2>(k, k).copy_from(&q);
    }
    LinearProcess::without_input(f4, q4)
}

/// [px, vx, ax, py, vy, ay], white-jerk noise (Bar-Shalom §6.3.3).
fn ca6() -> Ca6 {
    let f = estim_core::nalgebra::Matrix3::new(1.0, DT, DT * DT / 2.0, 0.0, 1.0, DT, 0.0, 0.0, 1.0);
    let (t2, t3, t4, t5) = (DT.powi(2), DT.powi(3), DT.powi(4), DT.powi(5));
    let q = estim_core::nalgebra::Matrix3::new(
        t5 / 20.0,
        t4 / 8.0,
        t3 / 6.0,
        t4 / 8.0,
        t3 / 3.0,
        t2 / 2.0,
        t3 / 6.0,
        t2 / 2.0,
        DT,
    ) * Q_CA;
    let mut f6 = Matrix6::zeros();
    let mut q6 = Matrix6::zeros();
    for k in [0, 3] {
        f6.fixed_view_mut::<3, 3>(k, k).copy_from(&f);
        q6.fixed_view_mut::<3, 3>(k, k).copy_from(&q);
    }
    LinearProcess::without_input(f6, q6)
}

/// The CV model written by hand in the 6-state space: the CV blocks on [p, v], zero rows and
/// columns for a, and a ~ N(0, σ²) after each step (σ² as process noise on a).
fn cv6_by_hand() -> Ca6 {
    let (f, q) = cv_axis();
    #[rustfmt::skip]
    let f6 = Matrix6::new(
        f[(0, 0)], f[(0, 1)], 0.0, 0.0, 0.0, 0.0,
        f[(1, 0)], f[(1, 1)], 0.0, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, f[(0, 0)], f[(0, 1)], 0.0,
        0.0, 0.0, 0.0, f[(1, 0)], f[(1, 1)], 0.0,
        0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    );
    #[rustfmt::skip]
    let q6 = Matrix6::new(
        q[(0, 0)], q[(0, 1)], 0.0, 0.0, 0.0, 0.0,
        q[(1, 0)], q[(1, 1)], 0.0, 0.0, 0.0, 0.0,
        0.0, 0.0, SIGMA2, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, q[(0, 0)], q[(0, 1)], 0.0,
        0.0, 0.0, 0.0, q[(1, 0)], q[(1, 1)], 0.0,
        0.0, 0.0, 0.0, 0.0, 0.0, SIGMA2,
    );
    LinearProcess::without_input(f6, q6)
}

fn sensor() -> Sensor {
    #[rustfmt::skip]
    let h = Matrix2x6::new(
        1.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 1.0, 0.0, 0.0,
    );
    LinearMeasurement {
        observation: h,
        noise: Matrix2::identity() * 0.5,
    }
}

fn cv_map() -> StateMap<f64, U4, U6> {
    let variance = Vector6::new(0.0, 0.0, SIGMA2, 0.0, 0.0, SIGMA2);
    StateMap::new(&[0, 1, 3, 4], Vector6::zeros(), variance).unwrap()
}

fn pi() -> DMatrix<f64> {
    DMatrix::from_row_slice(2, 2, &[0.9, 0.1, 0.2, 0.8])
}

fn mu0() -> DVector<f64> {
    DVector::from_vec(vec![0.7, 0.3])
}

fn embedded_imm() -> Imm<f64, U6, Modes> {
    let cv_prior = Gaussian::new(
        Vector4::new(0.0, 1.0, 0.0, 0.5),
        Matrix4::from_diagonal(&Vector4::new(4.0, 1.0, 4.0, 1.0)),
    )
    .unwrap();
    let ca_prior = Gaussian::new(
        Vector6::new(0.0, 1.0, 0.0, 0.0, 0.5, 0.0),
        Matrix6::from_diagonal(&Vector6::new(4.0, 1.0, 1.0, 4.0, 1.0, 1.0)),
    )
    .unwrap();
    let modes = EmbeddedModes((
        Embedded::new(KalmanFilter::new(cv_prior), cv_map()).unwrap(),
        Embedded::new(KalmanFilter::new(ca_prior), StateMap::identity(U6)).unwrap(),
    ));
    Imm::new(modes, pi(), mu0()).unwrap()
}

/// The independent route: an equal-size IMM of two 6-state KFs, the CV mode's prior written
/// out with the accelerations at their default N(0, σ²) (its model is [`cv6_by_hand`]).
fn reference_imm() -> Imm<f64, U6, SixStates> {
    let cv6_prior = Gaussian::new(
        Vector6::new(0.0, 1.0, 0.0, 0.0, 0.5, 0.0),
        Matrix6::from_diagonal(&Vector6::new(4.0, 1.0, SIGMA2, 4.0, 1.0, SIGMA2)),
    )
    .unwrap();
    let ca_prior = embedded_imm().modes().0.1.filter().estimate();
    let modes = (KalmanFilter::new(cv6_prior), KalmanFilter::new(ca_prior));
    Imm::new(modes, pi(), mu0()).unwrap()
}

/// A target straight at (1, 0.5) per step, then accelerating at (0.4, −0.3) from step 12,
/// positions with noise variance 0.5 (seeded).
fn readings(seed: u64, steps: usize) -> Vec<Vector2<f64>> {
    let mut g = rng(seed);
    let (mut p, mut v) = (Vector2::zeros(), Vector2::new(1.0, 0.5));
    (0..steps)
        .map(|k| {
            if k >= 12 {
                v += Vector2::new(0.4, -0.3) * DT;
            }
            p += v * DT;
            p + Vector2::new(normal(&mut g), normal(&mut g)) * 0.5_f64.sqrt()
        })
        .collect()
}

#[test]
fn a_cv_mode_inside_a_ca_imm_is_the_hand_written_six_state_cv_with_zero_acceleration_rows() {
    let (mut embedded, mut reference) = (embedded_imm(), reference_imm());
    assert_bitwise_eq(embedded.state(), reference.state(), "combined prior");
    let (models, models6) = ((cv4(), ca6()), (cv6_by_hand(), ca6()));
    let sensor = sensor();
    let (mut mixed, mut worst, mut mu_ca) = (false, 0.0_f64, Vec::new());
    for z in readings(37, 24) {
        embedded.predict_modes(&models, &(), DT).unwrap();
        reference.predict_modes(&models6, &(), DT).unwrap();
        let a = embedded.update_modes(&sensor, &z).unwrap();
        let b = reference.update_modes(&sensor, &z).unwrap();
        let scale = reference.covariance().amax().max(reference.state().amax());
        worst = worst
            .max((embedded.state() - reference.state()).amax() / scale)
            .max((embedded.covariance() - reference.covariance()).amax() / scale)
            .max((embedded.probabilities() - reference.probabilities()).amax())
            .max((a.log_likelihood - b.log_likelihood).abs() / b.log_likelihood.abs().max(1.0));
        // The CV mode's own 4-state estimate is the reference's [p, v] block, its lifted
        // accelerations the defaults (0, σ²) exactly: nothing ever moves them there.
        let cv = embedded.modes().0.0.filter();
        let cv6 = reference.modes().0.state();
        for (a, &i) in [0, 1, 3, 4].iter().enumerate() {
            assert!((cv.state()[a] - cv6[i]).abs() <= 1e-12 * scale);
        }
        let lifted = embedded.modes().0.0.covariance();
        assert_eq!(
            (lifted[(2, 2)], lifted[(5, 5)], lifted[(0, 2)]),
            (SIGMA2, SIGMA2, 0.0)
        );
        let mu = embedded.probabilities()[1];
        mixed |= mu > 0.05 && mu < 0.95;
        mu_ca.push(mu);
    }
    // The same algorithm through different matrix sizes: every extra term of the 6-state CV
    // (zero rows, zero cross-covariances) is an exact zero, so the runs are bit-identical
    // here (measured 0). Not asserted bitwise: nalgebra's size-specialised products may sum
    // in another order on other targets; 1e-12 is a few hundred ulps of round-off over 24
    // steps of 6 × 6 products, mixtures and exp/ln of the mode likelihoods.
    assert!(worst < 1e-12, "largest relative difference {worst:e}");
    // The run exercises mixing both ways (μ neither 0 nor 1), and the CA mode is more
    // probable while the target accelerates (readings 13 on) than on the straight leg after
    // the prior's influence (readings 5–12): measured means 0.33 and 0.11. (Not near 1:
    // mixing hands the CV mode the CA mode's velocity every step, so CV's one-step error is
    // only a Δt²/2 ≈ 0.25, under the reading noise's σ ≈ 0.7.)
    assert!(mixed);
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let (straight, accelerating) = (mean(&mu_ca[4..12]), mean(&mu_ca[12..]));
    assert!(
        accelerating > 2.0 * straight,
        "μ_CA {straight} then {accelerating}"
    );
}

#[test]
fn one_embedded_mode_with_the_identity_map_is_that_filter_bit_for_bit() {
    let (process, sensor) = (cv(0.1), position(0.5));
    let mut kf = KalmanFilter::new(prior());
    let mode = Embedded::new(KalmanFilter::new(prior()), StateMap::identity(U2)).unwrap();
    let mut imm = Imm::new(
        EmbeddedModes((mode,)),
        DMatrix::identity(1, 1),
        DVector::from_element(1, 1.0),
    )
    .unwrap();
    let mut g = rng(5);
    for k in 1..=15 {
        let z = estim_core::nalgebra::Vector1::new(k as f64 * DT + normal(&mut g));
        kf.predict(&process, &u0(), DT).unwrap();
        imm.predict_modes(&(process.clone(),), &u0(), DT).unwrap();
        let expected = kf.update(&sensor, &z).unwrap();
        let report = imm.update_modes(&sensor, &z).unwrap();
        assert_bitwise_eq(imm.state(), kf.state(), "state");
        assert_bitwise_eq(imm.covariance(), kf.covariance(), "covariance");
        assert_eq!(report.innovation, expected.innovation);
        assert_eq!(
            report.log_likelihood.to_bits(),
            expected.log_likelihood.to_bits()
        );
    }
}

#[test]
fn bad_maps_and_sizes_are_typed_errors_and_a_failed_step_changes_nothing() {
    let map_error = |e: Result<StateMap<f64, U4, U6>, Error>| match e {
        Err(Error::DimensionMismatch {
            quantity: Quantity::StateMap,
            expected_rows,
            found_rows,
            ..
        }) => (expected_rows, found_rows),
        other => panic!("not a state-map size error: {other:?}"),
    };
    let (zeros, ones) = (Vector6::zeros(), Vector6::repeat(1.0));
    // A map of the wrong size: three places for a 4-state mode, or a place outside the
    // 6-state common state, or a place twice.
    assert_eq!(map_error(StateMap::new(&[0, 1, 3], zeros, ones)), (4, 3));
    assert_eq!(map_error(StateMap::new(&[0, 1, 3, 6], zeros, ones)), (6, 7));
    assert_eq!(map_error(StateMap::new(&[0, 1, 3, 3], zeros, ones)), (4, 3));
    assert!(matches!(
        StateMap::<f64, U4, U6>::new(&[0, 1, 3, 4], zeros, Vector6::repeat(-1.0)),
        Err(Error::NotPositiveSemiDefinite {
            quantity: Quantity::StateMap,
            ..
        })
    ));
    assert!(matches!(
        StateMap::<f64, U4, U6>::new(&[0, 1, 3, 4], Vector6::repeat(f64::NAN), ones),
        Err(Error::NonFinite {
            quantity: Quantity::StateMap,
            ..
        })
    ));
    // Runtime sizes: default mean and variance of different lengths; a filter the map does
    // not fit; modes whose common states differ (no common space to mix in).
    assert!(matches!(
        StateMap::<f64, Dyn, Dyn>::new(&[0], DVector::zeros(3), DVector::zeros(2)),
        Err(Error::DimensionMismatch {
            quantity: Quantity::StateMap,
            ..
        })
    ));
    let dyn_kf =
        |n| KalmanFilter::new(Gaussian::new(DVector::zeros(n), DMatrix::identity(n, n)).unwrap());
    let into = |n, places: &[usize]| {
        StateMap::<f64, Dyn, Dyn>::new(places, DVector::zeros(n), DVector::repeat(n, 1.0)).unwrap()
    };
    assert!(matches!(
        Embedded::new(dyn_kf(3), into(4, &[0, 1])),
        Err(Error::DimensionMismatch {
            quantity: Quantity::StateMap,
            expected_rows: 2,
            found_rows: 3,
            ..
        })
    ));
    let modes = EmbeddedModes((
        Embedded::new(dyn_kf(2), into(4, &[0, 2])).unwrap(),
        Embedded::new(dyn_kf(2), into(5, &[0, 2])).unwrap(),
    ));
    assert!(matches!(
        Imm::new(modes, pi(), mu0()),
        Err(Error::DimensionMismatch {
            quantity: Quantity::Mean,
            expected_rows: 4,
            found_rows: 5,
            ..
        })
    ));
    // A CA model with a NaN in Q fails the prediction after the CV mode has predicted and
    // both have been mixed: every mode and μ are as before.
    let mut imm = embedded_imm();
    let sensor = sensor();
    for z in readings(3, 14) {
        imm.predict_modes(&(cv4(), ca6()), &(), DT).unwrap();
        imm.update_modes(&sensor, &z).unwrap();
    }
    let before = imm.snapshot();
    let cv_mode = &imm.modes().0.0;
    let lifted = (*cv_mode.state(), *cv_mode.covariance());
    let mut bad = ca6();
    bad.0.noise[(0, 0)] = f64::NAN;
    assert!(imm.predict_modes(&(cv4(), bad), &(), DT).is_err());
    assert_eq!(imm.snapshot(), before);
    // The lifted estimates the IMM mixes from are restored with the filters.
    assert_bitwise_eq(imm.modes().0.0.state(), &lifted.0, "lifted CV state");
    assert_bitwise_eq(
        imm.modes().0.0.covariance(),
        &lifted.1,
        "lifted CV covariance",
    );
}

/// The CV/CA models as one model of the `Predict` trait (the fusion driver's process).
#[derive(Clone, Debug)]
struct CvCa((Cv4, Ca6));

impl estim_filters::ProcessInput<f64, U6> for CvCa {
    type Input = ();
}

impl estim_filters::imm::ModeModels for CvCa {
    type Models = (Cv4, Ca6);
    fn models(&self) -> &(Cv4, Ca6) {
        &self.0
    }
}

mod in_the_fusion_driver {
    use super::*;
    use estim_core::error::Result;
    use estim_filters::fusion::{
        FusionDriver, FusionSettings, Innovation, SensorSet, SensorSettings,
    };

    struct Fix(Sensor);

    impl SensorSet<f64, U6, Imm<f64, U6, Modes>> for Fix {
        type Reading = Vector2<f64>;
        fn count(&self) -> usize {
            1
        }
        fn sensor(&self, _: &Vector2<f64>) -> usize {
            0
        }
        fn dimension(&self, _: usize) -> usize {
            2
        }
        fn update(
            &self,
            imm: &mut Imm<f64, U6, Modes>,
            z: &Vector2<f64>,
        ) -> Result<Innovation<f64>> {
            imm.update(&self.0, z).map(|r| Innovation::of(&r))
        }
    }

    fn driver() -> FusionDriver<f64, U6, Imm<f64, U6, Modes>, CvCa, Fix> {
        let settings = FusionSettings {
            horizon: 5.0,
            max_step: DT,
            ..FusionSettings::default()
        };
        FusionDriver::new(
            embedded_imm(),
            CvCa((cv4(), ca6())),
            (),
            Fix(sensor()),
            0.0,
            settings,
            SensorSettings::default(),
        )
        .unwrap()
    }

    #[test]
    fn a_late_measurement_rolls_back_the_mixed_size_modes_bit_identically() {
        let zs = readings(11, 16);
        let mut ordered = driver();
        for (k, z) in zs.iter().enumerate() {
            ordered.fuse((k + 1) as f64 * DT, *z).unwrap();
        }
        // The thirteenth reading (just after the acceleration starts) three steps late.
        let mut late = driver();
        let mut order: Vec<usize> = (0..16).collect();
        order.remove(12);
        order.insert(15, 12);
        let mut replayed = 0;
        for &k in &order {
            replayed += late.fuse((k + 1) as f64 * DT, zs[k]).unwrap().replayed;
        }
        assert!(replayed > 0);
        let (a, b) = (ordered.filter().snapshot(), late.filter().snapshot());
        assert_bitwise_eq(a.probabilities(), b.probabilities(), "μ after the replay");
        assert_bitwise_eq(a.state(), b.state(), "state after the replay");
        assert_bitwise_eq(
            a.covariance(),
            b.covariance(),
            "covariance after the replay",
        );
        assert_eq!(a, b);
    }
}

#[cfg(feature = "serde")]
#[test]
fn a_checkpoint_resumes_bit_for_bit_and_an_edited_map_is_refused() {
    let mut imm = embedded_imm();
    let (models, sensor) = ((cv4(), ca6()), sensor());
    let zs = readings(21, 16);
    let step = |imm: &mut Imm<f64, U6, Modes>, z: &Vector2<f64>| {
        imm.predict_modes(&models, &(), DT).unwrap();
        imm.update_modes(&sensor, z).unwrap();
    };
    for z in &zs[..10] {
        step(&mut imm, z);
    }
    let saved = serde_json::to_string(&imm).unwrap();
    let mut resumed: Imm<f64, U6, Modes> = serde_json::from_str(&saved).unwrap();
    assert_eq!(resumed.snapshot(), imm.snapshot());
    for z in &zs[10..] {
        step(&mut imm, z);
        step(&mut resumed, z);
        assert_bitwise_eq(resumed.state(), imm.state(), "resumed state");
        assert_bitwise_eq(resumed.covariance(), imm.covariance(), "resumed covariance");
        assert_bitwise_eq(resumed.probabilities(), imm.probabilities(), "resumed μ");
    }
    // A place repeated, a place dropped: refused by the map's own checks.
    for edit in ["\"places\":[0,1,3,3]", "\"places\":[0,1,3]"] {
        let edited = saved.replacen("\"places\":[0,1,3,4]", edit, 1);
        assert_ne!(edited, saved);
        assert!(serde_json::from_str::<Imm<f64, U6, Modes>>(&edited).is_err());
    }
}

#[test]
fn the_smoother_over_a_cv_mode_inside_a_ca_imm_is_the_hand_written_six_state_ones() {
    let (mut embedded, mut reference) = (embedded_imm(), reference_imm());
    let (models, models6) = ((cv4(), ca6()), (cv6_by_hand(), ca6()));
    let sensor = sensor();
    let (mut smoother, mut smoother6) = (ImmSmoother::new(), ImmSmoother::new());
    for z in readings(37, 24) {
        smoother.predict(&mut embedded, &models, &(), DT).unwrap();
        smoother6
            .predict(&mut reference, &models6, &(), DT)
            .unwrap();
        embedded.update_modes(&sensor, &z).unwrap();
        reference.update_modes(&sensor, &z).unwrap();
    }
    let (a, b) = (
        smoother.smooth(&embedded).unwrap(),
        smoother6.smooth(&reference).unwrap(),
    );
    assert_eq!(a.len(), b.len());
    let mut worst = 0.0_f64;
    for (a, b) in a.iter().zip(&b) {
        let scale = b.estimate.covariance().amax().max(b.estimate.mean().amax());
        worst = worst
            .max((a.estimate.mean() - b.estimate.mean()).amax() / scale)
            .max((a.estimate.covariance() - b.estimate.covariance()).amax() / scale)
            .max((&a.probabilities - &b.probabilities).amax());
    }
    // The cross-covariances differ by the round-off of the Cholesky solve through the map,
    // P Dᵀ (D P Dᵀ)⁻¹ Cₘ Eᵀ against the reference's P F₆ᵀ, then the backward pass's own
    // factorisations: measured 3.3e-15; 1e-12 is the forward test's bound.
    assert!(worst < 1e-12, "largest relative difference {worst:e}");
}

/// A copy with runtime sizes.
fn dynamic<R: estim_core::nalgebra::Dim, C: estim_core::nalgebra::Dim>(
    m: &estim_core::nalgebra::OMatrix<f64, R, C>,
) -> DMatrix<f64>
where
    estim_core::nalgebra::DefaultAllocator: estim_core::nalgebra::allocator::Allocator<R, C>,
{
    DMatrix::from_column_slice(m.nrows(), m.ncols(), m.as_slice())
}

#[test]
fn runtime_sizes_run_the_same_imm() {
    let mut fixed = embedded_imm();
    let runtime_mode = |g: Gaussian<f64, Dyn>, map: StateMap<f64, Dyn, Dyn>| {
        Embedded::new(KalmanFilter::new(g), map).unwrap()
    };
    let runtime_map = |places: &[usize], variance: f64| {
        let mut v = DVector::zeros(6);
        (0..6)
            .filter(|i| !places.contains(i))
            .for_each(|i| v[i] = variance);
        StateMap::new(places, DVector::zeros(6), v).unwrap()
    };
    let (cv, ca) = (
        fixed.modes().0.0.filter().estimate(),
        fixed.modes().0.1.filter().estimate(),
    );
    let gaussian = |mean: &[f64], covariance: DMatrix<f64>| {
        Gaussian::new(DVector::from_column_slice(mean), covariance).unwrap()
    };
    let modes = EmbeddedModes((
        runtime_mode(
            gaussian(cv.mean().as_slice(), dynamic(cv.covariance())),
            runtime_map(&[0, 1, 3, 4], SIGMA2),
        ),
        runtime_mode(
            gaussian(ca.mean().as_slice(), dynamic(ca.covariance())),
            runtime_map(&[0, 1, 2, 3, 4, 5], 0.0),
        ),
    ));
    let mut runtime = Imm::new(modes, pi(), mu0()).unwrap();
    let (cv4, ca6) = (cv4(), ca6());
    let models = (
        LinearProcess::without_input(dynamic(&cv4.0.transition), dynamic(&cv4.0.noise)),
        LinearProcess::without_input(dynamic(&ca6.0.transition), dynamic(&ca6.0.noise)),
    );
    let fixed_sensor = sensor();
    let sensor = LinearMeasurement::<f64, Dyn, U2> {
        observation: estim_core::nalgebra::OMatrix::<f64, U2, Dyn>::from_column_slice(
            fixed_sensor.observation.as_slice(),
        ),
        noise: fixed_sensor.noise,
    };
    for z in readings(37, 16) {
        fixed
            .predict_modes(&(cv4.clone(), ca6.clone()), &(), DT)
            .unwrap();
        runtime.predict_modes(&models, &(), DT).unwrap();
        fixed.update_modes(&fixed_sensor, &z).unwrap();
        runtime.update_modes(&sensor, &z).unwrap();
        // The same arithmetic through nalgebra's runtime-size kernels: round-off only, a few
        // ulps a step (1e-12 as in the equivalence test above).
        let scale = fixed.covariance().amax().max(fixed.state().amax());
        assert!((dynamic(fixed.state()) - runtime.state()).amax() <= 1e-12 * scale);
        assert!((dynamic(fixed.covariance()) - runtime.covariance()).amax() <= 1e-12 * scale);
        assert!((fixed.probabilities() - runtime.probabilities()).amax() <= 1e-12);
    }
}
