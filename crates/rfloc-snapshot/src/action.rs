//! The five motion actions of the seed (Table 4) and their motion model.

use std::f64::consts::{FRAC_PI_2, PI};

use rand::Rng;
use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

/// One of the seed's five actions (section 3.3.1, Table 4), numbered 1–5 there and 0–4 here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Action {
    /// F: drive straight.
    Forward,
    /// AL: drive while turning left.
    ArcLeft,
    /// AR: drive while turning right.
    ArcRight,
    /// RL: (nearly) rotate in place to the left.
    RotateLeft,
    /// RR: (nearly) rotate in place to the right.
    RotateRight,
}

impl Action {
    /// All actions in index order.
    pub const ALL: [Action; 5] = [
        Action::Forward,
        Action::ArcLeft,
        Action::ArcRight,
        Action::RotateLeft,
        Action::RotateRight,
    ];
    /// Number of actions.
    pub const COUNT: usize = 5;

    /// Index 0..5 (the seed's number minus one).
    #[must_use]
    pub fn index(self) -> usize {
        self as usize
    }

    /// Action from its index.
    #[must_use]
    pub fn from_index(i: usize) -> Option<Action> {
        Action::ALL.get(i).copied()
    }

    /// The mirror-image action (left ↔ right); `None` for forward.
    #[must_use]
    pub fn opposite(self) -> Option<Action> {
        match self {
            Action::Forward => None,
            Action::ArcLeft => Some(Action::ArcRight),
            Action::ArcRight => Some(Action::ArcLeft),
            Action::RotateLeft => Some(Action::RotateRight),
            Action::RotateRight => Some(Action::RotateLeft),
        }
    }

    /// True for the two rotations.
    #[must_use]
    pub fn is_rotation(self) -> bool {
        matches!(self, Action::RotateLeft | Action::RotateRight)
    }
}

/// A velocity command: `v` in m/s (forward), `omega` in rad/s (counter-clockwise positive).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotionCommand {
    pub v: f64,
    pub omega: f64,
}

/// Nominal commands per action and the uniform noise added to them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActionTable {
    /// Nominal command of each action, in [`Action::index`] order.
    pub commands: [MotionCommand; 5],
    /// Half-width of the uniform translational noise η_t, m/s.
    pub noise_v: f64,
    /// Half-width of the uniform rotational noise η_r, rad/s.
    pub noise_omega: f64,
}

impl ActionTable {
    /// Table 4 of the seed: F (2.5, 0), AL (2.5, π/2), AR (2.5, −π/2), RL (0.25, π/2),
    /// RR (0.25, −π/2), with η_t ~ U[−1, 1] m/s and η_r ~ U[−π/5, π/5] rad/s. The seed's
    /// simulator applies them for `dt = 0.25 s` per step (appendix A).
    #[must_use]
    pub fn seed_table() -> Self {
        let c = |v: f64, omega: f64| MotionCommand { v, omega };
        Self {
            commands: [
                c(2.5, 0.0),
                c(2.5, FRAC_PI_2),
                c(2.5, -FRAC_PI_2),
                c(0.25, FRAC_PI_2),
                c(0.25, -FRAC_PI_2),
            ],
            noise_v: 1.0,
            noise_omega: PI / 5.0,
        }
    }

    /// Nominal command of an action.
    #[must_use]
    pub fn nominal(&self, action: Action) -> MotionCommand {
        self.commands
            .get(action.index())
            .copied()
            .unwrap_or(MotionCommand { v: 0.0, omega: 0.0 })
    }

    /// Nominal command plus uniform noise drawn from `rng`.
    pub fn sample<R: Rng + ?Sized>(&self, action: Action, rng: &mut R) -> MotionCommand {
        let n = self.nominal(action);
        let ev = if self.noise_v > 0.0 {
            rng.random_range(-self.noise_v..=self.noise_v)
        } else {
            0.0
        };
        let ew = if self.noise_omega > 0.0 {
            rng.random_range(-self.noise_omega..=self.noise_omega)
        } else {
            0.0
        };
        MotionCommand {
            v: n.v + ev,
            omega: n.omega + ew,
        }
    }
}

impl Default for ActionTable {
    fn default() -> Self {
        Self::seed_table()
    }
}

/// Integrates a constant velocity command for `dt` seconds (exact circular arc).
#[must_use]
pub fn integrate(pose: &Pose2, cmd: MotionCommand, dt: f64) -> Pose2 {
    let dth = cmd.omega * dt;
    let (dx, dy) = if dth.abs() < 1e-9 {
        (cmd.v * dt, 0.0)
    } else {
        let r = cmd.v / cmd.omega;
        (r * dth.sin(), r * (1.0 - dth.cos()))
    };
    pose.compose(&Pose2 {
        x: dx,
        y: dy,
        theta: dth,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrate_straight_and_quarter_circle() {
        let p = integrate(
            &Pose2::new(0.0, 0.0, 0.0),
            MotionCommand { v: 2.0, omega: 0.0 },
            0.5,
        );
        assert!((p.x - 1.0).abs() < 1e-12 && p.y.abs() < 1e-12);
        // v = π/2, ω = π/2 for 1 s: quarter circle of radius 1 to the left.
        let p = integrate(
            &Pose2::new(0.0, 0.0, 0.0),
            MotionCommand {
                v: FRAC_PI_2,
                omega: FRAC_PI_2,
            },
            1.0,
        );
        assert!(
            (p.x - 1.0).abs() < 1e-12
                && (p.y - 1.0).abs() < 1e-12
                && (p.theta - FRAC_PI_2).abs() < 1e-12
        );
    }

    #[test]
    fn indices_and_opposites_round_trip() {
        for a in Action::ALL {
            assert_eq!(Action::from_index(a.index()), Some(a));
            if let Some(o) = a.opposite() {
                assert_eq!(o.opposite(), Some(a));
            }
        }
        assert_eq!(Action::from_index(5), None);
    }
}
