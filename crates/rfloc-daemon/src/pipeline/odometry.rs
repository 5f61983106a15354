//! Dead-reckoning pipeline.

use nalgebra::Matrix3;
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};

use crate::events::DeviceEvent;
use crate::pipeline::{InitOutcome, Pipeline};

/// Dead reckoning from the base's odometry. Position variance grows with distance travelled
/// (1 % of distance as standard deviation) and heading variance with rotation (2 %).
#[derive(Debug, Default)]
pub struct OdometryPipeline {
    /// Where the odometry frame lies on the map (identity until an `initPosition`).
    frame: Pose2,
    last: Option<Pose2>,
    travelled: f64,
    rotated: f64,
}

impl Pipeline for OdometryPipeline {
    fn name(&self) -> &'static str {
        "odometry"
    }

    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        let DeviceEvent::Odometry { t, pose, .. } = event else {
            return None;
        };
        if let Some(prev) = self.last {
            self.travelled += pose.distance(&prev);
            self.rotated += rfloc_pose::angle_diff(pose.theta, prev.theta).abs();
        }
        self.last = Some(*pose);
        let sxy = (0.01 * self.travelled).max(1e-3);
        let sth = (0.02 * self.rotated).max(1e-3);
        Some(PoseEstimate {
            time: *t,
            pose: self.frame.compose(pose),
            covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(
                sxy * sxy,
                sxy * sxy,
                sth * sth,
            )),
            mode: EstimateMode::Degraded,
            source: "odometry".into(),
        })
    }

    /// The odometry frame is placed so that the latest odometry pose comes out at `pose`.
    fn init_position(&mut self, pose: Pose2) -> InitOutcome {
        let odometry = self.last.unwrap_or_default();
        self.frame = pose.compose(&Pose2::default().relative_to(&odometry));
        InitOutcome::Done
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfloc_pose::Pose2;

    /// The base's odometry at time `x`, having driven `x` metres along x.
    fn ev(x: f64) -> DeviceEvent {
        DeviceEvent::Odometry {
            device: "base".into(),
            t: x,
            pose: Pose2::new(x, 0.0, 0.0),
            v: 0.0,
            w: 0.0,
        }
    }

    #[test]
    fn odometry_variance_grows_with_travel() {
        let mut p = OdometryPipeline::default();
        let a = p.handle(&ev(0.0)).unwrap();
        let b = p.handle(&ev(10.0)).unwrap();
        assert!(b.covariance[(0, 0)] > a.covariance[(0, 0)]);
        assert!(
            (b.covariance[(0, 0)] - 0.01).abs() < 1e-12,
            "σ = 0.1 m after 10 m"
        );
        assert_eq!(b.mode, EstimateMode::Degraded);
    }

    #[test]
    fn init_position_places_the_odometry_frame() {
        let mut p = OdometryPipeline::default();
        p.handle(&ev(1.0));
        assert_eq!(
            p.init_position(Pose2::new(5.0, 5.0, std::f64::consts::FRAC_PI_2)),
            InitOutcome::Done
        );
        let e = p.handle(&ev(2.0)).unwrap();
        assert!(
            (e.pose.x - 5.0).abs() < 1e-9 && (e.pose.y - 6.0).abs() < 1e-9,
            "{:?}",
            e.pose
        );
    }
}
