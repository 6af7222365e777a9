//! Expectation–maximisation ([`em::estimate`]): recovery of known Q and R within the Monte
//! Carlo spread measured over seeds at two record lengths, a monotone log-likelihood on a
//! model with every kind of structure and missing data, the exact log-likelihood when nothing
//! is free, a singular scalar-multiple Q, static and runtime sizes agreeing, and bad input.

use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim};
use estim_core::nalgebra::{
    Dyn, Matrix1, Matrix2, Matrix2x1, OMatrix, OVector, U1, U2, Vector1, Vector2,
};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess, Quantity};
use estim_filters::noise_id::em::estimate;
use estim_filters::noise_id::{
    CovarianceStructure, EmSettings, LinearGaussian, MatrixStructure, NoiseIdError, Record,
    Setting, Unidentifiable,
};
use estim_filters::{KalmanFilter, filter_sequence};
use rand::rngs::StdRng;

use crate::common::{gaussian_matrix, rng, sample};

/// One simulated record: inputs u₀ … u_{K−1} and measurements z₀ … z_K; `missing(k)` drops zₖ.
/// Process noise w = `noise_factor` · e with e standard normal (so a singular Q = G Gᵀ works).
struct Simulated<M: Dim, U: Dim>
where
    DefaultAllocator: Alloc<M, U>,
{
    inputs: Vec<OVector<f64, U>>,
    measurements: Vec<Option<OVector<f64, M>>>,
}

fn simulate<N: Dim, M: Dim, U: Dim>(
    rng: &mut StdRng,
    model: &LinearGaussian<f64, N, M, U>,
    noise_factor: &OMatrix<f64, N, N>,
    steps: usize,
    missing: impl Fn(usize) -> bool,
) -> Simulated<M, U>
where
    DefaultAllocator: Alloc<N, M> + Alloc<N, U> + Alloc<M, U>,
{
    let (n, m, u) = (
        model.prior.mean().shape_generic().0,
        model.measurement.observation.shape_generic().0,
        model.process.input.shape_generic().1,
    );
    let zero_m = OVector::<f64, M>::zeros_generic(m, U1);
    let mut x = sample(rng, model.prior.mean(), model.prior.covariance());
    let mut out = Simulated {
        inputs: Vec::with_capacity(steps),
        measurements: Vec::with_capacity(steps + 1),
    };
    for k in 0..=steps {
        let z =
            &model.measurement.observation * &x + sample(rng, &zero_m, &model.measurement.noise);
        out.measurements.push((!missing(k)).then_some(z));
        if k < steps {
            let input = gaussian_matrix(rng, u, U1);
            x = &model.process.transition * &x
                + &model.process.input * &input
                + noise_factor * gaussian_matrix(rng, n, U1);
            out.inputs.push(input);
        }
    }
    out
}

fn records<'a, M: Dim, U: Dim>(runs: &'a [Simulated<M, U>]) -> Vec<Record<'a, f64, M, U>>
where
    DefaultAllocator: Alloc<M, U>,
{
    runs.iter()
        .map(|r| Record {
            inputs: &r.inputs,
            measurements: &r.measurements,
        })
        .collect()
}

/// The scalar random walk x⁺ = x + w, z = x + v, with Q, R.
fn walk(q: f64, r: f64) -> LinearGaussian<f64, U1, U1, U1> {
    LinearGaussian {
        process: LinearProcess {
            transition: Matrix1::new(1.0),
            input: Matrix1::zeros(),
            noise: Matrix1::new(q),
        },
        measurement: LinearMeasurement {
            observation: Matrix1::new(1.0),
            noise: Matrix1::new(r),
        },
        prior: Gaussian::new(Vector1::new(0.0), Matrix1::new(10.0)).unwrap(),
    }
}

/// Asserts ℓ never decreases by more than 10⁻¹⁰ |ℓ|: the round-off of summing ~10³ terms
/// of the prediction-error likelihood and of the smoother's statistics is ~10⁻¹³ |ℓ|.
fn assert_monotone(history: &[f64]) {
    for (i, w) in history.windows(2).enumerate() {
        assert!(
            w[1] >= w[0] - 1e-10 * w[0].abs(),
            "iteration {}: {} → {}",
            i + 1,
            w[0],
            w[1]
        );
    }
}

#[test]
fn recovers_q_and_r_within_the_monte_carlo_spread_at_two_lengths() {
    let (q, r, seeds) = (0.04, 0.25, 12);
    let truth = walk(q, r);
    let settings = EmSettings::new()
        .with_process_noise(CovarianceStructure::Full)
        .with_measurement_noise(CovarianceStructure::Full)
        .with_iterations(2000, 1e-11)
        .unwrap();
    let mut spreads = Vec::new();
    for steps in [150, 600] {
        let mut estimates = Vec::new();
        for seed in 0..seeds {
            let run = simulate(
                &mut rng(500 + seed),
                &truth,
                &Matrix1::new(q.sqrt()),
                steps,
                |_| false,
            );
            let fit = estimate(
                &walk(1.0, 1.0),
                &settings,
                &records(std::slice::from_ref(&run)),
            )
            .unwrap();
            assert_monotone(&fit.history);
            assert!(fit.converged, "steps {steps}, seed {seed}");
            estimates.push([
                fit.model.process.noise[(0, 0)],
                fit.model.measurement.noise[(0, 0)],
            ]);
        }
        let n = seeds as f64;
        let mut sd = [0.0; 2];
        for i in 0..2 {
            let mean = estimates.iter().map(|e| e[i]).sum::<f64>() / n;
            sd[i] =
                (estimates.iter().map(|e| (e[i] - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            // The truth within 4 standard errors of the mean of the 12 estimates (the measured
            // spread sd / √12; ML bias at these lengths is far below it).
            let t = [q, r][i];
            assert!(
                (mean - t).abs() < 4.0 * sd[i] / n.sqrt(),
                "steps {steps}, {i}: mean {mean}, sd {}",
                sd[i]
            );
        }
        spreads.push(sd);
    }
    // Four times the data: the spread shrinks by about 2 (ratio of two 12-sample sds of
    // Gaussian estimates is within [0.25, 0.8] · 1/2 … with margin for the χ² spread of each).
    for i in 0..2 {
        let ratio = spreads[1][i] / spreads[0][i];
        assert!(
            (0.25..0.85).contains(&ratio),
            "parameter {i}: ratio {ratio}"
        );
    }
}

/// A 2-state system with an input, position and velocity measured.
fn two_state() -> LinearGaussian<f64, U2, U2, U1> {
    LinearGaussian {
        process: LinearProcess {
            transition: Matrix2::new(1.0, 0.5, 0.0, 0.9),
            input: Matrix2x1::new(0.1, 0.5),
            noise: Matrix2::new(0.02, 0.01, 0.01, 0.05),
        },
        measurement: LinearMeasurement {
            observation: Matrix2::new(1.0, 0.0, 0.0, 1.0),
            noise: Matrix2::new(0.3, 0.0, 0.0, 0.1),
        },
        prior: Gaussian::new(Vector2::new(1.0, -1.0), Matrix2::new(1.0, 0.2, 0.2, 0.5)).unwrap(),
    }
}

#[test]
fn log_likelihood_is_monotone_with_every_structure_and_missing_data() {
    let truth = two_state();
    let factor = truth.process.noise.cholesky().unwrap().unpack();
    let runs: Vec<_> = (0..4)
        .map(|s| {
            simulate(&mut rng(40 + s), &truth, &factor, 120, |k| {
                k % 5 == 2 || (30..40).contains(&k)
            })
        })
        .collect();
    let mut start = truth.clone();
    start.process.noise = Matrix2::identity();
    start.measurement.noise = Matrix2::identity();
    start.process.transition = Matrix2::new(1.0, 0.5, 0.0, 0.5);
    start.prior = Gaussian::new(Vector2::zeros(), Matrix2::identity()).unwrap();
    let variants = [
        EmSettings::new()
            .with_process_noise(CovarianceStructure::Full)
            .with_measurement_noise(CovarianceStructure::Diagonal)
            .with_transition(MatrixStructure::FreeEntries(vec![(1, 1)]))
            .with_prior(true, CovarianceStructure::Full),
        EmSettings::new()
            .with_process_noise(CovarianceStructure::DiagonalWithFixed(vec![0]))
            .with_measurement_noise(CovarianceStructure::ScalarMultiple(Matrix2::new(
                3.0, 0.0, 0.0, 1.0,
            )))
            .with_observation(MatrixStructure::FreeEntries(vec![(0, 0), (1, 1)])),
        EmSettings::new()
            .with_process_noise(CovarianceStructure::Full)
            .with_measurement_noise(CovarianceStructure::Full)
            .with_transition(MatrixStructure::Free),
    ];
    for (v, settings) in variants.into_iter().enumerate() {
        let settings = settings.with_iterations(60, 0.0).unwrap();
        let fit = estimate(&start, &settings, &records(&runs)).unwrap();
        assert_eq!(fit.history.len(), 60, "variant {v}");
        assert_monotone(&fit.history);
        assert!(fit.history[59] > fit.history[0], "variant {v}");
    }
}

#[test]
fn with_nothing_free_the_log_likelihood_is_the_filters() {
    let truth = two_state();
    let factor = truth.process.noise.cholesky().unwrap().unpack();
    let runs: Vec<_> = (0..2)
        .map(|s| simulate(&mut rng(9 + s), &truth, &factor, 50, |k| k % 7 == 3))
        .collect();
    let fit = estimate(&truth, &EmSettings::new(), &records(&runs)).unwrap();
    assert_eq!(fit.history.len(), 1);
    assert_eq!(fit.model, truth);
    let direct: f64 = runs
        .iter()
        .map(|run| {
            let mut kf = KalmanFilter::new(truth.prior.clone());
            filter_sequence(
                &mut kf,
                &truth.process,
                &run.inputs,
                1.0,
                &truth.measurement,
                &run.measurements,
            )
            .unwrap()
            .log_likelihood
        })
        .sum();
    // The same filter steps (the smoother's forward pass records predictions through the
    // cross-covariance form of the same prediction): equal to round-off.
    assert!(
        (fit.log_likelihood - direct).abs() < 1e-12 * direct.abs(),
        "{} vs {direct}",
        fit.log_likelihood
    );
}

#[test]
fn a_singular_scalar_multiple_q_is_recovered() {
    // Lu's form: a scalar noise W entering through Γ, Q = W Γ Γᵀ (rank 1).
    let gamma = Vector2::new(0.5, 1.0);
    let shape = gamma * gamma.transpose();
    let w = 0.2;
    let mut truth = two_state();
    truth.process.transition = Matrix2::new(1.0, 1.0, 0.0, 1.0);
    truth.process.noise = shape * w;
    truth.measurement = LinearMeasurement {
        observation: Matrix2::identity(),
        noise: Matrix2::new(0.5, 0.0, 0.0, 0.5),
    };
    let factor = Matrix2::from_columns(&[gamma * w.sqrt(), Vector2::zeros()]);
    let runs: Vec<_> = (0..6)
        .map(|s| simulate(&mut rng(70 + s), &truth, &factor, 200, |_| false))
        .collect();
    let mut start = truth.clone();
    start.process.noise = shape * 1.0;
    let settings = EmSettings::new()
        .with_process_noise(CovarianceStructure::ScalarMultiple(shape))
        .with_iterations(500, 1e-12)
        .unwrap();
    let fit = estimate(&start, &settings, &records(&runs)).unwrap();
    assert_monotone(&fit.history);
    let w_hat = fit.model.process.noise[(1, 1)];
    // 1200 transitions observed through noise 0.5: the ML of W has relative sd ≈
    // √(2/1200)·(1 + R/W-ish factor) < 0.15; 0.3 is over 2 such sds and catches a wrong M-step
    // (tr(S Q̄)/rank without the pseudo-inverse would be off by |Γ|⁴ = 1.56).
    assert!((w_hat / w - 1.0).abs() < 0.3, "{w_hat}");
    // The estimate keeps the shape exactly.
    assert!((fit.model.process.noise - shape * w_hat).abs().max() < 1e-15);
}

#[test]
fn static_and_runtime_sizes_agree() {
    let truth = two_state();
    let factor = truth.process.noise.cholesky().unwrap().unpack();
    let run = simulate(&mut rng(3), &truth, &factor, 80, |k| k % 4 == 1);
    let settings = EmSettings::new()
        .with_process_noise(CovarianceStructure::Full)
        .with_measurement_noise(CovarianceStructure::Diagonal)
        .with_iterations(20, 0.0)
        .unwrap();
    let fixed = estimate(&truth, &settings, &records(std::slice::from_ref(&run))).unwrap();
    let d = |m: &Matrix2<f64>| DMatrix::from_iterator(2, 2, m.iter().copied());
    let dynamic_model: LinearGaussian<f64, Dyn, Dyn, Dyn> = LinearGaussian {
        process: LinearProcess {
            transition: d(&truth.process.transition),
            input: DMatrix::from_iterator(2, 1, truth.process.input.iter().copied()),
            noise: d(&truth.process.noise),
        },
        measurement: LinearMeasurement {
            observation: d(&truth.measurement.observation),
            noise: d(&truth.measurement.noise),
        },
        prior: truth.prior.clone().into_dyn(),
    };
    let dynamic_settings = EmSettings::<f64, Dyn, Dyn>::new()
        .with_process_noise(CovarianceStructure::Full)
        .with_measurement_noise(CovarianceStructure::Diagonal)
        .with_iterations(20, 0.0)
        .unwrap();
    let inputs: Vec<DVector<f64>> = run
        .inputs
        .iter()
        .map(|u| DVector::from_column_slice(u.as_slice()))
        .collect();
    let zs: Vec<Option<DVector<f64>>> = run
        .measurements
        .iter()
        .map(|z| z.map(|z| DVector::from_column_slice(z.as_slice())))
        .collect();
    let dynamic = estimate(
        &dynamic_model,
        &dynamic_settings,
        &[Record {
            inputs: &inputs,
            measurements: &zs,
        }],
    )
    .unwrap();
    // Same algorithm, different kernels for the products (nalgebra unrolled vs faer/dynamic):
    // agreement to round-off accumulated over 20 iterations.
    for (a, b) in fixed.history.iter().zip(&dynamic.history) {
        assert!((a - b).abs() < 1e-9 * a.abs(), "{a} vs {b}");
    }
    assert!(
        (d(&fixed.model.process.noise) - &dynamic.model.process.noise)
            .abs()
            .max()
            < 1e-9
    );
}

#[test]
fn bad_input_is_a_typed_error() {
    let model = walk(1.0, 1.0);
    let free = EmSettings::new()
        .with_process_noise(CovarianceStructure::Full)
        .with_measurement_noise(CovarianceStructure::Full);
    let run = simulate(
        &mut rng(1),
        &walk(0.04, 0.25),
        &Matrix1::new(0.2),
        20,
        |_| false,
    );
    let one = |r: &Simulated<U1, U1>| {
        estimate(
            &model,
            &free,
            &[Record {
                inputs: &r.inputs,
                measurements: &r.measurements,
            }],
        )
    };

    let mut all_missing = simulate(&mut rng(1), &model, &Matrix1::new(1.0), 20, |_| true);
    assert_eq!(one(&all_missing), Err(NoiseIdError::AllMissing));
    all_missing.measurements[3] = Some(Vector1::new(f64::NAN));
    assert_eq!(
        one(&all_missing),
        Err(NoiseIdError::NonFiniteData {
            sequence: 0,
            step: 3,
            quantity: Quantity::Measurement
        })
    );
    let mut bad_input = simulate(&mut rng(2), &model, &Matrix1::new(1.0), 20, |_| false);
    bad_input.inputs[5] = Vector1::new(f64::INFINITY);
    assert_eq!(
        one(&bad_input),
        Err(NoiseIdError::NonFiniteInput {
            sequence: 0,
            step: 5
        })
    );
    let short = Simulated::<U1, U1> {
        inputs: run.inputs.clone(),
        measurements: run.measurements[..5].to_vec(),
    };
    assert!(matches!(
        one(&short),
        Err(NoiseIdError::SequenceLength { sequence: 0, .. })
    ));
    assert!(matches!(
        estimate(&model, &free, &[]),
        Err(NoiseIdError::SequenceLength { found: 0, .. })
    ));

    // Settings.
    assert!(matches!(
        free.clone().with_iterations(0, 1e-9),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::MaxIterations,
            ..
        })
    ));
    assert!(matches!(
        free.clone().with_iterations(10, f64::NAN),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::Tolerance,
            ..
        })
    ));
    let mut raw = free.clone();
    raw.tolerance = -1.0;
    assert!(matches!(
        estimate(&model, &raw, &records(std::slice::from_ref(&run))),
        Err(NoiseIdError::InvalidSetting {
            setting: Setting::Tolerance,
            ..
        })
    ));

    // Unidentifiable constraints.
    let rec = records(std::slice::from_ref(&run));
    let basis = free
        .clone()
        .with_transition(MatrixStructure::Free)
        .with_observation(MatrixStructure::FreeEntries(vec![(0, 0)]));
    assert_eq!(
        estimate(&model, &basis, &rec),
        Err(NoiseIdError::Unidentifiable(Unidentifiable::StateBasis))
    );
    let scale = free.clone().with_observation(MatrixStructure::Free);
    assert_eq!(
        estimate(&model, &scale, &rec),
        Err(NoiseIdError::Unidentifiable(Unidentifiable::StateScale))
    );
    let zero = free
        .clone()
        .with_process_noise(CovarianceStructure::ScalarMultiple(Matrix1::new(0.0)));
    assert_eq!(
        estimate(&model, &zero, &rec),
        Err(NoiseIdError::Unidentifiable(
            Unidentifiable::DegenerateShape(Quantity::ProcessNoise)
        ))
    );
    let single = Simulated::<U1, U1> {
        inputs: vec![],
        measurements: vec![Some(Vector1::new(0.3))],
    };
    assert_eq!(
        one(&single),
        Err(NoiseIdError::Unidentifiable(Unidentifiable::NoTransitions))
    );

    // An invalid starting model.
    let mut not_psd = model.clone();
    not_psd.measurement.noise = Matrix1::new(-1.0);
    assert!(matches!(
        estimate(&not_psd, &free, &rec),
        Err(NoiseIdError::Model(_))
    ));
}

#[test]
fn single_precision_follows_double() {
    // The same EM in f32 and f64 (one generic code path) on a random walk: 30 iterations.
    let run = simulate(
        &mut rng(8),
        &walk(0.04, 0.25),
        &Matrix1::new(0.2),
        200,
        |k| k % 6 == 0,
    );
    let settings = EmSettings::new()
        .with_process_noise(CovarianceStructure::Full)
        .with_measurement_noise(CovarianceStructure::Full)
        .with_iterations(30, 0.0)
        .unwrap();
    let double = estimate(
        &walk(1.0, 1.0),
        &settings,
        &records(std::slice::from_ref(&run)),
    )
    .unwrap();
    let start = LinearGaussian::<f32, U1, U1, U1> {
        process: LinearProcess {
            transition: Matrix1::new(1.0),
            input: Matrix1::zeros(),
            noise: Matrix1::new(1.0),
        },
        measurement: LinearMeasurement {
            observation: Matrix1::new(1.0),
            noise: Matrix1::new(1.0),
        },
        prior: Gaussian::new(Vector1::new(0.0), Matrix1::new(10.0)).unwrap(),
    };
    let single_settings = EmSettings::<f32, U1, U1>::new()
        .with_process_noise(CovarianceStructure::Full)
        .with_measurement_noise(CovarianceStructure::Full)
        .with_iterations(30, 0.0)
        .unwrap();
    let inputs: Vec<Vector1<f32>> = run.inputs.iter().map(|u| u.cast()).collect();
    let zs: Vec<Option<Vector1<f32>>> = run
        .measurements
        .iter()
        .map(|z| z.map(|z| z.cast()))
        .collect();
    let single = estimate(
        &start,
        &single_settings,
        &[Record {
            inputs: &inputs,
            measurements: &zs,
        }],
    )
    .unwrap();
    // f32 round-off (ε ≈ 1.2e-7) accumulated over 200 steps and 30 iterations: 1e-3 relative
    // is ~10⁴ ε, far above it and far below the 30-iteration change of Q (a factor ~25).
    let q = (
        single.model.process.noise[(0, 0)] as f64,
        double.model.process.noise[(0, 0)],
    );
    let r = (
        single.model.measurement.noise[(0, 0)] as f64,
        double.model.measurement.noise[(0, 0)],
    );
    assert!((q.0 / q.1 - 1.0).abs() < 1e-3, "{q:?}");
    assert!((r.0 / r.1 - 1.0).abs() < 1e-3, "{r:?}");
    let (ls, ld) = (
        *single.history.last().unwrap() as f64,
        *double.history.last().unwrap(),
    );
    assert!((ls - ld).abs() < 1e-4 * ld.abs(), "{ls} vs {ld}");
}

/// An index outside its matrix is a programmer error: `estimate` panics, and the panic names
/// the caller's line (`#[track_caller]`), for every kind of index. Before, the checks panicked
/// inside closures, which `#[track_caller]` does not reach: the location was em.rs.
#[test]
fn index_panics_name_the_callers_line() {
    use std::panic::{self, AssertUnwindSafe};
    use std::sync::{Arc, Mutex};
    let model = walk(1.0, 1.0);
    let run = simulate(&mut rng(1), &model, &Matrix1::new(0.2), 5, |_| false);
    let records = [Record {
        inputs: &run.inputs,
        measurements: &run.measurements,
    }];
    let bad = [
        EmSettings::new().with_process_noise(CovarianceStructure::DiagonalWithFixed(vec![1])),
        EmSettings::new().with_measurement_noise(CovarianceStructure::DiagonalWithFixed(vec![3])),
        EmSettings::new().with_prior(false, CovarianceStructure::DiagonalWithFixed(vec![1])),
        EmSettings::new().with_transition(MatrixStructure::FreeEntries(vec![(0, 1)])),
        EmSettings::new().with_observation(MatrixStructure::FreeEntries(vec![(1, 0)])),
    ];
    // The hook is global: this thread's panics are recorded, every other thread's go to the
    // hook that was there (other tests run beside this one). It is put back before asserting.
    let seen = Arc::new(Mutex::new(Vec::new()));
    let previous = Arc::new(panic::take_hook());
    let (record, forward, this) = (
        Arc::clone(&seen),
        Arc::clone(&previous),
        std::thread::current().id(),
    );
    panic::set_hook(Box::new(move |info| {
        if std::thread::current().id() == this {
            let at = info.location().map(|l| (l.file().to_string(), l.line()));
            record.lock().unwrap().push(at);
        } else {
            forward(info);
        }
    }));
    let outcomes: Vec<bool> = bad
        .iter()
        .map(|settings| {
            panic::catch_unwind(AssertUnwindSafe(|| estimate(&model, settings, &records))).is_err()
        })
        .collect();
    // Drops this test's hook (and with it its reference to the previous one), then restores
    // that one.
    drop(panic::take_hook());
    match Arc::try_unwrap(previous) {
        Ok(previous) => panic::set_hook(previous),
        Err(_) => unreachable!("the test's hook, which held the other reference, is dropped"),
    }
    assert_eq!(outcomes, [true; 5], "every bad index panics");
    // Five panics, all at the one call above.
    let seen = seen.lock().unwrap().clone();
    assert_eq!(seen.len(), bad.len());
    let (file, line) = seen[0].clone().expect("a location");
    assert_eq!(file, file!());
    assert!(
        seen.iter().all(|at| *at == Some((file.clone(), line))),
        "{seen:?}"
    );
}
