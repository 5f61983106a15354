//! Beacon observations as the filter takes them.

use serde::{Deserialize, Serialize};

/// A beacon's identity: its 64-bit radio address (e.g. an XBee serial number) or any other
/// unique key. Data association is by this key.
pub type BeaconId = u64;

/// A range-like reading of one beacon.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum RangeReading {
    /// A distance in metres with its variance in m².
    Metres {
        /// Range, m (> 0).
        range_m: f64,
        /// Variance, m².
        variance_m2: f64,
    },
    /// A received signal strength in dBm with its variance in dB². How it is used depends on
    /// [`crate::RssiHandling`].
    RssiDbm {
        /// RSSI, dBm (negative).
        rssi_dbm: f64,
        /// Variance, dB².
        variance_db2: f64,
    },
}

/// A bearing reading: angle from the robot's heading to the beacon, counter-clockwise positive.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BearingReading {
    /// Bearing relative to the robot heading, rad.
    pub bearing_rad: f64,
    /// Variance, rad².
    pub variance_rad2: f64,
}

/// One observation of one beacon. At least one of `range` and `bearing` must be present.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BeaconObservation {
    /// Which beacon.
    pub id: BeaconId,
    /// Range or RSSI, if measured.
    pub range: Option<RangeReading>,
    /// Bearing, if measured.
    pub bearing: Option<BearingReading>,
}

impl BeaconObservation {
    /// A range (m) and bearing (rad) observation with standard deviations `sigma_r` (m) and
    /// `sigma_b` (rad).
    #[must_use]
    pub fn range_bearing(
        id: BeaconId,
        range_m: f64,
        bearing_rad: f64,
        sigma_r: f64,
        sigma_b: f64,
    ) -> Self {
        Self {
            id,
            range: Some(RangeReading::Metres {
                range_m,
                variance_m2: sigma_r * sigma_r,
            }),
            bearing: Some(BearingReading {
                bearing_rad,
                variance_rad2: sigma_b * sigma_b,
            }),
        }
    }

    /// An RSSI (dBm) and bearing (rad) observation with standard deviations in dB and rad.
    #[must_use]
    pub fn rssi_bearing(
        id: BeaconId,
        rssi_dbm: f64,
        bearing_rad: f64,
        sigma_db: f64,
        sigma_b: f64,
    ) -> Self {
        Self {
            id,
            range: Some(RangeReading::RssiDbm {
                rssi_dbm,
                variance_db2: sigma_db * sigma_db,
            }),
            bearing: Some(BearingReading {
                bearing_rad,
                variance_rad2: sigma_b * sigma_b,
            }),
        }
    }

    /// An RSSI-only observation (no bearing).
    #[must_use]
    pub fn rssi_only(id: BeaconId, rssi_dbm: f64, sigma_db: f64) -> Self {
        Self {
            id,
            range: Some(RangeReading::RssiDbm {
                rssi_dbm,
                variance_db2: sigma_db * sigma_db,
            }),
            bearing: None,
        }
    }

    /// A bearing-only observation.
    #[must_use]
    pub fn bearing_only(id: BeaconId, bearing_rad: f64, sigma_b: f64) -> Self {
        Self {
            id,
            range: None,
            bearing: Some(BearingReading {
                bearing_rad,
                variance_rad2: sigma_b * sigma_b,
            }),
        }
    }
}

/// What happened to one observation in [`crate::EkfSlam::update`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ObservationOutcome {
    /// A mapped beacon was used to correct the state; `nis` is its normalised innovation squared.
    Updated {
        /// Normalised innovation squared `νᵀS⁻¹ν`.
        nis: f64,
        /// Measurement dimension (1 or 2).
        dof: usize,
    },
    /// A new beacon was added to the map (inverse measurement model or delayed triangulation).
    Added,
    /// A new beacon's view was stored; it is not yet constrained enough to be added.
    Pending,
    /// The Mahalanobis gate rejected the observation.
    Rejected {
        /// Normalised innovation squared that exceeded the gate.
        nis: f64,
        /// Measurement dimension (1 or 2).
        dof: usize,
    },
    /// The observation was unusable.
    Invalid(crate::InvalidObservation),
}
