//! Forward model of the four-antenna array, for tests and simulators.
//!
//! `RSS_k = A1 − 10·A2·log10(d) + (F/2)·cos(ψ − α_k)`, where `d` is the emitter distance,
//! `ψ` the emitter bearing in the robot frame, `α_k ∈ {0, π, π/2, −π/2}` the boresight of the
//! front, back, left and right antenna and `F` the front-to-back ratio of one reflector (dB).
//! Noise is optional: i.i.d. Gaussian per antenna with standard deviation `σ` dB.

use rand::Rng;
use rand_distr::{Distribution, Normal};
use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

use crate::antenna::{AntennaRss, DifferentialRssConfig};
use crate::Point2;

/// Parameters of the simulated array. Defaults: `A1 = −45 dBm`, `A2 = 2`, `F = 12 dB`,
/// `σ = 2 dB`, distances below 0.1 m treated as 0.1 m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DirectionalArrayModel {
    /// Mean RSS over the four antennas at 1 m, dBm (`A1`).
    pub a1_dbm_at_1m: f64,
    /// Path-loss exponent (`A2`).
    pub a2_path_loss_exponent: f64,
    /// Front-to-back ratio of one antenna with its reflector, dB.
    pub front_to_back_db: f64,
    /// Standard deviation of the per-antenna Gaussian noise, dB (used by [`Self::sample`]).
    pub noise_std_db: f64,
}

impl Default for DirectionalArrayModel {
    fn default() -> Self {
        Self {
            a1_dbm_at_1m: -45.0,
            a2_path_loss_exponent: 2.0,
            front_to_back_db: 12.0,
            noise_std_db: 2.0,
        }
    }
}

impl DirectionalArrayModel {
    /// The calibration the inverse ([`crate::differential_range_bearing`]) needs to match this
    /// model exactly (range clamps at their defaults).
    #[must_use]
    pub fn matching_calibration(&self) -> DifferentialRssConfig {
        DifferentialRssConfig {
            a1_dbm_at_1m: self.a1_dbm_at_1m,
            a2_path_loss_exponent: self.a2_path_loss_exponent,
            ..DifferentialRssConfig::default()
        }
    }

    /// Noise-free RSS of the four antennas for a robot pose and emitter position.
    #[must_use]
    pub fn expected(&self, robot: &Pose2, emitter: &Point2) -> AntennaRss {
        let dx = emitter.x - robot.x;
        let dy = emitter.y - robot.y;
        let d = dx.hypot(dy).max(0.1);
        let psi = dy.atan2(dx) - robot.theta;
        let level = self.a1_dbm_at_1m - 10.0 * self.a2_path_loss_exponent * d.log10();
        let half = self.front_to_back_db / 2.0;
        AntennaRss {
            front: level + half * psi.cos(),
            back: level - half * psi.cos(),
            left: level + half * psi.sin(),
            right: level - half * psi.sin(),
        }
    }

    /// [`Self::expected`] plus i.i.d. Gaussian noise of `noise_std_db` on each antenna. A
    /// non-positive or non-finite standard deviation gives the noise-free reading.
    pub fn sample<R: Rng + ?Sized>(
        &self,
        robot: &Pose2,
        emitter: &Point2,
        rng: &mut R,
    ) -> AntennaRss {
        let mut rss = self.expected(robot, emitter);
        if let Ok(normal) = Normal::new(0.0, self.noise_std_db) {
            if self.noise_std_db > 0.0 {
                rss.front += normal.sample(rng);
                rss.back += normal.sample(rng);
                rss.left += normal.sample(rng);
                rss.right += normal.sample(rng);
            }
        }
        rss
    }
}
