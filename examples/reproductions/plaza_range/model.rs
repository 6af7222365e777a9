//! The estimation model of `plaza_range`: a unicycle pose driven by wheel odometry, range
//! biases as Gauss-Markov states, and one biased range sensor per beacon, all from
//! `estim_models` (motion, augment, sensors); plus the particle filter's own sampler and
//! outlier-tolerant likelihood for the same model.
//!
//! State (static size [`N`]): x = (x, y, ψ, c, g₀ … g₇): the pose, a bias c common to every
//! range (the robot's radio and antenna delay) and one bias gⱼ per beacon (its multipath and
//! antenna delay). A reading of beacon j at oⱼ is
//!
//! ```text
//! z = ‖(x, y) − oⱼ‖ + c + gⱼ + v,    v ~ N(0, σ_w²)
//! ```
//!
//! **Why a common bias and one per beacon** (rather than one bias, or per-beacon biases only):
//! an uncalibrated UWB radio adds its own delay to every range (metres, the same for all
//! beacons: c), while multipath, non-line-of-sight paths and each beacon's antenna delay differ
//! per beacon and change as the robot moves (gⱼ, zero-mean, correlated over tens of seconds).
//! One bias cannot follow the second part; per-beacon biases alone would have to learn the
//! large common part four times from a zero-mean prior. On the Plaza run the EKF ends with
//! c ≈ 2.6 m and gⱼ between −1.3 and +1.6 m (the per-beacon mean range errors against the
//! ground truth, +1.9 to +3.4 m in the data's README, are time averages of c + gⱼ).
//!
//! c and gⱼ are first-order Gauss-Markov processes (`GaussMarkov`): ranges have
//! time-correlated errors, and modelling them as states is what lets the filter be both
//! accurate and consistent (a white-noise range model that is consistent must inflate σ_w to
//! the correlated part's size and then weights every reading too little; one that is accurate
//! is overconfident). The state has room for [`MAX_BEACONS`] beacons, so any survey of up to
//! that many runs with the same static sizes; the bias states of absent beacons are never
//! observed and stay at their prior.

use estim_core::nalgebra::{Const, Matrix1, SMatrix, SVector, Vector1, Vector2, Vector3};
use estim_core::rand::Rng;
use estim_core::rand_distr::{Distribution, StandardNormal};
use estim_core::{MeasurementModel, ProcessModel};
use estim_filters::particle::{MeasurementLikelihood, ProcessSampler};
use estim_models::augment::{Augmented, Biased};
use estim_models::motion::{GaussMarkov, Unicycle};
use estim_models::sensors::Range;

/// The most beacons the state has room for.
pub const MAX_BEACONS: usize = 8;
/// Bias states: the common one and one per beacon.
pub const K: usize = 1 + MAX_BEACONS;
/// The state size: pose (3) and biases.
pub const N: usize = 3 + K;
/// Index of the common bias c.
pub const COMMON: usize = 3;

/// The state vector.
pub type State = SVector<f64, N>;
/// The odometry-driven motion with the bias states appended.
pub type Motion = Augmented<Unicycle<f64>, GaussMarkov<f64, K>, 3, K>;
/// A range to one beacon with the common and the beacon's bias added.
pub type BiasedRange = Biased<Range<f64, 2>, f64, 3, 1, K>;

/// The noise settings, each a physical statement about the sensors (see [`Noise::default`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    /// Odometry distance error growth [m/√m]: the distance travelled over a step has variance
    /// k_d² |Δd| (wheel slip and radius error accumulate as a random walk per metre).
    pub distance_per_sqrt_m: f64,
    /// Odometry heading error growth [rad/√m]: the turn over a step has variance
    /// k_ψ² |Δd| + q_ψ Δt (differential wheel slip while driving, plus a small drift).
    pub heading_per_sqrt_m: f64,
    /// q_ψ [rad²/s]: heading drift density independent of the motion.
    pub heading_drift: f64,
    /// σ_w [m]: the white part of a UWB range error.
    pub range_sd: f64,
    /// σ_g [m]: the steady-state size of a beacon's correlated range error (multipath,
    /// non-line-of-sight paths, its antenna delay).
    pub beacon_bias_sd: f64,
    /// τ_g [s]: how long a beacon's range error stays correlated.
    pub beacon_bias_tau: f64,
    /// σ_c [m]: the prior size of the range bias common to every beacon (the robot's radio).
    pub common_bias_sd: f64,
    /// q_c [m²/s]: the drift density of the common bias (τ_c = 2σ_c²/q_c).
    pub common_bias_drift: f64,
    /// The particle filter's probability that a range is an outlier (uniform over
    /// [`OUTLIER_SPAN`]) rather than z = h(x) + v.
    pub outlier_probability: f64,
    /// The particle filter's roughening of the pose [m/√s, rad/√s]: a jitter of this density
    /// added to each particle's position and heading (Gordon, Salmond & Smith 1993), so that
    /// the cloud keeps distinct poses while the robot stands still and ranges keep coming
    /// (with no motion the odometry adds no noise, and resampling alone would collapse it).
    pub particle_jitter: [f64; 2],
}

/// The span of range errors an outlier is drawn from in the particle filter's likelihood [m].
pub const OUTLIER_SPAN: f64 = 50.0;

impl Default for Noise {
    /// The settings, none fitted by an optimiser to a log. In fairness: σ_g and τ_g were
    /// picked after looking at this run's range residuals against its ground truth (and agree
    /// with the data README's spread of 0.8–1.8 m), and the particle roughening and count were
    /// set after a first full run on the Plaza log; another recording may want other values:
    ///
    /// - odometry: 5 cm of distance and 0.6° of heading error per √m driven (a wheeled robot
    ///   on pavement and grass; 1 % to 5 % of distance over tens of metres), q_ψ 1e-6 rad²/s;
    /// - UWB ranges: white σ_w 0.5 m, a per-beacon correlated error of σ_g 1 m lasting
    ///   τ_g 30 s (multipath changes as the robot moves tens of metres at about 1 m/s), and a
    ///   common bias of up to σ_c 5 m (radio and antenna delays are metres for uncalibrated UWB)
    ///   drifting by q_c 1e-4 m²/s (0.4 m over half an hour, a temperature drift);
    /// - for the particle filter, a range outlier probability of 5 % and a pose roughening of
    ///   5 cm/√s and 0.3°/√s (0.35 m and 2° over the 48 s the Plaza robot stands at the start,
    ///   below the ranges' resolution).
    fn default() -> Self {
        Self {
            distance_per_sqrt_m: 0.05,
            heading_per_sqrt_m: 0.01,
            heading_drift: 1e-6,
            range_sd: 0.5,
            beacon_bias_sd: 1.0,
            beacon_bias_tau: 30.0,
            common_bias_sd: 5.0,
            common_bias_drift: 1e-4,
            outlier_probability: 0.05,
            particle_jitter: [0.05, 0.005],
        }
    }
}

impl Noise {
    /// The bias dynamics: c with τ_c = 2σ_c²/q_c, every gⱼ with (τ_g, σ_g²).
    pub fn biases(&self) -> GaussMarkov<f64, K> {
        let mut time_constant = SVector::<f64, K>::repeat(self.beacon_bias_tau);
        let mut variance = SVector::<f64, K>::repeat(self.beacon_bias_sd.powi(2));
        time_constant[0] = 2.0 * self.common_bias_sd.powi(2) / self.common_bias_drift;
        variance[0] = self.common_bias_sd.powi(2);
        GaussMarkov {
            time_constant,
            variance,
        }
    }

    /// The motion model over a step of `dt` with input u = (v, ω): the unicycle's input
    /// variances are those of the step's mean speed and rate, so they are the distance and
    /// turn variances above divided by Δt² (which keeps a step split in two as noisy as the
    /// whole).
    pub fn motion(&self, u: &Vector2<f64>, dt: f64) -> Motion {
        let distance = u[0].abs() * dt;
        let speed = self.distance_per_sqrt_m.powi(2) * distance / (dt * dt);
        let rate =
            (self.heading_per_sqrt_m.powi(2) * distance + self.heading_drift * dt) / (dt * dt);
        Augmented {
            model: Unicycle {
                speed_variance: speed,
                rate_variance: rate,
            },
            augment: self.biases(),
        }
    }

    /// The range sensor of the beacon at `index` (of at most [`MAX_BEACONS`]) at `origin`.
    pub fn range(&self, index: usize, origin: Vector2<f64>) -> BiasedRange {
        let mut coupling = SMatrix::<f64, 1, K>::zeros();
        coupling[0] = 1.0;
        coupling[1 + index] = 1.0;
        Biased {
            model: Range {
                origin,
                variance: self.range_sd.powi(2),
            },
            coupling,
        }
    }
}

/// The motion as the particle filter samples it: the odometry input is perturbed (speed and
/// rate drawn from their variances) and the pose moved exactly, the biases drawn from their
/// exact Gauss-Markov transition. This is the model's true noise (a particle's pose noise is
/// not additive Gaussian: it bends with the heading), and it avoids a factorisation of a
/// state-dependent Q per particle. Only the first `beacons` beacon biases are drawn: the
/// others are never observed (they keep their value).
#[derive(Clone, Copy, Debug)]
pub struct SampledMotion {
    motion: Motion,
    beacons: usize,
    /// Per bias state: e^{−Δt/τ} and the standard deviation of the step's noise.
    decay: [f64; K],
    sd: [f64; K],
    /// The standard deviations of the speed and rate inputs.
    input_sd: [f64; 2],
    /// The roughening's standard deviations over the step (position, heading).
    jitter_sd: [f64; 2],
}

impl SampledMotion {
    /// The sampler of `motion` over a step of `dt`, drawing the biases of `beacons` beacons,
    /// with the pose roughened by `jitter` (densities, see [`Noise::particle_jitter`]).
    pub fn new(motion: Motion, beacons: usize, dt: f64, jitter: [f64; 2]) -> Self {
        let b = &motion.augment;
        Self {
            motion,
            beacons: beacons.min(MAX_BEACONS),
            decay: std::array::from_fn(|i| (-dt / b.time_constant[i]).exp()),
            sd: std::array::from_fn(|i| {
                (-b.variance[i] * (-2.0 * dt / b.time_constant[i]).exp_m1()).sqrt()
            }),
            input_sd: [
                motion.model.speed_variance.sqrt(),
                motion.model.rate_variance.sqrt(),
            ],
            jitter_sd: jitter.map(|j| j * dt.sqrt()),
        }
    }
}

impl ProcessModel<f64, Const<N>> for SampledMotion {
    type Input = Vector2<f64>;

    fn transition(&self, x: &State, u: &Vector2<f64>, dt: f64) -> State {
        self.motion.transition(x, u, dt)
    }

    fn process_noise(&self, x: &State, u: &Vector2<f64>, dt: f64) -> SMatrix<f64, N, N> {
        self.motion.process_noise(x, u, dt)
    }
}

impl ProcessSampler<f64, Const<N>> for SampledMotion {
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        x: &State,
        u: &Vector2<f64>,
        dt: f64,
        rng: &mut R,
    ) -> State {
        let mut normal = || -> f64 { StandardNormal.sample(rng) };
        let noisy = Vector2::new(
            u[0] + self.input_sd[0] * normal(),
            u[1] + self.input_sd[1] * normal(),
        );
        let pose = self
            .motion
            .model
            .transition(&Vector3::new(x[0], x[1], x[2]), &noisy, dt);
        let mut y = *x;
        y[0] = pose[0] + self.jitter_sd[0] * normal();
        y[1] = pose[1] + self.jitter_sd[0] * normal();
        y[2] = pose[2] + self.jitter_sd[1] * normal();
        for i in 0..=self.beacons {
            y[3 + i] = self.decay[i] * x[3 + i] + self.sd[i] * normal();
        }
        y
    }
}

/// A range whose error is, with probability ε, an outlier uniform over [`OUTLIER_SPAN`], and
/// otherwise N(0, σ_w²): p(z | x) = (1 − ε) N(z − h(x); 0, σ_w²) + ε / span. The particle
/// filter's counterpart of the Kalman filters' gate (a gated Gaussian update cannot be written
/// as a likelihood; this mixture down-weights an outlier instead of letting it empty the cloud).
#[derive(Clone, Copy, Debug)]
pub struct TolerantRange {
    pub range: BiasedRange,
    pub outlier_probability: f64,
}

impl MeasurementModel<f64, Const<N>, Const<1>> for TolerantRange {
    fn measure(&self, x: &State) -> Vector1<f64> {
        self.range.measure(x)
    }

    fn measurement_noise(&self, x: &State) -> Matrix1<f64> {
        self.range.measurement_noise(x)
    }
}

impl MeasurementLikelihood<f64, Const<N>, Const<1>> for TolerantRange {
    fn log_likelihood(&self, z: &Vector1<f64>, x: &State) -> f64 {
        let variance = self.range.model.variance;
        let e = z[0] - self.range.measure(x)[0];
        let inlier = (1.0 - self.outlier_probability) * (-0.5 * e * e / variance).exp()
            / (2.0 * std::f64::consts::PI * variance).sqrt();
        (inlier + self.outlier_probability / OUTLIER_SPAN).ln()
    }
}
