//! Range and bearing of the emitter from the differential RSS of four directional antennas.
//!
//! The antennas sit at 90° on the robot: `front` (boresight 0 rad in the robot frame), `left`
//! (+π/2), `back` (π) and `right` (−π/2). The seed's equations (3)–(4) did not survive the text
//! extraction; what survives is that the per-axis *differential* RSS gives the direction, that
//! the distance comes from "the traditional approach of mapping RSS values to distance" with two
//! calibrated parameters `A1` and `A2`, and that the front+back sum indicates nearness. This
//! module implements the following reconstruction (see `docs/estimators-emitter.md`):
//!
//! - eq. (3) bearing: `θ = atan2(y1 − y2, x1 − x2)` with `x1/x2` = front/back and `y1/y2` =
//!   left/right RSS in dBm;
//! - eq. (4) range: `r = 10^((A1 − S̄) / (10·A2))` with `S̄` the mean of the four RSS values,
//!   `A1` the mean RSS at 1 m (dBm) and `A2` the path-loss exponent.
//!
//! Both are exact for the gain model of [`crate::model::DirectionalArrayModel`] without noise:
//! a dB gain `(F/2)·cos ψ` makes the axis differences `F·cos θ` and `F·sin θ`, and its four
//! samples 90° apart sum to zero, so `S̄` carries only the path loss.

use serde::{Deserialize, Serialize};

use crate::error::EmitterError;

/// One simultaneous RSS reading of the four antennas, dBm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AntennaRss {
    /// Antenna looking forward (`x1` in the seed), dBm.
    pub front: f64,
    /// Antenna looking backward (`x2`), dBm.
    pub back: f64,
    /// Antenna looking left (`y1`), dBm.
    pub left: f64,
    /// Antenna looking right (`y2`), dBm.
    pub right: f64,
}

impl AntennaRss {
    /// True when all four values are finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.front.is_finite()
            && self.back.is_finite()
            && self.left.is_finite()
            && self.right.is_finite()
    }

    /// Mean of the four readings, dBm (orientation-independent strength).
    #[must_use]
    pub fn mean_dbm(&self) -> f64 {
        (self.front + self.back + self.left + self.right) / 4.0
    }
}

/// Calibration of the RSS → distance mapping (the seed's `A1`, `A2`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DifferentialRssConfig {
    /// `A1`: mean RSS of the four antennas with the emitter at 1 m, dBm.
    pub a1_dbm_at_1m: f64,
    /// `A2`: path-loss exponent (2 in free space, 1.6–3.5 indoors).
    pub a2_path_loss_exponent: f64,
    /// Ranges are clamped to `[min_range_m, max_range_m]`.
    pub min_range_m: f64,
    /// Upper clamp of the range, metres (the seed detects the emitter beyond 50 m).
    pub max_range_m: f64,
}

impl Default for DifferentialRssConfig {
    /// `A1 = −45 dBm`, `A2 = 2.0`, range clamped to `[0.1, 60] m`. These are simulator defaults;
    /// the seed does not publish its calibrated values.
    fn default() -> Self {
        Self {
            a1_dbm_at_1m: -45.0,
            a2_path_loss_exponent: 2.0,
            min_range_m: 0.1,
            max_range_m: 60.0,
        }
    }
}

impl DifferentialRssConfig {
    /// Checks that the values are usable.
    ///
    /// # Errors
    /// [`EmitterError::InvalidConfig`] for a non-finite `A1`, a non-positive `A2` or bad clamps.
    pub fn validate(&self) -> Result<(), EmitterError> {
        if !self.a1_dbm_at_1m.is_finite() {
            return Err(EmitterError::InvalidConfig("A1 must be finite"));
        }
        if !(self.a2_path_loss_exponent.is_finite() && self.a2_path_loss_exponent > 0.0) {
            return Err(EmitterError::InvalidConfig("A2 must be finite and > 0"));
        }
        if !(self.min_range_m > 0.0 && self.max_range_m >= self.min_range_m) {
            return Err(EmitterError::InvalidConfig(
                "need 0 < min_range_m <= max_range_m",
            ));
        }
        Ok(())
    }
}

/// Emitter position relative to the robot: range (m) and bearing from the robot heading (rad,
/// counter-clockwise positive, in `(-π, π]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RangeBearing {
    /// Distance robot → emitter, metres.
    pub range_m: f64,
    /// Angle of the emitter from the robot's heading, radians.
    pub bearing_rad: f64,
}

impl RangeBearing {
    /// The emitter position in the world frame given the robot pose.
    #[must_use]
    pub fn to_world(&self, robot: &rfloc_pose::Pose2) -> crate::Point2 {
        let a = robot.theta + self.bearing_rad;
        crate::Point2::new(
            robot.x + self.range_m * a.cos(),
            robot.y + self.range_m * a.sin(),
        )
    }
}

/// The seed's eq. (3)–(4) as reconstructed here: bearing from the two axis differences, range
/// from the mean level through the log-distance mapping with `A1`, `A2`.
///
/// # Errors
/// [`EmitterError::NonFiniteRss`] if a reading is NaN/∞; [`EmitterError::InvalidConfig`] for a
/// bad calibration.
pub fn differential_range_bearing(
    rss: &AntennaRss,
    config: &DifferentialRssConfig,
) -> Result<RangeBearing, EmitterError> {
    config.validate()?;
    if !rss.is_finite() {
        return Err(EmitterError::NonFiniteRss {
            front: rss.front,
            back: rss.back,
            left: rss.left,
            right: rss.right,
        });
    }
    let dx = rss.front - rss.back;
    let dy = rss.left - rss.right;
    let bearing_rad = rfloc_pose::wrap_angle(dy.atan2(dx));
    let exponent = (config.a1_dbm_at_1m - rss.mean_dbm()) / (10.0 * config.a2_path_loss_exponent);
    let range_m = 10f64
        .powf(exponent)
        .clamp(config.min_range_m, config.max_range_m);
    Ok(RangeBearing {
        range_m,
        bearing_rad,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emitter_straight_ahead_at_one_metre() {
        let cfg = DifferentialRssConfig::default();
        let rss = AntennaRss {
            front: -39.0,
            back: -51.0,
            left: -45.0,
            right: -45.0,
        };
        let rb = differential_range_bearing(&rss, &cfg).unwrap();
        assert!(rb.bearing_rad.abs() < 1e-12);
        assert!((rb.range_m - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ten_db_weaker_is_sqrt_ten_further_with_exponent_two() {
        let cfg = DifferentialRssConfig::default();
        let rss = AntennaRss {
            front: -55.0,
            back: -55.0,
            left: -49.0,
            right: -61.0,
        };
        let rb = differential_range_bearing(&rss, &cfg).unwrap();
        assert!((rb.bearing_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((rb.range_m - 10f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn nan_reading_is_an_error_not_a_panic() {
        let rss = AntennaRss {
            front: f64::NAN,
            back: -50.0,
            left: -50.0,
            right: -50.0,
        };
        let err = differential_range_bearing(&rss, &DifferentialRssConfig::default());
        assert!(matches!(err, Err(EmitterError::NonFiniteRss { .. })));
    }

    #[test]
    fn range_is_clamped() {
        let cfg = DifferentialRssConfig::default();
        let loud = AntennaRss {
            front: 20.0,
            back: 20.0,
            left: 20.0,
            right: 20.0,
        };
        assert_eq!(
            differential_range_bearing(&loud, &cfg).unwrap().range_m,
            0.1
        );
        let faint = AntennaRss {
            front: -200.0,
            back: -200.0,
            left: -200.0,
            right: -200.0,
        };
        assert_eq!(
            differential_range_bearing(&faint, &cfg).unwrap().range_m,
            60.0
        );
    }
}
