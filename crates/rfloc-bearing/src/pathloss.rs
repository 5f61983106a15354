//! Log-distance path loss: RSSI ↔ range, with the range variance from shadowing.

use serde::{Deserialize, Serialize};

/// `RSSI(d) = P_ref − 10 η log10(d / d_ref) + X`, `X ~ N(0, σ²)` dB.
///
/// `P_ref` must be measured with the antenna pointing at the beacon (reflector gain included),
/// because ranges are taken from the peak of a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PathLossModel {
    /// RSSI at the reference distance, dBm (−29 dBm in the seed's eq. 2.7; its own range test
    /// used −33 dBm).
    pub p_ref_dbm: f64,
    /// Reference distance, m.
    pub d_ref_m: f64,
    /// Path-loss exponent η (2 in free space and in the seed).
    pub eta: f64,
    /// Shadowing standard deviation σ, dB.
    pub shadowing_sigma_db: f64,
}

impl Default for PathLossModel {
    fn default() -> Self {
        Self {
            p_ref_dbm: -29.0,
            d_ref_m: 1.0,
            eta: 2.0,
            shadowing_sigma_db: 4.0,
        }
    }
}

/// A range with its variance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeEstimate {
    /// Median range estimate `d̂ = d_ref·10^((P_ref − RSSI)/(10 η))`, m.
    pub range_m: f64,
    /// First-order variance `(d̂·σ_ln)²` with `σ_ln = σ·ln10/(10 η)`, m².
    pub variance_m2: f64,
}

impl PathLossModel {
    /// Expected RSSI at distance `d_m` (no shadowing), dBm.
    #[must_use]
    pub fn rssi_at(&self, d_m: f64) -> f64 {
        self.p_ref_dbm - 10.0 * self.eta * (d_m / self.d_ref_m).log10()
    }

    /// Standard deviation of `ln d̂`: `σ·ln10/(10 η)`.
    #[must_use]
    pub fn sigma_ln(&self) -> f64 {
        self.shadowing_sigma_db * std::f64::consts::LN_10 / (10.0 * self.eta)
    }

    /// Inverts the model. `d̂` is the median of the log-normal range distribution (its mean is
    /// `exp(σ_ln²/2)` higher).
    #[must_use]
    pub fn range_from_rssi(&self, rssi_dbm: f64) -> RangeEstimate {
        let range_m = self.d_ref_m * 10f64.powf((self.p_ref_dbm - rssi_dbm) / (10.0 * self.eta));
        let s = range_m * self.sigma_ln();
        RangeEstimate {
            range_m,
            variance_m2: s * s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seed 003, Table 4.1: with P_ref = −33 dB·m and η = 2 the measured RSSI −23, −33.103,
    /// −38.308, −41.974 give 0.3162, 1.0119, 1.8425, 2.81 m.
    #[test]
    fn reproduces_seed_table_4_1() {
        let m = PathLossModel {
            p_ref_dbm: -33.0,
            ..PathLossModel::default()
        };
        for (rssi, want) in [
            (-23.0, 0.3162),
            (-33.103, 1.0119),
            (-38.308, 1.8425),
            (-41.974, 2.81),
        ] {
            let r = m.range_from_rssi(rssi).range_m;
            assert!((r - want).abs() < 5e-4, "{rssi} dBm -> {r} m, table {want}");
        }
    }

    #[test]
    fn round_trip_and_variance() {
        let m = PathLossModel::default();
        for d in [0.3, 1.0, 2.5, 7.0] {
            let e = m.range_from_rssi(m.rssi_at(d));
            assert!((e.range_m - d).abs() < 1e-9);
            // σ = 4 dB, η = 2 -> σ_ln = 0.4605.
            assert!((e.variance_m2.sqrt() / d - 0.460_517).abs() < 1e-5);
        }
    }
}
