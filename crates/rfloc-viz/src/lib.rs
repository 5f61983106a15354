//! rfloc's robot data as Foxglove channels: live over the Foxglove WebSocket protocol
//! (subprotocol `foxglove.websocket.v1`) and recorded into MCAP files.
//!
//! A [`Viz`] owns the channels of [`topics`]; [`Viz::serve`] attaches a live server and
//! [`Viz::record`] an MCAP recording (any number of each, at any time). The daemon publishes
//! [`VizEvent`]s, or calls the method of the same name, with the measurement time as a
//! [`Stamp`] (Unix nanoseconds); that time is both the message's `timestamp` and its log time.
//!
//! Every message is protobuf: the well-known Foxglove schemas (`foxglove.PoseInFrame`,
//! `foxglove.FrameTransforms`, …, from the `foxglove` crate) and one custom schema,
//! `linkbytes.LinkBytes`, for raw device bytes; each channel carries its schema as a protobuf
//! `FileDescriptorSet`, in the MCAP file and in the live `advertise` message alike.
//!
//! Frames: `map` (world), `odom` (odometry), `base_link` (robot). A planar pose covariance
//! (3×3 over x, y, yaw) is widened to Foxglove's 6×6 by [`covariance_6x6`].
#![forbid(unsafe_code)]

mod base64;
mod channels;
mod convert;
mod event;
mod hub;
mod live;
mod record;
mod stamp;
pub mod topics;
mod viz;

pub use convert::{
    covariance_6x6, map_to_odom, principal_axes, ELLIPSE_SIGMA_95, PARTICLE_STRIDE,
    UNKNOWN_VARIANCE,
};
pub use event::{
    Direction, Landmark, LandmarkKind, LogLevel, Particle, RangeScan, TargetEstimate, VizEvent,
};
pub use live::{LiveServer, CLIENT_QUEUE_BYTES, SUBPROTOCOLS};
pub use record::Recording;
pub use stamp::Stamp;
pub use viz::{Viz, VizError, DEFAULT_BACKLOG};
