//! The emulated Pioneer's motion hook for a simulated world: each motion substep is clipped
//! where the body would touch a wall or obstacle (the robot may still turn on the spot, which
//! the emulator reports as a wheel stall), and the true pose at the end of every SIP period is
//! logged so that sensors and scoring can use the truth of the exact period a SIP came from,
//! however late the trial loop reads it.

use std::sync::{Arc, Mutex, PoisonError};

use rfloc_aria::emulator::MotionHook;
use rfloc_pose::Pose2;
use rfloc_sim::{Point, World};

/// Motion substeps per SIP period in the emulator (`rfloc_aria`'s `SUBSTEPS`).
pub const SUBSTEPS_PER_TICK: u64 = 10;

#[derive(Debug, Default)]
struct LogState {
    calls: u64,
    /// True pose after tick `k + 1` (ticks counted from 1).
    ticks: Vec<Pose2>,
}

/// Shared, append-only log of the true pose per emulator tick.
#[derive(Debug, Clone, Default)]
pub struct TruthLog {
    state: Arc<Mutex<LogState>>,
}

impl TruthLog {
    /// An empty log.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// True pose after tick `tick` (1-based), if the emulator has got that far.
    #[must_use]
    pub fn after_tick(&self, tick: u64) -> Option<Pose2> {
        let s = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let i = usize::try_from(tick.checked_sub(1)?).ok()?;
        s.ticks.get(i).copied()
    }

    fn record(&self, accepted: Pose2) {
        let mut s = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        s.calls += 1;
        if s.calls % SUBSTEPS_PER_TICK == 0 {
            s.ticks.push(accepted);
        }
    }

    /// A motion hook that keeps a disc of `radius` out of the world's walls and obstacles and
    /// logs the accepted pose into this log.
    #[must_use]
    pub fn motion_hook(&self, world: Arc<World>, radius: f64) -> MotionHook {
        let log = self.clone();
        Box::new(move |current: &Pose2, proposed: &Pose2| {
            let free = |p: &Pose2| !world.disk_collides(&Point::new(p.x, p.y), radius);
            let accepted = if free(proposed) {
                *proposed
            } else {
                // Blocked: the wheels stall; turning on the spot stays possible.
                Pose2::new(current.x, current.y, proposed.theta)
            };
            log.record(accepted);
            accepted
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn hook_stops_at_a_wall_and_logs_once_per_tick() {
        let world = Arc::new(
            World::from_toml_str("[area]\nmin=[0.0,0.0]\nmax=[2.0,2.0]\n", Path::new("w")).unwrap(),
        );
        let log = TruthLog::new();
        let mut hook = log.motion_hook(Arc::clone(&world), 0.2);
        let mut pose = Pose2::new(1.0, 1.0, 0.0);
        for _ in 0..2 * SUBSTEPS_PER_TICK {
            let proposed = Pose2::new(pose.x + 0.1, pose.y, pose.theta + 0.01);
            pose = hook(&pose, &proposed);
        }
        // Stopped 0.2 m short of the wall at x = 2 but still turned.
        assert!(pose.x <= 1.8 + 1e-9 && pose.x > 1.6);
        assert!((pose.theta - 0.2).abs() < 1e-9);
        assert_eq!(log.after_tick(2), Some(pose));
        assert!(log.after_tick(1).is_some());
        assert!(log.after_tick(0).is_none() && log.after_tick(3).is_none());
    }
}
