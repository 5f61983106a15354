//! Differential-drive robot: exact unicycle integration, wheel-speed conversion, seeded
//! odometry noise and slip, and collision against the world's walls with a bumper flag.
//!
//! Defaults are the Pioneer 3-DX numbers of seed 003 Table 3.1: axle track ℓ = 0.331 m,
//! wheel diameter d = 0.195 m, σ_v = 0.0119 m/s, σ_ω = 0.0012 rad/s. The robot body is a
//! disk of radius 0.20 m (seed 001: "the robot is 40 cm in diameter").

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

use crate::geometry::Point;
use crate::noise::gaussian;
use crate::world::World;

/// Integrates the unicycle `ẋ = v cos θ, ẏ = v sin θ, θ̇ = ω` exactly over `dt` (the robot
/// follows a circular arc of radius `v/ω`; a straight line when `ω ≈ 0`).
#[must_use]
pub fn integrate_unicycle(pose: &Pose2, v: f64, omega: f64, dt: f64) -> Pose2 {
    let dtheta = omega * dt;
    if dtheta.abs() < 1e-9 {
        let mid = pose.theta + 0.5 * dtheta;
        return Pose2::new(
            pose.x + v * dt * mid.cos(),
            pose.y + v * dt * mid.sin(),
            pose.theta + dtheta,
        );
    }
    let r = v / omega;
    let th1 = pose.theta + dtheta;
    Pose2::new(
        pose.x + r * (th1.sin() - pose.theta.sin()),
        pose.y - r * (th1.cos() - pose.theta.cos()),
        th1,
    )
}

/// Body geometry and noise of a differential-drive base.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiffDriveParams {
    /// Distance between the wheels, metres (ℓ, seed 003 Table 3.1).
    pub axle_track: f64,
    /// Wheel diameter, metres (d, seed 003 Table 3.1).
    pub wheel_diameter: f64,
    /// Radius of the body disk used for collision, metres.
    pub body_radius: f64,
    /// σ of additive noise on the executed linear speed, m/s (σ_v, seed 003 Table 3.1).
    pub sigma_v: f64,
    /// σ of additive noise on the executed turn rate, rad/s (σ_ω, seed 003 Table 3.1).
    pub sigma_omega: f64,
    /// Mean fraction of commanded wheel travel lost to slip (0 = none).
    pub slip_mean: f64,
    /// σ of the slip fraction (drawn per step, clamped to [0, 1]).
    pub slip_sigma: f64,
    /// Maximum |v| the base executes, m/s.
    pub max_speed: f64,
    /// Maximum |ω| the base executes, rad/s.
    pub max_turn_rate: f64,
}

impl Default for DiffDriveParams {
    fn default() -> Self {
        Self {
            axle_track: 0.331,
            wheel_diameter: 0.195,
            body_radius: 0.20,
            sigma_v: 0.0119,
            sigma_omega: 0.0012,
            slip_mean: 0.0,
            slip_sigma: 0.0,
            max_speed: 1.2,
            max_turn_rate: 5.236, // 300 °/s
        }
    }
}

impl DiffDriveParams {
    /// Left and right wheel rim speeds (m/s) for a body twist.
    #[must_use]
    pub fn wheel_speeds(&self, v: f64, omega: f64) -> (f64, f64) {
        let h = 0.5 * self.axle_track;
        (v - omega * h, v + omega * h)
    }

    /// Body twist `(v, ω)` for left/right wheel rim speeds.
    #[must_use]
    pub fn twist(&self, left: f64, right: f64) -> (f64, f64) {
        (0.5 * (left + right), (right - left) / self.axle_track)
    }
}

/// Result of one simulation step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutcome {
    /// True pose after the step.
    pub truth: Pose2,
    /// Dead-reckoned pose from the wheel encoders after the step.
    pub odometry: Pose2,
    /// True when the body hit a wall or obstacle during the step (it stops at contact).
    pub bumped: bool,
    /// Executed (true) linear and angular speed over the step.
    pub executed: (f64, f64),
}

/// A simulated differential-drive robot: true pose, odometry pose and its own RNG.
#[derive(Debug, Clone)]
pub struct RobotSim {
    pub params: DiffDriveParams,
    truth: Pose2,
    odometry: Pose2,
    rng: ChaCha8Rng,
    bumped: bool,
}

impl RobotSim {
    /// A robot at `start` (odometry starts there too) with noise drawn from `seed`.
    #[must_use]
    pub fn new(params: DiffDriveParams, start: Pose2, seed: u64) -> Self {
        Self {
            params,
            truth: start,
            odometry: start,
            rng: ChaCha8Rng::seed_from_u64(seed),
            bumped: false,
        }
    }

    /// True pose.
    #[must_use]
    pub fn truth(&self) -> Pose2 {
        self.truth
    }

    /// Encoder dead-reckoning pose.
    #[must_use]
    pub fn odometry(&self) -> Pose2 {
        self.odometry
    }

    /// Whether the last step ended in contact.
    #[must_use]
    pub fn bumped(&self) -> bool {
        self.bumped
    }

    /// Applies the command `(v, ω)` for `dt` seconds.
    ///
    /// The encoders see the commanded wheel rotation (clamped to the limits); the body moves
    /// by that rotation less slip, plus Gaussian speed noise. If the body would touch a wall
    /// the motion is cut at the last collision-free fraction of the step (bisection, 1 mm
    /// resolution on a 1 m step) and the bumper flag is set; the encoders then only count
    /// the travelled fraction (the wheels stall at contact).
    pub fn step(&mut self, v_cmd: f64, omega_cmd: f64, dt: f64, world: &World) -> StepOutcome {
        let p = self.params;
        let v = if v_cmd.is_finite() {
            v_cmd.clamp(-p.max_speed, p.max_speed)
        } else {
            0.0
        };
        let w = if omega_cmd.is_finite() {
            omega_cmd.clamp(-p.max_turn_rate, p.max_turn_rate)
        } else {
            0.0
        };
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
        let slip = (p.slip_mean + gaussian(&mut self.rng, p.slip_sigma)).clamp(0.0, 1.0);
        let v_true = v * (1.0 - slip) + gaussian(&mut self.rng, p.sigma_v);
        let w_true = w * (1.0 - slip) + gaussian(&mut self.rng, p.sigma_omega);

        let start = self.truth;
        let blocked = |f: f64| {
            let q = integrate_unicycle(&start, v_true, w_true, dt * f);
            world.disk_collides(&Point::new(q.x, q.y), p.body_radius)
        };
        let clearance = |q: &Pose2| {
            let c = Point::new(q.x, q.y);
            world
                .walls
                .iter()
                .map(|s| s.distance_to_point(&c))
                .fold(f64::INFINITY, f64::min)
        };
        let (fraction, bumped) = if !blocked(1.0) {
            (1.0, false)
        } else if blocked(0.0) {
            // Already in contact: only a move that does not reduce the clearance is executed.
            let probe = integrate_unicycle(&start, v_true, w_true, dt);
            if clearance(&probe) >= clearance(&start) {
                (1.0, false)
            } else {
                (0.0, true)
            }
        } else {
            // Bisection for the last collision-free fraction of the step.
            let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
            for _ in 0..12 {
                let mid = 0.5 * (lo + hi);
                if blocked(mid) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            (lo, true)
        };
        self.bumped = bumped;
        self.truth = integrate_unicycle(&start, v_true, w_true, dt * fraction);
        self.odometry = integrate_unicycle(&self.odometry, v, w, dt * fraction);
        StepOutcome {
            truth: self.truth,
            odometry: self.odometry,
            bumped: self.bumped,
            executed: (v_true, w_true),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;
    use std::path::Path;

    fn open_world() -> World {
        World::from_toml_str(
            "[area]\nmin=[-50.0,-50.0]\nmax=[50.0,50.0]\n",
            Path::new("w"),
        )
        .unwrap()
    }

    fn noiseless() -> DiffDriveParams {
        DiffDriveParams {
            sigma_v: 0.0,
            sigma_omega: 0.0,
            ..DiffDriveParams::default()
        }
    }

    #[test]
    fn straight_line_moves_along_heading() {
        let p = integrate_unicycle(&Pose2::new(1.0, 2.0, PI / 2.0), 0.5, 0.0, 4.0);
        assert!((p.x - 1.0).abs() < 1e-12 && (p.y - 4.0).abs() < 1e-12);
    }

    #[test]
    fn pure_rotation_keeps_position() {
        let p = integrate_unicycle(&Pose2::new(1.0, 2.0, 0.0), 0.0, PI / 2.0, 1.0);
        assert!((p.x - 1.0).abs() < 1e-12 && (p.y - 2.0).abs() < 1e-12);
        assert!((p.theta - PI / 2.0).abs() < 1e-12);
    }

    #[test]
    fn arc_closes_a_circle_in_many_steps() {
        // v = 0.5 m/s, ω = 0.25 rad/s → radius 2 m, period 8π s; 1000 steps.
        let mut p = Pose2::new(0.0, 0.0, 0.0);
        let period = 2.0 * PI / 0.25;
        let n = 1000;
        let mut max_dist_from_centre_err: f64 = 0.0;
        for _ in 0..n {
            p = integrate_unicycle(&p, 0.5, 0.25, period / f64::from(n));
            let r = p.x.hypot(p.y - 2.0);
            max_dist_from_centre_err = max_dist_from_centre_err.max((r - 2.0).abs());
        }
        assert!(
            p.x.abs() < 1e-9 && p.y.abs() < 1e-9 && p.theta.abs() < 1e-9,
            "{p:?}"
        );
        assert!(max_dist_from_centre_err < 1e-9);
    }

    #[test]
    fn quarter_arc_in_one_step_is_exact() {
        let p = integrate_unicycle(&Pose2::new(0.0, 0.0, 0.0), PI / 2.0, PI / 2.0, 1.0);
        // radius 1, quarter turn left: (1, 1, π/2)
        assert!((p.x - 1.0).abs() < 1e-12 && (p.y - 1.0).abs() < 1e-12);
    }

    #[test]
    fn wheel_speed_round_trip() {
        let d = DiffDriveParams::default();
        let (l, r) = d.wheel_speeds(0.3, 0.8);
        let (v, w) = d.twist(l, r);
        assert!((v - 0.3).abs() < 1e-12 && (w - 0.8).abs() < 1e-12);
    }

    #[test]
    fn noiseless_robot_odometry_equals_truth() {
        let w = open_world();
        let mut r = RobotSim::new(noiseless(), Pose2::new(0.0, 0.0, 0.0), 1);
        for _ in 0..100 {
            r.step(0.4, 0.2, 0.1, &w);
        }
        assert_eq!(r.truth(), r.odometry());
        assert!(!r.bumped());
    }

    #[test]
    fn same_seed_same_trajectory_different_seed_differs() {
        let w = open_world();
        let run = |seed| {
            let mut r = RobotSim::new(
                DiffDriveParams {
                    slip_sigma: 0.05,
                    ..DiffDriveParams::default()
                },
                Pose2::default(),
                seed,
            );
            (0..200)
                .map(|i| {
                    r.step(0.5, if i % 50 < 25 { 0.3 } else { -0.3 }, 0.1, &w)
                        .truth
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }

    #[test]
    fn odometry_drifts_from_truth_with_noise_and_slip() {
        let w = open_world();
        let params = DiffDriveParams {
            slip_mean: 0.05,
            slip_sigma: 0.02,
            ..DiffDriveParams::default()
        };
        let mut r = RobotSim::new(params, Pose2::default(), 9);
        for _ in 0..100 {
            r.step(0.5, 0.0, 0.1, &w);
        }
        // 5 m commanded; slip of ~5 % leaves the truth ~0.25 m short of the odometry.
        let gap = r.odometry().x - r.truth().x;
        assert!(gap > 0.15 && gap < 0.35, "gap {gap}");
    }

    #[test]
    fn wall_stops_robot_and_sets_bumper() {
        let w =
            World::from_toml_str("[area]\nmin=[0.0,0.0]\nmax=[3.0,2.0]\n", Path::new("w")).unwrap();
        let mut r = RobotSim::new(noiseless(), Pose2::new(1.0, 1.0, 0.0), 1);
        let mut bumped = false;
        for _ in 0..100 {
            bumped |= r.step(0.5, 0.0, 0.1, &w).bumped;
        }
        assert!(bumped);
        // Stops with the 0.2 m body at the x = 3 wall.
        assert!((r.truth().x - 2.8).abs() < 2e-3, "{:?}", r.truth());
        // Pushing on into the wall is refused and keeps the bumper pressed.
        let stuck = r.truth();
        let out = r.step(0.5, 0.0, 0.1, &w);
        assert!(out.bumped);
        assert!(out.truth.distance(&stuck) < 1e-9);
        // Backing away is allowed.
        let out = r.step(-0.5, 0.0, 0.1, &w);
        assert!(!out.bumped && out.truth.x < 2.8);
    }
}
