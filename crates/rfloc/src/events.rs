//! What device tasks send to the estimator task.

use rfloc_pose::Pose2;

use crate::message::DeviceState;

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

impl DeviceEvent {
    /// The device this event came from.
    #[must_use]
    pub fn device(&self) -> &str {
        match self {
            DeviceEvent::Odometry { device, .. }
            | DeviceEvent::HfTag { device, .. }
            | DeviceEvent::UhfSnapshot { device, .. }
            | DeviceEvent::Mark { device, .. }
            | DeviceEvent::Status { device, .. } => device,
        }
    }
}
