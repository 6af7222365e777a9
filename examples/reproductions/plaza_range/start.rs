//! The start pose from the ranges alone (no ground truth): a robust least-squares fit of the
//! start position p₀, heading ψ₀ and common range bias c to the ranges of a first window,
//! along the odometry's own track.
//!
//! With dᵢ the odometry track at reading i's time in the start frame (integrated from the
//! origin, heading 0), reading i of beacon j is modelled as
//!
//! ```text
//! zᵢ = ‖p₀ + R(ψ₀) dᵢ − oⱼ‖ + c + eᵢ
//! ```
//!
//! ψ₀ is found by a grid (every 2°, each with a Gauss-Newton fit of p₀ and c), then all four
//! are refined together; Huber weights (threshold [`HUBER_M`]) bound the outliers' pull. The
//! window ends when the odometry has covered [`Start::fit_distance`]: before the robot moves,
//! ranges fix p₀ and c but not ψ₀.
//!
//! The covariance is the fit's, σ̂² (JᵀWJ)⁻¹, inflated because the range errors are
//! correlated over τ_g: a beacon's n readings in a window of T seconds are worth about
//! max(1, T/τ_g) independent ones, not n. To it is added what the per-beacon biases gⱼ
//! (σ_g each, constant over the window) do to the fit: the fit moves by aⱼ gⱼ for a bias gⱼ on
//! beacon j, so the covariance gains σ_g² Σⱼ aⱼ aⱼᵀ, and the filters' prior correlates the
//! start with each gⱼ (a common bias is absorbed by c, so aⱼ is small when the beacons agree).

use estim_core::nalgebra::{Matrix3, Matrix4, Rotation2, Vector2, Vector3, Vector4};

use super::data::{DataError, Odometry, RangeReading, Recording};

/// Huber threshold of the start fit [m].
pub const HUBER_M: f64 = 2.0;

/// The fitted start: mean (x, y, ψ, c), covariance, and its sensitivity to the per-beacon
/// biases.
#[derive(Clone, Debug)]
pub struct Start {
    pub mean: Vector4<f64>,
    /// The covariance of the fit's error from the range noise and from the per-beacon biases:
    /// Σ_n + σ_g² Σⱼ aⱼ aⱼᵀ.
    pub covariance: Matrix4<f64>,
    /// aⱼ = ∂(x̂, ŷ, ψ̂, ĉ)/∂gⱼ, one per beacon of the survey (zero for a beacon not heard in the
    /// window): a bias gⱼ on every reading of beacon j moves the fit by aⱼ gⱼ, so the start
    /// error and the beacon biases are correlated (cov = −σ_g² aⱼ in the state's prior).
    pub sensitivity: Vec<Vector4<f64>>,
    /// The end of the window [s] and the distance the odometry covered by then [m].
    pub window_end: f64,
    pub fit_distance: f64,
    /// Readings used and the covariance inflation applied.
    pub readings: usize,
    pub inflation: f64,
}

/// The odometry track (x, y, ψ) at each odometry time, from (0, 0, 0) at the first one,
/// integrated exactly as the unicycle does (chord at the mid-heading).
pub fn track(odometry: &[Odometry]) -> Vec<(f64, Vector3<f64>)> {
    let mut pose = Vector3::<f64>::zeros();
    let mut out = Vec::with_capacity(odometry.len());
    out.push((odometry[0].t, pose));
    for o in &odometry[1..] {
        let half = 0.5 * o.turn;
        let chord = if half.abs() < 1e-9 {
            o.distance
        } else {
            o.distance * half.sin() / half
        };
        pose += Vector3::new(
            chord * (pose[2] + half).cos(),
            chord * (pose[2] + half).sin(),
            o.turn,
        );
        out.push((o.t, pose));
    }
    out
}

/// The track position at time `t` (linear between odometry times).
fn at(track: &[(f64, Vector3<f64>)], t: f64) -> Vector2<f64> {
    let i = track.partition_point(|(s, _)| *s < t);
    if i == 0 {
        return track[0].1.xy();
    }
    if i >= track.len() {
        return track[track.len() - 1].1.xy();
    }
    let ((a, pa), (b, pb)) = (track[i - 1], track[i]);
    let w = if b > a { (t - a) / (b - a) } else { 1.0 };
    pa.xy() + (pb.xy() - pa.xy()) * w
}

fn huber(e: f64) -> f64 {
    if e.abs() <= HUBER_M {
        1.0
    } else {
        HUBER_M / e.abs()
    }
}

fn huber_cost(e: f64) -> f64 {
    if e.abs() <= HUBER_M {
        0.5 * e * e
    } else {
        HUBER_M * (e.abs() - 0.5 * HUBER_M)
    }
}

/// One reading in the fit: the track offset d, the beacon and the range.
struct Point {
    d: Vector2<f64>,
    o: Vector2<f64>,
    z: f64,
    beacon: usize,
}

/// Prediction, residual and ∂r̂/∂(x, y, ψ, c) of one reading.
fn linearise(p: &Point, theta: &Vector4<f64>) -> (f64, Vector4<f64>) {
    let rot = Rotation2::new(theta[2]);
    let q = Vector2::new(theta[0], theta[1]) + rot * p.d - p.o;
    let r = q.norm().max(1e-9);
    let u = q / r;
    let (s, c) = theta[2].sin_cos();
    let dr = Vector2::new(-s * p.d[0] - c * p.d[1], c * p.d[0] - s * p.d[1]);
    (
        p.z - r - theta[3],
        Vector4::new(u[0], u[1], u.dot(&dr), 1.0),
    )
}

/// Gauss-Newton with Huber weights on (x, y, c) at fixed ψ; returns the parameters and cost.
fn fit_at_heading(points: &[Point], psi: f64, start: Vector2<f64>) -> (Vector4<f64>, f64) {
    let mut theta = Vector4::new(start[0], start[1], psi, 0.0);
    for _ in 0..15 {
        let (mut a, mut b) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
        for p in points {
            let (e, j) = linearise(p, &theta);
            let j = Vector3::new(j[0], j[1], j[3]);
            let w = huber(e);
            a += w * j * j.transpose();
            b += w * j * e;
        }
        let Some(step) = a.cholesky().map(|c| c.solve(&b)) else {
            break;
        };
        theta += Vector4::new(step[0], step[1], 0.0, step[2]);
        if step.norm() < 1e-6 {
            break;
        }
    }
    let cost = points
        .iter()
        .map(|p| huber_cost(linearise(p, &theta).0))
        .sum();
    (theta, cost)
}

/// Fits the start over the ranges up to where the odometry has covered `fit_distance` metres.
/// `tau` and `bias_sd` are the per-beacon range errors' correlation time (for the inflation)
/// and size σ_g.
pub fn fit(rec: &Recording, fit_distance: f64, tau: f64, bias_sd: f64) -> Result<Start, DataError> {
    let track = track(&rec.odometry);
    let t0 = rec.odometry[0].t;
    let mut covered = 0.0;
    let mut window_end = rec.odometry[rec.odometry.len() - 1].t;
    for o in &rec.odometry[1..] {
        covered += o.distance.abs();
        if covered >= fit_distance {
            window_end = o.t;
            break;
        }
    }
    let used: Vec<&RangeReading> = rec
        .ranges
        .iter()
        .filter(|r| r.t >= t0 && r.t <= window_end)
        .collect();
    let mut beacons_seen: Vec<usize> = used.iter().map(|r| r.beacon).collect();
    beacons_seen.sort_unstable();
    beacons_seen.dedup();
    if used.len() < 8 || beacons_seen.len() < 3 {
        return Err(DataError::Empty {
            file: rec.range_file.clone(),
            what: format!(
                "ranges to 3 beacons in the first {fit_distance} m driven (the start fit): {} readings of {} beacons by {:.1} s",
                used.len(),
                beacons_seen.len(),
                window_end - t0
            ),
        });
    }
    let points: Vec<Point> = used
        .iter()
        .map(|r| {
            let b = rec.beacons[r.beacon];
            Point {
                d: at(&track, r.t),
                o: Vector2::new(b.x, b.y),
                z: r.range,
                beacon: r.beacon,
            }
        })
        .collect();
    let centroid = rec
        .beacons
        .iter()
        .fold(Vector2::zeros(), |s, b| s + Vector2::new(b.x, b.y))
        / rec.beacons.len() as f64;
    let (mut theta, _) = (0..180)
        .map(|k| fit_at_heading(&points, (2.0 * k as f64).to_radians(), centroid))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("a non-empty grid");
    let mut normal = Matrix4::<f64>::zeros();
    for _ in 0..30 {
        let (mut a, mut b) = (Matrix4::<f64>::zeros(), Vector4::<f64>::zeros());
        for p in &points {
            let (e, j) = linearise(p, &theta);
            let w = huber(e);
            a += w * j * j.transpose();
            b += w * j * e;
        }
        normal = a;
        let Some(step) = a.cholesky().map(|c| c.solve(&b)) else {
            break;
        };
        theta += step;
        if step.norm() < 1e-9 {
            break;
        }
    }
    let (mut sum, mut weights) = (0.0, 0.0);
    for p in &points {
        let e = linearise(p, &theta).0;
        sum += huber(e) * e * e;
        weights += huber(e);
    }
    let variance = sum / (weights - 4.0).max(1.0);
    let per_beacon = points.len() as f64 / beacons_seen.len() as f64;
    let independent = ((window_end - t0) / tau).max(1.0);
    let inflation = (per_beacon / independent).max(1.0);
    let inverse = normal
        .cholesky()
        .map(|c| c.inverse())
        .ok_or_else(|| DataError::Empty {
            file: rec.range_file.clone(),
            what: "geometry to fix the start (the start fit is singular)".into(),
        })?;
    // aⱼ = (JᵀWJ)⁻¹ Σ_{i of beacon j} wᵢ Jᵢ: the fit's response to a bias on beacon j.
    let mut sensitivity = vec![Vector4::<f64>::zeros(); rec.beacons.len()];
    for p in &points {
        let (e, j) = linearise(p, &theta);
        sensitivity[p.beacon] += huber(e) * j;
    }
    for a in &mut sensitivity {
        *a = inverse * *a;
    }
    let covariance = inverse * (variance * inflation)
        + sensitivity
            .iter()
            .fold(Matrix4::zeros(), |s, a| s + a * a.transpose())
            * bias_sd.powi(2);
    Ok(Start {
        mean: theta,
        covariance,
        sensitivity,
        window_end,
        fit_distance: covered.min(fit_distance),
        readings: points.len(),
        inflation,
    })
}
