//! MCAP recordings read back with the `mcap` crate's reader: summary, schemas, channels,
//! message counts, log times and decoded messages.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::collections::BTreeMap;

use foxglove::messages::{FrameTransforms, LaserScan, Log, Odometry, PoseInFrame};
use foxglove::Decode;
use rfloc_viz::{map_to_odom, topics, Viz, VizError, UNKNOWN_VARIANCE};

#[test]
fn every_channel_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    common::record_every_channel(&path);
    let bytes = std::fs::read(&path).unwrap();

    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    let stats = summary.stats.as_ref().expect("statistics");
    let expected = common::expected_counts();
    assert_eq!(stats.message_count, expected.values().sum::<u64>());
    assert_eq!(stats.channel_count, 13);
    // SceneUpdate serves four channels: ten distinct schemas.
    assert_eq!(stats.schema_count, 10);
    assert_eq!(stats.message_start_time, common::T0);
    assert_eq!(stats.message_end_time, common::stamp(1004).unix_nanos());

    let mut counts = BTreeMap::new();
    for (id, channel) in &summary.channels {
        let schema = channel.schema.as_ref().expect("every channel has a schema");
        assert_eq!(channel.message_encoding, "protobuf", "{}", channel.topic);
        assert_eq!(schema.encoding, "protobuf", "{}", channel.topic);
        assert!(!schema.data.is_empty());
        let expected_schema = match channel.topic.as_str() {
            topics::POSE => "foxglove.PoseInFrame",
            topics::POSE_COVARIANCE => "foxglove.Odometry",
            topics::POSE_ELLIPSE | topics::TARGET | topics::BEACONS | topics::TAGS => {
                "foxglove.SceneUpdate"
            }
            topics::PATH => "foxglove.PosesInFrame",
            topics::TF => "foxglove.FrameTransforms",
            topics::PARTICLES => "foxglove.PointCloud",
            topics::SCAN => "foxglove.LaserScan",
            topics::STATUS => "foxglove.Log",
            topics::LINK => "linkbytes.LinkBytes",
            topics::OBSERVATION => "observation.Observation",
            other => panic!("unexpected channel {other}"),
        };
        assert_eq!(schema.name, expected_schema, "{}", channel.topic);
        let n = stats.channel_message_counts.get(id).copied().unwrap_or(0);
        counts.insert(channel.topic.as_str(), n);
    }
    let expected_str: BTreeMap<&str, u64> = expected.iter().map(|(k, v)| (*k, *v)).collect();
    assert_eq!(counts, expected_str);

    // Read every message: per-channel sequence numbers, log time = publish time = the stamp.
    let mut seen: BTreeMap<String, Vec<u32>> = BTreeMap::new();
    let mut poses = Vec::new();
    let mut last_time = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.log_time, m.publish_time);
        assert!(m.log_time >= last_time, "messages in time order");
        last_time = m.log_time;
        seen.entry(m.channel.topic.clone())
            .or_default()
            .push(m.sequence);
        match m.channel.topic.as_str() {
            topics::POSE => {
                let p = PoseInFrame::decode(&m.data[..]).unwrap();
                assert_eq!(p.timestamp.unwrap().total_nanos(), m.log_time);
                poses.push(p);
            }
            topics::POSE_COVARIANCE => {
                let o = Odometry::decode(&m.data[..]).unwrap();
                let c = &o.pose_covariance;
                assert_eq!(c.len(), 36);
                assert_eq!(
                    (c[0], c[1], c[6], c[7], c[35]),
                    (0.04, 0.01, 0.01, 0.09, 0.01)
                );
                assert_eq!(
                    (c[14], c[21], c[28]),
                    (UNKNOWN_VARIANCE, UNKNOWN_VARIANCE, UNKNOWN_VARIANCE)
                );
            }
            topics::TF => {
                let tf = FrameTransforms::decode(&m.data[..]).unwrap();
                let frames: Vec<_> = tf
                    .transforms
                    .iter()
                    .map(|t| (t.parent_frame_id.as_str(), t.child_frame_id.as_str()))
                    .collect();
                assert_eq!(frames, [("map", "odom"), ("odom", "base_link")]);
                if m.sequence == 0 {
                    let expected = map_to_odom(
                        &common::estimate(0).pose,
                        &rfloc_pose::Pose2::new(0.5, 0.0, 0.05),
                    );
                    let t = tf.transforms[0].translation.unwrap();
                    assert!((t.x - expected.x).abs() < 1e-12 && (t.y - expected.y).abs() < 1e-12);
                }
            }
            topics::SCAN => {
                let s = LaserScan::decode(&m.data[..]).unwrap();
                assert_eq!(s.frame_id, "base_link");
                assert_eq!(s.ranges.len(), 681);
                assert_eq!((s.start_angle, s.end_angle), (-2.0, 2.0));
                assert_eq!(s.pose.unwrap().position.unwrap().x, 0.2);
            }
            topics::STATUS => {
                let l = Log::decode(&m.data[..]).unwrap();
                assert!(matches!(l.name.as_str(), "urg" | "xbee"));
            }
            topics::LINK => {
                // The custom message: the raw bytes travel verbatim in its `data` field.
                let i = u8::try_from(m.sequence).unwrap();
                let raw = [b'G', b'D', i, 0xff, 0x0a];
                assert!(
                    m.data.windows(5).any(|w| w == raw),
                    "link bytes {:?}",
                    m.data
                );
                assert!(m.data.windows(3).any(|w| w == b"urg"));
            }
            _ => {}
        }
    }
    for (topic, sequences) in &seen {
        let n = u32::try_from(sequences.len()).unwrap();
        assert_eq!(*sequences, (0..n).collect::<Vec<_>>(), "{topic}");
    }
    assert_eq!(poses.len(), 3);
    let p = poses[2].pose.unwrap().position.unwrap();
    assert_eq!((p.x, p.y), (3.0, 0.0));
    assert_eq!(poses[2].frame_id, "map");
}

#[test]
fn a_silent_recording_still_lists_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("silent.mcap");
    let viz = Viz::new();
    let recording = viz.record(&path).unwrap();
    assert_eq!(recording.path(), path);
    assert!(
        viz.is_watched(topics::PARTICLES),
        "a recording wants every channel"
    );
    assert_eq!(recording.finish().unwrap(), path);
    assert!(!viz.is_watched(topics::PARTICLES));
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let mut topics: Vec<_> = summary.channels.values().map(|c| c.topic.clone()).collect();
    topics.sort();
    let mut all: Vec<_> = topics::ALL.iter().map(|t| (*t).to_string()).collect();
    all.sort();
    assert_eq!(topics, all);
    assert_eq!(summary.stats.unwrap().message_count, 0);
}

#[test]
fn two_recordings_at_once_and_no_overwriting() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.mcap"), dir.path().join("b.mcap"));
    let viz = Viz::new();
    let ra = viz.record(&a).unwrap();
    viz.pose(common::stamp(0), &common::estimate(0));
    let rb = viz.record(&b).unwrap();
    viz.pose(common::stamp(1), &common::estimate(1));
    rb.flush().unwrap();
    drop(rb); // dropping finishes the file too
    ra.finish().unwrap();
    let count = |p: &std::path::Path| {
        let bytes = std::fs::read(p).unwrap();
        mcap::Summary::read(&bytes)
            .unwrap()
            .unwrap()
            .stats
            .unwrap()
            .message_count
    };
    assert_eq!((count(&a), count(&b)), (6, 3));

    let before = std::fs::read(&a).unwrap();
    match viz.record(&a) {
        Err(VizError::Record { path, source }) => {
            assert_eq!(path, a);
            assert_eq!(source.kind(), std::io::ErrorKind::AlreadyExists);
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert_eq!(
        std::fs::read(&a).unwrap(),
        before,
        "the existing file is untouched"
    );
}
