//! A small seeded world for the integration tests: a unicycle robot driven by noisy velocity
//! commands and radio beacons observed in range/RSSI and bearing with Gaussian noise.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rfloc_pose::{wrap_angle, Pose2};

/// Draws N(0, σ²).
pub fn gauss(rng: &mut ChaCha8Rng, sigma: f64) -> f64 {
    if sigma <= 0.0 {
        return 0.0;
    }
    Normal::new(0.0, sigma).unwrap().sample(rng)
}

/// True motion: the commanded (v, ω) plus N(0, σ²) each, integrated with the same midpoint rule
/// as the filter (so the filter's process model is exact up to its noise).
pub fn step_truth(
    p: &Pose2,
    v: f64,
    w: f64,
    dt: f64,
    sigma_v: f64,
    sigma_w: f64,
    rng: &mut ChaCha8Rng,
) -> Pose2 {
    let vt = v + gauss(rng, sigma_v);
    let wt = w + gauss(rng, sigma_w);
    let phi = p.theta + wt * dt / 2.0;
    Pose2::new(
        p.x + vt * dt * phi.cos(),
        p.y + vt * dt * phi.sin(),
        p.theta + wt * dt,
    )
}

/// Noise-free range and bearing from `p` to `(bx, by)`.
pub fn range_bearing(p: &Pose2, bx: f64, by: f64) -> (f64, f64) {
    let dx = bx - p.x;
    let dy = by - p.y;
    (dx.hypot(dy), wrap_angle(dy.atan2(dx) - p.theta))
}

/// Uniform in [lo, hi).
pub fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}
