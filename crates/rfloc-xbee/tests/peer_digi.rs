//! digi-xbee 1.5.0 (`tests/peers/xbee_digi.py`) against the coordinator emulator on a pty:
//! `open()`, network discovery, local and remote `DB`/`NI`, in API modes 1 and 2, for the
//! Zigbee and the 802.15.4 flavour (each with its ND layout).
//!
//! The interpreter comes from `RFLOC_PYTHON` (a venv with `digi-xbee==1.5.0`). Without it the
//! test prints why and passes; with it, any failure fails the test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use rfloc_xbee::{ApiMode, Beacon, CoordinatorEmulator, EmulatorConfig, Flavor, NdLayout};
use serde_json::Value;
use tokio_serial::{SerialPort, SerialStream};

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/peers/xbee_digi.py")
}

const RSSI: [f64; 3] = [-40.0, -55.0, -70.0];

async fn run(python: &std::ffi::OsStr, mode: ApiMode, flavor: Flavor) -> Value {
    let (master, slave) = SerialStream::pair().unwrap();
    let path = slave.name().unwrap();
    let emulator = CoordinatorEmulator::new(
        (1..=3).map(Beacon::numbered).collect(),
        Arc::new(|i| RSSI.get(i).copied()),
        EmulatorConfig {
            mode,
            flavor,
            nd_layout: match flavor {
                Flavor::Zigbee => NdLayout::ZigbeeOrDigiMesh,
                Flavor::Ieee802154 => NdLayout::Ieee802154,
            },
            nt_units: 0x20,
            ..EmulatorConfig::default()
        },
    );
    let server = tokio::spawn(async move { emulator.serve(master).await });
    let mut cmd = std::process::Command::new(python);
    cmd.arg(script())
        .arg(&path)
        .arg("--api-mode")
        .arg(mode.ap_value().to_string())
        .arg("--flavor")
        .arg(match flavor {
            Flavor::Zigbee => "zigbee",
            Flavor::Ieee802154 => "802.15.4",
        });
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
    assert!(output.status.success(), "{json}\nstderr: {stderr}");
    json
}

fn check(json: &Value, mode: ApiMode, flavor: Flavor) {
    let (protocol, firmware) = match flavor {
        Flavor::Zigbee => ("ZIGBEE", "4060"),
        Flavor::Ieee802154 => ("RAW_802_15_4", "2003"),
    };
    assert_eq!(json["protocol"], protocol, "{json}");
    assert_eq!(json["firmware_version"], firmware);
    assert_eq!(json["hardware_version"], 0x2E);
    assert_eq!(
        json["operating_mode"],
        match mode {
            ApiMode::Unescaped => "API_MODE",
            ApiMode::Escaped => "ESCAPED_API_MODE",
        }
    );
    assert_eq!(json["address64"], "0013A2004000FFFF");
    assert_eq!(json["address16"], "0000");
    assert_eq!(json["role"], "COORDINATOR");
    assert_eq!(json["node_id"], "coordinator");
    assert_eq!(json["local_ni"], "coordinator");
    assert_eq!(json["discovery_finished"], true);
    let nodes = json["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 3, "{json}");
    for (k, node) in nodes.iter().enumerate() {
        let n = k + 1;
        assert_eq!(node["address64"], format!("0013A2004000000{n}"));
        assert_eq!(node["address16"], format!("100{n}"));
        assert_eq!(node["node_id"], format!("beacon{n}"));
        assert_eq!(node["remote_ni"], format!("beacon{n}"));
        assert_eq!(node["remote_db"], -RSSI[k] as i64, "{node}");
    }
    // The local DB is the RSSI of the last packet heard: the last remote reply (beacon3).
    assert_eq!(json["local_db"], 70);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn digi_xbee_opens_discovers_and_reads_db_ni() {
    let Some(python) = std::env::var_os("RFLOC_PYTHON") else {
        println!("skipped: RFLOC_PYTHON not set (a venv with digi-xbee==1.5.0 runs this test)");
        return;
    };
    for flavor in [Flavor::Zigbee, Flavor::Ieee802154] {
        for mode in [ApiMode::Unescaped, ApiMode::Escaped] {
            let json = run(&python, mode, flavor).await;
            println!("{flavor:?} AP={}: {json}", mode.ap_value());
            check(&json, mode, flavor);
        }
    }
}
