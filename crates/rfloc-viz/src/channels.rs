//! The fixed channel table: topic, protobuf schema (name and `FileDescriptorSet`) of each.

use foxglove::messages::{
    FrameTransforms, LaserScan, Log, Odometry, PointCloud, PoseInFrame, PosesInFrame, SceneUpdate,
};
use foxglove::Encode;

use crate::convert::{LinkBytes, Observation};
use crate::topics;

/// Index of a channel in [`table`]; the protocol's channel id is this plus one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ch {
    Pose,
    PoseCovariance,
    PoseEllipse,
    Path,
    Tf,
    Target,
    Beacons,
    Tags,
    Particles,
    Scan,
    Status,
    Link,
    Observation,
}

impl Ch {
    const ALL: [Ch; 13] = [
        Ch::Pose,
        Ch::PoseCovariance,
        Ch::PoseEllipse,
        Ch::Path,
        Ch::Tf,
        Ch::Target,
        Ch::Beacons,
        Ch::Tags,
        Ch::Particles,
        Ch::Scan,
        Ch::Status,
        Ch::Link,
        Ch::Observation,
    ];

    pub(crate) fn index(self) -> usize {
        self as usize
    }

    pub(crate) fn from_index(i: usize) -> Option<Ch> {
        Self::ALL.get(i).copied()
    }
}

/// A channel as sinks advertise it.
#[derive(Debug, Clone)]
pub(crate) struct ChannelInfo {
    pub(crate) topic: &'static str,
    /// Always `protobuf`, for messages and schemas.
    pub(crate) encoding: String,
    pub(crate) schema_name: String,
    pub(crate) schema_encoding: String,
    /// A serialized `google.protobuf.FileDescriptorSet` that defines `schema_name`.
    pub(crate) schema: Vec<u8>,
}

fn info<T: Encode>(topic: &'static str) -> ChannelInfo {
    let schema = T::get_schema();
    ChannelInfo {
        topic,
        encoding: T::get_message_encoding(),
        schema_name: schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
        schema_encoding: schema
            .as_ref()
            .map(|s| s.encoding.clone())
            .unwrap_or_default(),
        schema: schema.map(|s| s.data.into_owned()).unwrap_or_default(),
    }
}

/// Every channel, in [`Ch`] order (which is [`topics::ALL`]'s).
pub(crate) fn table() -> Vec<ChannelInfo> {
    vec![
        info::<PoseInFrame>(topics::POSE),
        info::<Odometry>(topics::POSE_COVARIANCE),
        info::<SceneUpdate>(topics::POSE_ELLIPSE),
        info::<PosesInFrame>(topics::PATH),
        info::<FrameTransforms>(topics::TF),
        info::<SceneUpdate>(topics::TARGET),
        info::<SceneUpdate>(topics::BEACONS),
        info::<SceneUpdate>(topics::TAGS),
        info::<PointCloud>(topics::PARTICLES),
        info::<LaserScan>(topics::SCAN),
        info::<Log>(topics::STATUS),
        info::<LinkBytes>(topics::LINK),
        info::<Observation>(topics::OBSERVATION),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_follows_the_topic_list_and_every_channel_has_a_protobuf_schema() {
        let t = table();
        let topics: Vec<_> = t.iter().map(|c| c.topic).collect();
        assert_eq!(topics, topics::ALL);
        for (i, ch) in Ch::ALL.iter().enumerate() {
            assert_eq!(ch.index(), i);
            assert_eq!(Ch::from_index(i), Some(*ch));
        }
        assert_eq!(t[Ch::Link.index()].topic, topics::LINK);
        assert_eq!(t[Ch::Scan.index()].schema_name, "foxglove.LaserScan");
        assert_eq!(t[Ch::Link.index()].schema_name, "linkbytes.LinkBytes");
        for c in &t {
            assert_eq!(c.encoding, "protobuf", "{}", c.topic);
            assert_eq!(c.schema_encoding, "protobuf", "{}", c.topic);
            assert!(!c.schema.is_empty(), "{}", c.topic);
        }
    }
}
