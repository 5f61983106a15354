//! Joint learning of the tag map and the exploration trajectory on a drifting odometry: the
//! map learned along the odometry gets worse as the exploration goes on, the joint one does not.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{explore, World};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;
use rfloc_snapshot::{learn_jointly, JointConfig, ReadModel, TagMap, TagMapConfig};

/// Odometry of a true path: each true increment with relative noise and a slowly wandering
/// heading error (what wheel slip does to a differential drive).
fn odometry(truth: &[Pose2], seed: u64, heading_sigma: f64) -> Vec<Pose2> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut normal = move || {
        let u1: f64 = rng.random::<f64>().max(1e-300);
        let u2: f64 = rng.random();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let mut out = vec![truth[0]];
    for w in truth.windows(2) {
        let d = w[1].relative_to(&w[0]);
        let dist = d.x.hypot(d.y);
        let noisy = Pose2::new(
            d.x * (1.0 + 0.01 * normal()),
            d.y * (1.0 + 0.01 * normal()),
            d.theta + heading_sigma * (dist / 0.25).max(0.3).sqrt() * normal(),
        );
        let last = *out.last().unwrap();
        out.push(last.compose(&noisy));
    }
    out
}

/// The map learned along `samples`' poses and the one learned jointly with the path, with the
/// same reader model (σ 150 per read, no dropout): (along, joint, joint poses, report).
fn learn_both(
    samples: &[(&rfloc_snapshot::Snapshot, Pose2)],
) -> (TagMap, TagMap, Vec<Pose2>, rfloc_snapshot::JointReport) {
    let model = ReadModel {
        read_sigma: 150.0,
        dropout: 0.0,
        ..ReadModel::seed000(1000.0, 1)
    };
    let plain = TagMap::learn(
        samples.iter().copied(),
        model.clone(),
        TagMapConfig::default(),
    );
    let (joint, poses, report) = learn_jointly(
        samples,
        model,
        TagMapConfig::default(),
        &JointConfig::default(),
    );
    (plain, joint, poses, report)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median distance of the mapped tags from their true positions.
fn tag_error(map: &TagMap, world: &World) -> f64 {
    median(
        map.tags
            .iter()
            .filter_map(|t| {
                let i = world.ids.iter().position(|id| *id == t.id)?;
                let (x, y) = world.tags[i];
                Some((t.x - x).hypot(t.y - y))
            })
            .collect(),
    )
}

/// Median pose error of the last quarter of a trajectory.
fn late_error(poses: &[Pose2], truth: &[Pose2]) -> f64 {
    let from = poses.len() * 3 / 4;
    median(
        poses[from..]
            .iter()
            .zip(&truth[from..])
            .map(|(a, b)| a.distance(b))
            .collect(),
    )
}

/// A 7 m square at the seed's tag density, 2000 exploration steps, odometry that drifts by
/// 0.8 m: the map along the odometry is off by about 0.2 m (median), the joint one stays within
/// 0.12 m of the truth, and the poses late in the run stay as good as the map.
#[test]
fn joint_learning_keeps_the_map_consistent_on_a_drifting_path() {
    let world = World::square(21, 7.0, 32.0, 0.05);
    let run = explore(&world, 2000, 0.1, 22);
    let truth: Vec<Pose2> = run.iter().map(|o| o.pose).collect();
    let odo = odometry(&truth, 23, 0.003);
    let drift = truth
        .iter()
        .zip(&odo)
        .map(|(a, b)| a.distance(b))
        .fold(0.0, f64::max);
    let samples: Vec<_> = run
        .iter()
        .map(|o| &o.snapshot)
        .zip(odo.iter().copied())
        .collect();
    let (plain, joint, poses, report) = learn_both(&samples);
    let (plain_tags, joint_tags) = (tag_error(&plain, &world), tag_error(&joint, &world));
    let (late_odo, late_joint) = (late_error(&odo, &truth), late_error(&poses, &truth));
    println!(
        "odometry drift max {drift:.3} m; tags median: odometry {plain_tags:.3} m, joint \
         {joint_tags:.3} m; last quarter poses median: odometry {late_odo:.3} m, joint \
         {late_joint:.3} m; mapped {} / {}; {report:?}",
        plain.len(),
        joint.len()
    );
    assert!(
        drift > 0.5,
        "the test needs a drifting odometry ({drift} m)"
    );
    assert!(plain_tags > 0.15, "odometry map {plain_tags} m");
    assert!(joint_tags < 0.12, "joint map {joint_tags} m");
    assert!(late_odo > 0.25, "odometry late {late_odo} m");
    assert!(late_joint < 0.12, "joint late {late_joint} m");
    assert!(joint.len() + 20 >= plain.len());
    assert!(report.factors > 1500, "{report:?}");
}

/// Without drift the joint learning changes little: the poses stay near the odometry and the
/// map is as good as the one along it.
#[test]
fn joint_learning_keeps_an_exact_odometry() {
    let world = World::square(31, 5.0, 32.0, 0.05);
    let run = explore(&world, 800, 0.1, 32);
    let truth: Vec<Pose2> = run.iter().map(|o| o.pose).collect();
    let samples: Vec<_> = run
        .iter()
        .map(|o| &o.snapshot)
        .zip(truth.iter().copied())
        .collect();
    let (plain, joint, poses, report) = learn_both(&samples);
    let pose_error = median(
        poses
            .iter()
            .zip(&truth)
            .map(|(a, b)| a.distance(b))
            .collect(),
    );
    let (plain_tags, joint_tags) = (tag_error(&plain, &world), tag_error(&joint, &world));
    println!("poses {pose_error:.3} m; tags {plain_tags:.3} / {joint_tags:.3} m; {report:?}");
    assert!(pose_error < 0.05, "{pose_error}");
    assert!(
        joint_tags < plain_tags + 0.02,
        "{joint_tags} vs {plain_tags}"
    );
}
