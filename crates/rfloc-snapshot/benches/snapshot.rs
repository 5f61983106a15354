//! Criterion benchmarks: FasterPAM on 1625 objects (k = 812), value iteration on
//! 1000 states × 5 actions, learning the tag map of seed 000's world from 1000 survey
//! snapshots, and one particle-filter update on it (1500 particles).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod problems;

use criterion::{criterion_group, criterion_main, Criterion};
use rfloc_snapshot::cluster::fasterpam;
use rfloc_snapshot::{value_iteration, ValueIterationConfig};

fn clustering(c: &mut Criterion) {
    let d = problems::clustering_problem(1625);
    let init = problems::initial_medoids(1625);
    let mut g = c.benchmark_group("clustering");
    g.sample_size(10);
    g.bench_function("fasterpam_1625_k812", |b| {
        b.iter(|| fasterpam::fasterpam(&d, init.clone(), 100))
    });
    g.bench_function("dissimilarity_matrix_1625", |b| {
        b.iter(|| problems::clustering_problem(1625))
    });
    g.finish();
}

fn planning(c: &mut Criterion) {
    let (m, r) = problems::vi_model(1000);
    let cfg = ValueIterationConfig {
        discount: 0.95,
        epsilon: 0.01,
        max_iter: 1000,
    };
    c.bench_function("value_iteration_1000x5", |b| {
        b.iter(|| value_iteration(&m, &r, &cfg).unwrap())
    });
}

fn tag_map(c: &mut Criterion) {
    use rand::SeedableRng;
    use rfloc_snapshot::{ReadModel, TagMap, TagMapConfig, TrackConfig, TrackFilter};
    let model = ReadModel::seed000(1000.0, 2);
    let (tags, survey) = problems::tag_survey(&model);
    let pairs = || survey.iter().map(|(s, p)| (s, *p));
    let mut g = c.benchmark_group("tag_map");
    g.sample_size(10);
    g.bench_function("learn_800_tags_1000_snapshots", |b| {
        b.iter(|| TagMap::learn(pairs(), model.clone(), TagMapConfig::default()))
    });
    let map = TagMap::learn(pairs(), model.clone(), TagMapConfig::default());
    let prints =
        rfloc_snapshot::FingerprintMap::new(pairs(), rfloc_snapshot::SnapshotDistance::RssL1);
    let truth = rfloc_pose::Pose2::new(2.5, 2.5, 0.4);
    let snapshot = problems::tag_snapshot(&model, &tags, &truth);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut filter = TrackFilter::new(TrackConfig::default());
    filter.update_with_map(&map, &prints, &snapshot, &mut rng);
    g.bench_function("track_update_1500_particles", |b| {
        b.iter(|| {
            let mut f = filter.clone();
            f.update_with_map(&map, &prints, &snapshot, &mut rng);
            f.estimate()
        })
    });
    g.finish();
}

criterion_group!(benches, clustering, planning, tag_map);
criterion_main!(benches);
