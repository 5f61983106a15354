//! From an rfloc pose estimate (x, y, yaw with a 3×3 covariance) to `agvPosition`.
//!
//! The specification leaves open how `localizationScore` (0 = position unknown, 1 = position
//! known) and `deviationRange` (metres) are computed. This crate fixes them as functions of the
//! largest standard deviation of the position, σ_max = √λ_max, where λ_max is the larger
//! eigenvalue of the x/y block of the covariance:
//!
//! * `localizationScore = 1 / (1 + (σ_max / σ_half)²)` with σ_half = [`SCORE_HALF_SIGMA_M`]
//!   (0.1 m): 1 for an exact position, 0.5 at σ_max = 0.1 m, 0.2 at 0.2 m, falling towards 0 as
//!   the position becomes unknown. It is strictly decreasing in σ_max.
//! * `deviationRange = 2 σ_max`: the radius that holds the position with about 95 % probability
//!   along the worst axis of a Gaussian.
//!
//! A covariance that is not finite, not symmetric enough, or has a negative position variance
//! gives no score and no range (`None`): the vehicle then reports neither.

use crate::messages::AgvPosition;

/// σ_max at which the localisation score is 0.5, metres.
pub const SCORE_HALF_SIGMA_M: f64 = 0.1;

/// Largest relative asymmetry between `cov[0][1]` and `cov[1][0]` accepted as rounding.
const SYMMETRY_TOLERANCE: f64 = 1e-6;

/// Largest standard deviation of the position (metres) from a 3×3 covariance over
/// (x, y, yaw): the square root of the larger eigenvalue of its x/y block.
///
/// `None` if an entry of the x/y block is not finite, the block is not symmetric (beyond
/// rounding), or it is not positive semi-definite.
pub fn position_sigma_max(cov: &[[f64; 3]; 3]) -> Option<f64> {
    let a = cov[0][0];
    let c = cov[1][1];
    let b1 = cov[0][1];
    let b2 = cov[1][0];
    if ![a, b1, b2, c].iter().all(|v| v.is_finite()) {
        return None;
    }
    let scale = a.abs().max(c.abs()).max(f64::MIN_POSITIVE);
    if (b1 - b2).abs() > SYMMETRY_TOLERANCE * scale {
        return None;
    }
    let b = 0.5 * (b1 + b2);
    // Positive semi-definite: non-negative diagonal and determinant (with rounding slack).
    let slack = 1e-12 * scale * scale;
    if a < 0.0 || c < 0.0 || a * c - b * b < -slack {
        return None;
    }
    let mean = 0.5 * (a + c);
    let half_diff = 0.5 * (a - c);
    let lambda_max = mean + half_diff.hypot(b);
    Some(lambda_max.max(0.0).sqrt())
}

/// `localizationScore` from σ_max (metres): `1 / (1 + (σ_max / 0.1 m)²)`, in [0, 1].
///
/// `None` for a negative or non-finite σ_max; an infinite σ_max gives 0.
pub fn localization_score_from_sigma(sigma_max: f64) -> Option<f64> {
    if sigma_max.is_nan() || sigma_max < 0.0 {
        return None;
    }
    if sigma_max.is_infinite() {
        return Some(0.0);
    }
    let r = sigma_max / SCORE_HALF_SIGMA_M;
    Some((1.0 / (1.0 + r * r)).clamp(0.0, 1.0))
}

/// `localizationScore` of a 3×3 (x, y, yaw) covariance; see the module documentation.
pub fn localization_score(cov: &[[f64; 3]; 3]) -> Option<f64> {
    position_sigma_max(cov).and_then(localization_score_from_sigma)
}

/// `deviationRange` of a 3×3 (x, y, yaw) covariance: 2 σ_max, metres.
pub fn deviation_range(cov: &[[f64; 3]; 3]) -> Option<f64> {
    position_sigma_max(cov)
        .map(|s| 2.0 * s)
        .filter(|r| r.is_finite())
}

/// Wraps an angle into (−π, π], the range of `theta`.
pub fn wrap_angle(theta: f64) -> f64 {
    use std::f64::consts::PI;
    if !theta.is_finite() {
        return theta;
    }
    let mut t = theta % (2.0 * PI);
    if t <= -PI {
        t += 2.0 * PI;
    } else if t > PI {
        t -= 2.0 * PI;
    }
    t
}

/// `agvPosition` of a pose estimate on map `map_id`: theta wrapped into (−π, π], score and range
/// from `cov`, `positionInitialized` as given.
pub fn agv_position_from_estimate(
    x: f64,
    y: f64,
    yaw: f64,
    cov: &[[f64; 3]; 3],
    map_id: &str,
    position_initialized: bool,
) -> AgvPosition {
    AgvPosition {
        x,
        y,
        theta: wrap_angle(yaw),
        map_id: map_id.to_owned(),
        map_description: None,
        position_initialized,
        localization_score: localization_score(cov),
        deviation_range: deviation_range(cov),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cov2(a: f64, b: f64, c: f64) -> [[f64; 3]; 3] {
        [[a, b, 0.0], [b, c, 0.0], [0.0, 0.0, 0.04]]
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn known_answers_diagonal() {
        // σx = 0.1 m, σy = 0.05 m: σ_max = 0.1, score 0.5, range 0.2 m.
        let c = cov2(0.01, 0.0, 0.0025);
        assert!(close(position_sigma_max(&c).unwrap(), 0.1));
        assert!(close(localization_score(&c).unwrap(), 0.5));
        assert!(close(deviation_range(&c).unwrap(), 0.2));
        // σ_max = 0.2 m → 1 / (1 + 4) = 0.2; range 0.4 m.
        let c = cov2(0.0001, 0.0, 0.04);
        assert!(close(localization_score(&c).unwrap(), 0.2));
        assert!(close(deviation_range(&c).unwrap(), 0.4));
        // σ_max = 0.05 m → 1 / 1.25 = 0.8.
        let c = cov2(0.0025, 0.0, 0.0025);
        assert!(close(localization_score(&c).unwrap(), 0.8));
        // Exact position.
        let c = cov2(0.0, 0.0, 0.0);
        assert!(close(localization_score(&c).unwrap(), 1.0));
        assert!(close(deviation_range(&c).unwrap(), 0.0));
    }

    #[test]
    fn known_answer_correlated() {
        // [[0.02, 0.01], [0.01, 0.02]] has eigenvalues 0.03 and 0.01.
        let c = cov2(0.02, 0.01, 0.02);
        let s = position_sigma_max(&c).unwrap();
        assert!(close(s, 0.03_f64.sqrt()));
        assert!(close(localization_score(&c).unwrap(), 1.0 / (1.0 + 3.0)));
        assert!(close(deviation_range(&c).unwrap(), 2.0 * 0.03_f64.sqrt()));
    }

    #[test]
    fn yaw_variance_does_not_matter() {
        let mut c = cov2(0.01, 0.0, 0.0025);
        c[2][2] = 100.0;
        c[0][2] = 0.5;
        c[2][0] = 0.5;
        assert!(close(localization_score(&c).unwrap(), 0.5));
    }

    #[test]
    fn invalid_covariances_give_none() {
        assert!(localization_score(&cov2(f64::NAN, 0.0, 0.01)).is_none());
        assert!(localization_score(&cov2(-0.01, 0.0, 0.01)).is_none());
        assert!(localization_score(&cov2(0.01, 0.02, 0.01)).is_none()); // det < 0
        let mut c = cov2(0.01, 0.0, 0.01);
        c[0][1] = 0.001;
        assert!(localization_score(&c).is_none()); // asymmetric
        assert!(deviation_range(&cov2(f64::INFINITY, 0.0, 0.01)).is_none());
    }

    #[test]
    fn score_is_monotone_and_bounded() {
        let mut last = 1.0;
        for i in 1..2000 {
            let s = localization_score_from_sigma(f64::from(i) * 0.001).unwrap();
            assert!(s < last && s > 0.0);
            last = s;
        }
        assert_eq!(localization_score_from_sigma(f64::INFINITY), Some(0.0));
        assert_eq!(localization_score_from_sigma(-1.0), None);
    }

    #[test]
    fn wrap_angle_range() {
        use std::f64::consts::PI;
        assert!(close(wrap_angle(3.0 * PI), PI));
        assert!(close(wrap_angle(-PI), PI));
        assert!(close(wrap_angle(-3.0 * PI / 2.0), PI / 2.0));
        assert!(close(wrap_angle(0.25), 0.25));
    }

    #[test]
    fn agv_position_mapping() {
        let p = agv_position_from_estimate(1.0, 2.0, 7.0, &cov2(0.01, 0.0, 0.0025), "hall", true);
        assert!(close(p.theta, 7.0 - 2.0 * std::f64::consts::PI));
        assert_eq!(p.localization_score, Some(0.5));
        assert!(close(p.deviation_range.unwrap(), 0.2));
        assert_eq!(p.map_id, "hall");
    }
}
