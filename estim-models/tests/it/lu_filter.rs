//! Lu: the multi-rate filter against the paper's listing written out by hand (E9), the
//! framework's Joseph-form covariance against the information form, the gains (E12), the
//! covariance analysis (exact moments of the Monte Carlo checks) and the paper's residual
//! matrix (E11).

use estim_models::lu::{
    FilterSettings, GpsMeasurement, LuFilter, Mechanisation, PAPER_RESIDUAL_CORRELATION, Scenario,
    covariance_analysis, covariance_history, noise_input, simulate, transition_matrix,
};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

/// The listing of §2.6 with E9 corrected, in plain nalgebra: at step j, if a fix is available
/// P = (M⁻¹ + Hᵀ V⁻¹ H)⁻¹, K = P Hᵀ V⁻¹, x̂ = x̄ + K(δz − H x̄), else x̂ = x̄, P = M; then
/// x̄ ← Φ x̂, M ← Φ P Φᵀ + Γ W Γᵀ. Fixes at j = 40, 80, …; the mechanisation alongside.
/// Returns (x̂, P) after every fix.
fn hand_written_listing(scenario: &Scenario, seed: u64) -> Vec<(Vector3<f64>, Matrix3<f64>)> {
    let record = simulate(scenario, seed).unwrap();
    let dt = scenario.dt;
    let phi = transition_matrix(dt, Default::default());
    let g = noise_input(dt);
    let q = g * g.transpose() * scenario.accel_noise_variance;
    let h = GpsMeasurement::observation();
    let v_inv = Matrix2::new(
        1.0 / scenario.gps_position_variance,
        0.0,
        0.0,
        1.0 / scenario.gps_velocity_variance,
    );
    let mut x_bar = Vector3::zeros();
    let mut m = scenario.error_prior_covariance();
    let mut mech = Mechanisation::new(scenario.position_mean, scenario.velocity_mean);
    let mut fixes = record.gps.iter().peekable();
    let mut out = Vec::new();
    for j in 0..=scenario.steps {
        let (x_hat, p) = match fixes.peek() {
            Some((step, z)) if *step == j => {
                let dz = Vector2::new(z[0] - mech.position, z[1] - mech.velocity);
                let p = (m.try_inverse().unwrap() + h.transpose() * v_inv * h)
                    .try_inverse()
                    .unwrap();
                let k = p * h.transpose() * v_inv;
                let x_hat = x_bar + k * (dz - h * x_bar);
                fixes.next();
                out.push((x_hat, p));
                (x_hat, p)
            }
            _ => (x_bar, m),
        };
        if j == scenario.steps {
            break;
        }
        x_bar = phi * x_hat;
        m = phi * p * phi.transpose() + q;
        mech.step(record.accelerometer[j], dt);
    }
    out
}

/// The framework filter (KalmanFilter on ErrorStateProcess/GpsMeasurement, Joseph update, fed
/// the GPS fix every 40th step) reproduces the listing's estimate and covariance at all 150
/// fixes of two realizations.
#[test]
fn multi_rate_filter_matches_the_hand_written_listing() {
    let scenario = Scenario::paper();
    let settings = FilterSettings::consistent(&scenario);
    for seed in [5, 6] {
        let reference = hand_written_listing(&scenario, seed);
        let record = simulate(&scenario, seed).unwrap();
        let mut filter = LuFilter::new(&scenario, &settings).unwrap();
        let mut fixes = record.gps.iter();
        let mut k = 0;
        for j in 0..scenario.steps {
            filter.propagate(record.accelerometer[j]).unwrap();
            if (j + 1) % scenario.gps_every == 0 {
                let (step, z) = fixes.next().unwrap();
                assert_eq!(*step, j + 1);
                filter.update(z).unwrap();
                let (x_ref, p_ref) = &reference[k];
                let x = filter.error_estimate();
                let p = filter.covariance();
                // Information form vs Joseph form: both exact; they differ by round-off
                // amplified by the conditioning of M (entries from 1e2 to 1e-7): 1e-8 relative
                // per entry, measured against the diagonal scale.
                for i in 0..3 {
                    let sx = p_ref[(i, i)].sqrt();
                    assert!(
                        (x[i] - x_ref[i]).abs() < 1e-6 * sx,
                        "fix {k}, component {i}: {} vs {}",
                        x[i],
                        x_ref[i]
                    );
                    for l in 0..3 {
                        let scale = (p_ref[(i, i)] * p_ref[(l, l)]).sqrt();
                        assert!(
                            (p[(i, l)] - p_ref[(i, l)]).abs() < 1e-8 * scale,
                            "fix {k}, P[{i},{l}]: {} vs {}",
                            p[(i, l)],
                            p_ref[(i, l)]
                        );
                    }
                }
                k += 1;
            }
        }
        assert_eq!(k, 150);
        // The estimates in navigation terms.
        let est = filter.estimate();
        let truth = record.truth[scenario.steps];
        let sigma = filter.covariance().diagonal().map(f64::sqrt);
        for (i, t) in [truth.position, truth.velocity, truth.bias]
            .iter()
            .enumerate()
        {
            // One realization: within 4.5 σ (a consistent filter exceeds it with p ≈ 7e-6).
            assert!(
                (est[i] - t).abs() < 4.5 * sigma[i],
                "{i}: {} vs {t}",
                est[i]
            );
        }
    }
}

/// √P at 30 s and the gains: the deterministic values, by the information form (the paper's)
/// and the framework filter (Joseph), agree; the bias gains vanish and K₁₂ is the largest (E12).
#[test]
fn only_the_bias_gains_vanish() {
    let scenario = Scenario::paper();
    let settings = FilterSettings::consistent(&scenario);
    let h = covariance_history(&scenario, &settings, scenario.steps).unwrap();
    let sigma = h.sigma(h.index_at(30.0));
    // Reference √P(30 s) from the research notes (numpy, independent code): 0.0976 m,
    // 0.00692 m/s, 4.68e-4 m/s², printed to 3 digits.
    for (s, r) in sigma.iter().zip([0.0976, 0.00692, 4.68e-4]) {
        assert!((s / r - 1.0).abs() < 2e-3, "{s} vs {r}");
    }
    let long = scenario.with_duration(3000.0);
    let hl = covariance_history(&long, &settings, long.steps).unwrap();
    let k = hl.gain[hl.gain.len() - 1];
    // Notes (numpy Riccati to 3000 s): K11 0.0075, K12 0.1319, K21 0.0002, K22 0.0148.
    for ((i, j), r, tol) in [
        ((0, 0), 0.0075, 0.01),
        ((0, 1), 0.1319, 0.005),
        ((1, 0), 0.0002, 0.1),
        ((1, 1), 0.0148, 0.01),
    ] {
        assert!(
            (k[(i, j)] / r - 1.0).abs() < tol,
            "K[{i},{j}] = {}",
            k[(i, j)]
        );
    }
    // Bias row: no process noise on b, so P_bb → 0 like 1/t and its gains with it.
    let k30 = h.gain[h.index_at(30.0)];
    assert!(k[(2, 0)].abs() < 1e-6 && k[(2, 1)].abs() < 1e-4, "{k}");
    assert!(k[(2, 1)].abs() < 0.1 * k30[(2, 1)].abs());
    let largest = k.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert_eq!(largest, k[(0, 1)].abs());

    // The framework filter's P at every fix equals the information-form P.
    let mut filter = LuFilter::new(&scenario, &settings).unwrap();
    let record = simulate(&scenario, 0).unwrap();
    let mut fixes = record.gps.iter();
    for j in 0..scenario.steps {
        filter.propagate(record.accelerometer[j]).unwrap();
        if (j + 1) % scenario.gps_every == 0 {
            filter.update(&fixes.next().unwrap().1).unwrap();
            let i = (j + 1) / scenario.gps_every;
            let (p, p_ref) = (filter.covariance(), &h.posterior[i]);
            for a in 0..3 {
                let rel = (p[(a, a)] / p_ref[(a, a)] - 1.0).abs();
                assert!(rel < 1e-8, "fix {i} P[{a},{a}]: {rel:e}");
            }
            let g = filter.gain();
            assert!((g - h.gain[i]).abs().max() < 1e-8 * h.gain[i].abs().max());
        }
    }
}

/// The covariance analysis of the consistent filter: cov(e) = P and cov(e, δx̂) = 0 at every
/// fix (the two properties the Monte Carlo checks estimate), and E e = 0.
#[test]
fn covariance_analysis_of_the_consistent_filter() {
    let scenario = Scenario::paper();
    let a = covariance_analysis(&scenario, &FilterSettings::consistent(&scenario)).unwrap();
    assert_eq!(a.time.len(), 151);
    for k in 1..a.time.len() {
        // Round-off of the 6 × 6 recursion relative to the variances (ratios within 1e-7).
        let r = a.covariance_ratio(k);
        assert!(
            (r - Vector3::repeat(1.0)).abs().max() < 1e-7,
            "fix {k}: {r}"
        );
        assert!(a.max_orthogonality(k) < 1e-7, "fix {k}");
        assert_eq!(a.mean_error[k], Vector3::zeros());
    }
}

/// The exact effect of each printed variant (what the Monte Carlo of the paper would show with
/// infinitely many runs).
#[test]
fn covariance_analysis_of_printed_variants() {
    let s = Scenario::paper();
    let end = |f: FilterSettings, sc: Scenario| {
        let a = covariance_analysis(&sc, &f).unwrap();
        let n = a.time.len() - 1;
        let max_ratio = (1..=n)
            .map(|k| a.covariance_ratio(k))
            .fold(Vector3::repeat(0.0), |m, r| m.sup(&r));
        let max_orth = (1..=n).map(|k| a.max_orthogonality(k)).fold(0.0, f64::max);
        let max_mean = (1..=n)
            .map(|k| a.mean_error[k].abs())
            .fold(Vector3::zeros(), |m, v| m.sup(&v));
        (a.covariance_ratio(n), max_ratio, max_orth, max_mean, a)
    };
    // E3: W = 0.0016 in the filter: P too large in δv, b (cov(e)/P at 30 s ≈ 0.77, 0.49).
    let (r, _, _, _, _) = end(FilterSettings::printed_noise(&s), s);
    assert!(
        (r[0] - 1.0).abs() < 1e-3 && (0.74..0.79).contains(&r[1]) && (0.47..0.51).contains(&r[2]),
        "{r}"
    );
    // E2: M₀ = diag(1, 100, 0.01): δp variance 50× the filter's at the first fix.
    let (_, max_ratio, orth, _, _) = end(FilterSettings::printed_prior(&s), s);
    assert!(max_ratio[0] > 40.0 && orth > 0.9, "{max_ratio} {orth}");
    // E4: printed Φ₁₃: covariances within 0.5 %, but the δp error correlates with b̂ (≈ −0.068
    // at 30 s): the bias the filter propagates with the wrong sign accumulates as −Δt² b̂ per step.
    let (r, _, orth, _, a) = end(FilterSettings::printed_coupling(&s), s);
    assert!((r - Vector3::repeat(1.0)).abs().max() < 5e-3, "{r}");
    assert!((0.06..0.075).contains(&orth), "{orth}");
    let c = a.orthogonality_correlation(a.time.len() - 1);
    assert!(c[(0, 2)] < -0.06, "{c}");
    // E5: closed-form truth: unbiased no more; δv mean error up to ≈ 0.03 m/s, several σ.
    let (r, _, orth, mean, a) = end(
        FilterSettings::consistent(&s),
        s.with_truth(estim_models::lu::TruthIntegration::Exact),
    );
    assert!((r - Vector3::repeat(1.0)).abs().max() < 1e-7 && orth < 1e-7);
    assert!((0.02..0.04).contains(&mean[1]), "{mean}");
    let sigmas = (1..a.time.len())
        .map(|k| (a.mean_error[k][1] / a.filter_covariance[k][(1, 1)].sqrt()).abs())
        .fold(0.0, f64::max);
    assert!(sigmas > 3.0, "{sigmas}");
}

/// E11: with the paper's N = 5000, the standard errors of (1/N) Σ r(20) r(30)ᵀ for white
/// residuals are √(S₂₀ᵢᵢ S₃₀ⱼⱼ / N); the printed matrix is 3.4, 4.0, 0.3 and 8.5 of them.
#[test]
fn paper_residual_matrix_is_not_white() {
    let s = Scenario::paper();
    let h = covariance_history(&s, &FilterSettings::consistent(&s), s.steps).unwrap();
    let obs = GpsMeasurement::observation();
    let v = s.gps().noise_covariance();
    let innovation = |t: f64| obs * h.prior[h.index_at(t)] * obs.transpose() + v;
    let (s20, s30) = (innovation(20.0), innovation(30.0));
    let se = Matrix2::from_fn(|i, j| (s20[(i, i)] * s30[(j, j)] / 5000.0).sqrt());
    // Notes: SE ≈ [[0.0144, 0.0006], [0.0006, 2.4e-5]].
    assert!(
        (se[(0, 0)] - 0.0143).abs() < 2e-4 && (se[(1, 1)] - 2.35e-5).abs() < 1e-6,
        "{se}"
    );
    let paper = Matrix2::from_fn(|i, j| PAPER_RESIDUAL_CORRELATION[i][j]);
    let z = paper.component_div(&se);
    assert!(
        z[(0, 0)] > 3.0 && z[(0, 1)].abs() > 3.5 && z[(1, 1)] > 8.0,
        "{z}"
    );
    assert!(z[(1, 0)].abs() < 1.0);
}

/// A non-finite accelerometer sample is a typed error at `propagate`, with the filter
/// unchanged: before, it returned `Ok`, turned the mechanisation into NaN, and every later
/// update failed blaming the GPS fix.
#[test]
fn a_non_finite_acceleration_is_refused_at_once() {
    let scenario = Scenario::paper();
    let mut filter = LuFilter::new(&scenario, &FilterSettings::consistent(&scenario)).unwrap();
    filter.propagate(0.01).unwrap();
    let before = filter.clone();
    for a in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert_eq!(
            filter.propagate(a),
            Err(estim_core::Error::NonFinite {
                stage: estim_core::Stage::Prediction,
                quantity: estim_core::Quantity::Measurement,
            })
        );
        assert_eq!(filter, before);
    }
    filter.propagate(0.02).unwrap();
    assert!(filter.update(&Vector2::new(0.1, 0.01)).is_ok());
}
