//! The navigation goal as a region of learned states.
//!
//! A learned state is a snapshot cluster, so it fixes a heading as well as a place: the seed's
//! single goal state asks the robot to arrive facing the way the goal state's snapshots were
//! taken. Here every state whose mean position lies within `radius` of the goal point belongs to
//! the goal; their transitions are merged into one goal state before value iteration, and the
//! navigator sees any member as that goal state.

use rfloc_sim::Point;
use rfloc_snapshot::{Action, Plan, PlanConfig, SnapshotDatabase, SnapshotError, TransitionCounts};

/// Goal states and the state map used for planning and navigation.
#[derive(Debug, Clone, PartialEq)]
pub struct GoalRegion {
    /// Planning state of every database state (goal members map to [`Self::goal`]).
    map: Vec<usize>,
    /// The merged goal state.
    pub goal: usize,
    /// Number of database states in the region.
    pub members: usize,
}

impl GoalRegion {
    /// States within `radius` of `point` (the nearest state when none is).
    #[must_use]
    pub fn around(db: &SnapshotDatabase, point: &Point, radius: f64) -> Option<Self> {
        let d: Vec<f64> = db
            .states
            .iter()
            .map(|s| (s.pose.x - point.x).hypot(s.pose.y - point.y))
            .collect();
        let nearest = d
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, _)| i)?;
        let inside = |i: usize| i == nearest || d.get(i).is_some_and(|x| *x <= radius);
        let goal = (0..db.states.len()).find(|&i| inside(i))?;
        let map: Vec<usize> = (0..db.state_count())
            .map(|i| {
                if i < db.states.len() && inside(i) {
                    goal
                } else {
                    i
                }
            })
            .collect();
        let members = (0..db.states.len()).filter(|&i| inside(i)).count();
        Some(Self { map, goal, members })
    }

    /// The planning state of a database state.
    #[must_use]
    pub fn planning_state(&self, state: usize) -> usize {
        self.map.get(state).copied().unwrap_or(state)
    }

    /// Value-iteration plan over the database's transition counts with the region merged.
    ///
    /// # Errors
    /// What [`Plan::solve`] reports.
    pub fn plan(&self, db: &SnapshotDatabase, config: &PlanConfig) -> Result<Plan, SnapshotError> {
        let n = db.state_count();
        let mut merged = TransitionCounts::new(n);
        for action in Action::ALL {
            for from in 0..n {
                if db.counts.row_total(from, action) <= 0.0 {
                    continue;
                }
                for to in 0..n {
                    let c = db.counts.count(from, action, to);
                    if c > 0.0 {
                        merged.record_weighted(
                            self.planning_state(from),
                            action,
                            self.planning_state(to),
                            c,
                        )?;
                    }
                }
            }
        }
        let model = merged.to_model(&db.config.prior);
        Plan::solve(&model, self.goal, Some(db.no_tags_state()), config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfloc_pose::Pose2;
    use rfloc_snapshot::{
        ClusterCount, ClusteringMethod, LearnConfig, Observation, Snapshot, TagId,
    };

    /// Four places on a line, each with its own tag; forward moves one place right.
    fn line_db() -> SnapshotDatabase {
        let mut obs = Vec::new();
        for _ in 0..5 {
            for x in 0..4u8 {
                obs.push(Observation {
                    snapshot: Snapshot::from_reads([(TagId::new(vec![x]), 3000.0)]),
                    pose: Pose2::new(f64::from(x), 0.0, 0.0),
                    action: (x < 3).then_some(Action::Forward),
                });
            }
        }
        let config = LearnConfig {
            clustering: ClusteringMethod::KMedoids {
                k: ClusterCount::Fixed(4),
                max_iter: 50,
                seed: 1,
            },
            ..LearnConfig::default()
        };
        SnapshotDatabase::learn(&obs, &config).unwrap()
    }

    fn state_at(db: &SnapshotDatabase, x: f64) -> usize {
        db.states
            .iter()
            .position(|s| (s.pose.x - x).abs() < 1e-9)
            .unwrap()
    }

    #[test]
    fn region_merges_nearby_states_and_the_plan_leads_into_it() {
        let db = line_db();
        assert_eq!(db.states.len(), 4);
        let region = GoalRegion::around(&db, &Point::new(2.5, 0.0), 0.6).unwrap();
        assert_eq!(region.members, 2);
        let (s0, s1, s2, s3) = (
            state_at(&db, 0.0),
            state_at(&db, 1.0),
            state_at(&db, 2.0),
            state_at(&db, 3.0),
        );
        assert_eq!(region.planning_state(s2), region.goal);
        assert_eq!(region.planning_state(s3), region.goal);
        assert_eq!(region.planning_state(s0), s0);
        assert_eq!(
            region.planning_state(db.no_tags_state()),
            db.no_tags_state()
        );
        let plan = region.plan(&db, &PlanConfig::default()).unwrap();
        assert_eq!(plan.policy[s0], Action::Forward);
        assert_eq!(plan.policy[s1], Action::Forward);
        // No state near the point: the nearest one alone is the goal.
        let far = GoalRegion::around(&db, &Point::new(0.0, 3.0), 0.4).unwrap();
        assert_eq!((far.members, far.goal), (1, s0));
    }
}
