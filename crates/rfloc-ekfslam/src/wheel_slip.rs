//! Odometry increment covariance from wheel slip: each wheel's travel has a relative Gaussian
//! error per fixed interval (a differential drive's encoders see wheel rotation, not ground
//! motion). Unlike [`crate::OdometryNoise`], whose σ grows linearly with each increment's
//! length, this model's variance grows with the number of intervals, so it does not depend on
//! how often odometry is sampled.

use nalgebra::Matrix3;
use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

/// Relative wheel-travel error of σ `relative_sigma` per `interval_s`, on a base with wheel
/// track `track_m`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WheelSlipNoise {
    /// Relative σ of one wheel's travel over one interval (dimensionless).
    pub relative_sigma: f64,
    /// Distance between the wheels' contact points, m.
    pub track_m: f64,
    /// Interval the error is drawn for, s.
    pub interval_s: f64,
}

/// Wheel travels (left, right) of a robot-frame increment on a base with track `track_m`, m.
#[must_use]
pub fn wheel_travel(delta: &Pose2, track_m: f64) -> (f64, f64) {
    let d = delta.x.hypot(delta.y).copysign(delta.x);
    let half = track_m / 2.0;
    (d - delta.theta * half, d + delta.theta * half)
}

impl WheelSlipNoise {
    /// Covariance of an increment `delta` (robot frame: along, lateral, heading) that took `dt`
    /// seconds. The wheel errors of `dt / interval_s` intervals add up; the lateral error within
    /// the increment comes from the heading error at half the step. Small floors keep the
    /// matrix positive definite.
    #[must_use]
    pub fn increment_covariance(&self, delta: &Pose2, dt: f64) -> Matrix3<f64> {
        let d = delta.x.hypot(delta.y);
        let (sl, sr) = wheel_travel(delta, self.track_m);
        let n = if self.interval_s > 0.0 && dt.is_finite() {
            // Continuous in `dt`: a jitter in when odometry is sampled changes the covariance
            // by as little, instead of jumping by one whole interval at a rounding boundary.
            (dt / self.interval_s).max(1.0)
        } else {
            1.0
        };
        let k = self.relative_sigma * self.relative_sigma / n;
        let (vl, vr) = (k * sl * sl, k * sr * sr);
        let track2 = self.track_m * self.track_m;
        let along = (vl + vr) / 4.0 + 1e-10;
        let heading = (vl + vr) / track2 + 1e-10;
        let cross = (vr - vl) / (2.0 * self.track_m);
        let lateral = heading * d * d / 4.0 + 1e-10;
        Matrix3::new(
            along, 0.0, cross, //
            0.0, lateral, 0.0, //
            cross, 0.0, heading,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_driving_loads_both_wheels_evenly() {
        let m = WheelSlipNoise {
            relative_sigma: 0.05,
            track_m: 0.4,
            interval_s: 0.01,
        };
        // 3 cm in 100 ms: 10 intervals; each wheel travels 3 cm.
        let c = m.increment_covariance(&Pose2::new(0.03, 0.0, 0.0), 0.1);
        let per_wheel = 0.05 * 0.05 / 10.0 * 0.03 * 0.03;
        assert!((c[(0, 0)] - per_wheel / 2.0).abs() < 1e-9);
        assert!((c[(2, 2)] - 2.0 * per_wheel / 0.16).abs() < 1e-9);
        assert!(c[(0, 2)].abs() < 1e-15, "no along/heading correlation");
        // Half the intervals of the same travel: twice the variance.
        let fast = m.increment_covariance(&Pose2::new(0.03, 0.0, 0.0), 0.05);
        assert!(((fast[(0, 0)] - 1e-10) / (c[(0, 0)] - 1e-10) - 2.0).abs() < 1e-6);
    }

    #[test]
    fn sampling_jitter_changes_the_covariance_by_as_little() {
        let m = WheelSlipNoise {
            relative_sigma: 0.05,
            track_m: 0.4,
            interval_s: 0.01,
        };
        let step = Pose2::new(0.03, 0.0, 0.0);
        // 0.1049 s and 0.1051 s straddle 10.5 intervals: 0.2 % apart, not 10 %.
        let a = m.increment_covariance(&step, 0.1049)[(0, 0)] - 1e-10;
        let b = m.increment_covariance(&step, 0.1051)[(0, 0)] - 1e-10;
        assert!((a / b - 0.1051 / 0.1049).abs() < 1e-9, "{a} {b}");
        // Shorter than one interval counts as one.
        let short = m.increment_covariance(&step, 0.001)[(0, 0)];
        let one = m.increment_covariance(&step, 0.01)[(0, 0)];
        assert!((short - one).abs() < 1e-18);
    }

    #[test]
    fn turning_left_correlates_along_and_heading_errors() {
        let m = WheelSlipNoise {
            relative_sigma: 0.05,
            track_m: 0.4,
            interval_s: 0.01,
        };
        let c = m.increment_covariance(&Pose2::new(0.02, 0.0, 0.05), 0.1);
        assert!(c[(0, 2)] > 0.0);
        assert!(c.symmetric_eigenvalues().min() > 0.0);
        let still = m.increment_covariance(&Pose2::new(0.0, 0.0, 0.0), 0.1);
        assert!(still.iter().all(|v| v.abs() < 1e-9));
        let (l, r) = wheel_travel(&Pose2::new(0.0, 0.0, 1.0), 0.4);
        assert!((l + 0.2).abs() < 1e-12 && (r - 0.2).abs() < 1e-12);
    }
}
