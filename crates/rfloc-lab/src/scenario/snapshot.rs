//! Simulated trials of the snapshot scenarios (seed 000: UHF RFID snapshot localisation and
//! MDP navigation), end to end through rfloc's drivers.
//!
//! Per trial ([`rig`]): an emulated Pioneer on a pty and an emulated Alien ALR-9900 on a
//! loopback TCP listener, reached through `AriaClient` and `AlienClient` over links opened by
//! `rfloc_transport::open` and recorded into `pioneer.cap` and `alien.cap`. The reader's tags and
//! RSS come from the scenario's UHF model at the antenna pose of the emulator's true pose.
//!
//! 1. **Exploration**: `exploration_steps` steps of `ExplorationPolicy`; each step reads
//!    [`READS_PER_STEP`] tag lists at rest, averages them (`Snapshot::average`, the seed's
//!    `scanNetTags`), then drives the chosen action ([`actuation`]: Table 4's per-step
//!    displacement over [`DRIVE_DURATION_S`], with the scenario's action noise). Each sample is
//!    stored with the emulator's **true** pose (as the seed's simulator did; used only for the
//!    seed-style cluster database and scoring) and with the robot's **odometry** pose (used for
//!    everything the robot decides). The world has walls (the seed's had none): when the
//!    Pioneer's SIPs report a wheel stall, the odometry pose is kept as a stall place and the
//!    next [`STALL_TURN_STEPS`] actions are rotations ([`reflex`]).
//! 2. **Learning**: the seed's cluster database (`SnapshotDatabase::learn`, k-medoids, k = n/2,
//!    true poses) is saved, with the survey and the tag map, as one learned-state set (`state-manifest.json`, versioned files) and loaded back; the same with
//!    odometry poses gives `snapshot-db-odometry.json`. Both are scored as comparisons (on at
//!    most [`CLUSTER_DB_MAX_STEPS`] steps). The robot itself learns the **tag map and its
//!    exploration trajectory together** (`learn_jointly`: the odometry drifts, and a map placed
//!    along it blurs with the explored area) and uses the **fine map** (`FingerprintMap`: every
//!    exploration snapshot at its learned pose), the **learned motion** of each action (`ActionModel`: mean odometry increment of the
//!    steps that did not stall) and a **lattice plan** (`LatticePlan`: value iteration on a
//!    0.15 m × 11.25° lattice over the explored floor; steps near its edge or near stall places
//!    cost more) to the goal point.
//! 3. **Navigation**: each step reads a snapshot and hands it, with the base's odometry, to the
//!    daemon's own `SnapshotPipeline` on the reloaded survey and tag map (the localiser `rfloc
//!    run` uses with `[estimator] survey` and `tag_map`: a particle filter moved by the odometry
//!    increment and weighed by the tag map); the published pose's best lattice action is taken
//!    unless the `CycleBreaker` sees a repeat (the robot back at a place/heading for the
//!    [`CYCLE_REPEATS`]th time in [`CYCLE_WINDOW`] decisions, or reversing its turn there), then
//!    an untried action. A wheel stall turns the robot for [`NAV_STALL_TURN_STEPS`] steps. The
//!    robot stops when the estimate is within [`GOAL_FRACTION`] of the goal tolerance of the
//!    goal after [`STOP_CONFIDENT_STEPS`] steps of a fix with a tight ([`STOP_SPREAD_M`]) and
//!    steady ([`STOP_JUMP_M`]) cloud, or after `navigation_steps` steps. The particle filter
//!    starts from the first snapshot (global
//!    localisation), not from the odometry pose the robot ended exploration with.
//!
//! Recorded: truth and the particle filter's estimate at every navigation step (the seed-style
//! histogram filter, the nearest-state rule and other filter settings are scored on the same
//! sequence). **Times in `truth.csv`, `estimate.csv` and `time_to_goal` are navigation steps**
//! (the seed's Table 4.9 unit), not seconds. `navigation.csv` logs every decision,
//! `metrics.csv` the trial's numbers, and `table-4.9.md` in the output folder gathers one row per
//! trial next to the seed's row of the same number. A trial succeeds when the robot stops within
//! the goal tolerance. A "limit cycle" (referee) is counted when the true distance to the goal
//! does not improve by [`STALL_GAIN_M`] for [`STALL_WINDOW`] steps ([`stall`]).
//!
//! Measured: see `docs/results.md` (seed 000) and the `rfloc-snapshot` README.
//!
//! Reproducibility: every random draw is seeded from the trial seed, and the Pioneer runs in
//! lock-step with the trial (see [`rig`]), so a run is a function of the scenario and the seed:
//! two runs write identical captures, truth and estimates (`tests/sim_determinism.rs`).

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::{EstimateMode, Pose2};
use rfloc_sim::recorder::TrialRecorder;
use rfloc_sim::Scenario;
use rfloc_snapshot::{
    learn_jointly, Action, ActionTable, CycleBreaker, ExplorationConfig, ExplorationInput,
    ExplorationPolicy, FilterConfig, FingerprintMap, JointConfig, LatticeConfig, LearnConfig,
    Observation, ReadModel, Snapshot, SnapshotDatabase, StateFilter, Survey, TagId, TagMap,
    TagMapConfig, TrackConfig, TrackFilter,
};
use rfloc_snapshot::{state_set, store};

use super::SimOptions;
use rfloc_daemon::events::DeviceEvent;
use rfloc_daemon::pipeline::{Pipeline, SnapshotPipeline};

mod actuation;
mod reflex;
pub(crate) mod rig;
mod stall;

use actuation::Actuation;
use reflex::StallReflex;
use rig::{RigSpec, SnapshotRig};
use stall::StallDetector;

/// Tag-list reads averaged per step (the seed's experiment script: `n = 2`).
pub const READS_PER_STEP: usize = 2;
/// Simulated seconds the Pioneer takes to drive one action.
pub const DRIVE_DURATION_S: f64 = 0.5;
/// Navigation steps without [`STALL_GAIN_M`] of progress that count as a limit cycle.
pub const STALL_WINDOW: usize = 60;
/// Progress towards the goal that resets the stall window, metres.
pub const STALL_GAIN_M: f64 = 0.1;
/// Relative σ of wheel slip on the true motion (odometry does not see it).
pub const WHEEL_SLIP: f64 = 0.02;
/// Rotation steps taken after a wheel stall (about 160° with Table 4's rotations).
pub const STALL_TURN_STEPS: usize = 18;
/// The robot stops when its estimate is within this fraction of the goal tolerance of the goal.
pub const GOAL_FRACTION: f64 = 0.5;
/// ... and the published pose is a fix (its mode holds most of the particles' weight,
/// `pipeline::snapshot::FIX_MASS`) whose spread is at most this (m) ...
pub const STOP_SPREAD_M: f64 = 0.2;
/// ... without the estimate jumping by more than this (m) from one step to the next ...
pub const STOP_JUMP_M: f64 = 0.4;
/// ... for this many consecutive steps.
pub const STOP_CONFIDENT_STEPS: usize = 3;
/// Decisions remembered by the limit-cycle breaker, and visits of one place/heading in them
/// that count as a cycle.
pub const CYCLE_WINDOW: usize = 16;
pub const CYCLE_REPEATS: usize = 3;
/// Rotation steps after a wheel stall during navigation (the plan already keeps off the walls).
pub const NAV_STALL_TURN_STEPS: usize = 6;
/// The seed's cluster databases (compared, not used by the robot) are learned from at most
/// this many exploration steps: the dissimilarity matrix grows with the square of the steps
/// (4 bytes each: 36 MB at this size).
pub const CLUSTER_DB_MAX_STEPS: usize = 3000;
/// Likelihood temperatures compared by replaying each trial's navigation sequence.
pub const REPLAY_TAUS: [f64; 5] = [0.03, 0.06, 0.12, 0.25, 0.5];

/// Seed 000 Table 4.9, per trial: max and RMS localisation error (m), initial and max distance
/// to the goal (m), steps to the goal, comment.
const SEED_TABLE_4_9: [(f64, f64, f64, f64, u32, &str); 20] = [
    (0.263108, 0.113088, 1.451262, 1.451262, 28, ""),
    (1.373005, 0.408296, 2.017578, 2.017578, 44, ""),
    (0.277988, 0.115034, 2.612348, 2.613312, 45, ""),
    (0.266809, 0.127836, 1.618905, 1.618905, 21, ""),
    (1.209967, 0.339866, 1.158275, 1.158275, 20, ""),
    (2.573254, 0.962738, 5.180108, 5.184237, 85, ""),
    (1.209967, 0.339866, 1.158275, 1.158275, 20, ""),
    (0.770608, 0.289507, 2.255162, 2.255162, 77, ""),
    (0.396196, 0.175624, 2.562783, 2.562783, 30, ""),
    (0.84493, 0.253016, 2.035301, 2.035301, 182, "circling"),
    (2.651533, 0.997474, 2.890733, 3.259291, 43, ""),
    (0.564744, 0.213986, 3.679879, 3.701556, 57, ""),
    (0.318143, 0.180671, 1.854034, 1.856366, 37, ""),
    (0.948004, 0.246589, 3.370003, 3.370003, 89, ""),
    (1.656564, 0.412161, 5.620122, 5.620122, 71, ""),
    (0.832765, 0.18374, 4.616417, 4.616417, 51, ""),
    (3.670778, 0.858748, 6.051785, 6.775494, 488, "limit cycling"),
    (0.355889, 0.167153, 1.706876, 1.935891, 48, ""),
    (0.407162, 0.143514, 2.070111, 2.170551, 41, ""),
    (0.663023, 0.229172, 2.984635, 2.984635, 114, ""),
];

/// One trial's row of the Table 4.9 comparison.
struct TableRow {
    trial: usize,
    max_error: f64,
    rms_error: f64,
    initial_distance: f64,
    max_distance: f64,
    steps: usize,
    reached: bool,
    limit_cycles: usize,
    cycles_broken: usize,
    wall_stalls: u32,
}

/// Appends the trial's row, with the seed's row of the same number, to `table-4.9.md` in the
/// output folder (the first trial starts the file).
fn write_table_row(out: &Path, row: &TableRow) -> anyhow::Result<()> {
    use std::io::Write;
    let path = out.join("table-4.9.md");
    let mut text = String::new();
    if row.trial == 0 {
        text.push_str(
            "# Seed 000 Table 4.9, trial by trial: rfloc | seed\n\n\
             Steps are navigation steps. Limit cycles: stretches of 60 steps without 0.1 m of true \
             progress (referee); broken: repeats detected by the robot.\n\n\
             | # | max loc error (m) | RMS loc error (m) | initial distance (m) | max distance (m) | steps | goal | limit cycles | broken | wall stalls |\n\
             |---|---|---|---|---|---|---|---|---|---|\n",
        );
    }
    let seed = SEED_TABLE_4_9.get(row.trial);
    let pair = |ours: String, theirs: Option<String>| match theirs {
        Some(t) => format!("{ours} \\| {t}"),
        None => ours,
    };
    text.push_str(&format!(
        "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
        row.trial + 1,
        pair(
            format!("{:.3}", row.max_error),
            seed.map(|s| format!("{:.3}", s.0))
        ),
        pair(
            format!("{:.3}", row.rms_error),
            seed.map(|s| format!("{:.3}", s.1))
        ),
        pair(
            format!("{:.2}", row.initial_distance),
            seed.map(|s| format!("{:.2}", s.2))
        ),
        pair(
            format!("{:.2}", row.max_distance),
            seed.map(|s| format!("{:.2}", s.3))
        ),
        pair(row.steps.to_string(), seed.map(|s| s.4.to_string())),
        pair(
            (if row.reached { "reached" } else { "missed" }).to_string(),
            seed.map(|s| if s.5.is_empty() {
                "reached".to_string()
            } else {
                s.5.to_string()
            }),
        ),
        row.limit_cycles,
        row.cycles_broken,
        row.wall_stalls,
    ));
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(row.trial != 0)
        .write(true)
        .truncate(row.trial == 0)
        .open(&path)
        .with_context(|| format!("opening {}", path.display()))?;
    f.write_all(text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// Tag-map settings compared by replaying each trial's navigation sequence with the track
/// filter.
fn tag_map_variants() -> Vec<(&'static str, TagMapConfig)> {
    let d = TagMapConfig::default();
    vec![
        ("default", d),
        (
            "temperature_1",
            TagMapConfig {
                temperature: 1.0,
                ..d
            },
        ),
        (
            "temperature_4",
            TagMapConfig {
                temperature: 4.0,
                ..d
            },
        ),
        (
            "map_sigma_400",
            TagMapConfig {
                map_sigma: 400.0,
                ..d
            },
        ),
    ]
}

/// The reader model the robot localises with: seed 000's propagation fit (Table 3.2), with the
/// scenario's threshold, read noise, dropout and antenna mounting taken as the robot's
/// calibration of its reader, and `[mismatch] scale` as a miscalibrated distance scale.
fn read_model(scenario: &Scenario) -> ReadModel {
    let uhf = scenario.uhf_model();
    ReadModel {
        behind_attenuation: uhf.behind_attenuation,
        read_sigma: uhf.noise_sigma,
        dropout: uhf.dropout,
        antenna_offset: uhf.antenna_offset,
        distance_scale: scenario.spec.mismatch.map_or(1.0, |m| m.scale),
        ..ReadModel::seed000(uhf.threshold, READS_PER_STEP)
    }
}

/// One exploration step in `exploration.csv`: where the robot was, what its odometry said and
/// where the joint learning of map and trajectory placed it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExplorationRow {
    pub step: usize,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub odom_x: f64,
    pub odom_y: f64,
    pub odom_theta: f64,
    pub learned_x: f64,
    pub learned_y: f64,
    pub learned_theta: f64,
}

/// Writes the exploration's true, odometry and learned poses, one row per step.
///
/// # Errors
/// When the file cannot be written.
pub fn write_exploration(
    path: &Path,
    rows: impl Iterator<Item = (Pose2, Pose2, Pose2)>,
) -> anyhow::Result<()> {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_path(path)
        .with_context(|| format!("writing {}", path.display()))?;
    for (step, (t, o, l)) in rows.enumerate() {
        w.serialize(ExplorationRow {
            step,
            x: t.x,
            y: t.y,
            theta: t.theta,
            odom_x: o.x,
            odom_y: o.y,
            odom_theta: o.theta,
            learned_x: l.x,
            learned_y: l.y,
            learned_theta: l.theta,
        })
        .with_context(|| format!("writing {}", path.display()))?;
    }
    w.flush()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Planar distance of two poses.
fn dist(a: &Pose2, b: &Pose2) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// Largest difference between a database and its reloaded copy (state poses and prototype
/// RSS; the JSON text need not round-trip every float to the last bit). Fails when the states or
/// their tag sets differ.
fn reload_difference(saved: &SnapshotDatabase, loaded: &SnapshotDatabase) -> anyhow::Result<f64> {
    anyhow::ensure!(
        saved.states.len() == loaded.states.len() && saved.counts == loaded.counts,
        "the reloaded database has other states or transition counts"
    );
    let mut worst = 0.0_f64;
    for (a, b) in saved.states.iter().zip(&loaded.states) {
        anyhow::ensure!(
            a.prototype.len() == b.prototype.len()
                && a.prototype
                    .iter()
                    .zip(b.prototype.iter())
                    .all(|(x, y)| x.0 == y.0),
            "a reloaded state has other tags"
        );
        for (x, y) in a.prototype.iter().zip(b.prototype.iter()) {
            worst = worst.max((x.1 - y.1).abs());
        }
        worst = worst
            .max((a.pose.x - b.pose.x).abs())
            .max((a.pose.y - b.pose.y).abs())
            .max((a.pose.theta - b.pose.theta).abs());
    }
    anyhow::ensure!(worst < 1e-6, "the reloaded database differs by {worst}");
    Ok(worst)
}

/// Learns on the blocking pool so that the drivers' tasks keep running meanwhile; hands the
/// observations back.
async fn learn_blocking(
    observations: Vec<Observation>,
    config: LearnConfig,
) -> anyhow::Result<(Vec<Observation>, SnapshotDatabase)> {
    tokio::task::spawn_blocking(move || {
        let db = SnapshotDatabase::learn(&observations, &config);
        (observations, db)
    })
    .await
    .map_err(|e| anyhow::anyhow!("learning task failed: {e}"))
    .and_then(|(o, db)| Ok((o, db?)))
}

/// Mean position error of a histogram filter with `config` run again over the navigation
/// sequence (same snapshots and actions), so that filter settings compare on identical data.
fn replay_mean_error(
    db: &SnapshotDatabase,
    config: FilterConfig,
    sequence: &[(Option<Action>, Snapshot, Pose2)],
) -> Option<f64> {
    let mut filter = StateFilter::new(db, config);
    let mut errors = Errors::default();
    for (i, (action, snapshot, truth)) in sequence.iter().enumerate() {
        if let Some(a) = action {
            filter.predict(db, *a);
        }
        filter.update(db, snapshot);
        #[allow(clippy::cast_precision_loss)]
        let est = filter.estimate(db, i as f64);
        errors.push(dist(&est.pose, truth));
    }
    errors.mean()
}

/// Which measurement model a replayed track filter uses.
enum TrackModel<'a> {
    /// The fingerprint kernels alone.
    Fingerprints,
    /// The tag map (fingerprints only propose poses).
    Map(&'a TagMap),
}

/// Mean position error of a track filter run again over the navigation sequence (same
/// odometry increments and snapshots).
fn replay_track_error(
    map: &FingerprintMap,
    model: &TrackModel<'_>,
    sequence: &[(Pose2, Snapshot, Pose2)],
    seed: u64,
) -> Option<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut filter = TrackFilter::new(TrackConfig::default());
    let mut errors = Errors::default();
    for (delta, snapshot, truth) in sequence {
        filter.predict(delta, &mut rng);
        match model {
            TrackModel::Fingerprints => filter.update(map, snapshot, &mut rng),
            TrackModel::Map(tags) => filter.update_with_map(tags, map, snapshot, &mut rng),
        }
        if let Some(e) = filter.estimate() {
            errors.push(dist(&e.pose, truth));
        }
    }
    errors.mean()
}

/// Median of a list (NaN when empty).
fn median(v: &[f64]) -> f64 {
    let mut sorted = v.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Per-trial error accumulator.
#[derive(Debug, Default)]
struct Errors {
    sum: f64,
    sq: f64,
    max: f64,
    n: usize,
}

impl Errors {
    fn push(&mut self, e: f64) {
        self.sum += e;
        self.sq += e * e;
        self.max = self.max.max(e);
        self.n += 1;
    }
    #[allow(clippy::cast_precision_loss)]
    fn mean(&self) -> Option<f64> {
        (self.n > 0).then(|| self.sum / self.n as f64)
    }
    #[allow(clippy::cast_precision_loss)]
    fn rms(&self) -> Option<f64> {
        (self.n > 0).then(|| (self.sq / self.n as f64).sqrt())
    }
}

/// Runs one trial.
#[allow(clippy::too_many_lines, clippy::cast_precision_loss)]
pub async fn run_trial(
    scenario: &Scenario,
    trial: usize,
    dir: &Path,
    _opts: &SimOptions,
) -> anyhow::Result<TrialRecorder> {
    let wall = Instant::now();
    let mut rec = TrialRecorder::new(scenario, trial);
    let seed = scenario.trial_seed(trial);
    let params = &scenario.spec.params;
    let explore_steps = params.exploration_steps.unwrap_or(1000);
    let nav_steps = params.navigation_steps.unwrap_or(500);
    let drive = scenario.spec.robot.drive;
    let act = Actuation {
        table: ActionTable::seed_table(),
        action_duration_s: params.action_duration_s.unwrap_or(scenario.spec.dt_s),
        drive_duration_s: DRIVE_DURATION_S,
        sigma_v: drive.sigma_v,
        sigma_omega: drive.sigma_omega,
        max_speed: drive.max_speed,
        max_turn_rate: drive.max_turn_rate,
    };
    let (goal, tolerance) = scenario
        .goal(trial)
        .zip(scenario.spec.goal.map(|g| g.tolerance_m))
        .context("the snapshot scenario needs a goal")?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x534e_4150_5348_4f54);

    let mut rig = SnapshotRig::start(&RigSpec {
        scenario,
        trial,
        dir,
        reads_per_step: READS_PER_STEP,
        slip: WHEEL_SLIP,
    })
    .await?;

    // 1. Exploration.
    let mut explorer = ExplorationPolicy::new(ExplorationConfig::default());
    let mut reflex = StallReflex::new(STALL_TURN_STEPS);
    let mut known: std::collections::BTreeSet<TagId> = std::collections::BTreeSet::new();
    let mut by_truth: Vec<Observation> = Vec::with_capacity(explore_steps);
    let mut odom_poses: Vec<Pose2> = Vec::with_capacity(explore_steps);
    // Whether each action's SIPs reported a wheel stall (a wall is there).
    let mut stalled_steps: Vec<bool> = Vec::with_capacity(explore_steps);
    for step in 0..explore_steps {
        let snapshot = rig.read_snapshot().await?;
        let new_tags = snapshot
            .iter()
            .filter(|(id, _)| !known.contains(id))
            .count();
        known.extend(snapshot.iter().map(|(id, _)| id.clone()));
        let input = ExplorationInput {
            tags_seen: snapshot.len(),
            new_tags,
        };
        let last = step + 1 == explore_steps;
        let policy_action = explorer.step(input, &mut rng);
        let action = (!last).then(|| reflex.override_action(policy_action));
        by_truth.push(Observation {
            snapshot,
            pose: rig.truth(),
            action,
        });
        odom_poses.push(rig.odometry_pose());
        if let Some(a) = action {
            let cmd = act.drive_command(act.noisy(a, &mut rng));
            let stalled = rig.drive(cmd, DRIVE_DURATION_S).await?;
            stalled_steps.push(stalled);
            reflex.after_action(stalled, &mut rng);
        }
    }
    let odom_drift = by_truth
        .last()
        .zip(odom_poses.last())
        .map_or(0.0, |(o, p)| dist(&o.pose, p));
    let empty = by_truth.iter().filter(|o| o.snapshot.is_empty()).count();

    // 2. Learning, atomic save, reload.
    // The tag map and the exploration trajectory are learned together (`learn_jointly`: the
    // odometry drifts, and a map placed along it blurs with the explored area); everything
    // else is learned from that trajectory.
    let (joint_samples, joint_model) = (
        by_truth
            .iter()
            .map(|o| o.snapshot.clone())
            .zip(odom_poses.iter().copied())
            .collect::<Vec<_>>(),
        read_model(scenario),
    );
    let joint_start = Instant::now();
    let (learned_tags, smoothed, joint_report, odometry_tags) =
        tokio::task::spawn_blocking(move || {
            let pairs: Vec<(&Snapshot, Pose2)> =
                joint_samples.iter().map(|(s, p)| (s, *p)).collect();
            let (map, poses, report) = learn_jointly(
                &pairs,
                joint_model.clone(),
                TagMapConfig::default(),
                &JointConfig::default(),
            );
            // For comparison: the map placed along the odometry alone.
            let plain = TagMap::learn(pairs.iter().copied(), joint_model, TagMapConfig::default());
            (map, poses, report, plain)
        })
        .await
        .map_err(|e| anyhow::anyhow!("tag mapping task failed: {e}"))?;
    let joint_s = joint_start.elapsed().as_secs_f64();

    // The seed's cluster databases (compared, not used by the robot): on the first
    // `CLUSTER_DB_MAX_STEPS` steps of a long exploration (the dissimilarity matrix grows with
    // the square of the steps).
    let cluster_steps = by_truth.len().min(CLUSTER_DB_MAX_STEPS);
    let config = LearnConfig::default();
    let mut cluster_obs = by_truth.clone();
    cluster_obs.truncate(cluster_steps);
    if let Some(last) = cluster_obs.last_mut() {
        last.action = None;
    }
    let (cluster_obs, learned) = learn_blocking(cluster_obs, config)
        .await
        .context("learning the database")?;
    // Everything learned is written as one set (the database, the survey and the tag map
    // together: a crash leaves the previous set whole), and used from its reloaded copies.
    let db_bytes = store::to_json(&learned, "snapshot-db.json")?;
    let db = SnapshotDatabase::from_json(&db_bytes, "snapshot-db.json")
        .context("reloading the database")?;
    let reload_diff = reload_difference(&learned, &db)?;
    let by_odom: Vec<Observation> = cluster_obs
        .iter()
        .zip(&odom_poses)
        .map(|(o, p)| Observation {
            pose: *p,
            ..o.clone()
        })
        .collect();
    let (_, odom_db) = learn_blocking(by_odom, config)
        .await
        .context("learning (odometry)")?;
    let odom_bytes = store::to_json(&odom_db, "snapshot-db-odometry.json")?;

    // The survey: every exploration snapshot at the robot's own estimate of where it was taken
    // (the jointly smoothed trajectory; a live robot localises from it and the tag map:
    // `[estimator] survey`, `tag_map`); the fingerprints are learned from the reloaded copy.
    let survey_bytes = store::to_json(
        &Survey::with_actions(
            by_truth
                .iter()
                .zip(&smoothed)
                .enumerate()
                .map(|(i, (o, p))| {
                    (
                        &o.snapshot,
                        *p,
                        o.action,
                        stalled_steps.get(i).copied().unwrap_or(false),
                    )
                }),
        ),
        "survey.json",
    )?;
    let survey =
        Arc::new(Survey::from_json(&survey_bytes, "survey.json").context("reloading the survey")?);
    // The fine localisation map: the survey's snapshots as fingerprints.
    let fingerprints = survey.fingerprints(config.distance);
    // The tag map, used from the reloaded copy.
    let tags_bytes = store::to_json(&learned_tags, "tag-map.json")?;
    let tag_map =
        TagMap::from_json(&tags_bytes, "tag-map.json").context("reloading the tag map")?;
    state_set::write_set(
        dir,
        &[
            ("snapshot-db.json", db_bytes),
            ("snapshot-db-odometry.json", odom_bytes),
            ("survey.json", survey_bytes),
            ("tag-map.json", tags_bytes),
        ],
    )
    .with_context(|| format!("saving the learned state in {}", dir.display()))?;
    // Errors of the learned tag positions and of the smoothed trajectory against the truth.
    let world_tags: std::collections::HashMap<String, (f64, f64)> = scenario
        .world
        .uhf_tags
        .iter()
        .map(|w| (w.epc.to_ascii_uppercase(), (w.position.x, w.position.y)))
        .collect();
    let errors_of = |map: &TagMap| -> Vec<f64> {
        map.tags
            .iter()
            .filter_map(|t| {
                let (x, y) = world_tags.get(&t.id.to_string().to_ascii_uppercase())?;
                Some((t.x - x).hypot(t.y - y))
            })
            .collect()
    };
    let odometry_tag_errors = errors_of(&odometry_tags);
    let trajectory_errors = |poses: &[Pose2]| -> Vec<f64> {
        by_truth
            .iter()
            .zip(poses)
            .map(|(o, p)| dist(&o.pose, p))
            .collect()
    };
    let (smoothed_errors, odometry_errors) =
        (trajectory_errors(&smoothed), trajectory_errors(&odom_poses));
    write_exploration(
        &dir.join("exploration.csv"),
        by_truth
            .iter()
            .zip(&odom_poses)
            .zip(&smoothed)
            .map(|((o, odo), learned)| (o.pose, *odo, *learned)),
    )?;
    let tag_errors = errors_of(&tag_map);
    // The plan: the learned motion of each action (mean odometry increment of the surveyed
    // steps that did not stall) and the places where the wheels stalled, from the survey.
    let goal_radius = GOAL_FRACTION * tolerance;
    let (plan_survey, table, step_s) = (Arc::clone(&survey), act.table, act.action_duration_s);
    let lattice = tokio::task::spawn_blocking(move || {
        plan_survey.lattice_plan(
            &table,
            step_s,
            (goal.x, goal.y),
            goal_radius,
            LatticeConfig::default(),
        )
    })
    .await
    .map_err(|e| anyhow::anyhow!("planning task failed: {e}"))?;

    // 3. Navigation. Localisation is the daemon's own snapshot pipeline on the reloaded tag
    // map and survey, fed the base's odometry and each snapshot as device events.
    let mut localiser = SnapshotPipeline::on_tag_map(tag_map.clone(), &survey, seed);
    let mut cycles = CycleBreaker::new(CYCLE_WINDOW, CYCLE_REPEATS);
    let mut nav_reflex = StallReflex::new(NAV_STALL_TURN_STEPS);
    let mut filter = StateFilter::new(&db, FilterConfig::default());
    let mut odom_filter = StateFilter::new(&odom_db, FilterConfig::default());
    let mut stalls = StallDetector::new(STALL_WINDOW, STALL_GAIN_M);
    let (mut track_err, mut filter_err, mut nearest_err, mut odom_err) = (
        Errors::default(),
        Errors::default(),
        Errors::default(),
        Errors::default(),
    );
    let goal_pose = Pose2::new(goal.x, goal.y, 0.0);
    let mut prev: Option<Action> = None;
    let mut declared = None::<&'static str>;
    let mut steps_taken = 0usize;
    let mut nav_stalls = 0u32;
    let mut nav_log =
        String::from("step,x,y,theta,est_x,est_y,est_theta,spread,mode,action,reason\n");
    let mut replay: Vec<(Option<Action>, Snapshot, Pose2)> = Vec::new();
    let mut track_replay: Vec<(Pose2, Snapshot, Pose2)> = Vec::new();
    let start_distance = dist(&rig.truth(), &goal_pose);
    let mut max_goal_distance = start_distance;
    let mut last_odom = rig.odometry_pose();
    let mut confident_steps = 0usize;
    let mut last_est: Option<Pose2> = None;
    for step in 0..=nav_steps {
        let snapshot: Snapshot = rig.read_snapshot().await?;
        let odom = rig.odometry_pose();
        let delta = odom.relative_to(&last_odom);
        last_odom = odom;
        let now = rig.sim_time();
        localiser.handle(&DeviceEvent::Odometry {
            device: "base".into(),
            t: now,
            pose: odom,
            v: 0.0,
            w: 0.0,
        });
        let published = localiser.handle(&DeviceEvent::UhfSnapshot {
            device: "uhf".into(),
            t: now,
            tags: snapshot.iter().map(|(id, r)| (id.to_string(), r)).collect(),
        });
        // The published pose with the spread of its mode (RMS distance of its particles).
        let tracked = published.map(|e| {
            let spread = (e.covariance[(0, 0)] + e.covariance[(1, 1)])
                .max(0.0)
                .sqrt();
            (e.pose, spread, e.mode)
        });
        if let Some(a) = prev {
            filter.predict(&db, a);
            odom_filter.predict(&odom_db, a);
        }
        filter.update(&db, &snapshot);
        odom_filter.update(&odom_db, &snapshot);
        let t = step as f64;
        let hist = filter.estimate(&db, t);
        let est = tracked.map_or(hist.pose, |e| e.0);
        let truth = rig.truth();
        rec.truth(t, truth);
        rec.estimate(t, est);
        rec.capture_time(t, now);
        track_err.push(dist(&est, &truth));
        filter_err.push(dist(&hist.pose, &truth));
        odom_err.push(dist(&odom_filter.estimate(&odom_db, t).pose, &truth));
        if let Some(s) = db.states.get(db.localise(&snapshot).state) {
            nearest_err.push(dist(&s.pose, &truth));
        }
        stalls.push(dist(&truth, &goal_pose));
        max_goal_distance = max_goal_distance.max(dist(&truth, &goal_pose));
        replay.push((prev, snapshot.clone(), truth));
        track_replay.push((delta, snapshot.clone(), truth));
        steps_taken = step;
        // Confident: a tight cloud that did not jump since the last step (a step moves ≤ 0.3 m).
        let steady = last_est.is_some_and(|p: Pose2| dist(&p, &est) <= STOP_JUMP_M);
        last_est = tracked.map(|e| e.0);
        let confident = steady
            && tracked.is_some_and(|(_, spread, mode)| {
                mode == EstimateMode::Fix && spread <= STOP_SPREAD_M
            });
        confident_steps = if confident { confident_steps + 1 } else { 0 };
        if confident_steps >= STOP_CONFIDENT_STEPS && dist(&est, &goal_pose) <= goal_radius {
            declared = Some("estimate");
            break;
        }
        if step == nav_steps {
            break;
        }
        let (action, reason) = match tracked {
            Some((pose, _, _)) => {
                let ranked = lattice.ranked(&pose);
                cycles.choose(&pose, &ranked)
            }
            None => {
                let input = ExplorationInput {
                    tags_seen: snapshot.len(),
                    new_tags: 0,
                };
                (explorer.step(input, &mut rng), "no fix")
            }
        };
        let action = nav_reflex.override_action(action);
        let (spread, mode) = tracked.map_or((f64::NAN, "none"), |(_, s, m)| {
            (
                s,
                match m {
                    EstimateMode::Fix => "fix",
                    EstimateMode::Degraded => "degraded",
                    EstimateMode::NoFix => "no_fix",
                },
            )
        });
        nav_log.push_str(&format!(
            "{step},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{spread:.3},{mode},{action:?},{reason}\n",
            truth.x, truth.y, truth.theta, est.x, est.y, est.theta
        ));
        let cmd = act.drive_command(act.noisy(action, &mut rng));
        let stalled = rig.drive(cmd, DRIVE_DURATION_S).await?;
        nav_stalls += u32::from(stalled);
        nav_reflex.after_action(stalled, &mut rng);
        prev = Some(action);
    }
    let final_truth = rig.truth();
    let sim_time = rig.sim_time();
    let counters = rig.counters();
    rig.shutdown().await?;

    let reached = declared.is_some() && dist(&final_truth, &goal_pose) <= tolerance;
    rec.set_success(reached);
    let flag = |b: bool| if b { 1.0 } else { 0.0 };
    rec.metric("limit_cycle_rate", flag(stalls.stalls() > 0));
    rec.metric("stopped_by_robot_rate", flag(declared.is_some()));
    rec.metric("final_distance_to_goal_m", dist(&final_truth, &goal_pose));
    rec.metric("initial_distance_to_goal_m", start_distance);
    rec.metric("navigation_steps", steps_taken as f64);
    if let (Some(m), Some(r)) = (nearest_err.mean(), nearest_err.rms()) {
        rec.metric("nearest_state_mean_error_m", m);
        rec.metric("nearest_state_rmse_m", r);
        rec.metric("nearest_state_max_error_m", nearest_err.max);
    }
    if let Some(m) = track_err.mean() {
        rec.metric("track_mean_error_check_m", m);
    }
    if let (Some(m), Some(r)) = (filter_err.mean(), filter_err.rms()) {
        rec.metric("histogram_filter_mean_error_m", m);
        rec.metric("histogram_filter_rmse_m", r);
        rec.metric("histogram_filter_max_error_m", filter_err.max);
    }
    if let Some(m) = odom_err.mean() {
        rec.metric("odometry_db_mean_error_m", m);
        rec.metric("odometry_db_max_error_m", odom_err.max);
    }
    rec.metric("odometry_drift_after_exploration_m", odom_drift);
    for tau in REPLAY_TAUS {
        let cfg = FilterConfig {
            likelihood_scale: tau,
            ..FilterConfig::default()
        };
        if let Some(m) = replay_mean_error(&db, cfg, &replay) {
            rec.metric(&format!("replay_tau_{tau}_mean_error_m"), m);
        }
    }
    if let Some(m) = replay_track_error(
        &fingerprints,
        &TrackModel::Fingerprints,
        &track_replay,
        seed,
    ) {
        rec.metric("track_replay_fingerprints_mean_error_m", m);
    }
    for (name, cfg) in tag_map_variants() {
        let mut variant = tag_map.clone();
        variant.config = cfg;
        if let Some(m) = replay_track_error(
            &fingerprints,
            &TrackModel::Map(&variant),
            &track_replay,
            seed,
        ) {
            rec.metric(&format!("track_replay_map_{name}_mean_error_m"), m);
        }
    }
    // The same with a map learned by a miscalibrated reader model (mean RSS 15 % low, read σ
    // 1.5 times the true one): how much localisation depends on the calibration.
    let mut wrong = read_model(scenario);
    wrong.coeffs.iter_mut().for_each(|c| *c *= 0.85);
    wrong.read_sigma *= 1.5;
    let miscalibrated = TagMap::learn(survey.pairs(), wrong, TagMapConfig::default());
    if let Some(m) = replay_track_error(
        &fingerprints,
        &TrackModel::Map(&miscalibrated),
        &track_replay,
        seed,
    ) {
        rec.metric("track_replay_map_miscalibrated_mean_error_m", m);
    }
    rec.metric("mapped_tags", tag_map.len() as f64);
    if !tag_errors.is_empty() {
        rec.metric("tag_map_median_error_m", median(&tag_errors));
        rec.metric(
            "tag_map_mean_error_m",
            tag_errors.iter().sum::<f64>() / tag_errors.len() as f64,
        );
    }
    if !odometry_tag_errors.is_empty() {
        rec.metric(
            "tag_map_odometry_median_error_m",
            median(&odometry_tag_errors),
        );
    }
    rec.metric("survey_median_error_m", median(&smoothed_errors));
    rec.metric("survey_odometry_median_error_m", median(&odometry_errors));
    rec.metric(
        "survey_max_error_m",
        smoothed_errors.iter().copied().fold(0.0, f64::max),
    );
    rec.metric(
        "survey_odometry_max_error_m",
        odometry_errors.iter().copied().fold(0.0, f64::max),
    );
    rec.metric("joint_mean_correction_m", joint_report.mean_correction_m);
    rec.metric(
        "joint_last_round_change_m",
        joint_report.last_round_change_m,
    );
    rec.metric("joint_learning_s", joint_s);
    rec.metric("joint_relocks", joint_report.relocks as f64);
    rec.metric("joint_closures", joint_report.closures as f64);
    rec.metric(
        "joint_diverged",
        if joint_report.diverged { 1.0 } else { 0.0 },
    );
    rec.metric(
        "joint_retried",
        if joint_report.retried { 1.0 } else { 0.0 },
    );
    rec.metric("cluster_database_steps", cluster_steps as f64);
    rec.metric("states", db.states.len() as f64);
    rec.metric("fingerprints", fingerprints.len() as f64);
    rec.metric("lattice_sweeps", lattice.sweeps as f64);
    rec.metric("database_reload_max_difference", reload_diff);
    rec.metric("empty_exploration_snapshots", empty as f64);
    rec.metric("limit_cycles", stalls.stalls() as f64);
    rec.metric("cycles_broken", cycles.broken() as f64);
    rec.metric("navigation_wall_stalls", f64::from(nav_stalls));
    rec.metric(
        "exploration_stall_places",
        survey.stall_places().len() as f64,
    );
    rec.metric("unsettled_stops", counters.unsettled as f64);
    rec.metric("wheel_stall_actions", counters.stalls as f64);
    rec.metric("wall_turns", reflex.triggered() as f64);
    rec.metric("bad_epcs", counters.bad_epcs as f64);
    rec.metric("tag_list_reads", counters.reads as f64);
    rec.metric("sim_time_s", sim_time);
    rec.metric("wall_time_s", wall.elapsed().as_secs_f64());
    rec.metric(
        "stopped_by_estimate_rate",
        flag(declared == Some("estimate")),
    );
    let lines: String = rec
        .extra
        .iter()
        .map(|(k, v)| format!("{k},{v}\n"))
        .collect();
    std::fs::write(dir.join("metrics.csv"), format!("metric,value\n{lines}"))
        .context("writing metrics.csv")?;
    std::fs::write(dir.join("navigation.csv"), nav_log).context("writing navigation.csv")?;
    if let Some(out) = dir.parent() {
        write_table_row(
            out,
            &TableRow {
                trial,
                max_error: track_err.max,
                rms_error: track_err.rms().unwrap_or(f64::NAN),
                initial_distance: start_distance,
                max_distance: max_goal_distance,
                steps: steps_taken,
                reached,
                limit_cycles: stalls.stalls(),
                cycles_broken: cycles.broken(),
                wall_stalls: nav_stalls,
            },
        )?;
    }
    tracing::info!(
        trial,
        reached,
        steps = steps_taken,
        states = db.states.len(),
        "snapshot trial done"
    );
    Ok(rec)
}
