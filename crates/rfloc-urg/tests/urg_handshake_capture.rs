//! A URG session with the handshake: `tests/captures/urg-handshake-emulated/laser.cap`
//! (workspace root), recorded from [`UrgClient::connect`] (`SCIP2.0`, `VV`, `PP`), `BM`, five
//! `GD` scans and `QT` against the emulator over a pty, through `rfloc_transport`'s recorder.
//!
//! `record_handshake_capture` (ignored; run it to regenerate) writes the capture;
//! `handshake_session_replays_to_golden` drives the client through it in request/response mode
//! and compares what it read with `laser.session.golden` (`RFLOC_BLESS=1` rewrites it).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;

use rfloc_capture::{Capture, Header};
use rfloc_transport::replay::{ReplayMode, Replayer};
use rfloc_transport::{CaptureSink, MonotonicClock, Recorder, SharedClock};
use rfloc_urg::{EmulatorConfig, UrgClient, UrgConfig, UrgEmulator, UrgGeometry};
use tokio::io::{AsyncRead, AsyncWrite};

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures/urg-handshake-emulated")
}

/// A corridor: walls 1.5 m to either side, an end wall 4 m ahead.
fn corridor(angle: f64) -> Option<f64> {
    let (s, c) = angle.sin_cos();
    let side = if s.abs() > 1e-9 {
        1.5 / s.abs()
    } else {
        f64::INFINITY
    };
    let end = if c > 1e-9 { 4.0 / c } else { f64::INFINITY };
    let r = side.min(end);
    r.is_finite().then_some(r)
}

/// The session both the recording and the replay run; returns the client's view of it.
async fn session<T: AsyncRead + AsyncWrite + Unpin>(io: T) -> String {
    let mut out = String::from(
        "# UrgClient replay of laser.cap (handshake, 5 GD scans); RFLOC_BLESS=1 rewrites\n",
    );
    let (mut client, info) = UrgClient::connect(io, UrgConfig::default()).await.unwrap();
    for (k, v) in info.version.iter().chain(&info.parameters) {
        writeln!(out, "{k} = {v}").unwrap();
    }
    let g = client.geometry();
    assert_eq!(info.geometry, Some(g));
    assert_eq!(g, UrgGeometry::default(), "the emulated URG-04LX");
    writeln!(out, "geometry {g:?}").unwrap();
    client.laser_on().await.unwrap();
    for _ in 0..5 {
        let scan = client.scan().await.unwrap();
        let echoes = scan.beams(&g).filter(|b| b.1.is_some()).count();
        let front = scan.ranges_mm[usize::from(g.front_step - g.first_step)];
        let nearest = scan
            .ranges_mm
            .iter()
            .filter(|mm| (g.min_mm..=g.max_mm).contains(mm))
            .min()
            .copied()
            .unwrap_or(0);
        writeln!(
            out,
            "scan values={} echoes={echoes} nearest={nearest} front={front}",
            scan.ranges_mm.len()
        )
        .unwrap();
    }
    client.laser_off().await.unwrap();
    let s = client.stats();
    writeln!(
        out,
        "stats replies={} bad_replies={} dropped_bytes={}",
        s.replies, s.bad_replies, s.dropped_bytes
    )
    .unwrap();
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "writes tests/captures/urg-handshake-emulated; run to regenerate the capture"]
async fn record_handshake_capture() {
    std::fs::create_dir_all(dir()).unwrap();
    let clock: SharedClock = Arc::new(MonotonicClock::new());
    let mut header = Header::new("hokuyo-urg", "serial 115200 8N1");
    header.notes.push(
        "rfloc-urg UrgClient::connect (SCIP2.0, VV, PP), BM, 5 GD, QT <-> UrgEmulator \
         (URG-04LX, corridor 1.5 m to each side, end wall 4 m ahead) over a pty pair"
            .into(),
    );
    let sink = CaptureSink::create(&dir().join("laser.cap"), &header, clock).unwrap();
    let (master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let emulator = UrgEmulator::new(Arc::new(corridor), EmulatorConfig::default());
    let server = tokio::spawn(async move { emulator.serve(master).await });
    let out = session(Recorder::new(slave, sink.clone())).await;
    sink.flush().unwrap();
    server.abort();
    println!("{out}");
}

#[tokio::test]
async fn handshake_session_replays_to_golden() {
    let cap = Capture::from_path(&dir().join("laser.cap")).unwrap();
    assert_eq!(cap.header.device.as_deref(), Some("hokuyo-urg"));
    let (io, mut handle) = Replayer::new(cap).mode(ReplayMode::RequestResponse).start();
    let mut out = session(io).await;
    let report = handle.finished().await;
    assert!(report.mismatches.is_empty(), "{:?}", report.mismatches);
    writeln!(
        out,
        "replay requests={} mismatches={}",
        report.requests,
        report.mismatches.len()
    )
    .unwrap();
    let golden = dir().join("laser.session.golden");
    if std::env::var_os("RFLOC_BLESS").is_some() {
        std::fs::write(&golden, &out).unwrap();
    }
    assert_eq!(out, std::fs::read_to_string(&golden).unwrap());
    assert!(
        out.contains("PROT = SCIP 2.0\n") && out.contains("AMAX = 725\n"),
        "{out}"
    );
}
