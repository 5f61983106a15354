//! The exploration policy: weighted random actions (section 3.3.1 of the seed).

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::action::Action;

/// Weights and schedule of the exploration policy.
///
/// The seed states the behaviour in words (its `actGen` is not in the appendix): forward and
/// arcs are more likely early in exploration and rotations least likely; the rotation
/// probability grows as fewer tags are seen and is 1 when none are; forward is biased up when
/// unknown tags are detected (frontier exploration). This struct makes those rules numeric.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExplorationConfig {
    /// Relative weights of forward, arc left, arc right (in that order).
    pub translation_weights: [f64; 3],
    /// Total rotation probability at the start of exploration.
    pub rotation_early: f64,
    /// Total rotation probability after `ramp_steps` steps.
    pub rotation_late: f64,
    /// Steps over which the rotation probability ramps linearly from early to late.
    pub ramp_steps: usize,
    /// Tag count at and above which the tag count no longer raises the rotation probability.
    pub full_view_tags: usize,
    /// Forward weight is multiplied by `1 + frontier_bias` when the snapshot holds unknown tags.
    pub frontier_bias: f64,
    /// Consecutive "no tags" steps after which the turn-around uses the arc (moves while turning)
    /// instead of a rotation, like the seed's watchdog (`watchdog > 10`).
    pub watchdog_steps: usize,
}

impl Default for ExplorationConfig {
    fn default() -> Self {
        Self {
            translation_weights: [0.5, 0.25, 0.25],
            rotation_early: 0.1,
            rotation_late: 0.3,
            ramp_steps: 500,
            full_view_tags: 10,
            frontier_bias: 1.0,
            watchdog_steps: 10,
        }
    }
}

/// What the exploration step sees of the last snapshot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExplorationInput {
    /// Number of tags in the snapshot.
    pub tags_seen: usize,
    /// How many of them were never seen before.
    pub new_tags: usize,
}

/// State of the exploration policy; [`ExplorationPolicy::step`] is a pure function of this state,
/// the input and the RNG.
#[derive(Debug, Clone, PartialEq)]
pub struct ExplorationPolicy {
    config: ExplorationConfig,
    steps: usize,
    turn_left: bool,
    blind_steps: usize,
}

impl ExplorationPolicy {
    /// A fresh policy (turn direction left until the first random draw).
    #[must_use]
    pub fn new(config: ExplorationConfig) -> Self {
        Self {
            config,
            steps: 0,
            turn_left: true,
            blind_steps: 0,
        }
    }

    /// Action probabilities for the next step, in [`Action::index`] order.
    #[must_use]
    pub fn probabilities(&self, input: ExplorationInput) -> [f64; 5] {
        let c = &self.config;
        let ramp = if c.ramp_steps == 0 {
            1.0
        } else {
            (self.steps as f64 / c.ramp_steps as f64).min(1.0)
        };
        let base = (c.rotation_early + (c.rotation_late - c.rotation_early) * ramp).clamp(0.0, 1.0);
        let full = c.full_view_tags.max(1) as f64;
        let scarcity = (1.0 - input.tags_seen as f64 / full).max(0.0);
        let p_rot = base + (1.0 - base) * scarcity;
        let mut tw = c.translation_weights.map(|w| w.max(0.0));
        if input.new_tags > 0 {
            tw[0] *= 1.0 + c.frontier_bias.max(0.0);
        }
        let tsum: f64 = tw.iter().sum();
        let t = if tsum > 0.0 {
            tw.map(|w| (1.0 - p_rot) * w / tsum)
        } else {
            [0.0; 3]
        };
        let r = if tsum > 0.0 { p_rot / 2.0 } else { 0.5 };
        [t[0], t[1], t[2], r, r]
    }

    /// Chooses the next action.
    ///
    /// With no tags visible the robot turns around in a direction drawn once per blind spell
    /// (the seed's `tf`); after `watchdog_steps` blind steps it arcs in that direction instead.
    pub fn step<R: Rng + ?Sized>(&mut self, input: ExplorationInput, rng: &mut R) -> Action {
        self.steps += 1;
        if input.tags_seen == 0 {
            self.blind_steps += 1;
            let rotate = self.blind_steps <= self.config.watchdog_steps;
            return match (rotate, self.turn_left) {
                (true, true) => Action::RotateLeft,
                (true, false) => Action::RotateRight,
                (false, true) => Action::ArcLeft,
                (false, false) => Action::ArcRight,
            };
        }
        self.blind_steps = 0;
        self.turn_left = rng.random::<bool>();
        let p = self.probabilities(input);
        let mut u = rng.random::<f64>() * p.iter().sum::<f64>();
        for (i, w) in p.iter().enumerate() {
            if u < *w {
                return Action::from_index(i).unwrap_or(Action::Forward);
            }
            u -= w;
        }
        Action::Forward
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_chacha::rand_core::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn rotation_probability_rules() {
        let p = ExplorationPolicy::new(ExplorationConfig::default());
        let blind = p.probabilities(ExplorationInput {
            tags_seen: 0,
            new_tags: 0,
        });
        assert!((blind[3] + blind[4] - 1.0).abs() < 1e-12);
        let many = p.probabilities(ExplorationInput {
            tags_seen: 40,
            new_tags: 0,
        });
        assert!((many[3] + many[4] - 0.1).abs() < 1e-12);
        let few = p.probabilities(ExplorationInput {
            tags_seen: 5,
            new_tags: 0,
        });
        assert!(few[3] > many[3] && few[3] < blind[3]);
        let frontier = p.probabilities(ExplorationInput {
            tags_seen: 40,
            new_tags: 3,
        });
        assert!(frontier[0] > many[0]);
        for probs in [blind, many, few, frontier] {
            assert!((probs.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn rotations_become_more_likely_later_and_steps_are_seeded() {
        let input = ExplorationInput {
            tags_seen: 30,
            new_tags: 0,
        };
        let count_rot = |skip: usize| {
            let mut p = ExplorationPolicy::new(ExplorationConfig::default());
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            for _ in 0..skip {
                p.step(input, &mut rng);
            }
            (0..2000)
                .filter(|_| p.step(input, &mut rng).is_rotation())
                .count()
        };
        assert!(count_rot(0) < count_rot(1000));
        let run = |seed| {
            let mut p = ExplorationPolicy::new(ExplorationConfig::default());
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            (0..50).map(|_| p.step(input, &mut rng)).collect::<Vec<_>>()
        };
        assert_eq!(run(9), run(9));
        assert_ne!(run(9), run(10));
    }

    #[test]
    fn blind_turns_keep_direction_then_arc() {
        let mut p = ExplorationPolicy::new(ExplorationConfig::default());
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let blind = ExplorationInput::default();
        let acts: Vec<Action> = (0..12).map(|_| p.step(blind, &mut rng)).collect();
        assert!(acts[..10].iter().all(|a| *a == acts[0] && a.is_rotation()));
        assert!(acts[10..].iter().all(|a| !a.is_rotation()));
    }
}
