//! The `plaza_range` example on a short slice of the vendored Plaza run (the robot at rest,
//! then its first few minutes of driving), and its reader on bad recordings.

use std::path::PathBuf;

use crate::plaza_range::data::{DataError, load, read, write_csv};
use crate::plaza_range::model::MAX_BEACONS;
use crate::plaza_range::{Config, run_config, vendored};

/// The slice: the first 300 s (48 s at rest, then about 250 m driven), the EKF with its
/// smoother, the iterated EKF and the particle filter at the example's 1000 particles; no
/// UKF, no white-noise comparisons, no figures.
fn slice() -> Config {
    Config {
        seconds: Some(300.0),
        ukf: false,
        white_noise_models: false,
        figures: false,
        ..Config::full(vendored())
    }
}

#[test]
fn short_slice_localises_from_ranges_and_the_smoother_is_best() {
    let r = run_config(&slice()).unwrap();
    // The start comes from the ranges, not the ground truth: within 2 m and 15° of it (the
    // fit's own σ, with the per-beacon biases' share, is about 1 m and 4°).
    assert!(r.start_error.0 < 2.0, "{:?}", r.start_error);
    assert!(r.start_error.1.abs() < 15.0, "{:?}", r.start_error);
    let smoother = r.ekf.smoothed.as_ref().unwrap().1;
    let iekf = r.iekf.as_ref().unwrap().score;
    let particle = r.particle.as_ref().unwrap().score;
    // The whole-run target for the smoother (1.1 m) holds on the slice, and the
    // smoother, which uses every range for every estimate, beats each filter.
    assert!(smoother.rmse <= 1.1, "{smoother:?}");
    for filter in [r.ekf.score, iekf, particle] {
        assert!(smoother.rmse < filter.rmse, "{smoother:?} vs {filter:?}");
    }
    // The Kalman filters localise to better than 2 m RMS over the slice (its first minutes
    // carry the start's error: 1.7 m off the ground truth, 1.45 m RMS on the slice, 1.1 m over
    // the whole run), and are consistent, not only accurate: each estimate's own 3σ covers at
    // least 95 % of the position errors (99.7 % for a Gaussian error; the ground truth is a
    // GPS with its own errors).
    for s in [smoother, r.ekf.score, iekf] {
        assert!(s.rmse < 2.0, "{s:?}");
        assert!(s.coverage.unwrap() >= 0.95, "{s:?}");
    }
    // The particle filter is particle-limited in its 8 live dimensions (pose, common bias,
    // four beacon biases), and on this slice its result depends on the seed: over 53 seeds at
    // 1000 particles (38, 1-52) the coverage has median 0.85 and ranges 0.51-1.00, the RMSE
    // 1.23-2.47 m (at 500 particles, 25 seeds: coverage 0.19-0.93, RMSE up to 3.5 m, so that
    // count is not tested). The RMSE bound holds for all 53 seeds, the coverage bound for 51:
    // a change to the filter that redraws its particles but keeps its statistics passes about
    // 24 times in 25. A coverage of 0.55 is what a Gaussian error gets from a σ understated
    // 3.6 times (P(|z| < 3/3.6)): a filter that much more overconfident fails (the PF here,
    // seed 38: 0.77).
    assert!(particle.rmse < 2.5, "{particle:?}");
    assert!(particle.coverage.unwrap() >= 0.55, "{particle:?}");
    // The NIS of the range updates: 1 for a consistent 1-D sensor; the bias states keep it
    // within [0.5, 2] where a white range model is far off (the full run's comparison).
    let u = r.ekf.updates.unwrap();
    assert!((0.5..=2.0).contains(&u.mean_nis), "{u:?}");
    // Outliers exist but are few: at most 5 % gated.
    assert!(u.gated_fraction() <= 0.05, "{u:?}");
}

/// The same recording with other beacon ids, listed in another order, and every position
/// (beacons, ground truth) moved by a constant offset; the odometry is relative and stays.
/// None of that is information an estimate may depend on: the EKF, its smoother and dead
/// reckoning must give the same RMSE, coverage and NIS, and the same bias per beacon.
///
/// Tolerance 10⁻⁹ m: every value is written exactly (`{}` of an f64 reads back to the same
/// f64), so the differences are the rounding of coordinates near 10³ m instead of 10¹ m,
/// about 10⁻¹³ m per value; over the whole run they stay at 10⁻¹³ m. A filter that used an id,
/// the survey's order or the absolute position would be off by centimetres or more.
#[test]
fn relabelled_reordered_and_moved_beacons_give_the_same_run() {
    let source = vendored();
    let dir = scratch("transformed");
    let (dx, dy) = (1234.5, -789.25);
    // 0, 1, 5, 6 → 100, 93, 65, 58: distinct, none of the old ids.
    let id = |old: f64| 100.0 - 7.0 * old;
    let table =
        |name: &str, columns: usize, timed: bool| read(&source, name, columns, timed).unwrap();
    let lines = |rows: Vec<String>| rows.join("\n") + "\n";
    let mut survey: Vec<String> = table("TL", 3, false)
        .rows
        .iter()
        .map(|r| format!("{},{},{}", id(r[0]), r[1] + dx, r[2] + dy))
        .collect();
    survey.reverse();
    write_csv(&dir, "TL", &lines(survey)).unwrap();
    let truth = table("GT", 4, true)
        .rows
        .iter()
        .map(|r| format!("{},{},{},{}", r[0], r[1] + dx, r[2] + dy, r[3]))
        .collect();
    write_csv(&dir, "GT", &lines(truth)).unwrap();
    // In the file's own order (it steps back in time twice; the reader sorts it).
    let ranges = table("TD", 4, false)
        .rows
        .iter()
        .map(|r| format!("{},{},{},{}", r[0], r[1], id(r[2]), r[3]))
        .collect();
    write_csv(&dir, "TD", &lines(ranges)).unwrap();
    let odometry = table("DR", 3, true)
        .rows
        .iter()
        .map(|r| format!("{},{},{}", r[0], r[1], r[2]))
        .collect();
    write_csv(&dir, "DR", &lines(odometry)).unwrap();

    // 120 s: 48 s at rest, the start fit over the first 20 m driven, a minute of tracking.
    let fast = |data: PathBuf| Config {
        seconds: Some(120.0),
        ukf: false,
        iekf: false,
        particle: false,
        white_noise_models: false,
        figures: false,
        ..Config::full(data)
    };
    let a = run_config(&fast(source)).unwrap();
    let b = run_config(&fast(dir.clone())).unwrap();
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9;
    let (sa, sb) = (
        a.ekf.smoothed.as_ref().unwrap().1,
        b.ekf.smoothed.as_ref().unwrap().1,
    );
    for (x, y) in [
        (a.dead_reckoning.1, b.dead_reckoning.1),
        (a.ekf.score, b.ekf.score),
        (sa, sb),
    ] {
        assert!(close(x.rmse, y.rmse), "{x:?} vs {y:?}");
        assert_eq!(x.coverage.is_some(), y.coverage.is_some());
        assert!(
            close(x.coverage.unwrap_or(0.0), y.coverage.unwrap_or(0.0)),
            "{x:?} vs {y:?}"
        );
    }
    let (ua, ub) = (a.ekf.updates.unwrap(), b.ekf.updates.unwrap());
    assert_eq!((ua.applied, ua.gated), (ub.applied, ub.gated));
    assert!(close(ua.mean_nis, ub.mean_nis), "{ua:?} vs {ub:?}");
    // The biases: the common one, then one per beacon in the survey's order (here reversed).
    let mut per_beacon = b.ekf.biases[1..].to_vec();
    per_beacon.reverse();
    assert!(
        close(a.ekf.biases[0], b.ekf.biases[0]),
        "{:?} vs {:?}",
        a.ekf.biases,
        b.ekf.biases
    );
    for (x, y) in a.ekf.biases[1..].iter().zip(&per_beacon) {
        assert!(close(*x, *y), "{:?} vs {:?}", a.ekf.biases, b.ekf.biases);
    }
    // And the scores are not trivially equal: the run localised.
    assert!(sa.rmse > 0.0 && sa.rmse < 2.0, "{sa:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scratch folder of this test process.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("estim-plaza-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A tiny well-formed recording: two beacons, three odometry rows, two ranges.
fn tiny(dir: &std::path::Path) {
    write_csv(dir, "TL", "0,0,0\n1,10,0\n").unwrap();
    write_csv(dir, "GT", "0.0,1,1,0\n0.2,1.1,1,0\n0.4,1.2,1,0\n").unwrap();
    write_csv(dir, "DR", "0.0,0,0\n0.2,0.1,0\n0.4,0.1,0\n").unwrap();
    write_csv(dir, "TD", "0.1,2,0,1.5\n0.3,2,1,9.0\n").unwrap();
}

#[test]
fn a_nan_row_is_named_by_file_line_and_column() {
    let dir = scratch("nan");
    tiny(&dir);
    write_csv(&dir, "TD", "0.1,2,0,1.5\n0.3,2,1,NaN\n").unwrap();
    let err = load(&dir).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::Value {
                line: 2,
                column: 4,
                ..
            }
        ),
        "{err:?}"
    );
    // Through the example's run too, with a message naming the file and the line.
    let err = run_config(&Config::full(dir.clone()))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("TD.csv line 2") && err.contains("NaN"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_time_going_backwards_is_named_by_file_and_line() {
    let dir = scratch("backwards");
    tiny(&dir);
    write_csv(&dir, "DR", "0.0,0,0\n0.2,0.1,0\n0.1,0.1,0\n").unwrap();
    let err = load(&dir).unwrap_err();
    assert!(
        matches!(err, DataError::Backwards { line: 3, .. }),
        "{err:?}"
    );
    let err = run_config(&Config::full(dir.clone()))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("DR.csv line 3"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_missing_file_or_a_bad_beacon_is_named() {
    let dir = scratch("missing");
    tiny(&dir);
    std::fs::remove_file(dir.join("GT.csv")).unwrap();
    let err = run_config(&Config::full(dir.clone())).err().unwrap();
    let data = err.downcast_ref::<DataError>().unwrap();
    assert!(
        matches!(data, DataError::Missing { file } if file.ends_with("GT.csv")),
        "{data:?}"
    );
    assert!(err.to_string().contains("GT.csv"), "{err}");
    // A range from a beacon the survey does not list.
    tiny(&dir);
    write_csv(&dir, "TD", "0.1,2,0,1.5\n0.3,2,7,9.0\n").unwrap();
    let err = load(&dir).unwrap_err();
    assert!(
        matches!(err, DataError::Beacon { line: 2, id, .. } if id == 7.0),
        "{err:?}"
    );
    // More beacons than the state has room for: the first one too many is named.
    let survey: String = (0..=MAX_BEACONS).map(|i| format!("{i},{i},0\n")).collect();
    write_csv(&dir, "TL", &survey).unwrap();
    let err = load(&dir).unwrap_err();
    assert!(
        matches!(err, DataError::Beacon { line, .. } if line == MAX_BEACONS + 1),
        "{err:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
