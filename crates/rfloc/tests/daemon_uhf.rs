//! The daemon binary on the UHF mine-robot setup: a Pioneer on a real pseudo-terminal, an Alien
//! reader emulator behind a loopback TCP socket that wants a password (read from a credential
//! file, never logged), and a learned snapshot database in the state folder. Moving the tags
//! the reader sees from one learned place to another moves the published pose with them.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rfloc_alien::{EmulatorOptions, ReaderEmulator};
use rfloc_aria::{EmulatorConfig as RobotConfig, RobotEmulator};
use rfloc_pose::Pose2;
use rfloc_snapshot::{
    Action, ClusterCount, ClusteringMethod, LearnConfig, Observation, Snapshot, SnapshotDatabase,
    TagId,
};
use tokio_serial::{SerialPort, SerialStream};

const SECRET: &str = "s3cret-reader-pw";

/// Tags seen at two learned places.
fn place(which: usize) -> Vec<(Vec<u8>, f64)> {
    let base = if which == 0 { 0x10u8 } else { 0x20u8 };
    (0..4)
        .map(|i| (vec![0xE2, 0x00, base, i], 4000.0 - 500.0 * f64::from(i)))
        .collect()
}

fn learned_database() -> SnapshotDatabase {
    let mut obs = Vec::new();
    for (which, (x, y)) in [(0usize, (0.0, 0.0)), (1, (2.0, 1.0))] {
        for k in 0..4 {
            let reads = place(which)
                .into_iter()
                .map(|(id, rss)| (TagId::new(id), rss + f64::from(k) * 10.0));
            obs.push(Observation {
                snapshot: Snapshot::from_reads(reads),
                pose: Pose2::new(x + 0.01 * f64::from(k), y, 0.0),
                action: Some(Action::Forward),
            });
        }
    }
    let config = LearnConfig {
        clustering: ClusteringMethod::KMedoids {
            k: ClusterCount::Fixed(2),
            max_iter: 50,
            seed: 1,
        },
        ..LearnConfig::default()
    };
    SnapshotDatabase::learn(&obs, &config).unwrap()
}

async fn wait_pose_near<R: tokio::io::AsyncBufRead + Unpin>(
    lines: &mut tokio::io::Lines<R>,
    x: f64,
    y: f64,
) -> serde_json::Value {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    loop {
        let line = tokio::time::timeout_at(deadline, lines.next_line())
            .await
            .unwrap_or_else(|_| panic!("no pose near ({x}, {y})"))
            .unwrap()
            .expect("stream ended");
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        if v["class"] == "POSE" && v["source"] == "snapshot" {
            let (px, py) = (v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap());
            if (px - x).hypot(py - y) < 0.2 {
                return v;
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uhf_daemon_localises_on_the_learned_database() {
    let dir = tempfile::tempdir().unwrap();
    learned_database()
        .save(&dir.path().join("snapshot-db.json"))
        .unwrap();
    std::fs::write(dir.path().join("alien.pw"), format!("{SECRET}\n")).unwrap();

    let (master, slave) = SerialStream::pair().unwrap();
    let base_path = slave.name().unwrap();
    let mut robot = RobotEmulator::new(RobotConfig::default());
    tokio::spawn(async move {
        let _ = robot.serve(master).await;
    });

    let seen = Arc::new(Mutex::new(1usize));
    let field_seen = Arc::clone(&seen);
    let field = Arc::new(move || place(*field_seen.lock().unwrap()));
    let options = EmulatorOptions {
        password: SECRET.into(),
        ..EmulatorOptions::default()
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let reader_addr = listener.local_addr().unwrap();
    tokio::spawn(async move {
        let _ = ReaderEmulator::new(field, options)
            .serve_listener(listener)
            .await;
    });

    let pose_port = common::free_port();
    let cfg = dir.path().join("robot.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"[robot]
name = "uhf-e2e"

[[device]]
name = "base"
link = {{ kind = "serial", path = "{base_path}", baud = 9600 }}
[device.driver]
kind = "aria"

[[device]]
name = "uhf"
link = {{ kind = "tcp", address = "{reader_addr}" }}
[device.driver]
kind = "alien"
password_file = "alien.pw"
reads_per_snapshot = 2

[estimator]
pipeline = "snapshot"

[pose]
tcp = "127.0.0.1:{pose_port}"

[state]
dir = "{}"
"#,
            dir.path().display()
        ),
    )
    .unwrap();

    let daemon = common::Daemon::start(&cfg, "debug");
    let mut lines = daemon.pose_lines(pose_port).await;
    let at_b = wait_pose_near(&mut lines, 2.0, 1.0).await;
    assert_eq!(at_b["mode"], "fix");
    *seen.lock().unwrap() = 0;
    wait_pose_near(&mut lines, 0.0, 0.0).await;

    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{log}");
    assert!(log.contains("learned snapshot database loaded"), "{log}");
    assert!(
        !log.contains(SECRET),
        "the reader password appeared in the log"
    );
    drop(slave);
}
