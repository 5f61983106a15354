//! The daemon binary against emulated devices: a Pioneer on a real pseudo-terminal and an HF
//! reader behind a loopback TCP socket (as through a serial-to-TCP bridge). A client on the
//! JSON port receives poses; the reader's link is killed mid-run and the daemon reconnects;
//! SIGTERM ends the daemon cleanly and the robot saw STOP and CLOSE.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::sync::Arc;
use std::time::Duration;

use rfloc_aria::{EmulatorConfig as RobotConfig, RobotEmulator};
use rfloc_kts::{EmulatorConfig as ReaderConfig, KtsEmulator, TagGrid};
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio_serial::{SerialPort, SerialStream};

/// Reads JSON lines until one satisfies `pred`, within `limit`.
async fn wait_for<R: tokio::io::AsyncBufRead + Unpin>(
    lines: &mut tokio::io::Lines<R>,
    limit: Duration,
    what: &str,
    pred: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = tokio::time::Instant::now() + limit;
    loop {
        let line = tokio::time::timeout_at(deadline, lines.next_line())
            .await
            .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
            .unwrap()
            .unwrap_or_else(|| panic!("stream ended waiting for {what}"));
        let v: serde_json::Value =
            serde_json::from_str(&line).unwrap_or_else(|e| panic!("bad JSON {line}: {e}"));
        if pred(&v) {
            return v;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn daemon_publishes_reconnects_and_stops_the_robot() {
    // Pioneer emulator on a pty; the test keeps the slave side open.
    let (master, slave) = SerialStream::pair().unwrap();
    let base_path = slave.name().unwrap();
    let mut robot = RobotEmulator::new(RobotConfig::default());
    let robot_state = robot.handle();
    tokio::spawn(async move {
        let _ = robot.serve(master).await;
    });

    // HF reader emulator behind a loopback listener; each connection gets a fresh reader, and
    // `kill` drops the current connection.
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let reader_addr = listener.local_addr().unwrap();
    let (kill_tx, kill_rx) = watch::channel(0u32);
    let connections = Arc::new(std::sync::atomic::AtomicU32::new(0));
    let conns = Arc::clone(&connections);
    tokio::spawn(async move {
        loop {
            let (sock, _) = listener.accept().await.unwrap();
            conns.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            let mut kill = kill_rx.clone();
            kill.borrow_and_update();
            let antenna = Arc::new(|| (0.1, 0.1));
            let mut emulator =
                KtsEmulator::new(ReaderConfig::new(TagGrid::seed002_test_field(), antenna));
            tokio::spawn(async move {
                tokio::select! {
                    _ = emulator.serve(sock) => {}
                    _ = kill.changed() => {}
                }
            });
        }
    });

    let pose_port = common::free_port();
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("robot.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"[robot]
name = "e2e"

[[device]]
name = "base"
link = {{ kind = "serial", path = "{base_path}", baud = 9600 }}
[device.driver]
kind = "aria"

[[device]]
name = "hf"
link = {{ kind = "tcp", address = "{reader_addr}" }}
[device.driver]
kind = "kts"

[estimator]
pipeline = "odometry"

[pose]
tcp = "127.0.0.1:{pose_port}"
"#
        ),
    )
    .unwrap();

    let daemon = common::Daemon::start(&cfg, "info");
    let mut lines = daemon.pose_lines(pose_port).await;
    let version = wait_for(&mut lines, Duration::from_secs(5), "VERSION", |v| {
        v["class"] == "VERSION"
    })
    .await;
    assert_eq!(version["proto_major"], 1);
    // The greeting carries each device's last state, so `connected` is seen even if it came first.
    wait_for(&mut lines, Duration::from_secs(10), "hf connected", |v| {
        v["class"] == "DEVICE" && v["name"] == "hf" && v["state"] == "connected"
    })
    .await;
    let pose = wait_for(&mut lines, Duration::from_secs(10), "a POSE", |v| {
        v["class"] == "POSE"
    })
    .await;
    assert_eq!(pose["cov"].as_array().unwrap().len(), 36);
    assert_eq!(pose["source"], "odometry");

    // Kill the reader's link: the daemon notices, reconnects, and the reader scans again.
    kill_tx.send(1).unwrap();
    wait_for(
        &mut lines,
        Duration::from_secs(10),
        "hf reconnecting",
        |v| v["class"] == "DEVICE" && v["name"] == "hf" && v["state"] == "reconnecting",
    )
    .await;
    wait_for(
        &mut lines,
        Duration::from_secs(10),
        "hf connected again",
        |v| v["class"] == "DEVICE" && v["name"] == "hf" && v["state"] == "connected",
    )
    .await;
    assert!(connections.load(std::sync::atomic::Ordering::SeqCst) >= 2);
    wait_for(
        &mut lines,
        Duration::from_secs(5),
        "poses after the reconnect",
        |v| v["class"] == "POSE",
    )
    .await;

    // SIGTERM: clean exit, robot stopped and closed.
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "exit {status:?}\n{log}");
    assert!(log.contains("SIGTERM"), "{log}");
    let state = robot_state.state();
    assert!(!state.open, "robot connection not closed: {state:?}\n{log}");
    assert!(
        state.v.abs() < 1e-9 && state.w.abs() < 1e-9,
        "robot still moving: {state:?}"
    );
    drop(slave);
}
