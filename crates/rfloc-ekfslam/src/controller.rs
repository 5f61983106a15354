//! Waypoint following as in the XBee EKF-SLAM reference (seed 003 §2.4): a P-controller on the
//! heading error with a saturated rate of change of the turn command, a speed law that slows
//! down near the active waypoint, and switching to the next waypoint once within `rho_min`.
//! The reference's fuzzy speed controller is replaced by a documented closed-form law.

use rfloc_pose::{angle_diff, Pose2};
use serde::{Deserialize, Serialize};

/// Controller parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WaypointControllerConfig {
    /// Proportional gain from heading error (rad) to turn rate (rad/s), 1/s.
    pub k_heading: f64,
    /// Largest turn-rate command, rad/s (the reference's γ_max).
    pub max_turn_rate: f64,
    /// Largest change of the turn-rate command per second, rad/s² (the reference's Υ_max).
    pub max_turn_accel: f64,
    /// Cruise speed, m/s.
    pub max_speed: f64,
    /// Speed floor while a waypoint is active and the robot faces it, m/s.
    pub min_speed: f64,
    /// Distance (m) below which the speed falls linearly towards `min_speed`.
    pub slow_radius: f64,
    /// Switching distance ρ_min, m.
    pub rho_min: f64,
    /// Heading error (rad) beyond which the robot turns on the spot (speed 0).
    pub turn_in_place_above: f64,
}

impl Default for WaypointControllerConfig {
    fn default() -> Self {
        Self {
            k_heading: 1.5,
            max_turn_rate: 0.8,
            max_turn_accel: 2.0,
            max_speed: 0.3,
            min_speed: 0.05,
            slow_radius: 1.0,
            rho_min: 0.2,
            turn_in_place_above: 1.2,
        }
    }
}

/// A command for the base.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlCommand {
    /// Forward speed, m/s.
    pub v: f64,
    /// Turn rate, rad/s (counter-clockwise positive).
    pub omega: f64,
    /// Index of the waypoint being driven to; `None` once done.
    pub active_waypoint: Option<usize>,
    /// True once the last waypoint has been reached (then `v = ω = 0`).
    pub done: bool,
}

/// Pure waypoint follower: feed it the current pose estimate and the time since the previous
/// call; it returns the command. It keeps only the active index and the previous turn command.
#[derive(Debug, Clone, PartialEq)]
pub struct WaypointController {
    config: WaypointControllerConfig,
    waypoints: Vec<(f64, f64)>,
    active: usize,
    last_omega: f64,
}

impl WaypointController {
    /// A controller over `waypoints` (m, map frame), visited in order.
    #[must_use]
    pub fn new(config: WaypointControllerConfig, waypoints: Vec<(f64, f64)>) -> Self {
        Self {
            config,
            waypoints,
            active: 0,
            last_omega: 0.0,
        }
    }

    /// Index of the active waypoint, `None` when done.
    #[must_use]
    pub fn active_waypoint(&self) -> Option<usize> {
        (self.active < self.waypoints.len()).then_some(self.active)
    }

    /// True when all waypoints have been reached.
    #[must_use]
    pub fn is_done(&self) -> bool {
        self.active >= self.waypoints.len()
    }

    /// Computes the command for the estimate `pose`, `dt` seconds after the previous call.
    /// Non-finite input gives a stop command without changing the controller's state.
    pub fn command(&mut self, pose: &Pose2, dt: f64) -> ControlCommand {
        let c = self.config;
        let stop = |active| ControlCommand {
            v: 0.0,
            omega: 0.0,
            active_waypoint: active,
            done: false,
        };
        if !(pose.is_finite() && dt.is_finite() && dt >= 0.0) {
            return stop(self.active_waypoint());
        }
        // Switch waypoints while within rho_min (possibly several at once).
        let mut target = None;
        while let Some(&(wx, wy)) = self.waypoints.get(self.active) {
            let rho = (wx - pose.x).hypot(wy - pose.y);
            if rho <= c.rho_min {
                self.active += 1;
                continue;
            }
            target = Some((wx, wy, rho));
            break;
        }
        let Some((wx, wy, rho)) = target else {
            self.last_omega = 0.0;
            return ControlCommand {
                v: 0.0,
                omega: 0.0,
                active_waypoint: None,
                done: true,
            };
        };
        let err = angle_diff((wy - pose.y).atan2(wx - pose.x), pose.theta);
        let wanted = c.k_heading * err;
        let max_step = c.max_turn_accel * dt;
        let step = (wanted - self.last_omega).clamp(-max_step, max_step);
        let omega = (self.last_omega + step).clamp(-c.max_turn_rate, c.max_turn_rate);
        self.last_omega = omega;
        let v = if err.abs() > c.turn_in_place_above {
            0.0
        } else {
            let radial = (rho / c.slow_radius).min(1.0);
            let base = c.min_speed + (c.max_speed - c.min_speed) * radial;
            base * err.cos().max(0.0)
        };
        ControlCommand {
            v,
            omega,
            active_waypoint: Some(self.active),
            done: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turn_command_is_rate_limited_and_saturated() {
        let cfg = WaypointControllerConfig {
            max_turn_accel: 1.0,
            max_turn_rate: 0.5,
            ..Default::default()
        };
        let mut c = WaypointController::new(cfg, vec![(0.0, 5.0)]);
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let a = c.command(&pose, 0.1);
        assert!(
            (a.omega - 0.1).abs() < 1e-12,
            "first step limited to accel·dt: {}",
            a.omega
        );
        let mut last = a;
        for _ in 0..20 {
            last = c.command(&pose, 0.1);
        }
        assert!(
            (last.omega - 0.5).abs() < 1e-12,
            "saturates at max_turn_rate: {}",
            last.omega
        );
        assert_eq!(last.v, 0.0, "90° off: turns on the spot");
    }

    #[test]
    fn switches_at_rho_min_and_reports_done() {
        let mut c = WaypointController::new(
            WaypointControllerConfig::default(),
            vec![(1.0, 0.0), (2.0, 0.0)],
        );
        let a = c.command(&Pose2::new(0.0, 0.0, 0.0), 0.1);
        assert_eq!(a.active_waypoint, Some(0));
        assert!(a.v > 0.0 && a.omega.abs() < 1e-12);
        let b = c.command(&Pose2::new(0.85, 0.0, 0.0), 0.1);
        assert_eq!(b.active_waypoint, Some(1));
        let d = c.command(&Pose2::new(1.9, 0.0, 0.0), 0.1);
        assert!(d.done && d.v == 0.0 && d.active_waypoint.is_none());
        assert!(c.is_done());
    }

    #[test]
    fn slows_down_near_waypoint() {
        let cfg = WaypointControllerConfig::default();
        let mut far = WaypointController::new(cfg, vec![(5.0, 0.0)]);
        let mut near = WaypointController::new(cfg, vec![(0.5, 0.0)]);
        let p = Pose2::new(0.0, 0.0, 0.0);
        let vf = far.command(&p, 0.1).v;
        let vn = near.command(&p, 0.1).v;
        assert!((vf - cfg.max_speed).abs() < 1e-12);
        assert!(vn < vf && vn >= cfg.min_speed, "{vn} vs {vf}");
    }

    #[test]
    fn non_finite_pose_gives_stop() {
        let mut c = WaypointController::new(WaypointControllerConfig::default(), vec![(1.0, 1.0)]);
        let cmd = c.command(
            &Pose2 {
                x: f64::NAN,
                y: 0.0,
                theta: 0.0,
            },
            0.1,
        );
        assert_eq!((cmd.v, cmd.omega), (0.0, 0.0));
        assert_eq!(cmd.active_waypoint, Some(0));
    }
}
