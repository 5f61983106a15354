//! A pose with its uncertainty, as estimators publish it.

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use crate::pose::Pose2;

/// How much a published pose can be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EstimateMode {
    /// No estimate yet (initialising, or not enough data).
    NoFix,
    /// Estimate from dead reckoning only, or from a device that has gone stale.
    Degraded,
    /// Estimate corrected by fresh sensor data.
    Fix,
}

/// A pose estimate: pose, 3×3 covariance over `(x, y, yaw)`, the time it refers to (seconds on the
/// daemon's clock) and the estimator that produced it.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseEstimate {
    pub time: f64,
    pub pose: Pose2,
    pub covariance: Matrix3<f64>,
    pub mode: EstimateMode,
    pub source: String,
}

impl PoseEstimate {
    /// The covariance in ROS `geometry_msgs/PoseWithCovariance` order: row-major 6×6 over
    /// `(x, y, z, roll, pitch, yaw)`. The unobserved z/roll/pitch get zero variance.
    #[must_use]
    pub fn ros_covariance(&self) -> [f64; 36] {
        let mut out = [0.0; 36];
        // Planar index -> ROS index.
        let map = [0usize, 1, 5];
        for (i, ri) in map.iter().enumerate() {
            for (j, rj) in map.iter().enumerate() {
                if let Some(slot) = out.get_mut(ri * 6 + rj) {
                    *slot = self.covariance[(i, j)];
                }
            }
        }
        out
    }

    /// Quaternion `(x, y, z, w)` of the heading about +z.
    #[must_use]
    pub fn quaternion(&self) -> [f64; 4] {
        let h = self.pose.theta / 2.0;
        [0.0, 0.0, h.sin(), h.cos()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros_covariance_places_yaw_at_index_35() {
        let est = PoseEstimate {
            time: 0.0,
            pose: Pose2::new(0.0, 0.0, 0.0),
            covariance: Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 5.0, 3.0, 5.0, 6.0),
            mode: EstimateMode::Fix,
            source: "test".into(),
        };
        let c = est.ros_covariance();
        assert_eq!(c[0], 1.0);
        assert_eq!(c[1], 2.0);
        assert_eq!(c[5], 3.0);
        assert_eq!(c[7], 4.0);
        assert_eq!(c[11], 5.0);
        assert_eq!(c[30], 3.0);
        assert_eq!(c[35], 6.0);
        assert_eq!(c[14], 0.0);
    }

    #[test]
    fn quaternion_of_half_turn() {
        let est = PoseEstimate {
            time: 0.0,
            pose: Pose2::new(0.0, 0.0, std::f64::consts::PI),
            covariance: Matrix3::zeros(),
            mode: EstimateMode::Fix,
            source: "t".into(),
        };
        let q = est.quaternion();
        assert!((q[2] - 1.0).abs() < 1e-12 && q[3].abs() < 1e-12);
    }
}
