//! Synthetic sweeps shared by the tests: log-distance path loss plus a reflector pattern.
#![allow(dead_code)]

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rfloc_bearing::{PathLossModel, ReflectorPattern, Sweep, SweepSample};

/// A beacon in the world frame.
#[derive(Debug, Clone, Copy)]
pub struct Beacon {
    pub id: u64,
    pub x: f64,
    pub y: f64,
}

/// True range and bearing (relative to `theta`) from `(x, y, theta)` to `b`.
pub fn truth(x: f64, y: f64, theta: f64, b: &Beacon) -> (f64, f64) {
    let (dx, dy) = (b.x - x, b.y - y);
    (dx.hypot(dy), rfloc_pose::wrap_angle(dy.atan2(dx) - theta))
}

/// Noise-free RSSI of `b` with the antenna at `antenna` on a robot at `(x, y, theta)`.
pub fn rssi(
    model: &PathLossModel,
    pattern: &ReflectorPattern,
    (x, y, theta): (f64, f64, f64),
    antenna: f64,
    b: &Beacon,
) -> f64 {
    let (r, bearing) = truth(x, y, theta, b);
    model.rssi_at(r) + pattern.gain_db(bearing - antenna)
}

/// A sweep at the given antenna angles. Each beacon gets one shadowing offset per sweep
/// (`shadow_db` σ) and every reading gets independent noise (`noise_db` σ). `heading(i)` gives
/// the robot heading at stop `i`.
pub fn sweep(
    beacons: &[Beacon],
    pose_xy: (f64, f64),
    heading: impl Fn(usize) -> f64,
    angles: &[f64],
    shadow_db: f64,
    noise_db: f64,
    seed: u64,
) -> Sweep {
    let model = PathLossModel::default();
    let pattern = ReflectorPattern::default();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let shadow = Normal::new(0.0, shadow_db.max(1e-12)).unwrap();
    let noise = Normal::new(0.0, noise_db.max(1e-12)).unwrap();
    let offsets: Vec<f64> = beacons.iter().map(|_| shadow.sample(&mut rng)).collect();
    let samples = angles
        .iter()
        .enumerate()
        .map(|(i, &a)| {
            let th = heading(i);
            SweepSample {
                antenna_rad: a,
                heading_rad: th,
                readings: beacons
                    .iter()
                    .zip(&offsets)
                    .map(|(b, off)| {
                        let v = rssi(&model, &pattern, (pose_xy.0, pose_xy.1, th), a, b);
                        (b.id, v + off + noise.sample(&mut rng))
                    })
                    .collect(),
            }
        })
        .collect();
    Sweep { samples }
}

/// The seed's 9° full-turn stops, −180° … 171°.
pub fn seed_stops() -> Vec<f64> {
    (0..40)
        .map(|i| (-180.0 + 9.0 * i as f64).to_radians())
        .collect()
}

/// The four beacons of the seed's bearing test (Table 4.2), robot at (1, 1).
pub fn seed_beacons() -> Vec<Beacon> {
    vec![
        Beacon {
            id: 1,
            x: 0.0,
            y: 0.0,
        },
        Beacon {
            id: 2,
            x: 0.0,
            y: 3.0,
        },
        Beacon {
            id: 3,
            x: 3.0,
            y: 0.0,
        },
        Beacon {
            id: 4,
            x: 3.0,
            y: 3.0,
        },
    ]
}
