//! Property tests: encodings round-trip, and GD replies survive any chunking and garbage
//! before them.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use proptest::prelude::*;
use rfloc_urg::encoding::{decode, encode};
use rfloc_urg::{Reply, ReplyDecoder, Scan};

/// A GD reply for steps `start..start+len-1`, cluster 1, as a sensor sends it.
fn gd_reply(start: u16, ranges: &[u32], stamp: u32) -> Vec<u8> {
    let end = start + u16::try_from(ranges.len()).unwrap() - 1;
    Reply::distance(format!("GD{start:04}{end:04}01").as_bytes(), stamp, ranges).to_bytes()
}

proptest! {
    #[test]
    fn encodings_round_trip(v in any::<u32>(), width in 2usize..=4) {
        let masked = v & ((1u32 << (6 * width)) - 1);
        let chars = encode(masked, width);
        prop_assert_eq!(chars.len(), width);
        prop_assert!(chars.iter().all(|c| (0x30..0x70).contains(c)));
        prop_assert_eq!(decode(&chars), Some(masked));
    }

    #[test]
    fn replies_round_trip_through_bytes(
        ranges in proptest::collection::vec(0u32..(1 << 18), 0..300),
        stamp in 0u32..(1 << 24),
        status in prop_oneof![Just(*b"00"), Just(*b"10"), Just(*b"02")],
    ) {
        let mut reply = Reply::distance(b"GD0044072501", stamp, &ranges);
        if status != *b"00" {
            // Error statuses carry neither time stamp nor data.
            reply = Reply { status, timestamp_ms: None, data: Vec::new(), ..reply };
        }
        let mut d = ReplyDecoder::new();
        d.push(&reply.to_bytes());
        prop_assert_eq!(d.next_reply().unwrap().unwrap(), reply);
    }

    #[test]
    fn gd_replies_decode_in_any_chunking(
        ranges in proptest::collection::vec(0u32..(1 << 18), 1..700),
        stamp in 0u32..(1 << 24),
        cuts in proptest::collection::vec(1usize..200, 0..20),
    ) {
        let bytes = gd_reply(44, &ranges, stamp);
        let mut d = ReplyDecoder::new();
        let mut rest = bytes.as_slice();
        for c in cuts {
            let (a, b) = rest.split_at(c.min(rest.len()));
            d.push(a);
            rest = b;
        }
        d.push(rest);
        let reply = d.next_reply().unwrap().unwrap();
        let scan = Scan::from_reply(&reply).unwrap();
        prop_assert_eq!(scan.ranges_mm, ranges);
        prop_assert_eq!(scan.timestamp_ms, stamp);
        prop_assert!(d.next_reply().is_none());
    }

    #[test]
    fn garbage_before_a_reply_costs_only_itself(
        garbage in proptest::collection::vec(any::<u8>(), 0..300),
        ranges in proptest::collection::vec(0u32..(1 << 18), 1..50),
    ) {
        let mut d = ReplyDecoder::new();
        // Garbage, then an empty line (a sensor's reply end), then a good reply.
        d.push(&garbage);
        d.push(b"\n\n");
        d.push(&gd_reply(100, &ranges, 1));
        let mut good = None;
        while let Some(r) = d.next_reply() {
            if let Ok(r) = r {
                if r.echo.starts_with(b"GD0100") {
                    good = Some(r);
                }
            }
        }
        let scan = Scan::from_reply(&good.expect("the good reply")).unwrap();
        prop_assert_eq!(scan.ranges_mm, ranges);
    }
}
