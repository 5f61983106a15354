//! `rfloc emulate` against third-party host libraries, the way a user develops against it:
//! digi-xbee 1.5.0 opens the emulated XBee on a pseudo-terminal (API modes 1 and 2, Zigbee and
//! 802.15.4 firmware with their ND layouts), discovers the network and reads local and remote
//! `DB` and `NI`; hokuyolx 0.9.0's default constructor opens the emulated URG, reads distances
//! at several clusterings, streams `MD` scans and goes to standby; a raw client syncs with the
//! emulated Pioneer on its TCP port.
//!
//! The Python peers run when `RFLOC_PYTHON` names an interpreter with digi-xbee and hokuyolx
//! (CI installs them); without it those tests print that they were skipped.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::Value;

fn peers() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/peers")
}

/// `rfloc emulate ARGS`, once it announces where it serves (its first stdout line).
struct Emulator {
    child: Child,
    announced: String,
}

impl Emulator {
    fn start(args: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_rfloc"))
            .arg("emulate")
            .args(args)
            .env("RFLOC_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(
            line.starts_with("PTY ") || line.starts_with("TCP "),
            "rfloc emulate announced {line:?}"
        );
        Self {
            child,
            announced: line.trim().to_string(),
        }
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs a peer script on `port` with `args`; its JSON, or `None` when no Python is configured.
fn peer(script: &str, port: &Path, args: &[&str]) -> Option<Value> {
    let Some(python) = std::env::var_os("RFLOC_PYTHON") else {
        println!("skipped: RFLOC_PYTHON not set (a venv with digi-xbee==1.5.0 and hokuyolx==0.9.0 runs this test)");
        return None;
    };
    let out = Command::new(python)
        .arg(peers().join(script))
        .arg(port)
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let json: Value = serde_json::from_str(stdout.trim()).unwrap_or_else(|e| {
        panic!(
            "{script}: no JSON ({e}); stdout {stdout}; stderr {}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    assert!(out.status.success(), "{script}: {json}");
    Some(json)
}

#[test]
fn digi_xbee_opens_discovers_and_reads_the_emulated_radio() {
    let dir = tempfile::tempdir().unwrap();
    for mode in ["1", "2"] {
        for flavor in ["zigbee", "802.15.4"] {
            let link = dir.path().join(format!("xbee-{mode}-{flavor}"));
            let link_text = link.to_str().unwrap();
            let _emulator = Emulator::start(&[
                "xbee",
                "--pty",
                link_text,
                "--api-mode",
                mode,
                "--flavor",
                flavor,
            ]);
            let Some(json) = peer(
                "xbee_digi.py",
                &link,
                &["--api-mode", mode, "--flavor", flavor],
            ) else {
                return;
            };
            let nodes = json["nodes"].as_array().unwrap();
            let found: Vec<(&str, i64, &str)> = nodes
                .iter()
                .map(|n| {
                    (
                        n["node_id"].as_str().unwrap(),
                        n["remote_db"].as_i64().unwrap(),
                        n["remote_ni"].as_str().unwrap(),
                    )
                })
                .collect();
            assert_eq!(
                found,
                [
                    ("beacon1", 40, "beacon1"),
                    ("beacon2", 55, "beacon2"),
                    ("beacon3", 70, "beacon3")
                ],
                "API mode {mode}, {flavor}: {json}"
            );
            assert!(json["local_db"].is_i64(), "{json}");
            assert_eq!(json["local_ni"], "coordinator", "{json}");
        }
    }
}

#[test]
fn hokuyolx_opens_scans_and_streams_the_emulated_laser() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("urg");
    let _emulator = Emulator::start(&["urg", "--pty", link.to_str().unwrap()]);
    let Some(json) = peer("urg_hokuyolx.py", &link, &[]) else {
        return;
    };
    assert_eq!(json["model"], "URG-04LX(Hokuyo Automatic Co.,Ltd.)");
    for (grouping, values) in [("0", 682), ("1", 682), ("3", 228)] {
        let d = &json["get_dist"][grouping];
        assert_eq!(d["values"], values, "grouping {grouping}: {d}");
        assert_eq!(d["front_mm"], 2000, "a wall 2 m ahead: {d}");
    }
    let md = json["iter_dist"].as_array().unwrap();
    assert_eq!(md.len(), 3, "{json}");
    assert!(md
        .iter()
        .all(|s| s["values"] == 682 && s["front_mm"] == 2000));
    assert_eq!(json["state_after_standby"], 0);
}

#[test]
fn the_emulated_pioneer_syncs_on_its_tcp_port() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let emulator = Emulator::start(&["aria", "--tcp", &format!("127.0.0.1:{port}")]);
    assert_eq!(emulator.announced, format!("TCP 127.0.0.1:{port}"));
    let mut robot = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    robot
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    // SYNC0, SYNC1, SYNC2 (docs/protocols/pioneer-aria.md): each echoed back.
    for sync in [0u8, 1, 2] {
        let packet = [0xFA, 0xFB, 0x03, sync, 0x00, sync];
        robot.write_all(&packet).unwrap();
        let mut head = [0u8; 4];
        robot.read_exact(&mut head).unwrap();
        assert_eq!(&head[..2], &[0xFA, 0xFB]);
        let mut rest = vec![0u8; usize::from(head[2]) - 1];
        robot.read_exact(&mut rest).unwrap();
        assert_eq!(head[3], sync, "SYNC{sync} echoed");
    }
}

/// A TCP emulator serves one client after another (as its help says): a client that sends
/// garbage and leaves, then one that asks properly and gets the device's answer. (The HF
/// reader used to serve its first client only and then close its port.)
#[test]
fn every_emulator_serves_a_second_client_after_a_garbage_one() {
    let answers: [(&str, &[u8], &[u8]); 5] = [
        ("aria", &[0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00], &[0xFA, 0xFB]),
        ("kts", b"AT\r", b"OK\r\n"),
        ("alien", b"", b"Username>"),
        ("urg", b"VV\n", b"VV\n00P\n"),
        // Local `NI` in API mode 2: the AT command response frame (0x88, frame id 1).
        (
            "xbee",
            &[0x7E, 0x00, 0x04, 0x08, 0x01, 0x4E, 0x49, 0x5F],
            &[0x7E, 0x00],
        ),
    ];
    let garbage: Vec<u8> = (0..3000_u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    for (device, request, expected) in answers {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let _emulator = Emulator::start(&[device, "--tcp", &format!("127.0.0.1:{port}")]);
        for round in 0..3 {
            let mut first = std::net::TcpStream::connect(("127.0.0.1", port))
                .unwrap_or_else(|e| panic!("{device}, round {round}: {e}"));
            first.write_all(&garbage).unwrap();
            drop(first);
            let mut client = std::net::TcpStream::connect(("127.0.0.1", port))
                .unwrap_or_else(|e| panic!("{device}, round {round}, second client: {e}"));
            client
                .set_read_timeout(Some(Duration::from_secs(5)))
                .unwrap();
            client.write_all(request).unwrap();
            let mut got = Vec::new();
            let mut buf = [0u8; 512];
            while !got.windows(expected.len()).any(|w| w == expected) {
                let n = client
                    .read(&mut buf)
                    .unwrap_or_else(|e| panic!("{device}, round {round}: {e}; got {got:?}"));
                assert!(n > 0, "{device}, round {round}: closed; got {got:?}");
                got.extend_from_slice(&buf[..n]);
            }
        }
    }
}
