//! Accuracy harness: robot RMSE against a truth trajectory and per-beacon final errors.
//!
//! RMSE here is the usual `sqrt(mean(e²))`. The reference (seed 003 eq. 3.1) prints
//! `sqrt(Σ e²)` without the mean, which grows with run length; its tables are only comparable
//! to this if read as root-mean-square.

use rfloc_pose::{angle_diff, Pose2};
use thiserror::Error;

use crate::filter::BeaconEstimate;
use crate::observation::BeaconId;

/// Why an accuracy report could not be computed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AccuracyError {
    /// Truth and estimate sequences differ in length.
    #[error("truth has {truth} samples, estimates {estimates}")]
    LengthMismatch {
        /// Truth length.
        truth: usize,
        /// Estimate length.
        estimates: usize,
    },
    /// No samples.
    #[error("no samples")]
    Empty,
}

/// Final error of one true beacon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeaconError {
    /// Beacon key.
    pub id: BeaconId,
    /// Euclidean distance between estimate and truth (m); `None` if the beacon was never mapped.
    pub error_m: Option<f64>,
}

/// Accuracy of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyReport {
    /// Samples compared.
    pub samples: usize,
    /// RMSE of the position error, m.
    pub position_rmse_m: f64,
    /// RMSE of the wrapped heading error, rad.
    pub heading_rmse_rad: f64,
    /// Largest position error, m.
    pub position_max_m: f64,
    /// Final error per true beacon, in the order given.
    pub beacons: Vec<BeaconError>,
}

/// Compares time-aligned `truth[k]` and `estimates[k]` poses, and the final beacon map
/// `mapped` against `true_beacons` (`(id, x, y)`, m). No alignment is applied (the map frame is
/// fixed by the start pose).
pub fn evaluate(
    truth: &[Pose2],
    estimates: &[Pose2],
    true_beacons: &[(BeaconId, f64, f64)],
    mapped: &[BeaconEstimate],
) -> Result<AccuracyReport, AccuracyError> {
    if truth.len() != estimates.len() {
        return Err(AccuracyError::LengthMismatch {
            truth: truth.len(),
            estimates: estimates.len(),
        });
    }
    if truth.is_empty() {
        return Err(AccuracyError::Empty);
    }
    let (mut sp, mut sh, mut max) = (0.0, 0.0, 0.0f64);
    for (t, e) in truth.iter().zip(estimates) {
        let d = t.distance(e);
        sp += d * d;
        let h = angle_diff(e.theta, t.theta);
        sh += h * h;
        max = max.max(d);
    }
    #[allow(clippy::cast_precision_loss)]
    let n = truth.len() as f64;
    let beacons = true_beacons
        .iter()
        .map(|&(id, x, y)| BeaconError {
            id,
            error_m: mapped
                .iter()
                .find(|b| b.id == id)
                .map(|b| (b.position.x - x).hypot(b.position.y - y)),
        })
        .collect();
    Ok(AccuracyReport {
        samples: truth.len(),
        position_rmse_m: (sp / n).sqrt(),
        heading_rmse_rad: (sh / n).sqrt(),
        position_max_m: max,
        beacons,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    #[test]
    fn rmse_of_known_errors() {
        let truth = vec![Pose2::new(0.0, 0.0, 3.1), Pose2::new(1.0, 0.0, 0.0)];
        let est = vec![Pose2::new(0.3, 0.4, -3.1), Pose2::new(1.0, 0.0, 0.1)];
        let mapped = [BeaconEstimate {
            id: 7,
            position: Vector2::new(3.0, 4.0),
            covariance: Matrix2::identity(),
        }];
        let r = evaluate(&truth, &est, &[(7, 0.0, 0.0), (8, 1.0, 1.0)], &mapped).unwrap();
        assert!((r.position_rmse_m - (0.25f64 / 2.0).sqrt()).abs() < 1e-12);
        // heading errors: wrap(-3.1-3.1) = 2π-6.2 ≈ 0.0832, and 0.1
        let h0 = 2.0 * std::f64::consts::PI - 6.2;
        assert!((r.heading_rmse_rad - ((h0 * h0 + 0.01) / 2.0).sqrt()).abs() < 1e-9);
        assert_eq!(r.beacons[0].error_m, Some(5.0));
        assert_eq!(r.beacons[1].error_m, None);
        assert!((r.position_max_m - 0.5).abs() < 1e-12);
    }

    #[test]
    fn mismatched_lengths_are_an_error() {
        assert_eq!(
            evaluate(&[Pose2::default()], &[], &[], &[]),
            Err(AccuracyError::LengthMismatch {
                truth: 1,
                estimates: 0
            })
        );
        assert_eq!(evaluate(&[], &[], &[], &[]), Err(AccuracyError::Empty));
    }
}
