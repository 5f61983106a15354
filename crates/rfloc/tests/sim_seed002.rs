//! `rfloc sim` on seed 002's 3×3 test: one trial end to end through the Pioneer and KTS
//! drivers on ptys, the daemon's HF-grid pipeline, captures and a report.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;
use std::process::Command;

#[test]
fn seed002_trial_initialises_within_the_targets() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_rfloc"))
        .current_dir(&root)
        .args(["sim", "scenarios/seed002-3x3.toml", "--trials", "1", "-o"])
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let trial = out.path().join("trial-00");
    for f in ["pioneer.cap", "kts.cap", "truth.csv", "estimate.csv"] {
        assert!(trial.join(f).exists(), "{f} missing");
    }
    // Both captures parse and hold traffic in both directions.
    for f in ["pioneer.cap", "kts.cap"] {
        let cap = rfloc_capture::Capture::from_path(&trial.join(f)).unwrap();
        assert!(
            !cap.rx_bytes().is_empty() && !cap.tx_bytes().is_empty(),
            "{f}"
        );
    }
    assert!(out.path().join("report.md").exists());
    // Targets: ≤ 10 mm and ≤ 5° (the seed: 37.5 mm and 23° on its real test).
    let value = |name: &str| -> f64 {
        let row = stdout
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("no {name}: {stdout}"));
        row.split('|').nth(2).unwrap().trim().parse().unwrap()
    };
    assert_eq!(value("successes"), 1.0);
    assert!(value("init_error_m") <= 0.010, "{stdout}");
    assert!(value("init_theta_error_deg") <= 5.0, "{stdout}");
}
