//! Emitter homing in the daemon (seed 001): four fixed receivers' RSSI polls, the base's
//! odometry and a range finder's scans in; robot poses and velocity commands out.
//!
//! - **Pose.** As in the seed, the robot's pose is its start composed with the odometry,
//!   published as `degraded` with the dead-reckoning covariance of the odometry pipeline.
//! - **Control steps** fall on odometry events, every `control_period_s`. A step combines the
//!   newest reading of each receiver if all four are younger than `reading_window_s` (each
//!   reading is used once) and feeds it to the particle filter at the step's pose; then the
//!   navigator, given the latest scan and the filtered estimate, makes a velocity request.
//! - **Scans** go into the occupancy grid (full system) at the pose of the next odometry event,
//!   before that event's control step.
//! - **Bumpers** come from the base's SIPs (`DeviceEvent::Bumpers`, on every change); the
//!   navigator's reflex backs away from a front contact and pulls away from a rear one.

use rfloc_emitter::{
    AntennaRss, Bumpers, DifferentialRssConfig, NavigatorConfig, NavigatorState,
    OccupancyGridConfig, ParticleFilterConfig, Point2,
};
use rfloc_pose::{Pose2, PoseEstimate};

use crate::config::{AntennaSide, EmitterSettings};
use crate::events::DeviceEvent;
use crate::pipeline::{Goal, InitOutcome, OdometryPipeline, Pipeline, Request, TargetEstimate};

pub mod homing;

pub use homing::{EmitterHoming, HomingConfig};

/// Seconds between `emitter estimate` log lines at info level.
const LOG_EVERY_S: f64 = 5.0;

/// The homing configuration a robot file describes, for a robot starting at `start`.
#[must_use]
pub fn homing_config(s: &EmitterSettings, start: &Pose2) -> HomingConfig {
    let cells = (s.map_side_m / s.grid_cell_m).round().max(1.0) as usize;
    let max_side = (s.map_max_side_m / s.grid_cell_m).round().max(1.0) as usize;
    HomingConfig {
        rss: DifferentialRssConfig {
            a1_dbm_at_1m: s.a1_dbm_at_1m,
            a2_path_loss_exponent: s.path_loss_exponent,
            ..DifferentialRssConfig::default()
        },
        filter: ParticleFilterConfig {
            particle_count: s.particles,
            ..ParticleFilterConfig::default()
        },
        grid: OccupancyGridConfig {
            resolution_m: s.grid_cell_m,
            width: cells,
            height: cells,
            origin: Point2::new(start.x - s.map_side_m / 2.0, start.y - s.map_side_m / 2.0),
            // `map_side_m` is the initial extent: the map grows with the explored area and the
            // goal, up to `map_max_side_m` squared.
            growable: true,
            max_cells: max_side.saturating_mul(max_side).max(cells * cells),
            ..OccupancyGridConfig::default()
        },
        navigator: NavigatorConfig {
            use_planner: s.full_system,
            obstacle_distance_m: s.obstacle_distance_m,
            arrival_distance_m: s.arrival_distance_m,
            drive_speed_mps: s.drive_speed_mps,
            arrival_max_sigma_m: s.arrival_max_sigma_m,
            ..NavigatorConfig::default()
        },
        seed: s.seed,
        receiver_sensitivity_dbm: s.receiver_sensitivity_dbm,
    }
}

/// Counters of one run.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct EmitterCounters {
    /// Control steps taken.
    pub steps: u64,
    /// Filter updates (steps with all four receivers fresh).
    pub updates: u64,
    /// Steps without a fresh reading of every receiver.
    pub incomplete: u64,
    /// Polls the emitter did not answer.
    pub unanswered: u64,
    /// Filter updates with one or two receivers read as their sensitivity (heard nothing).
    pub censored: u64,
    /// Scans integrated.
    pub scans: u64,
    /// Times the navigator came to a stop at the emitter.
    pub arrivals: u64,
    /// Bumper contacts reported by the base.
    pub bumps: u64,
}

/// The emitter-homing pipeline.
#[derive(Debug)]
pub struct EmitterPipeline {
    homing: EmitterHoming,
    start: Pose2,
    dead_reckoning: OdometryPipeline,
    /// The latest published pose (start ∘ odometry).
    pose: Option<Pose2>,
    /// A scan waiting for the next odometry event, whose pose it is integrated at.
    pending_scan: Option<Vec<rfloc_emitter::ScanBeam>>,
    /// Newest reading per receiver: front, left, back, right; (time, dBm or `None` when the
    /// poll went unanswered).
    readings: [Option<(f64, Option<f64>)>; 4],
    control_period_s: f64,
    reading_window_s: f64,
    next_control: Option<f64>,
    next_log: f64,
    arrived: bool,
    estimate: Option<Point2>,
    requests: Vec<Request>,
    targets: Vec<TargetEstimate>,
    /// The bumper rings as the base last reported them.
    bumpers: Bumpers,
    counters: EmitterCounters,
    /// What a fleet manager asked for: homing (`None`), a goal, or standing still.
    fleet: FleetDrive,
}

/// The emitter robot under a fleet manager.
#[derive(Debug, Clone, Copy, PartialEq)]
enum FleetDrive {
    /// No goal was ever set: home on the emitter.
    Homing,
    /// Drive to this goal with the navigator (grid, A*, reflexes) instead of the emitter.
    Goal(Goal),
    /// The goal was taken away: stand still.
    Hold,
}

fn slot(side: AntennaSide) -> usize {
    match side {
        AntennaSide::Front => 0,
        AntennaSide::Left => 1,
        AntennaSide::Back => 2,
        AntennaSide::Right => 3,
    }
}

impl EmitterPipeline {
    /// A pipeline for the settings of a robot file.
    ///
    /// # Errors
    /// Filter or grid settings the emitter crate refuses.
    pub fn new(s: &EmitterSettings) -> Result<Self, String> {
        let start = Pose2::new(s.start[0], s.start[1], s.start[2].to_radians());
        Self::from_homing(
            homing_config(s, &start),
            start,
            s.control_period_s,
            s.reading_window_s,
        )
    }

    /// A pipeline with a homing configuration of its own (the `rfloc sim` trials calibrate
    /// theirs against the scenario), for a robot starting at `start`.
    ///
    /// # Errors
    /// Filter or grid settings the emitter crate refuses.
    pub fn from_homing(
        config: HomingConfig,
        start: Pose2,
        control_period_s: f64,
        reading_window_s: f64,
    ) -> Result<Self, String> {
        let homing = EmitterHoming::new(config, &start).map_err(|e| format!("{e:#}"))?;
        Ok(Self {
            homing,
            start,
            dead_reckoning: OdometryPipeline::default(),
            pose: None,
            pending_scan: None,
            readings: [None; 4],
            control_period_s,
            reading_window_s,
            next_control: None,
            next_log: 0.0,
            arrived: false,
            estimate: None,
            requests: Vec::new(),
            targets: Vec::new(),
            bumpers: Bumpers::default(),
            counters: EmitterCounters::default(),
            fleet: FleetDrive::Homing,
        })
    }

    /// Counters so far.
    #[must_use]
    pub fn counters(&self) -> EmitterCounters {
        self.counters
    }

    /// The homing state (filter, grid, navigator counters).
    #[must_use]
    pub fn homing(&self) -> &EmitterHoming {
        &self.homing
    }

    /// Whether the navigator's last step stopped at the emitter.
    #[must_use]
    pub fn arrived(&self) -> bool {
        self.arrived
    }

    /// The filtered emitter position, once there is one.
    #[must_use]
    pub fn estimate(&self) -> Option<Point2> {
        self.estimate
    }

    /// The four receivers' readings if all are fresh at `t`; they are then used up. With a
    /// receiver sensitivity configured, a receiver that heard nothing reads as that level as
    /// long as at least two heard the emitter (the true level was at most the sensitivity);
    /// otherwise all four must have heard it.
    fn take_fresh(&mut self, t: f64) -> Option<AntennaRss> {
        let window = self.reading_window_s;
        let floor = self.homing.config().receiver_sensitivity_dbm;
        let fresh = self
            .readings
            .map(|r| r.filter(|(rt, _)| t - rt <= window).map(|r| r.1));
        if fresh.iter().any(Option::is_none) {
            return None;
        }
        // Every receiver has answered this step: the readings are used up either way.
        self.readings = [None; 4];
        let heard = fresh.iter().filter(|r| matches!(r, Some(Some(_)))).count();
        if heard < 2 {
            return None;
        }
        let level = |r: Option<Option<f64>>| r.flatten().or(floor);
        let [front, left, back, right] = fresh.map(level);
        let rss = AntennaRss {
            front: front?,
            back: back?,
            left: left?,
            right: right?,
        };
        if heard < 4 {
            self.counters.censored += 1;
        }
        Some(rss)
    }

    fn control_step(&mut self, t: f64, pose: Pose2) {
        self.counters.steps += 1;
        match self.take_fresh(t) {
            Some(rss) => {
                if let Some(est) = self.homing.observe_rss(t, &pose, &rss) {
                    self.counters.updates += 1;
                    self.estimate = Some(est.mean);
                    let c = est.covariance;
                    self.targets.push(TargetEstimate {
                        time: t,
                        id: "emitter",
                        x: est.mean.x,
                        y: est.mean.y,
                        cov: [c[(0, 0)], c[(0, 1)], c[(1, 1)]],
                        raw: Some((est.raw.x, est.raw.y)),
                        source: "emitter",
                    });
                    tracing::debug!(
                        x = est.mean.x,
                        y = est.mean.y,
                        raw_x = est.raw.x,
                        raw_y = est.raw.y,
                        "emitter estimate"
                    );
                    if t >= self.next_log {
                        self.next_log = t + LOG_EVERY_S;
                        tracing::info!(
                            x = est.mean.x,
                            y = est.mean.y,
                            range_m = est.filtered_range_bearing.range_m,
                            updates = self.counters.updates,
                            "emitter estimate"
                        );
                    }
                }
            }
            None => self.counters.incomplete += 1,
        }
        match self.fleet {
            FleetDrive::Homing => {}
            FleetDrive::Hold => {
                self.requests.push(Request::Velocity { v: 0.0, w: 0.0 });
                return;
            }
            FleetDrive::Goal(g) => {
                if (pose.x - g.x).hypot(pose.y - g.y) <= 0.8 * g.tolerance_m {
                    self.requests.push(Request::Velocity { v: 0.0, w: 0.0 });
                    return;
                }
            }
        }
        let cmd = self.homing.command(t, pose, self.bumpers);
        let arrived = cmd.state == NavigatorState::Arrived;
        if arrived && !self.arrived {
            self.counters.arrivals += 1;
            let (x, y) = self.estimate.map_or((f64::NAN, f64::NAN), |p| (p.x, p.y));
            let arrivals = self.counters.arrivals;
            let plans = self.homing.plan_count();
            if arrivals == 1 {
                tracing::info!(
                    t,
                    robot_x = pose.x,
                    robot_y = pose.y,
                    emitter_x = x,
                    emitter_y = y,
                    plans,
                    "arrived at the emitter"
                );
            } else {
                // The estimate moved off and the robot followed: later arrivals at debug.
                tracing::debug!(t, arrivals, "arrived at the emitter again");
            }
        }
        self.arrived = arrived;
        self.requests.push(Request::Velocity {
            v: cmd.v_mps,
            w: cmd.omega_rps,
        });
    }
}

impl Drop for EmitterPipeline {
    /// The run's counters and the last estimate, once, when the daemon (or a replay) ends.
    fn drop(&mut self) {
        let c = self.counters();
        let (x, y) = self.estimate().map_or((f64::NAN, f64::NAN), |p| (p.x, p.y));
        tracing::info!(
            steps = c.steps,
            updates = c.updates,
            incomplete = c.incomplete,
            unanswered = c.unanswered,
            censored = c.censored,
            scans = c.scans,
            arrivals = c.arrivals,
            bumps = c.bumps,
            rejected_rss = self.homing.rejected_rss(),
            filter_restarts = self.homing.reinitialisations(),
            emitter_x = x,
            emitter_y = y,
            "emitter pipeline summary"
        );
    }
}

impl Pipeline for EmitterPipeline {
    fn scene(&self) -> Option<crate::pipeline::Scene> {
        let particles = self
            .homing
            .particles()
            .iter()
            .map(|p| [p.position.x, p.position.y, 0.0, p.weight])
            .collect();
        Some(crate::pipeline::Scene {
            particles,
            ..crate::pipeline::Scene::default()
        })
    }

    fn name(&self) -> &'static str {
        "emitter"
    }

    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        match event {
            DeviceEvent::Odometry { t, .. } => {
                let mut estimate = self.dead_reckoning.handle(event)?;
                let pose = self.start.compose(&estimate.pose);
                estimate.pose = pose;
                estimate.source = "emitter".into();
                self.pose = Some(pose);
                if let Some(beams) = self.pending_scan.take() {
                    self.homing.observe_scan(&pose, beams);
                }
                let due = *self.next_control.get_or_insert(*t);
                // A microsecond of slack: odometry stamped on a 0.1 s grid must not miss a
                // 0.2 s step to rounding (0.1·48 vs 0.2·24).
                if *t + 1e-6 >= due {
                    // Whole periods from the first step, so the cadence does not drift.
                    let behind = ((*t + 1e-6 - due) / self.control_period_s).floor() + 1.0;
                    self.next_control = Some(due + behind * self.control_period_s);
                    self.control_step(*t, pose);
                }
                Some(estimate)
            }
            DeviceEvent::EmitterRss {
                t, antenna, dbm, ..
            } => {
                let heard = dbm.filter(|v| v.is_finite());
                if heard.is_none() {
                    self.counters.unanswered += 1;
                }
                if let Some(r) = self.readings.get_mut(slot(*antenna)) {
                    *r = Some((*t, heard));
                }
                None
            }
            DeviceEvent::RangeScan { beams, .. } => {
                // Integrated at the next odometry pose: at most one SIP period (0.1 s) after
                // the scan, as close as the previous one and never before the control step
                // that follows it. A newer scan replaces one still waiting.
                self.pending_scan = Some(beams.clone());
                self.counters.scans += 1;
                None
            }
            DeviceEvent::Bumpers { front, rear, .. } => {
                self.bumpers = Bumpers {
                    front: *front,
                    rear: *rear,
                };
                if *front || *rear {
                    self.counters.bumps += 1;
                    tracing::info!(front, rear, bumps = self.counters.bumps, "bumper contact");
                }
                None
            }
            DeviceEvent::WheelStall { .. }
            | DeviceEvent::HfTag { .. }
            | DeviceEvent::UhfSnapshot { .. }
            | DeviceEvent::Sweep { .. }
            | DeviceEvent::Mark { .. }
            | DeviceEvent::Status { .. } => None,
        }
    }

    fn take_requests(&mut self) -> Vec<Request> {
        std::mem::take(&mut self.requests)
    }

    fn take_targets(&mut self) -> Vec<TargetEstimate> {
        std::mem::take(&mut self.targets)
    }

    fn drives_to_goals(&self) -> bool {
        true
    }

    /// A goal takes the emitter's place as the navigator's target (the navigator stops on its
    /// own at `arrival_distance_m`, the pipeline within 0.8 of the goal's tolerance); `None`
    /// holds the robot still. The emitter is still tracked meanwhile.
    fn set_goal(&mut self, goal: Option<Goal>) -> bool {
        self.fleet = goal.map_or(FleetDrive::Hold, FleetDrive::Goal);
        self.homing
            .set_goal(goal.map(|g| rfloc_emitter::Point2::new(g.x, g.y)));
        if goal.is_none() {
            self.requests.push(Request::Velocity { v: 0.0, w: 0.0 });
        }
        true
    }

    /// The start becomes what makes the current odometry come out at `pose`.
    fn init_position(&mut self, pose: Pose2) -> InitOutcome {
        // start ⊕ odometry = the pose published last; the new start keeps that odometry.
        let odometry = self
            .pose
            .map_or_else(Pose2::default, |p| p.relative_to(&self.start));
        self.start = pose.compose(&Pose2::default().relative_to(&odometry));
        self.pose = Some(pose);
        InitOutcome::Done
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic)]
mod tests {
    use super::*;
    use rfloc_emitter::ScanBeam;

    fn settings() -> EmitterSettings {
        toml::from_str("a1_dbm_at_1m = -45.0\nparticles = 200\n").unwrap()
    }

    fn odometry(t: f64, x: f64) -> DeviceEvent {
        DeviceEvent::Odometry {
            device: "base".into(),
            t,
            pose: Pose2::new(x, 0.0, 0.0),
            v: 0.0,
            w: 0.0,
        }
    }

    fn rss(t: f64, antenna: AntennaSide, dbm: f64) -> DeviceEvent {
        DeviceEvent::EmitterRss {
            device: format!("{antenna:?}"),
            t,
            antenna,
            dbm: Some(dbm),
        }
    }

    /// The four readings of an emitter `d` metres straight ahead (free-space A2 = 2, A1 =
    /// −45 dBm): the front antenna hears it best, the back worst, left and right alike.
    fn ahead(t: f64, d: f64) -> Vec<DeviceEvent> {
        let level = -45.0 - 20.0 * d.log10();
        vec![
            rss(t, AntennaSide::Front, level + 5.0),
            rss(t, AntennaSide::Left, level - 2.0),
            rss(t, AntennaSide::Back, level - 10.0),
            rss(t, AntennaSide::Right, level - 2.0),
        ]
    }

    #[test]
    fn four_fresh_readings_make_one_update_and_the_robot_heads_for_the_emitter() {
        let mut p = EmitterPipeline::new(&settings()).unwrap();
        let mut commands = Vec::new();
        for k in 0..50 {
            let t = f64::from(k) * 0.1;
            if k % 2 == 0 {
                for e in ahead(t, 4.0) {
                    assert!(p.handle(&e).is_none());
                }
            }
            let est = p.handle(&odometry(t, 0.0)).unwrap();
            assert_eq!(est.source, "emitter");
            commands.extend(p.take_requests());
        }
        let targets = p.take_targets();
        let c = p.counters();
        assert_eq!(
            targets.len() as u64,
            c.updates,
            "one TARGET per filter update"
        );
        let last = targets.last().unwrap();
        assert_eq!((last.id, last.source), ("emitter", "emitter"));
        assert!(
            (last.time - 4.8).abs() < 1e-9 && last.cov[0] > 0.0 && last.raw.is_some(),
            "{last:?}"
        );
        assert_eq!(c.steps, 25, "one step per 0.2 s of odometry");
        assert_eq!(c.updates, 25, "every step had four fresh readings");
        let e = p.estimate().unwrap();
        assert!(e.x > 1.0 && e.y.abs() < 1.5, "emitter ahead: {e:?}");
        let Some(Request::Velocity { v, .. }) = commands.last() else {
            panic!("no command: {commands:?}");
        };
        assert!(*v > 0.0, "drives towards it: {commands:?}");
    }

    #[test]
    fn stale_or_missing_receivers_do_not_update_the_filter() {
        let mut p = EmitterPipeline::new(&settings()).unwrap();
        // Three receivers only.
        for e in ahead(0.0, 3.0).into_iter().take(3) {
            p.handle(&e);
        }
        p.handle(&odometry(0.0, 0.0));
        // All four, but one a second old.
        p.handle(&rss(0.1, AntennaSide::Front, -50.0));
        for e in ahead(1.0, 3.0).into_iter().skip(1) {
            p.handle(&e);
        }
        p.handle(&odometry(1.0, 0.0));
        p.handle(&DeviceEvent::EmitterRss {
            device: "front".into(),
            t: 1.1,
            antenna: AntennaSide::Front,
            dbm: None,
        });
        let c = p.counters();
        assert_eq!((c.steps, c.updates, c.incomplete), (2, 0, 2));
        assert_eq!(c.unanswered, 1);
        assert!(p.estimate().is_none());
    }

    #[test]
    fn receivers_that_hear_nothing_read_as_the_sensitivity_if_two_heard() {
        let mut s = settings();
        s.receiver_sensitivity_dbm = Some(-100.0);
        let mut p = EmitterPipeline::new(&s).unwrap();
        let silent = |t, antenna| DeviceEvent::EmitterRss {
            device: format!("{antenna:?}"),
            t,
            antenna,
            dbm: None,
        };
        // Two heard, two silent: one update, counted as censored.
        for e in [
            rss(0.0, AntennaSide::Front, -70.0),
            rss(0.0, AntennaSide::Left, -80.0),
            silent(0.0, AntennaSide::Back),
            silent(0.0, AntennaSide::Right),
        ] {
            p.handle(&e);
        }
        p.handle(&odometry(0.0, 0.0));
        let c = p.counters();
        assert_eq!((c.updates, c.censored, c.unanswered), (1, 1, 2));
        let est = p.estimate().unwrap();
        assert!(est.x > 0.0 && est.y > 0.0, "front-left: {est:?}");
        // One heard: no update.
        for e in [
            rss(0.2, AntennaSide::Front, -70.0),
            silent(0.2, AntennaSide::Left),
            silent(0.2, AntennaSide::Back),
            silent(0.2, AntennaSide::Right),
        ] {
            p.handle(&e);
        }
        p.handle(&odometry(0.2, 0.0));
        assert_eq!(p.counters().updates, 1);
        // Without a sensitivity every receiver must hear it.
        let mut strict = EmitterPipeline::new(&settings()).unwrap();
        for e in [
            rss(0.0, AntennaSide::Front, -70.0),
            rss(0.0, AntennaSide::Left, -80.0),
            rss(0.0, AntennaSide::Back, -85.0),
            silent(0.0, AntennaSide::Right),
        ] {
            strict.handle(&e);
        }
        strict.handle(&odometry(0.0, 0.0));
        assert_eq!(strict.counters().updates, 0);
    }

    #[test]
    fn the_map_grows_for_a_far_estimate_and_arrival_needs_it_near() {
        let mut s = settings();
        s.map_side_m = 4.0;
        let mut p = EmitterPipeline::new(&s).unwrap();
        let before = p.homing().grid().width();
        // An emitter 20 m ahead, far outside the initial 4 m map.
        for k in 0..40 {
            let t = f64::from(k) * 0.1;
            if k % 2 == 0 {
                for e in ahead(t, 20.0) {
                    p.handle(&e);
                }
            }
            p.handle(&odometry(t, 0.0));
        }
        let e = p.estimate().unwrap();
        assert!(e.x > 8.0, "{e:?}");
        let g = p.homing().grid();
        assert!(g.width() > before, "the map grew: {} cells wide", g.width());
        assert!(g.world_to_cell(&e).is_some(), "the estimate is on the map");
        assert!(!p.arrived(), "no arrival 20 m from the estimate");
    }

    #[test]
    fn a_front_bumper_contact_backs_the_robot_away() {
        let mut p = EmitterPipeline::new(&settings()).unwrap();
        for e in ahead(0.0, 3.0) {
            p.handle(&e);
        }
        p.handle(&odometry(0.0, 0.0));
        let Some(Request::Velocity { v, .. }) = p.take_requests().pop() else {
            panic!("no command");
        };
        assert!(v >= 0.0, "{v}");
        let bump = |front| DeviceEvent::Bumpers {
            device: "base".into(),
            t: 0.1,
            front,
            rear: false,
        };
        p.handle(&bump(true));
        p.handle(&odometry(0.2, 0.0));
        let Some(Request::Velocity { v, .. }) = p.take_requests().pop() else {
            panic!("no command");
        };
        assert!(v < 0.0, "reverses off the contact: {v}");
        assert_eq!(p.counters().bumps, 1);
        p.handle(&bump(false));
        assert_eq!(p.counters().bumps, 1, "a release is not a contact");
    }

    #[test]
    fn the_pose_is_the_start_composed_with_odometry_and_scans_are_counted() {
        let mut s = settings();
        s.start = [1.0, 2.0, 90.0];
        let mut p = EmitterPipeline::new(&s).unwrap();
        let est = p.handle(&odometry(0.0, 0.5)).unwrap();
        assert!((est.pose.x - 1.0).abs() < 1e-9 && (est.pose.y - 2.5).abs() < 1e-9);
        let beams = vec![ScanBeam {
            angle_rad: 0.0,
            range_m: 1.0,
            max_range_m: 8.0,
        }];
        p.handle(&DeviceEvent::RangeScan {
            device: "laser".into(),
            t: 0.05,
            beams,
        });
        assert_eq!(p.counters().scans, 1);
    }

    #[test]
    fn a_fleet_goal_replaces_the_emitter_and_none_holds_the_robot() {
        let mut p = EmitterPipeline::new(&settings()).unwrap();
        assert!(p.drives_to_goals());
        p.handle(&odometry(0.0, 0.0));
        p.take_requests();
        assert!(p.set_goal(Some(Goal {
            x: 0.1,
            y: 0.0,
            tolerance_m: 0.25,
            max_speed: None
        })));
        p.handle(&odometry(0.2, 0.0));
        assert_eq!(
            p.take_requests(),
            vec![Request::Velocity { v: 0.0, w: 0.0 }],
            "already there"
        );
        p.set_goal(None);
        assert_eq!(
            p.take_requests(),
            vec![Request::Velocity { v: 0.0, w: 0.0 }]
        );
        for k in 2..6 {
            p.handle(&odometry(0.2 * f64::from(k), 0.0));
            for r in p.take_requests() {
                assert_eq!(r, Request::Velocity { v: 0.0, w: 0.0 }, "held still");
            }
        }
        assert_eq!(
            p.init_position(Pose2::new(2.0, 1.0, 0.0)),
            InitOutcome::Done
        );
        let e = p.handle(&odometry(1.2, 0.5)).unwrap();
        assert!(
            (e.pose.x - 2.5).abs() < 1e-9 && (e.pose.y - 1.0).abs() < 1e-9,
            "{:?}",
            e.pose
        );
    }
}
