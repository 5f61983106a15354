//! How one of the seed's five actions becomes a velocity command for the Pioneer.
//!
//! Seed 000 Table 4 gives each action a velocity pair applied for one simulation step; the
//! scenario reads a step as `action_duration_s` (0.1 s), so forward moves 0.25 m and the arcs
//! and rotations turn π/20 rad per step. A P3-DX cannot do 2.5 m/s, so the trial drives the same
//! displacement over a longer time: the command is scaled by `action_duration / drive_duration`.
//! The action noise of the scenario (`drive.sigma_v`, `drive.sigma_omega`, Gaussian, in Table 4
//! units) is added to the nominal command before scaling, and the noisy command is clamped to
//! the scenario's `max_speed` / `max_turn_rate`, also in Table 4 units.

use rand::Rng;
use rfloc_snapshot::{Action, ActionTable, MotionCommand};

/// Turns actions into drive commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Actuation {
    /// Nominal commands (seed Table 4).
    pub table: ActionTable,
    /// Duration of one action in the seed's units, seconds.
    pub action_duration_s: f64,
    /// Simulated seconds the Pioneer takes to drive one action.
    pub drive_duration_s: f64,
    /// σ of the Gaussian noise on v and ω, Table 4 units (m/s, rad/s).
    pub sigma_v: f64,
    pub sigma_omega: f64,
    /// Limits of the noisy command, Table 4 units.
    pub max_speed: f64,
    pub max_turn_rate: f64,
}

/// One standard normal draw (Box–Muller).
fn standard_normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl Actuation {
    /// The noisy command of `action` in Table 4 units (what the seed's simulator would apply for
    /// `action_duration_s`).
    pub fn noisy<R: Rng + ?Sized>(&self, action: Action, rng: &mut R) -> MotionCommand {
        let n = self.table.nominal(action);
        let v = n.v + self.sigma_v * standard_normal(rng);
        let omega = n.omega + self.sigma_omega * standard_normal(rng);
        MotionCommand {
            v: v.clamp(-self.max_speed, self.max_speed),
            omega: omega.clamp(-self.max_turn_rate, self.max_turn_rate),
        }
    }

    /// The Pioneer command that drives `seed_command`'s displacement in `drive_duration_s`.
    #[must_use]
    pub fn drive_command(&self, seed_command: MotionCommand) -> MotionCommand {
        let k = if self.drive_duration_s > 0.0 {
            self.action_duration_s / self.drive_duration_s
        } else {
            1.0
        };
        MotionCommand {
            v: seed_command.v * k,
            omega: seed_command.omega * k,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn actuation(sigma: f64) -> Actuation {
        Actuation {
            table: ActionTable::seed_table(),
            action_duration_s: 0.1,
            drive_duration_s: 0.5,
            sigma_v: sigma,
            sigma_omega: sigma,
            max_speed: 3.5,
            max_turn_rate: 2.2,
        }
    }

    #[test]
    fn drive_command_keeps_the_step_displacement() {
        let a = actuation(0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let seed_cmd = a.noisy(Action::ArcLeft, &mut rng);
        assert!((seed_cmd.v - 2.5).abs() < 1e-12);
        let d = a.drive_command(seed_cmd);
        // 0.25 m and π/20 rad either way.
        assert!((d.v * 0.5 - 0.25).abs() < 1e-12);
        assert!((d.omega * 0.5 - std::f64::consts::PI / 20.0).abs() < 1e-12);
    }

    #[test]
    fn noise_has_the_scenario_spread_and_is_clamped() {
        let a = actuation(0.577);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let vs: Vec<f64> = (0..4000)
            .map(|_| a.noisy(Action::Forward, &mut rng).v)
            .collect();
        let mean = vs.iter().sum::<f64>() / vs.len() as f64;
        let sd = (vs.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vs.len() as f64).sqrt();
        assert!((mean - 2.5).abs() < 0.05, "mean {mean}");
        assert!((sd - 0.577).abs() < 0.05, "sd {sd}");
        assert!(vs.iter().all(|v| *v <= 3.5));
        let wide = actuation(50.0);
        let c = wide.noisy(Action::RotateLeft, &mut rng);
        assert!(c.v.abs() <= 3.5 && c.omega.abs() <= 2.2);
    }
}
