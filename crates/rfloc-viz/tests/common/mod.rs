//! A recording with messages on every channel, shared by the MCAP tests.
#![allow(dead_code, clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Matrix2, Matrix3};
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};
use rfloc_viz::{
    topics, Direction, Landmark, LandmarkKind, LogLevel, Particle, RangeScan, Stamp,
    TargetEstimate, Viz, VizEvent,
};

/// Base time of the events: 2026-01-01T00:00:00Z.
pub const T0: u64 = 1_767_225_600_000_000_000;

pub fn stamp(ms: u64) -> Stamp {
    Stamp::from_unix_nanos(T0 + ms * 1_000_000)
}

pub fn estimate(i: u64) -> PoseEstimate {
    #[allow(clippy::cast_precision_loss)]
    let k = i as f64;
    PoseEstimate {
        time: 0.0,
        pose: Pose2::new(1.0 + k, 2.0 - k, 0.1 * k),
        covariance: Matrix3::new(0.04, 0.01, 0.0, 0.01, 0.09, 0.0, 0.0, 0.0, 0.01),
        mode: EstimateMode::Fix,
        source: "ekf".into(),
    }
}

/// The events, in time order: 3 poses (3 messages on each pose channel), 1 path, 2 transform
/// sets, 1 target, 1 beacon map, 1 tag map, 1 particle set, 4 scans, 2 status lines and 5 link
/// chunks.
pub fn events() -> Vec<VizEvent> {
    let mut out = Vec::new();
    for i in 0..3 {
        out.push(VizEvent::Pose {
            stamp: stamp(100 * i),
            estimate: estimate(i),
        });
    }
    out.push(VizEvent::Path {
        stamp: stamp(310),
        poses: (0..3).map(|i| estimate(i).pose).collect(),
    });
    for i in 0..2 {
        out.push(VizEvent::Transforms {
            stamp: stamp(320 + i),
            map_pose: estimate(i).pose,
            odom_pose: Pose2::new(0.5, 0.0, 0.05),
        });
    }
    out.push(VizEvent::Target {
        stamp: stamp(330),
        target: TargetEstimate {
            id: "emitter-1".into(),
            x: 20.0,
            y: 5.0,
            covariance: Matrix2::new(4.0, 1.0, 1.0, 2.0),
        },
    });
    for (kind, ms) in [(LandmarkKind::Beacon, 340), (LandmarkKind::Tag, 341)] {
        out.push(VizEvent::Landmarks {
            stamp: stamp(ms),
            kind,
            landmarks: vec![
                Landmark {
                    id: "a".into(),
                    x: 0.0,
                    y: 0.0,
                    covariance: None,
                },
                Landmark {
                    id: "b".into(),
                    x: 5.0,
                    y: 1.0,
                    covariance: Some(Matrix2::identity() * 0.01),
                },
            ],
        });
    }
    out.push(VizEvent::Particles {
        stamp: stamp(350),
        particles: (0..100)
            .map(|i| Particle {
                pose: Pose2::new(f64::from(i) * 0.01, 0.0, 0.0),
                weight: 0.01,
            })
            .collect(),
    });
    for i in 0..4 {
        out.push(VizEvent::Scan {
            stamp: stamp(400 + 100 * i),
            scan: RangeScan {
                mount: Pose2::new(0.2, 0.0, 0.0),
                start_angle: -2.0,
                end_angle: 2.0,
                ranges: vec![1.5; 681],
                intensities: Vec::new(),
            },
        });
    }
    out.push(VizEvent::Status {
        stamp: stamp(800),
        device: "urg".into(),
        level: LogLevel::Info,
        message: "connected".into(),
    });
    out.push(VizEvent::Status {
        stamp: stamp(900),
        device: "xbee".into(),
        level: LogLevel::Error,
        message: "stale".into(),
    });
    for i in 0..5u8 {
        out.push(VizEvent::LinkBytes {
            stamp: stamp(1000 + u64::from(i)),
            device: "urg".into(),
            direction: if i % 2 == 0 {
                Direction::Tx
            } else {
                Direction::Rx
            },
            bytes: vec![b'G', b'D', i, 0xff, 0x0a],
        });
    }
    out.push(VizEvent::Observation {
        stamp: stamp(1004),
        device: "hf".into(),
        kind: "hf_tag".into(),
        json: "{\"uid\":\"E00401503A5BD691\",\"rssi\":7}".into(),
    });
    out
}

/// Message count per topic of [`events`].
pub fn expected_counts() -> BTreeMap<&'static str, u64> {
    BTreeMap::from([
        (topics::POSE, 3),
        (topics::POSE_COVARIANCE, 3),
        (topics::POSE_ELLIPSE, 3),
        (topics::PATH, 1),
        (topics::TF, 2),
        (topics::TARGET, 1),
        (topics::BEACONS, 1),
        (topics::TAGS, 1),
        (topics::PARTICLES, 1),
        (topics::SCAN, 4),
        (topics::STATUS, 2),
        (topics::LINK, 5),
        (topics::OBSERVATION, 1),
    ])
}

/// Records [`events`] into a new MCAP file at `path`.
pub fn record_every_channel(path: &Path) {
    let viz = Viz::new();
    let recording = viz.record(path).unwrap();
    for e in events() {
        viz.publish(&e);
    }
    recording.finish().unwrap();
}
