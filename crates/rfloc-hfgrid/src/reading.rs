//! Reader output as the estimators take it.

use serde::{Deserialize, Serialize};

use crate::grid::TagUid;

/// One tag report: `SCAN:+UID=<uid>,+RSSI=<first>/<second>`. Only `rssi_first` (the main
/// receiver channel) is used, as in the reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TagReading {
    /// Tag UID.
    pub uid: TagUid,
    /// RSSI of the main channel, 0–7.
    pub rssi_first: u8,
    /// RSSI of the auxiliary channel, 0–7 (unused).
    pub rssi_second: u8,
}

/// Everything read at one heading of the initialisation turn: either one of the eight stops
/// (heading = multiple of 45°) or one reading with the odometry heading (continuous turn).
/// Several reports of the same tag are allowed (repeated scans); they are pooled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TurnStop {
    /// Robot heading at this stop relative to the start of the turn, rad (CCW positive).
    pub heading_rad: f64,
    /// Tag reports collected at this heading.
    pub readings: Vec<TagReading>,
}
