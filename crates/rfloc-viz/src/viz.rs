//! The publisher and its sinks: a live Foxglove WebSocket server and MCAP recordings.

use std::fmt;
use std::fs::File;
use std::io::BufWriter;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use foxglove::messages::{
    FrameTransforms, LaserScan, Log, Odometry, PointCloud, PoseInFrame, PosesInFrame, SceneUpdate,
};
use foxglove::{
    Channel, Context, Encode, McapWriteOptions, McapWriterHandle, WebSocketServerHandle,
};
use rfloc_pose::{Pose2, PoseEstimate};

use crate::convert::{self, LinkBytes};
use crate::event::{
    Direction, Landmark, LandmarkKind, LogLevel, Particle, RangeScan, TargetEstimate, VizEvent,
};
use crate::{topics, Stamp};

/// Errors of starting or stopping a sink.
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// A time that is not a Unix time Foxglove can hold (negative, not finite, after 2106).
    #[error("time {0} s is not a Unix time in 1970..2106")]
    InvalidTime(f64),
    /// The live server could not start (the address is taken, say).
    #[error("live server on {addr}: {source}")]
    Serve {
        addr: SocketAddr,
        #[source]
        source: foxglove::FoxgloveError,
    },
    /// An MCAP file could not be created, written or closed.
    #[error("MCAP recording {path}: {source}")]
    Record {
        path: PathBuf,
        #[source]
        source: foxglove::FoxgloveError,
    },
}

struct Channels {
    pose: Channel<PoseInFrame>,
    pose_covariance: Channel<Odometry>,
    pose_ellipse: Channel<SceneUpdate>,
    path: Channel<PosesInFrame>,
    tf: Channel<FrameTransforms>,
    target: Channel<SceneUpdate>,
    beacons: Channel<SceneUpdate>,
    tags: Channel<SceneUpdate>,
    particles: Channel<PointCloud>,
    scan: Channel<LaserScan>,
    status: Channel<Log>,
    link: Channel<LinkBytes>,
}

struct Inner {
    // Channels and sinks belong to this context, not to the process-wide default one, so that
    // two `Viz` never mix.
    context: Arc<Context>,
    channels: Channels,
}

/// Publishes rfloc's robot data on Foxglove channels (see [`crate::topics`]) to every sink that
/// is attached: live WebSocket clients ([`Viz::serve`]) and MCAP files ([`Viz::record`]).
///
/// Publishing never fails and never waits for a client: a message is encoded once (protobuf)
/// and handed to each sink; the live server queues it per client and drops the oldest queued
/// messages of a client that does not keep up. A recording writes into a buffered file on the
/// publishing thread. With no sink attached (or no client subscribed to a channel), publishing
/// costs a check and nothing is encoded. `Viz` is cheap to clone; clones publish to the same
/// channels.
#[derive(Clone)]
pub struct Viz {
    inner: Arc<Inner>,
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

/// Log time = measurement time, for every channel.
fn send<T: Encode>(channel: &Channel<T>, stamp: Stamp, msg: &T) {
    channel.log_with_time(msg, stamp.unix_nanos());
}

impl Viz {
    /// A publisher with every channel of [`crate::topics`] and no sink yet.
    #[must_use]
    pub fn new() -> Self {
        let context = Context::new();
        let ch = |topic: &str| context.channel_builder(topic);
        let channels = Channels {
            pose: ch(topics::POSE).build(),
            pose_covariance: ch(topics::POSE_COVARIANCE).build(),
            pose_ellipse: ch(topics::POSE_ELLIPSE).build(),
            path: ch(topics::PATH).build(),
            tf: ch(topics::TF).build(),
            target: ch(topics::TARGET).build(),
            beacons: ch(topics::BEACONS).build(),
            tags: ch(topics::TAGS).build(),
            particles: ch(topics::PARTICLES).build(),
            scan: ch(topics::SCAN).build(),
            status: ch(topics::STATUS).build(),
            link: ch(topics::LINK).build(),
        };
        Self {
            inner: Arc::new(Inner { context, channels }),
        }
    }

    /// Starts a live Foxglove WebSocket server (subprotocol `foxglove.websocket.v1`) on `addr`
    /// (port 0 picks a free port) in the current tokio runtime, and returns once it listens.
    /// Clients see every channel advertised and receive the channels they subscribe to.
    /// `backlog` is the number of messages queued per client (the oldest go first when full);
    /// `None` takes the default of 1024.
    ///
    /// # Errors
    /// [`VizError::Serve`] when the address cannot be bound.
    pub async fn serve(
        &self,
        addr: SocketAddr,
        backlog: Option<usize>,
    ) -> Result<LiveServer, VizError> {
        let mut server = self
            .inner
            .context
            .websocket_server()
            .name("rfloc")
            .bind(addr.ip().to_string(), addr.port());
        if let Some(n) = backlog {
            server = server.message_backlog_size(n.max(1));
        }
        let handle = server
            .start()
            .await
            .map_err(|source| VizError::Serve { addr, source })?;
        Ok(LiveServer {
            local_addr: SocketAddr::new(addr.ip(), handle.port()),
            handle: Some(handle),
        })
    }

    /// Starts recording every channel into a new MCAP file at `path` (an existing file is not
    /// overwritten). Messages are protobuf, in chunks without compression.
    ///
    /// # Errors
    /// [`VizError::Record`] when the file exists or cannot be created.
    pub fn record(&self, path: impl AsRef<Path>) -> Result<Recording, VizError> {
        let path = path.as_ref().to_path_buf();
        let record_error = |source| VizError::Record {
            path: path.clone(),
            source,
        };
        let file = File::create_new(&path)
            .map_err(|e| record_error(foxglove::FoxgloveError::IoError(e)))?;
        let options = McapWriteOptions::new().compression(None).profile("rfloc");
        let handle = self
            .inner
            .context
            .mcap_writer_with_options(options)
            .create(BufWriter::new(file))
            .map_err(record_error)?;
        Ok(Recording {
            path,
            handle: Some(handle),
        })
    }

    /// Publishes one event to every sink.
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
        }
    }

    /// The robot's pose estimate in `map`, on [`topics::POSE`], [`topics::POSE_COVARIANCE`] and
    /// [`topics::POSE_ELLIPSE`]. `estimate.time` is not read: `stamp` is the time.
    pub fn pose(&self, stamp: Stamp, estimate: &PoseEstimate) {
        let ch = &self.inner.channels;
        if ch.pose.has_sinks() {
            send(&ch.pose, stamp, &convert::pose_in_frame(stamp, estimate));
        }
        if ch.pose_covariance.has_sinks() {
            send(
                &ch.pose_covariance,
                stamp,
                &convert::odometry(stamp, estimate),
            );
        }
        if ch.pose_ellipse.has_sinks() {
            send(
                &ch.pose_ellipse,
                stamp,
                &convert::pose_ellipse(stamp, estimate),
            );
        }
    }

    /// A path of poses in `map`, on [`topics::PATH`].
    pub fn path(&self, stamp: Stamp, poses: &[Pose2]) {
        let ch = &self.inner.channels.path;
        if ch.has_sinks() {
            send(ch, stamp, &convert::path(stamp, poses));
        }
    }

    /// The frames `map → odom → base_link` on [`topics::TF`], from the robot's pose in `map`
    /// and its odometry pose in `odom` (`map → odom = map_pose ∘ odom_pose⁻¹`).
    pub fn transforms(&self, stamp: Stamp, map_pose: &Pose2, odom_pose: &Pose2) {
        let ch = &self.inner.channels.tf;
        if ch.has_sinks() {
            send(ch, stamp, &convert::transforms(stamp, map_pose, odom_pose));
        }
    }

    /// A target (emitter) estimate on [`topics::TARGET`].
    pub fn target(&self, stamp: Stamp, target: &TargetEstimate) {
        let ch = &self.inner.channels.target;
        if ch.has_sinks() {
            send(ch, stamp, &convert::target(stamp, target));
        }
    }

    /// The whole beacon or tag map on [`topics::BEACONS`] or [`topics::TAGS`], replacing the
    /// one published before.
    pub fn landmarks(&self, stamp: Stamp, kind: LandmarkKind, landmarks: &[Landmark]) {
        let ch = match kind {
            LandmarkKind::Beacon => &self.inner.channels.beacons,
            LandmarkKind::Tag => &self.inner.channels.tags,
        };
        if ch.has_sinks() {
            send(ch, stamp, &convert::landmarks(stamp, kind, landmarks));
        }
    }

    /// Particles in `map` on [`topics::PARTICLES`].
    pub fn particles(&self, stamp: Stamp, particles: &[Particle]) {
        let ch = &self.inner.channels.particles;
        if ch.has_sinks() {
            send(ch, stamp, &convert::particles(stamp, particles));
        }
    }

    /// A range scan in `base_link` on [`topics::SCAN`].
    pub fn scan(&self, stamp: Stamp, scan: &RangeScan) {
        let ch = &self.inner.channels.scan;
        if ch.has_sinks() {
            send(ch, stamp, &convert::laser_scan(stamp, scan));
        }
    }

    /// A device status line on [`topics::STATUS`].
    pub fn status(&self, stamp: Stamp, device: &str, level: LogLevel, message: &str) {
        let ch = &self.inner.channels.status;
        if ch.has_sinks() {
            send(ch, stamp, &convert::log(stamp, device, level, message));
        }
    }

    /// Raw bytes of a device link on [`topics::LINK`].
    pub fn link_bytes(&self, stamp: Stamp, device: &str, direction: Direction, bytes: &[u8]) {
        let ch = &self.inner.channels.link;
        if ch.has_sinks() {
            send(
                ch,
                stamp,
                &convert::link_bytes(stamp, device, direction, bytes),
            );
        }
    }
}

/// A running live server. Dropping it stops the server (clients are disconnected).
pub struct LiveServer {
    local_addr: SocketAddr,
    handle: Option<WebSocketServerHandle>,
}

impl fmt::Debug for LiveServer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LiveServer")
            .field("local_addr", &self.local_addr)
            .finish_non_exhaustive()
    }
}

impl LiveServer {
    /// The address the server listens on (with the port chosen when 0 was asked for).
    #[must_use]
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// The URL to give Foxglove's "Open connection → Foxglove WebSocket".
    #[must_use]
    pub fn url(&self) -> String {
        format!("ws://{}", self.local_addr)
    }

    /// How many clients are connected.
    #[must_use]
    pub fn client_count(&self) -> usize {
        self.handle
            .as_ref()
            .map_or(0, WebSocketServerHandle::client_count)
    }

    /// Stops the server and waits until its clients are closed.
    pub async fn stop(mut self) {
        if let Some(handle) = self.handle.take() {
            handle.stop().wait().await;
        }
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        if let Some(handle) = self.handle.take() {
            // Dropping the shutdown handle aborts the client tasks at once.
            drop(handle.stop());
        }
    }
}

/// A running MCAP recording. [`Recording::finish`] writes the summary and closes the file;
/// dropping it does the same but can only log a failure.
pub struct Recording {
    path: PathBuf,
    handle: Option<McapWriterHandle<BufWriter<File>>>,
}

impl fmt::Debug for Recording {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Recording")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl Recording {
    /// The file being written.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes buffered messages out (closing the current chunk), so that a reader of the file
    /// so far sees them.
    ///
    /// # Errors
    /// [`VizError::Record`] on a write error.
    pub fn flush(&self) -> Result<(), VizError> {
        match &self.handle {
            Some(h) => h.flush().map_err(|source| VizError::Record {
                path: self.path.clone(),
                source,
            }),
            None => Ok(()),
        }
    }

    /// Stops recording, writes the MCAP summary (schemas, channels, statistics, indexes) and
    /// closes the file; returns its path.
    ///
    /// # Errors
    /// [`VizError::Record`] on a write error.
    pub fn finish(mut self) -> Result<PathBuf, VizError> {
        let path = std::mem::take(&mut self.path);
        if let Some(handle) = self.handle.take() {
            let writer = handle.close().map_err(|source| VizError::Record {
                path: path.clone(),
                source,
            })?;
            let file = writer.into_inner().map_err(|e| VizError::Record {
                path: path.clone(),
                source: foxglove::FoxgloveError::IoError(e.into_error()),
            })?;
            file.sync_all().map_err(|e| VizError::Record {
                path: path.clone(),
                source: foxglove::FoxgloveError::IoError(e),
            })?;
        }
        Ok(path)
    }
}
