//! UHF snapshot pipeline (seed 000) on a live robot.
//!
//! Two localisers, chosen by what the state folder holds:
//! - **tag map** (`[estimator] survey` and `tag_map` set and loadable): a particle filter over
//!   `(x, y, θ)` moved by the base's odometry between snapshots and weighed by each snapshot
//!   against the learned tag positions under the reader model stored with the map; the survey's
//!   fingerprints propose poses (global localisation at the first snapshot, recovery after a
//!   kidnap). The pose is the local mean of the heaviest mode with the particles' covariance;
//!   `fix` when that mode holds most of the weight and is tight, `degraded` otherwise.
//! - **cluster database** (`[estimator] database`, the seed's method): a histogram filter over
//!   the learned states, updated with each snapshot.
//!
//! All files come from an exploration run (`rfloc sim` writes them per trial) and are read
//! from `[state] dir`. Without any, the pipeline publishes nothing and says why once.

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::{EstimateMode, Pose2, PoseEstimate};
use rfloc_snapshot::{
    FilterConfig, FingerprintMap, LearnConfig, Snapshot, SnapshotDatabase, StateFilter, Survey,
    TagId, TagMap, TrackConfig, TrackFilter,
};

use crate::config::SnapshotSettings;
use crate::events::DeviceEvent;
use crate::pipeline::goal::{GoalDrive, GoalSettings};
use crate::pipeline::{Goal, Pipeline, Request};

/// A tag-map pose is a `fix` when the heaviest mode holds this much of the weight ...
pub const FIX_MASS: f64 = 0.8;
/// ... and its particles' RMS distance from the estimate is at most this, metres.
pub const FIX_SPREAD_M: f64 = 0.3;
/// An odometry step longer than this between two snapshots is a rebase (the base reconnected
/// and its odometry restarted), not motion, metres.
const MAX_ODOMETRY_STEP_M: f64 = 2.0;

/// The particle filter on the tag map.
struct MapLocaliser {
    tags: TagMap,
    prints: FingerprintMap,
    filter: TrackFilter,
    rng: ChaCha8Rng,
    /// The base's latest odometry pose, and the one at the last snapshot.
    odometry: Option<Pose2>,
    at_last_snapshot: Option<Pose2>,
}

impl MapLocaliser {
    /// A localiser on `tags`, its proposals from the survey's fingerprints.
    fn new(tags: TagMap, survey: &Survey, seed: u64) -> Self {
        Self {
            tags,
            prints: survey.fingerprints(LearnConfig::default().distance),
            filter: TrackFilter::new(TrackConfig::default()),
            rng: ChaCha8Rng::seed_from_u64(seed),
            odometry: None,
            at_last_snapshot: None,
        }
    }

    fn on_snapshot(&mut self, t: f64, snapshot: &Snapshot) -> Option<PoseEstimate> {
        if let (Some(now), Some(before)) = (self.odometry, self.at_last_snapshot) {
            let step = now.relative_to(&before);
            if step.x.hypot(step.y) <= MAX_ODOMETRY_STEP_M {
                self.filter.predict(&step, &mut self.rng);
            } else {
                tracing::warn!(
                    step_m = step.x.hypot(step.y),
                    "odometry jumped between snapshots: taken as a rebase"
                );
            }
        }
        self.at_last_snapshot = self.odometry;
        self.filter
            .update_with_map(&self.tags, &self.prints, snapshot, &mut self.rng);
        let e = self.filter.estimate()?;
        let mode = if e.mass >= FIX_MASS && e.spread <= FIX_SPREAD_M {
            EstimateMode::Fix
        } else {
            EstimateMode::Degraded
        };
        Some(PoseEstimate {
            time: t,
            pose: e.pose,
            covariance: e.covariance,
            mode,
            source: "snapshot".into(),
        })
    }
}

enum Localiser {
    Map(Box<MapLocaliser>),
    Clusters(Box<(SnapshotDatabase, StateFilter)>),
}

/// Snapshot localisation on the learned state, and optionally driving to a goal.
pub struct SnapshotPipeline {
    localiser: Option<Localiser>,
    goal: Option<GoalDrive>,
    /// The survey a tag-map localiser was learned with: goals are planned over it.
    survey: Option<Box<Survey>>,
    /// How goal drives step (`goal` is set per drive).
    drive: GoalSettings,
    /// A stop to send after a goal was taken away.
    stop_pending: bool,
    path: PathBuf,
    warned: bool,
}

fn drive_settings(settings: &SnapshotSettings) -> GoalSettings {
    GoalSettings {
        goal: settings.goal.map_or((0.0, 0.0), |[x, y]| (x, y)),
        radius_m: settings.goal_radius_m,
        action_duration_s: settings.action_duration_s,
        drive_duration_s: settings.drive_duration_s,
    }
}

impl std::fmt::Debug for SnapshotPipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SnapshotPipeline")
            .field("path", &self.path)
            .field(
                "localiser",
                &match &self.localiser {
                    Some(Localiser::Map(_)) => "tag map",
                    Some(Localiser::Clusters(_)) => "cluster database",
                    None => "none",
                },
            )
            .field("goal", &self.goal.as_ref().map(GoalDrive::phase))
            .finish()
    }
}

/// `path` relative to the state folder unless absolute.
/// The file that holds `name` of the state folder: through the folder's learned-state set
/// (`state-manifest.json`, checked) when it has one. Absolute paths are taken as they are.
fn state_file(name: &Path, state_dir: Option<&Path>) -> Result<PathBuf, String> {
    match state_dir {
        Some(dir) if name.is_relative() => {
            rfloc_snapshot::state_set::resolve(dir, name).map_err(|e| e.to_string())
        }
        Some(dir) => Ok(dir.join(name)),
        None => Ok(name.to_path_buf()),
    }
}

/// Loads every learned file the settings name, as a run would (`rfloc validate`).
pub fn load_learned_check(
    settings: &SnapshotSettings,
    state_dir: Option<&Path>,
) -> Result<(), String> {
    load_learned(settings, state_dir).map(drop)
}

/// Loads (and checks) every learned file the settings name; the error says which and why.
fn load_learned(
    settings: &SnapshotSettings,
    state_dir: Option<&Path>,
) -> Result<(Localiser, Option<Survey>), String> {
    if let (Some(survey), Some(tag_map)) = (&settings.survey, &settings.tag_map) {
        let survey_path = state_file(survey, state_dir)?;
        let map_path = state_file(tag_map, state_dir)?;
        let survey = Survey::load(&survey_path).map_err(|e| format!("survey: {e}"))?;
        let tags = TagMap::load(&map_path).map_err(|e| format!("tag map: {e}"))?;
        tracing::info!(
            survey = %survey_path.display(),
            tag_map = %map_path.display(),
            "tag map and survey loaded"
        );
        let map = MapLocaliser::new(tags, &survey, settings.seed);
        return Ok((Localiser::Map(Box::new(map)), Some(survey)));
    }
    let path = state_file(&settings.database, state_dir)?;
    let db = SnapshotDatabase::load(&path).map_err(|e| format!("database: {e}"))?;
    tracing::info!(path = %path.display(), states = db.state_count(), "learned snapshot database loaded");
    let filter = StateFilter::new(&db, FilterConfig::default());
    Ok((Localiser::Clusters(Box::new((db, filter))), None))
}

impl SnapshotPipeline {
    /// A pipeline on a tag map and survey already in memory (what a simulated trial has just
    /// learned and reloaded), its filter's draws seeded with `seed`.
    #[must_use]
    pub fn on_tag_map(tags: TagMap, survey: &Survey, seed: u64) -> Self {
        Self {
            localiser: Some(Localiser::Map(Box::new(MapLocaliser::new(
                tags, survey, seed,
            )))),
            goal: None,
            survey: Some(Box::new(survey.clone())),
            drive: drive_settings(&SnapshotSettings::default()),
            stop_pending: false,
            path: PathBuf::from("(in memory)"),
            warned: false,
        }
    }

    /// Loads the learned files named in the settings (relative paths from `state_dir`, through
    /// its learned-state set): the survey and tag map when both are set, the cluster database
    /// otherwise. A file that is missing, damaged or from another set is an error.
    pub fn new(settings: &SnapshotSettings, state_dir: Option<&Path>) -> Result<Self, String> {
        if let Some(dir) = state_dir {
            if let Ok(removed) = rfloc_snapshot::state_set::clean_stale(dir) {
                for p in removed {
                    tracing::warn!(path = %p.display(), "removed what an interrupted save left");
                }
            }
        }
        let path = state_file(&settings.database, state_dir).unwrap_or_default();
        let (localiser, survey) = load_learned(settings, state_dir)?;
        let drive = drive_settings(settings);
        let goal = match (&survey, settings.goal) {
            (Some(survey), Some(_)) => Some(GoalDrive::plan(survey, drive)),
            _ => None,
        };
        Ok(Self {
            localiser: Some(localiser),
            goal,
            survey: survey.map(Box::new),
            drive,
            stop_pending: false,
            path,
            warned: false,
        })
    }
}

impl Pipeline for SnapshotPipeline {
    fn name(&self) -> &'static str {
        "snapshot"
    }

    fn take_requests(&mut self) -> Vec<Request> {
        let mut out = self
            .goal
            .as_mut()
            .map(GoalDrive::take_requests)
            .unwrap_or_default();
        if std::mem::take(&mut self.stop_pending) {
            out.push(Request::Velocity { v: 0.0, w: 0.0 });
        }
        out
    }

    /// With a tag map and its survey: a goal is planned over the survey (value iteration, as the
    /// robot file's `goal`) and driven to in seed actions until steady fixes are within the
    /// smaller of `goal_radius_m` and the goal's tolerance. The cluster database cannot drive.
    fn drives_to_goals(&self) -> bool {
        self.survey.is_some()
    }

    fn set_goal(&mut self, goal: Option<Goal>) -> bool {
        let Some(survey) = self.survey.as_deref() else {
            return false;
        };
        match goal {
            Some(g) => {
                let settings = GoalSettings {
                    goal: (g.x, g.y),
                    radius_m: self.drive.radius_m.min(g.tolerance_m),
                    ..self.drive
                };
                // The same goal again keeps the drive (and its plan) going.
                if self.goal.as_ref().is_some_and(|d| d.settings() == settings) {
                    return true;
                }
                let was_driving = self.goal.is_some();
                self.goal = Some(GoalDrive::plan(survey, settings));
                self.stop_pending = was_driving;
            }
            None => {
                self.stop_pending = self.goal.take().is_some();
            }
        }
        true
    }

    fn handle(&mut self, event: &DeviceEvent) -> Option<PoseEstimate> {
        let (t, tags) = match event {
            DeviceEvent::UhfSnapshot { t, tags, .. } => (*t, tags),
            DeviceEvent::WheelStall { t, .. } => {
                if let Some(g) = &mut self.goal {
                    g.on_stall(*t);
                }
                return None;
            }
            DeviceEvent::Odometry { t, pose, v, w, .. } => {
                if let Some(Localiser::Map(m)) = &mut self.localiser {
                    m.odometry = Some(*pose);
                }
                if let Some(g) = &mut self.goal {
                    g.on_odometry(*t, *v, *w);
                }
                return None;
            }
            _ => return None,
        };
        let Some(localiser) = &mut self.localiser else {
            if !self.warned {
                self.warned = true;
                tracing::error!(path = %self.path.display(), "snapshots arrive but nothing is learned: no poses");
            }
            return None;
        };
        let snapshot = Snapshot::from_reads(
            tags.iter()
                .filter_map(|(id, rss)| Some((TagId::from_hex(id)?, *rss))),
        );
        match localiser {
            Localiser::Map(m) => {
                let estimate = m.on_snapshot(t, &snapshot)?;
                if let Some(g) = &mut self.goal {
                    g.on_estimate(&estimate);
                }
                Some(estimate)
            }
            Localiser::Clusters(c) => {
                let (db, filter) = &mut **c;
                filter.update(db, &snapshot);
                let mut est = filter.estimate(db, t);
                est.source = "snapshot".into();
                Some(est)
            }
        }
    }
}
