//! serde (feature `serde`): a checkpointed filter resumes bit-identically, bad checkpoints are
//! refused, reports round-trip, and Monte Carlo shards written as JSON merge into exactly the
//! statistics of one run.

use crate::consistency_common::{DT, Lu, input, simulate};
use estim_core::nalgebra::{DMatrix, DVector, Dyn, U2, U3, Vector2};
use estim_core::propagate::Unscented;
use estim_core::{Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::monte_carlo::{MonteCarlo, MonteCarloError, Shard};
use estim_filters::{
    CovarianceUpdate, Ekf, Estimator, FadingMemoryRls, Gate, GaussianFilter, Iekf, KalmanFilter,
    Predict, SecondOrderEkf, SrEkf, SrKalmanFilter, SrUkf, Ukf, Update, UpdateReport,
};

/// Runs `filter` over Lu's recorded inputs and measurements for steps `range`.
fn run<F>(filter: &mut F, lu: &Lu, zs: &[Vector2<f64>], range: std::ops::Range<usize>)
where
    F: Predict<f64, U3, LinearProcess<f64, U3, estim_core::nalgebra::U1>>
        + Update<f64, U3, U2, LinearMeasurement<f64, U3, U2>>,
{
    for k in range {
        filter.predict(&lu.process, &input(k), DT).unwrap();
        filter.update(&lu.sensor, &zs[k]).unwrap();
    }
}

fn measurements(n: usize) -> Vec<Vector2<f64>> {
    (0..n)
        .map(|k| Vector2::new((k as f64 * 0.3).sin() * 5.0, (k as f64 * 0.1).cos()))
        .collect()
}

/// Checkpoint after 30 steps through JSON, resume, and run 30 more beside the original: the
/// two agree to the bit (`==` compares state, covariance, propagator, state space and
/// settings; the assert on bits is explicit for the estimate).
#[test]
fn resumed_filters_are_bit_identical() {
    let lu = Lu::new();
    let zs = measurements(60);
    macro_rules! check {
        ($filter:expr, $ty:ty) => {{
            let mut original: $ty = $filter;
            run(&mut original, &lu, &zs, 0..30);
            let json = serde_json::to_string(&original).unwrap();
            let mut resumed: $ty = serde_json::from_str(&json).unwrap();
            assert!(resumed == original, "{}", stringify!($ty));
            run(&mut original, &lu, &zs, 30..60);
            run(&mut resumed, &lu, &zs, 30..60);
            assert!(resumed == original, "{}", stringify!($ty));
            let bits = |f: &$ty| {
                f.state()
                    .iter()
                    .chain(f.covariance().iter())
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&resumed), bits(&original), "{}", stringify!($ty));
        }};
    }
    check!(KalmanFilter::new(lu.prior.clone()), KalmanFilter<f64, U3>);
    check!(
        Ekf::new(lu.prior.clone())
            .with_covariance_update(CovarianceUpdate::Standard)
            .with_gate(Gate::Probability(0.999))
            .unwrap(),
        Ekf<f64, U3>
    );
    check!(SecondOrderEkf::new(lu.prior.clone()), SecondOrderEkf<f64, U3>);
    check!(
        Ukf::with_propagator(lu.prior.clone(), Unscented::new(0.5, 2.0, 1.0).unwrap())
            .with_gate(50.0)
            .unwrap(),
        Ukf<f64, U3>
    );
    // Every filter of the family: the square-root forms (their factor compared too, by `==`),
    // the IEKF and the fading-memory RLS (its updates only).
    check!(SrKalmanFilter::new(lu.prior.clone()), SrKalmanFilter<f64, U3>);
    check!(
        SrEkf::new(lu.prior.clone()).with_gate(50.0).unwrap(),
        SrEkf<f64, U3>
    );
    check!(SrUkf::new(lu.prior.clone()), SrUkf<f64, U3>);
    check!(
        Iekf::new(lu.prior.clone()).with_iterations(4, 1e-10).unwrap(),
        Iekf<f64, U3>
    );
    let mut rls = FadingMemoryRls::new(lu.prior.clone(), 0.97).unwrap();
    for z in &zs[..30] {
        rls.update(&lu.sensor, z).unwrap();
    }
    let mut resumed: FadingMemoryRls<f64, U3> =
        serde_json::from_str(&serde_json::to_string(&rls).unwrap()).unwrap();
    for z in &zs[30..] {
        rls.update(&lu.sensor, z).unwrap();
        resumed.update(&lu.sensor, z).unwrap();
    }
    assert_eq!(resumed, rls);
}

/// A square-root checkpoint holds S, which must be lower triangular with a non-negative
/// diagonal (the filter's invariant) and whose S Sᵀ must be finite: anything else is refused.
#[test]
fn bad_square_root_checkpoints_are_refused() {
    let lu = Lu::new();
    let good = serde_json::to_value(SrUkf::new(lu.prior.clone())).unwrap();
    let with_factor = |factor: serde_json::Value| {
        let mut v = good.clone();
        v["factor"] = factor;
        serde_json::from_value::<SrUkf<f64, U3>>(v)
    };
    assert!(with_factor(good["factor"].clone()).is_ok());
    // Column-major: an entry above the diagonal, a negative pivot, an overflowing S Sᵀ. Each
    // is refused by the filter's own check (its message), not by a serde type error.
    let refused = |factor: serde_json::Value, why: &str| {
        let e = with_factor(factor).unwrap_err().to_string();
        assert!(e.contains(why), "{e}");
    };
    let not_psd = "not positive semi-definite";
    refused(
        serde_json::json!([1.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0]),
        not_psd,
    );
    refused(
        serde_json::json!([-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        not_psd,
    );
    refused(
        serde_json::json!([1e200, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        "not finite",
    );
}

/// Runtime sizes resume too (faer's kernels behind them are deterministic).
#[test]
fn resumed_runtime_size_filters_are_bit_identical() {
    let n = 4;
    let process = LinearProcess::without_input(
        DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                0.95
            } else if j == i + 1 {
                0.1
            } else {
                0.0
            }
        }),
        DMatrix::identity(n, n) * 1e-2,
    );
    let sensor = LinearMeasurement {
        observation: DMatrix::from_fn(2, n, |i, j| (i + j) as f64 * 0.5 + 1.0),
        noise: DMatrix::identity(2, 2) * 0.3,
    };
    let prior = Gaussian::new(DVector::zeros(n), DMatrix::identity(n, n)).unwrap();
    let mut original = Ukf::new(prior);
    let step = |f: &mut Ukf<f64, Dyn>, k: usize| {
        f.predict(&process, &(), 0.1).unwrap();
        f.update(&sensor, &DVector::from_column_slice(&[k as f64 * 0.1, 1.0]))
            .unwrap();
    };
    (0..20).for_each(|k| step(&mut original, k));
    let mut resumed: Ukf<f64, Dyn> =
        serde_json::from_str(&serde_json::to_string(&original).unwrap()).unwrap();
    (20..40).for_each(|k| {
        step(&mut original, k);
        step(&mut resumed, k);
    });
    assert!(resumed == original);
}

/// A checkpoint whose shapes disagree, with a non-finite entry or an invalid setting is an
/// error, never a filter.
#[test]
fn bad_checkpoints_are_refused() {
    let lu = Lu::new();
    let good = serde_json::to_value(Ukf::new(lu.prior.clone())).unwrap();
    let with = |path: &[&str], value: serde_json::Value| {
        let mut v = good.clone();
        let mut at = &mut v;
        for key in path {
            at = &mut at[*key];
        }
        *at = value;
        serde_json::from_value::<Ukf<f64, U3>>(v)
    };
    assert!(with(&[], good.clone()).is_ok());
    // (Non-finite entries have no JSON form: JSON writes NaN as null, which is refused as a
    // type error; the finiteness check is for formats that carry them.)
    // Each refusal names its cause: serde's type and length checks for the first two, the
    // filter's own parameter checks for the rest.
    let refused = |path: &[&str], value: serde_json::Value, why: &str| {
        let e = with(path, value).unwrap_err().to_string();
        assert!(e.contains(why), "{e}");
    };
    refused(
        &["state"],
        serde_json::json!([0.0, null, 0.0]),
        "invalid type: null",
    );
    refused(
        &["state"],
        serde_json::json!([0.0, 0.0]),
        "invalid length 2",
    );
    let alpha = serde_json::json!(-1.0);
    refused(
        &["propagator", "alpha"],
        alpha,
        "unscented alpha = -1 is out of range",
    );
    let gate = serde_json::json!({"Nis": -1.0});
    refused(&["gate"], gate, "gate threshold = -1 is out of range");
    let gate = serde_json::json!({"Probability": 1.5});
    refused(&["gate"], gate, "gate probability = 1.5 is out of range");
    // Runtime sizes: a covariance of the wrong size.
    let prior = Gaussian::new(DVector::<f64>::zeros(2), DMatrix::identity(2, 2)).unwrap();
    let mut v = serde_json::to_value(KalmanFilter::new(prior)).unwrap();
    v["covariance"] = serde_json::to_value(DMatrix::<f64>::identity(3, 3)).unwrap();
    let e = serde_json::from_value::<GaussianFilter<f64, Dyn, estim_core::Affine>>(v).unwrap_err();
    assert!(e.to_string().contains("covariance"), "{e}");
}

/// Issue 41, defect 5: a runtime-size covariance claiming 2⁶³ − 1 rows made nalgebra's
/// storage check multiply rows × columns unchecked: a panic ("attempt to multiply with
/// overflow") where overflow checks are on, and where they are off 2⁶³ × 2 wraps to 0 and an
/// empty matrix claiming 2⁶³ rows got through. Every corrupted shape is a serde error now, for
/// a filter checkpoint, a `Gaussian` and an update report, whatever the build.
#[test]
fn a_corrupted_runtime_shape_is_an_error_not_a_panic() {
    let prior = Gaussian::new(DVector::<f64>::zeros(2), DMatrix::identity(2, 2)).unwrap();
    let filter = serde_json::to_value(KalmanFilter::new(prior.clone())).unwrap();
    let gaussian = serde_json::to_value(&prior).unwrap();
    let huge = i64::MAX as u64;
    // The error is ours, naming the claim (the shape check) or the quantity (the
    // comparison with the state), not nalgebra's count of a wrapped product.
    let names_the_fault = |e: &serde_json::Error| {
        let text = e.to_string();
        text.contains("claims") || text.contains("covariance")
    };
    // (The shape, and whether the error must name it: a tuple of the wrong length is
    // serde_json's own error.)
    let shapes = [
        (serde_json::json!([[1.0, 0.0, 0.0, 1.0], huge, 2]), true),
        (serde_json::json!([[1.0, 0.0, 0.0, 1.0], 2, huge]), true),
        (serde_json::json!([[], huge + 1, 2]), true),
        (serde_json::json!([[], 0, 2]), true),
        (serde_json::json!([[1.0, 0.0, 0.0, 1.0], 4, 1]), true),
        (serde_json::json!([[1.0, 0.0, 0.0, 1.0], 1, 4]), true),
        (serde_json::json!([[1.0, 0.0, 0.0, 1.0], 2, 2, 2]), false),
        (serde_json::json!([[1.0, 0.0, 0.0, 1.0], 2]), false),
    ];
    for (shape, named) in shapes {
        let mut f = filter.clone();
        f["covariance"] = shape.clone();
        let text = f.to_string();
        let result = std::panic::catch_unwind(|| {
            serde_json::from_str::<GaussianFilter<f64, Dyn, estim_core::Affine>>(&text)
        });
        let e = result
            .unwrap_or_else(|_| panic!("panic restoring a checkpoint with covariance {shape}"))
            .unwrap_err();
        assert!(!named || names_the_fault(&e), "{shape}: {e}");
        let mut g = gaussian.clone();
        g["covariance"] = shape.clone();
        let text = g.to_string();
        let result = std::panic::catch_unwind(|| serde_json::from_str::<Gaussian<f64, Dyn>>(&text));
        let e = result
            .unwrap_or_else(|_| panic!("panic restoring a Gaussian with covariance {shape}"))
            .unwrap_err();
        assert!(!named || names_the_fault(&e), "{shape}: {e}");
    }
    // An update report of runtime size reads its S the same way.
    let mut report = serde_json::to_value(UpdateReport::<f64, Dyn>::zeros(Dyn(2))).unwrap();
    report["innovation_covariance"] = serde_json::json!([[1.0, 0.0, 0.0, 1.0], huge, 2]);
    let text = report.to_string();
    let result = std::panic::catch_unwind(|| serde_json::from_str::<UpdateReport<f64, Dyn>>(&text));
    assert!(names_the_fault(
        &result.expect("panic restoring a report").unwrap_err()
    ));
    // The state vector claims its length the same way.
    let mut f = filter.clone();
    f["state"] = serde_json::json!([[0.0, 0.0], huge, null]);
    let text = f.to_string();
    assert!(serde_json::from_str::<GaussianFilter<f64, Dyn, estim_core::Affine>>(&text).is_err());
    // The good checkpoint still restores.
    let back: GaussianFilter<f64, Dyn, estim_core::Affine> =
        serde_json::from_value(filter).unwrap();
    assert_eq!(back.covariance(), prior.covariance());
}

#[test]
fn update_reports_round_trip() {
    let lu = Lu::new();
    let mut kf = KalmanFilter::new(lu.prior.clone());
    let report = kf.update(&lu.sensor, &Vector2::new(1.0, -0.5)).unwrap();
    let back: UpdateReport<f64, U2> =
        serde_json::from_str(&serde_json::to_string(&report).unwrap()).unwrap();
    assert_eq!(back, report);
}

/// Shards over seed ranges, each written to JSON and read back (as separate processes would),
/// merge into exactly the statistics of one run, in any order; wrong sets of shards are
/// refused.
#[test]
fn json_shards_merge_into_one_run_bit_for_bit() {
    let lu = Lu::new();
    let mc = MonteCarlo::new(120, 4)
        .unwrap()
        .with_seed(5)
        .with_chunks(12)
        .unwrap()
        .with_residual_pair(1, 3)
        .unwrap();
    let realization = |_: usize, seed: u64, rec: &mut estim_filters::Recorder| {
        simulate(
            &lu,
            &lu.process,
            &lu.sensor,
            KalmanFilter::new,
            40,
            10,
            seed,
            |slot, x, kf, report| {
                rec.record_filter(slot, x, kf)?;
                rec.record_innovation(slot, report)?;
                rec.record_residual(slot, &report.innovation)
            },
        )
    };
    let whole = mc.run_sequential(realization).unwrap();
    let files: Vec<String> = (0..5)
        .map(|s| serde_json::to_string(&mc.run_shard(s, 5, realization).unwrap()).unwrap())
        .collect();
    let read = |order: &[usize]| -> Vec<Shard> {
        order
            .iter()
            .map(|&i| serde_json::from_str(&files[i]).unwrap())
            .collect()
    };
    let merged = mc.merge_shards(read(&[3, 0, 4, 1, 2])).unwrap();
    assert_eq!(merged, whole);
    let bits = |s: &estim_filters::EnsembleStats| {
        s.slots
            .iter()
            .filter_map(|s| s.estimate.as_ref())
            .flat_map(|e| {
                e.mean_error
                    .iter()
                    .chain(e.error_covariance.iter())
                    .map(|v| v.to_bits())
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&merged), bits(&whole));
    assert_eq!(
        read(&[0, 1, 2, 3, 4])
            .iter()
            .map(Shard::runs)
            .sum::<usize>(),
        120
    );

    let shards_error =
        |r: Result<_, MonteCarloError>| matches!(r, Err(MonteCarloError::Shards { .. }));
    assert!(
        shards_error(mc.merge_shards(read(&[0, 1, 3, 4]))),
        "a shard missing"
    );
    assert!(
        shards_error(mc.merge_shards(read(&[0, 1, 1, 2, 3, 4]))),
        "a shard twice"
    );
    let other = mc.clone().with_seed(6);
    assert!(
        shards_error(other.merge_shards(read(&[0, 1, 2, 3, 4]))),
        "another experiment"
    );
    assert!(shards_error(
        mc.run_shard(5, 5, realization).map(|_| whole.clone())
    ));

    // A shard edited on disk so that its buffers disagree with its dimensions: refused, not a
    // panic on an index out of range.
    let mut edited: serde_json::Value = serde_json::from_str(&files[2]).unwrap();
    edited["chunks"][0]["slots"][1]["mean_e"]
        .as_array_mut()
        .unwrap()
        .pop();
    let mut shards = read(&[0, 1, 3, 4]);
    shards.push(serde_json::from_value(edited).unwrap());
    assert!(shards_error(mc.merge_shards(shards)), "a corrupted shard");

    // Counts no chunk of this experiment can hold (the sums overflowed: a panic in debug
    // builds, wrapped totals in release): refused.
    for (path, value) in [
        (&["runs"][..], u64::MAX),
        (&["runs"][..], 11),
        (&["slots", "1", "count"][..], u64::MAX),
        (&["slots", "1", "nis_count"][..], 11),
        (&["slots", "1", "nis_dof"][..], u64::MAX),
        (&["pairs", "0", "count"][..], 11),
    ] {
        let mut edited: serde_json::Value = serde_json::from_str(&files[2]).unwrap();
        let mut field = &mut edited["chunks"][0];
        for key in path {
            field = match key.parse::<usize>() {
                Ok(i) => &mut field[i],
                Err(_) => &mut field[*key],
            };
        }
        assert!(field.is_u64(), "{path:?}");
        *field = serde_json::json!(value);
        let mut shards = read(&[0, 1, 3, 4]);
        shards.push(serde_json::from_value(edited).unwrap());
        if value == u64::MAX && path == ["runs"] {
            assert_eq!(shards[4].runs(), usize::MAX, "saturates");
        }
        assert!(shards_error(mc.merge_shards(shards)), "{path:?} = {value}");
    }

    // Statistics edited so that a matrix is smaller than the mean error: a typed error from
    // the verdict, not an index out of bounds.
    let mut stats = serde_json::to_value(&whole).unwrap();
    stats["slots"][1]["estimate"]["error_covariance"] =
        serde_json::to_value(estim_core::nalgebra::DMatrix::<f64>::zeros(1, 1)).unwrap();
    let stats: estim_filters::EnsembleStats = serde_json::from_value(stats).unwrap();
    assert!(matches!(
        stats.verdict(0.95),
        Err(estim_filters::ValidationError::Estimation(
            estim_core::Error::DimensionMismatch {
                stage: estim_core::Stage::ConsistencyCheck,
                ..
            }
        ))
    ));
}
