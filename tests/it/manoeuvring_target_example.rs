//! The `manoeuvring_target` example in small form (30 runs × 150 steps, its seed): the CV/CT
//! IMM beats both single-model filters, its NEES is nearer its χ² mean, and its smoother
//! beats it; the CT-mode probability's calibration as measured.

use crate::manoeuvring_target::{STEPS, calibration, mean, monte_carlo};

const RUNS: usize = 30;

#[test]
fn the_imm_beats_single_models_and_its_smoother_beats_it() {
    let s = monte_carlo(RUNS, 0x1aa5).unwrap();
    let rmse: Vec<f64> = s.tracks.iter().map(|t| mean(&t.rmse(RUNS))).collect();
    let nees: Vec<f64> = s
        .tracks
        .iter()
        .map(|t| mean(&t.average_nees(RUNS)))
        .collect();
    eprintln!("RMSE {rmse:.3?}, NEES {nees:.3?}");
    // Measured (30 runs): RMSE CV 6.86, CT 13.6, IMM 4.13, smoother 2.14 m; the average NEES
    // 18.4, 276 and 6.15 (χ² mean 4: |ln(NEES/4)| 1.53, 4.2, 0.43). The orderings are what
    // the example shows; each bound sits between the measured values (4.13 < 0.8 · 6.86 =
    // 5.5, 2.14 < 0.7 · 4.13 = 2.9, 0.43 < 0.5 · 1.53), a regression guard.
    assert!(
        rmse[2] < 0.8 * rmse[0] && rmse[2] < 0.5 * rmse[1],
        "{rmse:?}"
    );
    assert!(rmse[3] < 0.7 * rmse[2], "{rmse:?}");
    let distance = |n: f64| (n / 4.0).ln().abs();
    assert!(distance(nees[2]) < 0.5 * distance(nees[0]), "{nees:?}");
    assert!(distance(nees[2]) < 0.5 * distance(nees[1]), "{nees:?}");
    let (filter, smoother) = (s.tracks[2].rmse(RUNS), s.tracks[3].rmse(RUNS));
    let better = filter.iter().zip(&smoother).filter(|(f, s)| s < f).count();
    eprintln!(
        "smoother below the IMM at {better} of {STEPS} times; clipped {}",
        s.clipped
    );
    // Measured 140 of 150 (the times it is not are at the very end, where the smoothed
    // estimate tends to the filtered one, and at turn onsets).
    assert!(better >= STEPS * 8 / 10, "{better}");
    assert_eq!(s.kim_fallbacks, 0);
}

#[test]
fn the_ct_probability_is_ordered_but_biased_high_at_low_values() {
    let s = monte_carlo(RUNS, 0x1aa5).unwrap();
    let bins = calibration(&s, 5);
    eprintln!("{bins:#?}");
    // The frequency of the true CT mode rises with the stated probability p̄ …
    for pair in bins.windows(2) {
        assert!(pair[0].frequency < pair[1].frequency, "{bins:?}");
    }
    // … but is below it at low p̄: measured 0.071 at p̄ = 0.120 (30 runs; 0.071 at 0.121
    // with 200), 8 binomial σ, and 0.167 at 0.277 (the Markov prior and a CT mode with ω ≈ 0 keep CT's share on
    // straight legs). This pins the bias the example reports; a calibrated IMM would fail it.
    assert!(
        bins[0].mean_probability - bins[0].frequency > 5.0 * bins[0].sigma,
        "{bins:?}"
    );
    // At p̄ ≈ 0.9 it is right within 0.05 (measured 0.914 against 0.893; 0.896 against 0.896
    // with 200 runs).
    assert!(
        (bins[4].mean_probability - bins[4].frequency).abs() < 0.05,
        "{bins:?}"
    );
}
