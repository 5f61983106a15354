//! Seeded wheel slip between the robot's ground motion and its encoders, applied to the
//! odometry increments the pipeline receives.
//!
//! `rfloc_aria::WheelSlip` perturbs the emulator's ground truth instead (the encoders stay
//! exact). Its draws are a function of the simulated tick, so in a lock-step trial it would be
//! reproducible as well; the trial keeps the error on the odometry side, where the filter's
//! noise model describes it. Here the draws happen only for increments in which the wheels
//! turned; the error model is the emulator's (a relative Gaussian error of each wheel's travel
//! per substep).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
pub use rfloc_ekfslam::wheel_travel;
use rfloc_pose::Pose2;

/// Relative per-substep wheel travel error.
pub struct OdometrySlip {
    rng: ChaCha8Rng,
    sigma: f64,
    track_m: f64,
    substep_s: f64,
}

/// The pose change of driving `ds` along an arc that turns by `dth` (midpoint heading).
#[must_use]
pub fn arc(ds: f64, dth: f64) -> Pose2 {
    let half = dth / 2.0;
    Pose2::new(ds * half.cos(), ds * half.sin(), dth)
}

impl OdometrySlip {
    /// Slip of relative σ `sigma` per `substep_s` for a base with wheel track `track_m`.
    #[must_use]
    pub fn new(seed: u64, sigma: f64, track_m: f64, substep_s: f64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            sigma,
            track_m,
            substep_s,
        }
    }

    fn gaussian(&mut self) -> f64 {
        // Box–Muller; 1 − u keeps the logarithm finite.
        let u: f64 = self.rng.random();
        let v: f64 = self.rng.random();
        (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// The increment the encoders report for a ground increment `delta` that took `dt`
    /// seconds. An increment without wheel motion is returned unchanged and draws nothing.
    pub fn apply(&mut self, delta: &Pose2, dt: f64) -> Pose2 {
        let (sl, sr) = wheel_travel(delta, self.track_m);
        if (sl.abs() < 1e-9 && sr.abs() < 1e-9) || self.sigma <= 0.0 {
            return *delta;
        }
        // n substeps of equal travel: the relative errors add up to σ·s/√n.
        let n = (dt / self.substep_s).round().max(1.0);
        let k = self.sigma / n.sqrt();
        let el = self.gaussian() * k * sl.abs();
        let er = self.gaussian() * k * sr.abs();
        let (sl, sr) = (sl + el, sr + er);
        arc((sl + sr) / 2.0, (sr - sl) / self.track_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standstill_draws_nothing_and_motion_is_seeded() {
        let mut a = OdometrySlip::new(7, 0.05, 0.357, 0.01);
        let mut b = OdometrySlip::new(7, 0.05, 0.357, 0.01);
        let zero = Pose2::new(0.0, 0.0, 0.0);
        assert_eq!(a.apply(&zero, 0.1), zero);
        let step = arc(0.03, 0.01);
        // `a` saw a standstill first, `b` did not: same draws for the same motion.
        assert_eq!(a.apply(&step, 0.1), b.apply(&step, 0.1));
        assert_ne!(a.apply(&step, 0.1), step);
    }

    #[test]
    fn travel_error_has_the_model_spread() {
        let mut s = OdometrySlip::new(1, 0.05, 0.357, 0.01);
        let step = arc(0.03, 0.0);
        let n = 20_000;
        let sq: f64 = (0..n).map(|_| (s.apply(&step, 0.1).x - 0.03).powi(2)).sum();
        // Mean of two wheels, each σ = 0.05·0.03/√10.
        let want = 0.05 * 0.03 / 10f64.sqrt() / 2f64.sqrt();
        let got = (sq / f64::from(n)).sqrt();
        assert!((got / want - 1.0).abs() < 0.05, "{got} vs {want}");
    }

    #[test]
    fn wheel_travel_round_trips_through_arc() {
        let d = arc(0.05, -0.2);
        let (l, r) = wheel_travel(&d, 0.357);
        let back = arc((l + r) / 2.0, (r - l) / 0.357);
        assert!(back.distance(&d) < 1e-12 && (back.theta - d.theta).abs() < 1e-12);
    }
}
