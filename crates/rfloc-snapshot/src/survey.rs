//! The survey: every exploration snapshot with the pose the robot believed it had (odometry).
//!
//! It is what the robot learns everything else from ([`crate::TagMap`], the fingerprints that
//! propose poses to [`crate::TrackFilter`], the cluster database), so a live robot keeps it
//! next to them. Saved as JSON, atomically (`store`).

use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

use crate::action::{integrate, Action, ActionTable};
use crate::distance::SnapshotDistance;
use crate::lattice::{ActionModel, LatticeConfig, LatticePlan};
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
    /// The action driven after the snapshot, towards the next sample (none for the last one,
    /// or when not recorded).
    #[serde(default)]
    pub action: Option<Action>,
    /// The wheels stalled during that action (a wall was in the way).
    #[serde(default)]
    pub stalled: bool,
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
                    action: None,
                    stalled: false,
                })
                .collect(),
        }
    }

    /// A survey of `(snapshot, pose, action driven next, whether it stalled)`.
    #[must_use]
    pub fn with_actions<'a>(
        samples: impl IntoIterator<Item = (&'a Snapshot, Pose2, Option<Action>, bool)>,
    ) -> Self {
        Self {
            format_version: SURVEY_FORMAT_VERSION,
            samples: samples
                .into_iter()
                .map(|(s, p, action, stalled)| SurveySample {
                    pose: p,
                    snapshot: s.clone(),
                    action,
                    stalled,
                })
                .collect(),
        }
    }

    /// The poses of the samples.
    #[must_use]
    pub fn poses(&self) -> Vec<Pose2> {
        self.samples.iter().map(|s| s.pose).collect()
    }

    /// The learned motion of each action: the mean odometry increment of the recorded actions
    /// that did not stall (`fallback` for an action never driven).
    #[must_use]
    pub fn action_model(&self, fallback: &[Pose2; 5]) -> ActionModel {
        ActionModel::learn(
            self.samples
                .windows(2)
                .filter_map(|w| match (w.first(), w.get(1)) {
                    (Some(a), Some(b)) if !a.stalled => a.action.map(|act| (&a.pose, act, &b.pose)),
                    _ => None,
                }),
            fallback,
        )
    }

    /// Value iteration to `goal` over the surveyed floor (`LatticePlan`), with the learned
    /// motion of each action (the nominal `table` command over `action_duration_s` for an action
    /// never driven) and the stall places as walls.
    #[must_use]
    pub fn lattice_plan(
        &self,
        table: &ActionTable,
        action_duration_s: f64,
        goal: (f64, f64),
        goal_radius: f64,
        config: LatticeConfig,
    ) -> LatticePlan {
        let fallback =
            Action::ALL.map(|a| integrate(&Pose2::default(), table.nominal(a), action_duration_s));
        LatticePlan::solve(
            self.action_model(&fallback),
            &self.poses(),
            &self.stall_places(),
            goal,
            goal_radius,
            config,
        )
    }

    /// Where the wheels stalled: the pose after each stalled action (a wall is near).
    #[must_use]
    pub fn stall_places(&self) -> Vec<Pose2> {
        self.samples
            .windows(2)
            .filter_map(|w| match (w.first(), w.get(1)) {
                (Some(a), Some(b)) if a.stalled => Some(b.pose),
                _ => None,
            })
            .collect()
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::tag::TagId;

    #[test]
    fn actions_and_stalls_come_from_consecutive_samples() {
        let s = Snapshot::from_reads([(TagId::new(vec![1]), 2000.0)]);
        let poses = [
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(0.2, 0.0, 0.0),
            Pose2::new(0.4, 0.0, 0.0),
            Pose2::new(0.4, 0.0, 0.0),
            Pose2::new(0.4, 0.0, 0.3),
        ];
        let acts = [
            (Some(Action::Forward), false),
            (Some(Action::Forward), false),
            (Some(Action::Forward), true),
            (Some(Action::RotateLeft), false),
            (None, false),
        ];
        let survey = Survey::with_actions(
            poses
                .iter()
                .zip(acts)
                .map(|(p, (a, stalled))| (&s, *p, a, stalled)),
        );
        let fallback = [Pose2::new(9.0, 9.0, 0.0); 5];
        let model = survey.action_model(&fallback);
        // The stalled forward step does not count; rotations and the unseen arcs.
        assert!((model.increment(Action::Forward).x - 0.2).abs() < 1e-12);
        assert!((model.increment(Action::RotateLeft).theta - 0.3).abs() < 1e-12);
        assert_eq!(model.increment(Action::ArcLeft), fallback[1]);
        assert_eq!(survey.stall_places(), vec![poses[3]]);
        assert_eq!(survey.poses().len(), 5);
        // A survey written without actions still reads, with none recorded.
        let old = r#"{"format_version":1,"samples":[{"pose":{"x":1.0,"y":2.0,"theta":0.5},"snapshot":{"01":2000.0}}]}"#;
        let back: Survey = serde_json::from_str(old).unwrap();
        assert_eq!(back.samples[0].action, None);
        assert!(!back.samples[0].stalled);
    }
}
