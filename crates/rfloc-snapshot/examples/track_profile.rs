//! Times the parts of one particle-filter update on the tag map (seed 000's world, 1000
//! particles): `cargo run --release -p rfloc-snapshot --example track_profile`. Each part:
//! mean wall and CPU time per call, and the best of 20 batches (on a shared machine the least
//! disturbed; compare builds by running them alternately). `ONLY=estimate` (a name prefix)
//! times one part, longer, for a profiler such as `perf record`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

#[path = "../benches/problems.rs"]
mod problems;

use std::time::Instant;

use rand::SeedableRng;
use rfloc_pose::Pose2;
use rfloc_snapshot::{
    FingerprintMap, LikelihoodScratch, ReadModel, SnapshotDistance, TagMap, TagMapConfig,
    TrackConfig, TrackFilter,
};

/// This thread's time on a CPU, ns (Linux `schedstat`; 0 elsewhere): on a shared machine
/// it does not count the time other processes held the core.
fn cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

/// Mean over `reps` calls (wall and CPU time), and the best mean of 20 batches of `reps / 20`
/// (the least disturbed by other processes on a shared machine).
fn time<T>(name: &str, reps: usize, mut f: impl FnMut() -> T) {
    // `ONLY=part` times only the parts whose name starts with `part`, 200 times as often (for
    // a profiler).
    let reps = match std::env::var("ONLY") {
        Ok(only) if name.starts_with(&only) => reps * 200,
        Ok(_) => return,
        Err(_) => reps,
    };
    let _ = f();
    let batch = (reps / 20).max(1);
    let mut best = f64::INFINITY;
    let t = Instant::now();
    let c = cpu_ns();
    for _ in 0..20 {
        let b = Instant::now();
        for _ in 0..batch {
            std::hint::black_box(f());
        }
        best = best.min(b.elapsed().as_secs_f64() * 1e6 / batch as f64);
    }
    let n = (20 * batch) as f64;
    let cpu = (cpu_ns() - c) as f64 / 1e3 / n;
    println!(
        "{name:<40} {:>9.2} µs wall {cpu:>9.2} µs cpu {best:>9.2} µs best batch",
        t.elapsed().as_secs_f64() * 1e6 / n
    );
}

fn main() {
    let model = ReadModel::seed000(1000.0, 2);
    let (tags, survey) = problems::tag_survey(&model);
    let pairs = || survey.iter().map(|(s, p)| (s, *p));
    let map = TagMap::learn(pairs(), model.clone(), TagMapConfig::default());
    let prints = FingerprintMap::new(pairs(), SnapshotDistance::RssL1);
    let truth = Pose2::new(2.5, 2.5, 0.4);
    let snapshot = problems::tag_snapshot(&model, &tags, &truth);
    println!("snapshot: {} tags; map {} tags", snapshot.len(), map.len());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut filter = TrackFilter::new(TrackConfig {
        particles: 1000,
        ..TrackConfig::default()
    });
    for _ in 0..5 {
        filter.predict(&Pose2::default(), &mut rng);
        filter.update_with_map(&map, &prints, &snapshot, &mut rng);
    }
    let poses = filter.particles().0.to_vec();
    let obs = map.observe(&snapshot);
    let mut scratch = LikelihoodScratch::default();
    let mut out = Vec::new();
    time("observe", 1000, || map.observe(&snapshot));
    time("log_likelihoods (1000 poses)", 1000, || {
        map.log_likelihoods(&poses, &obs, &mut scratch, &mut out);
        out.len()
    });
    let none = map.observe(&rfloc_snapshot::Snapshot::new());
    time("log_likelihoods, no reads (field only)", 1000, || {
        map.log_likelihoods(&poses, &none, &mut scratch, &mut out);
        out.len()
    });
    time("matches (k = 40)", 300, || {
        prints.matches(&snapshot, 40, 0.05)
    });
    time("estimate", 1000, || filter.estimate());
    time("clone", 1000, || filter.clone());
    time("predict", 300, || {
        let mut f = filter.clone();
        f.predict(&Pose2::new(0.05, 0.0, 0.02), &mut rng);
        f
    });
    time("update_with_map", 300, || {
        let mut f = filter.clone();
        f.update_with_map(&map, &prints, &snapshot, &mut rng);
        f
    });
    time("update_with_map + estimate", 1000, || {
        let mut f = filter.clone();
        f.update_with_map(&map, &prints, &snapshot, &mut rng);
        f.estimate()
    });
    println!("field tiles {:?}", map.field_tiles());
}
