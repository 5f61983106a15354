//! Referee-side detection of the seed's "circling" and "limit cycling" (Table 4.9, runs 10 and
//! 17): the true distance to the goal stops improving for a long stretch of navigation steps.

/// Counts stretches of `window` steps in which the true distance to the goal never came
/// `min_gain` closer than the reference distance (the distance at the last such gain).
#[derive(Debug, Clone, PartialEq)]
pub struct StallDetector {
    window: usize,
    min_gain: f64,
    best: f64,
    since_best: usize,
    stalls: usize,
}

impl StallDetector {
    /// A detector with no history.
    #[must_use]
    pub fn new(window: usize, min_gain: f64) -> Self {
        Self {
            window: window.max(1),
            min_gain,
            best: f64::INFINITY,
            since_best: 0,
            stalls: 0,
        }
    }

    /// Adds one step's distance to the goal; returns true when this step completes a stall.
    pub fn push(&mut self, distance: f64) -> bool {
        if distance < self.best - self.min_gain || !self.best.is_finite() {
            self.best = distance;
            self.since_best = 0;
            return false;
        }
        self.since_best += 1;
        if self.since_best >= self.window {
            self.stalls += 1;
            self.since_best = 0;
            return true;
        }
        false
    }

    /// Stalls counted so far.
    #[must_use]
    pub fn stalls(&self) -> usize {
        self.stalls
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_approach_never_stalls() {
        let mut d = StallDetector::new(20, 0.1);
        for k in 0..200 {
            assert!(!d.push(5.0 - 0.02 * f64::from(k)));
        }
        assert_eq!(d.stalls(), 0);
    }

    #[test]
    fn oscillation_between_two_places_is_counted_once_per_window() {
        let mut d = StallDetector::new(20, 0.1);
        d.push(2.0);
        let fired: usize = (0..60)
            .map(|k| d.push(if k % 2 == 0 { 1.95 } else { 2.05 }))
            .filter(|f| *f)
            .count();
        assert_eq!(fired, 3);
        assert_eq!(d.stalls(), 3);
        // Progress again resets the count of the current stretch.
        assert!(!d.push(1.0));
    }
}
