//! Estimator pipelines: each turns device events into pose estimates, with no I/O.

use nalgebra::Matrix3;
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};

use crate::config::EstimatorConfig;
use crate::events::DeviceEvent;

mod hfgrid;

pub use hfgrid::HfGridPipeline;

/// A pose estimator fed by device events.
pub trait Pipeline: Send {
    /// Name used as the POSE `source`.
    fn name(&self) -> &'static str;
    /// Consumes one event; returns a new estimate when there is one.
    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate>;
}

/// Builds the pipeline a configuration asks for.
#[must_use]
pub fn build(config: &EstimatorConfig) -> Box<dyn Pipeline> {
    match config {
        EstimatorConfig::Odometry => Box::new(OdometryPipeline::default()),
        EstimatorConfig::Hfgrid(s) => Box::new(HfGridPipeline::new(s)),
        EstimatorConfig::Ekfslam(_) | EstimatorConfig::Snapshot(_) => Box::new(Unavailable {
            name: config.name(),
            warned: false,
        }),
    }
}

/// Whether the daemon can run a pipeline end to end yet.
#[must_use]
pub fn is_wired(config: &EstimatorConfig) -> bool {
    matches!(
        config,
        EstimatorConfig::Odometry | EstimatorConfig::Hfgrid(_)
    )
}

/// A pipeline whose estimator exists as a library but is not wired into the daemon yet.
#[derive(Debug)]
struct Unavailable {
    name: &'static str,
    warned: bool,
}

impl Pipeline for Unavailable {
    fn name(&self) -> &'static str {
        self.name
    }

    fn handle(&mut self, _event: &DeviceEvent) -> Option<PoseEstimate> {
        if !self.warned {
            self.warned = true;
            tracing::error!(
                pipeline = self.name,
                "pipeline not wired into the daemon yet: no poses will be published"
            );
        }
        None
    }
}

/// Dead reckoning from the base's odometry. Position variance grows with distance travelled
/// (1 % of distance as standard deviation) and heading variance with rotation (2 %).
#[derive(Debug, Default)]
pub struct OdometryPipeline {
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
            pose: *pose,
            covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(
                sxy * sxy,
                sxy * sxy,
                sth * sth,
            )),
            mode: EstimateMode::Degraded,
            source: "odometry".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odometry_variance_grows_with_travel() {
        let mut p = OdometryPipeline::default();
        let ev = |x: f64| DeviceEvent::Odometry {
            device: "base".into(),
            t: x,
            pose: Pose2::new(x, 0.0, 0.0),
            v: 0.0,
            w: 0.0,
        };
        let a = p.handle(&ev(0.0)).unwrap();
        let b = p.handle(&ev(10.0)).unwrap();
        assert!(b.covariance[(0, 0)] > a.covariance[(0, 0)]);
        assert!(
            (b.covariance[(0, 0)] - 0.01).abs() < 1e-12,
            "σ = 0.1 m after 10 m"
        );
        assert_eq!(b.mode, EstimateMode::Degraded);
    }
}
