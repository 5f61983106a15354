//! The daemon binary on the XBee beacon robot (seed 003) in simulation: `rfloc run` starts an
//! emulated Pioneer and an emulated XBee coordinator on real pseudo-terminals, its XBee task
//! sweeps a simulated antenna stepper with one `ND` round per stop, and the EKF-SLAM pipeline
//! drives the base through the seed's four waypoints, stopping to sweep. Once the published pose
//! has stood still near the last waypoint for 8 s (pose stamps are simulated seconds) the daemon
//! is stopped with SIGTERM; the last pose must be near the robot's true pose, which the daemon
//! logs on exit, and the log must show the four beacons mapped and the last waypoint reached.
//! Replaying the run's captures must then reproduce the published poses to their printed digit.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::time::Duration;

/// `config/sim-xbee.toml` with a free pose port, a faster clock, a longer time limit, less
/// slip and a capture folder.
fn config(dir: &std::path::Path, port: u16) -> std::path::PathBuf {
    common::sim_robot_file(
        dir,
        "sim-xbee.toml",
        "127.0.0.1:2949",
        port,
        &[
            ("time_scale = 5.0", "time_scale = 10.0"),
            ("duration_s = 200.0", "duration_s = 1000.0"),
            ("slip_sigma = 0.05", "slip_sigma = 0.02"),
        ],
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ekfslam_daemon_maps_beacons_and_drives_the_waypoints() {
    let dir = tempfile::tempdir().unwrap();
    let port = common::free_port();
    let path = config(dir.path(), port);
    let daemon = common::Daemon::start(&path, "info");
    let mut lines = daemon.pose_lines(port).await;
    let mut fixes = 0usize;
    let mut poses = 0usize;
    let mut live = std::collections::BTreeMap::new();
    // (stamp, x, y) where the pose last moved.
    let mut parked: Option<(f64, f64, f64)> = None;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(120);
    let last = loop {
        let Some(line) = common::next_line_before(&mut lines, deadline).await else {
            daemon
                .fail_with_log_tail("the robot never parked at the last waypoint")
                .await
        };
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        if v["class"] != "POSE" {
            continue;
        }
        assert_eq!(v["source"], "ekfslam");
        poses += 1;
        if v["mode"] == "fix" {
            fixes += 1;
        }
        let (t, x, y) = (
            v["stamp"].as_f64().unwrap(),
            v["x"].as_f64().unwrap(),
            v["y"].as_f64().unwrap(),
        );
        live.insert(stamp_key(&v), (x, y, v["yaw"].as_f64().unwrap()));
        match parked {
            Some((t0, x0, y0)) if (x - x0).hypot(y - y0) < 0.005 => {
                // The controller is done once the estimate is inside the switching distance
                // (0.3 m), so the robot parks just inside it (one run stopped at 0.298 m). A
                // sweep on the way stands still for about 3.5 s (one sweep every 6.5 s of
                // simulated time, 3 s of it driving), so 8 s without moving is parked.
                if t - t0 >= 8.0 && (x - 7.0).hypot(y - 2.0) < 0.6 {
                    break v;
                }
            }
            _ => parked = Some((t, x, y)),
        }
    };
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{status:?}\n{log}");
    assert!(poses > 500, "{poses} poses");
    assert!(fixes > poses / 2, "{fixes} of {poses} poses were fixes");
    assert!(log.contains("last waypoint reached"), "{log}");
    assert_eq!(
        common::logged(&log, "sweep applied", "mapped"),
        4.0,
        "all four beacons mapped"
    );
    let (tx, ty) = (
        common::logged(&log, "final true pose", "x"),
        common::logged(&log, "final true pose", "y"),
    );
    let (ex, ey) = (last["x"].as_f64().unwrap(), last["y"].as_f64().unwrap());
    let error = (ex - tx).hypot(ey - ty);
    // The last waypoint is (7, 2) and the switching distance 0.3 m.
    assert!(
        (tx - 7.0).hypot(ty - 2.0) < 0.6,
        "robot ended at ({tx}, {ty})"
    );
    assert!(
        error < 0.3,
        "final estimate ({ex}, {ey}) is {error:.3} m from truth ({tx}, {ty})"
    );
    // Every link was recorded; the radio's capture holds the ND requests of the sweeps.
    let xbee = std::fs::read_to_string(dir.path().join("cap/xbee.cap")).unwrap();
    let sweeps = common::logged(&log, "sweep applied", "sweep");
    let tx_lines = xbee.lines().filter(|l| l.contains(" tx ")).count();
    assert!(
        tx_lines as f64 >= sweeps * 40.0,
        "{tx_lines} requests for {sweeps} sweeps of 40 stops"
    );
    assert!(dir.path().join("cap/base.cap").exists());

    // Replaying the session's own captures (odometry from the base, sweeps rebuilt from the
    // radio's ND rounds and sweep marks) gives back the poses the daemon published.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .args(["replay", "-c"])
        .arg(&path)
        .arg(dir.path().join("cap"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let replayed: std::collections::BTreeMap<i64, (f64, f64, f64)> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|v| v["class"] == "POSE")
        .map(|v| {
            (
                stamp_key(&v),
                (
                    v["x"].as_f64().unwrap(),
                    v["y"].as_f64().unwrap(),
                    v["yaw"].as_f64().unwrap(),
                ),
            )
        })
        .collect();
    let common: Vec<_> = live.keys().filter(|k| replayed.contains_key(k)).collect();
    assert!(
        common.len() * 10 >= live.len() * 9,
        "{} of {} live poses replayed",
        common.len(),
        live.len()
    );
    // Equal to the printed digit. Live odometry is stamped when the client decodes a SIP and
    // the capture when the bytes were read: two readings of a wall-paced clock, microseconds
    // apart, so the replayed increments' durations (and wheel-slip covariances) differ in the
    // last bits, which can tip the fourth decimal of a coordinate.
    let (unit_m, unit_rad) = (1e-4, 1e-6);
    for k in common {
        let ((lx, ly, lt), (rx, ry, rt)) = (live[k], replayed[k]);
        assert!(
            (lx - rx).abs() <= unit_m * 1.5
                && (ly - ry).abs() <= unit_m * 1.5
                && (lt - rt).abs() <= unit_rad * 1.5,
            "pose at stamp {k} ms: live {:?}, replayed {:?}",
            live[k],
            replayed[k]
        );
    }
}

/// A pose's stamp in milliseconds (the stream prints microseconds).
fn stamp_key(v: &serde_json::Value) -> i64 {
    (v["stamp"].as_f64().unwrap() * 1000.0).round() as i64
}
