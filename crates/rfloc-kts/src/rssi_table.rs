//! The RFIDM1356 RSSI ↔ antenna-to-tag distance relation measured in seed 002.
//!
//! Source: seed 002 (`002_a245ca0983afd786.txt`), §6.2, **Table 4** "Relation between RSSI and
//! distance antenna to tag (data)", antenna parallel to the floor at 1.5 cm height:
//!
//! | RSSI      | 0  | 1   | 2   | 3   | 4   | 5 | 6   | 7   |
//! |-----------|----|-----|-----|-----|-----|---|-----|-----|
//! | max [cm]  | 14 | 9.8 | 9   | 8   | 7   | 6 | 3.5 | 2.8 |
//! | middle    | 5  | 5.1 | 5.3 | 5.5 | 5.8 | 4 | –   | –   |
//! | min       | –  | 4.7 | 4.5 | 4.3 | 4.2 | – | –   | –   |
//!
//! "there exists a blind spot at a distance of 5 cm where the RSSI drops to 0".
//!
//! The forward model (distance → RSSI) is the seed's own emulator, Appendix A (Matlab, lines
//! 17–19): `r2 = [r1, 9.75, 9.0, 8.0, 7.0, 6.0, 5.8, 5.5, 5.3, 5.1, 5.0, 4.7, 4.5, 4.3, 4.2,
//! 4.0, 3.5, 2.75, 0]`, `r4 = [0, 1, 2, 3, 4, 5, 4, 3, 2, 1, 0, 1, 2, 3, 4, 5, 6, 7, 7]` with
//! `RSSI = r4(last index where r2 > d)`. `r1`, the read range, is garbled in the extraction; the
//! text says "0 defines … a distance from 14 to around 10 cm" and Table 4 gives 14 cm, so
//! `r1 = 14`. The two agree with Table 4 except that the emulator rounds 9.8 → 9.75 and
//! 2.8 → 2.75.

/// Read range: no tag is reported beyond this distance (cm). Seed 002 Table 4, RSSI 0 max.
pub const READ_RANGE_CM: f64 = 14.0;

/// Distance of the blind spot where RSSI drops to 0 (cm). Seed 002 §6.2 and Table 4.
pub const BLIND_SPOT_CM: f64 = 5.0;

/// Table 4, maximal distance per RSSI 0..=7 (cm).
pub const TABLE4_MAX_CM: [f64; 8] = [14.0, 9.8, 9.0, 8.0, 7.0, 6.0, 3.5, 2.8];
/// Table 4, middle distance per RSSI (cm); `None` where the table has no entry.
pub const TABLE4_MIDDLE_CM: [Option<f64>; 8] = [
    Some(5.0),
    Some(5.1),
    Some(5.3),
    Some(5.5),
    Some(5.8),
    Some(4.0),
    None,
    None,
];
/// Table 4, minimal distance per RSSI (cm); `None` where the table has no entry.
pub const TABLE4_MIN_CM: [Option<f64>; 8] = [
    None,
    Some(4.7),
    Some(4.5),
    Some(4.3),
    Some(4.2),
    None,
    None,
    None,
];

/// Appendix A `r2`: band edges (cm), decreasing.
const EMULATOR_EDGES_CM: [f64; 19] = [
    READ_RANGE_CM,
    9.75,
    9.0,
    8.0,
    7.0,
    6.0,
    5.8,
    5.5,
    5.3,
    5.1,
    5.0,
    4.7,
    4.5,
    4.3,
    4.2,
    4.0,
    3.5,
    2.75,
    0.0,
];
/// Appendix A `r4`: RSSI of each band.
const EMULATOR_RSSI: [u8; 19] = [0, 1, 2, 3, 4, 5, 4, 3, 2, 1, 0, 1, 2, 3, 4, 5, 6, 7, 7];

/// The RSSI (0..=7) the seed's emulator gives a tag at `distance_cm` from the antenna centre, or
/// `None` when the tag is out of range (`distance_cm >= 14`), as Appendix A does.
#[must_use]
pub fn rssi_at_distance(distance_cm: f64) -> Option<u8> {
    if !distance_cm.is_finite() || distance_cm >= READ_RANGE_CM {
        return None;
    }
    let d = distance_cm.max(0.0);
    EMULATOR_EDGES_CM
        .iter()
        .zip(EMULATOR_RSSI.iter())
        .rev()
        .find(|(edge, _)| **edge > d)
        .map(|(_, r)| *r)
}

/// The candidate distances (cm) Table 4 gives for an RSSI: max, middle, min when present.
#[must_use]
pub fn distances_for_rssi(rssi: u8) -> Vec<f64> {
    let i = usize::from(rssi);
    let mut v = Vec::new();
    if let Some(d) = TABLE4_MAX_CM.get(i) {
        v.push(*d);
    }
    if let Some(Some(d)) = TABLE4_MIDDLE_CM.get(i) {
        v.push(*d);
    }
    if let Some(Some(d)) = TABLE4_MIN_CM.get(i) {
        v.push(*d);
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_model_matches_appendix_a() {
        assert_eq!(rssi_at_distance(14.0), None);
        assert_eq!(rssi_at_distance(13.9), Some(0));
        assert_eq!(rssi_at_distance(9.75), Some(0));
        assert_eq!(rssi_at_distance(9.7), Some(1));
        assert_eq!(rssi_at_distance(6.5), Some(4));
        assert_eq!(rssi_at_distance(5.9), Some(5));
        assert_eq!(rssi_at_distance(5.6), Some(4));
        assert_eq!(rssi_at_distance(5.05), Some(1));
        // The 5 cm blind spot.
        assert_eq!(rssi_at_distance(4.9), Some(0));
        assert_eq!(rssi_at_distance(4.6), Some(1));
        assert_eq!(rssi_at_distance(4.1), Some(4));
        assert_eq!(rssi_at_distance(3.7), Some(5));
        assert_eq!(rssi_at_distance(3.0), Some(6));
        assert_eq!(rssi_at_distance(1.0), Some(7));
        assert_eq!(rssi_at_distance(0.0), Some(7));
        assert_eq!(rssi_at_distance(f64::NAN), None);
    }

    #[test]
    fn forward_model_agrees_with_table4() {
        // Every Table 4 distance, moved 0.05 cm inwards, maps back to its RSSI (the emulator
        // rounds 9.8 → 9.75 and 2.8 → 2.75, so those two are checked 0.1 cm inwards).
        for rssi in 0u8..8 {
            for d in distances_for_rssi(rssi) {
                let inward = if (d - 9.8).abs() < 1e-9 || (d - 2.8).abs() < 1e-9 {
                    0.1
                } else {
                    0.05
                };
                assert_eq!(
                    rssi_at_distance(d - inward),
                    Some(rssi),
                    "rssi {rssi} d {d}"
                );
            }
        }
    }

    #[test]
    fn table4_candidates() {
        assert_eq!(distances_for_rssi(4), vec![7.0, 5.8, 4.2]);
        assert_eq!(distances_for_rssi(7), vec![2.8]);
        assert!(distances_for_rssi(9).is_empty());
    }
}
