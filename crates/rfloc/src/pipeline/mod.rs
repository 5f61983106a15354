//! Estimator pipelines: each turns device events into pose estimates, with no I/O.

use rfloc_pose::PoseEstimate;

use crate::config::EstimatorConfig;
use crate::events::DeviceEvent;

mod ekfslam;
pub mod emitter;
mod goal;
mod hfgrid;
mod odometry;
mod snapshot;

pub use ekfslam::EkfSlamPipeline;
pub use emitter::EmitterPipeline;
pub use hfgrid::HfGridPipeline;
pub use odometry::OdometryPipeline;
pub use snapshot::SnapshotPipeline;

/// A pose estimator fed by device events.
pub trait Pipeline: Send {
    /// Name used as the POSE `source`.
    fn name(&self) -> &'static str;
    /// Consumes one event; returns a new estimate when there is one.
    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate>;
    /// What the pipeline wants the devices to do, oldest first (drained by the daemon after
    /// every event). Pipelines that only listen never ask for anything.
    fn take_requests(&mut self) -> Vec<Request> {
        Vec::new()
    }
    /// Estimates of things other than the robot (the emitter a robot homes on), oldest first
    /// (drained by the daemon after every event, published as TARGET lines).
    fn take_targets(&mut self) -> Vec<TargetEstimate> {
        Vec::new()
    }
}

/// A position estimate of something the robot tracks, in the map frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetEstimate {
    /// Time of the measurement it includes last (driver clock), seconds.
    pub time: f64,
    /// What it is (`emitter`).
    pub id: &'static str,
    /// Position, metres.
    pub x: f64,
    pub y: f64,
    /// Position covariance (xx, xy, yy), m².
    pub cov: [f64; 3],
    /// The unfiltered position of the same update, when the pipeline has one.
    pub raw: Option<(f64, f64)>,
    /// Pipeline name.
    pub source: &'static str,
}

/// A pipeline's request to the devices; the daemon routes it to the device task that can act.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// Drive the base: forward speed (m/s), turn rate (rad/s).
    Velocity { v: f64, w: f64 },
    /// Sweep the directional antenna once; the robot stands still with this odometry heading.
    Sweep { heading_rad: f64 },
}

/// Builds the pipeline a configuration asks for.
#[must_use]
pub fn build(config: &EstimatorConfig, state_dir: Option<&std::path::Path>) -> Box<dyn Pipeline> {
    match config {
        EstimatorConfig::Odometry => Box::new(OdometryPipeline::default()),
        EstimatorConfig::Hfgrid(s) => Box::new(HfGridPipeline::new(s)),
        EstimatorConfig::Snapshot(s) => Box::new(SnapshotPipeline::new(s, state_dir)),
        EstimatorConfig::Ekfslam(s) => match EkfSlamPipeline::new(s) {
            Ok(p) => Box::new(p),
            Err(e) => Box::new(Unavailable {
                name: config.name(),
                reason: e,
                warned: false,
            }),
        },
        EstimatorConfig::Emitter(s) => match EmitterPipeline::new(s) {
            Ok(p) => Box::new(p),
            Err(e) => Box::new(Unavailable {
                name: config.name(),
                reason: e,
                warned: false,
            }),
        },
    }
}

/// Sweep settings for the XBee radio's task: the pipeline's step, path-loss model and antenna
/// pattern where it has them, the bearing crate's defaults otherwise.
#[must_use]
pub fn scan_config(config: &EstimatorConfig) -> rfloc_bearing::ScanConfig {
    let mut scan = rfloc_bearing::ScanConfig::default();
    if let EstimatorConfig::Ekfslam(e) = config {
        scan.plan.step_deg = e.sweep_step_deg;
        scan.estimator.path_loss.p_ref_dbm = e.p_ref_dbm;
        scan.estimator.path_loss.eta = e.path_loss_exponent;
        scan.estimator.pattern = e.antenna_pattern;
    }
    scan
}

/// Whether the pipeline drives the base itself (then no simulated motion script runs).
#[must_use]
pub fn drives_base(config: &EstimatorConfig) -> bool {
    match config {
        EstimatorConfig::Ekfslam(e) => !e.waypoints.is_empty(),
        EstimatorConfig::Snapshot(s) => s.goal.is_some(),
        EstimatorConfig::Emitter(_) => true,
        _ => false,
    }
}

/// A pipeline that could not be built from a validated configuration (for example an
/// estimator refusing a start covariance): it publishes nothing and says why once.
#[derive(Debug)]
struct Unavailable {
    name: &'static str,
    reason: String,
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
                reason = %self.reason,
                "pipeline could not be built: no poses will be published"
            );
        }
        None
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn the_sweep_task_fits_the_configured_antenna_pattern() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/sim-xbee.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let cfg = crate::config::RobotConfig::parse(&text, path).unwrap();
        let scan = scan_config(&cfg.estimator);
        let Some(rfloc_bearing::GainPattern::CosinePower(p)) = scan.estimator.pattern else {
            panic!("no cosine-power pattern: {:?}", scan.estimator.pattern);
        };
        assert!((p.exponent - 8.0).abs() < 1e-12 && (p.back_lobe_db + 10.0).abs() < 1e-12);
        // Without the setting the sweep keeps the parabolic peak fit.
        let plain = text.replace(
            "antenna_pattern = { kind = \"cosine_power\", exponent = 8.0, back_lobe_db = -10.0 }\n",
            "",
        );
        assert_ne!(plain, text);
        let cfg = crate::config::RobotConfig::parse(&plain, path).unwrap();
        assert!(scan_config(&cfg.estimator).estimator.pattern.is_none());
    }
}
