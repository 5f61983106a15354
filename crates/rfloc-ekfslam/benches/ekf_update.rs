//! Cost of one velocity prediction plus one range-bearing update with 4, 50 and 200 beacons.
#![allow(clippy::expect_used)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::Matrix3;
use rfloc_ekfslam::{BeaconObservation, EkfSlam, EkfSlamConfig};
use rfloc_pose::Pose2;

/// A filter with `n` beacons on a ring of radius 5 m around the origin.
fn filter_with(n: usize) -> EkfSlam {
    let mut f = EkfSlam::new(
        EkfSlamConfig::default(),
        Pose2::new(0.0, 0.0, 0.0),
        Matrix3::identity() * 1e-4,
    )
    .expect("valid start");
    let obs: Vec<_> = (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            BeaconObservation::range_bearing(i as u64, 5.0, a, 0.1, 0.05)
        })
        .collect();
    f.update(&obs);
    f
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("predict_plus_update");
    for n in [4usize, 50, 200] {
        let mut f = filter_with(n);
        let mut k = 0u64;
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, &n| {
            b.iter(|| {
                f.predict_velocity(0.0, 0.0, 0.1).expect("finite");
                let id = k % n as u64;
                k += 1;
                let a = id as f64 / n as f64 * std::f64::consts::TAU;
                let out = f.update(&[BeaconObservation::range_bearing(id, 5.0, a, 0.1, 0.05)]);
                std::hint::black_box(out);
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
