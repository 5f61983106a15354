//! Robot-side limit-cycle detection for pose-based navigation.
//!
//! The seed's limit cycles (section 4.1) are repeating place/action sequences: the robot comes
//! back to the same place with the same heading and does the same thing again (rotate left,
//! rotate right, …; or circling the goal). [`CycleBreaker`] keys each decision by a coarse
//! place-and-heading cell; when the robot has come back to the current key `repeats` times
//! within the last `window` decisions (consecutive decisions at one key count once, so turning
//! on the spot is not a cycle), or has reversed its rotation or arc `repeats − 1` times without
//! leaving the key, it takes the best-ranked action not yet taken from that key within the
//! window (the next-best action when all were), for `escape_steps` decisions.

use std::collections::VecDeque;

use rfloc_pose::{wrap_angle, Pose2};

use crate::action::Action;

/// Coarse key of a pose: 0.3 m cells and 45° heading sectors.
fn key(pose: &Pose2) -> (i64, i64, i64) {
    let sector = (wrap_angle(pose.theta) / std::f64::consts::FRAC_PI_4).round() as i64;
    (
        (pose.x / 0.3).round() as i64,
        (pose.y / 0.3).round() as i64,
        sector.rem_euclid(8),
    )
}

/// Detects and breaks repeating place/action sequences.
#[derive(Debug, Clone)]
pub struct CycleBreaker {
    window: usize,
    repeats: usize,
    escape_steps: usize,
    escape_left: usize,
    history: VecDeque<((i64, i64, i64), Action)>,
    broken: usize,
}

impl CycleBreaker {
    /// A breaker remembering `window` decisions; `repeats` visits of one key count as a cycle.
    #[must_use]
    pub fn new(window: usize, repeats: usize) -> Self {
        Self {
            window: window.max(2),
            repeats: repeats.max(2),
            escape_steps: 2,
            escape_left: 0,
            history: VecDeque::new(),
            broken: 0,
        }
    }

    /// Cycles detected so far.
    #[must_use]
    pub fn broken(&self) -> usize {
        self.broken
    }

    /// Chooses among `ranked` (best first, e.g. [`crate::LatticePlan::ranked`]) at `pose`;
    /// returns the action and why (`"plan"` or `"cycle escape"`).
    pub fn choose(&mut self, pose: &Pose2, ranked: &[(Action, f64)]) -> (Action, &'static str) {
        let k = key(pose);
        let best = ranked.first().map_or(Action::Forward, |r| r.0);
        // Returns to this key: maximal runs of it in the window (turning on the spot through a
        // sector is one visit, not several), counting the current step.
        let mut runs = 0usize;
        let mut prev_key = None;
        for (h, _) in &self.history {
            if *h == k && prev_key != Some(*h) {
                runs += 1;
            }
            prev_key = Some(*h);
        }
        if prev_key != Some(k) {
            runs += 1;
        }
        // Mirror-image reversals (left after right) within the current stay at this key.
        let stay: Vec<Action> = self
            .history
            .iter()
            .rev()
            .take_while(|(h, _)| *h == k)
            .map(|(_, a)| *a)
            .collect();
        let reversals = stay
            .windows(2)
            .filter(|w| match (w.first(), w.get(1)) {
                (Some(a), Some(b)) => a.opposite() == Some(*b),
                _ => false,
            })
            .count();
        let visits = runs.max(reversals + 1);
        if visits >= self.repeats && self.escape_left == 0 {
            self.escape_left = self.escape_steps;
            self.broken += 1;
            tracing::debug!(?k, visits, "navigation limit cycle detected");
        }
        let (action, reason) = if self.escape_left > 0 {
            self.escape_left -= 1;
            let tried: Vec<Action> = self
                .history
                .iter()
                .filter(|(h, _)| *h == k)
                .map(|(_, a)| *a)
                .collect();
            let untried = ranked.iter().map(|r| r.0).find(|a| !tried.contains(a));
            let fallback = ranked.get(1).map_or(best, |r| r.0);
            (untried.unwrap_or(fallback), "cycle escape")
        } else {
            (best, "plan")
        };
        self.history.push_back((k, action));
        while self.history.len() > self.window {
            self.history.pop_front();
        }
        (action, reason)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_left_right_ping_pong_is_broken_with_an_untried_action() {
        let mut c = CycleBreaker::new(16, 3);
        let p = Pose2::new(1.0, 1.0, 0.1);
        let mut out = Vec::new();
        for k in 0..8 {
            // A plan whose best action flips between the rotations at the same pose.
            let ranked = if k % 2 == 0 {
                [
                    (Action::RotateLeft, 1.0),
                    (Action::RotateRight, 1.1),
                    (Action::Forward, 3.0),
                ]
            } else {
                [
                    (Action::RotateRight, 1.0),
                    (Action::RotateLeft, 1.1),
                    (Action::Forward, 3.0),
                ]
            };
            out.push(c.choose(&p, &ranked));
        }
        assert_eq!(out[0].0, Action::RotateLeft);
        assert_eq!(out[1].0, Action::RotateRight);
        // After two reversals without leaving the key the next decision escapes.
        assert_eq!(out[2].1, "plan");
        assert_eq!(out[3], (Action::Forward, "cycle escape"));
        assert!(c.broken() >= 1);
        // Turning on the spot in one direction is not a cycle.
        let mut turning = CycleBreaker::new(16, 3);
        for i in 0..12 {
            let q = Pose2::new(1.0, 1.0, 0.05 * f64::from(i));
            assert_eq!(
                turning.choose(&q, &[(Action::RotateLeft, 1.0), (Action::Forward, 2.0)]),
                (Action::RotateLeft, "plan")
            );
        }
        // Coming back to a place for the third time is.
        let mut circling = CycleBreaker::new(16, 3);
        let ring = [
            Pose2::new(1.0, 1.0, 0.0),
            Pose2::new(2.0, 1.0, 0.0),
            Pose2::new(2.0, 2.0, 0.0),
        ];
        let picks: Vec<&str> = (0..7)
            .map(|i| {
                circling
                    .choose(
                        &ring[i % 3],
                        &[(Action::ArcLeft, 1.0), (Action::Forward, 2.0)],
                    )
                    .1
            })
            .collect();
        assert_eq!(picks[6], "cycle escape", "{picks:?}");
        assert_eq!(circling.broken(), 1);
        // Moving on without revisits follows the plan.
        let mut fresh = CycleBreaker::new(16, 3);
        for i in 0..10 {
            let q = Pose2::new(0.5 * f64::from(i), 0.0, 0.0);
            assert_eq!(
                fresh.choose(&q, &[(Action::Forward, 1.0)]),
                (Action::Forward, "plan")
            );
        }
        assert_eq!(fresh.broken(), 0);
    }
}
