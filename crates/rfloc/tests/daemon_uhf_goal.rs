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

/// The exploration both tests drive on (run once per test binary): its folder, the trial
/// folder (survey, tag map) and the scenario file.
fn explored() -> &'static (tempfile::TempDir, PathBuf, PathBuf) {
    static EXPLORED: std::sync::OnceLock<(tempfile::TempDir, PathBuf, PathBuf)> =
        std::sync::OnceLock::new();
    EXPLORED.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let (trial, scenario) = explore(dir.path());
        (dir, trial, scenario)
    })
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

/// The UHF robot's file: its tag map and survey from `trial`, the simulated world of
/// `scenario`, the robot at `start`, `goal_line` in `[estimator]` and `extra` sections.
fn robot_file(
    trial: &Path,
    scenario: &Path,
    start: rfloc_pose::Pose2,
    goal_line: &str,
    extra: &str,
    port: u16,
) -> String {
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
{goal_line}

[pose]
tcp = "127.0.0.1:{port}"

[state]
dir = {trial:?}
{extra}
[simulation]
scenario = {scenario:?}
time_scale = 5.0
seed = 11
duration_s = 400.0
motion = "still"
start = [{sx}, {sy}, {sh}]
slip_sigma = 0.02
"#,
        sx = start.x,
        sy = start.y,
        sh = start.theta.to_degrees(),
        trial = trial.display().to_string(),
        scenario = scenario.display().to_string(),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uhf_daemon_drives_to_a_goal_on_its_tag_map() {
    let dir = tempfile::tempdir().unwrap();
    let (_, trial, scenario) = explored();
    let survey = rfloc_snapshot::Survey::load(
        &rfloc_snapshot::state_set::resolve(trial, std::path::Path::new("survey.json")).unwrap(),
    )
    .unwrap();
    let (start, goal) = start_and_goal(&survey);
    let port = common::free_port();
    let cfg = dir.path().join("robot.toml");
    std::fs::write(
        &cfg,
        robot_file(
            trial,
            scenario,
            start,
            &format!("goal = [{}, {}]", goal.0, goal.1),
            "",
            port,
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

/// The same robot as a VDA 5050 vehicle: no goal in its file; a fleet manager's order (from
/// where the robot localised itself to the surveyed goal) is planned over the survey and driven
/// in seed actions, and the order finishes at its last node. The node tolerance (0.25 m) is
/// what the robot's estimate must reach; its true pose must then be within the seed's 0.4 m.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uhf_fleet_vehicle_drives_an_order_on_its_tag_map() {
    let Some(mosquitto) =
        common::fleet::require_mosquitto("uhf_fleet_vehicle_drives_an_order_on_its_tag_map")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (_, trial, scenario) = explored();
    let survey = rfloc_snapshot::Survey::load(
        &rfloc_snapshot::state_set::resolve(trial, std::path::Path::new("survey.json")).unwrap(),
    )
    .unwrap();
    let (start, goal) = start_and_goal(&survey);
    let broker = common::fleet::Broker::start(&mosquitto, dir.path()).await;
    let mut m = common::fleet::Manager::connect(broker.port, "manager-uhf").await;
    let serial = "uhf-1";
    let fleet = format!(
        "\n[fleet]\nbroker = \"{}\"\nmanufacturer = \"rfloc\"\nserial_number = \"{serial}\"\n\
         node_tolerance_m = 0.25\n",
        broker.address()
    );
    let cfg = dir.path().join("robot.toml");
    let port = common::free_port();
    std::fs::write(&cfg, robot_file(trial, scenario, start, "", &fleet, port)).unwrap();
    let daemon = common::Daemon::start(&cfg, "info");
    let Some(s) = m
        .wait_for(serial, "state", 60.0, |s| {
            s["agvPosition"]["positionInitialized"] == true
        })
        .await
    else {
        daemon.fail_with_log_tail("never localised").await
    };
    let (x0, y0) = common::fleet::position(&s).unwrap();
    m.order(serial, serial, "u1", &[(x0, y0), goal]).await;
    let done = m
        .wait_for(serial, "state", 150.0, |s| {
            s["orderId"] == "u1" && s["lastNodeId"] == "u1-n1"
        })
        .await;
    if done.is_none() {
        daemon.fail_with_log_tail("order u1 not finished").await;
    }
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{log}");
    assert!(log.contains("fleet order accepted"), "{log}");
    let (tx, ty) = (
        common::logged(&log, "simulated robot final true pose", "x"),
        common::logged(&log, "simulated robot final true pose", "y"),
    );
    let miss = (tx - goal.0).hypot(ty - goal.1);
    assert!(
        miss <= 0.4,
        "order finished {miss:.2} m from its last node ({tx:.2}, {ty:.2})\n{log}"
    );
}
