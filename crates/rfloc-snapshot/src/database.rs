//! The learned database: states (medoid snapshots with positions) and transition models.

use serde::{Deserialize, Serialize};

use rfloc_pose::{angle_diff, Pose2};

use crate::action::Action;
use crate::cluster::{cluster, ClusteringMethod};
use crate::distance::{DissimilarityMatrix, IndexedSnapshot, SnapshotDistance, TagIndex};
use crate::error::SnapshotError;
use crate::snapshot::Snapshot;
use crate::transition::{TransitionCounts, TransitionModel, TransitionPrior};

/// Version of the stored database layout.
pub const FORMAT_VERSION: u32 = 1;

/// Everything that shapes what is learned.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct LearnConfig {
    /// Snapshot dissimilarity used for clustering and localisation.
    pub distance: SnapshotDistance,
    /// Clustering method and parameters.
    pub clustering: ClusteringMethod,
    /// Prior of the transition model.
    pub prior: TransitionPrior,
}

impl LearnConfig {
    /// FNV-1a 64-bit hash of the configuration's JSON text, as 16 hex digits. Stored with the
    /// database so that a database learned under another configuration can be recognised.
    #[must_use]
    pub fn hash(&self) -> String {
        let text = serde_json::to_string(self).unwrap_or_default();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in text.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        format!("{h:016x}")
    }
}

/// One learning sample: the snapshot taken at a pose, and the action executed right after it
/// (`None` when the next sample does not follow from this one, e.g. at the end of a run).
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// The (averaged, thresholded) snapshot.
    pub snapshot: Snapshot,
    /// True or odometry pose when the snapshot was taken (metres, radians).
    pub pose: Pose2,
    /// Action executed between this sample and the next.
    pub action: Option<Action>,
}

/// A learned state: a cluster of snapshots represented by its medoid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LearnedState {
    /// The medoid snapshot.
    pub prototype: Snapshot,
    /// Mean position of the member snapshots' poses; heading is their circular mean.
    pub pose: Pose2,
    /// Sample covariance of the members' `(x, y, θ)` about `pose` (row-major 3×3; θ deviations
    /// wrapped). Zero for a single member.
    pub covariance: [[f64; 3]; 3],
    /// Number of member snapshots.
    pub members: usize,
}

/// The nearest state of a snapshot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Localisation {
    /// State index; [`SnapshotDatabase::no_tags_state`] for an empty snapshot.
    pub state: usize,
    /// Dissimilarity to that state's prototype.
    pub distance: f64,
}

/// States, transitions and the configuration they were learned with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SnapshotDatabase {
    /// Layout version ([`FORMAT_VERSION`]).
    pub format_version: u32,
    /// Configuration used to learn.
    pub config: LearnConfig,
    /// [`LearnConfig::hash`] of `config`.
    pub config_hash: String,
    /// Learned states; index `states.len()` is the extra "no tags visible" state.
    pub states: Vec<LearnedState>,
    /// Raw transition counts over `states.len() + 1` states.
    pub counts: TransitionCounts,
    /// Transition probabilities (counts with the prior applied).
    pub transitions: TransitionModel,
    /// Prototypes with interned tag IDs, for fast comparisons (derived, not stored).
    #[serde(skip)]
    lookup: StateLookup,
}

/// Prototypes with interned tag IDs; the last entry is the empty no-tags prototype.
#[derive(Debug, Clone, Default, PartialEq)]
struct StateLookup {
    tags: TagIndex,
    prototypes: Vec<IndexedSnapshot>,
}

impl SnapshotDatabase {
    /// Learns states and transitions from an exploration run.
    ///
    /// Non-empty snapshots are clustered; each cluster becomes a state. Consecutive samples
    /// linked by an action give one transition count each, using the cluster assignment of the
    /// samples (empty snapshots map to the no-tags state).
    ///
    /// # Errors
    /// [`SnapshotError::LearningData`] when no sample has a tag.
    pub fn learn(
        observations: &[Observation],
        config: &LearnConfig,
    ) -> Result<Self, SnapshotError> {
        let seen: Vec<usize> = observations
            .iter()
            .enumerate()
            .filter(|(_, o)| !o.snapshot.is_empty())
            .map(|(i, _)| i)
            .collect();
        if seen.is_empty() {
            return Err(SnapshotError::LearningData("no snapshot with tags".into()));
        }
        let snaps: Vec<Snapshot> = seen
            .iter()
            .filter_map(|&i| observations.get(i))
            .map(|o| o.snapshot.clone())
            .collect();
        let d = DissimilarityMatrix::from_snapshots(&snaps, config.distance);
        let clustering = cluster(&d, &config.clustering);
        let k = clustering.medoids.len();
        let mut members: Vec<Vec<Pose2>> = vec![Vec::new(); k];
        for (local, &c) in clustering.assignment.iter().enumerate() {
            if let (Some(m), Some(o)) = (
                members.get_mut(c),
                seen.get(local).and_then(|&i| observations.get(i)),
            ) {
                m.push(o.pose);
            }
        }
        let states: Vec<LearnedState> = clustering
            .medoids
            .iter()
            .zip(&members)
            .map(|(&m, poses)| {
                let (pose, covariance) = pose_statistics(poses);
                LearnedState {
                    prototype: snaps.get(m).cloned().unwrap_or_default(),
                    pose,
                    covariance,
                    members: poses.len(),
                }
            })
            .collect();
        let no_tags = k;
        let mut state_of = vec![no_tags; observations.len()];
        for (local, &c) in clustering.assignment.iter().enumerate() {
            if let Some(slot) = seen.get(local).and_then(|&i| state_of.get_mut(i)) {
                *slot = c;
            }
        }
        let mut counts = TransitionCounts::new(k + 1);
        for (i, pair) in observations.windows(2).enumerate() {
            if let (Some(first), Some(from), Some(to)) =
                (pair.first(), state_of.get(i), state_of.get(i + 1))
            {
                if let Some(action) = first.action {
                    counts.record(*from, action, *to)?;
                }
            }
        }
        let transitions = counts.to_model(&config.prior);
        tracing::debug!(
            states = k,
            samples = observations.len(),
            loss = clustering.loss,
            "snapshot database learned"
        );
        let mut db = Self {
            format_version: FORMAT_VERSION,
            config: *config,
            config_hash: config.hash(),
            states,
            counts,
            transitions,
            lookup: StateLookup::default(),
        };
        db.rebuild_lookup();
        Ok(db)
    }

    /// Index of the "no tags visible" state (= number of learned states).
    #[must_use]
    pub fn no_tags_state(&self) -> usize {
        self.states.len()
    }

    /// Number of states including the no-tags state.
    #[must_use]
    pub fn state_count(&self) -> usize {
        self.states.len() + 1
    }

    /// Rebuilds the interned-ID lookup (done by [`Self::learn`] and [`Self::load`]; call it
    /// after deserialising or editing `states` by other means).
    pub fn rebuild_lookup(&mut self) {
        let mut tags = TagIndex::default();
        let mut prototypes: Vec<IndexedSnapshot> = self
            .states
            .iter()
            .map(|s| tags.index(&s.prototype))
            .collect();
        prototypes.push(IndexedSnapshot::default());
        self.lookup = StateLookup { tags, prototypes };
    }

    /// Dissimilarity of a snapshot to every state (the no-tags state's prototype is the empty
    /// snapshot).
    #[must_use]
    pub fn distances(&self, snapshot: &Snapshot) -> Vec<f64> {
        if self.lookup.prototypes.len() == self.state_count() {
            let q = self.lookup.tags.index_query(snapshot);
            return self
                .lookup
                .prototypes
                .iter()
                .map(|p| self.config.distance.between_indexed(&q, p))
                .collect();
        }
        let empty = Snapshot::new();
        self.states
            .iter()
            .map(|s| self.config.distance.between(snapshot, &s.prototype))
            .chain(std::iter::once(
                self.config.distance.between(snapshot, &empty),
            ))
            .collect()
    }

    /// The seed's localisation: the state whose prototype is nearest (lowest index on ties);
    /// an empty snapshot gives the no-tags state.
    #[must_use]
    pub fn localise(&self, snapshot: &Snapshot) -> Localisation {
        if snapshot.is_empty() {
            return Localisation {
                state: self.no_tags_state(),
                distance: 0.0,
            };
        }
        self.distances(snapshot)
            .into_iter()
            .take(self.states.len())
            .enumerate()
            .fold(
                Localisation {
                    state: self.no_tags_state(),
                    distance: f64::INFINITY,
                },
                |best, (i, d)| {
                    if d < best.distance {
                        Localisation {
                            state: i,
                            distance: d,
                        }
                    } else {
                        best
                    }
                },
            )
    }

    /// Adds one transition observed later (e.g. during navigation), localising both snapshots,
    /// and refreshes the probabilities of the affected row.
    ///
    /// # Errors
    /// Never in practice (indices come from [`Self::localise`]); kept for out-of-range safety.
    pub fn record_transition(
        &mut self,
        before: &Snapshot,
        action: Action,
        after: &Snapshot,
    ) -> Result<(usize, usize), SnapshotError> {
        let from = self.localise(before).state;
        let to = self.localise(after).state;
        self.counts.record(from, action, to)?;
        self.transitions = self.counts.to_model(&self.config.prior);
        Ok((from, to))
    }
}

/// Mean pose (circular mean heading) and covariance of a set of poses.
fn pose_statistics(poses: &[Pose2]) -> (Pose2, [[f64; 3]; 3]) {
    let n = poses.len();
    if n == 0 {
        return (Pose2::default(), [[0.0; 3]; 3]);
    }
    let nf = n as f64;
    let mx = poses.iter().map(|p| p.x).sum::<f64>() / nf;
    let my = poses.iter().map(|p| p.y).sum::<f64>() / nf;
    let (s, c) = poses.iter().fold((0.0, 0.0), |(s, c), p| {
        (s + p.theta.sin(), c + p.theta.cos())
    });
    let mean = Pose2::new(mx, my, s.atan2(c));
    let mut cov = [[0.0; 3]; 3];
    if n > 1 {
        for p in poses {
            let e = [p.x - mx, p.y - my, angle_diff(p.theta, mean.theta)];
            for (r, er) in cov.iter_mut().zip(e) {
                for (cell, ec) in r.iter_mut().zip(e) {
                    *cell += er * ec / (nf - 1.0);
                }
            }
        }
    }
    (mean, cov)
}
