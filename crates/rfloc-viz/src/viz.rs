//! The publisher.

use std::fmt;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rfloc_pose::{Pose2, PoseEstimate};

use crate::channels::Ch;
use crate::convert;
use crate::event::{
    Direction, Landmark, LandmarkKind, LogLevel, Particle, RangeScan, TargetEstimate, VizEvent,
};
use crate::hub::Hub;
use crate::live::{self, LiveServer};
use crate::record::{self, Recording};
use crate::Stamp;

/// Default number of messages queued per live client.
pub const DEFAULT_BACKLOG: usize = 1024;

/// Errors of starting or stopping a sink, and of times.
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// A time that is not a Unix time Foxglove can hold (negative, not finite, after 2106).
    #[error("time {0} s is not a Unix time in 1970..2106")]
    InvalidTime(f64),
    /// The live server could not listen (the address is taken, say).
    #[error("live server on {addr}: {source}")]
    Serve {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    /// An MCAP file could not be created (it exists, say), written or closed.
    #[error("MCAP recording {path}: {source}")]
    Record {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Publishes rfloc's robot data on the Foxglove channels of [`crate::topics`] to every sink
/// attached: live WebSocket clients ([`Viz::serve`]) and MCAP recordings ([`Viz::record`]).
///
/// Publishing never fails and never waits for a client. A message is built and encoded
/// (protobuf) only when some sink wants it (a recording is running, or a live client subscribed
/// to its channel), once, whatever the number of sinks. The live server queues it per client and
/// drops a slow client's oldest queued messages; a recording writes it into a buffered file on
/// the publishing thread. `Viz` is cheap to clone; clones publish to the same sinks.
#[derive(Clone)]
pub struct Viz {
    hub: Arc<Hub>,
}

impl fmt::Debug for Viz {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Viz").finish_non_exhaustive()
    }
}

impl Default for Viz {
    fn default() -> Self {
        Self::new()
    }
}

impl Viz {
    /// A publisher with every channel and no sink yet.
    #[must_use]
    pub fn new() -> Self {
        Self {
            hub: Arc::new(Hub::new()),
        }
    }

    /// Starts a live server on `addr` (port 0 picks a free port) in the current tokio runtime
    /// and returns once it listens. `backlog` is the number of messages queued per client
    /// (`None`: [`DEFAULT_BACKLOG`]); when a client's queue is full its oldest message goes.
    ///
    /// # Errors
    /// [`VizError::Serve`] when `addr` cannot be bound.
    pub async fn serve(
        &self,
        addr: SocketAddr,
        backlog: Option<usize>,
    ) -> Result<LiveServer, VizError> {
        live::start(&self.hub, addr, backlog.unwrap_or(DEFAULT_BACKLOG))
            .await
            .map_err(|source| VizError::Serve { addr, source })
    }

    /// Starts recording every channel into a new MCAP file at `path` (an existing file is not
    /// overwritten): protobuf messages in uncompressed chunks, the summary written by
    /// [`Recording::finish`].
    ///
    /// # Errors
    /// [`VizError::Record`] when the file exists or cannot be created.
    pub fn record(&self, path: impl AsRef<Path>) -> Result<Recording, VizError> {
        record::start(&self.hub, path.as_ref())
    }

    /// Publishes one event.
    pub fn publish(&self, event: &VizEvent) {
        match event {
            VizEvent::Pose { stamp, estimate } => self.pose(*stamp, estimate),
            VizEvent::Path { stamp, poses } => self.path(*stamp, poses),
            VizEvent::Transforms {
                stamp,
                map_pose,
                odom_pose,
            } => self.transforms(*stamp, map_pose, odom_pose),
            VizEvent::Target { stamp, target } => self.target(*stamp, target),
            VizEvent::Landmarks {
                stamp,
                kind,
                landmarks,
            } => self.landmarks(*stamp, *kind, landmarks),
            VizEvent::Particles { stamp, particles } => self.particles(*stamp, particles),
            VizEvent::Scan { stamp, scan } => self.scan(*stamp, scan),
            VizEvent::Status {
                stamp,
                device,
                level,
                message,
            } => self.status(*stamp, device, *level, message),
            VizEvent::LinkBytes {
                stamp,
                device,
                direction,
                bytes,
            } => self.link_bytes(*stamp, device, *direction, bytes),
            VizEvent::Observation {
                stamp,
                device,
                kind,
                json,
            } => self.observation(*stamp, device, kind, json),
        }
    }

    /// Whether anything would be sent for this kind of event now; lets a caller skip building
    /// a costly event (a large particle set) that nobody watches.
    #[must_use]
    pub fn is_watched(&self, topic: &str) -> bool {
        crate::topics::ALL
            .iter()
            .position(|t| *t == topic)
            .and_then(Ch::from_index)
            .is_some_and(|ch| self.hub.wants(ch))
    }

    /// The robot's pose estimate in `map` on [`crate::topics::POSE`],
    /// [`crate::topics::POSE_COVARIANCE`] and [`crate::topics::POSE_ELLIPSE`].
    /// `estimate.time` is not read: `stamp` is the time.
    pub fn pose(&self, stamp: Stamp, estimate: &PoseEstimate) {
        self.hub
            .deliver(Ch::Pose, stamp, || convert::pose_in_frame(stamp, estimate));
        self.hub.deliver(Ch::PoseCovariance, stamp, || {
            convert::odometry(stamp, estimate)
        });
        self.hub.deliver(Ch::PoseEllipse, stamp, || {
            convert::pose_ellipse(stamp, estimate)
        });
    }

    /// A path of poses in `map` on [`crate::topics::PATH`].
    pub fn path(&self, stamp: Stamp, poses: &[Pose2]) {
        self.hub
            .deliver(Ch::Path, stamp, || convert::path(stamp, poses));
    }

    /// The frames `map → odom → base_link` on [`crate::topics::TF`], from the robot's pose in
    /// `map` and its odometry pose in `odom` (`map → odom = map_pose ∘ odom_pose⁻¹`).
    pub fn transforms(&self, stamp: Stamp, map_pose: &Pose2, odom_pose: &Pose2) {
        self.hub.deliver(Ch::Tf, stamp, || {
            convert::transforms(stamp, map_pose, odom_pose)
        });
    }

    /// A target (emitter) estimate on [`crate::topics::TARGET`].
    pub fn target(&self, stamp: Stamp, target: &TargetEstimate) {
        self.hub
            .deliver(Ch::Target, stamp, || convert::target(stamp, target));
    }

    /// The whole beacon or tag map on [`crate::topics::BEACONS`] or [`crate::topics::TAGS`],
    /// replacing the one published before.
    pub fn landmarks(&self, stamp: Stamp, kind: LandmarkKind, landmarks: &[Landmark]) {
        let ch = match kind {
            LandmarkKind::Beacon => Ch::Beacons,
            LandmarkKind::Tag => Ch::Tags,
        };
        self.hub
            .deliver(ch, stamp, || convert::landmarks(stamp, kind, landmarks));
    }

    /// Particles in `map` on [`crate::topics::PARTICLES`].
    pub fn particles(&self, stamp: Stamp, particles: &[Particle]) {
        self.hub.deliver(Ch::Particles, stamp, || {
            convert::particles(stamp, particles)
        });
    }

    /// A range scan in `base_link` on [`crate::topics::SCAN`].
    pub fn scan(&self, stamp: Stamp, scan: &RangeScan) {
        self.hub
            .deliver(Ch::Scan, stamp, || convert::laser_scan(stamp, scan));
    }

    /// A device status line on [`crate::topics::STATUS`].
    pub fn status(&self, stamp: Stamp, device: &str, level: LogLevel, message: &str) {
        self.hub.deliver(Ch::Status, stamp, || {
            convert::log(stamp, device, level, message)
        });
    }

    /// Raw bytes of a device link on [`crate::topics::LINK`].
    pub fn link_bytes(&self, stamp: Stamp, device: &str, direction: Direction, bytes: &[u8]) {
        self.hub.deliver(Ch::Link, stamp, || {
            convert::link_bytes(stamp, device, direction, bytes)
        });
    }

    /// A decoded device observation: its kind (`odometry`, `hf_tag`, …) and the observation as
    /// one JSON object.
    pub fn observation(&self, stamp: Stamp, device: &str, kind: &str, json: &str) {
        self.hub.deliver(Ch::Observation, stamp, || {
            convert::observation(stamp, device, kind, json)
        });
    }
}
