//! Robot-side limit-cycle detection for pose-based navigation.
//!
//! The seed's limit cycles (section 4.1) are repeating place/action sequences: the robot comes
//! back to the same place with the same heading and does the same thing again (rotate left,
//! rotate right, …; or circling the goal). [`CycleBreaker`] keys each decision by a coarse
//! place-and-heading cell; when the current key already occurs `repeats` times in the last
//! `window` decisions, it takes the best-ranked action not yet taken from that key within the
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
        let visits = self.history.iter().filter(|(h, _)| *h == k).count();
        if visits + 1 >= self.repeats && self.escape_left == 0 {
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
        let mut c = CycleBreaker::new(16, 4);
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
        assert_eq!(out[3], (Action::Forward, "cycle escape"));
        assert!(c.broken() >= 1);
        // Moving on without revisits follows the plan.
        let mut fresh = CycleBreaker::new(16, 4);
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
