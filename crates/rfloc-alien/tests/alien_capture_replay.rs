//! Replay of the reference capture `tests/captures/alien-seed000-interactive/alien.cap`
//! (workspace root): seed 000's interactive session (no `\x01`, `\n` line ends, echoed
//! commands, `IDK %i RSSI %m TIME %t;`, an `Error 1`, a `(No Tags)` poll, a closing
//! `Connection Timeout.`), driven through [`AlienClient`] by `rfloc_transport`'s `Replayer` in
//! request/response mode. The client's output is compared with `alien.snapshots.golden`
//! beside the capture (`RFLOC_BLESS=1` rewrites it).
#![allow(clippy::unwrap_used)] // helpers outside #[test] fns

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use rfloc_alien::{
    AlienClient, AlienConfig, AlienError, LineEnding, PromptMode, ReaderSetup, SetupCommand,
    SnapshotReader,
};
use rfloc_capture::Capture;
use rfloc_transport::replay::{ReplayMode, Replayer};
use rfloc_transport::SharedClock;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures/alien-seed000-interactive")
}

#[tokio::test]
async fn seed000_interactive_session_replays_to_golden() {
    let cap = Capture::from_path(&dir().join("alien.cap")).unwrap();
    let (io, mut handle) = Replayer::new(cap).mode(ReplayMode::RequestResponse).start();
    let clock: SharedClock = handle.clock();
    let config = AlienConfig {
        prompt_mode: PromptMode::Interactive,
        line_ending: LineEnding::Lf,
        reply_timeout: Duration::from_secs(2),
        time_source: Arc::new(|| "2026/11/21 10:00:01".to_string()),
        ..AlienConfig::default()
    };
    let mut out = String::from(
        "# AlienClient replay of alien.cap (interactive mode, LF line ends); RFLOC_BLESS=1 rewrites\n",
    );
    let mut client = AlienClient::connect(io, config.clone(), clock)
        .await
        .unwrap();
    out.push_str("login ok\n");
    // Seed 000 main script, command by command, with the replies the client returned.
    for c in &ReaderSetup::seed000().commands {
        let text = c.text(&(config.time_source)());
        let reply = client.command(&text).await.unwrap();
        writeln!(out, "{text:?} -> {:?}", reply.trim()).unwrap();
        if let SetupCommand::Raw(_) = c {
            // `TagListFormat=Custom` switched the parser to the seed's custom format.
            assert!(matches!(
                client.format(),
                rfloc_alien::TagListFormat::Custom(_)
            ));
        }
    }
    match client.command("bogus").await {
        Err(AlienError::Reader { code, text, .. }) => {
            assert_eq!((code, text.as_str()), (Some(1), "Command not understood."));
            writeln!(out, "\"bogus\" -> reader error {code:?} {text:?}").unwrap();
        }
        other => panic!("bogus: {other:?}"),
    }
    let mut counts = Vec::new();
    for _ in 0..6 {
        let snap = client.read_snapshot().await.unwrap();
        assert!(snap.malformed.is_empty(), "{:?}", snap.malformed);
        counts.push(snap.tags.len());
        writeln!(out, "snapshot t={:.6} tags={}", snap.t, snap.tags.len()).unwrap();
        for t in &snap.tags {
            writeln!(
                out,
                "  {} rssi={:.1} time={}",
                t.id,
                t.rssi.unwrap(),
                t.discovered.map(|d| d.to_string()).unwrap_or_default()
            )
            .unwrap();
        }
    }
    // Tag counts per poll as the capture holds them (5, 7, (No Tags), 5, 7, 5).
    assert_eq!(counts, [5, 7, 0, 5, 7, 5]);
    match client.next_unsolicited(Duration::from_secs(1)).await {
        Err(AlienError::Session(end)) => {
            assert_eq!(end, rfloc_alien::SessionEnd::ConnectionTimeout);
            writeln!(out, "unsolicited -> session ended: {end:?}").unwrap();
        }
        other => panic!("expected Connection Timeout, got {other:?}"),
    }
    let report = handle.finished().await;
    assert!(report.mismatches.is_empty(), "{:?}", report.mismatches);
    writeln!(
        out,
        "replay requests={} mismatches={}",
        report.requests,
        report.mismatches.len()
    )
    .unwrap();
    let s = client.stats();
    writeln!(
        out,
        "stats commands={} reader_errors={} malformed_tag_lines={} stray_frames={}",
        s.commands, s.reader_errors, s.malformed_tag_lines, s.stray_frames
    )
    .unwrap();

    let golden = dir().join("alien.snapshots.golden");
    if std::env::var_os("RFLOC_BLESS").is_some() {
        std::fs::write(&golden, &out).unwrap();
    }
    assert_eq!(out, std::fs::read_to_string(&golden).unwrap());
}

/// The same capture read back without a client (sans-IO [`rfloc_alien::Transcript`]): the
/// six polls give the tag counts the client got, after the setup switched the format.
#[test]
fn seed000_interactive_session_reads_back_as_a_transcript() {
    let cap = Capture::from_path(&dir().join("alien.cap")).unwrap();
    let mut t = rfloc_alien::Transcript::new();
    let mut polls = Vec::new();
    let mut errors = 0;
    for rec in &cap.records {
        match &rec.kind {
            rfloc_capture::RecordKind::Tx(b) => t.push_client(b),
            rfloc_capture::RecordKind::Rx(b) => {
                for ex in t.push_reader(rec.t(), b) {
                    errors += usize::from(ex.is_error());
                    if let Some(tags) = t.tags(&ex) {
                        polls.push(tags.len());
                    }
                }
            }
            rfloc_capture::RecordKind::Event(_) => {}
        }
    }
    assert_eq!(polls, [5, 7, 0, 5, 7, 5]);
    assert_eq!(errors, 1, "the `bogus` command's Error 1");
    assert!(matches!(
        t.format().format(),
        rfloc_alien::TagListFormat::Custom(_)
    ));
}
