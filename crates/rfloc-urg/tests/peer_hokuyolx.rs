//! hokuyolx 0.9.0 (`tests/peers/urg_hokuyolx.py`) against the emulator on a pty: its default
//! constructor (`%ST`, `TM0`, `TM1` ×10, `TM2`, `PP`, `BM`), `get_dist` at groupings 0, 1 and 3
//! (`GD`), `iter_dist` over `MD` for three scans, and `standby` (`QT`).
//!
//! The interpreter comes from `RFLOC_PYTHON` (a venv with `hokuyolx==0.9.0`, which needs numpy;
//! the script bridges the pty with pyserial). Without it the test prints why and passes; with
//! it, any failure fails the test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use rfloc_urg::{EmulatorConfig, UrgEmulator};
use serde_json::Value;
use tokio_serial::{SerialPort, SerialStream};

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/peers/urg_hokuyolx.py")
}

/// A wall 2 m ahead across ±60°.
fn wall_ahead(angle: f64) -> Option<f64> {
    (angle.abs() < 60f64.to_radians()).then(|| 2.0 / angle.cos())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hokuyolx_connects_scans_and_streams() {
    let Some(python) = std::env::var_os("RFLOC_PYTHON") else {
        println!("skipped: RFLOC_PYTHON not set (a venv with hokuyolx==0.9.0 runs this test)");
        return;
    };
    let (master, slave) = SerialStream::pair().unwrap();
    let path = slave.name().unwrap();
    let emulator = UrgEmulator::new(Arc::new(wall_ahead), EmulatorConfig::default());
    let server = tokio::spawn(async move { emulator.serve(master).await });
    let mut cmd = std::process::Command::new(python);
    cmd.arg(script()).arg(&path);
    let output = tokio::time::timeout(
        Duration::from_secs(90),
        tokio::task::spawn_blocking(move || cmd.output()),
    )
    .await
    .expect("the peer script timed out")
    .unwrap()
    .unwrap();
    drop(slave);
    server.abort();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    let json: Value = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("no JSON ({e}); stdout {stdout}; stderr {stderr}"));
    println!("{json}");
    assert!(output.status.success(), "{json}\nstderr: {stderr}");

    assert_eq!(json["model"], "URG-04LX(Hokuyo Automatic Co.,Ltd.)");
    let p = &json["params"];
    assert_eq!(
        (
            &p["amin"],
            &p["amax"],
            &p["ares"],
            &p["aforw"],
            &p["dmin"],
            &p["dmax"]
        ),
        (
            &Value::from(44),
            &Value::from(725),
            &Value::from(1024),
            &Value::from(384),
            &Value::from(20),
            &Value::from(5600)
        )
    );
    assert_eq!(p["scan_freq"], 10, "600 rpm");
    assert_eq!(json["state_after_open"], 3, "BM: single scan state");
    for (grouping, values) in [("0", 682), ("1", 682), ("3", 228)] {
        let d = &json["get_dist"][grouping];
        assert_eq!(d["values"], values, "grouping {grouping}: {d}");
        assert_eq!(d["front_mm"], 2000, "grouping {grouping}: {d}");
    }
    let md = json["iter_dist"].as_array().unwrap();
    let pending: Vec<i64> = md.iter().map(|s| s["pending"].as_i64().unwrap()).collect();
    assert_eq!(pending, [2, 1, 0]);
    assert!(md
        .iter()
        .all(|s| s["values"] == 682 && s["front_mm"] == 2000));
    let stamps: Vec<i64> = md
        .iter()
        .map(|s| s["timestamp_ms"].as_i64().unwrap())
        .collect();
    assert!(
        stamps.windows(2).all(|w| w[1] - w[0] >= 90),
        "one scan per 100 ms: {stamps:?}"
    );
    assert_eq!(
        json["state_after_md"], 0,
        "the laser goes off after the last MD scan"
    );
    assert_eq!(json["state_after_standby"], 0);
    assert_eq!(json["version"]["PROT"], "SCIP 2.0");
}
