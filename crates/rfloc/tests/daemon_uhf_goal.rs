//! The UHF robot drives itself to a goal: `rfloc sim` explores seed 000's world (reduced to
//! 500 steps) and leaves its survey and tag map; `rfloc run` then starts an emulated Pioneer
//! (walled in by the world) and an emulated Alien reader (the world's 800 tags, read at the
//! robot's true pose) and the snapshot pipeline localises on the tag map and drives to a goal
//! 2 m or more away, one seed action at a time. The robot must say it arrived, and its true
//! final pose (logged by the simulation at exit) must be within the seed's 0.4 m tolerance.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Explores the world and returns the trial folder (survey, tag map) and the scenario file.
fn explore(dir: &Path) -> (PathBuf, PathBuf) {
    let world = workspace().join("scenarios/worlds/seed000-5x5.toml");
    let text = std::fs::read_to_string(workspace().join("scenarios/seed000-sim.toml")).unwrap();
    let reduced = text
        .replace("exploration_steps = 1000", "exploration_steps = 500")
        .replace("navigation_steps = 500", "navigation_steps = 1")
        .replace(
            "world_file = \"worlds/seed000-5x5.toml\"",
            &format!("world_file = {:?}", world.to_str().unwrap()),
        );
    assert_ne!(reduced, text);
    let scenario = dir.join("seed000-sim.toml");
    std::fs::write(&scenario, reduced).unwrap();
    let out = dir.join("explore");
    let run = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .arg("sim")
        .arg(&scenario)
        .args(["--trials", "1", "--allow-failures", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    (out.join("trial-00"), scenario)
}

/// Two surveyed places at least 2 m apart and 0.7 m from the walls (start, goal).
fn start_and_goal(survey: &rfloc_snapshot::Survey) -> (rfloc_pose::Pose2, (f64, f64)) {
    let inner: Vec<rfloc_pose::Pose2> = survey
        .poses()
        .into_iter()
        .filter(|p| (0.7..=4.3).contains(&p.x) && (0.7..=4.3).contains(&p.y))
        .collect();
    let start = *inner
        .first()
        .expect("no surveyed place away from the walls");
    let goal = inner
        .iter()
        .rev()
        .find(|p| p.distance(&start) >= 2.0)
        .expect("no surveyed place 2 m from the start");
    (start, (goal.x, goal.y))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uhf_daemon_drives_to_a_goal_on_its_tag_map() {
    let dir = tempfile::tempdir().unwrap();
    let (trial, scenario) = explore(dir.path());
    let survey = rfloc_snapshot::Survey::load(
        &rfloc_snapshot::state_set::resolve(&trial, std::path::Path::new("survey.json")).unwrap(),
    )
    .unwrap();
    let (start, goal) = start_and_goal(&survey);
    let port = common::free_port();
    let cfg = dir.path().join("robot.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"[robot]
name = "uhf-goal-e2e"

[[device]]
name = "base"
[device.driver]
kind = "aria"
pulse_period_s = 0.5

[[device]]
name = "uhf"
[device.driver]
kind = "alien"
reads_per_snapshot = 2

[estimator]
pipeline = "snapshot"
survey = "survey.json"
tag_map = "tag-map.json"
goal = [{gx}, {gy}]

[pose]
tcp = "127.0.0.1:{port}"

[state]
dir = {trial:?}

[simulation]
scenario = {scenario:?}
time_scale = 5.0
seed = 11
duration_s = 400.0
motion = "still"
start = [{sx}, {sy}, {sh}]
slip_sigma = 0.02
"#,
            gx = goal.0,
            gy = goal.1,
            sx = start.x,
            sy = start.y,
            sh = start.theta.to_degrees(),
            trial = trial.display().to_string(),
            scenario = scenario.display().to_string(),
        ),
    )
    .unwrap();
    let daemon = common::Daemon::start(&cfg, "info");
    let mut lines = daemon.pose_lines(port).await;
    // Until the published pose has stayed near the goal for 10 poses (or 150 s of wall time).
    let deadline = tokio::time::Instant::now() + Duration::from_secs(150);
    let mut near = 0usize;
    let mut poses = 0usize;
    while near < 10 {
        let Ok(Ok(Some(line))) = tokio::time::timeout_at(deadline, lines.next_line()).await else {
            break;
        };
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        if v["class"] != "POSE" {
            continue;
        }
        poses += 1;
        let (x, y) = (v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap());
        near = if (x - goal.0).hypot(y - goal.1) < 0.3 {
            near + 1
        } else {
            0
        };
    }
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{log}");
    assert!(poses > 10, "{poses} poses\n{log}");
    assert!(log.contains("goal plan solved"), "{log}");
    assert!(
        log.contains("goal reached"),
        "the robot never said it arrived\n{log}"
    );
    let (tx, ty) = (
        common::logged(&log, "simulated robot final true pose", "x"),
        common::logged(&log, "simulated robot final true pose", "y"),
    );
    let miss = (tx - goal.0).hypot(ty - goal.1);
    let travelled = (tx - start.x).hypot(ty - start.y);
    assert!(
        miss <= 0.4,
        "stopped {miss:.2} m from the goal ({tx:.2}, {ty:.2}) after {travelled:.2} m\n{log}"
    );
    eprintln!(
        "start ({:.2}, {:.2}), goal ({:.2}, {:.2}): true final pose {miss:.3} m from the goal, {} actions",
        start.x,
        start.y,
        goal.0,
        goal.1,
        common::logged(&log, "goal reached", "actions")
    );
}
