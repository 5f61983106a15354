//! The daemon binary on the emitter-homing robot (seed 001, scenario A: the emitter 4 m
//! ahead) in simulation: `rfloc run` starts an emulated Pioneer and four emulated XBee
//! receivers on real pseudo-terminals; the receiver tasks poll the emitter's RSSI over the
//! XBee API (remote `DB`, then local `DB`), the simulation adds laser scans, and the emitter
//! pipeline drives the base. Once the published pose has stood still for 3 s (simulated) the
//! daemon is stopped with SIGTERM; the simulation's referee must have seen the true pose within
//! the seed's 50 cm of the emitter, faster than the seed's 90 s, and the log must show the
//! arrival and the filter's updates.
//! The stream carries the emitter estimates as TARGET lines. Replaying the captures must give
//! back the published poses and TARGET lines near the emitter.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::time::Duration;

/// Emitter position in scenarios A and B (`scenarios/worlds/seed001-a.toml`, `-b.toml`).
const EMITTER: (f64, f64) = (4.0, 0.0);

/// `config/sim-emitter.toml` with a free pose port, a longer time limit, a capture folder and
/// `edits`.
fn config(dir: &std::path::Path, port: u16, edits: &[(&str, &str)]) -> std::path::PathBuf {
    let mut all = vec![("duration_s = 120.0", "duration_s = 600.0")];
    all.extend_from_slice(edits);
    common::sim_robot_file(dir, "sim-emitter.toml", "127.0.0.1:2951", port, &all)
}

fn pose_of(v: &serde_json::Value) -> (i64, (f64, f64, f64)) {
    (
        (v["stamp"].as_f64().unwrap() * 1000.0).round() as i64,
        (
            v["x"].as_f64().unwrap(),
            v["y"].as_f64().unwrap(),
            v["yaw"].as_f64().unwrap(),
        ),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emitter_daemon_homes_on_the_emitter_over_four_xbee_receivers() {
    let log = home_on_the_emitter(&[], 90.0).await;
    assert!(
        log.contains("emulated URG laser on a pty"),
        "the laser on a wire"
    );
    assert!(common::logged(&log, "emitter pipeline summary", "scans") > 50.0);
}

/// Scenario B (a wall across the straight line) with the Pioneer's own sonar ring as the range
/// sensor instead of the laser: SIP sonar readings over the pty map the wall and keep the
/// robot off it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emitter_daemon_maps_the_wall_with_the_pioneer_sonar() {
    let log = home_on_the_emitter(
        &[
            ("seed001-a.toml", "seed001-b.toml"),
            ("pulse_period_s = 0.5", "pulse_period_s = 0.5\nsonar = true"),
            (
                "[[device]]\nname = \"laser\"\n[device.driver]\nkind = \"urg\"\nscan_period_s = 0.2\n",
                "",
            ),
        ],
        230.0,
    )
    .await;
    assert!(!log.contains("emulated URG laser"), "sonar, not the laser");
}

/// Runs the daemon on the edited robot file until the robot stands at the emitter, checks the
/// run against the referee (goal within `seed_full_s`, the seed's full-system time), the stream
/// and the captures, replays them, and returns the daemon's log.
async fn home_on_the_emitter(edits: &[(&str, &str)], seed_full_s: f64) -> String {
    let dir = tempfile::tempdir().unwrap();
    let port = common::free_port();
    let path = config(dir.path(), port, edits);
    let daemon = common::Daemon::start(&path, "info");
    let mut lines = daemon.pose_lines(port).await;
    let mut live = std::collections::BTreeMap::new();
    let mut parked: Option<(f64, f64, f64)> = None;
    let (mut targets, mut last_target) = (0usize, None);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(120);
    loop {
        let Some(line) = common::next_line_before(&mut lines, deadline).await else {
            daemon
                .fail_with_log_tail("the robot never stood still near the emitter")
                .await
        };
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        if v["class"] == "TARGET" {
            assert_eq!(
                (&v["id"], &v["source"]),
                (&"emitter".into(), &"emitter".into())
            );
            last_target = Some((v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap()));
            targets += 1;
            continue;
        }
        if v["class"] != "POSE" {
            continue;
        }
        assert_eq!(v["source"], "emitter");
        let (k, (x, y, yaw)) = pose_of(&v);
        live.insert(k, (x, y, yaw));
        let t = v["stamp"].as_f64().unwrap();
        match parked {
            Some((t0, x0, y0)) if (x - x0).hypot(y - y0) < 0.02 => {
                // The published pose is odometry, which matches the truth to a millimetre
                // here (no slip), so standing within 0.45 m means the referee saw the 50 cm
                // circle. The robot may also stand outside it for a while, 0.3 m from an
                // estimate that is off; the loop then waits for it to move on.
                if t - t0 >= 3.0 && (x - EMITTER.0).hypot(y - EMITTER.1) < 0.45 {
                    break;
                }
            }
            _ => parked = Some((t, x, y)),
        }
    }
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{status:?}\n{log}");
    let arrived_at = common::logged(&log, "arrived at the emitter", "t");
    let reached_at = common::logged(&log, "scenario goal reached", "t");
    let (tx, ty) = (
        common::logged(&log, "final true pose", "x"),
        common::logged(&log, "final true pose", "y"),
    );
    let reach = (tx - EMITTER.0).hypot(ty - EMITTER.1);
    // Reaching the 50 cm circle is checked by the referee's time below; after that the robot
    // stays within its 0.3 m stop distance of an estimate that keeps moving by decimetres.
    assert!(
        reach <= 0.75,
        "robot ended at ({tx:.3}, {ty:.3}), {reach:.3} m from the emitter"
    );
    // Faster than the seed's full system (A: 90 s, B: 230 s; 15 daemon runs of A–E took
    // 12–60 s, docs/results.md). The referee's time (true pose within 50 cm) can lag the
    // navigator's arrival when it stopped 0.3 m from an estimate that was off.
    assert!(
        reached_at < seed_full_s && arrived_at < seed_full_s,
        "goal reached after {reached_at} s, arrival declared after {arrived_at} s simulated"
    );
    let updates = common::logged(&log, "emitter pipeline summary", "updates");
    let steps = common::logged(&log, "emitter pipeline summary", "steps");
    let scans = common::logged(&log, "emitter pipeline summary", "scans");
    assert!(
        updates >= 0.5 * steps && steps > 50.0,
        "{updates} filter updates in {steps} control steps"
    );
    assert!(scans > 50.0, "{scans} laser scans");
    let (ex, ey) = (
        common::logged(&log, "emitter pipeline summary", "emitter_x"),
        common::logged(&log, "emitter pipeline summary", "emitter_y"),
    );
    assert!(
        (ex - EMITTER.0).hypot(ey - EMITTER.1) < 0.75,
        "emitter estimated at ({ex:.2}, {ey:.2})"
    );

    // The stream carried the filter's estimates as TARGET lines.
    let (lx, ly) = last_target.expect("no TARGET line on the stream");
    assert!(
        targets > 50 && (lx - EMITTER.0).hypot(ly - EMITTER.1) < 0.75,
        "{targets} TARGET lines, the last at ({lx:.2}, {ly:.2})"
    );

    // Every receiver's link was recorded with its polls.
    for side in ["front", "left", "back", "right"] {
        let cap = std::fs::read_to_string(dir.path().join(format!("cap/rx-{side}.cap"))).unwrap();
        let polls = cap.lines().filter(|l| l.contains(" tx ")).count();
        assert!(polls > 100, "rx-{side}: {polls} requests");
    }

    // Replay: the poses are the start composed with the recorded odometry, so they come back
    // exactly; the receivers' recorded DB answers feed the filter again.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .args(["replay", "-c"])
        .arg(&path)
        .arg(dir.path().join("cap"))
        .env("RFLOC_LOG", "info")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let objects: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .collect();
    let replayed: std::collections::BTreeMap<i64, (f64, f64, f64)> = objects
        .iter()
        .filter(|v| v["class"] == "POSE")
        .map(pose_of)
        .collect();
    let replayed_targets: Vec<&serde_json::Value> =
        objects.iter().filter(|v| v["class"] == "TARGET").collect();
    let common_keys: Vec<_> = live.keys().filter(|k| replayed.contains_key(k)).collect();
    assert!(
        common_keys.len() * 10 >= live.len() * 9,
        "{} of {} live poses replayed",
        common_keys.len(),
        live.len()
    );
    for k in common_keys {
        assert_eq!(live[k], replayed[k], "pose at stamp {k} ms");
    }
    let replay_updates = common::logged(&stderr, "emitter pipeline summary", "updates");
    assert_eq!(replayed_targets.len() as f64, replay_updates);
    let last = replayed_targets.last().expect("replay printed no TARGET");
    let (rx, ry) = (last["x"].as_f64().unwrap(), last["y"].as_f64().unwrap());
    eprintln!(
        "goal reached at {reached_at:.1} s, arrived at {arrived_at:.1} s; true end {reach:.3} m from the emitter; estimate ({ex:.3}, {ey:.3}) live, ({rx:.3}, {ry:.3}) replayed; {updates} / {replay_updates} filter updates"
    );
    assert!(
        replay_updates >= 0.5 * updates,
        "replay: {replay_updates} updates (live {updates})"
    );
    assert!(
        (rx - EMITTER.0).hypot(ry - EMITTER.1) < 0.75,
        "replay: emitter estimated at ({rx:.2}, {ry:.2})"
    );
    log
}
