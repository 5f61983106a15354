//! The emulated Pioneer's motion hook for a simulated world: each motion substep is clipped
//! where the body would touch a wall or obstacle (the robot may still turn on the spot, which
//! the emulator reports as a wheel stall), and the true pose at the end of every SIP period is
//! logged so that sensors and scoring can use the truth of the exact period a SIP came from,
//! however late the trial loop reads it.
//!
//! The log is also a **gate**: once the trial loop has opened it, the emulator may start tick
//! `k` only after the loop has released it (it releases `k + 1` when it has finished with SIP
//! `k`). So the robot never runs ahead of a slow control loop on a loaded machine, however
//! large the time scale; simulated time simply waits. The emulator must run on its own thread,
//! since waiting blocks it.

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Duration;

use rfloc_aria::emulator::MotionHook;
use rfloc_pose::Pose2;
use rfloc_sim::{Point, World};

/// Motion substeps per SIP period in the emulator (`rfloc_aria`'s `SUBSTEPS`).
pub const SUBSTEPS_PER_TICK: u64 = 10;

/// Longest wait for a release before the emulator goes on anyway (a stuck loop must not hang
/// the run forever).
const GATE_TIMEOUT: Duration = Duration::from_secs(10);

#[derive(Debug, Default)]
struct LogState {
    calls: u64,
    /// True pose after tick `k + 1` (ticks counted from 1).
    ticks: Vec<Pose2>,
    /// Ticks up to this one may run; `None` = gate open.
    released: Option<u64>,
    /// Releases that timed out.
    gate_timeouts: u64,
    /// The tick the emulator is waiting to start, while it waits.
    held: Option<u64>,
}

/// Shared, append-only log of the true pose per emulator tick, and the tick gate.
#[derive(Debug, Clone, Default)]
pub struct TruthLog {
    state: Arc<(Mutex<LogState>, Condvar)>,
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
        let s = self.lock();
        let i = usize::try_from(tick.checked_sub(1)?).ok()?;
        s.ticks.get(i).copied()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, LogState> {
        self.state.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Lets the emulator run ticks up to and including `tick` (and closes the gate beyond).
    pub fn release_through(&self, tick: u64) {
        let mut s = self.lock();
        s.released = Some(s.released.map_or(tick, |r| r.max(tick)));
        self.state.1.notify_all();
    }

    /// Opens the gate for good (end of the run).
    pub fn open_gate(&self) {
        let mut s = self.lock();
        s.released = None;
        self.state.1.notify_all();
    }

    /// The tick the emulator is held at, if it is waiting for a release.
    #[must_use]
    pub fn held(&self) -> Option<u64> {
        self.lock().held
    }

    /// How many times the emulator stopped waiting for a release.
    #[must_use]
    pub fn gate_timeouts(&self) -> u64 {
        self.lock().gate_timeouts
    }

    /// Called before each substep is accepted: blocks at the first substep of a tick that has
    /// not been released.
    fn wait_for_release(&self) {
        let mut s = self.lock();
        if s.calls % SUBSTEPS_PER_TICK != 0 {
            return;
        }
        let tick = s.calls / SUBSTEPS_PER_TICK + 1;
        if s.released.is_some_and(|r| r < tick) {
            s.held = Some(tick);
            self.state.1.notify_all();
        }
        while s.released.is_some_and(|r| r < tick) {
            let (next, timeout) = self
                .state
                .1
                .wait_timeout(s, GATE_TIMEOUT)
                .unwrap_or_else(PoisonError::into_inner);
            s = next;
            if timeout.timed_out() {
                s.gate_timeouts += 1;
                tracing::warn!(tick, "simulation gate timed out; the emulator goes on");
                break;
            }
        }
        s.held = None;
    }

    /// Blocks the calling thread until the emulator is held at the start of `tick` (true), or
    /// until it is past that point or `timeout` has elapsed (false). The emulator only needs
    /// to reach its next tick, a fraction of one SIP period of wall time.
    pub fn wait_held(&self, tick: u64, timeout: Duration) -> bool {
        let deadline = std::time::Instant::now() + timeout;
        let mut s = self.lock();
        loop {
            if s.held == Some(tick) {
                return true;
            }
            if s.ticks.len() as u64 >= tick {
                return false;
            }
            let now = std::time::Instant::now();
            if now >= deadline {
                return false;
            }
            s = self
                .state
                .1
                .wait_timeout(s, deadline - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    fn record(&self, accepted: Pose2) {
        let mut s = self.lock();
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
            log.wait_for_release();
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

    #[test]
    fn gate_holds_the_next_tick_until_released() {
        let world = Arc::new(
            World::from_toml_str("[area]\nmin=[0.0,0.0]\nmax=[2.0,2.0]\n", Path::new("w")).unwrap(),
        );
        let log = TruthLog::new();
        log.release_through(1);
        let mut hook = log.motion_hook(world, 0.2);
        let runner = std::thread::spawn(move || {
            let p = Pose2::new(1.0, 1.0, 0.0);
            for _ in 0..2 * SUBSTEPS_PER_TICK {
                let _ = hook(&p, &p);
            }
        });
        // Tick 1 runs; tick 2 waits for its release.
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        while log.after_tick(1).is_none() && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(50));
        assert!(log.after_tick(1).is_some());
        assert!(log.after_tick(2).is_none());
        assert!(log.wait_held(2, Duration::from_secs(5)));
        log.release_through(2);
        runner.join().unwrap();
        assert!(!log.wait_held(2, Duration::from_millis(10)));
        assert!(log.after_tick(2).is_some());
        assert_eq!(log.gate_timeouts(), 0);
    }
}
