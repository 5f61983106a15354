//! Synthetic reader output for the tests: which tags the antenna reports at a pose, with the
//! RSSI the model gives, optionally with missed reads and heading error.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rfloc_hfgrid::{RssiModel, TagGrid, TagReading, TurnStop};
use rfloc_pose::Pose2;

/// Antenna position for a robot pose (antenna 10 cm behind the centre, as in seed 002).
pub fn antenna(p: &Pose2, offset: (f64, f64)) -> (f64, f64) {
    p.transform_point(offset.0, offset.1)
}

/// One scan: every tag within range is reported with probability `p_read` and the noise-free
/// RSSI of `model` at its distance.
pub fn scan(
    grid: &TagGrid,
    model: &RssiModel,
    p: &Pose2,
    offset: (f64, f64),
    p_read: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<TagReading> {
    let (ax, ay) = antenna(p, offset);
    grid.tags_within(ax, ay, model.max_range_m())
        .into_iter()
        .filter_map(|(uid, tx, ty)| {
            let r = model.rssi_for_distance((tx - ax).hypot(ty - ay))?;
            (rng.random::<f64>() < p_read).then_some(TagReading {
                uid,
                rssi_first: r,
                rssi_second: r,
            })
        })
        .collect()
}

/// The eight-stop turn from `start`: at stop k the robot has turned `k·45° + jitter` while the
/// stop records the nominal `k·45°`; `scans` scans per stop.
pub fn turn(
    grid: &TagGrid,
    model: &RssiModel,
    start: &Pose2,
    heading_jitter_rad: f64,
    p_read: f64,
    scans: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<TurnStop> {
    (0..8)
        .map(|k| {
            let nominal = f64::from(k) * std::f64::consts::FRAC_PI_4;
            let jitter = if heading_jitter_rad > 0.0 {
                (rng.random::<f64>() * 2.0 - 1.0) * heading_jitter_rad
            } else {
                0.0
            };
            let pose = Pose2::new(start.x, start.y, start.theta + nominal + jitter);
            let readings = (0..scans)
                .flat_map(|_| scan(grid, model, &pose, (-0.10, 0.0), p_read, rng))
                .collect();
            TurnStop {
                heading_rad: nominal,
                readings,
            }
        })
        .collect()
}
