//! Property tests of the sans-IO codec: no panics on any bytes, chunking does not matter,
//! resynchronisation after garbage.
#![allow(clippy::unwrap_used)] // proptest strategies are closures outside #[test] fns

use proptest::prelude::*;
use rfloc_kts::{parse_line, KtsCodec, KtsLine, Rssi, Uid};

fn uid_strategy() -> impl Strategy<Value = Uid> {
    // E0, a non-zero manufacturer code, six free bytes.
    (1u8..=0xFF, any::<[u8; 6]>()).prop_map(|(m, rest)| {
        let mut v = 0xE0u64 << 56 | u64::from(m) << 48;
        for (i, b) in rest.iter().enumerate() {
            v |= u64::from(*b) << (8 * (5 - i));
        }
        Uid::from_u64(v).unwrap()
    })
}

fn line_strategy() -> impl Strategy<Value = (String, KtsLine)> {
    prop_oneof![
        (uid_strategy(), 0i32..8, 0i32..8).prop_map(|(uid, a, b)| (
            format!("SCAN:+UID={uid},+RSSI={a}/{b}"),
            KtsLine::ScanSeen {
                uid,
                rssi: Some(Rssi {
                    main: a,
                    aux: Some(b)
                })
            }
        )),
        uid_strategy().prop_map(|uid| (format!("SCAN:-UID={uid}"), KtsLine::ScanLost { uid })),
        Just(("OK".to_string(), KtsLine::Ok)),
        Just(("ERROR".to_string(), KtsLine::Error)),
        (0u32..1000).prop_map(|n| (format!("+CME ERROR: {n}"), KtsLine::CmeError(n))),
    ]
}

fn terminator() -> impl Strategy<Value = &'static str> {
    prop_oneof![
        Just("\r\n"),
        Just("\n"),
        Just("\r"),
        Just("<\\r>"),
        Just("<\\r>\r\n")
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(2002), ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048), cut in 0usize..2048) {
        let mut codec = KtsCodec::new();
        let cut = cut.min(bytes.len());
        let mut n = codec.decode(&bytes[..cut]).len();
        n += codec.decode(&bytes[cut..]).len();
        let s = codec.stats();
        prop_assert_eq!(s.lines + s.malformed, n as u64);
        let _ = parse_line(&bytes);
    }

    #[test]
    fn valid_lines_survive_any_chunking(
        lines in proptest::collection::vec((line_strategy(), terminator()), 1..40),
        cuts in proptest::collection::vec(any::<prop::sample::Index>(), 0..20),
    ) {
        let mut wire = Vec::new();
        let mut expected = Vec::new();
        for ((text, parsed), term) in &lines {
            wire.extend_from_slice(text.as_bytes());
            wire.extend_from_slice(term.as_bytes());
            expected.push(parsed.clone());
        }
        let mut points: Vec<usize> = cuts.iter().map(|i| i.index(wire.len() + 1)).collect();
        points.push(0);
        points.push(wire.len());
        points.sort_unstable();
        let mut codec = KtsCodec::new();
        let mut got = Vec::new();
        for w in points.windows(2) {
            for r in codec.decode(&wire[w[0]..w[1]]) {
                got.push(r.unwrap());
            }
        }
        prop_assert_eq!(got, expected);
        prop_assert_eq!(codec.stats().malformed, 0);
    }

    #[test]
    fn resyncs_after_garbage(
        garbage in proptest::collection::vec(any::<u8>(), 0..300),
        ((text, parsed), term) in (line_strategy(), terminator()),
    ) {
        let mut codec = KtsCodec::new();
        codec.decode(&garbage);
        // Any line end flushes the garbage; the next valid line parses.
        codec.decode(b"\r\n");
        let out = codec.decode(format!("{text}{term}").as_bytes());
        prop_assert_eq!(out.len(), 1);
        prop_assert_eq!(out[0].clone().unwrap(), parsed);
    }

    #[test]
    fn uid_text_round_trip(uid in uid_strategy()) {
        prop_assert_eq!(Uid::parse(&uid.to_string()).unwrap(), uid.clone());
        prop_assert_eq!(Uid::parse(&uid.to_string().to_lowercase()).unwrap(), uid);
    }
}
