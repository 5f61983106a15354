//! XBee EKF-SLAM pipeline (seed 003): odometry prediction, sweep updates, waypoint driving.
//!
//! The pipeline owns the decisions and no I/O. On every odometry event it predicts, then
//! (with waypoints) runs the waypoint controller on the estimate and asks the daemon to drive
//! the base. It sweeps `start_sweeps` times before driving, from the start pose (the one pose
//! known exactly; those bearings anchor the map). After `sweep_every_s` of driving it stops the base, waits
//! until the odometry shows it standing still, and asks for one antenna sweep; the sweep's per-beacon peak RSSI
//! and bearing update the filter (known association by 64-bit address) and driving resumes.
//! A beacon not yet mapped gets bearing-only views until the filter's delayed initialisation
//! triangulates it. Without waypoints the pipeline never moves the base: it sweeps whenever
//! the base has stood still for [`PASSIVE_STILL_S`] and the last sweep is `sweep_every_s` old.

use nalgebra::Matrix3;
use rfloc_ekfslam::{
    BeaconObservation, DelayedInit, EkfSlam, EkfSlamConfig, ObservationOutcome, OdometryNoise,
    PathLoss, WaypointController, WaypointControllerConfig, WheelSlipNoise,
};
use rfloc_pose::{Pose2, PoseEstimate};

use crate::config::EkfSlamSettings;
use crate::events::{DeviceEvent, SweptBeacon};
use crate::pipeline::{Goal, InitOutcome, Pipeline, Request};

/// Standing still this long (s) lets a pipeline without waypoints sweep.
pub const PASSIVE_STILL_S: f64 = 1.0;
/// An odometry increment longer than this (m), or than [`JUMP_SPEED`] × its duration, is a
/// rebase (the base reconnected and restarted its odometry), not motion.
const JUMP_M: f64 = 0.5;
const JUMP_SPEED: f64 = 3.0;
/// Speeds below these (m/s, rad/s) count as standing still.
const STILL_V: f64 = 1e-3;
const STILL_W: f64 = 1e-3;

/// How sweep readings become filter measurements.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Measurement {
    /// Range from the path-loss model, σ in metres.
    Range { sigma_m: f64 },
    /// Peak RSSI in dB (unbiased), σ in dB.
    Rssi { sigma_db: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Following waypoints (or, without waypoints, waiting for a still base).
    Driving,
    /// Stop commanded; waiting for the odometry to show the base still.
    Stopping,
    /// Sweep requested at this time; waiting for its result.
    Sweeping { since: f64 },
    /// Last waypoint reached.
    Done,
}

/// Counters of one pipeline run (logged on every sweep).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct EkfSlamCounters {
    pub sweeps: u64,
    pub failed_sweeps: u64,
    pub late_sweeps: u64,
    /// Beacon observations given to the filter.
    pub observations: u64,
    pub gate_rejections: u64,
    pub prediction_errors: u64,
    /// Odometry jumps taken as rebases (see [`JUMP_M`]).
    pub odometry_rebases: u64,
    /// Sum of the normalised innovations squared of applied updates and their degrees of
    /// freedom (their ratio is 1 for a consistent filter).
    pub nis_sum: f64,
    pub nis_dof: u64,
}

/// The EKF-SLAM pipeline.
pub struct EkfSlamPipeline {
    ekf: EkfSlam,
    controller: Option<WaypointController>,
    /// The controller's settings, for goals a fleet manager sets.
    controller_config: WaypointControllerConfig,
    measurement: Measurement,
    /// Odometry noise as wheel slip (else the filter's configured `OdometryNoise`).
    wheel_slip: Option<WheelSlipNoise>,
    /// σ_v (m/s) and σ_ω (rad/s) added to increments with wheel motion (wheel-slip model).
    velocity_noise: (f64, f64),
    bearing_floor_rad2: f64,
    sweep_every_s: f64,
    sweep_timeout_s: f64,
    phase: Phase,
    last: Option<(f64, Pose2)>,
    driven_since_sweep: f64,
    still_since: Option<f64>,
    last_sweep_end: Option<f64>,
    /// Sweeps still to take standing at the start pose before driving.
    start_sweeps_left: u32,
    requests: Vec<Request>,
    counters: EkfSlamCounters,
}

impl EkfSlamPipeline {
    /// Builds the filter and controller from validated settings.
    pub fn new(s: &EkfSlamSettings) -> Result<Self, String> {
        let measurement = match s.measurement.as_str() {
            "range" => Measurement::Range {
                sigma_m: s.range_sigma_m,
            },
            "rssi" => Measurement::Rssi {
                sigma_db: s.rssi_sigma_db,
            },
            other => return Err(format!("measurement {other:?} is not range or rssi")),
        };
        let config = EkfSlamConfig {
            path_loss: PathLoss {
                p_ref_dbm: s.p_ref_dbm,
                eta: s.path_loss_exponent,
            },
            odometry_noise: OdometryNoise {
                trans_per_m: s.odometry_trans_per_m,
                rot_per_rad: s.odometry_rot_per_rad,
                rot_per_m: s.odometry_rot_per_m,
                ..OdometryNoise::default()
            },
            delayed_init: DelayedInit {
                max_std_m: s.beacon_init_max_std_m,
                relax_after_views: s.beacon_init_relax_after_views,
                max_relative_std: s.beacon_init_max_relative_std,
                delay_range_bearing: s.beacon_init_with_range,
                view_poses_in_state: s.beacon_init_pose_copies,
                ..DelayedInit::default()
            },
            ..EkfSlamConfig::default()
        };
        let start = Pose2::new(s.start[0], s.start[1], s.start[2].to_radians());
        let ekf = EkfSlam::new(config, start, Matrix3::zeros()).map_err(|e| e.to_string())?;
        let controller_config = WaypointControllerConfig {
            rho_min: s.waypoint_switch_m,
            max_speed: s.max_speed_mps,
            ..WaypointControllerConfig::default()
        };
        let controller = (!s.waypoints.is_empty()).then(|| {
            WaypointController::new(
                controller_config,
                s.waypoints.iter().map(|w| (w[0], w[1])).collect(),
            )
        });
        let floor = s.bearing_floor_deg.to_radians();
        // With waypoints, the first sweeps (`start_sweeps`) are taken before driving, from the
        // start pose.
        let controller_present = controller.is_some();
        let phase = if controller_present {
            Phase::Stopping
        } else {
            Phase::Driving
        };
        Ok(Self {
            ekf,
            controller,
            controller_config,
            measurement,
            wheel_slip: s.wheel_slip.map(|w| WheelSlipNoise {
                relative_sigma: w.relative_sigma,
                track_m: w.track_m,
                interval_s: w.interval_s,
            }),
            velocity_noise: s
                .wheel_slip
                .map_or((0.0, 0.0), |w| (w.sigma_v_mps, w.sigma_omega_rps)),
            bearing_floor_rad2: floor * floor,
            sweep_every_s: s.sweep_every_s,
            sweep_timeout_s: s.sweep_timeout_s,
            phase,
            last: None,
            driven_since_sweep: 0.0,
            still_since: None,
            last_sweep_end: None,
            start_sweeps_left: if controller_present {
                s.start_sweeps.max(1)
            } else {
                0
            },
            requests: Vec::new(),
            counters: EkfSlamCounters::default(),
        })
    }

    /// The filter (map and pose).
    #[must_use]
    pub fn filter(&self) -> &EkfSlam {
        &self.ekf
    }

    /// Counters so far.
    #[must_use]
    pub fn counters(&self) -> EkfSlamCounters {
        self.counters
    }

    /// True once the last waypoint has been reached.
    #[must_use]
    pub fn is_done(&self) -> bool {
        self.phase == Phase::Done
    }

    fn stop_base(&mut self) {
        self.requests.push(Request::Velocity { v: 0.0, w: 0.0 });
    }

    fn on_odometry(&mut self, t: f64, pose: Pose2, v: f64, w: f64) -> Option<PoseEstimate> {
        let Some((t0, p0)) = self.last.replace((t, pose)) else {
            return Some(self.ekf.pose_estimate(t));
        };
        let dt = (t - t0).max(0.0);
        // Driving time since the previous event: a sweep's standstill does not count (a
        // caller that sends no odometry during a sweep would otherwise see it in one step).
        let driven = (t - self.last_sweep_end.map_or(t0, |e| e.max(t0))).max(0.0);
        let delta = pose.relative_to(&p0);
        if delta.x.hypot(delta.y) > JUMP_M.max(JUMP_SPEED * dt) {
            self.counters.odometry_rebases += 1;
            tracing::warn!(
                jump_m = delta.x.hypot(delta.y),
                rebases = self.counters.odometry_rebases,
                "odometry jumped; taken as a rebase of the base's odometry, not as motion"
            );
            return Some(self.ekf.pose_estimate(t));
        }
        let predicted = match &self.wheel_slip {
            Some(model) => {
                let mut cov = model.increment_covariance(&delta, dt.max(driven));
                let (sv, sw) = self.velocity_noise;
                let moved = delta.x.hypot(delta.y) > 1e-9 || delta.theta.abs() > 1e-9;
                if moved && (sv > 0.0 || sw > 0.0) {
                    let d = delta.x.hypot(delta.y);
                    let (ev, ew) = ((sv * dt).powi(2), (sw * dt).powi(2));
                    cov[(0, 0)] += ev;
                    cov[(1, 1)] += ew * d * d / 4.0;
                    cov[(2, 2)] += ew;
                }
                self.ekf.predict_odometry_with_covariance(delta, cov)
            }
            None => self.ekf.predict_odometry(delta),
        };
        if let Err(e) = predicted {
            self.counters.prediction_errors += 1;
            tracing::warn!(error = %e, count = self.counters.prediction_errors, "odometry increment not used");
        }
        let still = v.abs() < STILL_V
            && w.abs() < STILL_W
            && delta.x.hypot(delta.y) < 5e-4
            && delta.theta.abs() < 1e-3;
        if still {
            self.still_since.get_or_insert(t);
        } else {
            self.still_since = None;
        }
        let pose_now = self.ekf.pose();
        match (self.phase, self.controller.as_mut()) {
            (Phase::Driving, Some(controller)) => {
                let cmd = controller.command(&pose_now, driven);
                self.driven_since_sweep += driven;
                if cmd.done {
                    tracing::info!(x = pose_now.x, y = pose_now.y, "last waypoint reached");
                    self.phase = Phase::Done;
                    self.stop_base();
                } else if self.driven_since_sweep >= self.sweep_every_s {
                    self.phase = Phase::Stopping;
                    self.stop_base();
                } else {
                    self.requests.push(Request::Velocity {
                        v: cmd.v,
                        w: cmd.omega,
                    });
                }
            }
            (Phase::Driving, None) => {
                let settled = self.still_since.is_some_and(|s| t - s >= PASSIVE_STILL_S);
                let due = self
                    .last_sweep_end
                    .is_none_or(|e| t - e >= self.sweep_every_s);
                if settled && due {
                    self.request_sweep(t, pose.theta);
                }
            }
            (Phase::Stopping, _) => {
                if still {
                    self.request_sweep(t, pose.theta);
                } else {
                    self.stop_base();
                }
            }
            (Phase::Sweeping { since }, _) => {
                if t - since > self.sweep_timeout_s {
                    self.counters.failed_sweeps += 1;
                    tracing::warn!(
                        waited_s = t - since,
                        failed = self.counters.failed_sweeps,
                        "no sweep result; resuming without it"
                    );
                    // The sweeps at the start are not retried: the device did not answer.
                    self.start_sweeps_left = 0;
                    self.resume(t);
                }
            }
            (Phase::Done, _) => {}
        }
        Some(self.ekf.pose_estimate(t))
    }

    fn request_sweep(&mut self, t: f64, heading_rad: f64) {
        self.phase = Phase::Sweeping { since: t };
        self.requests.push(Request::Sweep { heading_rad });
    }

    fn resume(&mut self, t: f64) {
        self.phase = Phase::Driving;
        self.driven_since_sweep = 0.0;
        self.last_sweep_end = Some(t);
    }

    fn observation(&self, b: &SweptBeacon) -> BeaconObservation {
        let sigma_b = (b.bearing_variance_rad2.max(0.0) + self.bearing_floor_rad2).sqrt();
        if self.ekf.beacon(b.id).is_none() && !self.ekf.config().delayed_init.delay_range_bearing {
            return BeaconObservation::bearing_only(b.id, b.bearing_rad, sigma_b);
        }
        match self.measurement {
            Measurement::Range { sigma_m } => BeaconObservation::range_bearing(
                b.id,
                self.ekf.config().path_loss.distance_for(b.peak_rssi_dbm),
                b.bearing_rad,
                sigma_m,
                sigma_b,
            ),
            Measurement::Rssi { sigma_db } => BeaconObservation::rssi_bearing(
                b.id,
                b.peak_rssi_dbm,
                b.bearing_rad,
                sigma_db,
                sigma_b,
            ),
        }
    }

    fn on_sweep(
        &mut self,
        t: f64,
        result: &Result<Vec<SweptBeacon>, String>,
    ) -> Option<PoseEstimate> {
        if !matches!(self.phase, Phase::Sweeping { .. }) {
            // Given up on, or not asked for: the robot may have moved since, so the bearings
            // no longer refer to its pose.
            self.counters.late_sweeps += 1;
            tracing::warn!(
                late = self.counters.late_sweeps,
                "sweep result outside a sweep; not used"
            );
            return None;
        }
        let now = self.last.map_or(t, |(tl, _)| tl.max(t));
        match result {
            Ok(beacons) => {
                let obs: Vec<BeaconObservation> =
                    beacons.iter().map(|b| self.observation(b)).collect();
                let outcomes = self.ekf.update(&obs);
                let mut rejected = 0;
                for o in &outcomes {
                    match o {
                        ObservationOutcome::Rejected { .. } => rejected += 1,
                        ObservationOutcome::Updated { nis, dof } => {
                            self.counters.nis_sum += nis;
                            self.counters.nis_dof += *dof as u64;
                        }
                        _ => {}
                    }
                }
                self.counters.sweeps += 1;
                self.counters.observations += obs.len() as u64;
                self.counters.gate_rejections += rejected;
                let p = self.ekf.pose();
                tracing::info!(
                    sweep = self.counters.sweeps,
                    heard = beacons.len(),
                    rejected,
                    mapped = self.ekf.beacon_count(),
                    x = p.x,
                    y = p.y,
                    theta = p.theta,
                    "sweep applied"
                );
            }
            Err(reason) => {
                self.counters.failed_sweeps += 1;
                tracing::warn!(reason = %reason, failed = self.counters.failed_sweeps, "sweep failed; resuming without it");
            }
        }
        self.start_sweeps_left = self.start_sweeps_left.saturating_sub(1);
        if self.start_sweeps_left > 0 {
            // Still at the start pose: the next sweep as soon as the odometry shows it still.
            self.phase = Phase::Stopping;
            self.last_sweep_end = Some(now);
        } else {
            self.resume(now);
        }
        Some(self.ekf.pose_estimate(now))
    }
}

impl Pipeline for EkfSlamPipeline {
    fn scene(&self) -> Option<crate::pipeline::Scene> {
        let beacons = self
            .ekf
            .beacons()
            .iter()
            .map(|b| crate::pipeline::SceneMark {
                id: format!("{:016X}", b.id),
                x: b.position.x,
                y: b.position.y,
                cov: Some([
                    b.covariance[(0, 0)],
                    b.covariance[(0, 1)],
                    b.covariance[(1, 1)],
                ]),
            })
            .collect();
        Some(crate::pipeline::Scene {
            beacons,
            ..crate::pipeline::Scene::default()
        })
    }

    fn name(&self) -> &'static str {
        "ekfslam"
    }

    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        match event {
            DeviceEvent::Odometry { t, pose, v, w, .. } => self.on_odometry(*t, *pose, *v, *w),
            DeviceEvent::Sweep { t, result, .. } => self.on_sweep(*t, result),
            DeviceEvent::HfTag { .. }
            | DeviceEvent::UhfSnapshot { .. }
            | DeviceEvent::Mark { .. }
            | DeviceEvent::WheelStall { .. }
            | DeviceEvent::Bumpers { .. }
            | DeviceEvent::EmitterRss { .. }
            | DeviceEvent::RangeScan { .. }
            | DeviceEvent::Status { .. } => None,
        }
    }

    fn take_requests(&mut self) -> Vec<Request> {
        std::mem::take(&mut self.requests)
    }

    fn drives_to_goals(&self) -> bool {
        true
    }

    /// A goal replaces the waypoints with one, driven like them (sweeps included) until the
    /// estimate is inside the goal's tolerance (and the switching distance); `None` stops the
    /// base and leaves the pipeline sweeping whenever the base stands still.
    fn set_goal(&mut self, goal: Option<Goal>) -> bool {
        match goal {
            Some(g) => {
                let mut config = self.controller_config;
                config.rho_min = config.rho_min.min(0.8 * g.tolerance_m);
                if let Some(limit) = g.max_speed.filter(|v| v.is_finite() && *v > 0.0) {
                    config.max_speed = config.max_speed.min(limit);
                    config.min_speed = config.min_speed.min(config.max_speed);
                }
                self.controller = Some(WaypointController::new(config, vec![(g.x, g.y)]));
                if self.phase == Phase::Done {
                    self.phase = Phase::Driving;
                }
            }
            None => {
                self.controller = None;
                if matches!(self.phase, Phase::Done | Phase::Stopping) {
                    self.phase = Phase::Driving;
                }
                self.stop_base();
            }
        }
        true
    }

    /// A new start while nothing is mapped yet (the filter is rebuilt around it); refused once
    /// beacons are in the map, whose positions are relative to the pose the filter holds.
    fn init_position(&mut self, pose: Pose2) -> InitOutcome {
        if self.ekf.beacon_count() > 0
            || self.ekf.view_pose_count() > 0
            || !self.ekf.pending_beacons().is_empty()
        {
            return InitOutcome::Refused(
                "EKF-SLAM has mapped beacons relative to its pose; its position cannot be reset"
                    .into(),
            );
        }
        match EkfSlam::new(*self.ekf.config(), pose, Matrix3::zeros()) {
            Ok(ekf) => {
                self.ekf = ekf;
                tracing::info!(
                    x = pose.x,
                    y = pose.y,
                    theta = pose.theta,
                    "start position set"
                );
                InitOutcome::Done
            }
            Err(e) => InitOutcome::Refused(e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfloc_pose::EstimateMode;

    fn settings(waypoints: Vec<[f64; 2]>) -> EkfSlamSettings {
        let mut s: EkfSlamSettings = toml::from_str("").unwrap();
        assert_eq!(
            format!("{s:?}"),
            format!("{:?}", EkfSlamSettings::default()),
            "the serde defaults and Default agree"
        );
        s.waypoints = waypoints;
        s.sweep_every_s = 1.0;
        s
    }

    fn odo(t: f64, x: f64, y: f64, theta: f64, v: f64) -> DeviceEvent {
        DeviceEvent::Odometry {
            device: "base".into(),
            t,
            pose: Pose2::new(x, y, theta),
            v,
            w: 0.0,
        }
    }

    fn sweep(t: f64, beacons: Vec<SweptBeacon>) -> DeviceEvent {
        DeviceEvent::Sweep {
            device: "xbee".into(),
            t,
            result: Ok(beacons),
        }
    }

    /// What a perfect sweep from `pose` reports for beacons at `points`.
    fn perfect(pose: Pose2, points: &[(u64, f64, f64)], p: &PathLoss) -> Vec<SweptBeacon> {
        points
            .iter()
            .map(|&(id, x, y)| {
                let (dx, dy) = (x - pose.x, y - pose.y);
                SweptBeacon {
                    id,
                    peak_rssi_dbm: p.rssi_at(dx.hypot(dy)),
                    bearing_rad: rfloc_pose::angle_diff(dy.atan2(dx), pose.theta),
                    bearing_variance_rad2: 1e-4,
                }
            })
            .collect()
    }

    #[test]
    fn drives_stops_sweeps_and_resumes() {
        let mut p = EkfSlamPipeline::new(&settings(vec![[5.0, 0.0]])).unwrap();
        assert!(p.handle(&odo(0.0, 0.0, 0.0, 0.0, 0.0)).is_some());
        // Standing at the start: the first sweep comes before driving, from the start pose
        // (its bearings anchor the map to the one pose known exactly).
        p.handle(&odo(0.1, 0.0, 0.0, 0.0, 0.0));
        assert_eq!(
            p.take_requests().last(),
            Some(&Request::Sweep { heading_rad: 0.0 })
        );
        p.handle(&sweep(0.5, Vec::new()));
        assert_eq!(p.phase, Phase::Driving);
        assert_eq!(p.counters().sweeps, 1);
        // Driving: a forward command towards the waypoint.
        p.handle(&odo(0.6, 0.0, 0.0, 0.0, 0.0));
        let r = p.take_requests();
        assert!(
            matches!(r.as_slice(), [Request::Velocity { v, .. }] if *v > 0.0),
            "{r:?}"
        );
        // After sweep_every_s of driving: stop.
        let mut x = 0.0;
        let mut t = 0.6;
        while p.phase == Phase::Driving {
            t += 0.1;
            x += 0.03;
            p.handle(&odo(t, x, 0.0, 0.0, 0.3));
        }
        assert_eq!(p.phase, Phase::Stopping);
        assert!((1.5..1.8).contains(&t), "{t}");
        assert_eq!(
            p.take_requests().last(),
            Some(&Request::Velocity { v: 0.0, w: 0.0 })
        );
        // Still moving: keep stopping; standing: sweep.
        t += 0.1;
        x += 0.01;
        p.handle(&odo(t, x, 0.0, 0.0, 0.1));
        assert_eq!(p.phase, Phase::Stopping);
        p.take_requests();
        t += 0.1;
        p.handle(&odo(t, x, 0.0, 0.0, 0.0));
        assert_eq!(p.take_requests(), vec![Request::Sweep { heading_rad: 0.0 }]);
        assert!(matches!(p.phase, Phase::Sweeping { .. }));
        // The result comes back: driving resumes and the filter has views.
        let est = p.handle(&sweep(t + 2.0, Vec::new())).unwrap();
        assert_eq!(est.mode, EstimateMode::Degraded, "no beacon, no fix");
        assert_eq!(p.phase, Phase::Driving);
        assert_eq!(p.counters().sweeps, 2);
    }

    #[test]
    fn takes_the_start_sweeps_standing_then_drives() {
        let mut s = settings(vec![[5.0, 0.0]]);
        s.start_sweeps = 3;
        let mut p = EkfSlamPipeline::new(&s).unwrap();
        p.handle(&odo(0.0, 0.0, 0.0, 0.0, 0.0));
        let mut t = 0.0;
        for k in 1..=3u64 {
            t += 0.1;
            p.handle(&odo(t, 0.0, 0.0, 0.0, 0.0));
            assert_eq!(
                p.take_requests(),
                vec![Request::Sweep { heading_rad: 0.0 }],
                "start sweep {k}"
            );
            t += 2.0;
            p.handle(&sweep(t, Vec::new()));
            assert_eq!(p.counters().sweeps, k);
            let expected = if k < 3 {
                Phase::Stopping
            } else {
                Phase::Driving
            };
            assert_eq!(p.phase, expected, "after start sweep {k}");
        }
        // Driving now: a forward command, no fourth sweep.
        t += 0.1;
        p.handle(&odo(t, 0.0, 0.0, 0.0, 0.0));
        let r = p.take_requests();
        assert!(
            matches!(r.as_slice(), [Request::Velocity { v, .. }] if *v > 0.0),
            "{r:?}"
        );
    }

    #[test]
    fn a_start_sweep_that_times_out_ends_the_start_sweeps() {
        let mut s = settings(vec![[5.0, 0.0]]);
        s.start_sweeps = 4;
        s.sweep_timeout_s = 1.0;
        let mut p = EkfSlamPipeline::new(&s).unwrap();
        p.handle(&odo(0.0, 0.0, 0.0, 0.0, 0.0));
        p.handle(&odo(0.1, 0.0, 0.0, 0.0, 0.0));
        assert_eq!(p.take_requests(), vec![Request::Sweep { heading_rad: 0.0 }]);
        // No result within the timeout: driving resumes and stays resumed after the next
        // regular sweep.
        p.handle(&odo(1.5, 0.0, 0.0, 0.0, 0.0));
        assert_eq!(p.phase, Phase::Driving);
        assert_eq!(p.counters().failed_sweeps, 1);
        assert_eq!(p.start_sweeps_left, 0);
    }

    #[test]
    fn without_waypoints_there_are_no_start_sweeps() {
        let mut s = settings(Vec::new());
        s.start_sweeps = 5;
        let p = EkfSlamPipeline::new(&s).unwrap();
        assert_eq!(p.start_sweeps_left, 0);
        assert_eq!(p.phase, Phase::Driving);
    }

    #[test]
    fn sweeps_map_beacons_and_correct_the_pose() {
        let beacons = [(1u64, 2.0, 3.0), (2, 4.0, -2.0), (3, -1.0, -3.0)];
        let mut p = EkfSlamPipeline::new(&settings(Vec::new())).unwrap();
        let path_loss = p.filter().config().path_loss;
        // A passive robot moved by someone else: still at several spots, each long enough.
        let spots = [
            (0.0, 0.0),
            (1.0, 0.0),
            (2.0, 0.5),
            (2.0, 1.5),
            (1.0, 2.0),
            (0.0, 1.0),
            (-1.0, 0.0),
            (0.5, -1.5),
        ];
        let mut t = 0.0;
        let mut at: (f64, f64) = spots[0];
        for (k, &(x, y)) in spots.iter().enumerate() {
            // Driven (not teleported) to the spot: 0.1 m per 0.1 s at most.
            let steps = ((x - at.0).hypot(y - at.1) / 0.1).ceil() as usize;
            for i in 1..=steps {
                let f = i as f64 / steps as f64;
                t += 0.1;
                p.handle(&odo(
                    t,
                    at.0 + f * (x - at.0),
                    at.1 + f * (y - at.1),
                    0.0,
                    1.0,
                ));
            }
            at = (x, y);
            for _ in 0..15 {
                t += 0.1;
                p.handle(&odo(t, x, y, 0.0, 0.0));
            }
            let asked = p.take_requests();
            assert_eq!(asked, vec![Request::Sweep { heading_rad: 0.0 }], "spot {k}");
            p.handle(&sweep(
                t,
                perfect(Pose2::new(x, y, 0.0), &beacons, &path_loss),
            ));
            assert!(p.take_requests().is_empty());
        }
        assert_eq!(p.filter().beacon_count(), 3);
        for (id, x, y) in beacons {
            let b = p.filter().beacon(id).unwrap();
            let e = (b.position.x - x).hypot(b.position.y - y);
            assert!(e < 0.05, "beacon {id} off by {e} m");
        }
        let est = p.handle(&odo(t + 0.1, 0.5, -1.5, 0.0, 0.0)).unwrap();
        assert_eq!(est.mode, EstimateMode::Fix);
        assert!(
            (est.pose.x - 0.5).abs() < 0.05 && (est.pose.y + 1.5).abs() < 0.05,
            "{:?}",
            est.pose
        );
    }

    #[test]
    fn a_lost_sweep_times_out_and_a_late_one_is_ignored() {
        let mut s = settings(vec![[5.0, 0.0]]);
        s.sweep_timeout_s = 2.0;
        let mut p = EkfSlamPipeline::new(&s).unwrap();
        p.handle(&odo(0.0, 0.0, 0.0, 0.0, 0.0));
        p.phase = Phase::Stopping;
        p.handle(&odo(0.1, 0.0, 0.0, 0.0, 0.0));
        assert!(matches!(p.phase, Phase::Sweeping { .. }));
        p.handle(&odo(2.0, 0.0, 0.0, 0.0, 0.0));
        assert!(matches!(p.phase, Phase::Sweeping { .. }));
        p.handle(&odo(2.2, 0.0, 0.0, 0.0, 0.0));
        assert_eq!(p.phase, Phase::Driving);
        assert_eq!(p.counters().failed_sweeps, 1);
        assert!(p.handle(&sweep(2.3, Vec::new())).is_none());
        assert_eq!(p.counters().late_sweeps, 1);
        // A failed sweep resumes driving too.
        p.phase = Phase::Sweeping { since: 2.3 };
        let failed = DeviceEvent::Sweep {
            device: "xbee".into(),
            t: 2.4,
            result: Err("probe failed".into()),
        };
        assert!(p.handle(&failed).is_some());
        assert_eq!(p.phase, Phase::Driving);
        assert_eq!(p.counters().failed_sweeps, 2);
    }

    #[test]
    fn an_odometry_rebase_does_not_move_the_estimate() {
        let mut p = EkfSlamPipeline::new(&settings(Vec::new())).unwrap();
        p.handle(&odo(0.0, 5.0, 3.0, 0.5, 0.0));
        let before = p.handle(&odo(0.1, 5.01, 3.0, 0.5, 0.1)).unwrap().pose;
        // The base reconnected: its odometry restarts at zero.
        let after = p.handle(&odo(0.2, 0.0, 0.0, 0.0, 0.1)).unwrap().pose;
        assert_eq!(before, after);
        assert_eq!(p.counters().odometry_rebases, 1);
        // Motion continues from the new origin.
        let moved = p.handle(&odo(0.3, 0.02, 0.0, 0.0, 0.1)).unwrap().pose;
        assert!((moved.distance(&after) - 0.02).abs() < 1e-9);
    }

    #[test]
    fn reaching_the_last_waypoint_stops_the_base() {
        let mut s = settings(vec![[0.1, 0.0]]);
        s.sweep_every_s = 100.0;
        let mut p = EkfSlamPipeline::new(&s).unwrap();
        p.handle(&odo(0.0, 0.0, 0.0, 0.0, 0.0));
        // The start's sweep first.
        p.handle(&odo(0.1, 0.0, 0.0, 0.0, 0.0));
        assert!(matches!(p.phase, Phase::Sweeping { .. }));
        p.take_requests();
        p.handle(&sweep(0.5, Vec::new()));
        p.handle(&odo(0.6, 0.0, 0.0, 0.0, 0.0));
        assert!(p.is_done(), "inside ρ_min of the only waypoint");
        assert_eq!(
            p.take_requests(),
            vec![Request::Velocity { v: 0.0, w: 0.0 }]
        );
        p.handle(&odo(0.7, 0.0, 0.0, 0.0, 0.0));
        assert!(p.take_requests().is_empty());
    }

    #[test]
    fn a_fleet_goal_is_driven_to_and_taken_away() {
        let mut s = settings(Vec::new());
        s.sweep_every_s = 100.0;
        let mut p = EkfSlamPipeline::new(&s).unwrap();
        assert!(p.drives_to_goals());
        assert_eq!(
            p.init_position(Pose2::new(1.0, 0.0, 0.0)),
            InitOutcome::Done
        );
        assert!(p.set_goal(Some(Goal {
            x: 3.0,
            y: 0.0,
            tolerance_m: 0.25,
            max_speed: Some(0.1)
        })));
        p.handle(&odo(0.0, 0.0, 0.0, 0.0, 0.0));
        p.handle(&odo(0.1, 0.0, 0.0, 0.0, 0.0));
        let r = p.take_requests();
        assert!(
            matches!(r.as_slice(), [Request::Velocity { v, .. }] if *v > 0.0 && *v <= 0.1),
            "{r:?}"
        );
        // Driven there in small steps: done, stopped within 0.8 of the tolerance (0.2 m).
        let (mut t, mut x) = (0.1, 0.0);
        let mut last = Vec::new();
        while !p.is_done() && t < 100.0 {
            t += 0.1;
            x += 0.01;
            p.handle(&odo(t, x, 0.0, 0.0, 0.1));
            last = p.take_requests();
        }
        assert!(p.is_done());
        assert!(
            (1.0 + x - 3.0).abs() <= 0.2 + 0.011,
            "stopped at {}",
            1.0 + x
        );
        assert_eq!(last, vec![Request::Velocity { v: 0.0, w: 0.0 }]);
        // A new goal drives again; taking it away stops the base.
        p.set_goal(Some(Goal {
            x: 0.0,
            y: 0.0,
            tolerance_m: 0.25,
            max_speed: None,
        }));
        p.handle(&odo(t + 0.1, x, 0.0, 0.0, 0.0));
        assert!(!p.is_done());
        p.take_requests();
        p.set_goal(None);
        assert_eq!(
            p.take_requests(),
            vec![Request::Velocity { v: 0.0, w: 0.0 }]
        );
    }
}
