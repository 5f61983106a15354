//! Property tests of the framing layer: encode → decode round trips in both API modes, and
//! recovery of valid frames after random garbage. Fixed seeds (proptest's deterministic RNG).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use rfloc_xbee::codec::{needs_escape, START_DELIMITER};
use rfloc_xbee::{encode_frame, ApiMode, FrameDecoder};

const SEED: [u8; 32] = *b"rfloc-xbee codec property seed!!";

fn runner() -> TestRunner {
    TestRunner::new_with_rng(
        Config {
            cases: 256,
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &SEED),
    )
}

/// Frame data biased towards the four special bytes so that escaping is exercised.
fn frame_data() -> impl Strategy<Value = Vec<u8>> {
    let byte = prop_oneof![
        3 => any::<u8>(),
        1 => prop::sample::select(vec![0x7E_u8, 0x7D, 0x11, 0x13]),
    ];
    prop::collection::vec(byte, 1..300)
}

fn decode_all(decoder: &mut FrameDecoder, chunks: &[&[u8]]) -> (Vec<Vec<u8>>, usize) {
    let mut frames = Vec::new();
    let mut errors = 0;
    for chunk in chunks {
        decoder.push(chunk);
        while let Some(item) = decoder.next_frame() {
            match item {
                Ok(f) => frames.push(f),
                Err(_) => errors += 1,
            }
        }
    }
    (frames, errors)
}

#[test]
fn escaped_round_trip() {
    runner()
        .run(&(frame_data(), 1usize..40), |(data, chunk)| {
            let wire = encode_frame(&data, ApiMode::Escaped).unwrap();
            // Only the delimiter is a bare special byte; everything else is escaped.
            prop_assert_eq!(wire[0], START_DELIMITER);
            let mut i = 1;
            while i < wire.len() {
                prop_assert!(!needs_escape(wire[i]) || wire[i] == 0x7D);
                i += if wire[i] == 0x7D { 2 } else { 1 };
            }
            let chunks: Vec<&[u8]> = wire.chunks(chunk).collect();
            let mut decoder = FrameDecoder::new(ApiMode::Escaped);
            let (frames, errors) = decode_all(&mut decoder, &chunks);
            prop_assert_eq!(frames, vec![data]);
            prop_assert_eq!(errors, 0);
            prop_assert_eq!(decoder.stats().dropped_bytes, 0);
            Ok(())
        })
        .unwrap();
}

#[test]
fn unescaped_round_trip() {
    runner()
        .run(&prop::collection::vec(frame_data(), 1..5), |frames| {
            let wire: Vec<u8> = frames
                .iter()
                .flat_map(|f| encode_frame(f, ApiMode::Unescaped).unwrap())
                .collect();
            prop_assert_eq!(
                wire.len(),
                frames.iter().map(|f| f.len() + 4).sum::<usize>()
            );
            let mut decoder = FrameDecoder::new(ApiMode::Unescaped);
            let (decoded, errors) = decode_all(&mut decoder, &[&wire]);
            prop_assert_eq!(decoded, frames);
            prop_assert_eq!(errors, 0);
            Ok(())
        })
        .unwrap();
}

/// AP=2: any garbage prefix (bare 0x7E included), then valid frames: every valid frame comes
/// out, in order, and the dropped-byte count equals the garbage that was not a frame.
#[test]
fn escaped_resync_after_garbage() {
    let strategy = (
        prop::collection::vec(any::<u8>(), 0..200),
        prop::collection::vec(frame_data(), 1..4),
        1usize..64,
    );
    runner()
        .run(&strategy, |(garbage, frames, chunk)| {
            let mut wire = garbage.clone();
            for f in &frames {
                wire.extend(encode_frame(f, ApiMode::Escaped).unwrap());
            }
            let chunks: Vec<&[u8]> = wire.chunks(chunk).collect();
            let mut decoder = FrameDecoder::new(ApiMode::Escaped);
            let (decoded, _) = decode_all(&mut decoder, &chunks);
            prop_assert!(decoded.len() >= frames.len());
            let tail = &decoded[decoded.len() - frames.len()..];
            prop_assert_eq!(tail, &frames[..]);
            let stats = decoder.stats();
            prop_assert_eq!(stats.dropped_bytes + stats.frame_bytes, wire.len() as u64);
            prop_assert_eq!(stats.frames as usize, decoded.len());
            Ok(())
        })
        .unwrap();
}

/// AP=1: garbage without a delimiter, a false start (0x7E, random length, a few bytes) in the
/// middle, then valid frames: the frames are recovered, nothing is lost silently.
#[test]
fn unescaped_resync_after_garbage_and_false_start() {
    let strategy = (
        prop::collection::vec(
            any::<u8>().prop_filter("no delimiter", |b| *b != 0x7E),
            0..100,
        ),
        prop::collection::vec(
            any::<u8>().prop_filter("no delimiter", |b| *b != 0x7E),
            0..6,
        ),
        prop::collection::vec(frame_data(), 1..4),
    );
    runner()
        .run(&strategy, |(garbage, false_start, frames)| {
            let mut wire = garbage.clone();
            wire.push(0x7E);
            wire.extend(&false_start);
            let mut valid = Vec::new();
            for f in &frames {
                valid.extend(encode_frame(f, ApiMode::Unescaped).unwrap());
            }
            wire.extend(&valid);
            let mut decoder = FrameDecoder::new(ApiMode::Unescaped);
            let (mut decoded, _) = decode_all(&mut decoder, &[&wire]);
            decoded.extend(decoder.finish().into_iter().filter_map(Result::ok));
            // A false start can by chance frame a valid-looking candidate; the real frames must
            // still all appear, in order, at the end.
            prop_assert!(decoded.len() >= frames.len());
            prop_assert_eq!(&decoded[decoded.len() - frames.len()..], &frames[..]);
            let stats = decoder.stats();
            let delivered_wire: usize = decoded.iter().map(|d| d.len() + 4).sum();
            prop_assert_eq!(stats.frame_bytes as usize, delivered_wire);
            prop_assert_eq!(stats.dropped_bytes as usize + delivered_wire, wire.len());
            Ok(())
        })
        .unwrap();
}

/// Arbitrary input never panics and every byte is accounted for once the input is finished.
#[test]
fn arbitrary_bytes_are_accounted_for() {
    for mode in [ApiMode::Unescaped, ApiMode::Escaped] {
        runner()
            .run(&prop::collection::vec(any::<u8>(), 0..600), |bytes| {
                let mut decoder = FrameDecoder::with_max_frame_data(mode, 64);
                decoder.push(&bytes);
                let items = decoder.finish();
                let stats = decoder.stats();
                prop_assert_eq!(
                    stats.frames as usize,
                    items.iter().filter(|i| i.is_ok()).count()
                );
                prop_assert_eq!(stats.dropped_bytes + stats.frame_bytes, bytes.len() as u64);
                Ok(())
            })
            .unwrap();
    }
}
