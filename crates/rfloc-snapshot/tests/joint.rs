//! Joint learning of the tag map and the exploration trajectory on a drifting odometry: the
//! map learned along the odometry gets worse with the explored area, the joint one does not.
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

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn tag_errors(map: &TagMap, world: &World) -> f64 {
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
    let model = ReadModel {
        read_sigma: 150.0,
        dropout: 0.0,
        ..ReadModel::seed000(1000.0, 1)
    };
    let t = std::time::Instant::now();
    let plain = TagMap::learn(
        samples.iter().copied(),
        model.clone(),
        TagMapConfig::default(),
    );
    let t_plain = t.elapsed();
    let t = std::time::Instant::now();
    let cfg = JointConfig {
        chunk: std::env::var("JOINT_CHUNK").map_or(250, |v| v.parse().unwrap()),

        ..JointConfig::default()
    };
    let (joint, poses, report) = learn_jointly(&samples, model, TagMapConfig::default(), &cfg);
    let t_joint = t.elapsed();
    let pose_err = |p: &[Pose2]| median(p.iter().zip(&truth).map(|(a, b)| a.distance(b)).collect());
    let (plain_tags, joint_tags) = (tag_errors(&plain, &world), tag_errors(&joint, &world));
    println!(
        "odometry drift max {drift:.3} m, median {:.3} m; joint poses median {:.3} m; \
         tags median: odometry {plain_tags:.3} m, joint {joint_tags:.3} m; mapped {} / {}; \
         {report:?}; times {t_plain:?} / {t_joint:?}",
        pose_err(&odo),
        pose_err(&poses),
        plain.len(),
        joint.len()
    );
    for (k, c) in poses.chunks(250).zip(truth.chunks(250)).enumerate() {
        let e: Vec<f64> = c.0.iter().zip(c.1).map(|(a, b)| a.distance(b)).collect();
        let o: Vec<f64> = odo[k * 250..k * 250 + c.0.len()]
            .iter()
            .zip(c.1)
            .map(|(a, b)| a.distance(b))
            .collect();
        let h: Vec<f64> =
            c.0.iter()
                .zip(c.1)
                .map(|(a, b)| rfloc_pose::angle_diff(a.theta, b.theta).abs())
                .collect();
        println!(
            "chunk {k}: joint {:.3} m {:.3} rad, odometry {:.3} m",
            median(e),
            median(h),
            median(o)
        );
    }
    assert!(
        drift > 0.3,
        "the test needs a drifting odometry ({drift} m)"
    );
    assert!(
        joint_tags < 0.6 * plain_tags,
        "{joint_tags} vs {plain_tags}"
    );
    assert!(pose_err(&poses) < 0.5 * pose_err(&odo));
    assert!(joint.len() + 20 >= plain.len());
}
