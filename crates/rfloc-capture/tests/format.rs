//! Capture format: round trips, the shipped reference captures, and malformed input.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;

use proptest::prelude::*;
use rfloc_capture::{Capture, CaptureErrorKind, CaptureWriter, Header, RecordKind};

const EXAMPLE: &str = "# rfloc-capture 1
# device: kts-rfidm1356
# link: serial 115200 8N1
# started: 2026-11-21T10:00:00Z
# note: free text
# operator: someone
0.000000 tx s:AT+Scan=AC,RSSI\\r
0.012400 rx s:OK\\r\\n
0.105000 rx s:SCAN:+UID=E00402000018313E,+RSSI=7/6\\r\\n
0.210000 rx x:7E 00 04 08 01 4E 44 64
0.300000 ev mark stop 1 heading_deg=45
";

#[test]
fn parses_the_format_example() {
    let cap = Capture::parse(EXAMPLE, "example.cap").unwrap();
    assert_eq!(cap.header.device.as_deref(), Some("kts-rfidm1356"));
    assert_eq!(cap.header.link.as_deref(), Some("serial 115200 8N1"));
    assert_eq!(cap.header.notes, vec!["free text".to_string()]);
    assert_eq!(
        cap.header.extra,
        vec![("operator".to_string(), "someone".to_string())]
    );
    assert_eq!(cap.records.len(), 5);
    assert_eq!(
        cap.records[0].kind,
        RecordKind::Tx(b"AT+Scan=AC,RSSI\r".to_vec())
    );
    assert_eq!(cap.records[1].t_ns, 12_400_000);
    assert_eq!(
        cap.records[3].kind,
        RecordKind::Rx(vec![0x7E, 0, 4, 8, 1, 0x4E, 0x44, 0x64])
    );
    assert_eq!(
        cap.records[4].kind,
        RecordKind::Event("mark stop 1 heading_deg=45".into())
    );
    let mut rx = b"OK\r\nSCAN:+UID=E00402000018313E,+RSSI=7/6\r\n".to_vec();
    rx.extend_from_slice(&[0x7E, 0, 4, 8, 1, 0x4E, 0x44, 0x64]);
    assert_eq!(cap.rx_bytes(), rx);
}

#[test]
fn parse_write_parse_is_identity() {
    let cap = Capture::parse(EXAMPLE, "example.cap").unwrap();
    let text = cap.to_text();
    let again = Capture::parse(&text, "rewritten").unwrap();
    assert_eq!(cap, again);
    // The canonical form is a fixed point.
    assert_eq!(again.to_text(), text);
}

fn shared_captures() -> Vec<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/captures");
    let mut out = Vec::new();
    let mut stack = vec![root];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "cap") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn every_shipped_capture_round_trips() {
    for path in shared_captures() {
        let cap = Capture::from_path(&path).unwrap_or_else(|e| panic!("{e}"));
        let again = Capture::parse(&cap.to_text(), "rewritten").unwrap();
        assert_eq!(cap, again, "{}", path.display());
    }
}

fn err_of(text: &str) -> (usize, CaptureErrorKind) {
    let e = Capture::parse(text, "bad.cap").unwrap_err();
    assert!(
        e.to_string().starts_with(&format!("bad.cap:{}:", e.line)),
        "{e}"
    );
    (e.line, e.kind)
}

#[test]
fn malformed_lines_are_errors_with_file_and_line() {
    let (l, k) = err_of("# rfloc-capture 2\n");
    assert_eq!(l, 1);
    assert!(matches!(k, CaptureErrorKind::BadMagic(_)));

    let (l, k) = err_of("# rfloc-capture 1\n0.1 rx s:ok\n0.05 rx s:late\n");
    assert_eq!(l, 3);
    assert!(matches!(k, CaptureErrorKind::TimeGoesBack { .. }));

    let (l, k) = err_of("# rfloc-capture 1\n# device: x\n0.1 up s:ok\n");
    assert_eq!(l, 3);
    assert_eq!(k, CaptureErrorKind::BadDirection("up".into()));

    let (_, k) = err_of("# rfloc-capture 1\nabc rx s:ok\n");
    assert!(matches!(k, CaptureErrorKind::BadTime(_)));

    let (_, k) = err_of("# rfloc-capture 1\n0.1 rx x:7E 0\n");
    assert!(matches!(k, CaptureErrorKind::BadHex { .. }));

    let (_, k) = err_of("# rfloc-capture 1\n0.1 rx s:bad\\q\n");
    assert!(matches!(k, CaptureErrorKind::BadText { .. }));

    let (_, k) = err_of("# rfloc-capture 1\n0.1 rx q:abc\n");
    assert!(matches!(k, CaptureErrorKind::BadPayloadKind(_)));

    let (_, k) = err_of("# rfloc-capture 1\n0.1 rx\n");
    assert!(matches!(k, CaptureErrorKind::MissingField(_)));

    let (_, k) = err_of("# rfloc-capture 1\n0.1 ev \n");
    assert_eq!(k, CaptureErrorKind::EmptyEvent);

    // A file saved with CRLF line ends is caught, not read as extra `\r` bytes.
    let (l, k) = err_of("# rfloc-capture 1\n0.1 rx s:OK\r\n");
    assert_eq!(l, 2);
    assert!(matches!(k, CaptureErrorKind::BadText { .. }));

    let e = Capture::parse_bytes(b"# rfloc-capture 1\n0.1 rx s:\xff\n", "bin.cap").unwrap_err();
    assert_eq!((e.line, e.kind), (2, CaptureErrorKind::NotUtf8));

    let e = Capture::from_path(std::path::Path::new("/nonexistent/x.cap")).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/x.cap"));
}

#[test]
fn writer_output_parses_back() {
    let mut w =
        CaptureWriter::new(Vec::new(), &Header::new("pioneer-aria", "serial 9600 8N1")).unwrap();
    w.write(0, RecordKind::Tx(vec![0xFA, 0xFB, 3, 0, 0, 0]))
        .unwrap();
    w.write(1_500, RecordKind::Rx(b"Alien>\0".to_vec()))
        .unwrap();
    w.write(1_000, RecordKind::Event("mark late".into()))
        .unwrap();
    assert_eq!(w.clamped_times(), 1);
    let text = String::from_utf8(w.into_inner()).unwrap();
    let cap = Capture::parse(&text, "w").unwrap();
    assert_eq!(cap.records.len(), 3);
    assert_eq!(cap.records[2].t_ns, 1_500);
}

fn arb_kind() -> impl Strategy<Value = RecordKind> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 1..64).prop_map(RecordKind::Rx),
        proptest::collection::vec(any::<u8>(), 1..64).prop_map(RecordKind::Tx),
        "[a-z][a-z0-9 =._-]{0,30}".prop_map(RecordKind::Event),
    ]
}

proptest! {
    #[test]
    fn any_record_sequence_round_trips(
        steps in proptest::collection::vec((0u64..5_000_000_000, arb_kind()), 0..40)
    ) {
        let mut w = CaptureWriter::new(Vec::new(), &Header::new("xbee-api2", "serial 9600 8N1")).unwrap();
        let mut t = 0u64;
        let mut expected = Vec::new();
        for (dt, kind) in steps {
            t += dt;
            w.write(t, kind.clone()).unwrap();
            expected.push((t, kind));
        }
        let text = String::from_utf8(w.into_inner()).unwrap();
        let cap = Capture::parse(&text, "prop").unwrap();
        let got: Vec<_> = cap.records.into_iter().map(|r| (r.t_ns, r.kind)).collect();
        prop_assert_eq!(got, expected);
    }

    #[test]
    fn random_text_never_panics(text in "\\PC{0,200}") {
        let _ = Capture::parse(&format!("# rfloc-capture 1\n{text}"), "fuzz");
    }
}
