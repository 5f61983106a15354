//! Estimator pipelines: each turns device events into pose estimates, with no I/O.

use rfloc_pose::PoseEstimate;

use crate::config::EstimatorConfig;
use crate::events::DeviceEvent;

mod hfgrid;
mod odometry;
mod snapshot;

pub use hfgrid::HfGridPipeline;
pub use odometry::OdometryPipeline;
pub use snapshot::SnapshotPipeline;

/// A pose estimator fed by device events.
pub trait Pipeline: Send {
    /// Name used as the POSE `source`.
    fn name(&self) -> &'static str;
    /// Consumes one event; returns a new estimate when there is one.
    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate>;
}

/// Builds the pipeline a configuration asks for.
#[must_use]
pub fn build(config: &EstimatorConfig, state_dir: Option<&std::path::Path>) -> Box<dyn Pipeline> {
    match config {
        EstimatorConfig::Odometry => Box::new(OdometryPipeline::default()),
        EstimatorConfig::Hfgrid(s) => Box::new(HfGridPipeline::new(s)),
        EstimatorConfig::Snapshot(s) => Box::new(SnapshotPipeline::new(s, state_dir)),
        EstimatorConfig::Ekfslam(_) => Box::new(Unavailable {
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
        EstimatorConfig::Odometry | EstimatorConfig::Hfgrid(_) | EstimatorConfig::Snapshot(_)
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
