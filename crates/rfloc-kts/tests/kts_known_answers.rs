//! Known-answer tests from seed 002 (`002_a245ca0983afd786.txt`).

use rfloc_kts::{KtsCodec, KtsLine, Rssi, Uid};

/// Seed 002 §7.2.1 and Table 7 "String preperation": the complete line
/// `SCAN:+UID=E00401503A5BD691,+RSSI=0/0` becomes `E00401503A5BD691 0/0` and then `1681 0`
/// (last three hex digits as a decimal tag number, first RSSI number); the incomplete line
/// `SCAN:-UID=E00401503A5BDAE4` is dropped.
#[test]
fn table7_string_preparation() {
    let mut codec = KtsCodec::new();
    let out =
        codec.decode(b"SCAN:+UID=E00401503A5BD691,+RSSI=0/0\r\nSCAN:-UID=E00401503A5BDAE4\r\n");
    let [Ok(KtsLine::ScanSeen {
        uid,
        rssi: Some(rssi),
    }), Ok(KtsLine::ScanLost { uid: lost })] = out.as_slice()
    else {
        panic!("unexpected decode {out:?}");
    };
    assert_eq!(format!("{uid} {rssi}"), "E00401503A5BD691 0/0");
    assert_eq!(
        format!("{} {}", uid.short_id(3).unwrap(), rssi.main),
        "1681 0"
    );
    assert_eq!(
        *rssi,
        Rssi {
            main: 0,
            aux: Some(0)
        }
    );
    assert_eq!(lost.to_string(), "E00401503A5BDAE4");
    assert_eq!(codec.stats().lost, 1);
}

/// Seed 002 §5: `SCAN:+UID=E00402000018313E,+RSSI=7/6`, "the first number the value for the
/// main and the second for the auxiliary receiver channel".
#[test]
fn section5_example_line() {
    let mut codec = KtsCodec::new();
    let out = codec.decode(b"SCAN:+UID=E00402000018313E,+RSSI=7/6\r\n");
    assert_eq!(
        out,
        vec![Ok(KtsLine::ScanSeen {
            uid: Uid::parse("E00402000018313E").unwrap(),
            rssi: Some(Rssi {
                main: 7,
                aux: Some(6)
            })
        })]
    );
}

/// Seed 002 §7.2.1: the strings are "35 characters" long (36 with one terminator byte).
#[test]
fn section721_line_length() {
    assert_eq!("SCAN:+UID=E00401503A5BD691,+RSSI=0/0".len(), 36);
    // The seed says 35 / 36; the line itself is 36 characters, so "35" is a slip in the text.
}

/// Seed 002 appendix A (the lab's Matlab emulator, unfiltered mode) wrote `OK` and the literal
/// `<\r>` as a terminator; both are handled.
#[test]
fn appendix_a_literal_terminator() {
    let mut codec = KtsCodec::new();
    let out = codec.decode(b"OK<\\r>SCAN:+UID=E00401503A5BD785,+RSSI=4/5<\\r>");
    assert_eq!(out.len(), 2);
    assert_eq!(out[0], Ok(KtsLine::Ok));
    assert!(matches!(
        &out[1],
        Ok(KtsLine::ScanSeen {
            rssi: Some(Rssi {
                main: 4,
                aux: Some(5)
            }),
            ..
        })
    ));
}
