//! `flight_ins` (estim's own extension, issue 38): the strapdown INS of `estim_models::nav`
//! over a real ArduPilot flight, GPS position and velocity fused at the time each fix was taken
//! through the fusion driver (IMU samples as inputs covering the interval before them,
//! `InputConvention::Preceding`), with an EKF and a UKF, compared with the autopilot's own EKF3.
//!
//! Everything specific to a recording is read from it: the origin (the ORGN home row, else the
//! first 3-D fix), the noise settings (PARM's EKF3 values, see [`Settings`]), the GPS latency
//! (PARM `GPS_DELAY_MS` when non-zero, else the maximum-likelihood latency of the GPS fixes
//! given the IMU, [`GPS_DELAY_GRID`]), the IMU period and the samples' lag (PARM
//! `INS_GYRO_FILTER`, [`Settings::imu_lag`]), the alignment (the first
//! [`Config::align_s`] seconds, checked to be at rest) and the airborne window (first to last GPS
//! speed above 8 m/s).

//!
//! Results, and the same code on other IMUs and rates: the example's docs
//! (`examples/flight_ins.rs`).

pub mod log;
mod report;

pub use report::{json, run};

use std::path::{Path, PathBuf};
use std::time::Instant;

use estim_core::nalgebra::{
    Const, Matrix3, Quaternion, SMatrix, SVector, UnitQuaternion, Vector2, Vector3,
};
use estim_core::{Gaussian, error::Result as CoreResult};
use estim_filters::fusion::{
    FusionDriver, FusionSettings, Innovation, InputConvention, SensorSet, SensorSettings,
};
use estim_filters::{Ekf, Estimator, Predict, Rollback, Ukf, Update};
use estim_models::nav::{
    ATTITUDE, GYRO_BIAS, GnssPosition, GnssVelocity, Imu, InsSettings, Origin, POSITION, Strapdown,
    VELOCITY, attitude, state_space, static_alignment,
};
use serde_json::{Value, json};

use log::{LogError, Table, read_parameters, read_table};

/// GPS speed above which the vehicle counts as airborne [m/s] (the definition).
pub const AIRBORNE_SPEED: f64 = 8.0;

/// The GPS latencies tried when neither `--gps-delay` nor PARM's `GPS_DELAY_MS` gives one [s]:
/// 0 to 0.3 s (receivers report 0.1-0.25 s; ArduPilot assumes 0.12 s for a u-blox M8, 0.22 s
/// for an unknown one) in 0.02 s steps. The run then takes the latency whose EKF run has the
/// largest GPS log-likelihood, Σ log N(ν; 0, S) over the fixes: a maximum-likelihood estimate
/// from the recording itself (IMU and GPS only; the autopilot's estimates are not used).
pub const GPS_DELAY_GRID: (f64, f64, usize) = (0.0, 0.02, 16);

/// Where the GPS latency came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DelaySource {
    /// `--gps-delay` ([`Config::gps_delay`]).
    Flag,
    /// PARM's `GPS_DELAY_MS`.
    Parameter,
    /// The maximum-likelihood estimate over [`GPS_DELAY_GRID`].
    Likelihood,
}

/// The vendored recording: `examples/data/ardupilot-p23`.
pub fn vendored() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/ardupilot-p23")
}

/// What to run.
#[derive(Clone, Debug)]
pub struct Config {
    /// The folder holding `IMU.csv.gz`, `GPS.csv.gz`, `MAG.csv.gz`, `XKQ.csv.gz`, `XKF1.csv.gz`
    /// and optionally `PARM.csv.gz`, `ORGN.csv.gz`.
    pub data: PathBuf,
    /// Stop this many seconds after the airborne window starts (the tests' short slice);
    /// `None`: the whole log.
    pub flight_seconds: Option<f64>,
    /// Also run the UKF.
    pub ukf: bool,
    /// Also run the EKF with the GPS fused on arrival (latency ignored).
    pub latency_ignored: bool,
    /// Write the figures.
    pub figures: bool,
    /// The GPS latency [s]; `None`: PARM's `GPS_DELAY_MS` if non-zero, else the
    /// maximum-likelihood estimate over [`GPS_DELAY_GRID`].
    pub gps_delay: Option<f64>,
    /// Length of the static alignment at the start of the IMU log [s].
    pub align_s: f64,
    /// The IMU instance (`I` of the IMU rows) the INS runs on.
    pub imu: u8,
    /// The compass instance (`I` of the MAG rows) the alignment's heading comes from.
    pub mag: u8,
    /// The EKF3 core (`C`: 0 or 1) the filters are scored against (the figures and the
    /// reference spread stay against core 0). Core c runs on IMU c.
    pub core: u8,
}

impl Config {
    /// The whole run over the recording in `data`.
    pub fn full(data: PathBuf) -> Self {
        Self {
            data,
            flight_seconds: None,
            ukf: true,
            latency_ignored: true,
            figures: true,
            gps_delay: None,
            align_s: 5.0,
            imu: 0,
            mag: 0,
            core: 0,
        }
    }
}

/// EKF3's target step [s] (`EKF_TARGET_DT` in ArduPilot's EKF3).
pub const EKF3_TARGET_STEP: f64 = 0.012;

/// EKF3's step for a loop (IMU) period T [s]: it accumulates n samples, n the smallest with
/// n T ≥ `EKF_TARGET_DT` − T/2 (`readIMUData`), so the step is n T: 20 ms at 50 Hz, 10 ms at
/// 100 and 200 Hz, 12.5 ms at 400 Hz.
pub fn ekf3_step(period: f64) -> f64 {
    let n = (EKF3_TARGET_STEP / period - 0.5).ceil().max(1.0);
    n * period
}

/// The settings derived from the recording, with where each came from.
///
/// **The process noise.** EKF3's `EK3_*_P_NSE` parameters are not densities: EKF3 adds
/// (Δt σ)² per prediction step to the variance of the step's delta angle (gyro, σ in rad/s),
/// delta velocity (accelerometer, m/s²) and of the biases, Δt its own step
/// ([`ekf_step`](Self::ekf_step)). White noise of density σ_c adds σ_c² Δt over the same step,
/// so the density EKF3 assumes is σ_c = σ √Δt: 0.015 rad/s at 50 Hz is 0.0021 rad/s/√Hz. The
/// nav model takes densities, so each parameter is converted so (at 50 Hz, ×0.141).
#[derive(Clone, Debug)]
pub struct Settings {
    /// Gyro noise [rad/s/√Hz]: `EK3_GYRO_P_NSE` √Δt.
    pub gyro_noise: f64,
    /// Accelerometer noise [m/s²/√Hz]: `EK3_ACC_P_NSE` √Δt.
    pub accel_noise: f64,
    /// Accelerometer bias walk [m/s³/√Hz]: `EK3_ABIAS_P_NSE` √Δt.
    pub accel_bias_walk: f64,
    /// Gyro bias walk [rad/s²/√Hz]: `EK3_GBIAS_P_NSE` √Δt.
    pub gyro_bias_walk: f64,
    /// EKF3's step Δt [s], which its `EK3_*_P_NSE` values are per: [`ekf3_step`] of the loop
    /// period 1/`SCHED_LOOP_RATE` (without `SCHED_LOOP_RATE`: the log's IMU period, which is
    /// the loop period when the IMU is logged every loop).
    pub ekf_step: f64,
    /// GPS NE position σ [m]: `EK3_POSNE_M_NSE`; down: `EK3_ALT_M_NSE`.
    pub pos_sd: Vector3<f64>,
    /// GPS velocity σ [m/s]: `EK3_VELNE_M_NSE` (N, E), `EK3_VELD_M_NSE` (D).
    pub vel_sd: Vector3<f64>,
    /// GPS latency [s].
    pub gps_delay: f64,
    /// Where [`gps_delay`](Self::gps_delay) came from.
    pub gps_delay_source: DelaySource,
    /// Magnetic declination [rad]: `COMPASS_DEC` (0 when the autopilot computes it itself; it
    /// only seeds the heading, which GPS velocity makes observable in flight).
    pub declination: f64,
    /// Median IMU period [s].
    pub imu_period: f64,
    /// How long a logged IMU sample lags the motion it measures [s]: the group delay at low
    /// frequency of the autopilot's two-pole Butterworth low-pass at `INS_GYRO_FILTER` Hz,
    /// √2 / (2π f_c) (11.25 ms at 20 Hz; 0 with the filter off). The sample is the rate at
    /// TimeUS − lag, so it is taken as the mean over the interval of one period centred there
    /// (the midpoint rule): (TimeUS − lag − T/2, TimeUS − lag + T/2].
    pub imu_lag: f64,
    /// Which values came from PARM (the others are ArduPilot's defaults).
    pub from_log: Vec<&'static str>,
}

/// One filter's estimate at an IMU sample (NE only where the comparison is NE).
#[derive(Clone, Debug)]
pub struct Point {
    pub t: f64,
    pub q: UnitQuaternion<f64>,
    pub v: Vector2<f64>,
    pub p: Vector2<f64>,
    /// Standard deviations: attitude (body frame, 3), velocity N, E, position N, E.
    pub sd: Option<[f64; 7]>,
}

/// Attitude error percentiles [deg] and NE RMS errors, over a window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    pub attitude_median: f64,
    pub attitude_p95: f64,
    pub attitude_max: f64,
    pub ne_position_rms: f64,
    pub ne_velocity_rms: f64,
    /// Fractions of the attitude axes, NE position and NE velocity components whose error
    /// against the reference is within the filter's own 3σ (`None` for the reference spread).
    pub coverage: Option<[f64; 3]>,
}

impl Metrics {
    pub fn json(&self) -> Value {
        let mut v = json!({
            "attitude_deg": {
                "median": self.attitude_median, "p95": self.attitude_p95, "max": self.attitude_max,
            },
            "ne_position_rms_m": self.ne_position_rms,
            "ne_velocity_rms_m_s": self.ne_velocity_rms,
        });
        if let Some(c) = self.coverage {
            v["coverage_3sigma"] =
                json!({ "attitude": c[0], "ne_position": c[1], "ne_velocity": c[2] });
        }
        v
    }
}

/// Metrics over the whole run and the airborne window (`None` if never airborne).
#[derive(Clone, Copy, Debug)]
pub struct Windows {
    pub whole: Metrics,
    pub airborne: Option<Metrics>,
}

impl Windows {
    pub(crate) fn json(&self) -> Value {
        json!({ "whole": self.whole.json(), "airborne": self.airborne.map(|m| m.json()) })
    }
}

/// One filter run.
#[derive(Clone, Debug)]
pub struct Run {
    pub windows: Windows,
    pub track: Vec<Point>,
    /// Wall time of the filter loop per IMU sample [µs].
    pub us_per_sample: f64,
    /// GPS positions and velocities rejected by the gate, of those fused.
    pub rejected: (usize, usize),
}

/// Everything the example computes.
pub struct FlightResult {
    pub settings: Settings,
    pub window: (f64, f64),
    pub airborne: Option<(f64, f64)>,
    pub imu_samples: usize,
    /// The IMU and compass instances used, and the EKF3 core scored against.
    pub instances: (u8, u8, u8),
    pub ekf: Run,
    pub ukf: Option<Run>,
    pub latency_ignored: Option<Run>,
    pub reference_spread: Windows,
    /// The reference's core-0 NE positions (XKF1, moved to this origin).
    pub reference_track: Vec<(f64, Vector2<f64>)>,
    /// The EKF's attitude error against XKQ core 0 over time [s, deg] (every 5th row).
    pub ekf_attitude_errors: Vec<(f64, f64)>,
    pub run_s: f64,
}

/// The log's contents used by the run.
struct Recording {
    imu: Table,
    gps: Table,
    xkq: [Table; 2],
    xkf: [Table; 2],
    origin: Origin,
    settings: Settings,
    /// The alignment: start time [s], initial attitude, gyro bias.
    start: f64,
    q0: UnitQuaternion<f64>,
    gyro_bias: Vector3<f64>,
    /// XKF1 NE position plus this = NE position about `origin`.
    reference_offset: Vector2<f64>,
}

fn t(r: &[f64]) -> f64 {
    r[0] * 1e-6
}

fn gps_ned(origin: &Origin, g: &[f64]) -> (Vector3<f64>, Vector3<f64>) {
    // GPS columns: TimeUS, I, Status, Lat, Lng, Alt, Spd, GCrs, VZ.
    let pos = origin.ned(g[3], g[4], g[5]);
    let course = g[7].to_radians();
    (
        pos,
        Vector3::new(g[6] * course.cos(), g[6] * course.sin(), g[8]),
    )
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn load(config: &Config) -> Result<Recording, Box<dyn std::error::Error>> {
    let dir = &config.data;
    let imu = read_table(
        dir,
        "IMU",
        &[
            "TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ",
        ],
    )?
    .select(1, f64::from(config.imu))
    .non_empty(&format!("IMU {} samples", config.imu))?;
    let gps_cols = [
        "TimeUS", "I", "Status", "Lat", "Lng", "Alt", "Spd", "GCrs", "VZ",
    ];
    let gps = read_table(dir, "GPS", &gps_cols)?.select(1, 0.0);
    let gps = Table {
        rows: gps.rows.iter().filter(|r| r[2] >= 3.0).cloned().collect(),
        lines: gps
            .rows
            .iter()
            .zip(&gps.lines)
            .filter(|(r, _)| r[2] >= 3.0)
            .map(|(_, l)| *l)
            .collect(),
        file: gps.file,
    }
    .non_empty("3-D GPS fixes of GPS 0")?;
    let mag = read_table(dir, "MAG", &["TimeUS", "I", "MagX", "MagY", "MagZ"])?
        .select(1, f64::from(config.mag));
    let xkq_all = read_table(dir, "XKQ", &["TimeUS", "C", "Q1", "Q2", "Q3", "Q4"])?;
    let xkf_all = read_table(dir, "XKF1", &["TimeUS", "C", "VN", "VE", "PN", "PE"])?;
    let xkq = [
        xkq_all.select(1, 0.0).non_empty("core 0")?,
        xkq_all.select(1, 1.0),
    ];
    let xkf = [
        xkf_all.select(1, 0.0).non_empty("core 0")?,
        xkf_all.select(1, 1.0),
    ];
    let parameters = read_parameters(dir)?.unwrap_or_default();
    let mut from_log = Vec::new();
    let mut parm = |name: &'static str, default: f64| match parameters.get(name) {
        Some(v) => {
            from_log.push(name);
            *v
        }
        None => default,
    };
    let gyro_noise = parm("EK3_GYRO_P_NSE", 0.015);
    let accel_noise = parm("EK3_ACC_P_NSE", 0.35);
    let accel_bias_walk = parm("EK3_ABIAS_P_NSE", 0.003);
    let gyro_bias_walk = parm("EK3_GBIAS_P_NSE", 0.001);
    let gyro_filter = parm("INS_GYRO_FILTER", 20.0);
    let loop_rate = parm("SCHED_LOOP_RATE", 0.0);
    let pos_ne = parm("EK3_POSNE_M_NSE", 0.5);
    let alt = parm("EK3_ALT_M_NSE", 3.0);
    let vel_ne = parm("EK3_VELNE_M_NSE", 0.5);
    let vel_d = parm("EK3_VELD_M_NSE", 0.7);
    let delay_ms = parm("GPS_DELAY_MS", 0.0);
    let declination = parm("COMPASS_DEC", 0.0);
    // Without a flag or a parameter the latency is estimated after loading (`run_config`);
    // until then 0, which only the at-rest reference offset below uses (at rest the position
    // does not depend on it).
    let (gps_delay, gps_delay_source) = match config.gps_delay {
        Some(d) => (d, DelaySource::Flag),
        None if delay_ms > 0.0 => (delay_ms * 1e-3, DelaySource::Parameter),
        None => (0.0, DelaySource::Likelihood),
    };
    let periods: Vec<f64> = imu
        .rows
        .windows(2)
        .map(|w| t(&w[1]) - t(&w[0]))
        .filter(|d| *d > 0.0)
        .collect();
    if periods.is_empty() {
        return Err(LogError::Empty {
            file: imu.file.clone(),
            what: format!("two IMU {} samples", config.imu),
        }
        .into());
    }
    let imu_period = median(periods);
    // EKF3's step (see `Settings`): the per-step σ of its parameters become densities.
    let loop_period = if loop_rate > 0.0 {
        1.0 / loop_rate
    } else {
        imu_period
    };
    let ekf_step = ekf3_step(loop_period);
    let density = ekf_step.sqrt();
    // The origin: the home row, else the first 3-D fix.
    let home = match read_table(dir, "ORGN", &["TimeUS", "Type", "Lat", "Lng", "Alt"]) {
        Ok(o) => o
            .rows
            .iter()
            .find(|r| r[1] == 1.0)
            .map(|r| (r[2], r[3], r[4])),
        Err(LogError::Missing { .. }) => None,
        Err(e) => return Err(e.into()),
    };
    let (lat, lon, h) = home.unwrap_or((gps.rows[0][3], gps.rows[0][4], gps.rows[0][5]));
    let origin = Origin::from_degrees(lat, lon, h)?;
    // Static alignment over the first `align_s` seconds of IMU 0 (and the magnetometer then).
    let t0 = t(&imu.rows[0]);
    let window: Vec<&Vec<f64>> = imu
        .rows
        .iter()
        .filter(|r| t(r) <= t0 + config.align_s)
        .collect();
    let n = window.len() as f64;
    let acc = window
        .iter()
        .fold(Vector3::zeros(), |s, r| s + Vector3::new(r[5], r[6], r[7]))
        / n;
    let gyro_bias = window
        .iter()
        .fold(Vector3::zeros(), |s, r| s + Vector3::new(r[2], r[3], r[4]))
        / n;
    // At rest: no rotation above 0.05 rad/s (3°/s; a MEMS gyro's bias is below 0.02 rad/s).
    if let Some(r) = window
        .iter()
        .find(|r| Vector3::new(r[2], r[3], r[4]).norm() > 0.05)
    {
        return Err(LogError::Recording {
            file: imu.file.clone(),
            what: format!("rotating at {:.3} s, during the alignment", t(r)),
        }
        .into());
    }
    let mag_window: Vec<&Vec<f64>> = mag
        .rows
        .iter()
        .filter(|r| t(r) <= t0 + config.align_s)
        .collect();
    if mag_window.is_empty() {
        return Err(LogError::Empty {
            file: mag.file.clone(),
            what: format!("compass {} readings during the alignment", config.mag),
        }
        .into());
    }
    let m = mag_window
        .iter()
        .fold(Vector3::zeros(), |s, r| s + Vector3::new(r[2], r[3], r[4]))
        / mag_window.len() as f64;
    // Only the field's horizontal direction sets the heading: the declination.
    let field = Vector3::new(declination.cos(), declination.sin(), 0.0);
    let q0 = static_alignment(&acc, &m, &field)?;
    let start = t(window[window.len() - 1]);
    // XKF1's origin is its own (set at its first fix): the constant offset to ours is the mean
    // of GPS minus XKF1 core 0 while at rest (speed < 1 m/s) before the first fast fix.
    let first_fast = gps
        .rows
        .iter()
        .find(|g| g[6] > AIRBORNE_SPEED)
        .map(|g| t(g))
        .unwrap_or(f64::INFINITY);
    let mut sum = Vector2::zeros();
    let mut count = 0usize;
    for g in gps.rows.iter().filter(|g| g[6] < 1.0 && t(g) < first_fast) {
        let (pos, _) = gps_ned(&origin, g);
        if let Some(r) = nearest(&xkf[0].rows, t(g) - gps_delay, 0.03)
            && (r[4] != 0.0 || r[5] != 0.0)
        {
            sum += pos.xy() - Vector2::new(r[4], r[5]);
            count += 1;
        }
    }
    let reference_offset = if count > 0 {
        sum / count as f64
    } else {
        Vector2::zeros()
    };
    let settings = Settings {
        gyro_noise: gyro_noise * density,
        accel_noise: accel_noise * density,
        accel_bias_walk: accel_bias_walk * density,
        gyro_bias_walk: gyro_bias_walk * density,
        ekf_step,
        pos_sd: Vector3::new(pos_ne, pos_ne, alt),
        vel_sd: Vector3::new(vel_ne, vel_ne, vel_d),
        gps_delay,
        gps_delay_source,
        declination,
        imu_period,
        imu_lag: if gyro_filter > 0.0 {
            core::f64::consts::SQRT_2 / (2.0 * core::f64::consts::PI * gyro_filter)
        } else {
            0.0
        },
        from_log,
    };
    Ok(Recording {
        imu,
        gps,
        xkq,
        xkf,
        origin,
        settings,
        start,
        q0,
        gyro_bias,
        reference_offset,
    })
}

/// The row of `rows` (sorted by time) nearest `time`, if within `tolerance` seconds.
fn nearest(rows: &[Vec<f64>], time: f64, tolerance: f64) -> Option<&Vec<f64>> {
    let i = rows.partition_point(|r| t(r) < time);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|j| rows.get(j))
        .min_by(|a, b| (t(a) - time).abs().total_cmp(&(t(b) - time).abs()))
        .filter(|r| (t(r) - time).abs() <= tolerance)
}

/// A GPS fix: position or velocity (NED).
#[derive(Clone, Copy, Debug)]
pub enum Fix {
    Position(Vector3<f64>),
    Velocity(Vector3<f64>),
}

/// The GPS receiver as the driver's sensor set: sensor 0 position, 1 velocity.
pub struct Gnss {
    pub position: GnssPosition,
    pub velocity: GnssVelocity,
}

impl<F> SensorSet<f64, Const<15>, F> for Gnss
where
    F: Update<f64, Const<15>, Const<3>, GnssPosition>
        + Update<f64, Const<15>, Const<3>, GnssVelocity>,
{
    type Reading = Fix;
    fn count(&self) -> usize {
        2
    }
    fn sensor(&self, reading: &Fix) -> usize {
        match reading {
            Fix::Position(_) => 0,
            Fix::Velocity(_) => 1,
        }
    }
    fn dimension(&self, _: usize) -> usize {
        3
    }
    fn update(&self, filter: &mut F, reading: &Fix) -> CoreResult<Innovation<f64>> {
        match reading {
            Fix::Position(z) => {
                Update::<f64, Const<15>, Const<3>, GnssPosition>::update(filter, &self.position, z)
                    .map(|r| Innovation::of(&r))
            }
            Fix::Velocity(z) => {
                Update::<f64, Const<15>, Const<3>, GnssVelocity>::update(filter, &self.velocity, z)
                    .map(|r| Innovation::of(&r))
            }
        }
    }
}

/// The prior after the alignment: attitude and gyro bias from it, at rest at the origin.
fn prior(rec: &Recording) -> Result<Gaussian<f64, Const<15>>, estim_core::Error> {
    let mut x = SVector::<f64, 15>::zeros();
    x.fixed_rows_mut::<3>(ATTITUDE)
        .copy_from(&estim_core::manifold::so3_log(&rec.q0));
    x.fixed_rows_mut::<3>(GYRO_BIAS).copy_from(&rec.gyro_bias);
    // σ: roll/pitch 8° (levelling with an uncalibrated accelerometer bias up to 0.4 m/s²),
    // heading 18° (declination and a disturbed compass), 0.5 m/s, 2 m, gyro bias 3 mrad/s
    // (the alignment's mean), accelerometer bias 0.3 m/s².
    let variances = [
        0.02, 0.02, 0.1, 0.25, 0.25, 0.25, 4.0, 4.0, 4.0, 1e-5, 1e-5, 1e-5, 0.1, 0.1, 0.1,
    ];
    let p =
        SMatrix::<f64, 15, 15>::from_diagonal(&SVector::<f64, 15>::from_column_slice(&variances));
    Gaussian::new(x, p)
}

/// A filter's track, its time per IMU sample [µs], its gate rejections (positions,
/// velocities) and the GPS log-likelihood of the run.
type Driven = (Vec<Point>, f64, (usize, usize), f64);

/// The largest latency of [`GPS_DELAY_GRID`] [s].
fn largest_grid_delay() -> f64 {
    let (first, step, count) = GPS_DELAY_GRID;
    first + step * (count - 1) as f64
}

fn drive<F>(
    rec: &Recording,
    latency: f64,
    end: f64,
    filter: F,
) -> Result<Driven, Box<dyn std::error::Error>>
where
    F: Predict<f64, Const<15>, Strapdown>
        + Rollback
        + Estimator<f64, Const<15>>
        + Update<f64, Const<15>, Const<3>, GnssPosition>
        + Update<f64, Const<15>, Const<3>, GnssVelocity>,
{
    let s = &rec.settings;
    let ins = Strapdown::new(
        rec.origin,
        InsSettings {
            gyro_noise: s.gyro_noise,
            accel_noise: s.accel_noise,
            gyro_bias_walk: s.gyro_bias_walk,
            accel_bias_walk: s.accel_bias_walk,
            // The gyros measure the earth's rotation too (15°/h; 11.8°/h about the vertical
            // at 52° N, 1.2° of heading in 6 minutes), and EKF3 models it: a known input, not
            // something for the gyro bias state to learn. No transport rate: the NED frame is
            // the tangent plane at a fixed origin, which turns with the earth alone.
            earth_rate: true,
            transport_rate: false,
        },
    )?;
    let gnss = Gnss {
        position: GnssPosition {
            noise: Matrix3::from_diagonal(&s.pos_sd.component_mul(&s.pos_sd)),
        },
        velocity: GnssVelocity {
            noise: Matrix3::from_diagonal(&s.vel_sd.component_mul(&s.vel_sd)),
        },
    };
    // The history must reach back over the latency; a step is at most 1.25 IMU periods.
    let horizon = latency.max(s.gps_delay) + 0.35;
    let settings = FusionSettings {
        horizon,
        capacity: (horizon / s.imu_period * 2.0).ceil() as usize + 64,
        max_step: 1.25 * s.imu_period,
        ..FusionSettings::default()
    };
    // Gate at 1 − 10⁻⁵: only gross errors (a glitching fix) are refused.
    let mut driver = FusionDriver::new(
        filter,
        ins,
        Imu::default(),
        gnss,
        rec.start,
        settings,
        SensorSettings::gated(0.99999),
    )?
    .with_input_convention(InputConvention::Preceding)?;
    // An IMU sample stands for the interval of one period centred on TimeUS − lag
    // (`Settings::imu_lag`): the driver's interval ends at TimeUS − shift.
    let shift = s.imu_lag - 0.5 * s.imu_period;
    let mut track = Vec::with_capacity(rec.imu.rows.len());
    let mut rejected = (0, 0);
    let mut next_gps = 0;
    let clock = Instant::now();
    for r in rec
        .imu
        .rows
        .iter()
        .filter(|r| t(r) > rec.start && t(r) <= end)
    {
        while next_gps < rec.gps.rows.len() && t(&rec.gps.rows[next_gps]) <= t(r) {
            let g = &rec.gps.rows[next_gps];
            next_gps += 1;
            let taken = t(g) - latency;
            // The same fixes at every latency of the grid, so that their likelihoods compare.
            if taken <= rec.start || t(g) <= rec.start + largest_grid_delay() {
                continue;
            }
            let (pos, vel) = gps_ned(&rec.origin, g);
            // The position and the velocity of one fix in one call: one rollback and one
            // replay of the IMU samples since it was taken, not one per reading.
            let fused =
                driver.fuse_all([(taken, Fix::Position(pos)), (taken, Fix::Velocity(vel))])?;
            for (k, f) in fused.iter().enumerate() {
                if !f.outcome.applied() {
                    if k == 0 {
                        rejected.0 += 1
                    } else {
                        rejected.1 += 1
                    }
                }
            }
        }
        let time = t(r) - shift;
        driver.set_input(
            time,
            Imu {
                gyro: Vector3::new(r[2], r[3], r[4]),
                accel: Vector3::new(r[5], r[6], r[7]),
            },
        )?;
        let (x, p) = (driver.filter().state(), driver.filter().covariance());
        let sd = |i: usize| p[(i, i)].max(0.0).sqrt();
        track.push(Point {
            t: time,
            q: attitude(x),
            v: Vector2::new(x[VELOCITY], x[VELOCITY + 1]),
            p: Vector2::new(x[POSITION], x[POSITION + 1]),
            sd: Some([
                sd(ATTITUDE),
                sd(ATTITUDE + 1),
                sd(ATTITUDE + 2),
                sd(VELOCITY),
                sd(VELOCITY + 1),
                sd(POSITION),
                sd(POSITION + 1),
            ]),
        });
    }
    let us = clock.elapsed().as_secs_f64() * 1e6 / track.len().max(1) as f64;
    Ok((track, us, rejected, driver.log_likelihood()))
}

fn quaternion(r: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(r[2], r[3], r[4], r[5]))
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// `track` against XKQ/XKF1 of `core` over `[a, b]`; `None` if nothing to compare there.
fn compare(rec: &Recording, track: &[Point], core: usize, (a, b): (f64, f64)) -> Option<Metrics> {
    let near = |time: f64| {
        let i = track.partition_point(|e| e.t < time);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| track.get(j))
            .min_by(|x, y| (x.t - time).abs().total_cmp(&(y.t - time).abs()))
            .filter(|e| (e.t - time).abs() <= 0.75 * rec.settings.imu_period)
    };
    let (mut angles, mut covered) = (Vec::new(), [0usize; 3]);
    let mut total = [0usize; 3];
    for r in rec.xkq[core].rows.iter().filter(|r| t(r) >= a && t(r) <= b) {
        if let Some(e) = near(t(r)) {
            // Body-frame error δ: q_ref = q̂ Exp(δ), the filter's own attitude error.
            let delta = (e.q.inverse() * quaternion(r)).scaled_axis();
            angles.push(delta.norm().to_degrees());
            if let Some(sd) = e.sd {
                total[0] += 3;
                covered[0] += (0..3).filter(|&i| delta[i].abs() <= 3.0 * sd[i]).count();
            }
        }
    }
    let (mut pos, mut vel) = (0.0, 0.0);
    let mut n = 0usize;
    for r in rec.xkf[core].rows.iter().filter(|r| t(r) >= a && t(r) <= b) {
        if let Some(e) = near(t(r)) {
            let dv = e.v - Vector2::new(r[2], r[3]);
            let dp = e.p - (Vector2::new(r[4], r[5]) + rec.reference_offset);
            vel += dv.norm_squared();
            pos += dp.norm_squared();
            n += 1;
            if let Some(sd) = e.sd {
                total[1] += 2;
                total[2] += 2;
                covered[2] += (0..2).filter(|&i| dv[i].abs() <= 3.0 * sd[3 + i]).count();
                covered[1] += (0..2).filter(|&i| dp[i].abs() <= 3.0 * sd[5 + i]).count();
            }
        }
    }
    if angles.is_empty() || n == 0 {
        return None;
    }
    angles.sort_by(f64::total_cmp);
    let frac = |i: usize| covered[i] as f64 / total[i].max(1) as f64;
    Some(Metrics {
        attitude_median: percentile(&angles, 0.5),
        attitude_p95: percentile(&angles, 0.95),
        attitude_max: angles[angles.len() - 1],
        ne_position_rms: (pos / n as f64).sqrt(),
        ne_velocity_rms: (vel / n as f64).sqrt(),
        coverage: (total[0] > 0).then(|| [frac(0), frac(1), frac(2)]),
    })
}

fn windows(
    rec: &Recording,
    track: &[Point],
    core: usize,
    whole: (f64, f64),
    airborne: Option<(f64, f64)>,
) -> Result<Windows, LogError> {
    let whole = compare(rec, track, core, whole).ok_or_else(|| LogError::Empty {
        file: rec.xkq[core].file.clone(),
        what: format!("core {core} reference rows in the run's window"),
    })?;
    Ok(Windows {
        whole,
        airborne: airborne.and_then(|w| compare(rec, track, core, w)),
    })
}

/// The latency of [`GPS_DELAY_GRID`] whose EKF run over the recording up to `end` has the
/// largest GPS log-likelihood (ties: the smaller latency).
fn likeliest_gps_delay(rec: &Recording, end: f64) -> Result<f64, Box<dyn std::error::Error>> {
    let (first, step, count) = GPS_DELAY_GRID;
    let mut best = (f64::NEG_INFINITY, first);
    for k in 0..count {
        let latency = first + step * k as f64;
        let filter = Ekf::new(prior(rec)?).with_state_space(state_space());
        let (_, _, _, log_likelihood) = drive(rec, latency, end, filter)?;
        if log_likelihood > best.0 {
            best = (log_likelihood, latency);
        }
    }
    Ok(best.1)
}

/// Runs the example's core: load, align, filter(s), compare.
pub fn run_config(config: &Config) -> Result<FlightResult, Box<dyn std::error::Error>> {
    let clock = Instant::now();
    let mut rec = load(config)?;
    let fast: Vec<f64> = rec
        .gps
        .rows
        .iter()
        .filter(|g| g[6] > AIRBORNE_SPEED)
        .map(|g| t(g))
        .collect();
    let log_end = t(&rec.imu.rows[rec.imu.rows.len() - 1]);
    let end = match (config.flight_seconds, fast.first()) {
        (Some(s), Some(a)) => (a + s).min(log_end),
        (Some(s), None) => (rec.start + s).min(log_end),
        (None, _) => log_end,
    };
    let airborne = fast
        .first()
        .map(|a| (*a, fast[fast.len() - 1].min(end)))
        .filter(|(a, b)| a < b);
    let whole = (rec.start, end);
    if rec.settings.gps_delay_source == DelaySource::Likelihood {
        rec.settings.gps_delay = likeliest_gps_delay(&rec, end)?;
    }
    let rec = rec;
    let core = usize::from(config.core);
    if core > 1 {
        return Err(LogError::Recording {
            file: rec.xkq[0].file.clone(),
            what: format!("EKF3 core {core} asked for: the comparison is with core 0 or 1"),
        }
        .into());
    }
    let ekf_with = |latency: f64| -> Result<Run, Box<dyn std::error::Error>> {
        let filter = Ekf::new(prior(&rec)?).with_state_space(state_space());
        let (track, us_per_sample, rejected, _) = drive(&rec, latency, end, filter)?;
        Ok(Run {
            windows: windows(&rec, &track, core, whole, airborne)?,
            track,
            us_per_sample,
            rejected,
        })
    };
    let ekf = ekf_with(rec.settings.gps_delay)?;
    let latency_ignored = if config.latency_ignored {
        Some(ekf_with(0.0)?)
    } else {
        None
    };
    let ukf = if config.ukf {
        let filter = Ukf::new(prior(&rec)?).with_state_space(state_space());
        let (track, us_per_sample, rejected, _) = drive(&rec, rec.settings.gps_delay, end, filter)?;
        Some(Run {
            windows: windows(&rec, &track, core, whole, airborne)?,
            track,
            us_per_sample,
            rejected,
        })
    } else {
        None
    };
    // The reference's own spread: EKF3 core 1 as a track against core 0.
    let core1: Vec<Point> = rec.xkq[1]
        .rows
        .iter()
        .filter_map(|q| {
            let f = nearest(&rec.xkf[1].rows, t(q), 1e-3)?;
            Some(Point {
                t: t(q),
                q: quaternion(q),
                v: Vector2::new(f[2], f[3]),
                p: Vector2::new(f[4], f[5]) + rec.reference_offset,
                sd: None,
            })
        })
        .collect();
    let reference_spread = windows(&rec, &core1, 0, whole, airborne)?;
    let reference_track = rec.xkf[0]
        .rows
        .iter()
        .filter(|r| t(r) >= whole.0 && t(r) <= whole.1)
        .map(|r| (t(r), Vector2::new(r[4], r[5]) + rec.reference_offset))
        .collect();
    let imu_samples = ekf.track.len();
    let ekf_attitude_errors = rec.xkq[0]
        .rows
        .iter()
        .filter(|r| t(r) >= whole.0 && t(r) <= whole.1)
        .step_by(5)
        .map(|r| {
            let i = ekf
                .track
                .partition_point(|e| e.t < t(r))
                .min(ekf.track.len() - 1);
            let e = &ekf.track[i];
            (t(r), e.q.angle_to(&quaternion(r)).to_degrees())
        })
        .collect();
    Ok(FlightResult {
        settings: rec.settings,
        window: whole,
        airborne,
        imu_samples,
        instances: (config.imu, config.mag, config.core),
        ekf,
        ukf,
        latency_ignored,
        reference_spread,
        reference_track,
        ekf_attitude_errors,
        run_s: clock.elapsed().as_secs_f64(),
    })
}
