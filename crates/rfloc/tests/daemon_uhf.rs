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

/// A Pioneer emulator on a pty, an Alien reader emulator (password [`SECRET`], tags from
/// `field`) on loopback TCP, the password file and a robot file for both in `dir`, with
/// `estimator` added to the snapshot pipeline's table.
struct UhfRig {
    config: std::path::PathBuf,
    pose_port: u16,
    _slave: SerialStream,
}

impl UhfRig {
    async fn start(dir: &std::path::Path, field: rfloc_alien::TagField, estimator: &str) -> Self {
        std::fs::write(dir.join("alien.pw"), format!("{SECRET}\n")).unwrap();
        let (master, slave) = SerialStream::pair().unwrap();
        let base_path = slave.name().unwrap();
        let mut robot = RobotEmulator::new(RobotConfig::default());
        tokio::spawn(async move {
            let _ = robot.serve(master).await;
        });
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let reader_addr = listener.local_addr().unwrap();
        let options = EmulatorOptions {
            password: SECRET.into(),
            ..EmulatorOptions::default()
        };
        tokio::spawn(async move {
            let _ = ReaderEmulator::new(field, options)
                .serve_listener(listener)
                .await;
        });
        let pose_port = common::free_port();
        let config = dir.join("robot.toml");
        std::fs::write(
            &config,
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
{estimator}
[pose]
tcp = "127.0.0.1:{pose_port}"

[state]
dir = "{}"
"#,
                dir.display()
            ),
        )
        .unwrap();
        Self {
            config,
            pose_port,
            _slave: slave,
        }
    }
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
    let seen = Arc::new(Mutex::new(1usize));
    let field_seen = Arc::clone(&seen);
    let rig = UhfRig::start(
        dir.path(),
        Arc::new(move || place(*field_seen.lock().unwrap())),
        "",
    )
    .await;
    let (cfg, pose_port) = (rig.config.clone(), rig.pose_port);
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
    drop(rig);
}

/// Tags at seeded random places in a 4 m × 4 m room.
fn room_tags() -> Vec<(f64, f64)> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    (0..250)
        .map(|_| (4.0 * rng.random::<f64>(), 4.0 * rng.random::<f64>()))
        .collect()
}

fn room_tag_id(i: usize) -> Vec<u8> {
    vec![0xE2, 0x00, (i >> 8) as u8, (i & 0xff) as u8]
}

/// What the reader sees from `pose` under `model`, with its read noise.
fn room_read(
    model: &rfloc_snapshot::ReadModel,
    tags: &[(f64, f64)],
    pose: &Pose2,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Vec<(Vec<u8>, f64)> {
    use rand::Rng;
    let a = model.antenna(pose);
    let mut out = Vec::new();
    for (i, (x, y)) in tags.iter().enumerate() {
        let m = model.mean_rss_from(&a, *x, *y);
        let (u1, u2): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
        let r = m + model.read_sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        if r >= model.threshold && rng.random::<f64>() >= model.dropout {
            out.push((room_tag_id(i), r));
        }
    }
    out
}

async fn wait_pose_close<R: tokio::io::AsyncBufRead + Unpin>(
    lines: &mut tokio::io::Lines<R>,
    truth: &Pose2,
) -> serde_json::Value {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    let mut last = String::new();
    loop {
        let line = tokio::time::timeout_at(deadline, lines.next_line())
            .await
            .unwrap_or_else(|_| panic!("no fix near {truth:?}; last: {last}"))
            .unwrap()
            .expect("stream ended");
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        if v["class"] == "POSE" && v["source"] == "snapshot" {
            let (px, py) = (v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap());
            let heading = v["yaw"].as_f64().unwrap();
            let dh = rfloc_pose::angle_diff(heading, truth.theta).abs();
            if (px - truth.x).hypot(py - truth.y) < 0.15 && dh < 0.2 && v["mode"] == "fix" {
                return v;
            }
            last = line;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uhf_daemon_localises_on_the_tag_map_and_recovers_from_a_kidnap() {
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().unwrap();
    let model = rfloc_snapshot::ReadModel::seed000(1000.0, 2);
    let tags = room_tags();
    // The survey an exploration run would have left: 500 places, all headings.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(22);
    let samples: Vec<(Snapshot, Pose2)> = (0..500)
        .map(|_| {
            let p = Pose2::new(
                0.2 + 3.6 * rng.random::<f64>(),
                0.2 + 3.6 * rng.random::<f64>(),
                std::f64::consts::TAU * rng.random::<f64>(),
            );
            let s = Snapshot::from_reads(
                room_read(&model, &tags, &p, &mut rng)
                    .into_iter()
                    .map(|(id, r)| (TagId::new(id), r)),
            );
            (s, p)
        })
        .collect();
    let survey = rfloc_snapshot::Survey::new(samples.iter().map(|(s, p)| (s, *p)));
    survey.save(&dir.path().join("survey.json")).unwrap();
    rfloc_snapshot::TagMap::learn(
        survey.pairs(),
        model.clone(),
        rfloc_snapshot::TagMapConfig::default(),
    )
    .save(&dir.path().join("tag-map.json"))
    .unwrap();
    // The robot stands still; the reader sees the room from `truth`.
    let a = Pose2::new(1.2, 2.5, 0.6);
    let b = Pose2::new(3.0, 1.0, -2.2);
    let truth = Arc::new(Mutex::new(a));
    let field_truth = Arc::clone(&truth);
    let field_rng = Mutex::new(rand_chacha::ChaCha8Rng::seed_from_u64(23));
    let field = Arc::new(move || {
        let pose = *field_truth.lock().unwrap();
        room_read(&model, &tags, &pose, &mut field_rng.lock().unwrap())
    });
    let rig = UhfRig::start(
        dir.path(),
        field,
        "survey = \"survey.json\"\ntag_map = \"tag-map.json\"\n",
    )
    .await;
    let (cfg, pose_port) = (rig.config.clone(), rig.pose_port);
    let session = dir.path().join("session");
    let daemon = common::Daemon::record(&cfg, &session, "debug");
    let mut lines = daemon.pose_lines(pose_port).await;
    let at_a = wait_pose_close(&mut lines, &a).await;
    // The covariance is the particle cloud's: positive, below the fix's spread bound.
    let cov: Vec<f64> = at_a["cov"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(cov.len(), 36, "{at_a}");
    assert!(
        cov[0] > 0.0 && cov[0] < 0.09 && cov[7] > 0.0 && cov[7] < 0.09,
        "{at_a}"
    );
    // Kidnapped: the filter finds the robot again from the survey's proposals.
    *truth.lock().unwrap() = b;
    wait_pose_close(&mut lines, &b).await;

    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{log}");
    assert!(log.contains("tag map and survey loaded"), "{log}");
    drop(rig);

    // The recorded reader link: the password never reached the file, each averaged snapshot is
    // marked, and the session replays through the same pipeline to the same two places.
    let text = std::fs::read_to_string(session.join("uhf.cap")).unwrap();
    assert!(!text.contains(SECRET), "the password is in the capture");
    assert!(
        text.contains("<redacted>"),
        "no redacted login in the capture"
    );
    let marks = text.matches("ev mark snapshot reads=2").count();
    assert!(marks >= 2, "{marks} snapshot marks");
    let replay = std::process::Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .arg("replay")
        .arg(&session)
        .output()
        .unwrap();
    assert!(
        replay.status.success(),
        "{}",
        String::from_utf8_lossy(&replay.stderr)
    );
    let poses: Vec<serde_json::Value> = String::from_utf8_lossy(&replay.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|v: &serde_json::Value| v["source"] == "snapshot")
        .collect();
    assert!(
        poses.len() + 2 >= marks,
        "{} poses for {marks} snapshots",
        poses.len()
    );
    let near = |v: &serde_json::Value, p: &Pose2| {
        (v["x"].as_f64().unwrap() - p.x).hypot(v["y"].as_f64().unwrap() - p.y) < 0.15
    };
    let first_b = poses
        .iter()
        .position(|v| near(v, &b))
        .expect("replay never at b");
    assert!(
        poses[..first_b].iter().any(|v| near(v, &a)),
        "replay never at a before b"
    );
    assert!(near(poses.last().unwrap(), &b), "replay ends away from b");
}
