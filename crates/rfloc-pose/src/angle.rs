//! Angle normalisation.

use std::f64::consts::PI;

/// Wraps an angle to `(-π, π]`. Non-finite input is returned unchanged so that callers can
/// detect it instead of getting a plausible-looking number.
#[must_use]
pub fn wrap_angle(a: f64) -> f64 {
    if !a.is_finite() {
        return a;
    }
    let mut r = a.rem_euclid(2.0 * PI); // [0, 2π)
    if r > PI {
        r -= 2.0 * PI;
    }
    r
}

/// Smallest signed difference `a - b`, wrapped to `(-π, π]`.
#[must_use]
pub fn angle_diff(a: f64, b: f64) -> f64 {
    wrap_angle(a - b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wraps_into_half_open_interval() {
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(0.25) - 0.25).abs() < 1e-15);
        assert!((wrap_angle(7.0 * PI / 4.0) + PI / 4.0).abs() < 1e-12);
    }

    #[test]
    fn diff_takes_short_way_round() {
        let d = angle_diff(PI - 0.1, -PI + 0.1);
        assert!((d + 0.2).abs() < 1e-12, "{d}");
    }

    #[test]
    fn non_finite_passes_through() {
        assert!(wrap_angle(f64::NAN).is_nan());
        assert!(wrap_angle(f64::INFINITY).is_infinite());
    }
}
