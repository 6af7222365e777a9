//! Angles: wrapping into one period, for headings, bearings and attitude residuals.
//!
//! An angle measurement or an angle state lives on a circle, so the difference of two angles
//! is only defined modulo 2π. A model with angle components wraps them in its `residual_into`
//! (the ⊖ of the filter's innovation ν = z ⊖ ẑ) with [`wrap_components`], and a simulator
//! wraps a drawn angle with [`wrap_angle`].

use nalgebra::{Dim, StorageMut, Vector};

use crate::Real;

/// Wraps an angle into (−π, π]: w = a − 2πk with the integer k that puts w in that interval.
///
/// Computed as w = ((a + π) mod 2π) − π with the Euclidean remainder (for `f64`, bit for bit
/// `(a + PI).rem_euclid(2.0 * PI) - PI`), and w = −π mapped to +π, so −π and π both give π.
/// Inputs already in (−π, π] come back unchanged up to the rounding of a + π − π (at most
/// one ulp of π). For |a| ≫ 2π the result carries the rounding of a + π, which grows
/// with |a| (about |a| · ε): wrap differences of angles, not huge accumulated angles.
///
/// NaN and ±∞ give NaN (∞ has no position on the circle); no panic.
///
/// ```
/// use core::f64::consts::PI;
/// use estim_core::wrap_angle;
///
/// assert_eq!(wrap_angle(0.5), 0.5);
/// assert_eq!(wrap_angle(-PI), PI);
/// assert_eq!(wrap_angle(PI), PI);
/// assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
/// assert!(wrap_angle(f64::NAN).is_nan());
/// assert!(wrap_angle(f32::INFINITY).is_nan());
/// ```
#[inline]
pub fn wrap_angle<T: Real>(a: T) -> T {
    let pi = T::pi();
    let two_pi = T::two_pi();
    // Euclidean remainder, as `f64::rem_euclid` computes it: r in [0, 2π] (2π only by
    // rounding a tiny negative remainder up).
    let mut r = (a + pi) % two_pi;
    if r < T::zero() {
        r += two_pi;
    }
    let w = r - pi;
    if w <= -pi { w + two_pi } else { w }
}

/// Wraps the listed components of a residual (or any vector) into (−π, π] with
/// [`wrap_angle`], leaving the others unchanged.
///
/// For a measurement z = (range, bearing) the model's residual is z_a ⊖ z_b = (r_a − r_b,
/// wrap(β_a − β_b)): compute the plain difference, then wrap the angle components. An index at
/// or past the end of `v` names no component and is skipped (a residual cannot fail, so this
/// does not panic); test a model's `residual_into` to catch a wrong index.
///
/// ```
/// use core::f64::consts::PI;
/// use estim_core::nalgebra::Vector2;
/// use estim_core::wrap_components;
///
/// // Range and bearing: the bearings 179° and −179° are 2° apart, not 358°.
/// let a = Vector2::new(10.0, 179f64.to_radians());
/// let b = Vector2::new(9.5, -179f64.to_radians());
/// let mut r = a - b;
/// wrap_components(&mut r, &[1]);
/// assert_eq!(r[0], 0.5);
/// assert!((r[1] + 2f64.to_radians()).abs() < 1e-12);
/// ```
#[inline]
pub fn wrap_components<T, D, S>(v: &mut Vector<T, D, S>, angle_indices: &[usize])
where
    T: Real,
    D: Dim,
    S: StorageMut<T, D>,
{
    for &i in angle_indices {
        if let Some(x) = v.get_mut(i) {
            *x = wrap_angle(*x);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;
    use nalgebra::{DVector, Vector3};

    /// The definition every copy of the helper used before it was shared.
    fn reference(a: f64) -> f64 {
        let w = (a + PI).rem_euclid(2.0 * PI) - PI;
        if w <= -PI { w + 2.0 * PI } else { w }
    }

    #[test]
    fn matches_the_rem_euclid_definition_bit_for_bit() {
        let mut values = vec![
            0.0,
            -0.0,
            PI,
            -PI,
            2.0 * PI,
            -2.0 * PI,
            3.0 * PI,
            -3.0 * PI,
            PI + 1e-15,
            -PI - 1e-15,
            PI - 1e-15,
            -PI + 1e-15,
            1e-300,
            -1e-300,
            f64::MIN_POSITIVE,
            1e6,
            -1e6,
            1e15,
            -1e15,
            f64::MAX,
            f64::MIN,
        ];
        // A deterministic sweep over ±50π, including every multiple of π/4.
        for k in -200..=200 {
            values.push(k as f64 * PI / 4.0);
            values.push(k as f64 * 0.77 + 0.001 * k as f64);
        }
        for a in values {
            assert_eq!(
                wrap_angle(a).to_bits(),
                reference(a).to_bits(),
                "wrap_angle({a:e})"
            );
        }
    }

    #[test]
    fn range_is_half_open_minus_pi_excluded() {
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
        assert_eq!(wrap_angle(3.0 * PI), PI);
        assert_eq!(wrap_angle(-3.0 * PI), PI);
        for k in -1000..=1000 {
            let a = k as f64 * 0.37;
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI, "wrap_angle({a}) = {w}");
            // w differs from a by a whole number of turns (to the rounding of a + π).
            let turns = (a - w) / (2.0 * PI);
            assert!(
                (turns - turns.round()).abs() < 1e-12,
                "{a} - {w} = {turns} turns"
            );
        }
    }

    #[test]
    fn values_inside_the_interval_are_kept() {
        for a in [0.0, 0.5, -0.5, 1.0, -3.0, 3.0, PI / 2.0, -PI / 2.0] {
            assert!((wrap_angle(a) - a).abs() <= 4.0 * f64::EPSILON, "{a}");
        }
        assert_eq!(wrap_angle(0.0), 0.0);
    }

    #[test]
    fn large_multiples() {
        // 1e6 rad is 159154.94... turns; its wrap is 1e6 - 159155·2π.
        let w = wrap_angle(1e6_f64);
        let expected = 1e6 - 159_155.0 * 2.0 * PI;
        assert!((w - expected).abs() < 1e-9, "{w} vs {expected}");
        assert!(wrap_angle(1e15_f64).abs() <= PI);
        assert!(wrap_angle(f64::MAX).abs() <= PI);
        assert!(wrap_angle(f64::MIN).abs() <= PI);
    }

    #[test]
    fn non_finite_gives_nan() {
        assert!(wrap_angle(f64::NAN).is_nan());
        assert!(wrap_angle(f64::INFINITY).is_nan());
        assert!(wrap_angle(f64::NEG_INFINITY).is_nan());
        assert!(wrap_angle(f32::NAN).is_nan());
        assert!(wrap_angle(f32::INFINITY).is_nan());
    }

    #[test]
    fn f32_matches_its_own_rem_euclid() {
        use core::f32::consts::PI as PI32;
        for k in -400..=400 {
            let a = k as f32 * 0.123_f32;
            let w = (a + PI32).rem_euclid(2.0 * PI32) - PI32;
            let expected = if w <= -PI32 { w + 2.0 * PI32 } else { w };
            assert_eq!(wrap_angle(a).to_bits(), expected.to_bits(), "{a}");
        }
        assert_eq!(wrap_angle(-PI32), PI32);
    }

    #[test]
    fn components_wraps_only_the_listed_indices() {
        let mut v = Vector3::new(4.0, 4.0, -4.0);
        wrap_components(&mut v, &[1, 2]);
        assert_eq!(v[0], 4.0);
        assert_eq!(v[1], reference(4.0));
        assert_eq!(v[2], reference(-4.0));

        let mut d = DVector::from_vec(vec![7.0, -7.0]);
        wrap_components(&mut d, &[0, 5]); // 5 names no component: skipped
        assert_eq!(d[0], reference(7.0));
        assert_eq!(d[1], -7.0);

        let mut none = Vector3::new(4.0, 5.0, 6.0);
        wrap_components(&mut none, &[]);
        assert_eq!(none, Vector3::new(4.0, 5.0, 6.0));
    }
}
