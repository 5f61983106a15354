//! Channel topics and frame names.
//!
//! | topic | schema | frame |
//! | --- | --- | --- |
//! | [`POSE`] | `foxglove.PoseInFrame` | `map` |
//! | [`POSE_COVARIANCE`] | `foxglove.Odometry` | `map` → `base_link` |
//! | [`POSE_ELLIPSE`] | `foxglove.SceneUpdate` | `map` |
//! | [`PATH`] | `foxglove.PosesInFrame` | `map` |
//! | [`TF`] | `foxglove.FrameTransforms` | `map` → `odom` → `base_link` |
//! | [`TARGET`] | `foxglove.SceneUpdate` | `map` |
//! | [`BEACONS`] | `foxglove.SceneUpdate` | `map` |
//! | [`TAGS`] | `foxglove.SceneUpdate` | `map` |
//! | [`PARTICLES`] | `foxglove.PointCloud` | `map` |
//! | [`SCAN`] | `foxglove.LaserScan` | `base_link` |
//! | [`STATUS`] | `foxglove.Log` | — |
//! | [`LINK`] | `linkbytes.LinkBytes` | — |

/// The world frame.
pub const MAP: &str = "map";
/// The odometry frame: where dead reckoning alone puts the robot's start.
pub const ODOM: &str = "odom";
/// The robot frame.
pub const BASE_LINK: &str = "base_link";

pub const POSE: &str = "/rfloc/pose";
pub const POSE_COVARIANCE: &str = "/rfloc/pose/covariance";
pub const POSE_ELLIPSE: &str = "/rfloc/pose/ellipse";
pub const PATH: &str = "/rfloc/path";
pub const TF: &str = "/tf";
pub const TARGET: &str = "/rfloc/target";
pub const BEACONS: &str = "/rfloc/beacons";
pub const TAGS: &str = "/rfloc/tags";
pub const PARTICLES: &str = "/rfloc/particles";
pub const SCAN: &str = "/rfloc/scan";
pub const STATUS: &str = "/rfloc/status";
pub const LINK: &str = "/rfloc/link";
/// A decoded device observation (`observation.Observation`: time, device, kind and the observation as
/// JSON).
pub const OBSERVATION: &str = "/rfloc/observation";

/// Every topic, in the order of the table above.
pub const ALL: [&str; 13] = [
    POSE,
    POSE_COVARIANCE,
    POSE_ELLIPSE,
    PATH,
    TF,
    TARGET,
    BEACONS,
    TAGS,
    PARTICLES,
    SCAN,
    STATUS,
    LINK,
    OBSERVATION,
];
