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
mod tags;

pub use ekfslam::EkfSlamPipeline;
pub use emitter::EmitterPipeline;
pub use hfgrid::HfGridPipeline;
pub use odometry::OdometryPipeline;
pub use snapshot::load_learned_check;
pub use snapshot::SnapshotPipeline;
pub use tags::{builtin_tag_field, load_tag_map, tag_grid};

/// Where a pipeline finds the files its configuration names.
#[derive(Debug, Clone, Copy, Default)]
pub struct PipelineEnv<'a> {
    /// `[state] dir`: learned maps and databases.
    pub state_dir: Option<&'a std::path::Path>,
    /// Folder of the robot file: tag tables.
    pub config_dir: Option<&'a std::path::Path>,
}

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
    /// What the pipeline knows of the world, for a viewer: its beacon or tag map, its
    /// particles. `None` when it has nothing to show.
    fn scene(&self) -> Option<Scene> {
        None
    }
    /// Whether [`Pipeline::set_goal`] can drive the robot (a fleet manager's orders need it).
    fn drives_to_goals(&self) -> bool {
        false
    }
    /// Drive to `goal` (map frame), replacing any route of the robot file; `None`: stop and stay
    /// (the configured route is not resumed). Returns whether the pipeline drives to goals; one
    /// that does not ignores the call. Called on the estimator thread between events.
    fn set_goal(&mut self, goal: Option<Goal>) -> bool {
        let _ = goal;
        false
    }
    /// Take `pose` (map frame) as where the robot is now (a fleet manager's `initPosition`).
    fn init_position(&mut self, pose: rfloc_pose::Pose2) -> InitOutcome {
        let _ = pose;
        InitOutcome::Refused(format!(
            "the {} pipeline cannot be given its position",
            self.name()
        ))
    }
    /// The outcome of an initialisation that was [`InitOutcome::Pending`], once it has one
    /// (polled between events).
    fn take_init_result(&mut self) -> Option<Result<(), String>> {
        None
    }
}

/// A pipeline's picture of the world ([`Pipeline::scene`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scene {
    /// Mapped beacons: id, position, position covariance (xx, xy, yy) when known.
    pub beacons: Vec<SceneMark>,
    /// Floor or wall tags.
    pub tags: Vec<SceneMark>,
    /// Particles: x, y, yaw, weight.
    pub particles: Vec<[f64; 4]>,
}

/// One mapped thing of a [`Scene`].
#[derive(Debug, Clone, PartialEq)]
pub struct SceneMark {
    pub id: String,
    pub x: f64,
    pub y: f64,
    pub cov: Option<[f64; 3]>,
}

/// Where a fleet manager wants the robot (the next node of an order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    /// Position in the map frame, metres.
    pub x: f64,
    pub y: f64,
    /// The goal counts as reached within this distance, metres: a pipeline stops inside it.
    pub tolerance_m: f64,
    /// Speed limit on the way, m/s.
    pub max_speed: Option<f64>,
}

/// What a pipeline did with an initial position.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InitOutcome {
    /// Taken: the pipeline's pose is the given one from now on.
    Done,
    /// Under way (the HF robot's 360° turn); the result comes from
    /// [`Pipeline::take_init_result`].
    Pending,
    /// Not possible, and why.
    Refused(String),
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

/// Builds the pipeline a configuration asks for; an error says why it cannot run (a file it
/// needs is missing or damaged).
pub fn build(config: &EstimatorConfig, env: PipelineEnv<'_>) -> Result<Box<dyn Pipeline>, String> {
    Ok(match config {
        EstimatorConfig::Odometry => Box::new(OdometryPipeline::default()),
        EstimatorConfig::Hfgrid(s) => {
            Box::new(HfGridPipeline::new(s, tag_grid(s, env.config_dir)?))
        }
        EstimatorConfig::Snapshot(s) => Box::new(SnapshotPipeline::new(s, env.state_dir)?),
        EstimatorConfig::Ekfslam(s) => Box::new(EkfSlamPipeline::new(s)?),
        EstimatorConfig::Emitter(s) => Box::new(EmitterPipeline::new(s)?),
    })
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

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn the_sweep_task_fits_the_configured_antenna_pattern() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/sim-xbee.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let cfg = crate::config::RobotConfig::parse(&text, path, None).unwrap();
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
        let cfg = crate::config::RobotConfig::parse(&plain, path, None).unwrap();
        assert!(scan_config(&cfg.estimator).estimator.pattern.is_none());
    }
}
