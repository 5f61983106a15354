//! Benchmark problems shared by the criterion bench, the timing example and `compare.py`
//! (which rebuilds the same numbers with the same generator).
#![allow(dead_code, clippy::panic)]

use rfloc_snapshot::{DissimilarityMatrix, TransitionModel};

/// 32-bit linear congruential generator (Numerical Recipes constants), chosen because it is
/// trivial to reproduce bit for bit in Python.
pub struct Lcg(u32);

impl Lcg {
    pub fn new(seed: u32) -> Self {
        Self(seed)
    }
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        f64::from(self.0) / 4_294_967_296.0
    }
}

/// 1625 points in a 5 m × 5 m × 2 "pose" box, Euclidean dissimilarities.
pub fn clustering_problem(n: usize) -> DissimilarityMatrix {
    let mut rng = Lcg::new(12345);
    let pts: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            [
                5.0 * rng.next_f64(),
                5.0 * rng.next_f64(),
                2.0 * rng.next_f64(),
            ]
        })
        .collect();
    DissimilarityMatrix::from_fn(n, |i, j| {
        let (a, b) = (pts[i], pts[j]);
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    })
}

/// Initial medoids used on both sides: every other object, `k = n / 2`.
pub fn initial_medoids(n: usize) -> Vec<usize> {
    (0..n / 2).map(|i| 2 * i).collect()
}

/// `states × 5` MDP: each (action, state) row has 5 successors `(s + o) mod S` with offsets and
/// weights from the LCG, normalised; rewards `R[s][a]` uniform in [0, 1); state 0 gets +10.
pub fn vi_problem(states: usize) -> (Vec<Vec<Vec<f64>>>, Vec<Vec<f64>>) {
    let mut rng = Lcg::new(777);
    let mut p = vec![vec![vec![0.0; states]; states]; 5];
    for pa in p.iter_mut() {
        for (s, row) in pa.iter_mut().enumerate() {
            let mut ws = [0.0; 5];
            let mut js = [0usize; 5];
            for k in 0..5 {
                js[k] = (s + (rng.next_f64() * 20.0) as usize) % states;
                ws[k] = 0.1 + rng.next_f64();
            }
            let total: f64 = ws.iter().sum();
            for k in 0..5 {
                row[js[k]] += ws[k] / total;
            }
        }
    }
    let mut r = vec![vec![0.0; 5]; states];
    for row in r.iter_mut() {
        for x in row.iter_mut() {
            *x = rng.next_f64();
        }
    }
    r[0] = vec![10.0; 5];
    (p, r)
}

pub fn vi_model(states: usize) -> (TransitionModel, Vec<Vec<f64>>) {
    let (p, r) = vi_problem(states);
    (
        TransitionModel::from_dense(&p).unwrap_or_else(|e| panic!("{e}")),
        r,
    )
}

/// Tag positions and survey samples of a tag-map benchmark world.
pub type TagWorld = (
    Vec<(f64, f64)>,
    Vec<(rfloc_snapshot::Snapshot, rfloc_pose::Pose2)>,
);

/// The seed 000 world for the tag-map benchmarks: 800 tags in 5 m × 5 m, 1000 survey poses,
/// noise-free snapshots under `model` (reads at or above its threshold).
pub fn tag_survey(model: &rfloc_snapshot::ReadModel) -> TagWorld {
    let mut rng = Lcg::new(777);
    let tags: Vec<(f64, f64)> = (0..800)
        .map(|_| (5.0 * rng.next_f64(), 5.0 * rng.next_f64()))
        .collect();
    let survey = (0..1000)
        .map(|_| {
            let p = rfloc_pose::Pose2::new(
                0.3 + 4.4 * rng.next_f64(),
                0.3 + 4.4 * rng.next_f64(),
                std::f64::consts::TAU * rng.next_f64(),
            );
            (tag_snapshot(model, &tags, &p), p)
        })
        .collect();
    (tags, survey)
}

/// What the reader sees from `pose` (noise-free).
pub fn tag_snapshot(
    model: &rfloc_snapshot::ReadModel,
    tags: &[(f64, f64)],
    pose: &rfloc_pose::Pose2,
) -> rfloc_snapshot::Snapshot {
    let a = model.antenna(pose);
    rfloc_snapshot::Snapshot::from_reads(tags.iter().enumerate().filter_map(|(i, (x, y))| {
        let m = model.mean_rss_from(&a, *x, *y);
        (m >= model.threshold).then(|| {
            (
                rfloc_snapshot::TagId::new(vec![(i >> 8) as u8, (i & 0xff) as u8]),
                m,
            )
        })
    }))
}

/// `n` noise-free snapshots of seed 000's world (800 tags in 5 m × 5 m) from random poses, as
/// the clustering of a 1625-step exploration sees them.
pub fn snapshot_problem(n: usize) -> Vec<rfloc_snapshot::Snapshot> {
    let model = rfloc_snapshot::ReadModel::seed000(1000.0, 2);
    let mut rng = Lcg::new(4242);
    let tags: Vec<(f64, f64)> = (0..800)
        .map(|_| (5.0 * rng.next_f64(), 5.0 * rng.next_f64()))
        .collect();
    (0..n)
        .map(|_| {
            let p = rfloc_pose::Pose2::new(
                0.3 + 4.4 * rng.next_f64(),
                0.3 + 4.4 * rng.next_f64(),
                std::f64::consts::TAU * rng.next_f64(),
            );
            tag_snapshot(&model, &tags, &p)
        })
        .collect()
}
