//! What one sweep recorded.

/// One antenna stop: where the antenna pointed, where the robot pointed, what was heard.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SweepSample {
    /// Antenna angle relative to the robot's forward direction, radians (as reached, not as
    /// planned).
    pub antenna_rad: f64,
    /// Robot heading when the sample was taken, radians (any fixed world frame).
    pub heading_rad: f64,
    /// `(beacon id, RSSI dBm)` heard at this stop; a beacon may appear several times (repeated
    /// probes) or not at all (not heard).
    pub readings: Vec<(u64, f64)>,
}

/// A sequence of antenna stops, in the order they were taken.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sweep {
    /// The stops.
    pub samples: Vec<SweepSample>,
}

impl Sweep {
    /// Every beacon id heard in the sweep, sorted.
    #[must_use]
    pub fn beacon_ids(&self) -> Vec<u64> {
        let mut ids: Vec<u64> = self
            .samples
            .iter()
            .flat_map(|s| s.readings.iter().map(|(id, _)| *id))
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }
}
