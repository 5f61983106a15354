//! Criterion benchmarks: FasterPAM on 1625 objects (k = 812) and value iteration on
//! 1000 states × 5 actions.
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

criterion_group!(benches, clustering, planning);
criterion_main!(benches);
