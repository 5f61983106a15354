//! Angle ↔ step conversion and target resolution, shared by the driver and the simulator.

use rfloc_pose::wrap_angle;

use crate::config::{MovePolicy, StepperConfig};
use crate::error::StepperError;

/// Longest single move, in steps (ten output turns at 32 microsteps and a 10:1 gear is 640 000).
pub const MAX_MOVE_STEPS: i64 = 10_000_000;

/// Converts between the absolute step counter and output angles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepGeometry {
    step_rad: f64,
    policy: MovePolicy,
}

impl StepGeometry {
    /// Builds the geometry of a validated configuration.
    pub fn new(config: &StepperConfig) -> Result<Self, StepperError> {
        config.validate()?;
        Ok(Self {
            step_rad: std::f64::consts::TAU / config.steps_per_output_rev(),
            policy: config.policy,
        })
    }

    /// Output angle of one (micro)step, radians.
    #[must_use]
    pub fn step_rad(&self) -> f64 {
        self.step_rad
    }

    /// Absolute output angle of a step count, radians.
    #[must_use]
    pub fn angle_of(&self, steps: i64) -> f64 {
        steps as f64 * self.step_rad
    }

    /// The step count at which the output points at `target_rad`, starting from `current`.
    ///
    /// [`MovePolicy::ShortestPath`]: the target is taken modulo one turn and the nearer way
    /// round is chosen. [`MovePolicy::Bounded`]: the target is absolute and must lie inside the
    /// travel; the nearest step that is still inside the travel is chosen.
    pub fn target_steps(&self, current: i64, target_rad: f64) -> Result<i64, StepperError> {
        if !target_rad.is_finite() {
            return Err(StepperError::NotFinite(target_rad));
        }
        let target = match self.policy {
            MovePolicy::ShortestPath => {
                let delta = wrap_angle(target_rad - self.angle_of(current));
                current + self.round_steps(delta)?
            }
            MovePolicy::Bounded { min_rad, max_rad } => {
                let tol = 1e-9;
                if target_rad < min_rad - tol || target_rad > max_rad + tol {
                    return Err(StepperError::OutOfRange {
                        target_rad,
                        min_rad,
                        max_rad,
                    });
                }
                let mut t = self.round_steps(target_rad)?;
                if self.angle_of(t) > max_rad + tol {
                    t -= 1;
                }
                if self.angle_of(t) < min_rad - tol {
                    t += 1;
                }
                t
            }
        };
        let delta = target - current;
        if delta.abs() > MAX_MOVE_STEPS {
            return Err(StepperError::MoveTooLong(delta));
        }
        Ok(target)
    }

    fn round_steps(&self, rad: f64) -> Result<i64, StepperError> {
        let s = (rad / self.step_rad).round();
        if s.abs() > MAX_MOVE_STEPS as f64 {
            return Err(StepperError::MoveTooLong(if s > 0.0 {
                MAX_MOVE_STEPS
            } else {
                -MAX_MOVE_STEPS
            }));
        }
        Ok(s as i64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn geom(policy: MovePolicy) -> StepGeometry {
        StepGeometry::new(&StepperConfig {
            full_steps_per_rev: 200,
            microsteps: 1,
            gear_ratio: 1.0,
            policy,
            ..StepperConfig::default()
        })
        .unwrap()
    }

    #[test]
    fn shortest_path_goes_the_near_way() {
        let g = geom(MovePolicy::ShortestPath);
        // 1.8° per step. From +171° (95 steps) to -171° is +18° (10 steps), not -342°.
        let from = 95;
        let to = g.target_steps(from, (-171.0f64).to_radians()).unwrap();
        assert_eq!(to, 105);
    }

    #[test]
    fn bounded_takes_the_absolute_angle() {
        let g = geom(MovePolicy::default());
        let to = g.target_steps(95, (-171.0f64).to_radians()).unwrap();
        assert_eq!(to, -95);
        assert!(matches!(
            g.target_steps(0, 1.5 * PI),
            Err(StepperError::OutOfRange { .. })
        ));
        assert!(matches!(
            g.target_steps(0, f64::NAN),
            Err(StepperError::NotFinite(_))
        ));
    }

    #[test]
    fn bounded_never_rounds_outside_the_travel() {
        let g = StepGeometry::new(&StepperConfig {
            full_steps_per_rev: 7,
            policy: MovePolicy::Bounded {
                min_rad: -0.5,
                max_rad: 0.5,
            },
            ..StepperConfig::default()
        })
        .unwrap();
        // One step is 0.8976 rad: 0.5 rad rounds to step 1 (0.8976 rad, outside), so the
        // nearest step inside the travel, 0, is chosen.
        assert_eq!(g.target_steps(0, 0.5).unwrap(), 0);
        assert_eq!(g.target_steps(0, -0.5).unwrap(), 0);
    }
}
