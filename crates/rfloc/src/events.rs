//! What device tasks send to the estimator task.

use rfloc_kts::{TagEvent, TagEventKind};
use rfloc_pose::Pose2;

use crate::config::AntennaSide;
use crate::message::DeviceState;
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
    /// A link changed state.
    Status {
        device: String,
        driver: &'static str,
        state: DeviceState,
        detail: String,
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
