//! Section 4: the circle example (Table 1), its configuration and simulator.
//!
//! The `boje_circle` example (`examples/reproductions/boje_circle.rs`) runs the filters on the
//! simulated data: the Monte Carlo with correct initial conditions (Fig 3), the wrong-IC run
//! (Fig 2) and the process/filter variants.
//!
//! Reading of the scenario (the paper leaves t_end and the orbit kinematics open; see the
//! module docs): a rigid arm, CG on a circle of radius 10 m about the origin, heading
//! θ = φ + π/2, rate ω(t) = sgn(t − t_end/2)·0.1·t rad/s (sgn(0) := +1), t_end = 20 s. The
//! truth is generated discretely consistent with the filter's model: velocities are exact at
//! the samples, uₖ = (v(tₖ₊₁) − v(tₖ))/h, xₖ₊₁ = A xₖ + B uₖ, and the accelerometer sample is
//! aₖ = M(θₖ)(uₖ, ωₖ²) + N(0, σ_a² I₄) (eq 4).

use estim_core::error::Result;
use estim_core::nalgebra::{Matrix6, Vector3, Vector4, Vector6};
use estim_core::{Error, Gaussian, Parameter};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use super::filter::{
    HEADING, PositionHeadingMeasurement, RATE, X, Y, input_matrix, transition_matrix,
};
use super::geometry::{ChannelVariances, sensor_signals};
use super::wrap_angle;

/// Which estim filter runs the 6-state model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FilterKind {
    /// [`Ekf`](estim_filters::Ekf): with the linear process this is exactly the paper's eq 16.
    Ekf,
    /// [`SecondOrderEkf`](estim_filters::SecondOrderEkf): adds the Hessian mean terms
    /// (ŷ = ω̂² + P_θ̇θ̇ for θ̇²).
    SecondOrderEkf,
    /// [`Ukf`](estim_filters::Ukf) with estim's default sigma points.
    Ukf,
}

/// Which process model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ProcessKind {
    /// The paper's linear process with σ²_θ folded into Q
    /// ([`PlanarProcess`](super::PlanarProcess)).
    Linear,
    /// θ inside f through eq 5 ([`NonlinearPlanarProcess`](super::NonlinearPlanarProcess)).
    Nonlinear,
}

/// Initial estimate relative to the truth and initial covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialConditions {
    /// x̂₀ − x₀ when `draw_error` is false.
    pub offset: Vector6<f64>,
    /// diag(P₀).
    pub variances: Vector6<f64>,
    /// Draw x̂₀ − x₀ ~ N(0, P₀) per run instead of using `offset`.
    pub draw_error: bool,
}

impl InitialConditions {
    /// Fig 3 ("correct" ICs): P₀ = diag(0.1², 0.1², 0.01², 0.5², 0.5², 0.01²) (erratum E5) and,
    /// for a consistent Monte Carlo, x̂₀ − x₀ drawn from N(0, P₀).
    pub fn correct() -> Self {
        Self {
            offset: Vector6::zeros(),
            variances: Vector6::new(0.01, 0.01, 1e-4, 0.25, 0.25, 1e-4),
            draw_error: true,
        }
    }

    /// Fig 2 (wrong ICs): P₀ = diag(1, 1, 1, 25, 25, 1) (erratum E5),
    /// x̂₀ = x₀ + (1, −1, 0.5, 5, −5, 0.5) (the paper gives no values; about one σ each).
    pub fn wrong() -> Self {
        Self {
            offset: Vector6::new(1.0, -1.0, 0.5, 5.0, -5.0, 0.5),
            variances: Vector6::new(1.0, 1.0, 1.0, 25.0, 25.0, 1.0),
            draw_error: false,
        }
    }
}

/// Settings of the circle example.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CircleConfig {
    /// t_end, s (not given in the paper; 20 s).
    pub t_end: f64,
    /// Accelerometer period h, s (Table 1: 0.01).
    pub dt: f64,
    /// Circle radius, m (10).
    pub circle_radius: f64,
    /// R, half the sensor separation, m (0.5).
    pub half_separation: f64,
    /// The rate slope in ω = sgn(t − t_end/2)·slope·t, rad/s² (0.1).
    pub rate_slope: f64,
    /// σ_a per accelerometer channel, m/s² (Table 1: 9.8e-3).
    pub sigma_accel: f64,
    /// σ_xy of the position fixes, m (Table 1: 1.0).
    pub sigma_xy: f64,
    /// σ_yθ of the compass, rad (Table 1: 0.1).
    pub sigma_theta: f64,
    /// Period of the position/compass fixes, s (Table 1: 1.0).
    pub fix_period: f64,
    /// Monte Carlo runs.
    pub runs: usize,
    /// Seed of run 0 (run k uses seed + k).
    pub seed: u64,
    /// Start of the "settled" part over which averages are taken, s.
    pub settle_time: f64,
    /// The filter.
    pub filter: FilterKind,
    /// The process model.
    pub process: ProcessKind,
    /// ICs of the Monte Carlo runs.
    pub initial: InitialConditions,
}

impl CircleConfig {
    /// Table 1 with the documented reading: t_end = 20 s, 50 runs, settled part t ≥ 2 s,
    /// paper's filter (EKF, linear process), correct ICs.
    pub fn paper() -> Self {
        Self {
            t_end: 20.0,
            dt: 0.01,
            circle_radius: 10.0,
            half_separation: 0.5,
            rate_slope: 0.1,
            sigma_accel: 9.8e-3,
            sigma_xy: 1.0,
            sigma_theta: 0.1,
            fix_period: 1.0,
            runs: 50,
            seed: 7,
            settle_time: 2.0,
            filter: FilterKind::Ekf,
            process: ProcessKind::Linear,
            initial: InitialConditions::correct(),
        }
    }

    /// As [`paper`](Self::paper) with 20 runs.
    pub fn quick() -> Self {
        Self {
            runs: 20,
            ..Self::paper()
        }
    }

    /// Number of accelerometer steps, t_end/h (rounded; saturating, so an out-of-range t_end
    /// gives a count that [`validate`](Self::validate) rejects).
    pub fn steps(&self) -> usize {
        (self.t_end / self.dt).round() as usize
    }

    /// Steps between fixes, round(fix_period/h) ≥ 1 (saturating; a NaN or infinite period is
    /// rejected by [`validate`](Self::validate), not read as "every step").
    pub fn fix_every(&self) -> usize {
        ((self.fix_period / self.dt).round() as usize).max(1)
    }

    /// The accelerometer channel variances (all σ_a²).
    pub fn variances(&self) -> ChannelVariances {
        ChannelVariances::equal(self.sigma_accel)
    }

    /// The GPS/compass model.
    pub fn fix_model(&self) -> PositionHeadingMeasurement {
        PositionHeadingMeasurement {
            sigma_xy: self.sigma_xy,
            sigma_theta: self.sigma_theta,
        }
    }

    /// Checks the configuration: Δt finite and > 0 ([`Parameter::StepSize`]), t_end finite
    /// and > 0 with at most [`MAX_STEPS`](crate::limits::MAX_STEPS) steps ([`Parameter::Duration`]),
    /// the fix period finite and > 0 ([`Parameter::Period`]), 1 ≤ runs ≤
    /// [`MAX_RUNS`](crate::limits::MAX_RUNS) ([`Parameter::RunCount`]), an even number of
    /// steps ≥ 2 (so t_end/2 is a sample), R > 0.
    ///
    /// Errors: [`Error::InvalidParameter`] (the parameters above; sample count for the rest)
    /// otherwise.
    ///
    /// ```
    /// use estim_models::boje::CircleConfig;
    /// assert!(CircleConfig::paper().validate().is_ok());
    /// let never = CircleConfig { fix_period: f64::NAN, ..CircleConfig::paper() };
    /// assert!(never.validate().is_err());
    /// ```
    pub fn validate(&self) -> Result<()> {
        use crate::limits::{check_period, check_runs, steps_for_duration};
        let steps = steps_for_duration(self.t_end, self.dt)?;
        check_period(self.fix_period, Parameter::Period)?;
        check_runs(self.runs)?;
        let ok = self.dt > 0.0
            && self.t_end > 0.0
            && steps >= 2
            && steps.is_multiple_of(2)
            && self.runs > 0
            && self.half_separation > 0.0;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidParameter {
                parameter: Parameter::SampleCount,
                value: steps as f64,
            })
        }
    }
}

/// Truth and sensor data of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct CircleData {
    /// tₖ = k h, k = 0..=K.
    pub times: Vec<f64>,
    /// The true state xₖ, k = 0..=K.
    pub truth: Vec<Vector6<f64>>,
    /// The true inertial input uₖ = (ẍ, ÿ, θ̈) over [tₖ, tₖ₊₁], k = 0..K.
    pub inputs: Vec<Vector3<f64>>,
    /// The accelerometer samples aₖ, k = 0..K.
    pub accel: Vec<Vector4<f64>>,
    /// The GPS/compass fix (x, y, θ wrapped) at step k, if any (k = fix period, 2·period, …
    /// < K).
    pub fixes: Vec<Option<Vector3<f64>>>,
}

/// ω(t) = sgn(t − t_end/2)·slope·t with sgn(0) = +1.
pub fn circle_rate(t: f64, config: &CircleConfig) -> f64 {
    let sign = if t >= config.t_end / 2.0 { 1.0 } else { -1.0 };
    sign * config.rate_slope * t
}

/// φ(t) = ∫₀ᵗ ω: −slope t²/2 before t_end/2, slope t²/2 − slope t_end²/4 after.
pub fn circle_angle(t: f64, config: &CircleConfig) -> f64 {
    let half = config.t_end / 2.0;
    if t >= half {
        0.5 * config.rate_slope * t * t - 0.25 * config.rate_slope * config.t_end * config.t_end
    } else {
        -0.5 * config.rate_slope * t * t
    }
}

/// Simulates one run of the circle scenario with the given seed.
///
/// Errors: invalid configuration (non-positive step, odd number of steps so t_end/2 is not a
/// sample, no runs).
pub fn simulate_circle(config: &CircleConfig, seed: u64) -> Result<CircleData> {
    config.validate()?;
    let k_steps = config.steps();
    let h = config.dt;
    let r = config.circle_radius;
    let every = config.fix_every();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let velocity = |k: usize| {
        let t = k as f64 * h;
        let (w, phi) = (circle_rate(t, config), circle_angle(t, config));
        let (s, c) = phi.sin_cos();
        Vector3::new(-r * w * s, r * w * c, w)
    };
    let (a, b) = (transition_matrix(h), input_matrix(h));
    let mut x = Vector6::new(0.0, 0.0, 0.0, r, 0.0, std::f64::consts::FRAC_PI_2);
    let v0 = velocity(0);
    x.fixed_view_mut::<3, 1>(0, 0).copy_from(&v0);
    let mut data = CircleData {
        times: Vec::with_capacity(k_steps + 1),
        truth: Vec::with_capacity(k_steps + 1),
        inputs: Vec::with_capacity(k_steps),
        accel: Vec::with_capacity(k_steps),
        fixes: Vec::with_capacity(k_steps),
    };
    let mut v = v0;
    for k in 0..k_steps {
        data.times.push(k as f64 * h);
        data.truth.push(x);
        let v_next = velocity(k + 1);
        let u = (v_next - v) / h;
        let inertial = Vector4::new(u[0], u[1], u[2], x[RATE] * x[RATE]);
        let mut sample = sensor_signals(x[HEADING], &inertial, config.half_separation);
        for s in sample.iter_mut() {
            *s += config.sigma_accel * normal();
        }
        let fix = if k > 0 && k.is_multiple_of(every) {
            Some(Vector3::new(
                x[X] + config.sigma_xy * normal(),
                x[Y] + config.sigma_xy * normal(),
                wrap_angle(x[HEADING] + config.sigma_theta * normal()),
            ))
        } else {
            None
        };
        data.inputs.push(u);
        data.accel.push(sample);
        data.fixes.push(fix);
        x = a * x + b * u;
        v = v_next;
    }
    data.times.push(k_steps as f64 * h);
    data.truth.push(x);
    Ok(data)
}

/// The prior N(x̂₀, P₀) for a run whose true initial state is `truth0`; `rng_seed` draws the
/// initial error when `initial.draw_error`.
///
/// Errors: a negative or non-finite P₀.
pub fn initial_prior(
    truth0: &Vector6<f64>,
    initial: &InitialConditions,
    rng_seed: u64,
) -> Result<Gaussian<f64, estim_core::nalgebra::U6>> {
    let offset = if initial.draw_error {
        let mut rng = StdRng::seed_from_u64(rng_seed ^ 0x5eed_0f1c);
        initial.variances.map(|v| {
            let n: f64 = StandardNormal.sample(&mut rng);
            v.max(0.0).sqrt() * n
        })
    } else {
        initial.offset
    };
    Gaussian::new(truth0 + offset, Matrix6::from_diagonal(&initial.variances))
}
