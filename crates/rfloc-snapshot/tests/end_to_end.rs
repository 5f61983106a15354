//! End-to-end: explore the seed's simulated world (5 m × 5 m, 800 tags, eq. 3.22/3.23 RSS,
//! threshold 1000, 5 % RSS noise, Table 4 actions with dt = 0.25 s), learn a database, then
//! localise along a fresh 400-step run with the seed's nearest-state rule and with the
//! histogram filter. Errors are planar distances between the true pose and the estimate, over
//! steps with tags visible, after the first 10 steps.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers outside #[test] fns

mod common;

use common::{explore, World};
use rfloc_snapshot::*;

struct Errors {
    nearest_mean: f64,
    nearest_max: f64,
    filter_mean: f64,
    filter_max: f64,
    states: usize,
}

fn run(config: &LearnConfig, learn_steps: usize) -> Errors {
    let world = World::seed_world(11, 0.05);
    let learn = explore(&world, learn_steps, 0.25, 21);
    let db = SnapshotDatabase::learn(&learn, config).unwrap();
    let test = explore(&world, 400, 0.25, 99);
    let mut filter = StateFilter::new(&db, FilterConfig::default());
    let mut nearest = Vec::new();
    let mut filtered = Vec::new();
    let mut prev_action = None;
    for (i, o) in test.iter().enumerate() {
        if let Some(a) = prev_action {
            filter.predict(&db, a);
        }
        filter.update(&db, &o.snapshot);
        prev_action = o.action;
        if o.snapshot.is_empty() || i < 10 {
            continue;
        }
        let sp = db.states[db.localise(&o.snapshot).state].pose;
        nearest.push(((sp.x - o.pose.x).powi(2) + (sp.y - o.pose.y).powi(2)).sqrt());
        let e = filter.estimate(&db, i as f64);
        filtered.push(((e.pose.x - o.pose.x).powi(2) + (e.pose.y - o.pose.y).powi(2)).sqrt());
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let e = Errors {
        nearest_mean: mean(&nearest),
        nearest_max: max(&nearest),
        filter_mean: mean(&filtered),
        filter_max: max(&filtered),
        states: db.states.len(),
    };
    println!(
        "{learn_steps} learning steps, {} states: nearest-state mean {:.3} m max {:.3} m; histogram filter mean {:.3} m max {:.3} m ({} test poses)",
        e.states, e.nearest_mean, e.nearest_max, e.filter_mean, e.filter_max, filtered.len()
    );
    e
}

/// A short exploration (800 snapshots, k = n/2), fast enough for debug builds.
#[test]
fn kmedoids_database_localises_along_a_fresh_run() {
    let e = run(&LearnConfig::default(), 800);
    assert!(e.states > 350 && e.states <= 400, "{}", e.states);
    assert!(
        e.filter_mean < e.nearest_mean,
        "the filter must beat nearest-state localisation"
    );
    assert!(
        e.filter_mean < 0.45,
        "filter mean error {:.3} m",
        e.filter_mean
    );
}

/// Threshold clustering on the same data gives a usable database too.
#[test]
fn threshold_database_localises() {
    let config = LearnConfig {
        clustering: ClusteringMethod::Threshold { max_distance: 0.25 },
        ..LearnConfig::default()
    };
    let e = run(&config, 800);
    assert!(e.states > 50, "{}", e.states);
    assert!(
        e.filter_mean < 0.6,
        "filter mean error {:.3} m",
        e.filter_mean
    );
}

/// The seed's data volume (1625 snapshots, k = n/2 as in section 3.3.2). About 1 s with the
/// workspace's dev-profile optimisation of this crate.
#[test]
fn seed_size_database_localises() {
    let e = run(&LearnConfig::default(), 1625);
    assert!(e.states > 700 && e.states <= 813, "{}", e.states);
    assert!(e.filter_mean < e.nearest_mean);
    assert!(
        e.filter_mean < 0.30,
        "filter mean error {:.3} m",
        e.filter_mean
    );
}

/// Denser learning (3000 snapshots, every snapshot its own state):
/// `cargo test -p rfloc-snapshot --test end_to_end -- --ignored --nocapture`.
#[test]
#[ignore = "a few seconds and a 36 MB dissimilarity matrix"]
fn dense_learning_localises_better() {
    let config = LearnConfig {
        clustering: ClusteringMethod::KMedoids {
            k: ClusterCount::Fraction(1.0),
            max_iter: 100,
            seed: 1,
        },
        ..LearnConfig::default()
    };
    let e = run(&config, 3000);
    assert!(
        e.filter_mean < 0.2,
        "filter mean error {:.3} m",
        e.filter_mean
    );
}
