//! rfloc values → Foxglove messages. Pure functions, so that every message can be checked
//! without a sink.

use foxglove::bytes::Bytes;
use foxglove::messages::{
    packed_element_field::NumericType, scene_entity_deletion, Color, CubePrimitive, FrameTransform,
    FrameTransforms, KeyValuePair, LaserScan, Log, Odometry, PackedElementField, PointCloud, Pose,
    PoseInFrame, PosesInFrame, Quaternion, SceneEntity, SceneEntityDeletion, SceneUpdate,
    SpherePrimitive, TextPrimitive, Timestamp, Vector3,
};
use nalgebra::{Matrix2, Matrix3};
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};

use crate::event::{
    Direction, Landmark, LandmarkKind, LogLevel, Particle, RangeScan, TargetEstimate,
};
use crate::topics::{BASE_LINK, MAP, ODOM};
use crate::Stamp;

/// The variance given to what a planar estimate does not know (z, roll, pitch, and all
/// velocities) in the 6×6 covariances: large, so that a reader treats them as unknown, rather
/// than zero, which would claim certainty.
pub const UNKNOWN_VARIANCE: f64 = 1.0e6;

/// Half-axis scale of a 95 % confidence ellipse of a 2-D Gaussian: √χ²₂(0.95) = √5.991.
pub const ELLIPSE_SIGMA_95: f64 = 2.447_746_830_680_816;

/// Thickness of the flat ellipsoids that draw position ellipses, metres.
const ELLIPSE_THICKNESS: f64 = 0.01;
/// Smallest drawn ellipse diameter, metres, so that a near-certain position stays visible.
const ELLIPSE_MIN_DIAMETER: f64 = 0.02;

/// A planar 3×3 covariance over (x, y, yaw) widened to the row-major 6×6 covariance of ROS and
/// Foxglove over (x, y, z, roll, pitch, yaw): the planar block goes to rows/columns 0, 1, 5;
/// z, roll and pitch get [`UNKNOWN_VARIANCE`] on the diagonal and zero correlation.
#[must_use]
pub fn covariance_6x6(planar: &Matrix3<f64>) -> [f64; 36] {
    let mut out = [0.0; 36];
    let index = [0usize, 1, 5];
    for (i, ri) in index.iter().enumerate() {
        for (j, rj) in index.iter().enumerate() {
            if let Some(slot) = out.get_mut(ri * 6 + rj) {
                *slot = planar[(i, j)];
            }
        }
    }
    for d in [2usize, 3, 4] {
        if let Some(slot) = out.get_mut(d * 6 + d) {
            *slot = UNKNOWN_VARIANCE;
        }
    }
    out
}

/// Standard deviations along the principal axes of a 2×2 covariance and the angle of the major
/// axis from +x: `(major_sd, minor_sd, angle)`. Negative eigenvalues (a matrix that is not quite
/// positive semi-definite) are taken as zero; a non-finite matrix gives `None`.
#[must_use]
pub fn principal_axes(cov: &Matrix2<f64>) -> Option<(f64, f64, f64)> {
    let (a, b, c) = (cov[(0, 0)], 0.5 * (cov[(0, 1)] + cov[(1, 0)]), cov[(1, 1)]);
    if !(a.is_finite() && b.is_finite() && c.is_finite()) {
        return None;
    }
    let mean = 0.5 * (a + c);
    let radius = (0.5 * (a - c)).hypot(b);
    let major = (mean + radius).max(0.0).sqrt();
    let minor = (mean - radius).max(0.0).sqrt();
    let angle = 0.5 * (2.0 * b).atan2(a - c);
    Some((major, minor, angle))
}

/// The map → odom transform from the robot's pose in `map` and its odometry pose in `odom`:
/// `map_pose ∘ odom_pose⁻¹`, so that `map_to_odom(m, o).compose(&o) == m`.
#[must_use]
pub fn map_to_odom(map_pose: &Pose2, odom_pose: &Pose2) -> Pose2 {
    let odom_inverse = Pose2::default().relative_to(odom_pose);
    map_pose.compose(&odom_inverse)
}

fn quaternion(theta: f64) -> Quaternion {
    let (s, c) = (0.5 * theta).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

fn vector(x: f64, y: f64, z: f64) -> Vector3 {
    Vector3 { x, y, z }
}

/// A planar pose as a Foxglove pose at z = 0, rotated about +z.
#[must_use]
pub(crate) fn pose3(p: &Pose2) -> Pose {
    Pose {
        position: Some(vector(p.x, p.y, 0.0)),
        orientation: Some(quaternion(p.theta)),
    }
}

fn at(x: f64, y: f64, z: f64) -> Pose {
    Pose {
        position: Some(vector(x, y, z)),
        orientation: Some(quaternion(0.0)),
    }
}

const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

const WHITE: Color = rgba(1.0, 1.0, 1.0, 1.0);
const TARGET_COLOR: Color = rgba(0.85, 0.2, 0.85, 1.0);
const TARGET_ELLIPSE: Color = rgba(0.85, 0.2, 0.85, 0.3);
const BEACON_COLOR: Color = rgba(0.2, 0.45, 0.95, 1.0);
const TAG_COLOR: Color = rgba(0.95, 0.8, 0.1, 1.0);
const LANDMARK_ELLIPSE: Color = rgba(0.5, 0.5, 0.5, 0.3);

/// Ellipse colour of a pose estimate: green with a fix, orange when degraded, red without.
fn mode_color(mode: EstimateMode) -> Color {
    match mode {
        EstimateMode::Fix => rgba(0.2, 0.8, 0.2, 0.35),
        EstimateMode::Degraded => rgba(1.0, 0.6, 0.0, 0.35),
        EstimateMode::NoFix => rgba(0.9, 0.1, 0.1, 0.35),
    }
}

fn mode_name(mode: EstimateMode) -> &'static str {
    match mode {
        EstimateMode::Fix => "fix",
        EstimateMode::Degraded => "degraded",
        EstimateMode::NoFix => "no_fix",
    }
}

/// A flat ellipsoid at `(x, y)` covering the 95 % region of a position covariance, or `None`
/// for a non-finite covariance.
fn ellipse(x: f64, y: f64, cov: &Matrix2<f64>, color: Color) -> Option<SpherePrimitive> {
    let (major, minor, angle) = principal_axes(cov)?;
    let d = |sd: f64| (2.0 * ELLIPSE_SIGMA_95 * sd).max(ELLIPSE_MIN_DIAMETER);
    Some(SpherePrimitive {
        pose: Some(pose3(&Pose2 { x, y, theta: angle })),
        size: Some(vector(d(major), d(minor), ELLIPSE_THICKNESS)),
        color: Some(color),
    })
}

fn label(x: f64, y: f64, text: String) -> TextPrimitive {
    TextPrimitive {
        pose: Some(at(x, y, 0.3)),
        billboard: true,
        font_size: 14.0,
        scale_invariant: true,
        color: Some(WHITE),
        text,
    }
}

fn entity(stamp: Stamp, id: String) -> SceneEntity {
    SceneEntity {
        timestamp: Some(stamp.timestamp()),
        frame_id: MAP.to_string(),
        id,
        ..SceneEntity::default()
    }
}

fn position_covariance(planar: &Matrix3<f64>) -> Matrix2<f64> {
    planar.fixed_view::<2, 2>(0, 0).into_owned()
}

pub(crate) fn pose_in_frame(stamp: Stamp, estimate: &PoseEstimate) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(stamp.timestamp()),
        frame_id: MAP.to_string(),
        pose: Some(pose3(&estimate.pose)),
    }
}

pub(crate) fn odometry(stamp: Stamp, estimate: &PoseEstimate) -> Odometry {
    let mut velocity_covariance = vec![0.0; 36];
    for d in 0..6 {
        if let Some(slot) = velocity_covariance.get_mut(d * 7) {
            *slot = UNKNOWN_VARIANCE;
        }
    }
    Odometry {
        timestamp: Some(stamp.timestamp()),
        frame_id: MAP.to_string(),
        body_frame_id: BASE_LINK.to_string(),
        pose: Some(pose3(&estimate.pose)),
        linear_velocity: None,
        angular_velocity: None,
        pose_covariance: covariance_6x6(&estimate.covariance).to_vec(),
        velocity_covariance,
        metadata: vec![
            KeyValuePair {
                key: "mode".to_string(),
                value: mode_name(estimate.mode).to_string(),
            },
            KeyValuePair {
                key: "source".to_string(),
                value: estimate.source.clone(),
            },
        ],
    }
}

pub(crate) fn pose_ellipse(stamp: Stamp, estimate: &PoseEstimate) -> SceneUpdate {
    let p = &estimate.pose;
    let mut e = entity(stamp, "pose".to_string());
    e.spheres.extend(ellipse(
        p.x,
        p.y,
        &position_covariance(&estimate.covariance),
        mode_color(estimate.mode),
    ));
    let yaw_sd = estimate.covariance[(2, 2)].max(0.0).sqrt().to_degrees();
    e.texts.push(label(
        p.x,
        p.y,
        format!(
            "{} {} σyaw {yaw_sd:.1}°",
            mode_name(estimate.mode),
            estimate.source
        ),
    ));
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![e],
    }
}

pub(crate) fn path(stamp: Stamp, poses: &[Pose2]) -> PosesInFrame {
    PosesInFrame {
        timestamp: Some(stamp.timestamp()),
        frame_id: MAP.to_string(),
        poses: poses.iter().map(pose3).collect(),
    }
}

fn frame_transform(stamp: Stamp, parent: &str, child: &str, p: &Pose2) -> FrameTransform {
    FrameTransform {
        timestamp: Some(stamp.timestamp()),
        parent_frame_id: parent.to_string(),
        child_frame_id: child.to_string(),
        translation: Some(vector(p.x, p.y, 0.0)),
        rotation: Some(quaternion(p.theta)),
    }
}

pub(crate) fn transforms(stamp: Stamp, map_pose: &Pose2, odom_pose: &Pose2) -> FrameTransforms {
    FrameTransforms {
        transforms: vec![
            frame_transform(stamp, MAP, ODOM, &map_to_odom(map_pose, odom_pose)),
            frame_transform(stamp, ODOM, BASE_LINK, odom_pose),
        ],
    }
}

pub(crate) fn target(stamp: Stamp, t: &TargetEstimate) -> SceneUpdate {
    let mut e = entity(stamp, t.id.clone());
    e.spheres.push(SpherePrimitive {
        pose: Some(at(t.x, t.y, 0.0)),
        size: Some(vector(0.25, 0.25, 0.25)),
        color: Some(TARGET_COLOR),
    });
    e.spheres
        .extend(ellipse(t.x, t.y, &t.covariance, TARGET_ELLIPSE));
    e.texts.push(label(t.x, t.y, t.id.clone()));
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![e],
    }
}

pub(crate) fn landmarks(stamp: Stamp, kind: LandmarkKind, marks: &[Landmark]) -> SceneUpdate {
    let entities = marks
        .iter()
        .map(|m| {
            let mut e = entity(stamp, m.id.clone());
            match kind {
                LandmarkKind::Beacon => e.cubes.push(CubePrimitive {
                    pose: Some(at(m.x, m.y, 0.1)),
                    size: Some(vector(0.2, 0.2, 0.2)),
                    color: Some(BEACON_COLOR),
                }),
                LandmarkKind::Tag => e.spheres.push(SpherePrimitive {
                    pose: Some(at(m.x, m.y, 0.05)),
                    size: Some(vector(0.12, 0.12, 0.12)),
                    color: Some(TAG_COLOR),
                }),
            }
            if let Some(cov) = &m.covariance {
                e.spheres.extend(ellipse(m.x, m.y, cov, LANDMARK_ELLIPSE));
            }
            e.texts.push(label(m.x, m.y, m.id.clone()));
            e
        })
        .collect();
    SceneUpdate {
        // The map replaces the previous one: entities older than this update go.
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(stamp.timestamp()),
            r#type: scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities,
    }
}

/// Bytes per particle in the point cloud of [`crate::topics::PARTICLES`]: x, y, yaw, weight as
/// little-endian `f32`.
pub const PARTICLE_STRIDE: u32 = 16;

pub(crate) fn particles(stamp: Stamp, ps: &[Particle]) -> PointCloud {
    let mut data = Vec::with_capacity(ps.len() * PARTICLE_STRIDE as usize);
    for p in ps {
        // f32 keeps a map position to the millimetre within 16 km.
        #[allow(clippy::cast_possible_truncation)]
        for v in [p.pose.x, p.pose.y, p.pose.theta, p.weight] {
            data.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    let field = |name: &str, offset: u32| PackedElementField {
        name: name.to_string(),
        offset,
        r#type: NumericType::Float32 as i32,
    };
    PointCloud {
        timestamp: Some(stamp.timestamp()),
        frame_id: MAP.to_string(),
        pose: Some(at(0.0, 0.0, 0.0)),
        point_stride: PARTICLE_STRIDE,
        fields: vec![
            field("x", 0),
            field("y", 4),
            field("yaw", 8),
            field("weight", 12),
        ],
        data: Bytes::from(data),
    }
}

pub(crate) fn laser_scan(stamp: Stamp, scan: &RangeScan) -> LaserScan {
    LaserScan {
        timestamp: Some(stamp.timestamp()),
        frame_id: BASE_LINK.to_string(),
        pose: Some(pose3(&scan.mount)),
        start_angle: scan.start_angle,
        end_angle: scan.end_angle,
        ranges: scan.ranges.clone(),
        intensities: scan.intensities.clone(),
    }
}

pub(crate) fn log(stamp: Stamp, device: &str, level: LogLevel, message: &str) -> Log {
    use foxglove::messages::log::Level;
    let level = match level {
        LogLevel::Debug => Level::Debug,
        LogLevel::Info => Level::Info,
        LogLevel::Warning => Level::Warning,
        LogLevel::Error => Level::Error,
        LogLevel::Fatal => Level::Fatal,
    };
    Log {
        timestamp: Some(stamp.timestamp()),
        level: level as i32,
        message: message.to_string(),
        name: device.to_string(),
        file: String::new(),
        line: 0,
    }
}

/// The custom message of [`crate::topics::LINK`]: protobuf `linkbytes.LinkBytes` with fields
/// `timestamp` (google.protobuf.Timestamp, 1), `device` (string, 2), `direction` (enum
/// `Direction { Rx = 0; Tx = 1; }`, 3) and `data` (bytes, 4).
#[derive(foxglove::Encode)]
pub(crate) struct LinkBytes {
    pub(crate) timestamp: Timestamp,
    pub(crate) device: String,
    pub(crate) direction: Direction,
    pub(crate) data: Bytes,
}

pub(crate) fn link_bytes(
    stamp: Stamp,
    device: &str,
    direction: Direction,
    bytes: &[u8],
) -> LinkBytes {
    LinkBytes {
        timestamp: stamp.timestamp(),
        device: device.to_string(),
        direction,
        data: Bytes::copy_from_slice(bytes),
    }
}

/// The custom message of [`crate::topics::OBSERVATION`]: protobuf `observation.Observation` with
/// fields `timestamp` (1), `device` (string, 2), `kind` (string, 3) and `json` (string, 4).
#[derive(foxglove::Encode)]
#[allow(clippy::struct_field_names)]
pub(crate) struct Observation {
    pub(crate) timestamp: Timestamp,
    pub(crate) device: String,
    pub(crate) kind: String,
    pub(crate) json: String,
}

pub(crate) fn observation(stamp: Stamp, device: &str, kind: &str, json: &str) -> Observation {
    Observation {
        timestamp: stamp.timestamp(),
        device: device.to_string(),
        kind: kind.to_string(),
        json: json.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    fn estimate(cov: Matrix3<f64>) -> PoseEstimate {
        PoseEstimate {
            time: 0.0,
            pose: Pose2::new(1.0, 2.0, FRAC_PI_2),
            covariance: cov,
            mode: EstimateMode::Degraded,
            source: "ekf".to_string(),
        }
    }

    #[test]
    fn covariance_goes_to_x_y_yaw_and_the_rest_is_unknown() {
        let cov = Matrix3::new(1.0, 0.1, 0.2, 0.1, 2.0, 0.3, 0.2, 0.3, 0.05);
        let c = covariance_6x6(&cov);
        let at = |r: usize, col: usize| c[r * 6 + col];
        assert_eq!((at(0, 0), at(0, 1), at(0, 5)), (1.0, 0.1, 0.2));
        assert_eq!((at(1, 0), at(1, 1), at(1, 5)), (0.1, 2.0, 0.3));
        assert_eq!((at(5, 0), at(5, 1), at(5, 5)), (0.2, 0.3, 0.05));
        for d in 2..5 {
            assert_eq!(at(d, d), UNKNOWN_VARIANCE, "diagonal {d}");
            for o in (0..6).filter(|&o| o != d) {
                assert_eq!((at(d, o), at(o, d)), (0.0, 0.0), "({d}, {o})");
            }
        }
        // Symmetric, like its source.
        for r in 0..6 {
            for col in 0..6 {
                assert_eq!(at(r, col), at(col, r));
            }
        }
    }

    #[test]
    fn principal_axes_of_diagonal_and_rotated_covariances() {
        let (maj, min, ang) = principal_axes(&Matrix2::new(4.0, 0.0, 0.0, 1.0)).unwrap();
        assert!(close(maj, 2.0) && close(min, 1.0) && close(ang, 0.0));
        let (maj, min, ang) = principal_axes(&Matrix2::new(1.0, 0.0, 0.0, 9.0)).unwrap();
        assert!(close(maj, 3.0) && close(min, 1.0) && close(ang.abs(), FRAC_PI_2));
        // R(45°) diag(4, 1) R(45°)ᵀ = [[2.5, 1.5], [1.5, 2.5]].
        let (maj, min, ang) = principal_axes(&Matrix2::new(2.5, 1.5, 1.5, 2.5)).unwrap();
        assert!(close(maj, 2.0) && close(min, 1.0) && close(ang, FRAC_PI_4));
        // Slightly indefinite: the negative eigenvalue is taken as zero.
        let (_, min, _) = principal_axes(&Matrix2::new(1.0, 0.0, 0.0, -1e-12)).unwrap();
        assert_eq!(min, 0.0);
        assert!(principal_axes(&Matrix2::new(f64::NAN, 0.0, 0.0, 1.0)).is_none());
    }

    #[test]
    fn map_to_odom_composes_back_to_the_map_pose() {
        let map = Pose2::new(10.0, -3.0, 2.5);
        let odom = Pose2::new(1.5, 0.5, -0.7);
        let m2o = map_to_odom(&map, &odom);
        let back = m2o.compose(&odom);
        assert!(close(back.x, map.x) && close(back.y, map.y) && close(back.theta, map.theta));
        // No drift: odometry equal to the map pose gives the identity.
        let id = map_to_odom(&map, &map);
        assert!(close(id.x, 0.0) && close(id.y, 0.0) && close(id.theta, 0.0));
    }

    #[test]
    fn transforms_chain_map_odom_base_link() {
        let stamp = Stamp::from_unix_nanos(5_000_000_123);
        let map = Pose2::new(3.0, 4.0, PI / 3.0);
        let odom = Pose2::new(1.0, 0.0, 0.0);
        let tf = transforms(stamp, &map, &odom);
        assert_eq!(tf.transforms.len(), 2);
        let (a, b) = (&tf.transforms[0], &tf.transforms[1]);
        assert_eq!(
            (a.parent_frame_id.as_str(), a.child_frame_id.as_str()),
            ("map", "odom")
        );
        assert_eq!(
            (b.parent_frame_id.as_str(), b.child_frame_id.as_str()),
            ("odom", "base_link")
        );
        let t = b.translation.unwrap();
        assert_eq!((t.x, t.y, t.z), (1.0, 0.0, 0.0));
        let expected = map_to_odom(&map, &odom);
        let t = a.translation.unwrap();
        assert!(close(t.x, expected.x) && close(t.y, expected.y));
        let q = a.rotation.unwrap();
        assert!(close(2.0 * q.z.atan2(q.w), expected.theta));
        assert_eq!(a.timestamp.unwrap().nsec(), 123);
    }

    #[test]
    fn pose_messages_carry_frame_quaternion_and_covariance() {
        let stamp = Stamp::from_unix_nanos(1_700_000_000_000_000_000);
        let est = estimate(Matrix3::from_diagonal(&nalgebra::Vector3::new(
            0.04, 0.01, 0.0025,
        )));
        let p = pose_in_frame(stamp, &est);
        assert_eq!(p.frame_id, "map");
        let pose = p.pose.unwrap();
        let q = pose.orientation.unwrap();
        assert!(close(q.z, FRAC_PI_4.sin()) && close(q.w, FRAC_PI_4.cos()));
        let odo = odometry(stamp, &est);
        assert_eq!(
            (odo.frame_id.as_str(), odo.body_frame_id.as_str()),
            ("map", "base_link")
        );
        assert_eq!(odo.pose_covariance.len(), 36);
        assert_eq!(odo.pose_covariance[35], 0.0025);
        assert_eq!(odo.velocity_covariance[0], UNKNOWN_VARIANCE);
        assert_eq!(odo.metadata[0].value, "degraded");
        let scene = pose_ellipse(stamp, &est);
        let sphere = scene.entities[0].spheres[0];
        let size = sphere.size.unwrap();
        // σx = 0.2 m, σy = 0.1 m: 95 % diameters 2·2.4477·σ.
        assert!(close(size.x, 2.0 * ELLIPSE_SIGMA_95 * 0.2));
        assert!(close(size.y, 2.0 * ELLIPSE_SIGMA_95 * 0.1));
        assert!(scene.entities[0].texts[0].text.contains("σyaw 2.9°"));
    }

    #[test]
    fn particles_pack_four_little_endian_floats() {
        let cloud = particles(
            Stamp::default(),
            &[
                Particle {
                    pose: Pose2::new(1.5, -2.0, 0.25),
                    weight: 0.5,
                },
                Particle {
                    pose: Pose2::new(0.0, 3.0, 0.0),
                    weight: 0.125,
                },
            ],
        );
        assert_eq!(cloud.data.len(), 32);
        let f = |i: usize| f32::from_le_bytes(cloud.data[i * 4..i * 4 + 4].try_into().unwrap());
        assert_eq!([f(0), f(1), f(2), f(3)], [1.5, -2.0, 0.25, 0.5]);
        assert_eq!([f(4), f(5), f(6), f(7)], [0.0, 3.0, 0.0, 0.125]);
        let names: Vec<_> = cloud
            .fields
            .iter()
            .map(|f| (f.name.as_str(), f.offset))
            .collect();
        assert_eq!(names, [("x", 0), ("y", 4), ("yaw", 8), ("weight", 12)]);
    }

    #[test]
    fn landmark_map_replaces_the_previous_one() {
        let marks = [
            Landmark {
                id: "b1".into(),
                x: 1.0,
                y: 2.0,
                covariance: None,
            },
            Landmark {
                id: "b2".into(),
                x: -1.0,
                y: 0.0,
                covariance: Some(Matrix2::identity()),
            },
        ];
        let u = landmarks(Stamp::from_unix_nanos(7), LandmarkKind::Beacon, &marks);
        assert_eq!(u.deletions.len(), 1);
        assert_eq!(
            u.deletions[0].r#type,
            scene_entity_deletion::Type::All as i32
        );
        assert_eq!(u.entities.len(), 2);
        assert_eq!(u.entities[0].cubes.len(), 1);
        assert_eq!(u.entities[0].spheres.len(), 0);
        assert_eq!(u.entities[1].spheres.len(), 1, "the covariance ellipse");
        assert_eq!(u.entities[1].texts[0].text, "b2");
        let u = landmarks(Stamp::default(), LandmarkKind::Tag, &marks[..1]);
        assert_eq!(
            (u.entities[0].cubes.len(), u.entities[0].spheres.len()),
            (0, 1)
        );
    }

    #[test]
    fn log_levels_map_to_foxglove_levels() {
        use foxglove::messages::log::Level;
        for (ours, theirs) in [
            (LogLevel::Debug, Level::Debug),
            (LogLevel::Info, Level::Info),
            (LogLevel::Warning, Level::Warning),
            (LogLevel::Error, Level::Error),
            (LogLevel::Fatal, Level::Fatal),
        ] {
            let m = log(Stamp::default(), "urg", ours, "stale");
            assert_eq!(m.level, theirs as i32);
            assert_eq!((m.name.as_str(), m.message.as_str()), ("urg", "stale"));
        }
    }
}
