//! One back-off policy for every device: the wait before reconnecting a link or restarting a
//! device task grows from `initial` to `max`, each wait spread by ±`jitter` (a fraction) so that
//! devices that failed together do not retry together. The spread is drawn from the device's
//! name and the attempt number, so a run's waits are reproducible.

use std::time::Duration;

/// The back-off policy (`[supervision]` of the robot file).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backoff {
    /// First wait, seconds.
    pub initial_s: f64,
    /// Longest wait, seconds.
    pub max_s: f64,
    /// Spread of each wait, a fraction of it (0: none).
    pub jitter: f64,
}

impl Default for Backoff {
    fn default() -> Self {
        Self {
            initial_s: 0.5,
            max_s: 30.0,
            jitter: 0.2,
        }
    }
}

/// SplitMix64: a well-mixed 64-bit value from a seed.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A stable 64-bit seed of a device name (FNV-1a).
#[must_use]
pub fn seed_of(name: &str) -> u64 {
    name.bytes().fold(0xCBF2_9CE4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01B3)
    })
}

impl Backoff {
    /// The wait before attempt `attempt` (0-based) of the device seeded `seed`: `initial_s`
    /// doubled per attempt up to `max_s`, times a factor in `[1 − jitter, 1 + jitter]`, never
    /// above `max_s` or below zero.
    #[must_use]
    pub fn delay(&self, attempt: u32, seed: u64) -> Duration {
        let base = self.initial_s * 2f64.powi(i32::try_from(attempt.min(40)).unwrap_or(40));
        let base = base.min(self.max_s);
        // A uniform draw in [-1, 1) from the seed and the attempt.
        #[allow(clippy::cast_precision_loss)]
        let u = (mix(seed ^ u64::from(attempt).wrapping_mul(0x2545_F491_4F6C_DD1D)) >> 11) as f64
            / (1u64 << 53) as f64;
        let spread = 1.0 + self.jitter * (2.0 * u - 1.0);
        let secs = (base * spread).clamp(0.0, self.max_s);
        Duration::try_from_secs_f64(secs).unwrap_or(Duration::ZERO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_double_to_the_cap_within_the_jitter() {
        let b = Backoff::default();
        let seed = seed_of("base");
        let waits: Vec<f64> = (0..10).map(|a| b.delay(a, seed).as_secs_f64()).collect();
        for (a, w) in waits.iter().enumerate() {
            let nominal = (0.5 * 2f64.powi(a as i32)).min(30.0);
            assert!(
                *w >= nominal * 0.8 - 1e-9 && *w <= (nominal * 1.2).min(30.0) + 1e-9,
                "attempt {a}: {w} s"
            );
        }
        assert!(waits[9] <= 30.0);
        // Reproducible, and different devices spread apart.
        assert_eq!(b.delay(3, seed), b.delay(3, seed));
        assert_ne!(b.delay(3, seed), b.delay(3, seed_of("hf")));
        // No jitter: exactly the doubling.
        let plain = Backoff {
            jitter: 0.0,
            ..Backoff::default()
        };
        assert_eq!(plain.delay(2, seed), Duration::from_secs(2));
        assert_eq!(plain.delay(30, seed), Duration::from_secs(30));
    }
}
