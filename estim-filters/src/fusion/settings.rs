//! The driver's settings and each sensor's: gate, reset rule, fault monitor. Probabilities are
//! turned into χ² thresholds once, at construction.

use estim_core::Real;
use estim_core::nalgebra::convert;

use super::error::{FusionError, FusionSetting};
use crate::consistency::dist::chi2_quantile;

/// The driver's time, memory and duplicate settings.
///
/// Construct with `..FusionSettings::default()` so that settings added later keep your code
/// compiling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusionSettings {
    /// How late a measurement may be \[s\]: one taken more than `horizon` before the latest
    /// event is refused ([`FusionError::TooOld`]). Finite, ≥ 0.
    pub horizon: f64,
    /// The number of records the history keeps (one per measurement, input change or time
    /// mark, plus the checkpoint). When it is full the oldest record is dropped, which can
    /// shorten the usable horizon: size it as (events per second) × horizon + 2. At least 2,
    /// at most [`FusionSettings::MAX_CAPACITY`] (every record is allocated up front). It is
    /// also the span [`FusionDriver::smooth`](super::FusionDriver::smooth) can smooth.
    pub capacity: usize,
    /// The longest single prediction \[s\]; longer gaps are predicted in equal sub-steps.
    /// \> 0, `f64::INFINITY` allowed (the default: **no subdivision**, one prediction per gap,
    /// at the events' own times, as the filters and the batch functions predict). Set it for
    /// a model discretised for one sample period (like Lu's error state, whose Q is per
    /// sample: then it is that period), or to bound the linearisation error of a nonlinear
    /// model over long gaps. Why not a small default: the models of the family take Δt, so a
    /// gap needs no cutting, and a default of 0.01 s silently turned a 0.2 s odometry
    /// interval into 20 predictions (20 times the work, and 20 times the noise of a model
    /// whose Q is per call).
    pub max_step: f64,
    /// The most sub-steps one gap may take (a guard against a timestamp far in the future,
    /// which would otherwise make a call run for hours). At least 1.
    pub max_substeps: usize,
    /// What to do with a second reading of a sensor at a time that already has one
    /// ([`DuplicatePolicy`]; default [`FuseBoth`](DuplicatePolicy::FuseBoth)).
    pub duplicates: DuplicatePolicy,
}

impl Default for FusionSettings {
    /// horizon 1 s, 256 records, no subdivision (max step ∞), at most 10⁶ sub-steps per gap,
    /// duplicates fused.
    fn default() -> Self {
        Self {
            horizon: 1.0,
            capacity: 256,
            max_step: f64::INFINITY,
            max_substeps: 1_000_000,
            duplicates: DuplicatePolicy::FuseBoth,
        }
    }
}

/// Two readings of one sensor with one timestamp: what the driver does with the second.
///
/// The default is [`FuseBoth`](Self::FuseBoth): a real log does repeat (time, sensor) pairs
/// (a timestamp rounded to the logger's tick, two replies of one beacon in one frame), and
/// two readings of a sensor are two measurements with independent noise, which is exactly
/// what fusing both assumes; stopping a run over it (the old behaviour, still
/// [`Refuse`](Self::Refuse)) loses the rest of the log. When the log writes the *same*
/// reading twice (a retransmission), fusing both would count it twice: choose
/// [`KeepFirst`](Self::KeepFirst).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum DuplicatePolicy {
    /// Fuse both, in the order they arrive (after the earlier one, before any later sensor).
    #[default]
    FuseBoth,
    /// Keep the first and ignore the second: `fuse` returns the first one's decision with
    /// [`Fused::ignored`](super::Fused::ignored) set, and nothing changes.
    KeepFirst,
    /// Refuse the second with [`FusionError::Duplicate`].
    Refuse,
}

impl FusionSettings {
    /// The largest history: 2¹⁶ records (at 1 kHz of events, a horizon of over a minute), a
    /// bound that keeps a mistyped capacity from allocating without limit.
    pub const MAX_CAPACITY: usize = 1 << 16;

    pub(crate) fn validate(&self) -> Result<(), FusionError> {
        if !(self.horizon.is_finite() && self.horizon >= 0.0) {
            return Err(FusionError::setting(FusionSetting::Horizon, self.horizon));
        }
        if !(2..=Self::MAX_CAPACITY).contains(&self.capacity) {
            return Err(FusionError::setting(
                FusionSetting::Capacity,
                self.capacity as f64,
            ));
        }
        if !(self.max_step > 0.0) {
            return Err(FusionError::setting(FusionSetting::MaxStep, self.max_step));
        }
        if self.max_substeps == 0 {
            return Err(FusionError::setting(FusionSetting::MaxSubsteps, 0.0));
        }
        Ok(())
    }
}

/// Which interval a sampled input covers: how [`FusionDriver::set_input`](super::FusionDriver::set_input)
/// reads the time it is given.
///
/// With inputs u₁, u₂, … at times t₁ < t₂ < …:
///
/// - [`HoldForward`](Self::HoldForward) (the default): uₖ is held from tₖ on, over
///   \[tₖ, tₖ₊₁): a command, a setpoint, a value that takes effect when it is set.
/// - [`Preceding`](Self::Preceding): uₖ covers the interval **before** its timestamp,
///   (tₖ₋₁, tₖ\]: an IMU sample (an increment or an average over the last sample period), a
///   wheel-odometry count. The prediction up to tₖ uses uₖ, also for a measurement taken
///   inside (tₖ₋₁, tₖ) that was fused before uₖ arrived: until uₖ arrives, the driver
///   predicts past tₖ₋₁ with uₖ₋₁ held forward (the real-time estimate), and when uₖ arrives
///   every event after tₖ₋₁ is re-run with it (from the history, as for a late
///   measurement), so the result does not depend on whether the measurement or the sample
///   came first, to the bit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum InputConvention {
    /// An input is held from its timestamp on.
    #[default]
    HoldForward,
    /// An input covers the interval from the previous input's timestamp to its own.
    Preceding,
}

/// How one sensor's measurements are judged. Each part is optional; [`SensorSettings::default`]
/// accepts everything (no gate, no reset, no monitor).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SensorSettings {
    /// Reject a measurement whose NIS exceeds the χ²ₘ quantile at this probability (e.g.
    /// 0.9999: one clean measurement in 10⁴ is rejected). `None`: no gate.
    pub gate_probability: Option<f64>,
    /// When to re-initialise the filter from this sensor. `None`: never.
    pub reset: Option<ResetSettings>,
    /// The windowed NIS fault monitor. `None`: never excluded.
    pub monitor: Option<MonitorSettings>,
}

impl SensorSettings {
    /// Only a gate at `probability`.
    pub fn gated(probability: f64) -> Self {
        Self {
            gate_probability: Some(probability),
            ..Self::default()
        }
    }

    /// These settings with `reset`.
    pub fn with_reset(mut self, reset: ResetSettings) -> Self {
        self.reset = Some(reset);
        self
    }

    /// These settings with `monitor`.
    pub fn with_monitor(mut self, monitor: MonitorSettings) -> Self {
        self.monitor = Some(monitor);
        self
    }
}

/// The reset rule of a sensor: which states it re-initialises and when.
#[derive(Clone, Debug, PartialEq)]
pub struct ResetSettings {
    /// Reset after this many consecutive rejections (during which no other sensor was
    /// accepted). At least 1.
    pub after_rejections: usize,
    /// The states the sensor re-initialises (e.g. the position a position fix observes).
    pub states: Vec<usize>,
    /// The large prior variance those states get before the measurement is applied; a few
    /// orders of magnitude above the sensor's noise. Finite, > 0.
    pub variance: f64,
    /// Also reset when the predicted variance of one of `states` exceeds this (covariance
    /// blow-up). Finite, > 0, or `None`.
    pub blow_up_variance: Option<f64>,
}

/// The windowed NIS χ² fault monitor of a sensor (see the [module docs](super), step 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonitorSettings {
    /// W, the number of recent NIS values summed. At least 1, at most
    /// [`MonitorSettings::MAX_WINDOW`] (the window is copied into every history record).
    pub window: usize,
    /// α, the false-alarm probability of each test on a consistent sensor: the threshold is the
    /// χ²_{W·m} quantile at 1 − α. In (0, 1). (The sum is of clipped NIS, which is smaller
    /// than the χ² variable, so the actual rate is at most α.)
    pub false_alarm: f64,
    /// Each NIS is clipped at the χ²ₘ quantile at this probability before it enters the
    /// window, so one outlier cannot raise a fault alone. In (0, 1).
    pub clip_probability: f64,
}

impl MonitorSettings {
    /// The largest window: 4096 values.
    pub const MAX_WINDOW: usize = 1 << 12;
}

impl Default for MonitorSettings {
    /// W = 20, α = 10⁻³, clipped at the 99 % quantile (for m = 1: q = 45.3, c = 6.63, a stuck
    /// channel is detected within ⌈q / c⌉ = 7 deliveries).
    fn default() -> Self {
        Self {
            window: 20,
            false_alarm: 1e-3,
            clip_probability: 0.99,
        }
    }
}

/// A sensor's settings turned into thresholds for its dimension.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Resolved<T> {
    pub dimension: usize,
    pub gate: Option<T>,
    pub reset: Option<ResolvedReset<T>>,
    pub monitor: Option<ResolvedMonitor<T>>,
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ResolvedReset<T> {
    pub after: usize,
    pub states: Vec<usize>,
    pub variance: T,
    pub blow_up: Option<T>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ResolvedMonitor<T> {
    pub window: usize,
    pub threshold: T,
    pub clip: T,
}

fn probability(p: f64, setting: FusionSetting) -> Result<f64, FusionError> {
    if p > 0.0 && p < 1.0 {
        Ok(p)
    } else {
        Err(FusionError::setting(setting, p))
    }
}

fn quantile(dof: usize, p: f64, setting: FusionSetting) -> Result<f64, FusionError> {
    let q = chi2_quantile(dof, probability(p, setting)?)
        .map_err(|_| FusionError::setting(FusionSetting::SensorDimension, dof as f64))?;
    if q.is_finite() && q > 0.0 {
        Ok(q)
    } else {
        Err(FusionError::setting(setting, p))
    }
}

fn positive(v: f64) -> Result<f64, FusionError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(FusionError::setting(FusionSetting::ResetVariance, v))
    }
}

impl SensorSettings {
    /// Checks the settings and computes the thresholds for a sensor of `dimension` components
    /// on a state of `states` components.
    pub(crate) fn resolve<T: Real>(
        &self,
        dimension: usize,
        states: usize,
    ) -> Result<Resolved<T>, FusionError> {
        if dimension == 0 {
            return Err(FusionError::setting(FusionSetting::SensorDimension, 0.0));
        }
        let gate = self
            .gate_probability
            .map(|p| quantile(dimension, p, FusionSetting::GateProbability))
            .transpose()?
            .map(convert::<f64, T>);
        let reset = match &self.reset {
            None => None,
            Some(r) => {
                if r.after_rejections == 0 {
                    return Err(FusionError::setting(FusionSetting::ResetAfter, 0.0));
                }
                if let Some(&bad) = r.states.iter().find(|&&i| i >= states) {
                    return Err(FusionError::setting(FusionSetting::ResetState, bad as f64));
                }
                Some(ResolvedReset {
                    after: r.after_rejections,
                    states: r.states.clone(),
                    variance: convert(positive(r.variance)?),
                    blow_up: r.blow_up_variance.map(positive).transpose()?.map(convert),
                })
            }
        };
        let monitor = match self.monitor {
            None => None,
            Some(m) => {
                if m.window == 0 || m.window > MonitorSettings::MAX_WINDOW {
                    return Err(FusionError::setting(
                        FusionSetting::MonitorWindow,
                        m.window as f64,
                    ));
                }
                let dof = m.window.checked_mul(dimension).ok_or(FusionError::setting(
                    FusionSetting::MonitorWindow,
                    m.window as f64,
                ))?;
                let alpha = probability(m.false_alarm, FusionSetting::MonitorProbability)?;
                Some(ResolvedMonitor {
                    window: m.window,
                    threshold: convert(quantile(
                        dof,
                        1.0 - alpha,
                        FusionSetting::MonitorProbability,
                    )?),
                    clip: convert(quantile(
                        dimension,
                        m.clip_probability,
                        FusionSetting::MonitorProbability,
                    )?),
                })
            }
        };
        Ok(Resolved {
            dimension,
            gate,
            reset,
            monitor,
        })
    }
}
