//! The `flight_ins` example on a short slice of the vendored ArduPilot flight (the alignment,
//! the ground run, and the first 30 s above 8 m/s), and its reader on bad recordings.

use std::path::PathBuf;

use crate::flight_ins::log::{LogError, read_table, write_gz};
use crate::flight_ins::{Config, run_config, vendored};

/// The slice: the EKF with the GPS at its time of validity and on arrival, no UKF, no figures.
fn slice() -> Config {
    Config {
        flight_seconds: Some(30.0),
        ukf: false,
        figures: false,
        ..Config::full(vendored())
    }
}

#[test]
fn short_slice_agrees_with_the_autopilot_and_latency_matters() {
    let result = run_config(&slice()).unwrap();
    let (a, b) = result.airborne.expect("the slice reaches 8 m/s");
    assert!(b - a > 25.0, "airborne slice {a}-{b} s");
    let air = result.ekf.windows.airborne.unwrap();
    // The airborne targets for the whole flight (median 0.7°, p95 2°, NE position
    // 0.8 m, NE velocity 0.3 m/s RMS against EKF3 core 0), which are also below EKF3's own
    // core-to-core spread in attitude (median 1.4°, p95 3.4° over the flight).
    assert!(air.attitude_median <= 0.7, "{air:?}");
    assert!(air.attitude_p95 <= 2.0, "{air:?}");
    assert!(air.ne_position_rms <= 0.8, "{air:?}");
    assert!(air.ne_velocity_rms <= 0.3, "{air:?}");
    // The filter's 3σ covers at least 90 % of the errors per component (a consistent filter
    // covers 99.7 %; the reference has its own errors, so some misses are the reference's).
    let coverage = air.coverage.unwrap();
    assert!(coverage.iter().all(|c| *c >= 0.9), "{coverage:?}");
    // GPS fused on arrival, 0.15 s late at up to 39 m/s: several metres of along-track lag.
    let late = result
        .latency_ignored
        .as_ref()
        .unwrap()
        .windows
        .airborne
        .unwrap();
    assert!(
        late.ne_position_rms > 2.0 * air.ne_position_rms,
        "{late:?} vs {air:?}"
    );
    assert!(
        late.ne_velocity_rms > 1.5 * air.ne_velocity_rms,
        "{late:?} vs {air:?}"
    );
}

/// A scratch folder of this test process.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("estim-flight-ins-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const HEADER: &str = "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ\n";
const COLUMNS: [&str; 8] = [
    "TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ",
];

#[test]
fn a_nan_row_is_named_by_file_line_and_column() {
    let dir = scratch("nan");
    let text = format!("{HEADER}1000,0,0,0,0,0,0,-9.8\n21000,0,0,nan,0,0,0,-9.8\n");
    write_gz(&dir, "IMU", &text).unwrap();
    let err = read_table(&dir, "IMU", &COLUMNS).unwrap_err();
    assert!(
        matches!(&err, LogError::Value { line: 3, column, .. } if column == "GyrY"),
        "{err:?}"
    );
    // Through the example's run too, with a message naming the file and line.
    let err = run_config(&Config::full(dir.clone()))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("IMU.csv.gz line 3") && err.contains("GyrY"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_time_going_backwards_is_named_by_file_and_line() {
    let dir = scratch("backwards");
    let text =
        format!("{HEADER}1000,0,0,0,0,0,0,-9.8\n21000,0,0,0,0,0,0,-9.8\n11000,0,0,0,0,0,0,-9.8\n");
    write_gz(&dir, "IMU", &text).unwrap();
    let err = read_table(&dir, "IMU", &COLUMNS).unwrap_err();
    assert!(
        matches!(err, LogError::Backwards { line: 4, .. }),
        "{err:?}"
    );
    let err = run_config(&Config::full(dir.clone()))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("IMU.csv.gz line 4"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_missing_file_or_column_is_named() {
    let dir = scratch("missing");
    write_gz(
        &dir,
        "IMU",
        &format!("{HEADER}1000,0,0,0,0,0,0,-9.8\n21000,0,0,0,0,0,0,-9.8\n"),
    )
    .unwrap();
    // IMU is there, GPS is not.
    let err = run_config(&Config::full(dir.clone())).err().unwrap();
    let log = err.downcast_ref::<LogError>().unwrap();
    assert!(
        matches!(log, LogError::Missing { file } if file.ends_with("GPS.csv.gz")),
        "{log:?}"
    );
    assert!(err.to_string().contains("GPS.csv.gz"), "{err}");
    let err = read_table(&dir, "IMU", &["TimeUS", "Gyr"]).unwrap_err();
    assert!(
        matches!(&err, LogError::Column { column, .. } if column == "Gyr"),
        "{err:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// EKF3's step by ArduPilot's rule (n samples, n the smallest with n T ≥ 12 ms − T/2): worked
/// by hand for the loop rates ArduPilot runs at.
#[test]
fn ekf3_step_follows_the_autopilots_accumulation_rule() {
    use crate::flight_ins::ekf3_step;
    for (rate, step) in [(50.0, 0.02), (100.0, 0.01), (200.0, 0.01), (400.0, 0.0125)] {
        let got = ekf3_step(1.0 / rate);
        assert!(
            (got - step).abs() < 1e-12,
            "{rate} Hz: {got} s, not {step} s"
        );
    }
}
