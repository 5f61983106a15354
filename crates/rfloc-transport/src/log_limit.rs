//! Rate-limited logging of repeated errors: a link full of garbage gives a few log lines and
//! then one summary per interval with the count, not one line per malformed frame.
//!
//! ```
//! # use rfloc_transport::LogLimit;
//! let mut limit = LogLimit::new(std::time::Duration::from_secs(10), 3);
//! for _ in 0..1000 {
//!     if let Some(suppressed) = limit.hit() {
//!         // log here, mentioning `suppressed` earlier occurrences that were not logged
//!         let _ = suppressed;
//!     }
//! }
//! assert_eq!(limit.total(), 1000);
//! ```

use std::time::{Duration, Instant};

/// Allows `burst` log lines per `interval`; the first one after a quiet stretch reports how
/// many were suppressed since the last one logged.
#[derive(Debug, Clone)]
pub struct LogLimit {
    interval: Duration,
    burst: u32,
    window_start: Option<Instant>,
    in_window: u32,
    suppressed: u64,
    total: u64,
}

impl Default for LogLimit {
    /// Three lines per ten seconds.
    fn default() -> Self {
        Self::new(Duration::from_secs(10), 3)
    }
}

impl LogLimit {
    #[must_use]
    pub fn new(interval: Duration, burst: u32) -> Self {
        Self {
            interval,
            burst: burst.max(1),
            window_start: None,
            in_window: 0,
            suppressed: 0,
            total: 0,
        }
    }

    /// One occurrence now: `Some(n)` when it should be logged (`n` occurrences were suppressed
    /// since the last one logged), `None` when it should not.
    pub fn hit(&mut self) -> Option<u64> {
        self.hit_at(Instant::now())
    }

    /// [`LogLimit::hit`] at a given instant.
    pub fn hit_at(&mut self, now: Instant) -> Option<u64> {
        self.total += 1;
        let fresh = self
            .window_start
            .is_none_or(|s| now.saturating_duration_since(s) >= self.interval);
        if fresh {
            self.window_start = Some(now);
            self.in_window = 0;
        }
        if self.in_window < self.burst {
            self.in_window += 1;
            Some(std::mem::take(&mut self.suppressed))
        } else {
            self.suppressed += 1;
            None
        }
    }

    /// Occurrences so far, logged or not.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_gives_a_burst_then_one_summary_per_interval() {
        let mut l = LogLimit::new(Duration::from_secs(10), 3);
        let t0 = Instant::now();
        let mut logged = Vec::new();
        // 8,112 malformed lines over 4 s, then one more 11 s later.
        for i in 0..8112u64 {
            let t = t0 + Duration::from_micros(i * 490);
            if let Some(s) = l.hit_at(t) {
                logged.push(s);
            }
        }
        assert_eq!(logged, vec![0, 0, 0]);
        assert_eq!(l.hit_at(t0 + Duration::from_secs(15)), Some(8109));
        assert_eq!(l.total(), 8113);
    }
}
