//! The estimator runs off the async runtime: a pipeline far slower than its input leaves the pose
//! stream, DEVICE lines and the stale detector as they are, and a pipeline that hangs stops the
//! systemd watchdog pings while the rest of the daemon runs on and still stops.
//!
//! One test (the watchdog is configured through the process environment): the simulated HF
//! robot of `config/sim.toml`, run in this process with a test pipeline, `NOTIFY_SOCKET` bound
//! to a datagram socket the test reads.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rfloc_daemon::config::{LoadOptions, RobotConfig, SectionCheck};
use rfloc_daemon::events::DeviceEvent;
use rfloc_daemon::pipeline::Pipeline;
use rfloc_pose::{EstimateMode, PoseEstimate};
use tokio::io::AsyncBufReadExt;

/// A pipeline that takes `delay` per observation and, after `hang_after` of them, blocks until
/// `release` is set.
struct TestPipeline {
    delay: Duration,
    hang_after: Option<u64>,
    release: Arc<AtomicBool>,
    seen: Arc<AtomicU64>,
}

impl Pipeline for TestPipeline {
    fn name(&self) -> &'static str {
        "test"
    }

    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        let n = self.seen.fetch_add(1, Ordering::AcqRel) + 1;
        if self.hang_after.is_some_and(|h| n > h) {
            while !self.release.load(Ordering::Acquire) {
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        std::thread::sleep(self.delay);
        match event {
            DeviceEvent::Odometry { t, pose, .. } => Some(PoseEstimate {
                time: *t,
                pose: *pose,
                covariance: nalgebra::Matrix3::identity() * 0.01,
                mode: EstimateMode::Fix,
                source: "test".into(),
            }),
            _ => None,
        }
    }
}

fn robot(port: u16) -> RobotConfig {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = std::fs::read_to_string(root.join("config/sim.toml"))
        .unwrap()
        .replace("127.0.0.1:2958", &format!("127.0.0.1:{port}"))
        .replace("listen = \"127.0.0.1:8765\"", "listen = \"127.0.0.1:0\"")
        .replace("stdout = true", "stdout = false")
        .replace("duration_s = 40.0", "duration_s = 30.0");
    let ext: &[&dyn SectionCheck] = &[&rfloc_lab::sim::SimulationSection];
    RobotConfig::load_text(
        &text,
        "sim.toml",
        Some(&root.join("config")),
        &LoadOptions {
            check_files: true,
            extensions: ext,
            for_replay: false,
        },
    )
    .unwrap()
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// What a client and the notify socket saw over one run.
#[derive(Debug, Default)]
struct Seen {
    /// Wall seconds from the run's start to each WATCHDOG=1.
    pings: Vec<f64>,
    /// DEVICE lines (state, wall seconds).
    devices: Vec<(String, f64)>,
    /// Seconds a late client waited for its greeting (VERSION and the DEVICE lines).
    greeting_s: f64,
    poses: usize,
}

async fn run_once(pipeline: TestPipeline, notify: &std::os::unix::net::UnixDatagram) -> Seen {
    let port = free_port();
    let mut cfg = robot(port);
    let sim = rfloc_lab::sim::start(&mut cfg).await.unwrap();
    let start = Instant::now();
    let daemon = tokio::spawn(rfloc_daemon::daemon::run_with_pipeline(
        cfg,
        rfloc_daemon::daemon::RunOptions::default(),
        Some(Box::new(sim)),
        Some(Box::new(pipeline)),
    ));
    // A client that joins 2 s into the run, while the estimator is far behind.
    tokio::time::sleep(Duration::from_secs(2)).await;
    // The daemon binds its port while it starts; on a loaded machine that can take longer
    // than the 2 s above, so the client retries for up to 10 s more.
    let mut attempt = 0;
    let stream = loop {
        match tokio::net::TcpStream::connect(("127.0.0.1", port)).await {
            Ok(s) => break s,
            Err(_) if attempt < 200 => {
                attempt += 1;
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            Err(e) => panic!("the daemon did not listen on {port} within 12 s: {e}"),
        }
    };
    let joined = Instant::now();
    let mut lines = tokio::io::BufReader::new(stream).lines();
    let mut seen = Seen::default();
    let mut greeted = false;
    loop {
        let line = tokio::time::timeout(Duration::from_millis(200), lines.next_line()).await;
        let mut buf = [0u8; 256];
        while let Ok(n) = notify.recv(&mut buf) {
            if buf
                .get(..n)
                .is_some_and(|m| m.windows(10).any(|w| w == b"WATCHDOG=1"))
            {
                seen.pings.push(start.elapsed().as_secs_f64());
            }
        }
        match line {
            Ok(Ok(Some(l))) => {
                let v: serde_json::Value = serde_json::from_str(&l).unwrap();
                match v["class"].as_str() {
                    Some("DEVICE") => {
                        seen.devices.push((
                            v["state"].as_str().unwrap().to_string(),
                            start.elapsed().as_secs_f64(),
                        ));
                        if !greeted && seen.devices.len() >= 2 {
                            greeted = true;
                            seen.greeting_s = joined.elapsed().as_secs_f64();
                        }
                    }
                    Some("POSE") => seen.poses += 1,
                    _ => {}
                }
            }
            Ok(Ok(None)) | Ok(Err(_)) => break,
            Err(_) => {
                if daemon.is_finished() {
                    break;
                }
            }
        }
    }
    daemon.await.unwrap().unwrap();
    seen
}

/// Only WATCHDOG=1 datagrams count as pings.
fn notify_socket(dir: &std::path::Path) -> std::os::unix::net::UnixDatagram {
    let path = dir.join("notify.sock");
    let sock = std::os::unix::net::UnixDatagram::bind(&path).unwrap();
    sock.set_nonblocking(true).unwrap();
    std::env::set_var("NOTIFY_SOCKET", &path);
    std::env::set_var("WATCHDOG_USEC", "1000000");
    std::env::remove_var("WATCHDOG_PID");
    sock
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_or_hung_estimator_leaves_the_daemon_running_and_a_hung_one_stops_the_watchdog() {
    let dir = tempfile::tempdir().unwrap();
    let notify = notify_socket(dir.path());

    // Slow: 40 ms per observation, far behind the base's SIPs and the reader's tags.
    let seen = Arc::new(AtomicU64::new(0));
    let slow = run_once(
        TestPipeline {
            delay: Duration::from_millis(40),
            hang_after: None,
            release: Arc::new(AtomicBool::new(true)),
            seen: Arc::clone(&seen),
        },
        &notify,
    )
    .await;
    assert!(
        slow.greeting_s < 1.0,
        "greeting took {:.2} s",
        slow.greeting_s
    );
    assert!(
        slow.devices.iter().all(|(s, _)| s != "stale"),
        "a device was reported stale while it kept sending: {:?}",
        slow.devices
    );
    assert!(slow.poses > 0, "no pose published");
    // Fed every 0.5 s while the estimator consumes: no gap of a whole watchdog interval.
    let gaps: Vec<f64> = slow.pings.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(slow.pings.len() >= 6, "pings {:?}", slow.pings);
    assert!(gaps.iter().all(|g| *g < 1.0), "watchdog gaps {gaps:?}");

    // Hung after 30 observations: the pings stop; the pose stream and DEVICE lines do not.
    // The estimator stays hung through the daemon's shutdown: the run must still return
    // (the thread is left behind), and the test releases it afterwards.
    let release = Arc::new(AtomicBool::new(false));
    let hung_seen = Arc::new(AtomicU64::new(0));
    let hung = run_once(
        TestPipeline {
            delay: Duration::ZERO,
            hang_after: Some(30),
            release: Arc::clone(&release),
            seen: Arc::clone(&hung_seen),
        },
        &notify,
    )
    .await;
    release.store(true, Ordering::Release);
    assert!(
        hung.greeting_s < 1.0,
        "greeting took {:.2} s",
        hung.greeting_s
    );
    assert!(
        hung.devices.iter().all(|(s, _)| s != "stale"),
        "{:?}",
        hung.devices
    );
    // The run lasts 6 s of wall time; the pipeline hangs within its first second or two.
    let late: Vec<&f64> = hung
        .pings
        .iter()
        .filter(|t| **t > 4.0 && **t < 6.0)
        .collect();
    assert!(
        late.is_empty(),
        "watchdog still fed while the estimator hung: {:?}",
        hung.pings
    );
}
