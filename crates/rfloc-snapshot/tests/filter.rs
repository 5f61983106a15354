//! Histogram filter: convergence from a uniform belief, and no flicker where nearest-state
//! localisation alternates between neighbouring states.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers outside #[test] fns

mod common;

use common::{explore, World};
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::{EstimateMode, Pose2};
use rfloc_snapshot::*;

fn setup() -> (World, SnapshotDatabase) {
    let world = World::seed_world(11, 0.05);
    let learn = explore(&world, 600, 0.25, 21);
    let db = SnapshotDatabase::learn(&learn, &LearnConfig::default()).unwrap();
    (world, db)
}

fn entropy(b: &[f64]) -> f64 {
    b.iter().filter(|p| **p > 0.0).map(|p| -p * p.ln()).sum()
}

#[test]
fn converges_from_uniform_belief() {
    let (world, db) = setup();
    let mut f = StateFilter::new(&db, FilterConfig::default());
    assert_eq!(f.estimate(&db, 0.0).mode, EstimateMode::NoFix);
    let h0 = entropy(f.belief());
    assert!((h0 - (db.state_count() as f64).ln()).abs() < 1e-9);
    let run = explore(&world, 80, 0.25, 5);
    let mut prev = None;
    let mut close = 0;
    let mut counted = 0;
    for (i, o) in run.iter().enumerate() {
        if let Some(a) = prev {
            f.predict(&db, a);
        }
        f.update(&db, &o.snapshot);
        prev = o.action;
        assert!((f.belief().iter().sum::<f64>() - 1.0).abs() < 1e-9);
        if i >= 10 && !o.snapshot.is_empty() {
            let e = f.estimate(&db, i as f64);
            assert_eq!(e.mode, EstimateMode::Fix);
            counted += 1;
            if ((e.pose.x - o.pose.x).powi(2) + (e.pose.y - o.pose.y).powi(2)).sqrt() < 0.75 {
                close += 1;
            }
            // covariance is symmetric positive semi-definite
            let c = e.covariance;
            assert!((c - c.transpose()).abs().max() < 1e-12);
            assert!(c.symmetric_eigenvalues().iter().all(|v| *v > -1e-12));
        }
    }
    assert!(entropy(f.belief()) < 0.5 * h0, "belief stayed diffuse");
    assert!(
        close as f64 >= 0.8 * counted as f64,
        "{close} of {counted} within 0.75 m"
    );
}

#[test]
fn does_not_flicker_between_neighbouring_states() {
    let (world, db) = setup();
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    // Find, on a grid of poses, the one where noisy snapshots make nearest-state localisation
    // switch most often (a border between states).
    let mut worst = (0, Pose2::default());
    for ix in 1..6 {
        for iy in 1..6 {
            for k in 0..4 {
                let pose = Pose2::new(
                    ix as f64 * 0.8,
                    iy as f64 * 0.8,
                    k as f64 * std::f64::consts::FRAC_PI_2,
                );
                let states: Vec<usize> = (0..8)
                    .map(|_| db.localise(&world.snapshot(&pose, &mut rng)).state)
                    .collect();
                let switches = states.windows(2).filter(|w| w[0] != w[1]).count();
                if switches > worst.0 {
                    worst = (switches, pose);
                }
            }
        }
    }
    let pose = worst.1;
    assert!(worst.0 >= 3, "no flickering pose found");
    let mut f = StateFilter::new(&db, FilterConfig::default());
    let mut nearest_switches = 0;
    let mut filter_switches = 0;
    let (mut last_nearest, mut last_map) = (None, None);
    for i in 0..30 {
        let s = world.snapshot(&pose, &mut rng);
        f.update(&db, &s); // the robot stands still: no prediction
        let n = db.localise(&s).state;
        let m = f.map_state();
        if i >= 3 {
            nearest_switches += usize::from(last_nearest.is_some_and(|l| l != n));
            filter_switches += usize::from(last_map.is_some_and(|l| l != m));
        }
        last_nearest = Some(n);
        last_map = Some(m);
    }
    println!("stationary at {pose:?}: nearest-state switched {nearest_switches} times, filter {filter_switches}");
    assert!(nearest_switches >= 3);
    assert!(filter_switches <= 1);
}
