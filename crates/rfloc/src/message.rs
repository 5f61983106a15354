//! gpsd-style JSON objects of the pose stream: `VERSION`, `POSE`, `DEVICE`.
//!
//! Numbers are printed with fixed precision; an estimate with a non-finite value is never
//! printed (the caller counts and logs it instead).

use std::fmt::Write;
use std::time::{SystemTime, UNIX_EPOCH};

use rfloc_pose::{EstimateMode, PoseEstimate};

/// Protocol version of the pose stream.
pub const PROTO_MAJOR: u32 = 1;

/// The `VERSION` object sent first to every client.
#[must_use]
pub fn version_json() -> String {
    format!(
        "{{\"class\":\"VERSION\",\"release\":\"{}\",\"proto_major\":{PROTO_MAJOR},\"proto_minor\":1}}",
        env!("CARGO_PKG_VERSION")
    )
}

/// Frames and formatting of POSE objects.
#[derive(Debug, Clone)]
pub struct PoseFormat {
    pub frame_id: String,
    pub child_frame_id: String,
    /// Fraction digits for metres; radians and quaternions get two more.
    pub precision: usize,
}

/// Why an estimate cannot be printed.
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

fn json_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// ISO 8601 UTC time with milliseconds, e.g. `2026-11-21T10:00:00.000Z`.
#[must_use]
pub fn iso8601(t: SystemTime) -> String {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs();
    let millis = d.subsec_millis();
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    let (y, m, day) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{day:02}T{:02}:{:02}:{:02}.{millis:03}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

/// Days since 1970-01-01 to (year, month, day), proleptic Gregorian.
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = u32::try_from(doy - (153 * mp + 2) / 5 + 1).unwrap_or(1);
    let m = u32::try_from(if mp < 10 { mp + 3 } else { mp - 9 }).unwrap_or(1);
    (if m <= 2 { y + 1 } else { y }, m, d)
}

/// One POSE object as a JSON line (without the newline).
pub fn pose_json(
    est: &PoseEstimate,
    wall: SystemTime,
    fmt: &PoseFormat,
) -> Result<String, NonFinite> {
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
    let cov = est.ros_covariance();
    if cov.iter().any(|v| !v.is_finite()) {
        return Err(NonFinite("covariance"));
    }
    let pm = fmt.precision;
    let pr = fmt.precision + 2;
    let q = est.quaternion();
    let mut s = String::with_capacity(512);
    s.push_str("{\"class\":\"POSE\"");
    let _ = write!(s, ",\"time\":{}", json_string(&iso8601(wall)));
    let _ = write!(s, ",\"stamp\":{:.6}", est.time);
    let _ = write!(s, ",\"frame_id\":{}", json_string(&fmt.frame_id));
    let _ = write!(
        s,
        ",\"child_frame_id\":{}",
        json_string(&fmt.child_frame_id)
    );
    let _ = write!(s, ",\"mode\":\"{}\"", mode_name(est.mode));
    let _ = write!(
        s,
        ",\"x\":{:.pm$},\"y\":{:.pm$},\"yaw\":{:.pr$}",
        p.x, p.y, p.theta
    );
    let _ = write!(
        s,
        ",\"quaternion\":[{:.pr$},{:.pr$},{:.pr$},{:.pr$}]",
        q[0], q[1], q[2], q[3]
    );
    s.push_str(",\"cov\":[");
    for (i, v) in cov.iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        // Variances can be tiny; scientific notation keeps them exact enough and finite.
        let _ = write!(s, "{v:.3e}");
    }
    s.push(']');
    let _ = write!(s, ",\"source\":{}", json_string(&est.source));
    s.push('}');
    Ok(s)
}

/// A TARGET line: `{"class":"TARGET","time":…,"stamp":…,"frame_id":…,"id":"emitter","x":…,
/// "y":…,"cov":[xx,xy,yy],"raw":[x,y],"source":…}` (metres with the pose precision; `raw`
/// only when the pipeline has an unfiltered position).
///
/// # Errors
/// A non-finite position, covariance or time.
pub fn target_json(
    t: &crate::pipeline::TargetEstimate,
    wall: SystemTime,
    fmt: &PoseFormat,
) -> Result<String, NonFinite> {
    if !(t.x.is_finite() && t.y.is_finite()) {
        return Err(NonFinite("position"));
    }
    if !t.time.is_finite() {
        return Err(NonFinite("time"));
    }
    if t.cov.iter().any(|v| !v.is_finite()) {
        return Err(NonFinite("covariance"));
    }
    let pm = fmt.precision;
    let mut s = String::with_capacity(256);
    s.push_str("{\"class\":\"TARGET\"");
    let _ = write!(s, ",\"time\":{}", json_string(&iso8601(wall)));
    let _ = write!(s, ",\"stamp\":{:.6}", t.time);
    let _ = write!(s, ",\"frame_id\":{}", json_string(&fmt.frame_id));
    let _ = write!(s, ",\"id\":{}", json_string(t.id));
    let _ = write!(s, ",\"x\":{:.pm$},\"y\":{:.pm$}", t.x, t.y);
    let _ = write!(
        s,
        ",\"cov\":[{:.3e},{:.3e},{:.3e}]",
        t.cov[0], t.cov[1], t.cov[2]
    );
    if let Some((rx, ry)) = t.raw.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        let _ = write!(s, ",\"raw\":[{rx:.pm$},{ry:.pm$}]");
    }
    let _ = write!(s, ",\"source\":{}", json_string(t.source));
    s.push('}');
    Ok(s)
}

/// State of one device link as reported in DEVICE objects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceState {
    Connecting,
    Connected,
    Stale,
    Reconnecting,
    Closed,
}

impl DeviceState {
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            DeviceState::Connecting => "connecting",
            DeviceState::Connected => "connected",
            DeviceState::Stale => "stale",
            DeviceState::Reconnecting => "reconnecting",
            DeviceState::Closed => "closed",
        }
    }
}

/// One DEVICE object as a JSON line.
#[must_use]
pub fn device_json(
    name: &str,
    driver: &str,
    state: DeviceState,
    detail: &str,
    wall: SystemTime,
) -> String {
    format!(
        "{{\"class\":\"DEVICE\",\"time\":{},\"name\":{},\"driver\":{},\"state\":\"{}\",\"detail\":{}}}",
        json_string(&iso8601(wall)),
        json_string(name),
        json_string(driver),
        state.as_str(),
        json_string(detail)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;
    use rfloc_pose::Pose2;
    use std::time::Duration;

    fn est() -> PoseEstimate {
        PoseEstimate {
            time: 12.5,
            pose: Pose2::new(1.23456, -0.5, std::f64::consts::FRAC_PI_2),
            covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(0.01, 0.02, 0.003)),
            mode: EstimateMode::Fix,
            source: "hfgrid".into(),
        }
    }

    fn fmt() -> PoseFormat {
        PoseFormat {
            frame_id: "map".into(),
            child_frame_id: "base_link".into(),
            precision: 3,
        }
    }

    #[test]
    fn pose_line_is_valid_json_with_fixed_precision() {
        let wall = UNIX_EPOCH + Duration::from_millis(1_795_255_200_123);
        let line = pose_json(&est(), wall, &fmt()).unwrap();
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["class"], "POSE");
        assert_eq!(v["mode"], "fix");
        assert_eq!(v["time"], "2026-11-21T10:00:00.123Z");
        assert!(line.contains("\"x\":1.235,"), "{line}");
        assert!(line.contains("\"yaw\":1.57080"), "{line}");
        let cov = v["cov"].as_array().unwrap();
        assert_eq!(cov.len(), 36);
        assert!((cov[0].as_f64().unwrap() - 0.01).abs() < 1e-9);
        assert!((cov[7].as_f64().unwrap() - 0.02).abs() < 1e-9);
        assert!((cov[35].as_f64().unwrap() - 0.003).abs() < 1e-9);
        let q = v["quaternion"].as_array().unwrap();
        assert!((q[3].as_f64().unwrap() - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-4);
    }

    #[test]
    fn non_finite_estimates_are_refused() {
        let mut e = est();
        e.pose.x = f64::NAN;
        assert_eq!(
            pose_json(&e, SystemTime::now(), &fmt()),
            Err(NonFinite("position"))
        );
        let mut e = est();
        e.covariance[(2, 2)] = f64::INFINITY;
        assert_eq!(
            pose_json(&e, SystemTime::now(), &fmt()),
            Err(NonFinite("covariance"))
        );
    }

    #[test]
    fn target_line_carries_position_covariance_and_raw_fix() {
        let mut t = crate::pipeline::TargetEstimate {
            time: 14.8,
            id: "emitter",
            x: 3.95123,
            y: -0.0431,
            cov: [0.0211, -0.0012, 0.0195],
            raw: Some((3.881, 0.1702)),
            source: "emitter",
        };
        let wall = UNIX_EPOCH + Duration::from_millis(1_795_255_200_123);
        let line = target_json(&t, wall, &fmt()).unwrap();
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["class"], "TARGET");
        assert_eq!(v["id"], "emitter");
        assert_eq!(v["time"], "2026-11-21T10:00:00.123Z");
        assert!(line.contains("\"x\":3.951,\"y\":-0.043,"), "{line}");
        assert!(line.contains("\"raw\":[3.881,0.170]"), "{line}");
        let cov: Vec<f64> = v["cov"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_f64().unwrap())
            .collect();
        assert_eq!(cov, vec![0.0211, -0.0012, 0.0195]);
        t.raw = None;
        let line = target_json(&t, wall, &fmt()).unwrap();
        assert!(!line.contains("raw"), "{line}");
        t.cov[1] = f64::NAN;
        assert_eq!(target_json(&t, wall, &fmt()), Err(NonFinite("covariance")));
    }

    #[test]
    fn device_line_escapes_text() {
        let line = device_json(
            "hf \"1\"",
            "kts",
            DeviceState::Stale,
            "silent 3.0 s",
            UNIX_EPOCH,
        );
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["name"], "hf \"1\"");
        assert_eq!(v["state"], "stale");
        assert_eq!(v["time"], "1970-01-01T00:00:00.000Z");
    }
}
