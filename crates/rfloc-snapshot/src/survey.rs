//! The survey: every exploration snapshot with the pose the robot believed it had (odometry).
//!
//! It is what the robot learns everything else from ([`crate::TagMap`], the fingerprints that
//! propose poses to [`crate::TrackFilter`], the cluster database), so a live robot keeps it
//! next to them. Saved as JSON, atomically (`store`).

use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

use crate::distance::SnapshotDistance;
use crate::snapshot::Snapshot;
use crate::track::FingerprintMap;

/// Layout version of a saved survey.
pub const SURVEY_FORMAT_VERSION: u32 = 1;

/// One surveyed place.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurveySample {
    pub pose: Pose2,
    pub snapshot: Snapshot,
}

/// The exploration snapshots with their poses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Survey {
    pub format_version: u32,
    pub samples: Vec<SurveySample>,
}

impl Survey {
    /// A survey of `(snapshot, pose)` pairs.
    #[must_use]
    pub fn new<'a>(samples: impl IntoIterator<Item = (&'a Snapshot, Pose2)>) -> Self {
        Self {
            format_version: SURVEY_FORMAT_VERSION,
            samples: samples
                .into_iter()
                .map(|(s, p)| SurveySample {
                    pose: p,
                    snapshot: s.clone(),
                })
                .collect(),
        }
    }

    /// The samples as `(snapshot, pose)` pairs, as the learners take them.
    pub fn pairs(&self) -> impl Iterator<Item = (&Snapshot, Pose2)> + '_ {
        self.samples.iter().map(|s| (&s.snapshot, s.pose))
    }

    /// The fingerprint map of the survey.
    #[must_use]
    pub fn fingerprints(&self, distance: SnapshotDistance) -> FingerprintMap {
        FingerprintMap::new(self.pairs(), distance)
    }
}
