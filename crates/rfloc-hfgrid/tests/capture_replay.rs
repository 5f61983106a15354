//! Replays the reference captures of seed 002's initialisation turn
//! (`tests/captures/kts-seed002-turn-h{0,90,180,-90}/kts.cap` in the workspace) through a minimal line
//! extraction (the KTS driver lives elsewhere) and compares the estimate with `truth.csv`.
//!
//! Extraction: rx bytes are concatenated; a line ends at `\n`; `\r` and the literal `<\r>` the
//! seed's logs contain are stripped; only `SCAN:+UID=<16 hex>,+RSSI=<a>/<b>` lines count
//! (`SCAN:-UID` lines are incomplete reads and are dropped, as in the seed). A line belongs to
//! the stop that was active when its first byte arrived; stops come from
//! `ev mark stop k heading_deg=…`.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers may panic

use std::path::{Path, PathBuf};

use rfloc_capture::{Capture, RecordKind};
use rfloc_hfgrid::{
    InitialPoseConfig, InitialPoseSolver, RssiModel, TagGrid, TagReading, TurnStop,
};
use rfloc_pose::{angle_diff, Pose2};

fn captures_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures")
}

fn parse_scan_line(line: &str) -> Option<TagReading> {
    let rest = line.strip_prefix("SCAN:+UID=")?;
    let (uid_hex, rssi) = rest.split_once(",+RSSI=")?;
    if uid_hex.len() != 16 {
        return None;
    }
    let uid = u64::from_str_radix(uid_hex, 16).ok()?;
    let (a, b) = rssi.split_once('/')?;
    Some(TagReading {
        uid,
        rssi_first: a.trim().parse().ok()?,
        rssi_second: b.trim().parse().ok()?,
    })
}

struct Extracted {
    stops: Vec<TurnStop>,
    dropped_lines: usize,
    malformed: Vec<String>,
}

fn extract(path: &Path) -> Extracted {
    let cap = Capture::from_path(path).unwrap();
    let mut stops: Vec<TurnStop> = Vec::new();
    let mut line = Vec::new();
    let mut line_stop: Option<usize> = None;
    let mut dropped = 0;
    let mut malformed = Vec::new();
    for rec in &cap.records {
        match &rec.kind {
            RecordKind::Event(e) => {
                if let Some(rest) = e.strip_prefix("mark stop ") {
                    let deg: f64 = rest
                        .split_once("heading_deg=")
                        .and_then(|(_, d)| d.trim().parse().ok())
                        .unwrap();
                    // The 360° stop repeats the 0° one; keep it (it is a ninth reading at +2π).
                    stops.push(TurnStop {
                        heading_rad: deg.to_radians(),
                        readings: Vec::new(),
                    });
                }
            }
            RecordKind::Rx(bytes) => {
                for &b in bytes {
                    if line.is_empty() {
                        line_stop = stops.len().checked_sub(1);
                    }
                    if b == b'\n' {
                        let text = String::from_utf8_lossy(&line)
                            .replace("<\\r>", "")
                            .replace('\r', "");
                        match (parse_scan_line(&text), line_stop) {
                            (Some(r), Some(k)) => stops[k].readings.push(r),
                            _ => {
                                if text.starts_with("SCAN:-UID=") {
                                    dropped += 1;
                                } else if !text.is_empty() && text != "OK" {
                                    malformed.push(text);
                                }
                            }
                        }
                        line.clear();
                    } else {
                        line.push(b);
                    }
                }
            }
            RecordKind::Tx(_) => {}
        }
    }
    Extracted {
        stops,
        dropped_lines: dropped,
        malformed,
    }
}

fn truth_at_start(path: &Path) -> Pose2 {
    let text = std::fs::read_to_string(path).unwrap();
    let row = text.lines().nth(1).unwrap();
    let v: Vec<f64> = row.split(',').map(|f| f.trim().parse().unwrap()).collect();
    Pose2::new(v[1], v[2], v[3])
}

#[test]
fn reference_captures_give_the_true_start_pose() {
    let dir = captures_dir();
    if !dir.exists() {
        // The references are outside the repository; without them there is nothing to replay.
        println!("skipped: {} not present", dir.display());
        return;
    }
    let solver = InitialPoseSolver::new(
        TagGrid::seed002_test_field(),
        RssiModel::seed002_blind_spot(),
        InitialPoseConfig::default(),
    );
    let (mut sp, mut sh, mut mp, mut mh) = (0.0, 0.0, 0.0f64, 0.0f64);
    let names = ["h0", "h90", "h180", "h-90"];
    for name in names {
        let folder = dir.join(format!("kts-seed002-turn-{name}"));
        let ex = extract(&folder.join("kts.cap"));
        let truth = truth_at_start(&folder.join("truth.csv"));
        assert_eq!(ex.stops.len(), 9, "{name}: stops");
        assert!(
            ex.malformed.is_empty(),
            "{name}: unparsed lines {:?}",
            ex.malformed
        );
        let reads: usize = ex.stops.iter().map(|s| s.readings.len()).sum();
        let est = solver.solve(&ex.stops).unwrap();
        let dp = est.pose.distance(&truth);
        let dh = angle_diff(est.pose.theta, truth.theta).abs();
        println!(
            "{name}: {reads} reads, {} incomplete SCAN:-UID lines dropped; estimate ({:.1}, {:.1}) mm {:.1}°, truth ({:.0}, {:.0}) mm {:.0}°: \
             error {:.1} mm / {:.2}°; σ ({:.1} mm, {:.1} mm, {:.2}°)",
            ex.dropped_lines,
            est.pose.x * 1e3,
            est.pose.y * 1e3,
            est.pose.theta.to_degrees(),
            truth.x * 1e3,
            truth.y * 1e3,
            truth.theta.to_degrees(),
            dp * 1e3,
            dh.to_degrees(),
            est.covariance[(0, 0)].sqrt() * 1e3,
            est.covariance[(1, 1)].sqrt() * 1e3,
            est.covariance[(2, 2)].sqrt().to_degrees()
        );
        sp += dp;
        sh += dh;
        mp = mp.max(dp);
        mh = mh.max(dh);
    }
    let n = names.len() as f64;
    println!(
        "captures: mean {:.1} mm / {:.2}°, max {:.1} mm / {:.2}° (seed 002 real hardware: 37.5 mm / 23°)",
        sp / n * 1e3,
        (sh / n).to_degrees(),
        mp * 1e3,
        mh.to_degrees()
    );
    assert!(sp / n <= 0.010 && (sh / n).to_degrees() <= 5.0);
}
