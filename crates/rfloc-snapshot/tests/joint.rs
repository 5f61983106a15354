//! Joint learning of the tag map and the exploration trajectory on a drifting odometry: the
//! map learned along the odometry gets worse as the exploration goes on, the joint one does not.
//! And what is returned when a learned trajectory leaves the odometry by more than it can
//! drift: the retry with the revisit rule, or the odometry when that diverges too.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{explore, World};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;
use rfloc_snapshot::{
    learn_jointly, JointConfig, JointReport, Observation, ReadModel, Snapshot, TagMap, TagMapConfig,
};

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

/// The reader model of these tests: seed 000's fit, σ 150 per read, no dropout.
fn reader() -> ReadModel {
    ReadModel {
        read_sigma: 150.0,
        dropout: 0.0,
        ..ReadModel::seed000(1000.0, 1)
    }
}

/// The exploration's snapshots, each with the pose the robot believed (`poses`).
fn pairs<'a>(run: &'a [Observation], poses: &[Pose2]) -> Vec<(&'a Snapshot, Pose2)> {
    run.iter()
        .map(|o| &o.snapshot)
        .zip(poses.iter().copied())
        .collect()
}

/// The map learned along `samples`' poses and the one learned jointly with the path, with the
/// same reader model ([`reader`]): (along, joint, joint poses, report).
fn learn_both(samples: &[(&Snapshot, Pose2)]) -> (TagMap, TagMap, Vec<Pose2>, JointReport) {
    let model = reader();
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
/// 0.045 m of the truth (0.038 m measured with the pose-graph rounds, 0.050 m before them), and
/// the poses late in the run stay as good as the map.
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
    let samples = pairs(&run, &odo);
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
    assert!(joint_tags < 0.045, "joint map {joint_tags} m");
    assert!(late_odo > 0.25, "odometry late {late_odo} m");
    assert!(late_joint < 0.05, "joint late {late_joint} m");
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
    let samples = pairs(&run, &truth);
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

/// `odo` with one faulty increment: at step `k` the encoders also count `slip` (in the robot
/// frame) that the robot did not move, and every later pose carries it.
fn with_slip(odo: &[Pose2], k: usize, slip: Pose2) -> Vec<Pose2> {
    let mut out = odo[..k].to_vec();
    for w in odo[k - 1..].windows(2) {
        let mut u = w[1].relative_to(&w[0]);
        if out.len() == k {
            u = u.compose(&slip);
        }
        let last = *out.last().unwrap();
        out.push(last.compose(&u));
    }
    out
}

/// A short exploration: 160 steps in a 4 m square at the seed's tag density, and its odometry
/// with a slowly wandering heading (within 0.18 m of the truth). (run, truth, odometry)
fn short_run() -> (Vec<Observation>, Vec<Pose2>, Vec<Pose2>) {
    let world = World::square(41, 4.0, 32.0, 0.05);
    let run = explore(&world, 160, 0.1, 42);
    let truth: Vec<Pose2> = run.iter().map(|o| o.pose).collect();
    let odo = odometry(&truth, 43, 0.002);
    (run, truth, odo)
}

/// The settings for [`short_run`]: a flat drift bound of 0.3 m (its odometry stays within
/// 0.18 m of the truth), and no pose-graph rounds (the measurements below were taken without
/// them; with them the short run has only a handful of closures).
fn short_run_joint() -> JointConfig {
    JointConfig {
        closure_rounds: 0,
        max_drift_m: 0.3,
        max_drift_rel: 0.0,
        ..JointConfig::default()
    }
}

/// Mean and largest distance of `poses` from `truth`.
fn errors(poses: &[Pose2], truth: &[Pose2]) -> (f64, f64) {
    let e: Vec<f64> = poses
        .iter()
        .zip(truth)
        .map(|(a, b)| a.distance(b))
        .collect();
    (
        e.iter().sum::<f64>() / e.len() as f64,
        e.iter().copied().fold(0.0, f64::max),
    )
}

/// Learns `samples` with `joint`, which must diverge without a retry that converges: the
/// result is flagged diverged, not retried, and is the odometry and the map placed along it.
fn assert_learns_the_odometry(samples: &[(&Snapshot, Pose2)], joint: &JointConfig) {
    let (map, poses, report) = learn_jointly(samples, reader(), TagMapConfig::default(), joint);
    println!("{report:?}");
    assert!(report.diverged, "{report:?}");
    assert!(!report.retried, "{report:?}");
    let odo: Vec<Pose2> = samples.iter().map(|(_, p)| *p).collect();
    assert_eq!(poses, odo);
    assert_eq!(report.max_correction_m, 0.0, "{report:?}");
    assert_eq!(report.mean_correction_m, 0.0, "{report:?}");
    let along = TagMap::learn(samples.iter().copied(), reader(), TagMapConfig::default());
    assert_eq!(map.tags, along.tags);
}

/// Settings under which the forward pass without the revisit rule runs away from the accurate
/// odometry of [`short_run`]: every tag placed so far, even one read once (no read count or σ
/// bound), places a pose as if the map were exact (2 mm floor), in chunks of 10 steps; the
/// drift bound of [`short_run_joint`] (0.3 m). The first attempt is without the rule, the
/// retry with it (30 steps).
///
/// Measured, each setting alone (no retry, no bound): without the rule the poses are 0.21 m
/// from the truth on average and 0.52 m at worst (step 158, where the odometry is 0.06 m off),
/// 55 factors are rejected, and the trajectory leaves the odometry by up to 0.47 m. A pose is
/// placed by tags first read a few steps before, themselves placed from the very poses the
/// factor corrects, so the trajectory follows its own error (from step 50 on, while the
/// odometry stays within 0.07 m of the truth). With the rule (tags first read at least 30
/// steps before the chunk) the error is 0.036 m mean, 0.095 m at worst, and the trajectory
/// stays within 0.10 m of the odometry.
fn credulous() -> JointConfig {
    JointConfig {
        chunk: 10,
        min_tag_reads: 1,
        max_tag_sigma: 1.0,
        floor_xy: 0.002,
        revisit_steps: 0,
        retry_revisit_steps: 30,
        ..short_run_joint()
    }
}

/// The odometry counts a 1 m lurch at step 80 that never happened (a wheel spinning in the
/// air). Both attempts (without and with the revisit rule) find the true path again (0.04 m
/// from the truth at step 99) and so leave the odometry by 1.0 m, more than the 0.3 m it is
/// assumed to drift: both diverge, and the result is the odometry and the map along it.
#[test]
fn both_attempts_diverging_give_the_odometry() {
    let (run, truth, odo) = short_run();
    let odo = with_slip(&odo, 80, Pose2::new(1.0, 0.0, 0.0));
    let (_, worst) = errors(&odo, &truth);
    assert!(
        worst > 0.9,
        "the slip should put the odometry off ({worst} m)"
    );
    let samples = pairs(&run, &odo);
    let joint = short_run_joint();
    assert_ne!(joint.revisit_steps, joint.retry_revisit_steps);
    assert_learns_the_odometry(&samples, &joint);
}

/// On [`short_run`] with the [`credulous`] settings the first attempt (no revisit rule) leaves
/// the odometry by 0.47 m, beyond the 0.3 m bound; the retry with the rule stays within 0.10 m
/// of it and is what is returned: flagged as retried, not diverged, the same result as an
/// attempt with the rule alone, and closer to the truth than the odometry.
#[test]
fn a_diverged_first_attempt_is_retried_with_the_revisit_rule() {
    let (run, truth, odo) = short_run();
    let samples = pairs(&run, &odo);
    let joint = credulous();
    let (odo_mean, odo_worst) = errors(&odo, &truth);
    assert!(
        odo_worst < joint.max_drift_m,
        "the bound should hold for this odometry ({odo_worst} m)"
    );
    let (map, poses, report) = learn_jointly(&samples, reader(), TagMapConfig::default(), &joint);
    let (mean, worst) = errors(&poses, &truth);
    println!(
        "odometry error mean {odo_mean:.3} m, worst {odo_worst:.3} m; learned {mean:.3} m, \
         {worst:.3} m; {report:?}"
    );
    assert!(report.retried, "{report:?}");
    assert!(!report.diverged, "{report:?}");
    assert!(report.max_correction_m <= joint.max_drift_m, "{report:?}");
    assert!(mean < odo_mean && worst < odo_worst, "{mean} {worst}");
    // The retry is the attempt with the revisit rule, as if it had been the only one.
    let rule = JointConfig {
        revisit_steps: joint.retry_revisit_steps,
        ..joint
    };
    let (alone_map, alone, alone_report) =
        learn_jointly(&samples, reader(), TagMapConfig::default(), &rule);
    assert!(!alone_report.diverged && !alone_report.retried);
    assert_eq!(poses, alone);
    assert_eq!(map.tags, alone_map.tags);
    assert_eq!(
        JointReport {
            retried: false,
            ..report
        },
        alone_report
    );
}

/// The first attempt of the test above with the retry turned off (`retry_revisit_steps` equal
/// to `revisit_steps`): nothing else is tried, the result is the odometry.
#[test]
fn no_retry_when_the_retry_setting_is_the_same() {
    let (run, _, odo) = short_run();
    let samples = pairs(&run, &odo);
    let joint = JointConfig {
        retry_revisit_steps: 0,
        ..credulous()
    };
    assert_learns_the_odometry(&samples, &joint);
}

/// The pose-graph rounds keep what the rounds corrected: after a false 1 m lurch in the
/// odometry at step 80 of the short run, the few closures between visits (poses at least
/// `closure_gap` apart) and the odometry leave the trajectory as close to the truth as the
/// rounds alone did, instead of putting it back on the odometry (which they did when the
/// closures had to be 200 steps apart: none in 160 steps, mean error 0.50 m).
#[test]
fn pose_graph_rounds_keep_the_rounds_corrections_on_a_short_run() {
    let (run, truth, odo) = short_run();
    let odo = with_slip(&odo, 80, Pose2::new(1.0, 0.0, 0.0));
    let samples = pairs(&run, &odo);
    let learn = |j: JointConfig| {
        let j = JointConfig {
            max_drift_m: 10.0,
            ..j
        };
        let (_, poses, report) = learn_jointly(&samples, reader(), TagMapConfig::default(), &j);
        (errors(&poses, &truth), report)
    };
    let ((rounds_mean, _), _) = learn(JointConfig {
        closure_rounds: 0,
        ..JointConfig::default()
    });
    let ((graph_mean, _), report) = learn(JointConfig::default());
    let (odo_mean, _) = errors(&odo, &truth);
    println!(
        "mean error: odometry {odo_mean:.3} m, rounds {rounds_mean:.3} m, with pose-graph \
         rounds {graph_mean:.3} m ({} closures)",
        report.closures
    );
    assert!(odo_mean > 0.4, "the test needs the lurch ({odo_mean} m)");
    assert!(report.closures > 0, "{report:?}");
    assert!(graph_mean < 0.2, "{graph_mean} m");
    assert!(
        graph_mean <= rounds_mean + 0.01,
        "{graph_mean} vs {rounds_mean} m"
    );
}
