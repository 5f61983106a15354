//! What device tasks send to the estimator task.

use rfloc_kts::{TagEvent, TagEventKind};
use rfloc_pose::Pose2;
use serde::Deserialize;

pub use rfloc_emitter::ScanBeam;

/// One observation or status change from a device task.
#[derive(Debug, Clone)]
pub enum DeviceEvent {
    /// Wheel odometry from the Pioneer base (pose in the odometry frame; `v`, `w` for
    /// pipelines that use the measured speeds).
    #[allow(dead_code)]
    Odometry {
        device: String,
        t: f64,
        pose: Pose2,
        v: f64,
        w: f64,
    },
    /// The base's SIPs began to report a stalled wheel (its motors push against something);
    /// sent once per stall, when the first SIP with a stall bit follows one without.
    WheelStall { device: String, t: f64 },
    /// The base's bumper rings changed: which are pressed now (any segment of the front or the
    /// rear ring, from the SIPs' bumper bits). Sent on every change.
    Bumpers {
        device: String,
        t: f64,
        front: bool,
        rear: bool,
    },
    /// An HF floor tag in the antenna field (`SCAN:+UID`), with the reader's RSSI numbers.
    HfTag {
        device: String,
        t: f64,
        uid: String,
        rssi: u8,
        rssi_second: u8,
    },
    /// A UHF snapshot: tag ID (hex EPC) → RSS, averaged over the configured number of reads.
    UhfSnapshot {
        device: String,
        t: f64,
        tags: Vec<(String, f64)>,
    },
    /// One antenna sweep of the XBee radio (seed 003): each beacon's peak RSSI and fitted
    /// bearing, or why the sweep was abandoned.
    Sweep {
        device: String,
        t: f64,
        result: Result<Vec<SweptBeacon>, String>,
    },
    /// One RSSI poll of an emitter receiver (seed 001): what the radio behind `antenna`
    /// measured on the emitter's answer, dBm; `None` when the emitter did not answer.
    EmitterRss {
        device: String,
        t: f64,
        antenna: AntennaSide,
        dbm: Option<f64>,
    },
    /// One scan of a range finder centred on the robot (beam angles from its heading).
    RangeScan {
        device: String,
        t: f64,
        beams: Vec<ScanBeam>,
    },
    /// A marker from a capture or a motion script, e.g. `stop 3 heading_deg=135`.
    Mark {
        device: String,
        t: f64,
        text: String,
    },
    /// A link changed state (or reports its error counters).
    Status {
        device: String,
        driver: &'static str,
        state: DeviceState,
        detail: String,
        /// Error counters of the link (malformed lines, dropped bytes), when it has any.
        counters: Vec<(&'static str, u64)>,
    },
}

/// What one sweep says about one beacon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweptBeacon {
    /// The beacon's 64-bit address.
    pub id: u64,
    /// Strongest RSSI over the sweep, dBm.
    pub peak_rssi_dbm: f64,
    /// Bearing of the beacon from the robot's forward direction, radians (counter-clockwise).
    pub bearing_rad: f64,
    /// Variance of that bearing from the peak fit, rad².
    pub bearing_variance_rad2: f64,
}

impl DeviceEvent {
    /// The device this event came from.
    #[must_use]
    pub fn device(&self) -> &str {
        match self {
            DeviceEvent::Odometry { device, .. }
            | DeviceEvent::WheelStall { device, .. }
            | DeviceEvent::Bumpers { device, .. }
            | DeviceEvent::HfTag { device, .. }
            | DeviceEvent::UhfSnapshot { device, .. }
            | DeviceEvent::Sweep { device, .. }
            | DeviceEvent::EmitterRss { device, .. }
            | DeviceEvent::RangeScan { device, .. }
            | DeviceEvent::Mark { device, .. }
            | DeviceEvent::Status { device, .. } => device,
        }
    }
}

impl DeviceEvent {
    /// The HF floor-tag event of a KTS `SCAN:+UID` report with RSSI; `None` for `SCAN:-UID`
    /// (a tag leaving the field is not a position fix) or a report without RSSI. RSSI values
    /// are clamped into 0–255 (the reader gives 0–7).
    #[must_use]
    pub fn from_tag_event(device: &str, ev: &TagEvent) -> Option<Self> {
        let TagEventKind::Seen { rssi: Some(r) } = &ev.kind else {
            return None;
        };
        let clamp = |v: i32| u8::try_from(v.clamp(0, 255)).unwrap_or(0);
        Some(DeviceEvent::HfTag {
            device: device.to_string(),
            t: ev.t,
            uid: ev.uid.to_string(),
            rssi: clamp(r.main),
            rssi_second: clamp(r.aux.unwrap_or(r.main)),
        })
    }

    /// When the observation was made (driver clock); `None` for status changes.
    #[must_use]
    pub fn time(&self) -> Option<f64> {
        match self {
            DeviceEvent::Odometry { t, .. }
            | DeviceEvent::WheelStall { t, .. }
            | DeviceEvent::Bumpers { t, .. }
            | DeviceEvent::HfTag { t, .. }
            | DeviceEvent::UhfSnapshot { t, .. }
            | DeviceEvent::Sweep { t, .. }
            | DeviceEvent::EmitterRss { t, .. }
            | DeviceEvent::RangeScan { t, .. }
            | DeviceEvent::Mark { t, .. } => Some(*t),
            DeviceEvent::Status { .. } => None,
        }
    }
}

/// State of one device link as reported in DEVICE objects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceState {
    Connecting,
    Connected,
    Stale,
    Reconnecting,
    Closed,
    /// The device task ended or panicked; the daemon restarts it after a back-off.
    Failed,
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
            DeviceState::Failed => "failed",
        }
    }
}

/// The four fixed reflectors of the emitter-homing robot, 90° apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AntennaSide {
    Front,
    Left,
    Back,
    Right,
}

impl AntennaSide {
    /// The name in a robot file.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            AntennaSide::Front => "front",
            AntennaSide::Left => "left",
            AntennaSide::Back => "back",
            AntennaSide::Right => "right",
        }
    }
}

impl DeviceEvent {
    /// The observation as one JSON line (`rfloc replay` of a folder with no pipeline to run).
    #[must_use]
    pub fn to_json(&self) -> String {
        use serde_json::json;
        let v = match self {
            DeviceEvent::Odometry {
                device,
                t,
                pose,
                v,
                w,
            } => {
                json!({"observation": "odometry", "device": device, "t": t, "x": pose.x, "y": pose.y, "theta": pose.theta, "v": v, "w": w})
            }
            DeviceEvent::WheelStall { device, t } => {
                json!({"observation": "wheel_stall", "device": device, "t": t})
            }
            DeviceEvent::Bumpers {
                device,
                t,
                front,
                rear,
            } => {
                json!({"observation": "bumpers", "device": device, "t": t, "front": front, "rear": rear})
            }
            DeviceEvent::HfTag {
                device,
                t,
                uid,
                rssi,
                rssi_second,
            } => {
                json!({"observation": "hf_tag", "device": device, "t": t, "uid": uid, "rssi": rssi, "rssi_second": rssi_second})
            }
            DeviceEvent::UhfSnapshot { device, t, tags } => {
                let tags: Vec<_> = tags
                    .iter()
                    .map(|(id, rss)| json!({"id": id, "rss": rss}))
                    .collect();
                json!({"observation": "uhf_snapshot", "device": device, "t": t, "tags": tags})
            }
            DeviceEvent::Sweep { device, t, result } => match result {
                Ok(beacons) => {
                    let b: Vec<_> = beacons
                        .iter()
                        .map(|b| json!({"id": format!("{:016X}", b.id), "peak_rssi_dbm": b.peak_rssi_dbm, "bearing_rad": b.bearing_rad, "bearing_variance_rad2": b.bearing_variance_rad2}))
                        .collect();
                    json!({"observation": "sweep", "device": device, "t": t, "beacons": b})
                }
                Err(why) => json!({"observation": "sweep", "device": device, "t": t, "error": why}),
            },
            DeviceEvent::EmitterRss {
                device,
                t,
                antenna,
                dbm,
            } => {
                json!({"observation": "emitter_rss", "device": device, "t": t, "antenna": antenna.as_str(), "dbm": dbm})
            }
            DeviceEvent::RangeScan { device, t, beams } => {
                let ranges: Vec<f64> = beams.iter().map(|b| b.range_m).collect();
                let angles: Vec<f64> = beams.iter().map(|b| b.angle_rad).collect();
                json!({"observation": "range_scan", "device": device, "t": t, "angles_rad": angles, "ranges_m": ranges})
            }
            DeviceEvent::Mark { device, t, text } => {
                json!({"observation": "mark", "device": device, "t": t, "text": text})
            }
            DeviceEvent::Status {
                device,
                driver,
                state,
                detail,
                ..
            } => {
                json!({"observation": "status", "device": device, "driver": driver, "state": state.as_str(), "detail": detail})
            }
        };
        v.to_string()
    }
}
