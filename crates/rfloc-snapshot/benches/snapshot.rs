//! Criterion benchmarks: FasterPAM on 1625 objects (k = 812), the dissimilarity matrix and
//! clustering of 1625 exploration snapshots, value iteration on 1000 states × 5 actions,
//! learning the tag map of seed 000's world from 1000 survey snapshots, and particle-filter
//! updates on it.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod problems;

use criterion::{criterion_group, criterion_main, Criterion};
use rfloc_snapshot::cluster::{self, fasterpam};
use rfloc_snapshot::{
    value_iteration, ClusteringMethod, DissimilarityMatrix, SnapshotDistance, ValueIterationConfig,
};

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
    // Real snapshots: the matrix over an inverted index, then the default clustering
    // (k-means++ start, FasterPAM, k = n/2), as `SnapshotDatabase::learn` runs them.
    let snaps = problems::snapshot_problem(1625);
    g.bench_function("snapshot_matrix_1625", |b| {
        b.iter(|| DissimilarityMatrix::from_snapshots(&snaps, SnapshotDistance::RssL1))
    });
    let m = DissimilarityMatrix::from_snapshots(&snaps, SnapshotDistance::RssL1);
    g.bench_function("snapshot_cluster_1625", |b| {
        b.iter(|| cluster::cluster(&m, &ClusteringMethod::default()))
    });
    g.bench_function("snapshot_matrix_and_cluster_1625", |b| {
        b.iter(|| {
            let m = DissimilarityMatrix::from_snapshots(&snaps, SnapshotDistance::RssL1);
            cluster::cluster(&m, &ClusteringMethod::default())
        })
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
    let step = rfloc_pose::Pose2::new(0.05, 0.0, 0.02);
    // Updates take microseconds: more, shorter samples, so that the median is not decided by a
    // few seconds in which the machine ran slower.
    g.sample_size(60);
    for particles in [1000, 1500] {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut filter = TrackFilter::new(TrackConfig {
            particles,
            ..TrackConfig::default()
        });
        // Global localisation, then a few steps so that the cloud is a tracking cloud.
        for _ in 0..5 {
            filter.predict(&rfloc_pose::Pose2::default(), &mut rng);
            filter.update_with_map(&map, &prints, &snapshot, &mut rng);
        }
        // One update and the estimate, as the daemon runs them: the same filter updated in
        // place (its work buffers kept), its particles just written (as the prediction before
        // each update writes them). The state is restored outside the timed part.
        g.bench_function(format!("track_update_{particles}_particles"), |b| {
            b.iter_custom(|iters| {
                let mut f = filter.clone();
                let mut spent = std::time::Duration::ZERO;
                for _ in 0..iters {
                    f.clone_from(&filter);
                    let start = std::time::Instant::now();
                    f.update_with_map(&map, &prints, &snapshot, &mut rng);
                    std::hint::black_box(f.estimate());
                    spent += start.elapsed();
                }
                spent
            })
        });
        // A whole cycle on one filter that keeps running: odometry, snapshot, estimate.
        let mut running = filter.clone();
        g.bench_function(format!("track_cycle_{particles}_particles"), |b| {
            b.iter(|| {
                running.predict(&step, &mut rng);
                running.update_with_map(&map, &prints, &snapshot, &mut rng);
                running.estimate()
            })
        });
    }
    g.sample_size(10);
    g.bench_function("miss_field_all_tiles_800_tags", |b| {
        b.iter(|| {
            let fresh = TagMap::from_tags(model.clone(), map.config, map.tags.clone());
            fresh.precompute_field();
            fresh
        })
    });
    g.finish();
}

criterion_group!(benches, clustering, planning, tag_map);
criterion_main!(benches);
