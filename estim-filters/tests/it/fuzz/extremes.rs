//! The classes of issue 41 (found by an outside fuzz campaign), each fuzzed here:
//!
//! - square-root filters whose factor stays finite while P = S Sᵀ overflows: the main
//!   generator keeps finite huge values out of F (generator limit 2, for the full-P forms'
//!   sake), so here the square-root KF, EKF and UKF get transitions scaled by 10¹⁰…10³⁰⁰,
//!   `f32` and `f64`, static and runtime sizes, checked by the same [`checked_call`] (an `Ok`
//!   has a finite, PSD P; an error leaves the filter bit-identical);
//! - the noise-matching entry points ([`MeasurementNoiseMatching::new`], `observe`,
//!   `observe_with`, and `model` inside a Kalman update) with ±f64::MAX, 10³⁰⁰, 10¹⁵⁴, NaN,
//!   nearly symmetric and adversarial settings: no panic, an error changes nothing, and every
//!   R̂ handed out is finite, exactly symmetric, with eigenvalues ≥ floor;
//! - [`Rts::with_lag`] with lags up to `usize::MAX`: no panic or abort, at most `lag` records,
//!   and its smoothed estimates the whole-pass smoother's last ones, to the bit;
//! - corrupted runtime-size checkpoints (a `GaussianFilter`, a `Gaussian`, an update report)
//!   claiming shapes up to 2⁶⁴ − 1 rows: no panic, and a restored value's shapes agree with
//!   its entries.
//!
//! 256 cases each (together well under a second in the test profile).

use std::panic::{AssertUnwindSafe, catch_unwind};

use estim_core::nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, U1, U2};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::noise_id::MeasurementNoiseMatching;
use estim_filters::smoother::Rts;
use estim_filters::{KalmanFilter, Update, UpdateOutcome, UpdateReport};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

use super::{Case, Op, case_in, matrix, op, run};

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 256,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

// ---------------------------------------------------------------------------------------
// Square-root filters whose P overflows.

/// Transition scales: in `f32` 10¹⁰…10²⁰ keep F finite while S Sᵀ overflows (3.4·10³⁸); in
/// `f64` 10¹⁵⁴…10³⁰⁰ do (1.8·10³⁰⁸); the rest are non-finite after conversion, or finite.
const SCALES: [f64; 9] = [1e10, 1e19, 1e20, 1e38, 1e100, 1e154, 1e155, 1e200, 1e300];

/// A case of the main generator on a square-root filter, its transitions scaled up.
fn overflowing_case() -> impl Strategy<Value = Case> {
    (
        any::<bool>().prop_flat_map(case_in),
        5..8usize,
        prop::collection::vec(prop::sample::select(SCALES.to_vec()), 12),
    )
        .prop_map(|(mut case, filter, scales)| {
            case.filter = filter;
            for (op, scale) in case.ops.iter_mut().zip(scales) {
                if let Op::Predict { f, .. } = op {
                    f.iter_mut().for_each(|v| *v *= scale);
                }
            }
            case
        })
}

#[test]
fn square_root_filters_refuse_an_overflowing_covariance() {
    proptest!(config(), |(case in overflowing_case())| {
        run(&case)?;
    });
}

// ---------------------------------------------------------------------------------------
// Noise matching.

/// Entries for R₀, S and ν: sane ones, or the values that overflowed R̂ and others.
fn value(sane: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => Just(sane),
        1 => prop::sample::select(vec![
            f64::MAX, -f64::MAX, 1e300, -1e300, 1e154, -1e154, 1e200, f64::NAN,
            f64::INFINITY, 0.0, 1e-300, 5e-324,
        ]),
    ]
}

/// A 2 × 2 matrix, row-major: A Aᵀ + 10⁻³ I, or with an entry pair overwritten by `value`,
/// or with a last-bits asymmetry (within `new`'s √ε tolerance).
fn noise_matrix() -> impl Strategy<Value = Vec<f64>> {
    (
        prop::collection::vec(-2.0..2.0f64, 4),
        prop::option::weighted(0.3, (0..2usize, 0..2usize, value(0.0))),
        any::<bool>(),
    )
        .prop_map(|(a, hit, skew)| {
            let a = DMatrix::from_row_slice(2, 2, &a);
            let p = &a * a.transpose() + DMatrix::identity(2, 2) * 1e-3;
            let mut v = vec![p[(0, 0)], p[(0, 1)], p[(0, 1)], p[(1, 1)]];
            if let Some((i, j, x)) = hit {
                v[i * 2 + j] = x;
                v[j * 2 + i] = x;
            }
            if skew {
                v[2] *= 1.0 + 1e-12;
            }
            v
        })
}

#[derive(Clone, Debug)]
enum NoiseOp {
    /// `observe` (or `observe_with` a given R) on a report made up here.
    Report {
        nu: Vec<f64>,
        s: Vec<f64>,
        applied: bool,
        with: Option<Vec<f64>>,
    },
    /// A Kalman update with `model(&sensor)`, then `observe` of its report.
    Filter { z: Vec<f64> },
}

fn noise_op() -> impl Strategy<Value = NoiseOp> {
    prop_oneof![
        3 => (
            prop::collection::vec((-3.0..3.0f64).prop_flat_map(value), 2),
            noise_matrix(),
            prop::bool::weighted(0.9),
            prop::option::weighted(0.2, noise_matrix()),
        )
            .prop_map(|(nu, s, applied, with)| NoiseOp::Report { nu, s, applied, with }),
        1 => prop::collection::vec((-3.0..3.0f64).prop_flat_map(value), 2)
            .prop_map(|z| NoiseOp::Filter { z }),
    ]
}

/// R̂ finite, exactly symmetric, with eigenvalues ≥ floor − tol: tol = 8 m² ε ‖R̂‖ (the
/// recomposition V Λ Vᵀ rounds each entry by a few ε max|λ| over m terms, and the eigenvalues
/// checked here are computed again with their own ε ‖R̂‖ backward error).
fn valid<M: Dim>(
    adaptive: &MeasurementNoiseMatching<f64, M>,
    floor: f64,
) -> Result<(), TestCaseError>
where
    DefaultAllocator: Alloc<M>,
{
    let r = adaptive.noise();
    let m = r.nrows();
    prop_assert!(r.iter().all(|v| v.is_finite()), "non-finite R̂ {r:?}");
    for i in 0..m {
        for j in 0..m {
            prop_assert!(
                r[(i, j)].to_bits() == r[(j, i)].to_bits(),
                "asymmetric R̂ {r:?}"
            );
        }
    }
    let d = DMatrix::from_fn(m, m, |i, j| r[(i, j)]);
    let scale = d.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let tol = 8.0 * (m * m) as f64 * f64::EPSILON * scale;
    let min = d.symmetric_eigenvalues().min();
    prop_assert!(
        min >= floor - tol,
        "λ_min(R̂) = {min:e} < floor {floor:e} − {tol:e}"
    );
    Ok(())
}

fn noise_case<M: Dim>(
    m: M,
    initial: &[f64],
    window: f64,
    floor: f64,
    ops: &[NoiseOp],
) -> Result<(), TestCaseError>
where
    DefaultAllocator: Alloc<Dyn, M>,
{
    let built = catch_unwind(AssertUnwindSafe(|| {
        MeasurementNoiseMatching::new(matrix(m, m, initial), window, floor)
    }));
    let mut adaptive = match built {
        Err(_) => return Err(TestCaseError::fail("panic in new")),
        Ok(Err(_)) => return Ok(()),
        Ok(Ok(a)) => a,
    };
    valid(&adaptive, floor)?;
    // A 2-state Kalman filter seen directly (H = I), for the `model` route.
    let n = Dyn(m.value());
    let sensor = LinearMeasurement {
        observation: OMatrix::<f64, M, Dyn>::identity_generic(m, n),
        noise: OMatrix::<f64, M, M>::identity_generic(m, m),
    };
    let prior = Gaussian::new(
        DVector::zeros(m.value()),
        DMatrix::identity(m.value(), m.value()),
    )
    .unwrap();
    let mut kf = KalmanFilter::new(prior);
    for op in ops {
        let before = adaptive.clone();
        let outcome = catch_unwind(AssertUnwindSafe(|| match op {
            NoiseOp::Report {
                nu,
                s,
                applied,
                with,
            } => {
                let report = UpdateReport {
                    innovation: matrix(m, U1, nu),
                    innovation_covariance: matrix(m, m, s),
                    nis: 0.0,
                    log_likelihood: 0.0,
                    outcome: if *applied {
                        UpdateOutcome::Applied
                    } else {
                        UpdateOutcome::Gated
                    },
                    iterations: None,
                };
                match with {
                    Some(r) => adaptive.observe_with(&report, &matrix(m, m, r)),
                    None => adaptive.observe(&report),
                }
            }
            NoiseOp::Filter { z } => match kf.update(&adaptive.model(&sensor), &matrix(m, U1, z)) {
                Ok(report) => adaptive.observe(&report),
                Err(_) => Ok(false),
            },
        }));
        match outcome {
            Err(_) => return Err(TestCaseError::fail(format!("panic in {op:?}"))),
            Ok(Err(_)) | Ok(Ok(false)) => prop_assert!(adaptive == before, "{op:?} changed it"),
            Ok(Ok(true)) => valid(&adaptive, floor)?,
        }
    }
    Ok(())
}

#[test]
fn noise_matching_never_hands_out_an_invalid_estimate() {
    let settings = (
        prop::sample::select(vec![1.0, 2.5, 10.0, 1e300, 0.5, f64::NAN]),
        prop::sample::select(vec![1e-6, 1.0, 1e300, 5e-324, 0.0, -1.0, f64::NAN]),
    );
    let ops = prop::collection::vec(noise_op(), 1..10);
    proptest!(config(), |(initial in noise_matrix(), (window, floor) in settings, ops in ops, dynamic in any::<bool>())| {
        if dynamic {
            noise_case(Dyn(2), &initial, window, floor, &ops)?;
        } else {
            noise_case(U2, &initial, window, floor, &ops)?;
        }
    });
}

// ---------------------------------------------------------------------------------------
// Rts::with_lag.

#[test]
fn a_fixed_lag_smoother_of_any_lag_is_the_whole_pass_tail() {
    let lags = prop_oneof![
        0..6usize,
        prop::sample::select(vec![
            1 << 30,
            1 << 40,
            usize::MAX / 2,
            usize::MAX - 1,
            usize::MAX
        ]),
    ];
    let ops = prop::collection::vec(op(6), 1..12);
    proptest!(config(), |(lag in lags, ops in ops)| {
        let prior = Gaussian::new(DVector::from_vec(vec![0.1, -0.2, 0.3]), DMatrix::identity(3, 3))
            .unwrap();
        let (mut whole_kf, mut lagged_kf) = (KalmanFilter::new(prior.clone()), KalmanFilter::new(prior));
        let mut whole = Rts::new();
        let built = catch_unwind(|| Rts::<f64, Dyn>::with_lag(lag));
        let Ok(mut lagged) = built else {
            return Err(TestCaseError::fail(format!("panic in with_lag({lag})")));
        };
        for op in &ops {
            match op {
                Op::Predict { f, b, q, u, dt } => {
                    let model = LinearProcess {
                        transition: matrix(Dyn(3), Dyn(3), f),
                        input: matrix(Dyn(3), U1, b),
                        noise: matrix(Dyn(3), Dyn(3), q),
                    };
                    let u = matrix(U1, U1, u);
                    let a = whole.predict(&mut whole_kf, &model, &u, *dt);
                    let b = catch_unwind(AssertUnwindSafe(|| lagged.predict(&mut lagged_kf, &model, &u, *dt)));
                    prop_assert!(b.as_ref().is_ok_and(|b| *b == a), "{op:?}: {a:?} / {b:?}");
                }
                Op::Update { h, r, z } => {
                    let model = LinearMeasurement {
                        observation: matrix(Dyn(2), Dyn(3), h),
                        noise: matrix(Dyn(2), Dyn(2), r),
                    };
                    let z = matrix(Dyn(2), U1, z);
                    let a = whole_kf.update(&model, &z).map(|_| ());
                    let b = lagged_kf.update(&model, &z).map(|_| ());
                    prop_assert_eq!(a, b);
                }
            }
            prop_assert_eq!(lagged.len(), whole.len().min(lag));
        }
        match (whole.smooth(&whole_kf), lagged.smooth(&lagged_kf)) {
            (Ok(all), Ok(tail)) => prop_assert!(tail[..] == all[all.len() - tail.len()..]),
            // The lagged pass runs over the last records only: a failure there is one of the
            // whole pass too.
            (all, Err(_)) => prop_assert!(all.is_err()),
            (Err(_), Ok(_)) => {}
        }
    });
}

// ---------------------------------------------------------------------------------------
// Corrupted checkpoints.

/// Claimed dimensions: small, around 2³², 2⁶³ and 2⁶⁴ (products that overflow or wrap), or
/// any.
#[cfg(feature = "serde")]
fn claimed() -> impl Strategy<Value = u64> {
    prop_oneof![
        3 => 0..5u64,
        2 => prop::sample::select(vec![
            1 << 32, (1 << 32) + 1, (1 << 62) + 1, i64::MAX as u64, 1 << 63, (1 << 63) + 1,
            u64::MAX - 1, u64::MAX,
        ]),
        1 => any::<u64>(),
    ]
}

#[cfg(feature = "serde")]
fn stored(len: usize, rows: u64, cols: Option<u64>) -> serde_json::Value {
    let data: Vec<f64> = (0..len)
        .map(|i| if i % 3 == 0 { 1.0 } else { 0.0 })
        .collect();
    match cols {
        Some(cols) => serde_json::json!([data, rows, cols]),
        None => serde_json::json!([data, rows, null]),
    }
}

#[cfg(feature = "serde")]
#[test]
fn a_corrupted_checkpoint_is_an_error_or_consistent() {
    let good = serde_json::to_value(KalmanFilter::new(
        Gaussian::new(DVector::<f64>::zeros(2), DMatrix::identity(2, 2)).unwrap(),
    ))
    .unwrap();
    proptest!(config(), |(n in 0..5usize, state_rows in claimed(), len in 0..17usize, rows in claimed(), cols in claimed())| {
        let state = stored(n, state_rows, None);
        let covariance = stored(len, rows, Some(cols));
        let mut filter = good.clone();
        filter["state"] = state.clone();
        filter["covariance"] = covariance.clone();
        let gaussian = serde_json::json!({ "mean": state, "covariance": covariance });
        let (filter, gaussian) = (filter.to_string(), gaussian.to_string());
        let restored = catch_unwind(|| {
            serde_json::from_str::<estim_filters::GaussianFilter<f64, Dyn, estim_core::Affine>>(&filter)
        });
        let Ok(restored) = restored else {
            return Err(TestCaseError::fail(format!("panic restoring {filter}")));
        };
        if let Ok(f) = restored {
            use estim_filters::Estimator;
            let n = f.state().len();
            prop_assert_eq!(f.covariance().shape(), (n, n));
            prop_assert_eq!(f.covariance().len(), len);
        }
        let mut report = serde_json::to_value(UpdateReport::<f64, Dyn>::zeros(Dyn(2))).unwrap();
        report["innovation"] = stored(n, state_rows, None);
        report["innovation_covariance"] = stored(len, rows, Some(cols));
        let report = report.to_string();
        let restored = catch_unwind(|| serde_json::from_str::<UpdateReport<f64, Dyn>>(&report));
        let Ok(restored) = restored else {
            return Err(TestCaseError::fail(format!("panic restoring {report}")));
        };
        if let Ok(r) = restored {
            prop_assert_eq!(r.innovation_covariance.len(), len);
            prop_assert_eq!(r.innovation.len(), n);
        }
        let restored = catch_unwind(|| serde_json::from_str::<Gaussian<f64, Dyn>>(&gaussian));
        let Ok(restored) = restored else {
            return Err(TestCaseError::fail(format!("panic restoring {gaussian}")));
        };
        if let Ok(g) = restored {
            let n = g.mean().len();
            prop_assert_eq!(g.covariance().shape(), (n, n));
            prop_assert_eq!(g.covariance().len(), len);
        }
    });
}
