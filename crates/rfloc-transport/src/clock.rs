//! Time sources for driver timestamps.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// A source of timestamps in seconds. Live links use [`MonotonicClock`]; replays use the
/// recorded time of the record being delivered ([`ManualClock`]).
pub trait Clock: Send + Sync + std::fmt::Debug {
    /// Seconds since the clock's epoch.
    fn now(&self) -> f64;
}

/// A shareable clock.
pub type SharedClock = Arc<dyn Clock>;

/// Monotonic wall time since the clock was created.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    start: Instant,
}

impl MonotonicClock {
    #[must_use]
    pub fn new() -> Self {
        Self {
            start: Instant::now(),
        }
    }

    /// A shared clock starting now.
    #[must_use]
    pub fn shared() -> SharedClock {
        Arc::new(Self::new())
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
}

/// A clock set from outside (a replay, a simulation), in nanoseconds.
#[derive(Debug, Default)]
pub struct ManualClock {
    ns: AtomicU64,
}

impl ManualClock {
    #[must_use]
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }

    /// Sets the time (nanoseconds).
    pub fn set_ns(&self, ns: u64) {
        self.ns.store(ns, Ordering::Release);
    }

    /// The time in nanoseconds.
    #[must_use]
    pub fn ns(&self) -> u64 {
        self.ns.load(Ordering::Acquire)
    }
}

impl Clock for ManualClock {
    #[allow(clippy::cast_precision_loss)]
    fn now(&self) -> f64 {
        self.ns() as f64 * 1e-9
    }
}
