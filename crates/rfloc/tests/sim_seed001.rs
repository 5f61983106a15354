//! `rfloc sim` on seed 001 scenario A end to end: the emulated Pioneer over a pty driven by the
//! emitter-homing pipeline until the robot is within 50 cm of the emitter. The emulator runs in
//! lock-step with the trial (simulated time only).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::path::PathBuf;
use std::process::Command;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn scenario_a_reaches_the_emitter_and_records_the_pioneer_link() {
    let out = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .current_dir(workspace())
        .args(["sim", "scenarios/seed001-a.toml", "--trials", "1", "-o"])
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stdout}\n{stderr}");

    // The report compares with Table 1 and carries the filter numbers.
    let report = std::fs::read_to_string(out.path().join("report.md")).unwrap();
    assert!(report.contains("| time_to_goal |"), "{report}");
    assert!(report.contains("| successes | 1.0000 |"), "{report}");
    for key in [
        "emitter_error_m",
        "emitter_raw_error_m",
        "filter_error_ratio",
    ] {
        assert!(report.contains(key), "{key} missing:\n{report}");
    }

    // Ground truth: the robot started at (0, 0) and ended within 0.5 m of the emitter (4, 0).
    let trial = out.path().join("trial-00");
    let rows = common::pose_rows(&trial.join("truth.csv"));
    let first = rows.first().unwrap();
    assert!(first[1].abs() < 1e-6 && first[2].abs() < 1e-6, "{first:?}");
    let last = rows.last().unwrap();
    let d = (last[1] - 4.0).hypot(last[2]);
    assert!(d <= 0.5, "ended {d:.2} m from the emitter: {last:?}");
    // Simulated time, 10 Hz, and the robot needed some of it to drive 3.5 m.
    assert!(last[0] > 5.0 && last[0] < 600.0, "{last:?}");

    // The Pioneer link was recorded: header, commands out, SIPs in.
    let cap = std::fs::read_to_string(trial.join("pioneer.cap")).unwrap();
    assert!(cap.starts_with("# rfloc-capture 1"), "{}", &cap[..80]);
    assert!(cap.contains("# device: pioneer-aria"));
    let tx = cap.lines().filter(|l| l.contains(" tx ")).count();
    let rx = cap.lines().filter(|l| l.contains(" rx ")).count();
    assert!(tx > 20 && rx > 50, "tx {tx} rx {rx}");
    assert!(trial.join("pioneer-preliminary.cap").exists());

    // Lock-step: the emulator's clock moves in whole SIP periods, so every record is stamped
    // with a multiple of 0.1 s, and no SIP is missing between the first and the last.
    const TICK_NS: u64 = 100_000_000;
    let capture = rfloc_capture::Capture::from_path(&trial.join("pioneer.cap")).unwrap();
    for r in &capture.records {
        let off = r.t_ns % TICK_NS;
        assert!(off.min(TICK_NS - off) < 1_000, "record at {} s", r.t());
    }
    let sips: Vec<u64> = capture
        .records
        .iter()
        .filter(|r| matches!(r.kind, rfloc_capture::RecordKind::Rx(_)) && r.t_ns > 0)
        .map(|r| r.t_ns)
        .collect();
    assert!(sips.len() > 50, "{} SIP records", sips.len());
    for pair in sips.windows(2) {
        assert!(
            pair[1].abs_diff(pair[0]).abs_diff(TICK_NS) < 1_000,
            "SIPs at {} ns and {} ns",
            pair[0],
            pair[1]
        );
    }
}

/// The reported facility-scale failure: an emitter 9.5 m away in plain sight lay outside the
/// fixed 12 m map, the navigator parked at the map's edge and declared arrival. The map grows
/// now, and the trial reaches the emitter.
#[test]
fn an_emitter_9_5_m_away_is_reached() {
    let out = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .current_dir(workspace())
        .args([
            "sim",
            "scenarios/facility-emitter-sight95.toml",
            "--trials",
            "1",
            "-o",
        ])
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stdout}\n{stderr}");
    let report = std::fs::read_to_string(out.path().join("report.md")).unwrap();
    assert!(report.contains("| successes | 1.0000 |"), "{report}");
    let truth = std::fs::read_to_string(out.path().join("trial-00/truth.csv")).unwrap();
    let last: Vec<f64> = truth
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let d = (last[1] - 9.5).hypot(last[2]);
    assert!(d <= 0.5, "ended {d:.2} m from the emitter: {last:?}");
}
