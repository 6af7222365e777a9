//! Seeded simulator of the truth, the biased accelerometer and the GPS receiver.
//!
//! One realization draws, in this order from one `StdRng` seeded with the run's seed:
//! p(0) ~ N(p̄₀, M₀ᵖ), v(0) ~ N(v̄₀, M₀ᵛ), b ~ N(0, M₀ᵇ) (constant for the run); then, as the
//! caller asks for them, one accelerometer noise sample w_j per step and two GPS noise samples
//! (η_p, η_v) per fix. At step j (t_j = j Δt):
//!
//! ```text
//! a_c(t_j) = a(t_j) + b + w_j,   w_j ~ N(0, W)
//! truth, Euler (default):  v(t_{j+1}) = v(t_j) + a(t_j) Δt,  p(t_{j+1}) = p(t_j) + v(t_j) Δt + a(t_j) Δt²/2
//! truth, exact:            the closed forms of §2.1
//! z(t_j) = (p(t_j) + η_p, v(t_j) + η_v),   η ~ N(0, diag(V_p, V_v))
//! ```
//!
//! a(t_j) = A sin(2π f t_j) is the same in every realization; a Monte Carlo computes it once
//! per step index ([`AccelerationProfile`]) and hands it to every run
//! ([`Simulator::with_profile`]): the same numbers, without a sine per step and run (the sine
//! was a third of the CPU time of Lu's 5000-run validation).

use std::sync::Arc;

use estim_core::Error;
use nalgebra::{Vector2, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

use super::model::{Mechanisation, Scenario, TruthIntegration};

/// The true kinematic state at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truth {
    /// p \[m\].
    pub position: f64,
    /// v \[m/s\].
    pub velocity: f64,
    /// The accelerometer bias b \[m/s²\].
    pub bias: f64,
}

impl Truth {
    /// The true error state δx = (p − p_c, v − v_c, b) against a mechanisation.
    #[inline]
    pub fn error_state(&self, mechanisation: &Mechanisation) -> Vector3<f64> {
        Vector3::new(
            self.position - mechanisation.position,
            self.velocity - mechanisation.velocity,
            self.bias,
        )
    }
}

/// The true acceleration a(t_j) = A sin(2π f t_j) at every step j = 0 … steps − 1 of a
/// scenario, computed once ([`Scenario::acceleration`] at t_j = j Δt, so bit for bit what a
/// [`Simulator`] computes itself) and shared by reference count between simulators
/// ([`Simulator::with_profile`]).
#[derive(Clone, Debug, PartialEq)]
pub struct AccelerationProfile {
    /// (A, f, Δt) it was computed for, as bits: a simulator of another scenario ignores it.
    key: [u64; 3],
    values: Arc<[f64]>,
}

impl AccelerationProfile {
    /// a(t_j) for every step of `scenario`.
    ///
    /// Errors: an invalid scenario ([`Scenario::validate`]; at most
    /// [`MAX_STEPS`](crate::limits::MAX_STEPS) steps), checked before anything is allocated.
    ///
    /// ```
    /// use estim_models::lu::{AccelerationProfile, Scenario};
    /// let s = Scenario::paper();
    /// let profile = AccelerationProfile::new(&s)?;
    /// assert_eq!(profile.values().len(), s.steps);
    /// assert_eq!(profile.values()[50], s.acceleration(50.0 * s.dt));
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn new(scenario: &Scenario) -> Result<Self, Error> {
        scenario.validate()?;
        let values = (0..scenario.steps)
            .map(|j| scenario.acceleration(j as f64 * scenario.dt))
            .collect();
        Ok(Self {
            key: profile_key(scenario),
            values,
        })
    }

    /// a(t_j), j = 0 … steps − 1 \[m/s²\].
    pub fn values(&self) -> &[f64] {
        &self.values
    }
}

/// What a(t_j) depends on: amplitude, frequency and Δt.
fn profile_key(s: &Scenario) -> [u64; 3] {
    [s.amplitude.to_bits(), s.frequency.to_bits(), s.dt.to_bits()]
}

/// A realization being generated step by step (no storage: what the Monte Carlo uses).
#[derive(Clone, Debug)]
pub struct Simulator {
    scenario: Scenario,
    rng: StdRng,
    /// a(t_j) precomputed ([`AccelerationProfile`]); empty when computed per step.
    profile: Arc<[f64]>,
    step: usize,
    truth: Truth,
    initial_position: f64,
    initial_velocity: f64,
}

impl Simulator {
    /// Draws the initial position, velocity and bias of one realization from `seed`.
    pub fn new(scenario: &Scenario, seed: u64) -> Self {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut normal = || rng.sample::<f64, _>(StandardNormal);
        let p0 = scenario.position_mean + scenario.position_variance.sqrt() * normal();
        let v0 = scenario.velocity_mean + scenario.velocity_variance.sqrt() * normal();
        let b = scenario.bias_variance.sqrt() * normal();
        Self {
            scenario: *scenario,
            rng,
            profile: Arc::from([]),
            step: 0,
            truth: Truth {
                position: p0,
                velocity: v0,
                bias: b,
            },
            initial_position: p0,
            initial_velocity: v0,
        }
    }

    /// [`new`](Self::new), taking a(t_j) from `profile` instead of computing a sine per step:
    /// the same draws and the same numbers bit for bit. A profile computed for another
    /// amplitude, frequency or Δt is ignored (a(t_j) is then computed as by `new`), as are
    /// steps beyond its length.
    ///
    /// ```
    /// use estim_models::lu::{AccelerationProfile, Scenario, Simulator};
    /// let s = Scenario::paper().with_duration(1.0);
    /// let profile = AccelerationProfile::new(&s)?;
    /// let (mut a, mut b) = (Simulator::new(&s, 7), Simulator::with_profile(&s, 7, &profile));
    /// for _ in 0..s.steps {
    ///     assert_eq!(a.accelerometer(), b.accelerometer());
    /// }
    /// # Ok::<(), estim_core::Error>(())
    /// ```
    pub fn with_profile(scenario: &Scenario, seed: u64, profile: &AccelerationProfile) -> Self {
        let mut sim = Self::new(scenario, seed);
        if profile.key == profile_key(scenario) {
            sim.profile = Arc::clone(&profile.values);
        }
        sim
    }

    /// The scenario.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The current step index j (0 at the start).
    #[inline]
    pub fn step_index(&self) -> usize {
        self.step
    }

    /// The current time t_j = j Δt \[s\].
    #[inline]
    pub fn time(&self) -> f64 {
        self.step as f64 * self.scenario.dt
    }

    /// The truth at the current time.
    #[inline]
    pub fn truth(&self) -> Truth {
        self.truth
    }

    /// The accelerometer reading a_c(t_j) at the current step j; then advances the truth to
    /// t_{j+1}.
    pub fn accelerometer(&mut self) -> f64 {
        let s = &self.scenario;
        let dt = s.dt;
        let a = match self.profile.get(self.step) {
            Some(&a) => a,
            None => s.acceleration(self.time()),
        };
        let w = s.accel_noise_variance.sqrt() * self.rng.sample::<f64, _>(StandardNormal);
        self.step += 1;
        match s.truth {
            TruthIntegration::Euler => {
                let truth = &mut self.truth;
                truth.position += truth.velocity * dt + 0.5 * a * dt * dt;
                truth.velocity += a * dt;
            }
            TruthIntegration::Exact => {
                let (p, v) = s.exact_position_velocity(
                    self.initial_position,
                    self.initial_velocity,
                    self.time(),
                );
                self.truth.position = p;
                self.truth.velocity = v;
            }
        }
        a + self.truth.bias + w
    }

    /// A GPS fix (z_p, z_v) of the truth at the current time.
    pub fn gps(&mut self) -> Vector2<f64> {
        let s = &self.scenario;
        let (sp, sv) = (
            s.gps_position_variance.sqrt(),
            s.gps_velocity_variance.sqrt(),
        );
        let ep = sp * self.rng.sample::<f64, _>(StandardNormal);
        let ev = sv * self.rng.sample::<f64, _>(StandardNormal);
        Vector2::new(self.truth.position + ep, self.truth.velocity + ev)
    }

    /// Whether a GPS fix is due at the current step (every `gps_every` steps, not at t = 0).
    #[inline]
    pub fn gps_due(&self) -> bool {
        self.step > 0 && self.step.is_multiple_of(self.scenario.gps_every)
    }
}

/// One whole realization, stored: the sensor streams and the truth at every step.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorRecord {
    /// a_c(t_j) for j = 0 … steps − 1 \[m/s²\].
    pub accelerometer: Vec<f64>,
    /// (step index, z) of every GPS fix, at steps gps_every, 2 gps_every, ….
    pub gps: Vec<(usize, Vector2<f64>)>,
    /// The truth at t_j for j = 0 … steps.
    pub truth: Vec<Truth>,
}

/// Simulates one realization of `scenario` from `seed` and stores it. Draws the same numbers as
/// a [`Simulator`] driven step by step (accelerometer, then the GPS fix when due).
///
/// Errors: an invalid scenario ([`Scenario::validate`]; at most
/// [`MAX_STEPS`](crate::limits::MAX_STEPS) steps, so the record stays under ~330 MB),
/// checked before anything is allocated.
///
/// ```
/// use estim_models::lu::{Scenario, simulate};
/// let record = simulate(&Scenario::paper().with_duration(1.0), 7)?;
/// assert_eq!(record.accelerometer.len(), 200);
/// assert!(simulate(&Scenario::paper().with_duration(f64::INFINITY), 7).is_err());
/// # Ok::<(), estim_core::Error>(())
/// ```
pub fn simulate(scenario: &Scenario, seed: u64) -> Result<SensorRecord, Error> {
    scenario.validate()?;
    let mut sim = Simulator::new(scenario, seed);
    let mut record = SensorRecord {
        accelerometer: Vec::with_capacity(scenario.steps),
        gps: Vec::with_capacity(scenario.updates()),
        truth: Vec::with_capacity(scenario.steps + 1),
    };
    record.truth.push(sim.truth());
    for _ in 0..scenario.steps {
        record.accelerometer.push(sim.accelerometer());
        record.truth.push(sim.truth());
        if sim.gps_due() {
            let z = sim.gps();
            record.gps.push((sim.step_index(), z));
        }
    }
    Ok(record)
}
