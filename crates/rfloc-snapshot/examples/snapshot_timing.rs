//! Prints timings of the benchmark problems in a form `benches/compare.py` parses:
//! `name seconds detail`. Run with
//! `cargo run --release --example snapshot_timing [EUCLIDEAN_MATRIX SNAPSHOT_MATRIX]`; with the
//! paths, both dissimilarity matrices are written there (n × n little-endian f32, as the crate
//! stores them) so that the Python side clusters exactly the same matrices.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

#[path = "../benches/problems.rs"]
mod problems;

use std::time::Instant;

use rfloc_snapshot::cluster::{self, fasterpam};
use rfloc_snapshot::{
    value_iteration, ClusteringMethod, DissimilarityMatrix, SnapshotDistance, ValueIterationConfig,
};

fn median_secs(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// Writes the matrix as n × n little-endian f32.
fn write_matrix(d: &DissimilarityMatrix, path: &str) {
    let bytes: Vec<u8> = (0..d.len())
        .flat_map(|i| d.row(i).iter().flat_map(|x| x.to_le_bytes()))
        .collect();
    std::fs::write(path, bytes).unwrap();
}

fn main() {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    let d = problems::clustering_problem(1625);
    if let Some(path) = paths.first() {
        write_matrix(&d, path);
    }
    let init = problems::initial_medoids(1625);
    let c = fasterpam::fasterpam(&d, init.clone(), 100);
    let t = median_secs(5, || {
        let _ = fasterpam::fasterpam(&d, init.clone(), 100);
    });
    println!(
        "fasterpam_1625_k812 {t:.6} loss={:.6} swaps={} iterations={}",
        c.loss, c.swaps, c.iterations
    );

    // The same clustering on the dissimilarities of 1625 exploration snapshots (seed 000's
    // world), from the same initial medoids; then the matrix itself and the default
    // clustering (k-means++ start) as learning runs them.
    let snaps = problems::snapshot_problem(1625);
    let t = median_secs(5, || {
        let _ = DissimilarityMatrix::from_snapshots(&snaps, SnapshotDistance::RssL1);
    });
    let d = DissimilarityMatrix::from_snapshots(&snaps, SnapshotDistance::RssL1);
    println!("snapshot_matrix_1625 {t:.6} n={}", d.len());
    if let Some(path) = paths.get(1) {
        write_matrix(&d, path);
    }
    let c = fasterpam::fasterpam(&d, init.clone(), 100);
    let t = median_secs(5, || {
        let _ = fasterpam::fasterpam(&d, init.clone(), 100);
    });
    println!(
        "fasterpam_snapshots_1625_k812 {t:.6} loss={:.6} swaps={} iterations={}",
        c.loss, c.swaps, c.iterations
    );
    let method = ClusteringMethod::default();
    let t = median_secs(5, || {
        let _ = cluster::cluster(&d, &method);
    });
    println!("cluster_default_1625 {t:.6} (k-means++ start, k = n/2)");
    let t = median_secs(5, || {
        let d = DissimilarityMatrix::from_snapshots(&snaps, SnapshotDistance::RssL1);
        let _ = cluster::cluster(&d, &method);
    });
    println!("matrix_and_cluster_1625 {t:.6}");

    let (m, r) = problems::vi_model(1000);
    let cfg = ValueIterationConfig {
        discount: 0.95,
        epsilon: 0.01,
        max_iter: 1000,
    };
    let res = value_iteration(&m, &r, &cfg).unwrap();
    let t = median_secs(20, || {
        let _ = value_iteration(&m, &r, &cfg).unwrap();
    });
    let vsum: f64 = res.value.iter().sum();
    let psum: usize = res.policy.iter().sum();
    println!(
        "value_iteration_1000x5 {t:.6} iter={} max_iter={} sumV={vsum:.6} sumPolicy={psum}",
        res.iterations, res.max_iter
    );
}
