//! Prints the mean cost of one velocity prediction plus one range-bearing update, in
//! nanoseconds, for 4, 50 and 200 mapped beacons: one line `rust <beacons> <ns>` each.
//! Used by `benches/compare.sh` next to the same sequence in filterpy.
#![allow(clippy::expect_used)]

use std::time::Instant;

use nalgebra::Matrix3;
use rfloc_ekfslam::{BeaconObservation, EkfSlam, EkfSlamConfig};
use rfloc_pose::Pose2;

fn main() {
    for (n, iters) in [(4usize, 20_000u32), (50, 5_000), (200, 1_000)] {
        let mut f = EkfSlam::new(
            EkfSlamConfig::default(),
            Pose2::new(0.0, 0.0, 0.0),
            Matrix3::identity() * 1e-4,
        )
        .expect("valid start");
        let ring = |i: usize| i as f64 / n as f64 * std::f64::consts::TAU;
        let obs: Vec<_> = (0..n)
            .map(|i| BeaconObservation::range_bearing(i as u64, 5.0, ring(i), 0.1, 0.05))
            .collect();
        f.update(&obs);
        let start = Instant::now();
        for k in 0..iters {
            f.predict_velocity(0.0, 0.0, 0.1).expect("finite");
            let id = k as usize % n;
            let out = f.update(&[BeaconObservation::range_bearing(
                id as u64,
                5.0,
                ring(id),
                0.1,
                0.05,
            )]);
            std::hint::black_box(out);
        }
        let ns = start.elapsed().as_nanos() as f64 / f64::from(iters);
        println!("rust {n} {ns:.0}");
    }
}
