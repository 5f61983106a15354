//! Fault injection against the daemon binary, on the simulated HF robot of `config/sim.toml`:
//! a full disk under the recording, hundreds of pose clients, and a client that never reads.
//! The other fault cases live next to the code they exercise; `docs/faults.md` lists them all
//! with their tests.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use tokio::io::AsyncBufReadExt;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `config/sim.toml` on pose port `port`, running `duration_s` simulated seconds, plus `extra`
/// lines in `[pose]`.
fn sim_robot(dir: &Path, port: u16, duration_s: f64, extra: &str) -> PathBuf {
    let text = std::fs::read_to_string(workspace().join("config/sim.toml"))
        .unwrap()
        .replace("127.0.0.1:2958", &format!("127.0.0.1:{port}"))
        .replace("listen = \"127.0.0.1:8765\"", "listen = \"127.0.0.1:0\"")
        .replace("duration_s = 40.0", &format!("duration_s = {duration_s}"))
        .replace("[pose]\n", &format!("[pose]\n{extra}"));
    let path = dir.join("robot.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_full_disk_under_the_recording_is_counted_and_the_robot_runs_on() {
    if !Path::new("/dev/full").exists() {
        eprintln!("skipped: no /dev/full on this machine");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let robot = sim_robot(dir.path(), common::free_port(), 20.0, "");
    let cap = dir.path().join("cap");
    std::fs::create_dir(&cap).unwrap();
    // Every file of the recording writes into a device that is always full.
    for f in ["base.cap", "hf.cap", "pipeline.order"] {
        std::os::unix::fs::symlink("/dev/full", cap.join(f)).unwrap();
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .args(["record", "-c"])
        .arg(&robot)
        .arg("-o")
        .arg(&cap)
        .env("RFLOC_LOG", "warn")
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    let poses = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|l| l.contains("\"class\":\"POSE\""))
        .count();
    assert!(poses >= 10, "{poses} poses while the disk was full\n{log}");
    assert!(
        log.contains("capture write failed") || log.contains("order log write failed"),
        "{log}"
    );
    // Each failing file is reported once, not once per record.
    let reports = log.matches("capture write failed").count();
    assert!(reports <= 2, "{reports} reports:\n{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_hundred_pose_clients_are_served_and_one_that_never_reads_stalls_nobody() {
    let dir = tempfile::tempdir().unwrap();
    let port = common::free_port();
    let robot = sim_robot(dir.path(), port, 60.0, "max_clients = 256\n");
    let daemon = common::Daemon::start(&robot, "warn");
    let first = daemon.pose_lines(port).await;
    // A client that never reads a byte.
    let _stuck = tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .unwrap();
    let mut clients = Vec::new();
    for _ in 0..200 {
        let s = tokio::net::TcpStream::connect(("127.0.0.1", port))
            .await
            .unwrap();
        clients.push(tokio::io::BufReader::new(s).lines());
    }
    // Every one of the 200 gets its greeting and, within the next poses, a POSE line.
    let mut served = 0;
    for lines in &mut clients {
        let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
        loop {
            match tokio::time::timeout_at(deadline, lines.next_line()).await {
                Ok(Ok(Some(l))) if l.contains("\"class\":\"POSE\"") => {
                    served += 1;
                    break;
                }
                Ok(Ok(Some(_))) => {}
                _ => break,
            }
        }
    }
    drop(first);
    let (status, log) = daemon.terminate().await;
    assert!(status.success(), "{log}");
    assert_eq!(served, 200, "{served} of 200 clients got a pose\n{log}");
}
