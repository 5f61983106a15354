//! Ground truth matched to the odometry samples the driver delivers.
//!
//! The Pioneer emulator calls a motion hook on every 10 ms substep of its own simulation step;
//! [`TruthLog::hook`] returns the proposed motion unchanged (no stall, the odometry is not
//! touched) and keeps the true pose at the end of every 100 ms tick, so no tick is ever missed,
//! however late the trial loop runs. Without emulator-side slip, the robot's odometry is its
//! true motion seen from the start pose (`truth.relative_to(start)`), so the tick a SIP came
//! from is the one whose odometry is closest to the SIP's (within the SIP's 1 mm and
//! 2π/4096 rad quantisation).

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use rfloc_aria::MotionHook;
use rfloc_pose::{angle_diff, Pose2};

/// Substeps of the emulator per SIP period (`rfloc_aria` simulates 10).
const SUBSTEPS: u64 = 10;
/// Ticks kept (60 s of simulated time): far more than the loop can fall behind.
const KEEP: usize = 600;
/// Metres a radian of heading difference counts as when matching odometry.
const HEADING_WEIGHT_M: f64 = 1.0;

/// One tick of the emulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthTick {
    /// Ticks since the emulator started (simulated time = tick × 100 ms).
    pub tick: u64,
    /// True pose at the end of the tick.
    pub truth: Pose2,
    /// The robot's odometry at that tick.
    pub odometry: Pose2,
}

#[derive(Debug, Default)]
struct History {
    substeps: u64,
    ticks: VecDeque<TruthTick>,
}

/// The true pose of every recent tick, filled by the emulator's motion hook.
#[derive(Debug, Clone)]
pub struct TruthLog {
    start: Pose2,
    history: Arc<Mutex<History>>,
}

impl TruthLog {
    /// A log for a robot starting at `start`; install [`TruthLog::hook`] in its emulator.
    #[must_use]
    pub fn new(start: Pose2) -> TruthLog {
        let log = TruthLog {
            start,
            history: Arc::new(Mutex::new(History::default())),
        };
        log.push(0, start);
        log
    }

    fn push(&self, tick: u64, truth: Pose2) {
        if let Ok(mut h) = self.history.lock() {
            h.ticks.push_back(TruthTick {
                tick,
                truth,
                odometry: truth.relative_to(&self.start),
            });
            while h.ticks.len() > KEEP {
                h.ticks.pop_front();
            }
        }
    }

    /// The emulator motion hook: accepts every proposed step, records each tick's end pose.
    #[must_use]
    pub fn hook(&self) -> MotionHook {
        let log = self.clone();
        Box::new(move |_current: &Pose2, proposed: &Pose2| {
            let tick = log.history.lock().ok().and_then(|mut h| {
                h.substeps += 1;
                (h.substeps % SUBSTEPS == 0).then_some(h.substeps / SUBSTEPS)
            });
            if let Some(tick) = tick {
                log.push(tick, *proposed);
            }
            *proposed
        })
    }

    /// The tick whose odometry is closest to `odometry` (the pose a SIP reported), the newest
    /// among equals (a robot standing still).
    #[must_use]
    pub fn at_odometry(&self, odometry: &Pose2) -> Option<TruthTick> {
        let h = self.history.lock().ok()?;
        let gap = |t: &TruthTick| {
            t.odometry.distance(odometry)
                + HEADING_WEIGHT_M * angle_diff(t.odometry.theta, odometry.theta).abs()
        };
        let mut best: Option<(f64, TruthTick)> = None;
        for t in h.ticks.iter().rev() {
            let g = gap(t);
            if best.is_none_or(|(b, _)| g < b) {
                best = Some((g, *t));
            }
        }
        best.map(|(_, t)| t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hook_keeps_tick_ends_and_matches_odometry() {
        let start = Pose2::new(1.0, 2.0, 0.5);
        let log = TruthLog::new(start);
        let mut hook = log.hook();
        let mut truth = start;
        for k in 0..30 {
            // 2 cm per substep straight ahead for 20 substeps, then standing still.
            let step = if k < 20 { 0.02 } else { 0.0 };
            let proposed = truth.compose(&Pose2::new(step, 0.0, 0.0));
            assert_eq!(hook(&truth, &proposed), proposed, "the hook never clips");
            truth = proposed;
        }
        // Tick 1 ended after 10 substeps: 0.2 m from the start, odometry (0.2, 0, 0).
        let t1 = log.at_odometry(&Pose2::new(0.2004, -0.0003, 0.0)).unwrap();
        assert_eq!(t1.tick, 1);
        assert!(
            t1.truth
                .distance(&start.compose(&Pose2::new(0.2, 0.0, 0.0)))
                < 1e-12
        );
        // Ticks 2 and 3 are at the same place: the newest wins.
        let t3 = log.at_odometry(&Pose2::new(0.4, 0.0, 0.0)).unwrap();
        assert_eq!(t3.tick, 3);
        assert_eq!(log.at_odometry(&Pose2::new(0.0, 0.0, 0.0)).unwrap().tick, 0);
    }
}
