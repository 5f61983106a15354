//! Clustering recovers known clusters; transitions are learned from an exploration log.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers outside #[test] fns

use rfloc_pose::Pose2;
use rfloc_snapshot::cluster::{cluster, fasterpam};
use rfloc_snapshot::*;

fn id(i: u32) -> TagId {
    TagId::new(i.to_be_bytes().to_vec())
}

/// Three places, each seeing its own 6 tags with place-specific RSS, observed 10 times with
/// ±5 % RSS variation and an occasional missing tag.
fn three_places() -> (Vec<Snapshot>, Vec<usize>) {
    let mut snaps = Vec::new();
    let mut truth = Vec::new();
    for rep in 0..10u32 {
        for place in 0..3u32 {
            let s: Snapshot = (0..6u32)
                .filter(|t| (rep + t + place) % 7 != 0)
                .map(|t| {
                    let base = 1500.0 + 500.0 * f64::from(t);
                    let wobble = 1.0 + 0.05 * (f64::from(rep * 7 + t * 3 + place) * 1.7).sin();
                    (id(place * 100 + t), base * wobble)
                })
                .collect();
            snaps.push(s);
            truth.push(place as usize);
        }
    }
    (snaps, truth)
}

fn same_partition(a: &[usize], b: &[usize]) -> bool {
    a.iter()
        .zip(b)
        .all(|(x, y)| a.iter().zip(b).all(|(u, v)| (x == u) == (y == v)))
}

#[test]
fn both_methods_recover_known_clusters() {
    let (snaps, truth) = three_places();
    for distance in [
        SnapshotDistance::RssL1,
        SnapshotDistance::SeedScore { id_weight: 0.6 },
    ] {
        let d = DissimilarityMatrix::from_snapshots(&snaps, distance);
        let km = cluster(
            &d,
            &ClusteringMethod::KMedoids {
                k: ClusterCount::Fixed(3),
                max_iter: 50,
                seed: 4,
            },
        );
        assert_eq!(km.medoids.len(), 3);
        assert!(
            same_partition(&km.assignment, &truth),
            "{distance:?} k-medoids {:?}",
            km.assignment
        );
        let th = cluster(&d, &ClusteringMethod::Threshold { max_distance: 0.5 });
        assert_eq!(th.medoids.len(), 3, "{distance:?}");
        assert!(
            same_partition(&th.assignment, &truth),
            "{distance:?} threshold {:?}",
            th.assignment
        );
        // each medoid belongs to its own cluster
        for (c, &m) in km.medoids.iter().enumerate() {
            assert_eq!(km.assignment[m], c);
        }
    }
}

#[test]
fn fasterpam_is_deterministic_for_a_seed() {
    let (snaps, _) = three_places();
    let d = DissimilarityMatrix::from_snapshots(&snaps, SnapshotDistance::RssL1);
    let a = fasterpam::fasterpam(&d, fasterpam::init_kmeanspp(&d, 5, 9), 50);
    let b = fasterpam::fasterpam(&d, fasterpam::init_kmeanspp(&d, 5, 9), 50);
    assert_eq!(a, b);
}

#[test]
fn transitions_and_positions_are_learned_from_a_log() {
    let (snaps, truth) = three_places();
    // a walk 0 -F-> 1 -F-> 2 -RL-> 0 ..., with one blind step (no tags) after place 2 every
    // third loop, and the pose of each place on the x axis
    let mut obs = Vec::new();
    for (k, (s, p)) in snaps.iter().zip(&truth).enumerate() {
        let action = if *p == 2 {
            Action::RotateLeft
        } else {
            Action::Forward
        };
        let pose = Pose2::new(*p as f64 + 0.01 * (k % 3) as f64, 0.0, 0.0);
        obs.push(Observation {
            snapshot: s.clone(),
            pose,
            action: Some(action),
        });
        if *p == 2 && k % 9 == 2 {
            obs.last_mut().unwrap().action = Some(Action::ArcRight);
            obs.push(Observation {
                snapshot: Snapshot::new(),
                pose: Pose2::new(3.0, 0.0, 0.0),
                action: Some(Action::RotateLeft),
            });
        }
    }
    let config = LearnConfig {
        clustering: ClusteringMethod::KMedoids {
            k: ClusterCount::Fixed(3),
            max_iter: 50,
            seed: 4,
        },
        prior: TransitionPrior {
            alpha: 0.0,
            self_fraction: 0.0,
        },
        ..LearnConfig::default()
    };
    let db = SnapshotDatabase::learn(&obs, &config).unwrap();
    assert_eq!(db.states.len(), 3);
    let blind = db.no_tags_state();
    assert_eq!(blind, 3);
    // state of each place, via the medoids' positions
    let state_at = |x: f64| {
        db.states
            .iter()
            .position(|s| (s.pose.x - x).abs() < 0.05)
            .unwrap()
    };
    let (s0, s1, s2) = (state_at(0.01), state_at(1.01), state_at(2.01));
    assert_eq!(db.states[s0].members, 10);
    let f = Action::Forward.index();
    assert_eq!(db.transitions.prob(f, s0, s1), 1.0);
    assert_eq!(db.transitions.prob(f, s1, s2), 1.0);
    assert_eq!(db.transitions.prob(Action::RotateLeft.index(), s2, s0), 1.0);
    assert_eq!(
        db.transitions.prob(Action::ArcRight.index(), s2, blind),
        1.0
    );
    assert_eq!(
        db.transitions.prob(Action::RotateLeft.index(), blind, s0),
        1.0
    );
    assert!(db.counts.count(s0, Action::Forward, s1) >= 9.0);
    // localisation of a training snapshot gives its own state; an empty one the no-tags state
    assert_eq!(db.localise(&snaps[0]).state, s0);
    assert_eq!(db.localise(&Snapshot::new()).state, blind);
    // online learning adds to the counts
    let before = db.counts.count(s1, Action::ArcLeft, s0);
    let mut db2 = db.clone();
    assert_eq!(
        db2.record_transition(&snaps[1], Action::ArcLeft, &snaps[0])
            .unwrap(),
        (s1, s0)
    );
    assert_eq!(db2.counts.count(s1, Action::ArcLeft, s0), before + 1.0);
    assert_eq!(db2.transitions.prob(Action::ArcLeft.index(), s1, s0), 1.0);
}
