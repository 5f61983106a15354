//! Driving to a goal on the UHF snapshot localiser (seed 000's navigation, as the daemon runs
//! it). No I/O: it turns published poses and odometry events into velocity requests.
//!
//! One step at a time, as the survey was driven: at rest, the next snapshot's pose picks the
//! action with the lowest cost-to-go on the lattice plan (value iteration over the surveyed
//! floor with each action's learned motion, `rfloc_snapshot::LatticePlan`), unless the cycle
//! breaker sees the robot repeating itself; the action's Table 4 command, scaled to the
//! configured drive time, is sent; after that time a stop; once the odometry shows the robot
//! still, the snapshot after the next decides again (the first may hold reads from before the
//! stop). The robot has arrived when [`CONFIDENT_STEPS`] decisions in a row saw a steady fix
//! within the goal radius; it then stays stopped. A wheel stall (the body against a wall the
//! plan did not know) stops the action at once, and the next [`STALL_TURN_STEPS`] actions
//! rotate on the spot, to the side the plan ranks better.

use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};
use rfloc_snapshot::{Action, ActionTable, CycleBreaker, LatticeConfig, LatticePlan, Survey};

use crate::pipeline::Request;

/// Decisions in a row with a steady fix near the goal before the robot counts as arrived.
pub const CONFIDENT_STEPS: usize = 3;
/// A fix is steady when it moved at most this far since the last decision, metres.
const STEADY_JUMP_M: f64 = 0.4;
/// ... and its particles' RMS distance from it is at most this, metres.
const STEADY_SPREAD_M: f64 = 0.2;
/// The robot counts as still below these speeds (m/s, rad/s), after at least this long.
const STILL_V: f64 = 1e-3;
const STILL_W: f64 = 1e-3;
const STOP_SETTLE_S: f64 = 0.2;
/// Rotations after a wheel stall (as the seed 000 trial's navigation).
pub const STALL_TURN_STEPS: usize = 6;
/// The cycle breaker's window and repeats (as the seed 000 trial).
const CYCLE_WINDOW: usize = 16;
const CYCLE_REPEATS: usize = 3;

/// What the drive is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    /// At rest; `skip` more snapshots pass before one decides.
    Deciding { skip: usize },
    /// Driving an action until this time.
    Driving { until: f64 },
    /// Stop sent at this time; waiting for the odometry to show the robot still.
    Stopping { since: f64 },
    /// Within the goal radius: stopped for good.
    Arrived,
}

/// How the goal drive is set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalSettings {
    pub goal: (f64, f64),
    /// The robot stops when a steady fix is within this distance of the goal, metres.
    pub radius_m: f64,
    /// Duration of one seed action in Table 4's units (the survey's step), seconds.
    pub action_duration_s: f64,
    /// Time the base takes to drive one action, seconds.
    pub drive_duration_s: f64,
}

/// Goal-seeking state machine.
pub struct GoalDrive {
    plan: LatticePlan,
    cycles: CycleBreaker,
    table: ActionTable,
    settings: GoalSettings,
    phase: Phase,
    confident: usize,
    last_fix: Option<Pose2>,
    requests: Vec<Request>,
    /// Rotations still to take after a stall, and their direction once chosen.
    turns_left: usize,
    turn: Option<Action>,
    /// Actions sent so far, and wheel stalls met.
    pub actions: u64,
    pub stalls: u64,
}

impl std::fmt::Debug for GoalDrive {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GoalDrive")
            .field("settings", &self.settings)
            .field("phase", &self.phase)
            .field("actions", &self.actions)
            .finish_non_exhaustive()
    }
}

impl GoalDrive {
    /// Plans to the goal over the surveyed floor with the survey's learned action motion.
    #[must_use]
    pub fn plan(survey: &Survey, settings: GoalSettings) -> Self {
        let table = ActionTable::seed_table();
        let plan = survey.lattice_plan(
            &table,
            settings.action_duration_s,
            settings.goal,
            settings.radius_m,
            LatticeConfig::default(),
        );
        tracing::info!(
            goal_x = settings.goal.0,
            goal_y = settings.goal.1,
            sweeps = plan.sweeps,
            "goal plan solved"
        );
        Self {
            plan,
            cycles: CycleBreaker::new(CYCLE_WINDOW, CYCLE_REPEATS),
            table,
            settings,
            phase: Phase::Deciding { skip: 0 },
            confident: 0,
            last_fix: None,
            requests: Vec::new(),
            turns_left: 0,
            turn: None,
            actions: 0,
            stalls: 0,
        }
    }

    /// The current phase.
    #[must_use]
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// What the drive was planned with.
    #[must_use]
    pub fn settings(&self) -> GoalSettings {
        self.settings
    }

    /// Velocity requests to route to the base, oldest first.
    pub fn take_requests(&mut self) -> Vec<Request> {
        std::mem::take(&mut self.requests)
    }

    fn stop(&mut self) {
        self.requests.push(Request::Velocity { v: 0.0, w: 0.0 });
    }

    /// An odometry event: ends a drive at its time, notices the robot still after a stop.
    pub fn on_odometry(&mut self, t: f64, v: f64, w: f64) {
        match self.phase {
            Phase::Driving { until } if t >= until => {
                self.stop();
                self.phase = Phase::Stopping { since: t };
            }
            Phase::Stopping { since }
                if t >= since + STOP_SETTLE_S && v.abs() < STILL_V && w.abs() < STILL_W =>
            {
                self.phase = Phase::Deciding { skip: 1 };
            }
            _ => {}
        }
    }

    /// The base reported a wheel stall: an action under way stops now, and the next actions
    /// turn away.
    pub fn on_stall(&mut self, t: f64) {
        if self.phase == Phase::Arrived {
            return;
        }
        self.stalls += 1;
        if matches!(self.phase, Phase::Driving { .. }) {
            self.stop();
            self.phase = Phase::Stopping { since: t };
        }
        if self.turns_left == 0 {
            self.turns_left = STALL_TURN_STEPS;
            self.turn = None;
        }
        tracing::info!(t, "wheel stall: turning away");
    }

    /// A published pose (one per snapshot): at rest, it decides the next action.
    pub fn on_estimate(&mut self, estimate: &PoseEstimate) {
        let Phase::Deciding { skip } = self.phase else {
            return;
        };
        if skip > 0 {
            self.phase = Phase::Deciding { skip: skip - 1 };
            return;
        }
        let pose = estimate.pose;
        let spread = (estimate.covariance[(0, 0)] + estimate.covariance[(1, 1)])
            .max(0.0)
            .sqrt();
        let steady = self
            .last_fix
            .is_some_and(|p| p.distance(&pose) <= STEADY_JUMP_M);
        self.last_fix = Some(pose);
        let fix = estimate.mode == EstimateMode::Fix && spread <= STEADY_SPREAD_M;
        self.confident = if fix && steady { self.confident + 1 } else { 0 };
        let (gx, gy) = self.settings.goal;
        if self.confident >= CONFIDENT_STEPS
            && (pose.x - gx).hypot(pose.y - gy) <= self.settings.radius_m
        {
            self.stop();
            self.phase = Phase::Arrived;
            tracing::info!(
                x = pose.x,
                y = pose.y,
                actions = self.actions,
                "goal reached"
            );
            return;
        }
        let ranked = self.plan.ranked(&pose);
        let (action, reason) = if self.turns_left > 0 {
            self.turns_left -= 1;
            let side = *self.turn.get_or_insert_with(|| {
                ranked
                    .iter()
                    .map(|r| r.0)
                    .find(|a| matches!(a, Action::RotateLeft | Action::RotateRight))
                    .unwrap_or(Action::RotateLeft)
            });
            (side, "wall")
        } else {
            self.cycles.choose(&pose, &ranked)
        };
        let n = self.table.nominal(action);
        let k = if self.settings.drive_duration_s > 0.0 {
            self.settings.action_duration_s / self.settings.drive_duration_s
        } else {
            1.0
        };
        self.requests.push(Request::Velocity {
            v: n.v * k,
            w: n.omega * k,
        });
        self.actions += 1;
        tracing::debug!(?action, reason, x = pose.x, y = pose.y, "goal drive step");
        self.phase = Phase::Driving {
            until: estimate.time + self.settings.drive_duration_s,
        };
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;
    use rfloc_snapshot::{Snapshot, TagId};

    /// A survey of a 2 m × 2 m floor, every pose driven forward along +x.
    fn floor() -> Survey {
        let s = Snapshot::from_reads([(TagId::new(vec![1]), 2000.0)]);
        let mut samples = Vec::new();
        for iy in 0..10 {
            for ix in 0..10 {
                for h in 0..8 {
                    let p = Pose2::new(
                        0.2 * f64::from(ix),
                        0.2 * f64::from(iy),
                        std::f64::consts::FRAC_PI_4 * f64::from(h),
                    );
                    samples.push((p, None));
                }
            }
        }
        Survey::with_actions(samples.iter().map(|(p, a)| (&s, *p, *a, false)))
    }

    /// The goal at (1.6, 1.0), stop within 0.2 m, Table 4 steps driven in 0.5 s.
    fn settings() -> GoalSettings {
        GoalSettings {
            goal: (1.6, 1.0),
            radius_m: 0.2,
            action_duration_s: 0.1,
            drive_duration_s: 0.5,
        }
    }

    fn fix(t: f64, pose: Pose2) -> PoseEstimate {
        PoseEstimate {
            time: t,
            pose,
            covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(0.001, 0.001, 0.01)),
            mode: EstimateMode::Fix,
            source: "snapshot".into(),
        }
    }

    #[test]
    fn drives_steps_stops_between_them_and_arrives() {
        let mut drive = GoalDrive::plan(&floor(), settings());
        // Far from the goal, facing it: the first decision drives (forward or an arc).
        drive.on_estimate(&fix(0.0, Pose2::new(0.2, 1.0, 0.0)));
        let r = drive.take_requests();
        let [Request::Velocity { v, .. }] = r.as_slice() else {
            panic!("{r:?}")
        };
        // Table 4's 2.5 m/s over 0.1 s, driven in 0.5 s.
        assert!((v - 0.5).abs() < 1e-9, "{v}");
        assert_eq!(drive.phase(), Phase::Driving { until: 0.5 });
        // Estimates while driving decide nothing; the drive ends on odometry time.
        drive.on_estimate(&fix(0.3, Pose2::new(0.3, 1.0, 0.0)));
        drive.on_odometry(0.4, 0.5, 0.0);
        assert!(drive.take_requests().is_empty());
        drive.on_odometry(0.5, 0.5, 0.0);
        assert_eq!(
            drive.take_requests(),
            vec![Request::Velocity { v: 0.0, w: 0.0 }]
        );
        // Still only after the settle time and at zero speed; then one snapshot is skipped.
        drive.on_odometry(0.6, 0.0, 0.0);
        assert!(matches!(drive.phase(), Phase::Stopping { .. }));
        drive.on_odometry(0.8, 0.0, 0.0);
        assert_eq!(drive.phase(), Phase::Deciding { skip: 1 });
        drive.on_estimate(&fix(0.9, Pose2::new(0.45, 1.0, 0.0)));
        assert!(drive.take_requests().is_empty());
        // At the goal: three steady fixes in a row stop it for good.
        let mut t = 1.0;
        let at_goal = Pose2::new(1.55, 1.0, 0.0);
        let mut stops = 0;
        for _ in 0..6 {
            drive.on_estimate(&fix(t, at_goal));
            for r in drive.take_requests() {
                if r == (Request::Velocity { v: 0.0, w: 0.0 }) {
                    stops += 1;
                }
            }
            if drive.phase() == Phase::Arrived {
                break;
            }
            // Finish the step it started.
            drive.on_odometry(t + 0.5, 0.0, 0.0);
            drive.take_requests();
            drive.on_odometry(t + 0.8, 0.0, 0.0);
            drive.on_estimate(&fix(t + 0.9, at_goal));
            t += 1.0;
        }
        assert_eq!(drive.phase(), Phase::Arrived, "{drive:?}");
        assert!(stops >= 1);
        drive.on_estimate(&fix(t + 5.0, Pose2::new(0.2, 1.0, 0.0)));
        assert!(drive.take_requests().is_empty(), "moved after arriving");
    }

    #[test]
    fn a_wheel_stall_stops_the_action_and_turns_away() {
        let mut drive = GoalDrive::plan(&floor(), settings());
        drive.on_estimate(&fix(0.0, Pose2::new(1.0, 1.0, 0.0)));
        assert_eq!(drive.take_requests().len(), 1);
        drive.on_stall(0.2);
        assert_eq!(
            drive.take_requests(),
            vec![Request::Velocity { v: 0.0, w: 0.0 }],
            "a stall stops the drive at once"
        );
        assert_eq!(drive.phase(), Phase::Stopping { since: 0.2 });
        let mut t = 0.2;
        let mut turns = Vec::new();
        for _ in 0..STALL_TURN_STEPS + 1 {
            drive.on_odometry(t + 0.3, 0.0, 0.0);
            drive.on_estimate(&fix(t + 0.4, Pose2::new(1.0, 1.0, 0.0)));
            drive.on_estimate(&fix(t + 0.5, Pose2::new(1.0, 1.0, 0.0)));
            turns.extend(drive.take_requests());
            drive.on_odometry(t + 1.0, 0.0, 0.0);
            drive.take_requests();
            t += 1.0;
        }
        // Six rotations on the spot to one side (Table 4's 0.25 m/s, π/2 rad/s, scaled), then
        // the plan again.
        let rotations: Vec<&Request> = turns
            .iter()
            .filter(|r| matches!(r, Request::Velocity { v, w } if (v.abs() - 0.05).abs() < 1e-9 && w.abs() > 0.3))
            .collect();
        assert_eq!(rotations.len(), STALL_TURN_STEPS, "{turns:?}");
        assert!(rotations.windows(2).all(|w| w[0] == w[1]), "{turns:?}");
        assert_eq!(drive.stalls, 1);
    }
}
