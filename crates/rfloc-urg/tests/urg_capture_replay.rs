//! Golden replay of `tests/captures/urg-emulated/laser.cap`: the laser link of a 4 s
//! `rfloc record` run of `config/sim-emitter.toml` (the daemon's URG task against the
//! simulation's URG emulator, robot at the start of seed 001 scenario A). Every `GD` reply
//! decodes, and the scans' summary equals `laser.scans.golden` (`RFLOC_BLESS=1` rewrites it).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;

use rfloc_capture::{Capture, RecordKind};
use rfloc_urg::{Command, ReplyDecoder, Scan, UrgGeometry};

fn session() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures/urg-emulated")
}

#[test]
fn the_recorded_laser_link_replays_to_its_golden_scans() {
    let cap = Capture::from_path(&session().join("laser.cap")).unwrap();
    assert_eq!(cap.header.device.as_deref(), Some("hokuyo-urg"));
    let gd = Command::GetDistance {
        start: 44,
        end: 725,
        cluster: 1,
    }
    .to_bytes();
    let mut decoder = ReplyDecoder::new();
    let (mut requests, mut lines) = (
        0usize,
        vec!["# scan: time stamp ms, values, echoes, nearest mm, front mm".to_string()],
    );
    let g = UrgGeometry::default();
    for rec in &cap.records {
        match &rec.kind {
            RecordKind::Tx(bytes) if *bytes == gd => requests += 1,
            RecordKind::Rx(bytes) => {
                decoder.push(bytes);
                while let Some(reply) = decoder.next_reply() {
                    let reply = reply.unwrap();
                    if !reply.echo.starts_with(b"GD") {
                        continue;
                    }
                    let scan = Scan::from_reply(&reply).unwrap();
                    let beams: Vec<(f64, Option<f64>)> = scan.beams(&g).collect();
                    let echoes = beams.iter().filter(|b| b.1.is_some()).count();
                    let nearest = scan
                        .ranges_mm
                        .iter()
                        .filter(|mm| (g.min_mm..=g.max_mm).contains(mm))
                        .min()
                        .copied()
                        .unwrap_or(0);
                    let front = scan
                        .ranges_mm
                        .get(usize::from(g.front_step - g.first_step))
                        .copied()
                        .unwrap_or(0);
                    lines.push(format!(
                        "{} {} {} {} {}",
                        scan.timestamp_ms,
                        scan.ranges_mm.len(),
                        echoes,
                        nearest,
                        front
                    ));
                }
            }
            _ => {}
        }
    }
    let stats = decoder.stats();
    assert_eq!((stats.bad_replies, stats.dropped_bytes), (0, 0));
    assert_eq!(lines.len() - 1, requests, "one scan per GD request");
    assert!(requests >= 10, "{requests} scans");
    let got = lines.join("\n") + "\n";
    let golden = session().join("laser.scans.golden");
    if std::env::var_os("RFLOC_BLESS").is_some() {
        std::fs::write(&golden, &got).unwrap();
    }
    let want = std::fs::read_to_string(&golden).unwrap();
    assert_eq!(got, want);
}
