//! The pose stream's messages: one JSON object per line, tagged by `class` (`VERSION`, `POSE`,
//! `TARGET`, `DEVICE`). The same types serialize on the server and deserialize in
//! `rfloc watch` and the tests.
//!
//! Numbers are rounded before they are written: metres to `precision` fraction digits, radians
//! and quaternions to two more, covariances to 4 significant digits, stamps to the microsecond.
//! An estimate with a non-finite value is never written (the caller counts and logs it).

use rfloc_pose::{EstimateMode, PoseEstimate};
use serde::{Deserialize, Serialize};

pub use crate::events::DeviceState;
use crate::pipeline::TargetEstimate;
use crate::time::TimeOrigin;

/// Protocol version of the pose stream.
pub const PROTO_MAJOR: u32 = 1;
/// Minor version: 1 added TARGET; 2 made `stamp` the measurement time in Unix seconds; 3 added
/// the odometry frames (`odom`, `map_odom`), `null` positions of `no_fix` poses, the requests
/// (`?WATCH`, `?DEVICES`, `?POLL`) and DEVICE `counters`.
pub const PROTO_MINOR: u32 = 3;

/// One line of the pose stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "class")]
pub enum Message {
    #[serde(rename = "VERSION")]
    Version(Version),
    #[serde(rename = "POSE")]
    Pose(Pose),
    #[serde(rename = "TARGET")]
    Target(Target),
    #[serde(rename = "DEVICE")]
    Device(Device),
}

impl Message {
    /// The message as one JSON line (without the newline).
    #[must_use]
    pub fn to_line(&self) -> String {
        // Serializing these plain structs cannot fail.
        serde_json::to_string(self).unwrap_or_default()
    }

    /// Parses one line.
    pub fn from_line(line: &str) -> Result<Self, serde_json::Error> {
        serde_json::from_str(line)
    }
}

/// `VERSION`: sent first to every client.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Version {
    pub release: String,
    pub proto_major: u32,
    pub proto_minor: u32,
}

impl Version {
    /// This build's version.
    #[must_use]
    pub fn current() -> Self {
        Self {
            release: env!("CARGO_PKG_VERSION").into(),
            proto_major: PROTO_MAJOR,
            proto_minor: PROTO_MINOR,
        }
    }
}

/// `POSE`: the robot's pose with covariance, at the time of the measurement it includes last.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// The measurement time, ISO 8601 UTC.
    pub time: String,
    /// The measurement time, Unix seconds.
    pub stamp: f64,
    pub frame_id: String,
    pub child_frame_id: String,
    /// `fix`, `degraded` or `no_fix`.
    pub mode: String,
    /// Position and heading in `frame_id`; `null` when `mode` is `no_fix` (there is none).
    pub x: Option<f64>,
    pub y: Option<f64>,
    pub yaw: Option<f64>,
    /// x, y, z, w; `null` with the position.
    pub quaternion: Option<[f64; 4]>,
    /// 6×6 row-major, ROS order (x y z roll pitch yaw). Never all zero unless the pose is known
    /// exactly: a `degraded` pose carries at least 1 cm and 0.01 rad standard deviations.
    pub cov: Vec<f64>,
    /// The robot in the odometry frame (`odom → base_link`: x, y, yaw), when the robot has
    /// odometry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom: Option<[f64; 3]>,
    /// The correction `map → odom` (x, y, yaw) that puts the odometry pose at this pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_odom: Option<[f64; 3]>,
    pub source: String,
}

/// `TARGET`: something the robot tracks besides itself (the emitter it homes on).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Target {
    pub time: String,
    pub stamp: f64,
    pub frame_id: String,
    pub id: String,
    pub x: f64,
    pub y: f64,
    /// Position covariance xx, xy, yy (m²).
    pub cov: [f64; 3],
    /// The unfiltered position of the same update.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw: Option<[f64; 2]>,
    pub source: String,
}

/// `DEVICE`: a device link changed state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Device {
    /// When the change was seen, ISO 8601 UTC.
    pub time: String,
    pub name: String,
    pub driver: String,
    pub state: String,
    pub detail: String,
    /// Error counters of the link (malformed lines, dropped bytes …), when it reports any.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub counters: std::collections::BTreeMap<String, u64>,
}

/// Frames, time origin and precision of POSE and TARGET messages.
#[derive(Debug, Clone)]
pub struct PoseFormat {
    pub frame_id: String,
    pub child_frame_id: String,
    /// Fraction digits for metres; radians and quaternions get two more.
    pub precision: usize,
    /// The instant the run clock (estimate times) reads zero.
    pub origin: TimeOrigin,
}

/// Why an estimate cannot be written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("estimate has a non-finite {0}")]
pub struct NonFinite(pub &'static str);

fn mode_name(mode: EstimateMode) -> &'static str {
    match mode {
        EstimateMode::NoFix => "no_fix",
        EstimateMode::Degraded => "degraded",
        EstimateMode::Fix => "fix",
    }
}

/// `v` rounded to `digits` fraction digits (the nearest double of the decimal text, so it
/// prints as that text).
fn fixed(v: f64, digits: usize) -> f64 {
    format!("{v:.digits$}").parse().unwrap_or(v)
}

/// `v` rounded to `digits` significant digits.
fn significant(v: f64, digits: usize) -> f64 {
    let d = digits.saturating_sub(1);
    format!("{v:.d$e}").parse().unwrap_or(v)
}

/// Smallest variance of a degraded pose's x, y and yaw: (1 cm)², (0.01 rad)².
const DEGRADED_VARIANCE_FLOOR: f64 = 1e-4;

/// The POSE message of an estimate; `odom` is the robot's latest odometry pose, when it has one.
pub fn pose(est: &PoseEstimate, fmt: &PoseFormat) -> Result<Pose, NonFinite> {
    pose_with_odometry(est, None, fmt)
}

/// [`pose`] with the odometry frames.
pub fn pose_with_odometry(
    est: &PoseEstimate,
    odom: Option<&rfloc_pose::Pose2>,
    fmt: &PoseFormat,
) -> Result<Pose, NonFinite> {
    let p = &est.pose;
    if !p.x.is_finite() || !p.y.is_finite() {
        return Err(NonFinite("position"));
    }
    if !p.theta.is_finite() {
        return Err(NonFinite("heading"));
    }
    if !est.time.is_finite() {
        return Err(NonFinite("time"));
    }
    let mut cov = est.ros_covariance();
    if cov.iter().any(|v| !v.is_finite()) {
        return Err(NonFinite("covariance"));
    }
    if est.mode == EstimateMode::Degraded {
        // A degraded pose is never reported as certain.
        for i in [0, 7, 35] {
            if let Some(v) = cov.get_mut(i) {
                *v = v.max(DEGRADED_VARIANCE_FLOOR);
            }
        }
    }
    let pm = fmt.precision.min(12);
    let pr = pm + 2;
    let q = est.quaternion();
    let known = est.mode != EstimateMode::NoFix;
    let frame = |p: &rfloc_pose::Pose2| [fixed(p.x, pm), fixed(p.y, pm), fixed(p.theta, pr)];
    let odom = odom.filter(|o| o.is_finite());
    let map_odom = odom
        .filter(|_| known)
        .map(|o| {
            est.pose
                .compose(&rfloc_pose::Pose2::default().relative_to(o))
        })
        .filter(rfloc_pose::Pose2::is_finite);
    Ok(Pose {
        time: fmt.origin.iso8601(est.time),
        stamp: fixed(fmt.origin.stamp(est.time), 6),
        frame_id: fmt.frame_id.clone(),
        child_frame_id: fmt.child_frame_id.clone(),
        mode: mode_name(est.mode).into(),
        x: known.then(|| fixed(p.x, pm)),
        y: known.then(|| fixed(p.y, pm)),
        yaw: known.then(|| fixed(p.theta, pr)),
        quaternion: known.then(|| q.map(|v| fixed(v, pr))),
        cov: cov.iter().map(|v| significant(*v, 4)).collect(),
        odom: odom.map(frame),
        map_odom: map_odom.as_ref().map(frame),
        source: est.source.to_string(),
    })
}

/// The TARGET message of a target estimate (`raw` only when finite).
pub fn target(t: &TargetEstimate, fmt: &PoseFormat) -> Result<Target, NonFinite> {
    if !(t.x.is_finite() && t.y.is_finite()) {
        return Err(NonFinite("position"));
    }
    if !t.time.is_finite() {
        return Err(NonFinite("time"));
    }
    if t.cov.iter().any(|v| !v.is_finite()) {
        return Err(NonFinite("covariance"));
    }
    let pm = fmt.precision.min(12);
    Ok(Target {
        time: fmt.origin.iso8601(t.time),
        stamp: fixed(fmt.origin.stamp(t.time), 6),
        frame_id: fmt.frame_id.clone(),
        id: t.id.into(),
        x: fixed(t.x, pm),
        y: fixed(t.y, pm),
        cov: t.cov.map(|v| significant(v, 4)),
        raw: t
            .raw
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| [fixed(x, pm), fixed(y, pm)]),
        source: t.source.into(),
    })
}

/// One POSE line.
pub fn pose_json(est: &PoseEstimate, fmt: &PoseFormat) -> Result<String, NonFinite> {
    pose(est, fmt).map(|p| Message::Pose(p).to_line())
}

/// One POSE line with the odometry frames.
pub fn pose_json_with_odometry(
    est: &PoseEstimate,
    odom: Option<&rfloc_pose::Pose2>,
    fmt: &PoseFormat,
) -> Result<String, NonFinite> {
    pose_with_odometry(est, odom, fmt).map(|p| Message::Pose(p).to_line())
}

/// One TARGET line.
pub fn target_json(t: &TargetEstimate, fmt: &PoseFormat) -> Result<String, NonFinite> {
    target(t, fmt).map(|t| Message::Target(t).to_line())
}

/// The `VERSION` line sent first to every client.
#[must_use]
pub fn version_json() -> String {
    Message::Version(Version::current()).to_line()
}

/// One DEVICE line.
#[must_use]
pub fn device_json(
    name: &str,
    driver: &str,
    state: DeviceState,
    detail: &str,
    wall: std::time::SystemTime,
) -> String {
    device_json_with_counters(name, driver, state, detail, &[], wall)
}

/// One DEVICE line with the link's error counters.
#[must_use]
pub fn device_json_with_counters(
    name: &str,
    driver: &str,
    state: DeviceState,
    detail: &str,
    counters: &[(&str, u64)],
    wall: std::time::SystemTime,
) -> String {
    Message::Device(Device {
        time: crate::time::iso8601(wall),
        name: name.into(),
        driver: driver.into(),
        state: state.as_str().into(),
        detail: detail.into(),
        counters: counters
            .iter()
            .map(|(k, v)| ((*k).to_string(), *v))
            .collect(),
    })
    .to_line()
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::panic)]
mod tests {
    use std::time::{Duration, UNIX_EPOCH};

    use nalgebra::Matrix3;
    use rfloc_pose::Pose2;

    use super::*;

    fn fmt() -> PoseFormat {
        PoseFormat {
            frame_id: "map".into(),
            child_frame_id: "base_link".into(),
            precision: 3,
            origin: TimeOrigin::from_unix_ns(1_795_255_200_000_000_000),
        }
    }

    fn est() -> PoseEstimate {
        PoseEstimate {
            time: 0.123,
            pose: Pose2::new(1.23456, -2.0, std::f64::consts::FRAC_PI_2),
            covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(0.01, 0.02, 0.003)),
            mode: EstimateMode::Fix,
            source: "test".into(),
        }
    }

    #[test]
    fn pose_line_is_json_with_the_measurement_time_and_rounded_numbers() {
        let line = pose_json(&est(), &fmt()).unwrap();
        let Message::Pose(p) = Message::from_line(&line).unwrap() else {
            panic!("{line}");
        };
        assert_eq!(p.mode, "fix");
        assert_eq!(p.time, "2026-11-21T10:00:00.123Z");
        assert!((p.stamp - 1_795_255_200.123).abs() < 1e-6, "{}", p.stamp);
        assert!(line.contains("\"x\":1.235,"), "{line}");
        assert!(line.contains("\"yaw\":1.5708,"), "{line}");
        assert_eq!(p.cov.len(), 36);
        assert_eq!((p.cov[0], p.cov[7], p.cov[35]), (0.01, 0.02, 0.003));
        assert!((p.quaternion.unwrap()[3] - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-4);
        let _ = Duration::ZERO;
        let _ = UNIX_EPOCH;
    }

    #[test]
    fn no_fix_has_no_position_and_degraded_is_never_certain() {
        let mut e = est();
        e.mode = EstimateMode::NoFix;
        let line = pose_json(&e, &fmt()).unwrap();
        assert!(
            line.contains("\"x\":null,\"y\":null,\"yaw\":null,\"quaternion\":null"),
            "{line}"
        );
        let mut e = est();
        e.mode = EstimateMode::Degraded;
        e.covariance = nalgebra::Matrix3::zeros();
        let Message::Pose(p) = Message::from_line(&pose_json(&e, &fmt()).unwrap()).unwrap() else {
            panic!();
        };
        assert_eq!((p.cov[0], p.cov[7], p.cov[35]), (1e-4, 1e-4, 1e-4));
    }

    #[test]
    fn the_odometry_frames_put_the_odometry_pose_at_the_estimate() {
        let e = est(); // (1.23456, -2, 90°)
        let odom = Pose2::new(1.0, 0.0, 0.0);
        let Message::Pose(p) =
            Message::from_line(&pose_json_with_odometry(&e, Some(&odom), &fmt()).unwrap()).unwrap()
        else {
            panic!();
        };
        assert_eq!(p.odom, Some([1.0, 0.0, 0.0]));
        let [x, y, yaw] = p.map_odom.unwrap();
        // map → odom ∘ odom → base_link = map → base_link.
        let back = Pose2::new(x, y, yaw).compose(&odom);
        assert!(
            (back.x - 1.235).abs() < 2e-3 && (back.y + 2.0).abs() < 2e-3,
            "{back:?}"
        );
    }

    #[test]
    fn non_finite_estimates_are_refused() {
        let mut e = est();
        e.pose.x = f64::NAN;
        assert_eq!(pose_json(&e, &fmt()), Err(NonFinite("position")));
        let mut e = est();
        e.covariance[(2, 2)] = f64::INFINITY;
        assert_eq!(pose_json(&e, &fmt()), Err(NonFinite("covariance")));
    }

    #[test]
    fn target_line_carries_position_covariance_and_raw_fix() {
        let mut t = TargetEstimate {
            time: 14.8,
            id: "emitter",
            x: 3.95123,
            y: -0.0431,
            cov: [0.0211, -0.0012, 0.0195],
            raw: Some((3.881, 0.1702)),
            source: "emitter",
        };
        let line = target_json(&t, &fmt()).unwrap();
        assert!(line.starts_with("{\"class\":\"TARGET\""), "{line}");
        assert!(line.contains("\"x\":3.951,\"y\":-0.043,"), "{line}");
        assert!(line.contains("\"raw\":[3.881,0.17]"), "{line}");
        let Message::Target(back) = Message::from_line(&line).unwrap() else {
            panic!("{line}");
        };
        assert_eq!(back.cov, [0.0211, -0.0012, 0.0195]);
        assert_eq!(back.time, "2026-11-21T10:00:14.800Z");
        t.raw = None;
        let line = target_json(&t, &fmt()).unwrap();
        assert!(!line.contains("raw"), "{line}");
        t.cov[1] = f64::NAN;
        assert_eq!(target_json(&t, &fmt()), Err(NonFinite("covariance")));
    }

    #[test]
    fn device_line_escapes_text() {
        let line = device_json(
            "hf \"1\"",
            "kts",
            DeviceState::Stale,
            "silent 3.0 s\u{1}",
            std::time::UNIX_EPOCH,
        );
        let Message::Device(d) = Message::from_line(&line).unwrap() else {
            panic!("{line}");
        };
        assert_eq!(d.name, "hf \"1\"");
        assert_eq!(d.state, "stale");
        assert_eq!(d.detail, "silent 3.0 s\u{1}");
        assert_eq!(d.time, "1970-01-01T00:00:00.000Z");
    }
}
