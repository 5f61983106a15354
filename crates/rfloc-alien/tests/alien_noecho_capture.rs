//! A session with a reader that does not echo: `tests/captures/alien-noecho-emulated/alien.cap`
//! (workspace root), recorded from [`AlienClient`] (interactive prompts, CR LF) against the
//! emulator with [`EchoMode::Never`] through `rfloc_transport`'s recorder. Seed 000's setup
//! sends `PersistTime = 0`, whose reply is the same text: the client must keep it.
//!
//! `record_noecho_capture` (ignored; run it to regenerate) writes the capture;
//! `noecho_session_replays_to_golden` drives the client through it in request/response mode
//! and compares what it returns with `alien.replies.golden` (`RFLOC_BLESS=1` rewrites it).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use rfloc_alien::{
    AlienClient, AlienConfig, AlienError, EchoMode, EchoState, EmulatorOptions, PromptMode,
    ReaderEmulator, ReaderSetup, SnapshotReader,
};
use rfloc_capture::{Capture, Header};
use rfloc_transport::replay::{ReplayMode, Replayer};
use rfloc_transport::{CaptureSink, MonotonicClock, Recorder, SharedClock};
use tokio::io::{AsyncRead, AsyncWrite};

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures/alien-noecho-emulated")
}

fn config() -> AlienConfig {
    AlienConfig {
        prompt_mode: PromptMode::Interactive,
        reply_timeout: Duration::from_secs(2),
        time_source: Arc::new(|| "2026/12/01 10:00:00".to_string()),
        ..AlienConfig::default()
    }
}

/// The session both the recording and the replay run; returns the client's view of it.
async fn session<T>(io: T, clock: SharedClock) -> String
where
    T: AsyncRead + AsyncWrite + Unpin + Send,
{
    let config = config();
    let mut out = String::from(
        "# AlienClient replay of alien.cap (interactive, reader without echo); RFLOC_BLESS=1 rewrites\n",
    );
    let mut client = AlienClient::connect(io, config.clone(), clock)
        .await
        .unwrap();
    out.push_str("login ok\n");
    for c in &ReaderSetup::seed000().commands {
        let text = c.text(&(config.time_source)());
        let reply = client.command(&text).await.unwrap();
        assert!(!reply.trim().is_empty(), "{text}: empty reply");
        writeln!(out, "{text:?} -> {:?}", reply.trim()).unwrap();
    }
    let persist = client.get("PersistTime").await.unwrap();
    writeln!(out, "get PersistTime -> {persist:?}").unwrap();
    match client.command("bogus").await {
        Err(AlienError::Reader { code, text, .. }) => {
            writeln!(out, "\"bogus\" -> reader error {code:?} {text:?}").unwrap();
        }
        other => panic!("bogus: {other:?}"),
    }
    for _ in 0..3 {
        let snap = client.read_snapshot().await.unwrap();
        assert!(snap.malformed.is_empty(), "{:?}", snap.malformed);
        writeln!(out, "snapshot tags={}", snap.tags.len()).unwrap();
        for t in &snap.tags {
            writeln!(out, "  {} rssi={:.1}", t.id, t.rssi.unwrap_or(f64::NAN)).unwrap();
        }
    }
    writeln!(out, "echo {:?}", client.echo_state()).unwrap();
    assert_eq!(client.echo_state(), EchoState::Silent);
    let s = client.stats();
    writeln!(
        out,
        "stats commands={} reader_errors={} malformed_tag_lines={} stray_frames={}",
        s.commands, s.reader_errors, s.malformed_tag_lines, s.stray_frames
    )
    .unwrap();
    client.quit().await.unwrap();
    out.push_str("quit ok\n");
    out
}

#[tokio::test]
#[ignore = "writes tests/captures/alien-noecho-emulated; run to regenerate the capture"]
async fn record_noecho_capture() {
    std::fs::create_dir_all(dir()).unwrap();
    let clock: SharedClock = Arc::new(MonotonicClock::new());
    let mut header = Header::new("alien-alr9900", "tcp 127.0.0.1:23");
    header.notes.push(
        "rfloc-alien AlienClient (interactive, CR LF) <-> ReaderEmulator with EchoMode::Never \
         over loopback TCP: seed 000 setup, get PersistTime, bogus, 3 polls, quit"
            .into(),
    );
    let sink = CaptureSink::create(&dir().join("alien.cap"), &header, Arc::clone(&clock)).unwrap();
    let field: rfloc_alien::TagField = Arc::new(|| {
        vec![
            (vec![0xE2, 0x00, 0x00, 0x01], 2500.5),
            (vec![0xE2, 0x00, 0x00, 0x02], 1200.0),
        ]
    });
    let emulator = ReaderEmulator::new(
        field,
        EmulatorOptions {
            echo: EchoMode::Never,
            ..EmulatorOptions::default()
        },
    );
    let (addr, _task) = emulator.bind_loopback().await.unwrap();
    let stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let out = session(Recorder::new(stream, sink.clone()), clock).await;
    sink.flush().unwrap();
    println!("{out}");
}

#[tokio::test]
async fn noecho_session_replays_to_golden() {
    let cap = Capture::from_path(&dir().join("alien.cap")).unwrap();
    assert_eq!(cap.header.device.as_deref(), Some("alien-alr9900"));
    let (io, mut handle) = Replayer::new(cap).mode(ReplayMode::RequestResponse).start();
    let clock = handle.clock();
    let mut out = session(io, clock).await;
    let report = handle.finished().await;
    assert!(report.mismatches.is_empty(), "{:?}", report.mismatches);
    writeln!(
        out,
        "replay requests={} mismatches={}",
        report.requests,
        report.mismatches.len()
    )
    .unwrap();
    let golden = dir().join("alien.replies.golden");
    if std::env::var_os("RFLOC_BLESS").is_some() {
        std::fs::write(&golden, &out).unwrap();
    }
    assert_eq!(out, std::fs::read_to_string(&golden).unwrap());
    // The reply that an echo-stripping client lost.
    assert!(
        out.contains("\"PersistTime = 0\" -> \"PersistTime = 0\""),
        "{out}"
    );
}
