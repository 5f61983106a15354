//! Histogram (discrete Bayes) filter over the learned states.
//!
//! Motion model: the learned transition matrix of the executed action. Measurement model:
//! `L_j = exp(−d(z, m_j) / τ)` with `d` the database's snapshot dissimilarity and `m_j` the
//! state's prototype (the empty snapshot for the no-tags state). The pose estimate is the
//! belief-weighted mean of the state positions near the most probable state, with the
//! covariance from the law of total covariance.

use nalgebra::Matrix3;
use rfloc_pose::{angle_diff, EstimateMode, Pose2, PoseEstimate};
use serde::{Deserialize, Serialize};

use crate::action::Action;
use crate::database::SnapshotDatabase;
use crate::snapshot::Snapshot;

/// Filter parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FilterConfig {
    /// Likelihood temperature τ (dissimilarity units): smaller trusts snapshots more.
    pub likelihood_scale: f64,
    /// Fraction of the belief spread uniformly at each prediction (recovers from a wrong belief
    /// or a kidnapped robot).
    pub mixing: f64,
    /// Only states within this radius (m) of the most probable state contribute to the pose
    /// estimate, so two far-apart modes are not averaged into a point between them.
    pub estimate_radius: f64,
}

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            likelihood_scale: 0.06,
            mixing: 0.1,
            estimate_radius: 1.5,
        }
    }
}

/// Belief over the database's states (the last entry is the no-tags state).
#[derive(Debug, Clone)]
pub struct StateFilter {
    config: FilterConfig,
    belief: Vec<f64>,
    last_had_tags: bool,
    updates: usize,
}

impl StateFilter {
    /// Uniform belief over `db`'s states.
    #[must_use]
    pub fn new(db: &SnapshotDatabase, config: FilterConfig) -> Self {
        let n = db.state_count();
        Self {
            config,
            belief: vec![1.0 / n as f64; n],
            last_had_tags: false,
            updates: 0,
        }
    }

    /// Current belief (sums to 1).
    #[must_use]
    pub fn belief(&self) -> &[f64] {
        &self.belief
    }

    /// Most probable state (lowest index on ties).
    #[must_use]
    pub fn map_state(&self) -> usize {
        self.belief
            .iter()
            .enumerate()
            .fold(
                (0, f64::NEG_INFINITY),
                |b, (i, p)| if *p > b.1 { (i, *p) } else { b },
            )
            .0
    }

    /// Prediction with the learned transition model of `action`.
    pub fn predict(&mut self, db: &SnapshotDatabase, action: Action) {
        let moved = db.transitions.propagate(action.index(), &self.belief);
        let n = moved.len().max(1) as f64;
        let eps = self.config.mixing.clamp(0.0, 1.0);
        self.belief = moved.iter().map(|p| (1.0 - eps) * p + eps / n).collect();
        normalise(&mut self.belief);
    }

    /// Measurement update with a snapshot.
    pub fn update(&mut self, db: &SnapshotDatabase, snapshot: &Snapshot) {
        let tau = self.config.likelihood_scale.max(1e-9);
        let d = db.distances(snapshot);
        // log-domain: subtract the smallest distance so the best likelihood is exp(0) = 1
        let dmin = d.iter().copied().fold(f64::INFINITY, f64::min);
        for (b, di) in self.belief.iter_mut().zip(&d) {
            *b *= (-(di - dmin) / tau).exp();
        }
        if !normalise(&mut self.belief) {
            // all mass underflowed: restart from the likelihood alone
            self.belief = d.iter().map(|di| (-(di - dmin) / tau).exp()).collect();
            normalise(&mut self.belief);
        }
        self.last_had_tags = !snapshot.is_empty();
        self.updates += 1;
    }

    /// Pose estimate at `time` (seconds, passed through). Mode: `NoFix` before any update,
    /// `Degraded` when the last snapshot was empty or the no-tags state is most probable,
    /// `Fix` otherwise.
    #[must_use]
    pub fn estimate(&self, db: &SnapshotDatabase, time: f64) -> PoseEstimate {
        let map = self.map_state();
        let anchor = db.states.get(map).map(|s| s.pose).or_else(|| {
            // no-tags state most probable: anchor on the best real state
            self.belief
                .iter()
                .take(db.states.len())
                .enumerate()
                .fold(None::<(usize, f64)>, |b, (i, p)| match b {
                    Some((_, bp)) if bp >= *p => b,
                    _ => Some((i, *p)),
                })
                .and_then(|(i, _)| db.states.get(i).map(|s| s.pose))
        });
        let mode = if self.updates == 0 {
            EstimateMode::NoFix
        } else if !self.last_had_tags || map == db.no_tags_state() {
            EstimateMode::Degraded
        } else {
            EstimateMode::Fix
        };
        let Some(anchor) = anchor else {
            return PoseEstimate {
                time,
                pose: Pose2::default(),
                covariance: Matrix3::identity() * 1e6,
                mode: EstimateMode::NoFix,
                source: "snapshot".into(),
            };
        };
        let r2 = self.config.estimate_radius.max(0.0).powi(2);
        let used: Vec<(f64, &crate::database::LearnedState)> = self
            .belief
            .iter()
            .zip(&db.states)
            .filter(|(p, s)| {
                **p > 0.0 && (s.pose.x - anchor.x).powi(2) + (s.pose.y - anchor.y).powi(2) <= r2
            })
            .map(|(p, s)| (*p, s))
            .collect();
        let w: f64 = used.iter().map(|u| u.0).sum();
        if w <= 0.0 {
            return PoseEstimate {
                time,
                pose: anchor,
                covariance: Matrix3::identity(),
                mode,
                source: "snapshot".into(),
            };
        }
        let mx = used.iter().map(|(p, s)| p * s.pose.x).sum::<f64>() / w;
        let my = used.iter().map(|(p, s)| p * s.pose.y).sum::<f64>() / w;
        let (ss, cc) = used.iter().fold((0.0, 0.0), |(a, b), (p, s)| {
            (a + p * s.pose.theta.sin(), b + p * s.pose.theta.cos())
        });
        let mean = Pose2::new(mx, my, ss.atan2(cc));
        let mut cov = Matrix3::zeros();
        for (p, s) in &used {
            let e = nalgebra::Vector3::new(
                s.pose.x - mx,
                s.pose.y - my,
                angle_diff(s.pose.theta, mean.theta),
            );
            let within = Matrix3::from_fn(|r, c| {
                s.covariance
                    .get(r)
                    .and_then(|row| row.get(c))
                    .copied()
                    .unwrap_or(0.0)
            });
            cov += (e * e.transpose() + within) * (*p / w);
        }
        PoseEstimate {
            time,
            pose: mean,
            covariance: cov,
            mode,
            source: "snapshot".into(),
        }
    }
}

/// Normalises in place; false when the sum is not positive and finite.
fn normalise(v: &mut [f64]) -> bool {
    let s: f64 = v.iter().sum();
    if s > 0.0 && s.is_finite() {
        v.iter_mut().for_each(|x| *x /= s);
        true
    } else {
        false
    }
}
