//! The robot's reaction to a wheel stall (the body pushed against a wall): the next few actions
//! are rotations in one direction, drawn once per stall, whatever the exploration policy or
//! the navigator asked for. Seed 000's simulated robot had no walls; its exploration turned
//! around only when no tags were visible, which a robot at a wall of a tagged floor never sees.

use rand::Rng;
use rfloc_snapshot::Action;

/// Pending turn-away rotations after a stall.
#[derive(Debug, Clone, PartialEq)]
pub struct StallReflex {
    steps: usize,
    left: usize,
    rotation: Action,
    triggered: usize,
}

impl StallReflex {
    /// A reflex turning for `steps` actions after each stall.
    #[must_use]
    pub fn new(steps: usize) -> Self {
        Self {
            steps,
            left: 0,
            rotation: Action::RotateLeft,
            triggered: 0,
        }
    }

    /// The action to execute instead of `wanted` (a rotation while the reflex is active).
    pub fn override_action(&mut self, wanted: Action) -> Action {
        if self.left == 0 {
            return wanted;
        }
        self.left -= 1;
        self.rotation
    }

    /// Reports whether the last action stalled; a new stall (with no turn pending) starts a turn
    /// in a random direction.
    pub fn after_action<R: Rng + ?Sized>(&mut self, stalled: bool, rng: &mut R) {
        if stalled && self.left == 0 {
            self.left = self.steps;
            self.triggered += 1;
            self.rotation = if rng.random::<bool>() {
                Action::RotateLeft
            } else {
                Action::RotateRight
            };
        }
    }

    /// Turns started so far.
    #[must_use]
    pub fn triggered(&self) -> usize {
        self.triggered
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn a_stall_turns_for_the_set_number_of_steps() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut r = StallReflex::new(3);
        assert_eq!(r.override_action(Action::Forward), Action::Forward);
        r.after_action(true, &mut rng);
        let turns: Vec<Action> = (0..3).map(|_| r.override_action(Action::Forward)).collect();
        assert!(turns.iter().all(|a| a.is_rotation() && *a == turns[0]));
        // A stall reported while turning does not extend the turn.
        r.after_action(false, &mut rng);
        assert_eq!(r.override_action(Action::ArcLeft), Action::ArcLeft);
        assert_eq!(r.triggered(), 1);
    }
}
