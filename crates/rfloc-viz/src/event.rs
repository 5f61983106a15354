//! What the daemon publishes: one [`VizEvent`] per message (or group of messages) on the
//! channels of [`crate::topics`].

use nalgebra::Matrix2;
use rfloc_pose::{Pose2, PoseEstimate};

use crate::Stamp;

/// Severity of a device status line (the levels of `foxglove.Log`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LogLevel {
    Debug,
    Info,
    Warning,
    Error,
    Fatal,
}

/// Which way bytes crossed a device link, seen from the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, foxglove::Encode)]
pub enum Direction {
    /// Received from the device.
    Rx,
    /// Sent to the device.
    Tx,
}

/// Which map a set of [`Landmark`]s belongs to; each has its own channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LandmarkKind {
    /// Radio beacons (drawn as cubes on [`crate::topics::BEACONS`]).
    Beacon,
    /// RFID tags (drawn as spheres on [`crate::topics::TAGS`]).
    Tag,
}

/// A mapped beacon or tag: its position in `map`, with an optional 2×2 position covariance
/// (x, y) in m², drawn as a 95 % ellipse when present.
#[derive(Debug, Clone, PartialEq)]
pub struct Landmark {
    /// Identifier shown as the label and used as the scene entity's id.
    pub id: String,
    pub x: f64,
    pub y: f64,
    pub covariance: Option<Matrix2<f64>>,
}

/// An estimate of a target (an emitter) in `map`: position, 2×2 position covariance in m²
/// (drawn as a 95 % ellipse) and a label.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetEstimate {
    /// Identifier of the target; one entity per id on [`crate::topics::TARGET`].
    pub id: String,
    pub x: f64,
    pub y: f64,
    pub covariance: Matrix2<f64>,
}

/// One weighted particle of a particle filter, a pose in `map`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Particle {
    pub pose: Pose2,
    pub weight: f64,
}

/// A planar range scan in the robot frame `base_link`: `ranges` (metres) at equally spaced
/// bearings from `start_angle` to `end_angle` (radians, counter-clockwise, 0 ahead of the
/// sensor), from a sensor mounted at `mount` in `base_link`.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeScan {
    pub mount: Pose2,
    pub start_angle: f64,
    pub end_angle: f64,
    pub ranges: Vec<f64>,
    /// Empty, or one intensity per range.
    pub intensities: Vec<f64>,
}

/// One thing to show, with its measurement time. [`crate::Viz::publish`] sends it to every
/// sink (live clients, MCAP recording); the `Viz` methods of the same names take the parts.
#[derive(Debug, Clone, PartialEq)]
pub enum VizEvent {
    /// The robot's pose estimate in `map`: [`crate::topics::POSE`] (`foxglove.PoseInFrame`),
    /// [`crate::topics::POSE_COVARIANCE`] (`foxglove.Odometry` with the 6×6 covariance) and
    /// [`crate::topics::POSE_ELLIPSE`] (`foxglove.SceneUpdate`). `estimate.time` is not read:
    /// `stamp` is the time.
    Pose {
        stamp: Stamp,
        estimate: PoseEstimate,
    },
    /// A path of poses in `map` ([`crate::topics::PATH`], `foxglove.PosesInFrame`).
    Path { stamp: Stamp, poses: Vec<Pose2> },
    /// The frame tree `map → odom → base_link` ([`crate::topics::TF`],
    /// `foxglove.FrameTransforms`) from the robot's pose in `map` and its odometry pose in
    /// `odom`: `map → odom = map_pose ∘ odom_pose⁻¹`, `odom → base_link = odom_pose`.
    Transforms {
        stamp: Stamp,
        map_pose: Pose2,
        odom_pose: Pose2,
    },
    /// A target (emitter) estimate ([`crate::topics::TARGET`], `foxglove.SceneUpdate`).
    Target {
        stamp: Stamp,
        target: TargetEstimate,
    },
    /// The whole beacon or tag map, replacing the previous one ([`crate::topics::BEACONS`] or
    /// [`crate::topics::TAGS`], `foxglove.SceneUpdate`).
    Landmarks {
        stamp: Stamp,
        kind: LandmarkKind,
        landmarks: Vec<Landmark>,
    },
    /// Particles of a particle filter in `map` ([`crate::topics::PARTICLES`],
    /// `foxglove.PointCloud`).
    Particles {
        stamp: Stamp,
        particles: Vec<Particle>,
    },
    /// A range scan in `base_link` ([`crate::topics::SCAN`], `foxglove.LaserScan`).
    Scan { stamp: Stamp, scan: RangeScan },
    /// A status line of a device ([`crate::topics::STATUS`], `foxglove.Log`, `name` = device).
    Status {
        stamp: Stamp,
        device: String,
        level: LogLevel,
        message: String,
    },
    /// Raw bytes that crossed a device link ([`crate::topics::LINK`], `linkbytes.LinkBytes`).
    LinkBytes {
        stamp: Stamp,
        device: String,
        direction: Direction,
        bytes: Vec<u8>,
    },
    /// A decoded device observation ([`crate::topics::OBSERVATION`], `observation.Observation`).
    Observation {
        stamp: Stamp,
        device: String,
        kind: String,
        json: String,
    },
}

impl VizEvent {
    /// The measurement time of the event.
    #[must_use]
    pub fn stamp(&self) -> Stamp {
        match self {
            VizEvent::Pose { stamp, .. }
            | VizEvent::Path { stamp, .. }
            | VizEvent::Transforms { stamp, .. }
            | VizEvent::Target { stamp, .. }
            | VizEvent::Landmarks { stamp, .. }
            | VizEvent::Particles { stamp, .. }
            | VizEvent::Scan { stamp, .. }
            | VizEvent::Status { stamp, .. }
            | VizEvent::LinkBytes { stamp, .. }
            | VizEvent::Observation { stamp, .. } => *stamp,
        }
    }
}
