//! The daemon's data as Foxglove channels (`rfloc-viz`): live over its WebSocket protocol
//! (`[foxglove] listen`) and into MCAP files (`rfloc replay --mcap`, `rfloc record --mcap`).
//! Every message carries the measurement time of what it shows.

use rfloc_pose::{Pose2, PoseEstimate};
use rfloc_viz::{Direction, Landmark, LandmarkKind, LogLevel, Particle, Stamp, Viz};

use crate::events::{DeviceEvent, DeviceState};
use crate::pipeline::{Scene, TargetEstimate};
use crate::time::TimeOrigin;

/// Publishes what the daemon sees to a [`Viz`] hub.
#[derive(Clone)]
pub struct VizOut {
    viz: Viz,
    origin: TimeOrigin,
    /// Run-clock seconds of the last scene published (scenes go out at most twice a second).
    last_scene: f64,
}

impl VizOut {
    /// Publishes into `viz`; `origin` turns run-clock seconds into Unix time.
    #[must_use]
    pub fn new(viz: Viz, origin: TimeOrigin) -> Self {
        Self {
            viz,
            origin,
            last_scene: f64::NEG_INFINITY,
        }
    }

    fn stamp(&self, t: f64) -> Option<Stamp> {
        Stamp::from_unix_secs(self.origin.stamp(t)).ok()
    }

    /// A decoded observation (and, for a range scan, the scan).
    pub fn observation(&self, event: &DeviceEvent) {
        let Some(stamp) = event.time().and_then(|t| self.stamp(t)) else {
            return;
        };
        if self.viz.is_watched(rfloc_viz::topics::OBSERVATION) {
            let json = event.to_json();
            let kind = serde_json::from_str::<serde_json::Value>(&json)
                .ok()
                .and_then(|v| v["observation"].as_str().map(str::to_string))
                .unwrap_or_default();
            self.viz.observation(stamp, event.device(), &kind, &json);
        }
        if let DeviceEvent::RangeScan { beams, .. } = event {
            if beams.len() >= 2 && self.viz.is_watched(rfloc_viz::topics::SCAN) {
                // LaserScan wants evenly spaced beams: the first and last angles bound them.
                let (first, last) = (
                    beams.first().map_or(0.0, |b| b.angle_rad),
                    beams.last().map_or(0.0, |b| b.angle_rad),
                );
                self.viz.scan(
                    stamp,
                    &rfloc_viz::RangeScan {
                        mount: Pose2::default(),
                        start_angle: first,
                        end_angle: last,
                        ranges: beams.iter().map(|b| b.range_m).collect(),
                        intensities: Vec::new(),
                    },
                );
            }
        }
    }

    /// A published pose, with the frame tree when the robot has odometry.
    pub fn pose(&self, est: &PoseEstimate, odom: Option<&Pose2>) {
        let Some(stamp) = self.stamp(est.time) else {
            return;
        };
        self.viz.pose(stamp, est);
        if let Some(o) = odom {
            if est.mode != rfloc_pose::EstimateMode::NoFix {
                self.viz.transforms(stamp, &est.pose, o);
            }
        }
    }

    /// A target estimate.
    pub fn target(&self, t: &TargetEstimate) {
        let Some(stamp) = self.stamp(t.time) else {
            return;
        };
        self.viz.target(
            stamp,
            &rfloc_viz::TargetEstimate {
                id: t.id.to_string(),
                x: t.x,
                y: t.y,
                covariance: nalgebra::Matrix2::new(t.cov[0], t.cov[1], t.cov[1], t.cov[2]),
            },
        );
    }

    /// A pipeline's scene at run-clock time `t` (at most twice a second).
    pub fn scene(&mut self, t: f64, scene: impl FnOnce() -> Option<Scene>) {
        if t - self.last_scene < 0.5 {
            return;
        }
        let watched = [
            rfloc_viz::topics::BEACONS,
            rfloc_viz::topics::TAGS,
            rfloc_viz::topics::PARTICLES,
        ]
        .iter()
        .any(|topic| self.viz.is_watched(topic));
        let (Some(stamp), true) = (self.stamp(t), watched) else {
            return;
        };
        let Some(scene) = scene() else {
            return;
        };
        self.last_scene = t;
        let marks = |m: &[crate::pipeline::SceneMark]| -> Vec<Landmark> {
            m.iter()
                .map(|m| Landmark {
                    id: m.id.clone(),
                    x: m.x,
                    y: m.y,
                    covariance: m
                        .cov
                        .map(|c| nalgebra::Matrix2::new(c[0], c[1], c[1], c[2])),
                })
                .collect()
        };
        if !scene.beacons.is_empty() {
            self.viz
                .landmarks(stamp, LandmarkKind::Beacon, &marks(&scene.beacons));
        }
        if !scene.tags.is_empty() {
            self.viz
                .landmarks(stamp, LandmarkKind::Tag, &marks(&scene.tags));
        }
        if !scene.particles.is_empty() {
            let particles: Vec<Particle> = scene
                .particles
                .iter()
                .map(|[x, y, yaw, w]| Particle {
                    pose: Pose2::new(*x, *y, *yaw),
                    weight: *w,
                })
                .collect();
            self.viz.particles(stamp, &particles);
        }
    }

    /// A device's status change, at wall time.
    pub fn status(&self, device: &str, state: DeviceState, detail: &str) {
        let level = match state {
            DeviceState::Connected | DeviceState::Connecting => LogLevel::Info,
            DeviceState::Reconnecting | DeviceState::Stale | DeviceState::Closed => {
                LogLevel::Warning
            }
            DeviceState::Failed => LogLevel::Error,
        };
        self.viz.status(
            Stamp::from(std::time::SystemTime::now()),
            device,
            level,
            &format!("{}: {detail}", state.as_str()),
        );
    }

    /// Raw bytes of a device link at run-clock time `t`.
    pub fn link_bytes(&self, t: f64, device: &str, received: bool, bytes: &[u8]) {
        if let Some(stamp) = self.stamp(t) {
            let direction = if received {
                Direction::Rx
            } else {
                Direction::Tx
            };
            self.viz.link_bytes(stamp, device, direction, bytes);
        }
    }
}
