//! The earth: the local NED origin (geodesy from `map_3d`), normal gravity, the earth rate.

use core::fmt;

use estim_core::nalgebra::Vector3;
#[cfg(feature = "std")]
use map_3d::Ellipsoid;
// f64's sin and sqrt without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// The earth's rotation rate Ω (WGS-84) \[rad/s\].
pub const EARTH_RATE: f64 = 7.292_115e-5;

/// WGS-84 semi-major axis a \[m\].
const A: f64 = 6_378_137.0;
/// WGS-84 flattening f.
const F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared e².
const E2: f64 = 6.694_379_990_14e-3;
/// Normal gravity at the equator γ_e \[m/s²\].
const GAMMA_E: f64 = 9.780_325_335_9;
/// Somigliana's constant k = (b γ_p − a γ_e) / (a γ_e).
const K: f64 = 1.931_852_652_41e-3;
/// m = Ω² a² b / GM.
const M: f64 = 3.449_786_506_84e-3;

/// Why a navigation input was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum NavError {
    /// A value that must be finite was not (which value).
    NonFinite(&'static str),
    /// A latitude outside (−90°, 90°) \[deg\].
    Latitude(f64),
    /// A vector that must not vanish did (which one): a zero accelerometer mean, a field with
    /// no horizontal component.
    Degenerate(&'static str),
}

impl fmt::Display for NavError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NavError::NonFinite(what) => write!(f, "{what} is not finite"),
            NavError::Latitude(lat) => write!(f, "latitude {lat}° is outside (-90°, 90°)"),
            NavError::Degenerate(what) => write!(f, "{what} vanishes"),
        }
    }
}

impl core::error::Error for NavError {}

/// γ(φ, h): WGS-84 normal gravity at geodetic latitude φ \[rad\] and height h \[m\] above the
/// ellipsoid \[m/s²\]: Somigliana γ₀ = γ_e (1 + k sin²φ)/√(1 − e² sin²φ), continued upward as
/// γ₀ (1 − 2h/a (1 + f + m − 2f sin²φ) + 3h²/a²) (NIMA TR8350.2, eqs. 4-1 and 4-3). Points
/// downward in NED; includes the centrifugal part.
///
/// ```
/// use estim_models::nav::normal_gravity;
/// assert!((normal_gravity(0.0, 0.0) - 9.780_325_335_9).abs() < 1e-10);
/// assert!((normal_gravity(core::f64::consts::FRAC_PI_2, 0.0) - 9.832_184_937_8).abs() < 1e-9);
/// ```
pub fn normal_gravity(latitude: f64, height: f64) -> f64 {
    let s2 = latitude.sin().powi(2);
    let g0 = GAMMA_E * (1.0 + K * s2) / (1.0 - E2 * s2).sqrt();
    g0 * (1.0 - 2.0 / A * (1.0 + F + M - 2.0 * F * s2) * height + 3.0 * height * height / (A * A))
}

/// ∂γ/∂h at (φ, h) \[1/s²\] (the free-air gradient, ≈ −3.086·10⁻⁶).
pub fn normal_gravity_gradient(latitude: f64, height: f64) -> f64 {
    let s2 = latitude.sin().powi(2);
    let g0 = GAMMA_E * (1.0 + K * s2) / (1.0 - E2 * s2).sqrt();
    g0 * (-2.0 / A * (1.0 + F + M - 2.0 * F * s2) + 6.0 * height / (A * A))
}

/// The origin of the local NED frame: geodetic latitude, longitude (stored in radians) and
/// height above the WGS-84 ellipsoid \[m\].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Origin {
    latitude: f64,
    longitude: f64,
    height: f64,
}

impl Origin {
    /// The origin at `latitude`, `longitude` \[deg\] and `height` \[m\].
    ///
    /// Errors: [`NavError::NonFinite`] for a non-finite value, [`NavError::Latitude`] for
    /// |latitude| ≥ 90° (NED is undefined at the poles).
    ///
    /// ```
    /// use estim_models::nav::Origin;
    /// let origin = Origin::from_degrees(51.642, -2.526, 60.0)?;
    /// // 100 m north and 50 m east, 10 m up.
    /// let lat = 51.642 + 100.0 / 111_250.0;
    /// let ned = origin.ned(lat, -2.526 + 50.0 / 69_200.0, 70.0);
    /// assert!((ned[0] - 100.0).abs() < 0.5 && (ned[1] - 50.0).abs() < 0.5);
    /// assert!((ned[2] + 10.0).abs() < 0.01);
    /// # Ok::<(), estim_models::nav::NavError>(())
    /// ```
    pub fn from_degrees(latitude: f64, longitude: f64, height: f64) -> Result<Self, NavError> {
        for (value, what) in [
            (latitude, "latitude"),
            (longitude, "longitude"),
            (height, "height"),
        ] {
            if !value.is_finite() {
                return Err(NavError::NonFinite(what));
            }
        }
        if !(latitude.abs() < 90.0) {
            return Err(NavError::Latitude(latitude));
        }
        Ok(Self {
            latitude: latitude.to_radians(),
            longitude: longitude.to_radians(),
            height,
        })
    }

    /// The latitude φ₀ \[rad\].
    pub fn latitude(&self) -> f64 {
        self.latitude
    }

    /// The longitude λ₀ \[rad\].
    pub fn longitude(&self) -> f64 {
        self.longitude
    }

    /// The height h₀ above the ellipsoid \[m\].
    pub fn height(&self) -> f64 {
        self.height
    }

    /// The NED position \[m\] of the point at `latitude`, `longitude` \[deg\], `height` \[m\]
    /// (exact ellipsoidal geodesy through ECEF, `map_3d::geodetic2ned`). Needs the `std`
    /// feature (`map_3d` calls std's float functions).
    #[cfg(feature = "std")]
    pub fn ned(&self, latitude: f64, longitude: f64, height: f64) -> Vector3<f64> {
        let (n, e, d) = map_3d::geodetic2ned(
            latitude.to_radians(),
            longitude.to_radians(),
            height,
            self.latitude,
            self.longitude,
            self.height,
            Ellipsoid::WGS84,
        );
        Vector3::new(n, e, d)
    }

    /// The radii of curvature at the origin \[m\]: meridian R_M = R_N (1 − e²)/(1 − e² sin²φ₀)
    /// and prime vertical R_N = a / √(1 − e² sin²φ₀) (`map_3d::get_radius_normal` with std,
    /// the same closed form through libm without).
    pub fn radii(&self) -> (f64, f64) {
        #[cfg(feature = "std")]
        let normal = map_3d::get_radius_normal(self.latitude, Ellipsoid::WGS84);
        #[cfg(not(feature = "std"))]
        let normal = radius_normal(self.latitude);
        let meridian = normal * (1.0 - E2) / (1.0 - E2 * self.latitude.sin().powi(2));
        (meridian, normal)
    }

    /// ω_ie in NED at the origin: Ω (cos φ₀, 0, −sin φ₀) \[rad/s\].
    pub fn earth_rate(&self) -> Vector3<f64> {
        Vector3::new(self.latitude.cos(), 0.0, -self.latitude.sin()) * EARTH_RATE
    }

    /// γ at height h₀ − p_D above the ellipsoid (p_D the NED down coordinate) \[m/s²\].
    pub fn gravity(&self, down: f64) -> f64 {
        normal_gravity(self.latitude, self.height - down)
    }
}

/// R_N(φ) = a / √(1 − e² sin²φ), the prime-vertical radius of curvature \[m\]: the closed form
/// `Origin::radii` uses without std (`map_3d::get_radius_normal` with std).
#[cfg_attr(feature = "std", allow(dead_code))]
fn radius_normal(latitude: f64) -> f64 {
    A / (1.0 - E2 * latitude.sin().powi(2)).sqrt()
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// The no_std closed form of R_N against map_3d's, which the std build uses: the two
    /// routes of `Origin::radii` agree. Both evaluate a / √(1 − e² sin²φ) in a few
    /// operations (map_3d from its own a and f), so they differ by rounding only: 1e-15
    /// relative (a few ulps) is the tolerance.
    #[test]
    fn radius_normal_matches_map_3d() {
        for degrees in [
            -89.0, -51.642, -10.0, 0.0, 0.3, 30.0, 45.0, 51.642, 80.0, 89.9,
        ] {
            let latitude = f64::to_radians(degrees);
            let ours = radius_normal(latitude);
            let theirs = map_3d::get_radius_normal(latitude, Ellipsoid::WGS84);
            assert!(
                ((ours - theirs) / theirs).abs() < 1e-15,
                "{degrees}°: {ours} vs {theirs}"
            );
        }
    }
}
