//! Supervision: a device task that panics is reported `failed` and restarted with back-off; a
//! device that never delivers is reported `stale` from the start; and once a device has been
//! down longer than `[supervision] max_down_s`, the systemd watchdog is no longer fed.
//!
//! One test (the watchdog is configured through the process environment), in process: a robot
//! file whose HF reader is replaced by a test driver, `NOTIFY_SOCKET` bound to a datagram socket.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::time::{Duration, Instant};

use rfloc_daemon::config::{Checks, RobotConfig};
use rfloc_daemon::devices::{CheckEnv, DeviceContext, DeviceDriver, Driver};
use rfloc_daemon::simulation::BoxFuture;
use tokio::io::AsyncBufReadExt;

/// A device whose task panics at once.
struct Crashing;

impl Driver for Crashing {
    const KIND: &'static str = "crashing";
    const CAPTURES: &'static [&'static str] = &["crashing"];
    type Settings = ();

    fn check(_s: &(), _c: &mut Checks<'_, '_>, _env: &CheckEnv<'_>) {}

    fn for_capture(_capture: &str) -> Option<()> {
        None
    }

    fn run(_s: (), _ctx: DeviceContext) -> BoxFuture<'static, ()> {
        Box::pin(async {
            panic!("wheel encoder table is empty");
        })
    }
}

/// A device whose task runs but never delivers anything.
struct Mute;

impl Driver for Mute {
    const KIND: &'static str = "mute";
    const CAPTURES: &'static [&'static str] = &["mute"];
    type Settings = ();

    fn check(_s: &(), _c: &mut Checks<'_, '_>, _env: &CheckEnv<'_>) {}

    fn for_capture(_capture: &str) -> Option<()> {
        None
    }

    fn run(_s: (), ctx: DeviceContext) -> BoxFuture<'static, ()> {
        Box::pin(async move { ctx.stop.cancelled().await })
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crashing_device_is_restarted_a_mute_one_goes_stale_and_the_watchdog_stops() {
    let dir = tempfile::tempdir().unwrap();
    let sock_path = dir.path().join("notify.sock");
    let notify = std::os::unix::net::UnixDatagram::bind(&sock_path).unwrap();
    notify.set_nonblocking(true).unwrap();
    std::env::set_var("NOTIFY_SOCKET", &sock_path);
    std::env::set_var("WATCHDOG_USEC", "1000000");
    std::env::remove_var("WATCHDOG_PID");

    let port = free_port();
    let dead = free_port(); // nothing listens: the base keeps reconnecting, alive
    let text = format!(
        r#"[robot]
name = "t"

[[device]]
name = "base"
link = {{ kind = "tcp", address = "127.0.0.1:{dead}" }}
stale_after_s = 30.0
[device.driver]
kind = "aria"

[[device]]
name = "crashy"
link = {{ kind = "tcp", address = "127.0.0.1:{dead}" }}
[device.driver]
kind = "kts"

[[device]]
name = "mute"
link = {{ kind = "tcp", address = "127.0.0.1:{dead}" }}
stale_after_s = 1.0
[device.driver]
kind = "kts"

[estimator]
pipeline = "odometry"

[pose]
tcp = "127.0.0.1:{port}"

[supervision]
backoff_initial_s = 0.2
backoff_max_s = 1.0
max_down_s = 2.0
"#
    );
    let mut cfg = RobotConfig::parse(&text, "t.toml", None).unwrap();
    cfg.devices[1].driver = DeviceDriver::new::<Crashing>(());
    cfg.devices[2].driver = DeviceDriver::new::<Mute>(());

    let start = Instant::now();
    let daemon = tokio::spawn(rfloc_daemon::daemon::run(
        cfg,
        rfloc_daemon::daemon::RunOptions::default(),
        None,
    ));
    tokio::time::sleep(Duration::from_millis(300)).await;
    let stream = tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .unwrap();
    let mut lines = tokio::io::BufReader::new(stream).lines();
    let mut pings: Vec<f64> = Vec::new();
    let mut crashy: Vec<(String, String)> = Vec::new();
    let mut mute: Vec<(String, f64)> = Vec::new();
    // When the daemon's first DEVICE line arrived: its router runs from about then (a loaded
    // machine starts it later than the test's clock).
    let mut up: Option<f64> = None;
    while start.elapsed() < Duration::from_secs(10) {
        let mut buf = [0u8; 256];
        while let Ok(n) = notify.recv(&mut buf) {
            if buf
                .get(..n)
                .is_some_and(|m| m.windows(10).any(|w| w == b"WATCHDOG=1"))
            {
                pings.push(start.elapsed().as_secs_f64());
            }
        }
        if let Ok(Ok(Some(l))) =
            tokio::time::timeout(Duration::from_millis(100), lines.next_line()).await
        {
            let v: serde_json::Value = serde_json::from_str(&l).unwrap();
            if v["class"] == "DEVICE" {
                up.get_or_insert(start.elapsed().as_secs_f64());
                let state = v["state"].as_str().unwrap().to_string();
                let detail = v["detail"].as_str().unwrap().to_string();
                match v["name"].as_str() {
                    Some("crashy") => crashy.push((state, detail)),
                    Some("mute") => mute.push((state, start.elapsed().as_secs_f64())),
                    _ => {}
                }
            }
        }
    }
    daemon.abort();

    // Reported and restarted, again and again, with the panic's message.
    let failed: Vec<&(String, String)> = crashy.iter().filter(|(s, _)| s == "failed").collect();
    assert!(failed.len() >= 3, "{crashy:?}");
    assert!(
        failed[0]
            .1
            .contains("panicked: wheel encoder table is empty")
            && failed[0].1.contains("restarting in"),
        "{crashy:?}"
    );
    // Never a word from the mute device: stale after its 1 s, counted from the start.
    let stale_at = mute
        .iter()
        .find(|(s, _)| s == "stale")
        .map(|(_, t)| *t)
        .unwrap_or_else(|| panic!("mute device never reported stale: {mute:?}"));
    let up = up.unwrap();
    assert!(
        stale_at - up < 2.5,
        "stale only {:.1} s after the daemon came up",
        stale_at - up
    );
    // Fed at first; no longer once a device has been down 2 s (crashy from its first crash,
    // mute from 1 s of silence).
    assert!(
        pings.iter().any(|t| *t < up + 1.5),
        "never fed: {pings:?} (up at {up:.1} s)"
    );
    assert!(
        !pings.iter().any(|t| *t > up + 5.0),
        "still fed with devices down: {pings:?} (up at {up:.1} s)"
    );
}
