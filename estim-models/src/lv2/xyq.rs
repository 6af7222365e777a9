//! The note's three-axis case in closed form: x, y and the redundant q = (x + y)/√2 axis.
//!
//! Every function here has an independent counterpart in the general model
//! ([`RedundantAxes::xyq`](super::RedundantAxes::xyq) fused by weighted least squares, or by
//! the Kalman filter in [`RedundantAxes::fuse_with_filter`](super::RedundantAxes::fuse_with_filter));
//! the tests in `estim-models/tests/it/lv2_fusion.rs` show they agree to round-off.

use core::f64::consts::SQRT_2;

use estim_core::nalgebra::{Matrix2, Vector2, Vector3};
use estim_core::{Error, Quantity, Stage};

use super::error::FusionError;

/// The noise standard deviations σx, σy, σq of the three channels (m/s²), independent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct XyqSigmas {
    /// σx.
    pub x: f64,
    /// σy.
    pub y: f64,
    /// σq.
    pub q: f64,
}

impl XyqSigmas {
    /// Checked: every σ finite and > 0 (else [`FusionError::Core`] with
    /// `NonFinite`/`NotPositiveDefinite` on the measurement noise).
    pub fn new(x: f64, y: f64, q: f64) -> Result<Self, FusionError> {
        let stage = Stage::Construction;
        let quantity = Quantity::MeasurementNoise;
        if ![x, y, q].iter().all(|s| s.is_finite()) {
            return Err(Error::NonFinite { stage, quantity }.into());
        }
        if !(x > 0.0 && y > 0.0 && q > 0.0) {
            return Err(Error::NotPositiveDefinite { stage, quantity }.into());
        }
        Ok(Self { x, y, q })
    }

    /// σ²x2 = 2σq² + σy² (eq 4): the variance of x̂₂ = √2 q̃ − ỹ.
    pub fn var_x2(&self) -> f64 {
        2.0 * self.q * self.q + self.y * self.y
    }

    /// σ²y2 = 2σq² + σx²: the variance of ŷ₂ = √2 q̃ − x̃ (the mirror of eq 4).
    pub fn var_y2(&self) -> f64 {
        2.0 * self.q * self.q + self.x * self.x
    }

    /// s₁ = 2σq² + σy² + σx² (eq 6), which is also the variance of the parity residual.
    pub fn s1(&self) -> f64 {
        2.0 * self.q * self.q + self.y * self.y + self.x * self.x
    }
}

/// One reading (x̃, ỹ, q̃) of the three channels (m/s²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct XyqReading {
    /// x̃.
    pub x: f64,
    /// ỹ.
    pub y: f64,
    /// q̃.
    pub q: f64,
}

impl XyqReading {
    /// The noise-free reading of the in-plane acceleration (x, y): q = (x + y)/√2 (eq 1).
    pub fn noise_free(x: f64, y: f64) -> Self {
        Self {
            x,
            y,
            q: (x + y) / SQRT_2,
        }
    }

    /// (x̃, ỹ, q̃) as a vector, in the axis order of
    /// [`RedundantAxes::xyq`](super::RedundantAxes::xyq).
    pub fn to_vector(&self) -> Vector3<f64> {
        Vector3::new(self.x, self.y, self.q)
    }
}

/// Which of the three channels are used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct XyqAxes {
    /// x̃ is used.
    pub x: bool,
    /// ỹ is used.
    pub y: bool,
    /// q̃ is used.
    pub q: bool,
}

impl XyqAxes {
    /// All three channels.
    pub const ALL: Self = Self {
        x: true,
        y: true,
        q: true,
    };

    /// How many channels are used.
    pub fn count(&self) -> usize {
        usize::from(self.x) + usize::from(self.y) + usize::from(self.q)
    }

    /// As `[x, y, q]` flags (the axis order of [`XyqReading::to_vector`]).
    pub fn to_array(&self) -> [bool; 3] {
        [self.x, self.y, self.q]
    }
}

/// x̂₂ = √2 q̃ − ỹ (eq 2): the estimate of x that does not use x̃.
pub fn x_hat_2(r: &XyqReading) -> f64 {
    SQRT_2 * r.q - r.y
}

/// ŷ₂ = √2 q̃ − x̃: the estimate of y that does not use ỹ (mirror of eq 2).
pub fn y_hat_2(r: &XyqReading) -> f64 {
    SQRT_2 * r.q - r.x
}

/// Eq 3: the minimum-variance combination of two **independent** unbiased estimates `a`, `b`
/// of one quantity with variances `var_a`, `var_b`: (a σb² + b σa²)/(σa² + σb²), and its
/// variance σa² σb²/(σa² + σb²).
pub fn combine_independent(a: f64, var_a: f64, b: f64, var_b: f64) -> (f64, f64) {
    let s = var_a + var_b;
    ((a * var_b + b * var_a) / s, var_a * var_b / s)
}

/// Eq 5 exactly as printed: x̂ = [(√2 q̃ − ỹ) σx² + x̃ (2σq² + σy²)] / (2σq² + σx² + σy²).
pub fn eq5_x_hat(r: &XyqReading, s: &XyqSigmas) -> f64 {
    let (vx, vy, vq) = (s.x * s.x, s.y * s.y, s.q * s.q);
    ((SQRT_2 * r.q - r.y) * vx + r.x * (2.0 * vq + vy)) / (2.0 * vq + vx + vy)
}

/// The mirror of eq 5 for y (not printed in the note):
/// ŷ = [(√2 q̃ − x̃) σy² + ỹ (2σq² + σx²)] / (2σq² + σx² + σy²).
pub fn eq5_y_hat(r: &XyqReading, s: &XyqSigmas) -> f64 {
    let (vx, vy, vq) = (s.x * s.x, s.y * s.y, s.q * s.q);
    ((SQRT_2 * r.q - r.x) * vy + r.y * (2.0 * vq + vx)) / (2.0 * vq + vx + vy)
}

/// Eq 6: the precomputed coefficients, so that each estimate costs 2 additions and 3
/// multiplications per sample.
///
/// ```text
/// s₁ = 2σq² + σy² + σx²,  f₁ = (2σq² + σy²)/s₁,  f₂ = σx²/s₁,  x̂ = x̃ f₁ + (√2 q̃ − ỹ) f₂
///                          g₁ = (2σq² + σx²)/s₁,  g₂ = σy²/s₁,  ŷ = ỹ g₁ + (√2 q̃ − x̃) g₂
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eq6Coefficients {
    /// s₁.
    pub s1: f64,
    /// f₁ (weight of x̃ in x̂); f₁ + f₂ = 1.
    pub f1: f64,
    /// f₂ (weight of x̂₂ in x̂).
    pub f2: f64,
    /// g₁ (weight of ỹ in ŷ); g₁ + g₂ = 1.
    pub g1: f64,
    /// g₂ (weight of ŷ₂ in ŷ).
    pub g2: f64,
}

impl Eq6Coefficients {
    /// Precomputes the coefficients for constant σ's.
    pub fn new(s: &XyqSigmas) -> Self {
        let s1 = s.s1();
        Self {
            s1,
            f1: s.var_x2() / s1,
            f2: s.x * s.x / s1,
            g1: s.var_y2() / s1,
            g2: s.y * s.y / s1,
        }
    }

    /// x̂ = x̃ f₁ + (√2 q̃ − ỹ) f₂: 3 multiplications (√2·q̃, ·f₁, ·f₂), 2 additions.
    pub fn x_hat(&self, r: &XyqReading) -> f64 {
        r.x * self.f1 + (SQRT_2 * r.q - r.y) * self.f2
    }

    /// ŷ = ỹ g₁ + (√2 q̃ − x̃) g₂.
    pub fn y_hat(&self, r: &XyqReading) -> f64 {
        r.y * self.g1 + (SQRT_2 * r.q - r.x) * self.g2
    }
}

/// Eq 7: the consistency (parity) residual x̂₁ − x̂₂ = x̃ − (√2 q̃ − ỹ) = x̃ + ỹ − √2 q̃.
///
/// The y-check ŷ₁ − ŷ₂ = ỹ − (√2 q̃ − x̃) is the same number: three axes carry one redundancy,
/// hence one parity, so a fault can be detected but not attributed to an axis.
pub fn parity_residual(r: &XyqReading) -> f64 {
    r.x + r.y - SQRT_2 * r.q
}

/// The χ² of the parity, (x̃ − (√2 q̃ − ỹ))² / (σx² + 2σq² + σy²): χ²₁ when the channels are
/// fault-free and Gaussian. It equals the weighted least-squares residual rᵀ R⁻¹ r.
pub fn parity_chi2(r: &XyqReading, s: &XyqSigmas) -> f64 {
    let p = parity_residual(r);
    p * p / s.s1()
}

/// The covariance of (x̂, ŷ) with all three axes, including the x̂–ŷ covariance the note does
/// not give:
///
/// ```text
/// P = (1/s₁) [[σx² (2σq² + σy²),  −σx² σy²        ],
///             [−σx² σy²,           σy² (2σq² + σx²)]]
/// ```
pub fn covariance(s: &XyqSigmas) -> Matrix2<f64> {
    let (vx, vy, vq) = (s.x * s.x, s.y * s.y, s.q * s.q);
    let s1 = s.s1();
    Matrix2::new(
        vx * (2.0 * vq + vy) / s1,
        -vx * vy / s1,
        -vx * vy / s1,
        vy * (2.0 * vq + vx) / s1,
    )
}

/// The fused estimate of (x, y) from the three-axis closed forms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct XyqEstimate {
    /// (x̂, ŷ) (m/s²).
    pub estimate: Vector2<f64>,
    /// Its covariance ((m/s²)²).
    pub covariance: Matrix2<f64>,
    /// The parity residual x̃ + ỹ − √2 q̃ (m/s²) when all three axes are used, else `None`.
    pub parity: Option<f64>,
    /// The χ² of the parity (0 when only two axes are used: no redundancy is left).
    pub chi2: f64,
    /// Degrees of freedom of `chi2`: 1 with three axes, 0 with two.
    pub dof: usize,
    /// The channels used.
    pub used: XyqAxes,
}

/// Fuses the channels flagged in `used` by the closed forms:
///
/// | used | x̂ | ŷ | P |
/// |---|---|---|---|
/// | x, y, q | eq 5 | mirror of eq 5 | [`covariance`] |
/// | y, q (x lost) | √2 q̃ − ỹ | ỹ | [[2σq² + σy², −σy²], [−σy², σy²]] |
/// | x, q (y lost) | x̃ | √2 q̃ − x̃ | [[σx², −σx²], [−σx², 2σq² + σx²]] |
/// | x, y (q lost) | x̃ | ỹ | diag(σx², σy²) |
///
/// Fewer than two channels: [`FusionError::TooFewAxes`]. A non-finite used reading:
/// [`FusionError::Core`] (`NonFinite` measurement); screen it out first (see [`screen`]).
pub fn fuse(r: &XyqReading, s: &XyqSigmas, used: XyqAxes) -> Result<XyqEstimate, FusionError> {
    let finite = [(used.x, r.x), (used.y, r.y), (used.q, r.q)]
        .iter()
        .all(|&(u, v)| !u || v.is_finite());
    if !finite {
        return Err(Error::NonFinite {
            stage: Stage::Update,
            quantity: Quantity::Measurement,
        }
        .into());
    }
    let (vx, vy, vq) = (s.x * s.x, s.y * s.y, s.q * s.q);
    let (estimate, covariance, parity) = match (used.x, used.y, used.q) {
        (true, true, true) => {
            let c = Eq6Coefficients::new(s);
            let est = Vector2::new(c.x_hat(r), c.y_hat(r));
            (est, covariance(s), Some(parity_residual(r)))
        }
        (false, true, true) => (
            Vector2::new(x_hat_2(r), r.y),
            Matrix2::new(2.0 * vq + vy, -vy, -vy, vy),
            None,
        ),
        (true, false, true) => (
            Vector2::new(r.x, y_hat_2(r)),
            Matrix2::new(vx, -vx, -vx, 2.0 * vq + vx),
            None,
        ),
        (true, true, false) => (Vector2::new(r.x, r.y), Matrix2::new(vx, 0.0, 0.0, vy), None),
        _ => {
            return Err(FusionError::TooFewAxes {
                usable: used.count(),
                required: 2,
            });
        }
    };
    let chi2 = parity.map_or(0.0, |p| p * p / s.s1());
    Ok(XyqEstimate {
        estimate,
        covariance,
        parity,
        chi2,
        dof: usize::from(parity.is_some()),
        used,
    })
}

/// The note's screening: a channel is used unless it is flagged in `missing` (order x, y, q),
/// its reading is not finite, or |reading| ≥ `full_scale` (saturated at the converter's rail;
/// `None` disables the check).
pub fn screen(r: &XyqReading, missing: [bool; 3], full_scale: Option<f64>) -> XyqAxes {
    let ok =
        |v: f64, miss: bool| !miss && v.is_finite() && full_scale.is_none_or(|fs| v.abs() < fs);
    XyqAxes {
        x: ok(r.x, missing[0]),
        y: ok(r.y, missing[1]),
        q: ok(r.q, missing[2]),
    }
}
