//! Ground truth matched to the odometry samples the driver delivers.
//!
//! The Pioneer emulator publishes its state (simulated time, true pose, its own odometry) after
//! every 100 ms tick. A sample the client decodes from a SIP carries that tick's odometry, but
//! the trial loop may read the emulator a tick later. [`TruthLog`] keeps the recent states and
//! finds the tick whose odometry equals the client's (to the SIP's quantisation), so truth and
//! estimate are compared at the same instant.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use rfloc_aria::{EmulatorHandle, EmulatorState};
use rfloc_pose::{angle_diff, Pose2};
use tokio::task::JoinHandle;

/// States kept (10 s of simulated time at the 100 ms SIP period).
const KEEP: usize = 100;
/// Metres a radian of heading difference counts as when matching odometry.
const HEADING_WEIGHT_M: f64 = 1.0;

/// One tick of the emulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthTick {
    /// Simulated seconds.
    pub sim_time: f64,
    /// True pose.
    pub truth: Pose2,
    /// The robot's own odometry at that tick.
    pub odometry: Pose2,
}

/// Recent emulator states, filled by a background task.
pub struct TruthLog {
    ticks: Arc<Mutex<VecDeque<TruthTick>>>,
    robot: EmulatorHandle,
    task: JoinHandle<()>,
}

/// Appends a state, replacing the last one when it is the same tick.
fn push(q: &mut VecDeque<TruthTick>, s: TruthTick) {
    match q.back_mut() {
        Some(last) if last.sim_time == s.sim_time => *last = s,
        Some(last) if last.sim_time > s.sim_time => {}
        _ => q.push_back(s),
    }
    while q.len() > KEEP {
        q.pop_front();
    }
}

fn tick_of(s: &EmulatorState) -> TruthTick {
    TruthTick {
        sim_time: s.sim_time,
        truth: s.truth,
        odometry: s.odometry,
    }
}

impl TruthLog {
    /// Starts following `robot`.
    pub fn follow(robot: &EmulatorHandle) -> TruthLog {
        let ticks = Arc::new(Mutex::new(VecDeque::<TruthTick>::with_capacity(KEEP + 1)));
        let mut rx = robot.subscribe();
        let log = Arc::clone(&ticks);
        let task = tokio::spawn(async move {
            loop {
                let s = tick_of(&rx.borrow_and_update());
                if let Ok(mut q) = log.lock() {
                    push(&mut q, s);
                }
                if rx.changed().await.is_err() {
                    break;
                }
            }
        });
        TruthLog {
            ticks,
            robot: robot.clone(),
            task,
        }
    }

    /// The tick whose odometry is closest to `odometry` (the pose a SIP reported; the right
    /// tick is within the SIP's quantisation, ≤ 0.5 mm and ≤ 0.0008 rad), preferring the newest
    /// among equals (a robot standing still); `None` before the first state.
    #[must_use]
    pub fn at_odometry(&self, odometry: &Pose2) -> Option<TruthTick> {
        let mut q = self.ticks.lock().ok()?;
        // The follower task may not have run yet (a loaded machine): the current state is
        // always there.
        push(&mut q, tick_of(&self.robot.state()));
        let gap = |t: &TruthTick| {
            t.odometry.distance(odometry)
                + HEADING_WEIGHT_M * angle_diff(t.odometry.theta, odometry.theta).abs()
        };
        let mut best: Option<(f64, TruthTick)> = None;
        for t in q.iter().rev() {
            let g = gap(t);
            if best.is_none_or(|(b, _)| g < b) {
                best = Some((g, *t));
            }
        }
        best.map(|(_, t)| t)
    }
}

impl Drop for TruthLog {
    fn drop(&mut self) {
        self.task.abort();
    }
}
