//! `rfloc record` of a simulated robot, then `rfloc replay` of the recording: the replay runs the
//! very device code of the live run over the recorded links, so it must print the POSE and
//! TARGET lines of the live run byte for byte, whatever the load of the machine (CI runs these
//! tests once more beside a CPU hog). One test per pipeline.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `config/<name>` with each `(old, new)` edit (each must change the text), the pose port moved
/// to a free one, POSE lines on stdout and the scenario path made absolute.
fn robot_file(dir: &Path, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(workspace().join("config").join(name)).unwrap();
    for (old, new) in edits {
        let edited = text.replacen(old, new, 1);
        assert_ne!(edited, text, "config/{name} has no {old:?} to edit");
        text = edited;
    }
    let scenarios = workspace().join("scenarios").display().to_string();
    text = text.replace("\"../scenarios/", &format!("\"{scenarios}/"));
    let port = common::free_port();
    let text = regex_free_port(&text, port);
    let text = if text.contains("stdout = true") {
        text
    } else {
        text.replace("[pose]\n", "[pose]\nstdout = true\n")
    };
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Replaces the `tcp = "127.0.0.1:NNNN"` of `[pose]` with `port`.
fn regex_free_port(text: &str, port: u16) -> String {
    text.lines()
        .map(|l| {
            if l.starts_with("tcp = \"127.0.0.1:") {
                format!("tcp = \"127.0.0.1:{port}\"")
            } else if l.starts_with("listen = \"127.0.0.1:") {
                // Any free port: several simulated robots run at once.
                "listen = \"127.0.0.1:0\"".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

/// POSE and TARGET lines of a run's stdout.
fn estimate_lines(stdout: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(stdout)
        .lines()
        .filter(|l| l.starts_with("{\"class\":\"POSE\"") || l.starts_with("{\"class\":\"TARGET\""))
        .map(str::to_string)
        .collect()
}

/// Records `robot` into `dir/cap`, replays it, and compares; returns the live lines.
fn record_and_replay(robot: &Path, dir: &Path) -> Vec<String> {
    let cap = dir.join("cap");
    let live = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .args(["record", "-c"])
        .arg(robot)
        .arg("-o")
        .arg(&cap)
        .env("RFLOC_LOG", "warn")
        .output()
        .unwrap();
    assert!(
        live.status.success(),
        "record: {}",
        String::from_utf8_lossy(&live.stderr)
    );
    let replay = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .arg("replay")
        .arg(&cap)
        .env("RFLOC_LOG", "warn")
        .output()
        .unwrap();
    assert!(
        replay.status.success(),
        "replay: {}",
        String::from_utf8_lossy(&replay.stderr)
    );
    let live = estimate_lines(&live.stdout);
    let replayed = estimate_lines(&replay.stdout);
    live.iter().for_each(|l| common::assert_stream_line(l));
    assert!(!live.is_empty(), "the live run published nothing");
    if let Some(i) = (0..live.len().max(replayed.len())).find(|i| live.get(*i) != replayed.get(*i))
    {
        panic!(
            "line {} of {} live / {} replayed differs:\nlive:     {:?}\nreplayed: {:?}",
            i + 1,
            live.len(),
            replayed.len(),
            live.get(i),
            replayed.get(i)
        );
    }
    assert!(cap.join("pipeline.order").exists());
    live
}

#[test]
fn hfgrid_live_equals_replay() {
    let dir = tempfile::tempdir().unwrap();
    let robot = robot_file(
        dir.path(),
        "sim.toml",
        &[("time_scale = 5.0", "time_scale = 10.0")],
    );
    let lines = record_and_replay(&robot, dir.path());
    assert!(
        lines.iter().any(|l| l.contains("\"mode\":\"fix\"")),
        "no fix"
    );
}

#[test]
fn odometry_live_equals_replay() {
    let dir = tempfile::tempdir().unwrap();
    let robot = robot_file(
        dir.path(),
        "sim.toml",
        &[
            ("pipeline = \"hfgrid\"", "pipeline = \"odometry\""),
            ("tag_field = \"seed002-test\"", ""),
            ("time_scale = 5.0", "time_scale = 10.0"),
            ("duration_s = 40.0", "duration_s = 25.0"),
            ("motion = \"turn\"", "motion = \"square\""),
        ],
    );
    let lines = record_and_replay(&robot, dir.path());
    assert!(lines.len() > 100, "{} poses", lines.len());
}

#[test]
fn ekfslam_live_equals_replay() {
    let dir = tempfile::tempdir().unwrap();
    let robot = robot_file(
        dir.path(),
        "sim-xbee.toml",
        &[
            ("time_scale = 5.0", "time_scale = 10.0"),
            ("duration_s = 200.0", "duration_s = 40.0"),
        ],
    );
    let lines = record_and_replay(&robot, dir.path());
    assert!(
        lines.iter().any(|l| l.contains("\"mode\":\"fix\"")),
        "no fix"
    );
}

#[test]
fn emitter_live_equals_replay() {
    let dir = tempfile::tempdir().unwrap();
    let robot = robot_file(
        dir.path(),
        "sim-emitter.toml",
        &[
            ("duration_s = 120.0", "duration_s = 30.0"),
            ("time_scale = 5.0", "time_scale = 10.0"),
        ],
    );
    let lines = record_and_replay(&robot, dir.path());
    assert!(
        lines.iter().any(|l| l.starts_with("{\"class\":\"TARGET\"")),
        "no TARGET line"
    );
}

#[test]
fn snapshot_live_equals_replay() {
    let dir = tempfile::tempdir().unwrap();
    // A short exploration learns a survey and a tag map.
    let world = workspace().join("scenarios/worlds/seed000-5x5.toml");
    let text = std::fs::read_to_string(workspace().join("scenarios/seed000-sim.toml")).unwrap();
    let reduced = text
        .replace("exploration_steps = 1000", "exploration_steps = 300")
        .replace("navigation_steps = 500", "navigation_steps = 1")
        .replace(
            "world_file = \"worlds/seed000-5x5.toml\"",
            &format!("world_file = {:?}", world.to_str().unwrap()),
        );
    assert_ne!(reduced, text);
    let scenario = dir.path().join("seed000-sim.toml");
    std::fs::write(&scenario, reduced).unwrap();
    let explore = dir.path().join("explore");
    let run = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .arg("sim")
        .arg(&scenario)
        .args(["--trials", "1", "--allow-failures", "-o"])
        .arg(&explore)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let trial = explore.join("trial-00");
    let robot = robot_file(
        dir.path(),
        "sim-uhf.toml",
        &[
            (
                "dir = \"out/seed000-sim/trial-00\"",
                &format!("dir = {:?}", trial.display().to_string()),
            ),
            (
                "scenario = \"../scenarios/seed000-sim.toml\"",
                &format!("scenario = {:?}", scenario.display().to_string()),
            ),
            ("time_scale = 5.0", "time_scale = 10.0"),
            ("duration_s = 300.0", "duration_s = 40.0"),
            ("start = [1.0, 1.0, 0.0]", "start = [2.0, 2.5, 0.0]"),
        ],
    );
    let lines = record_and_replay(&robot, dir.path());
    assert!(lines.len() > 10, "{} poses", lines.len());
}
