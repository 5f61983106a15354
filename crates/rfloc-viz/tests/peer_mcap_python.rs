//! The Python `mcap` package (`tests/peers/mcap_read.py`) reads a recording with every channel:
//! channel names, schemas and message counts, by iteration and from the summary, and every
//! message decoded by Google's protobuf runtime from the schemas stored in the file
//! (mcap-protobuf-support), with decoded fields of a pose and of the custom link message.
//!
//! The interpreter comes from `RFLOC_PYTHON` (a venv with `mcap==1.6.0` and
//! `mcap-protobuf-support==0.6.0`). Without it the test prints why and passes; with it, any
//! failure fails the test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::path::PathBuf;

use serde_json::Value;

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/peers/mcap_read.py")
}

#[test]
fn python_mcap_reads_every_channel() {
    let Some(python) = std::env::var_os("RFLOC_PYTHON") else {
        println!("skipped: RFLOC_PYTHON not set (a venv with mcap==1.6.0 and mcap-protobuf-support==0.6.0 runs this test)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("peer.mcap");
    common::record_every_channel(&path);

    let output = std::process::Command::new(python)
        .arg(script())
        .arg(&path)
        .output()
        .expect("the interpreter in RFLOC_PYTHON runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    let json: Value = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("no JSON ({e}); stdout {stdout}; stderr {stderr}"));
    println!("{json}");
    assert!(output.status.success(), "{json}\nstderr: {stderr}");

    let expected = common::expected_counts();
    let channels = json["channels"].as_object().unwrap();
    assert_eq!(channels.len(), expected.len(), "{json}");
    for (topic, n) in &expected {
        let c = &channels[*topic];
        assert_eq!(c["count"], *n, "{topic}: {c}");
        assert_eq!(c["summary_count"], *n, "{topic}: {c}");
        assert_eq!(c["decoded"], *n, "{topic}: {c}");
        assert_eq!(c["message_encoding"], "protobuf", "{topic}");
        assert_eq!(c["schema_encoding"], "protobuf", "{topic}");
    }
    assert_eq!(
        channels[rfloc_viz::topics::POSE]["schema"],
        "foxglove.PoseInFrame"
    );
    assert_eq!(
        channels[rfloc_viz::topics::LINK]["schema"],
        "linkbytes.LinkBytes"
    );
    assert_eq!(json["message_count"], expected.values().sum::<u64>());
    assert_eq!(json["first_log_time"], common::T0);
    assert_eq!(json["last_log_time"], common::stamp(1004).unix_nanos());
    assert!(json["library"].as_str().unwrap().starts_with("rfloc-viz "));

    // The first pose of `common::events`: (1, 2) heading 0, at T0.
    let pose = &json["samples"][rfloc_viz::topics::POSE];
    assert_eq!(pose["frame_id"], "map", "{pose}");
    assert_eq!(
        (&pose["x"], &pose["y"]),
        (&Value::from(1.0), &Value::from(2.0))
    );
    assert_eq!(
        (&pose["qz"], &pose["qw"]),
        (&Value::from(0.0), &Value::from(1.0))
    );
    assert_eq!(pose["log_time_ns"], common::T0);
    // The first link chunk: sent, b"GD" 0x00 0xff b"\n".
    let link = &json["samples"][rfloc_viz::topics::LINK];
    assert_eq!(link["device"], "urg", "{link}");
    assert_eq!(link["direction"], "Tx", "{link}");
    assert_eq!(link["data_hex"], "474400ff0a", "{link}");
}
