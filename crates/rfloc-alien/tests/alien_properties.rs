//! Property tests: no panics on any bytes, frames survive any chunking, TagList lines in the
//! project and seed formats round-trip for EPCs of any length.
#![allow(clippy::unwrap_used)] // proptest strategies outside #[test] fns

use proptest::prelude::*;
use rfloc_alien::{
    parse_reply, CustomFormat, Frame, ReplyFramer, TagListFormat, PROJECT_CUSTOM_FORMAT,
    SEED000_CUSTOM_FORMAT,
};

fn hex(id: &[u8]) -> String {
    id.iter().map(|b| format!("{b:02X}")).collect()
}

fn spaced(id: &[u8]) -> String {
    id.chunks(2).map(hex).collect::<Vec<_>>().join(" ")
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(9900), ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let mut f = ReplyFramer::new();
        for frame in f.push(&bytes) {
            if let Frame::Reply(body) = frame {
                let _ = parse_reply(&body);
                for fmt in [TagListFormat::Text, TagListFormat::Terse, TagListFormat::Xml,
                            TagListFormat::Custom(CustomFormat::compile(SEED000_CUSTOM_FORMAT).unwrap())] {
                    let _ = fmt.parse(&body);
                }
            }
        }
        let text = String::from_utf8_lossy(&bytes);
        let _ = TagListFormat::Xml.parse(&text);
        let _ = TagListFormat::Text.parse(&text);
        let _ = CustomFormat::compile(&text);
    }

    #[test]
    fn frames_survive_any_chunking(
        bodies in proptest::collection::vec("[ -~\r\n]{0,40}", 1..10),
        cuts in proptest::collection::vec(any::<prop::sample::Index>(), 0..10),
    ) {
        // Bodies without '>' so that none ends in a prompt word.
        let bodies: Vec<String> = bodies.into_iter().map(|b| b.replace('>', "")).collect();
        let wire: Vec<u8> = bodies.iter().flat_map(|b| b.bytes().chain([0u8])).collect();
        let mut points: Vec<usize> = cuts.iter().map(|i| i.index(wire.len() + 1)).collect();
        points.extend([0, wire.len()]);
        points.sort_unstable();
        let mut f = ReplyFramer::new();
        let mut got = Vec::new();
        for w in points.windows(2) {
            got.extend(f.push(&wire[w[0]..w[1]]));
        }
        let want: Vec<Frame> = bodies.into_iter().map(Frame::Reply).collect();
        prop_assert_eq!(got, want);
    }

    #[test]
    fn project_format_round_trip(
        tags in proptest::collection::vec((proptest::collection::vec(any::<u8>(), 1..=32), -9_999_999i64..9_999_999, 0u32..100_000, 0u32..4), 0..20),
    ) {
        let fmt = TagListFormat::Custom(CustomFormat::compile(PROJECT_CUSTOM_FORMAT).unwrap());
        let body: String = tags.iter().map(|(id, r, n, a)| format!(
            "id={};rssi={:.1};count={n};ant={a};disc=2026/11/21 10:00:05.123;last=2026/11/21 10:00:06.456;\r\n",
            hex(id), *r as f64 / 10.0)).collect();
        let (got, bad) = fmt.parse(&body);
        prop_assert!(bad.is_empty());
        prop_assert_eq!(got.len(), tags.len());
        for (g, (id, r, n, a)) in got.iter().zip(&tags) {
            prop_assert_eq!(&g.id.0, id);
            prop_assert!((g.rssi.unwrap() - *r as f64 / 10.0).abs() < 1e-6);
            prop_assert_eq!((g.count, g.antenna), (Some(*n), Some(*a)));
        }
    }

    #[test]
    fn seed_format_round_trip(
        tags in proptest::collection::vec((proptest::collection::vec(any::<u8>(), 1..=32), 0i64..99_999), 0..20),
    ) {
        let fmt = TagListFormat::Custom(CustomFormat::compile(SEED000_CUSTOM_FORMAT).unwrap());
        let body: String = tags.iter().map(|(id, r)| format!(
            "IDK {} RSSI {:.1} TIME 10:00:05;\r\n", spaced(id), *r as f64 / 10.0)).collect();
        let (got, bad) = fmt.parse(&body);
        prop_assert!(bad.is_empty(), "{:?}", bad);
        let ids: Vec<&Vec<u8>> = got.iter().map(|t| &t.id.0).collect();
        let want: Vec<&Vec<u8>> = tags.iter().map(|(id, _)| id).collect();
        prop_assert_eq!(ids, want);
    }
}
