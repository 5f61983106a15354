//! Replay of the reference capture `tests/captures/xbee-nd-api2/xbee.cap` (a coordinator in
//! API mode 2 answering `ND` at every 45° step over three sweeps, with line noise, responses
//! split at random points, one bad checksum and one truncated response).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;

use rfloc_capture::{Capture, RecordKind};
use std::time::Duration;

use rfloc_transport::replay::{Pace, ReplayMode, Replayer};
use rfloc_xbee::{
    ApiMode, AtCommandName, ClientConfig, DecodeError, DiscoveryEnd, Frame, FrameDecoder,
    NdLayoutHint, Node, XBeeClient,
};

fn capture_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures/xbee-nd-api2/xbee.cap")
}

fn load_capture() -> Capture {
    let path = capture_path();
    assert!(
        path.is_file(),
        "reference capture missing: {}",
        path.display()
    );
    Capture::from_path(&path).unwrap()
}

/// One ND round as seen by the codec: the request's frame ID and the NIs that answered.
#[derive(Debug, PartialEq)]
struct Round {
    frame_id: u8,
    nis: Vec<String>,
}

#[test]
fn capture_replay_through_codec() {
    let capture = load_capture();
    let mut decoder = FrameDecoder::new(ApiMode::Escaped);
    let mut request_decoder = FrameDecoder::new(ApiMode::Escaped);
    let mut rounds: Vec<Round> = Vec::new();
    let mut errors: Vec<DecodeError> = Vec::new();
    let mut other_frames = 0;
    for record in &capture.records {
        match &record.kind {
            RecordKind::Tx(bytes) => {
                request_decoder.push(bytes);
                let data = request_decoder.next_frame().unwrap().unwrap();
                let Frame::AtCommand(c) = Frame::parse(&data).unwrap() else {
                    panic!("request is not an AT command")
                };
                assert_eq!(c.command, AtCommandName::ND);
                rounds.push(Round {
                    frame_id: c.frame_id,
                    nis: Vec::new(),
                });
            }
            RecordKind::Rx(bytes) => {
                decoder.push(bytes);
                while let Some(item) = decoder.next_frame() {
                    match item {
                        Err(e) => errors.push(e),
                        Ok(data) => match Frame::parse(&data).unwrap() {
                            Frame::AtResponse(r) if r.command == AtCommandName::ND => {
                                let round = rounds.last_mut().expect("response before request");
                                assert_eq!(r.frame_id, round.frame_id, "response to another round");
                                let node = Node::parse(&r.data, NdLayoutHint::Auto).unwrap();
                                assert_eq!(node.address.0 >> 32, 0x0013_A200);
                                round.nis.push(node.ni);
                            }
                            _ => other_frames += 1,
                        },
                    }
                }
            }
            RecordKind::Event(_) => {}
        }
    }
    errors.extend(decoder.finish().into_iter().filter_map(Result::err));
    let stats = decoder.stats();
    // Golden output, checked by hand against the capture: 24 rounds (frame IDs 1..=0x18), all
    // four beacons answer except where a response was damaged on the wire.
    let expected = expected_rounds();
    assert_eq!(rounds, expected);
    // The same rounds as the driver-level golden file beside the capture (`RFLOC_BLESS=1`
    // rewrites it), which the workspace's replay regression test requires of every session.
    let mut text = String::from("# ND rounds of xbee.cap: frame ID, then the NIs that answered\n");
    for r in &rounds {
        text.push_str(&format!("0x{:02X} {}\n", r.frame_id, r.nis.join(" ")));
    }
    let golden = capture_path().with_file_name("xbee.rounds.golden");
    if std::env::var_os("RFLOC_BLESS").is_some() {
        std::fs::write(&golden, &text).unwrap();
    }
    assert_eq!(text, std::fs::read_to_string(&golden).unwrap());
    assert_eq!(
        other_frames, 0,
        "the capture holds no end-of-discovery frame"
    );
    assert_eq!(stats.frames, 92);
    assert_eq!(stats.bad_checksums, 3);
    assert_eq!(stats.truncated_frames, 1);
    assert_eq!(stats.garbage_runs, 1);
    assert_eq!(stats.bad_lengths, 0);
    // 3 bytes of line noise + 3 × 36 bytes of bad-checksum frames + 31 bytes truncated.
    assert_eq!(stats.dropped_bytes, 3 + 3 * 36 + 31);
    assert!(matches!(&errors[0], DecodeError::Garbage { bytes } if bytes == &[0x00, 0x13, 0x55]));
    assert_eq!(errors.len(), 5);
    let rx_total: usize = capture
        .records
        .iter()
        .filter_map(|r| match &r.kind {
            RecordKind::Rx(b) => Some(b.len()),
            _ => None,
        })
        .sum();
    assert_eq!(stats.frame_bytes + stats.dropped_bytes, rx_total as u64);
}

/// Golden output, checked by hand against the capture: 24 rounds (frame IDs 1..=0x18), all four
/// beacons answer except where a response was damaged on the wire.
fn expected_rounds() -> Vec<Round> {
    let missing = |id: u8| match id {
        0x07 => Some("beacon1"), // bad checksum (03, should be 02)
        0x0A => Some("beacon2"), // bad checksum (DA, should be DB)
        0x0B => Some("beacon4"), // truncated after the device type byte
        0x18 => Some("beacon4"), // bad checksum (84, should be 85), last frame of the capture
        _ => None,
    };
    (1..=0x18)
        .map(|frame_id| Round {
            frame_id,
            nis: ["beacon1", "beacon2", "beacon3", "beacon4"]
                .into_iter()
                .filter(|ni| missing(frame_id) != Some(*ni))
                .map(String::from)
                .collect(),
        })
        .collect()
}

/// End-to-end: the client itself talks to the replayed capture (request/response mode). Its
/// frame IDs start at 1 like the recorded ones, so every request must match byte for byte.
/// The capture has no end-of-discovery frame, so each round ends on the (shortened) NT timer.
#[tokio::test]
async fn capture_replay_through_client() {
    let (io, handle) = Replayer::new(load_capture())
        .mode(ReplayMode::RequestResponse)
        .pace(Pace::Fast)
        .strict(true)
        .hold_open(true)
        .start();
    let config = ClientConfig {
        mode: ApiMode::Escaped,
        node_discovery_timeout: Duration::from_millis(40),
        discovery_margin: Duration::from_millis(10),
        ..ClientConfig::default()
    };
    let mut client = XBeeClient::new(io, config);
    let mut rounds = Vec::new();
    for frame_id in 1..=0x18u8 {
        let discovery = client.discover().await.unwrap();
        assert_eq!(discovery.end, DiscoveryEnd::Timeout);
        assert!(discovery.rejected.is_empty());
        rounds.push(Round {
            frame_id,
            nis: discovery.nodes.into_iter().map(|n| n.ni).collect(),
        });
    }
    assert_eq!(rounds, expected_rounds());
    let report = handle.report();
    assert!(report.mismatches.is_empty(), "{:?}", report.mismatches);
    assert_eq!(report.requests, 0x18);
    assert_eq!(report.rx_bytes_delivered, report.rx_bytes_total);
    let stats = client.stats();
    assert_eq!(
        (stats.decode.bad_checksums, stats.decode.garbage_runs),
        (3, 1)
    );
    // The truncated frame of round 0x0B is only cut off when round 0x0C's first response arrives.
    assert_eq!(stats.decode.truncated_frames, 1);
    assert_eq!(stats.decode.frames, 92);
}
