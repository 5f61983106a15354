//! STEP/DIR timing constants and the acceleration ramp.
//!
//! Datasheet minimums (see `docs/protocols/stepper-gpio.md` for sources):
//!
//! | figure | A4988 | DRV8825 | used here |
//! |---|---|---|---|
//! | STEP high pulse width | 1 µs | 1.9 µs | [`STEP_PULSE_NS`] = 5 µs |
//! | STEP low pulse width | 1 µs | 1.9 µs | [`STEP_LOW_MIN_NS`] = 5 µs |
//! | DIR setup before STEP rising edge | 200 ns | 650 ns | [`DIR_SETUP_NS`] = 5 µs |
//! | DIR hold after STEP rising edge | 200 ns | 650 ns | covered by the step interval |
//! | wake-up from sleep before first STEP | 1 ms | 1.7 ms | [`ENABLE_SETTLE_NS`] = 2 ms |
//!
//! The margins are deliberate: a Linux GPIO ioctl already takes tens of microseconds, so the
//! cost is nil, and reports of DRV882x parts skipping steps near the 1.9 µs minimum exist.

/// Width of the STEP high pulse, ns (≥ 1.9 µs DRV8825, ≥ 1 µs A4988).
pub const STEP_PULSE_NS: u32 = 5_000;
/// Minimum STEP low time between pulses, ns (≥ 1.9 µs DRV8825, ≥ 1 µs A4988).
pub const STEP_LOW_MIN_NS: u32 = 5_000;
/// Delay between setting DIR and the next STEP rising edge, ns (≥ 650 ns DRV8825, ≥ 200 ns A4988).
pub const DIR_SETUP_NS: u32 = 5_000;
/// Delay after asserting ENABLE before the first STEP, ns. Covers the wake-up time of both
/// parts (1 ms A4988, 1.7 ms DRV8825) for boards that tie ENABLE and SLEEP together.
pub const ENABLE_SETTLE_NS: u32 = 2_000_000;
/// Highest step rate the pulse timing allows, steps/s.
pub const MAX_STEP_RATE_HZ: f64 = 1e9 / (STEP_PULSE_NS as f64 + STEP_LOW_MIN_NS as f64);

/// A trapezoidal speed profile in steps per second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RampProfile {
    /// Speed of the first and last step.
    pub start_speed: f64,
    /// Cruise speed.
    pub max_speed: f64,
    /// Acceleration, steps/s².
    pub accel: f64,
}

impl RampProfile {
    /// Period of step `i` (0-based) of an `n`-step move, in ns.
    ///
    /// The speed after `k` steps of constant acceleration from `v0` is `sqrt(v0² + 2 a k)`;
    /// the profile is symmetric, so step `i` uses `k = min(i, n - 1 - i)`, capped at the cruise
    /// speed. Short moves give a triangle, long ones a trapezoid. The period never drops below
    /// `STEP_PULSE_NS + STEP_LOW_MIN_NS`.
    #[must_use]
    pub fn interval_ns(&self, i: u64, n: u64) -> u32 {
        let k = i.min(n.saturating_sub(1).saturating_sub(i)) as f64;
        let v = (self.start_speed * self.start_speed + 2.0 * self.accel * k)
            .sqrt()
            .min(self.max_speed);
        let ns = (1e9 / v).round();
        let floor = f64::from(STEP_PULSE_NS + STEP_LOW_MIN_NS);
        // `as` saturates for out-of-range floats; validated configs keep v ≥ 1 step/s.
        ns.max(floor).min(f64::from(u32::MAX)) as u32
    }

    /// Total duration of an `n`-step move, seconds (for planning and the simulator).
    #[must_use]
    pub fn move_duration_s(&self, n: u64) -> f64 {
        (0..n)
            .map(|i| f64::from(self.interval_ns(i, n)) * 1e-9)
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_trapezoid() {
        let r = RampProfile {
            start_speed: 100.0,
            max_speed: 200.0,
            accel: 15_000.0,
        };
        let v: Vec<u32> = (0..5).map(|i| r.interval_ns(i, 5)).collect();
        // k = 0,1,2,1,0 -> 100 steps/s, 200 steps/s, capped 200 steps/s.
        assert_eq!(
            v,
            vec![10_000_000, 5_000_000, 5_000_000, 5_000_000, 10_000_000]
        );
    }

    #[test]
    fn single_step_uses_start_speed() {
        let r = RampProfile {
            start_speed: 50.0,
            max_speed: 500.0,
            accel: 1000.0,
        };
        assert_eq!(r.interval_ns(0, 1), 20_000_000);
        assert!((r.move_duration_s(1) - 0.02).abs() < 1e-12);
    }

    #[test]
    fn default_ramp_nine_degree_stop_duration() {
        // Defaults 100 → 400 steps/s at 800 steps/s²; 5 steps = 9° on a 1.8° motor.
        let r = RampProfile {
            start_speed: 100.0,
            max_speed: 400.0,
            accel: 800.0,
        };
        assert!((r.move_duration_s(5) - 0.047_273).abs() < 1e-6);
    }

    #[test]
    fn period_never_below_pulse_limits() {
        let r = RampProfile {
            start_speed: 1e9,
            max_speed: 1e9,
            accel: 1.0,
        };
        assert_eq!(r.interval_ns(0, 1), STEP_PULSE_NS + STEP_LOW_MIN_NS);
    }
}
