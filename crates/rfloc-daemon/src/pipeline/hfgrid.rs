//! HF floor-grid pipeline (seed 002): the initial pose from a 360° turn on the spot, then a
//! particle filter that tracks the robot with odometry and tag reports.
//!
//! Heading during the turn comes from the base's odometry (live, continuous turn) or from
//! `stop k heading_deg=…` marks (captured sessions, eight stops as in the seed). The turn is
//! solved once the readings cover a full turn (odometry) or when the input ends (a final
//! `end` mark, sent by replay), and again as more stops arrive while the first solve is refused.

use std::f64::consts::TAU;

use nalgebra::Matrix3;
use rfloc_hfgrid::{
    GridTracker, GridTrackerConfig, InitialPose, InitialPoseConfig, InitialPoseSolver, RssiModel,
    TagGrid, TagReading, TurnStop,
};
use rfloc_pose::{angle_diff, EstimateMode, Pose2, PoseEstimate};

use crate::config::HfGridSettings;
use crate::events::DeviceEvent;
use crate::pipeline::{InitOutcome, Pipeline, Request};

/// Where the pipeline is.
enum Phase {
    /// Collecting the turn.
    Turning,
    /// Tracking from the initial pose.
    Tracking(Box<GridTracker>),
}

/// Initial pose from a 360° turn over the tag grid, then tracking.
pub struct HfGridPipeline {
    solver: InitialPoseSolver,
    tracker_config: GridTrackerConfig,
    model: RssiModel,
    grid: TagGrid,
    phase: Phase,
    stops: Vec<TurnStop>,
    /// Heading of the stop being filled, relative to the start of the turn.
    current_heading: Option<f64>,
    odom_start: Option<Pose2>,
    odom_last: Option<Pose2>,
    /// Accumulated rotation since the turn started (odometry), rad.
    turned: f64,
    refusals: u64,
    last_no_fix: f64,
    /// Tag reports since the last odometry event, applied as one update.
    pending: Vec<TagReading>,
    /// A turn the pipeline drives itself (a fleet manager's `initPosition`): odometry time it
    /// started at, once odometry came.
    self_turn: Option<Option<f64>>,
    init_result: Option<Result<(), String>>,
    requests: Vec<Request>,
}

/// Turn rate of a turn the pipeline drives itself, rad/s (the seed's eight 45° steps in 2 s).
const SELF_TURN_RATE: f64 = std::f64::consts::PI / 8.0;
/// A self-driven turn not solved within this much odometry time fails, seconds.
const SELF_TURN_TIMEOUT_S: f64 = 120.0;

/// How much short of 360° of odometry rotation still counts as a full turn.
const FULL_TURN_SLACK: f64 = 10.0 * std::f64::consts::PI / 180.0;

impl std::fmt::Debug for HfGridPipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HfGridPipeline")
            .field("stops", &self.stops.len())
            .finish_non_exhaustive()
    }
}

impl HfGridPipeline {
    #[must_use]
    pub fn new(settings: &HfGridSettings, grid: TagGrid) -> Self {
        let model = RssiModel::seed002_blind_spot().scaled(settings.rssi_distance_scale);
        let offset = (-settings.antenna_offset_m, 0.0);
        let init = InitialPoseConfig {
            antenna_offset_m: offset,
            ..InitialPoseConfig::default()
        };
        let tracker_config = GridTrackerConfig {
            antenna_offset_m: offset,
            ..GridTrackerConfig::default()
        };
        Self {
            solver: InitialPoseSolver::new(grid.clone(), model.clone(), init),
            tracker_config,
            model,
            grid,
            phase: Phase::Turning,
            stops: Vec::new(),
            current_heading: None,
            odom_start: None,
            odom_last: None,
            turned: 0.0,
            refusals: 0,
            last_no_fix: f64::NEG_INFINITY,
            pending: Vec::new(),
            self_turn: None,
            init_result: None,
            requests: Vec::new(),
        }
    }

    fn reading(uid: &str, rssi: u8, rssi_second: u8) -> Option<TagReading> {
        let uid = u64::from_str_radix(uid, 16).ok()?;
        Some(TagReading {
            uid,
            rssi_first: rssi,
            rssi_second,
        })
    }

    /// Tries to solve the turn; on success switches to tracking and returns the estimate of the
    /// robot now (start heading plus the rotation since).
    fn try_solve(&mut self, time: f64) -> Option<PoseEstimate> {
        match self.solver.solve(&self.stops) {
            Ok(init) => {
                let est = self.start_tracking(&init, time);
                tracing::info!(
                    x = init.pose.x,
                    y = init.pose.y,
                    theta_deg = init.pose.theta.to_degrees(),
                    stops = init.stops_used,
                    tags = init.distinct_tags,
                    "initial pose from the turn"
                );
                est
            }
            Err(e) => {
                self.refusals += 1;
                tracing::warn!(reason = %e, stops = self.stops.len(), "initial pose refused");
                None
            }
        }
    }

    fn start_tracking(&mut self, init: &InitialPose, time: f64) -> Option<PoseEstimate> {
        // The solver answers for the start of the turn; the robot has turned since.
        // With odometry, the rotation since the start is known exactly; with stop marks it is
        // the last mark's heading.
        let rotated = match (self.odom_start, self.odom_last) {
            (Some(start), Some(last)) => angle_diff(last.theta, start.theta),
            _ => self.current_heading.unwrap_or(0.0),
        };
        let now = Pose2::new(init.pose.x, init.pose.y, init.pose.theta + rotated);
        let mut cov = init.covariance;
        // Keep the filter's start spread sane even if the solver is very confident.
        for i in 0..3 {
            cov[(i, i)] = cov[(i, i)].max(1e-6);
        }
        match GridTracker::new(
            self.grid.clone(),
            &self.model,
            self.tracker_config,
            now,
            cov,
        ) {
            Ok(t) => {
                self.phase = Phase::Tracking(Box::new(t));
                let mut est = init.to_estimate(time);
                est.pose = now;
                Some(est)
            }
            Err(e) => {
                tracing::error!(error = %e, "tracker could not start");
                None
            }
        }
    }

    fn tracking_estimate(tracker: &GridTracker, time: f64) -> PoseEstimate {
        let (pose, covariance) = tracker.estimate();
        PoseEstimate {
            time,
            pose,
            covariance,
            mode: EstimateMode::Fix,
            source: "hfgrid".into(),
        }
    }

    fn handle_turning(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        match event {
            DeviceEvent::Mark { t, text, .. } => {
                if text.trim() == "end" {
                    return self.try_solve(*t);
                }
                // `stop k heading_deg=H`
                let heading = text
                    .split_whitespace()
                    .find_map(|w| w.strip_prefix("heading_deg="))
                    .and_then(|h| h.parse::<f64>().ok())?;
                self.current_heading = Some(heading.to_radians());
                self.stops.push(TurnStop {
                    heading_rad: heading.to_radians(),
                    readings: Vec::new(),
                });
                None
            }
            DeviceEvent::Odometry { t, pose, .. } => {
                let start = *self.odom_start.get_or_insert(*pose);
                if let Some(last) = self.odom_last {
                    self.turned += angle_diff(pose.theta, last.theta).abs();
                }
                self.odom_last = Some(*pose);
                let rel = angle_diff(pose.theta, start.theta);
                // Continuous turn: one stop per 5° of heading change.
                let new_stop = self
                    .current_heading
                    .is_none_or(|h| angle_diff(rel, h).abs() > 5f64.to_radians());
                if new_stop {
                    self.current_heading = Some(rel);
                    self.stops.push(TurnStop {
                        heading_rad: rel,
                        readings: Vec::new(),
                    });
                }
                // A full turn, less a little for the base's acceleration limits.
                if self.turned >= TAU - FULL_TURN_SLACK {
                    return self.try_solve(*t);
                }
                // While turning: no fix yet, say so once a second.
                if *t - self.last_no_fix >= 1.0 {
                    self.last_no_fix = *t;
                    return Some(PoseEstimate {
                        time: *t,
                        pose: *pose,
                        covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(
                            100.0, 100.0, 10.0,
                        )),
                        mode: EstimateMode::NoFix,
                        source: "hfgrid-init".into(),
                    });
                }
                None
            }
            DeviceEvent::HfTag {
                uid,
                rssi,
                rssi_second,
                ..
            } => {
                let reading = Self::reading(uid, *rssi, *rssi_second)?;
                if self.stops.is_empty() {
                    // Readings before any heading source: the start of the turn.
                    self.current_heading = Some(0.0);
                    self.stops.push(TurnStop {
                        heading_rad: 0.0,
                        readings: Vec::new(),
                    });
                }
                if let Some(stop) = self.stops.last_mut() {
                    stop.readings.push(reading);
                }
                None
            }
            DeviceEvent::Status { .. }
            | DeviceEvent::WheelStall { .. }
            | DeviceEvent::Bumpers { .. }
            | DeviceEvent::EmitterRss { .. }
            | DeviceEvent::RangeScan { .. }
            | DeviceEvent::UhfSnapshot { .. }
            | DeviceEvent::Sweep { .. } => None,
        }
    }
}

impl HfGridPipeline {
    /// Drives a self-driven turn on odometry events: turn on, stop when the pose is solved, the
    /// solve was refused after a full turn and a quarter, or the time ran out.
    fn drive_turn(&mut self, event: &DeviceEvent) {
        let (Some(started), DeviceEvent::Odometry { t, .. }) = (&mut self.self_turn, event) else {
            return;
        };
        let start = *started.get_or_insert(*t);
        let outcome = if matches!(self.phase, Phase::Tracking(_)) {
            Some(Ok(()))
        } else if self.turned >= TAU + std::f64::consts::FRAC_PI_2 {
            Some(Err(format!(
                "no initial pose from a full turn ({} refusals)",
                self.refusals
            )))
        } else if *t - start > SELF_TURN_TIMEOUT_S {
            Some(Err(format!(
                "the turn did not complete within {SELF_TURN_TIMEOUT_S} s"
            )))
        } else {
            None
        };
        match outcome {
            Some(result) => {
                self.requests.push(Request::Velocity { v: 0.0, w: 0.0 });
                self.self_turn = None;
                self.init_result = Some(result);
            }
            None => self.requests.push(Request::Velocity {
                v: 0.0,
                w: SELF_TURN_RATE,
            }),
        }
    }

    fn handle_event(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        match &mut self.phase {
            Phase::Turning => self.handle_turning(event),
            Phase::Tracking(tracker) => match event {
                DeviceEvent::Odometry { t, pose, .. } => {
                    let prev = self.odom_last.replace(*pose);
                    if let Some(prev) = prev {
                        if let Err(e) = tracker.predict(pose.relative_to(&prev)) {
                            tracing::warn!(error = %e, "odometry increment rejected");
                        }
                    }
                    // Reports gathered since the last odometry event: one weighting step.
                    if !self.pending.is_empty() {
                        tracker.update(&self.pending);
                        self.pending.clear();
                    }
                    Some(Self::tracking_estimate(tracker, *t))
                }
                DeviceEvent::HfTag {
                    uid,
                    rssi,
                    rssi_second,
                    t,
                    ..
                } => {
                    let reading = Self::reading(uid, *rssi, *rssi_second)?;
                    if self.odom_last.is_some() {
                        self.pending.push(reading);
                        return None;
                    }
                    // Without odometry (a replayed reader alone) every report is a new estimate.
                    tracker.update(&[reading]);
                    Some(Self::tracking_estimate(tracker, *t))
                }
                DeviceEvent::Mark { .. }
                | DeviceEvent::Status { .. }
                | DeviceEvent::WheelStall { .. }
                | DeviceEvent::Bumpers { .. }
                | DeviceEvent::EmitterRss { .. }
                | DeviceEvent::RangeScan { .. }
                | DeviceEvent::UhfSnapshot { .. }
                | DeviceEvent::Sweep { .. } => None,
            },
        }
    }
}

impl Pipeline for HfGridPipeline {
    fn scene(&self) -> Option<crate::pipeline::Scene> {
        let tags = self
            .grid
            .tags()
            .into_iter()
            .map(|(uid, x, y)| crate::pipeline::SceneMark {
                id: format!("{uid:016X}"),
                x,
                y,
                cov: None,
            })
            .collect();
        Some(crate::pipeline::Scene {
            tags,
            ..crate::pipeline::Scene::default()
        })
    }

    fn name(&self) -> &'static str {
        "hfgrid"
    }

    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        let estimate = self.handle_event(event);
        self.drive_turn(event);
        estimate
    }

    fn take_requests(&mut self) -> Vec<Request> {
        std::mem::take(&mut self.requests)
    }

    /// The HF robot finds its own position: a 360° turn on the spot over the tag grid, driven
    /// by the pipeline, from which the initial pose is solved again (the given pose is not
    /// used). The outcome follows through [`Pipeline::take_init_result`].
    fn init_position(&mut self, _pose: Pose2) -> InitOutcome {
        self.phase = Phase::Turning;
        self.stops.clear();
        self.current_heading = None;
        self.odom_start = None;
        self.turned = 0.0;
        self.pending.clear();
        self.self_turn = Some(None);
        self.init_result = None;
        tracing::info!("initialisation turn started");
        InitOutcome::Pending
    }

    fn take_init_result(&mut self) -> Option<Result<(), String>> {
        self.init_result.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eight_marked_stops_over_the_seed_field_give_a_fix() {
        let mut p = HfGridPipeline::new(&HfGridSettings::default(), TagGrid::seed002_test_field());
        // Robot at (0.2, 0.2), heading 0, antenna 10 cm behind: the antenna circles (0.2, 0.2)
        // at 10 cm. Readings from the seed field using the blind-spot table.
        let model = RssiModel::seed002_blind_spot();
        let grid = TagGrid::seed002_test_field();
        let mut t = 0.0;
        for k in 0..8 {
            let h = f64::from(k) * 45f64.to_radians();
            p.handle(&DeviceEvent::Mark {
                device: "hf".into(),
                t,
                text: format!("stop {k} heading_deg={}", k * 45),
            });
            let ax = 0.2 - 0.1 * h.cos();
            let ay = 0.2 - 0.1 * h.sin();
            for (uid, x, y) in grid.tags() {
                let d = (x - ax).hypot(y - ay);
                if let Some(r) = model.rssi_for_distance(d) {
                    for _ in 0..3 {
                        t += 0.1;
                        let ev = DeviceEvent::HfTag {
                            device: "hf".into(),
                            t,
                            uid: format!("{uid:016X}"),
                            rssi: r,
                            rssi_second: r,
                        };
                        assert!(p.handle(&ev).is_none());
                    }
                }
            }
        }
        let est = p
            .handle(&DeviceEvent::Mark {
                device: "hf".into(),
                t,
                text: "end".into(),
            })
            .expect("a fix after the turn");
        assert_eq!(est.mode, EstimateMode::Fix);
        let err = (est.pose.x - 0.2).hypot(est.pose.y - 0.2);
        assert!(err < 0.03, "position error {err} m: {:?}", est.pose);
        // Tracking: odometry increments and tag reports keep producing fixes.
        let started = std::time::Instant::now();
        for k in 0..50 {
            t += 0.1;
            let odo = Pose2::new(0.001 * f64::from(k), 0.0, 0.0);
            let e = p
                .handle(&DeviceEvent::Odometry {
                    device: "base".into(),
                    t,
                    pose: odo,
                    v: 0.01,
                    w: 0.0,
                })
                .expect("tracking estimate");
            assert_eq!(e.mode, EstimateMode::Fix);
            let tag = DeviceEvent::HfTag {
                device: "hf".into(),
                t,
                uid: "E00401503A5BD785".into(),
                rssi: 3,
                rssi_second: 3,
            };
            assert!(
                p.handle(&tag).is_none(),
                "with odometry, estimates follow odometry"
            );
        }
        eprintln!("50 tracking steps took {:?}", started.elapsed());
    }

    #[test]
    fn init_position_turns_the_robot_and_reports_a_refusal() {
        let mut p = HfGridPipeline::new(&HfGridSettings::default(), TagGrid::seed002_test_field());
        assert_eq!(p.init_position(Pose2::default()), InitOutcome::Pending);
        let mut t = 0.0;
        let mut theta = 0.0;
        let mut turns = 0;
        // No tag under the antenna: the turn goes round, is refused, and stops.
        while p.self_turn.is_some() && t < 200.0 {
            p.handle(&DeviceEvent::Odometry {
                device: "base".into(),
                t,
                pose: Pose2::new(0.0, 0.0, theta),
                v: 0.0,
                w: SELF_TURN_RATE,
            });
            for r in p.take_requests() {
                if r == (Request::Velocity {
                    v: 0.0,
                    w: SELF_TURN_RATE,
                }) {
                    turns += 1;
                }
            }
            t += 0.1;
            theta += SELF_TURN_RATE * 0.1;
        }
        assert!(turns > 150, "{turns} turn requests");
        let result = p.take_init_result().expect("a result");
        assert!(result.is_err(), "{result:?}");
        p.handle(&DeviceEvent::Odometry {
            device: "base".into(),
            t,
            pose: Pose2::new(0.0, 0.0, theta),
            v: 0.0,
            w: 0.0,
        });
        assert!(p.take_requests().is_empty(), "the turn stopped for good");
    }
}
