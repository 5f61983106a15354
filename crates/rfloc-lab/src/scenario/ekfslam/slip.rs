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

/// Relative per-substep wheel travel error, and an optional additive speed error.
pub struct OdometrySlip {
    rng: ChaCha8Rng,
    sigma: f64,
    track_m: f64,
    substep_s: f64,
    /// σ_v (m/s), σ_ω (rad/s) and their own generator (so the slip draws do not move).
    velocity: Option<(f64, f64, ChaCha8Rng)>,
    /// Encoder scale: the odometry's wheel diameter over the true one (1 = calibrated).
    wheel_scale: f64,
}

/// The pose change of driving `ds` along an arc that turns by `dth` (midpoint heading).
#[must_use]
pub fn arc(ds: f64, dth: f64) -> Pose2 {
    let half = dth / 2.0;
    Pose2::new(ds * half.cos(), ds * half.sin(), dth)
}

/// A standard normal draw (Box–Muller; 1 − u keeps the logarithm finite).
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = rng.random();
    let v: f64 = rng.random();
    (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
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
            velocity: None,
            wheel_scale: 1.0,
        }
    }

    /// Wheels of diameter `true_m` under odometry that assumes `nominal_m`: every wheel travel
    /// the encoders report is `nominal_m / true_m` times the true one.
    #[must_use]
    pub fn with_wheel_diameter(mut self, true_m: f64, nominal_m: f64) -> Self {
        if true_m > 0.0 && nominal_m > 0.0 {
            self.wheel_scale = nominal_m / true_m;
        }
        self
    }

    /// Adds an error of the driven speed and turn rate, N(0, σ_v) m/s and N(0, σ_ω) rad/s over
    /// every increment in which the wheels turned (seed 003 Table 3.1), drawn from a generator
    /// seeded with `seed`.
    #[must_use]
    pub fn with_velocity_noise(mut self, sigma_v: f64, sigma_omega: f64, seed: u64) -> Self {
        self.velocity = (sigma_v > 0.0 || sigma_omega > 0.0)
            .then(|| (sigma_v, sigma_omega, ChaCha8Rng::seed_from_u64(seed)));
        self
    }

    fn gaussian(&mut self) -> f64 {
        gaussian(&mut self.rng)
    }

    /// The increment the encoders report for a ground increment `delta` that took `dt`
    /// seconds. An increment without wheel motion is returned unchanged and draws nothing.
    pub fn apply(&mut self, delta: &Pose2, dt: f64) -> Pose2 {
        let scaled;
        let delta = if (self.wheel_scale - 1.0).abs() > 1e-12 {
            let k = self.wheel_scale;
            scaled = arc(
                k * delta.x.hypot(delta.y).copysign(delta.x),
                k * delta.theta,
            );
            &scaled
        } else {
            delta
        };
        let (sl, sr) = wheel_travel(delta, self.track_m);
        if sl.abs() < 1e-9 && sr.abs() < 1e-9 {
            return *delta;
        }
        let slipped = self.slip(delta, dt, sl, sr);
        match &mut self.velocity {
            Some((sv, sw, rng)) => {
                let dv = gaussian(rng) * *sv * dt;
                let dw = gaussian(rng) * *sw * dt;
                let d = slipped.x.hypot(slipped.y).copysign(slipped.x) + dv;
                arc(d, slipped.theta + dw)
            }
            None => slipped,
        }
    }

    fn slip(&mut self, delta: &Pose2, dt: f64, sl: f64, sr: f64) -> Pose2 {
        if self.sigma <= 0.0 {
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
    fn velocity_noise_has_its_spread_and_leaves_the_slip_draws_alone() {
        let step = arc(0.03, 0.0);
        let mut plain = OdometrySlip::new(4, 0.05, 0.331, 0.01);
        let mut noisy = OdometrySlip::new(4, 0.05, 0.331, 0.01).with_velocity_noise(0.02, 0.01, 9);
        let mut exact = OdometrySlip::new(4, 0.0, 0.331, 0.01).with_velocity_noise(0.02, 0.01, 9);
        let n = 20_000;
        let (mut sq_d, mut sq_th) = (0.0, 0.0);
        for _ in 0..n {
            let a = plain.apply(&step, 0.1);
            let b = noisy.apply(&step, 0.1);
            // Same slip draws: the difference is the velocity noise only (small).
            assert!((a.x - b.x).abs() < 0.02 * 0.1 * 6.0, "{a:?} {b:?}");
            let c = exact.apply(&step, 0.1);
            sq_d += (c.x.hypot(c.y) - 0.03).powi(2);
            sq_th += c.theta.powi(2);
        }
        let sd = (sq_d / f64::from(n)).sqrt();
        let sth = (sq_th / f64::from(n)).sqrt();
        assert!((sd / 0.002 - 1.0).abs() < 0.05, "{sd}");
        assert!((sth / 0.001 - 1.0).abs() < 0.05, "{sth}");
        // A standstill stays exact.
        let zero = Pose2::new(0.0, 0.0, 0.0);
        assert_eq!(exact.apply(&zero, 0.1), zero);
    }

    #[test]
    fn larger_wheels_than_calibrated_make_odometry_short() {
        let mut s = OdometrySlip::new(1, 0.0, 0.331, 0.01).with_wheel_diameter(0.2145, 0.195);
        let d = s.apply(&arc(0.11, 0.01), 0.1);
        assert!((d.x.hypot(d.y) - 0.1).abs() < 1e-9, "{d:?}");
        assert!((d.theta - 0.01 / 1.1).abs() < 1e-9, "{d:?}");
    }

    #[test]
    fn wheel_travel_round_trips_through_arc() {
        let d = arc(0.05, -0.2);
        let (l, r) = wheel_travel(&d, 0.357);
        let back = arc((l + r) / 2.0, (r - l) / 0.357);
        assert!(back.distance(&d) < 1e-12 && (back.theta - d.theta).abs() < 1e-12);
    }
}
