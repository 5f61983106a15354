//! Stepper configuration (one `[stepper]` table of the robot TOML).

use serde::{Deserialize, Serialize};

use crate::error::StepperError;

/// How a target angle is reached.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum MovePolicy {
    /// The target is taken modulo one turn and reached the short way round. Only for mounts
    /// with a slip ring: the absolute position grows without bound.
    ShortestPath,
    /// The target is an absolute angle from the stored zero and must lie in `[min_rad, max_rad]`.
    /// Use this when cables run to the rotating part, so they never wind past the limits.
    Bounded {
        /// Lowest absolute angle allowed, radians.
        min_rad: f64,
        /// Highest absolute angle allowed, radians.
        max_rad: f64,
    },
}

impl Default for MovePolicy {
    fn default() -> Self {
        Self::Bounded {
            min_rad: -std::f64::consts::PI,
            max_rad: std::f64::consts::PI,
        }
    }
}

/// Mechanical and motion settings of a step/dir/enable stepper axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StepperConfig {
    /// Full steps per motor revolution (200 for a 1.8° motor).
    pub full_steps_per_rev: u32,
    /// Microsteps per full step set on the driver's MS pins (1, 2, 4, 8, 16, 32).
    pub microsteps: u32,
    /// Motor revolutions per output (antenna) revolution; 1.0 for direct drive.
    pub gear_ratio: f64,
    /// Speed at which a move starts and ends, in (micro)steps per second (≥ 1).
    pub start_speed_steps_per_s: f64,
    /// Cruise speed, (micro)steps per second.
    pub max_speed_steps_per_s: f64,
    /// Acceleration of the trapezoidal ramp, (micro)steps per second².
    pub accel_steps_per_s2: f64,
    /// The driver's ENABLE input is active low (true for A4988 and DRV8825 `nENBL`).
    pub enable_active_low: bool,
    /// Swap the DIR level so that positive angles turn counter-clockwise seen from above.
    pub invert_direction: bool,
    /// De-energise the coils after each move (saves power, loses holding torque).
    pub release_after_move: bool,
    /// How targets are reached.
    pub policy: MovePolicy,
}

impl Default for StepperConfig {
    fn default() -> Self {
        Self {
            full_steps_per_rev: 200,
            microsteps: 1,
            gear_ratio: 1.0,
            start_speed_steps_per_s: 100.0,
            max_speed_steps_per_s: 400.0,
            accel_steps_per_s2: 800.0,
            enable_active_low: true,
            invert_direction: false,
            release_after_move: false,
            policy: MovePolicy::default(),
        }
    }
}

impl StepperConfig {
    /// Checks that every number is usable; the driver calls this in its constructor.
    pub fn validate(&self) -> Result<(), StepperError> {
        let bad = |what: &str| Err(StepperError::InvalidConfig(what.to_owned()));
        if self.full_steps_per_rev == 0 || self.microsteps == 0 {
            return bad("full_steps_per_rev and microsteps must be > 0");
        }
        if !(self.gear_ratio.is_finite() && self.gear_ratio > 0.0) {
            return bad("gear_ratio must be finite and > 0");
        }
        if !(self.start_speed_steps_per_s.is_finite() && self.start_speed_steps_per_s >= 1.0) {
            return bad("start_speed_steps_per_s must be ≥ 1");
        }
        if !(self.max_speed_steps_per_s.is_finite()
            && self.max_speed_steps_per_s >= self.start_speed_steps_per_s)
        {
            return bad("max_speed_steps_per_s must be ≥ start_speed_steps_per_s");
        }
        if self.max_speed_steps_per_s > crate::timing::MAX_STEP_RATE_HZ {
            return bad("max_speed_steps_per_s exceeds the step rate the pulse timing allows");
        }
        if !(self.accel_steps_per_s2.is_finite() && self.accel_steps_per_s2 > 0.0) {
            return bad("accel_steps_per_s2 must be finite and > 0");
        }
        if let MovePolicy::Bounded { min_rad, max_rad } = self.policy {
            if !(min_rad.is_finite() && max_rad.is_finite() && min_rad <= 0.0 && max_rad >= 0.0) {
                return bad("bounded policy needs finite min_rad ≤ 0 ≤ max_rad");
            }
        }
        Ok(())
    }

    /// (Micro)steps per output revolution, as a real number (gear ratios need not be integral).
    #[must_use]
    pub fn steps_per_output_rev(&self) -> f64 {
        f64::from(self.full_steps_per_rev) * f64::from(self.microsteps) * self.gear_ratio
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_with_defaults_and_policy() {
        let c: StepperConfig = toml::from_str(
            "microsteps = 4\ngear_ratio = 2.5\n[policy]\nkind = \"bounded\"\nmin_rad = -3.2\nmax_rad = 3.2\n",
        )
        .unwrap();
        assert_eq!(c.microsteps, 4);
        assert!((c.steps_per_output_rev() - 2000.0).abs() < 1e-9);
        assert_eq!(
            c.policy,
            MovePolicy::Bounded {
                min_rad: -3.2,
                max_rad: 3.2
            }
        );
        let s: StepperConfig = toml::from_str("[policy]\nkind = \"shortest_path\"\n").unwrap();
        assert_eq!(s.policy, MovePolicy::ShortestPath);
        assert!(toml::from_str::<StepperConfig>("microstep = 4\n").is_err());
    }

    #[test]
    fn validation_rejects_unusable_numbers() {
        let bad = [
            StepperConfig {
                microsteps: 0,
                ..StepperConfig::default()
            },
            StepperConfig {
                gear_ratio: f64::NAN,
                ..StepperConfig::default()
            },
            StepperConfig {
                start_speed_steps_per_s: 0.5,
                ..StepperConfig::default()
            },
            StepperConfig {
                max_speed_steps_per_s: 50.0,
                ..StepperConfig::default()
            },
            StepperConfig {
                max_speed_steps_per_s: 1e6,
                ..StepperConfig::default()
            },
            StepperConfig {
                accel_steps_per_s2: 0.0,
                ..StepperConfig::default()
            },
            StepperConfig {
                policy: MovePolicy::Bounded {
                    min_rad: 0.5,
                    max_rad: 1.0,
                },
                ..StepperConfig::default()
            },
        ];
        for c in bad {
            assert!(
                matches!(c.validate(), Err(StepperError::InvalidConfig(_))),
                "{c:?}"
            );
        }
        assert!(StepperConfig::default().validate().is_ok());
    }
}
