//! Scenario files: one experiment = a world (file or inline), robot start, goal and/or
//! waypoints, duration, seeds, trial count, pipeline and sensor-model overrides.
//! See `docs/simulator.md` for the format; every file in `scenarios/` is loaded by a test.

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rfloc_pose::Pose2;
use serde::{Deserialize, Serialize};

use crate::emitter::EmitterModel;
use crate::error::{find_key_line, from_toml, SimError};
use crate::geometry::Point;
use crate::hf::HfModel;
use crate::kinematics::DiffDriveParams;
use crate::scanner::RangeScanner;
use crate::uhf::UhfModel;
use crate::world::{World, WorldSpec};
use crate::xbee::{RangeBearingNoise, XbeeModel};

/// Step of the lock-step trials: the emulated Pioneer's SIP period, seconds.
pub const SIP_PERIOD_S: f64 = 0.1;

/// Which rfloc pipeline a scenario exercises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pipeline {
    /// UHF snapshot localisation and MDP navigation (seed 000).
    Snapshot,
    /// Emitter tracking with motion planning only (seed 001, "preliminary system").
    EmitterPreliminary,
    /// Emitter tracking with mapping and A* (seed 001, "full system").
    EmitterFull,
    /// HF floor-grid initial pose (seed 002).
    HfInit,
    /// XBee EKF-SLAM with waypoint navigation (seed 003).
    EkfSlam,
}

/// TOML form of a scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioSpec {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Where the setup comes from (seed, section, table).
    #[serde(default)]
    pub source: String,
    /// The seed scenario whose published numbers the report may show beside rfloc's (a key of
    /// [`crate::published`]). They are shown only when this scenario is that seed's own
    /// experiment (same world, robot, sensors and settings; see
    /// [`Scenario::published_key`]); without it, none are shown.
    #[serde(default)]
    pub seed_reference: Option<String>,
    pub pipeline: Pipeline,
    /// A world file, relative to the scenario file. Exactly one of `world_file`/`world`.
    #[serde(default)]
    pub world_file: Option<String>,
    /// An inline world.
    #[serde(default)]
    pub world: Option<WorldSpec>,
    /// Simulated time per trial, seconds.
    pub duration_s: f64,
    /// Simulation step, seconds.
    pub dt_s: f64,
    pub trials: usize,
    /// Base seed; trial `i` uses `seed + i` for its random streams.
    pub seed: u64,
    pub robot: RobotSpec,
    #[serde(default)]
    pub goal: Option<GoalSpec>,
    /// Waypoints `[[x, y], …]` to visit in order.
    #[serde(default)]
    pub waypoints: Vec<[f64; 2]>,
    #[serde(default)]
    pub sensors: SensorSpec,
    #[serde(default)]
    pub params: PipelineParams,
    /// `[mismatch]`: give the estimator a model that differs from the simulator's.
    #[serde(default)]
    pub mismatch: Option<MismatchSpec>,
}

/// `[mismatch]`: how the estimator's model differs from the simulator's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MismatchSpec {
    /// Scale of the estimator's signal-to-distance model: for any signal level it infers a
    /// distance `scale` times the one the simulator's model gives (1.15 = ranges 15 % long).
    /// Emitter: `A1` shifted by `10·A2·log10(scale)` dB; EKF-SLAM: `P_ref` shifted by
    /// `10·η·log10(scale)` dB; HF: every RSSI band edge (cm) multiplied by `scale`; UHF
    /// snapshots: the robot's reader model reads a tag at distance `d` as the simulator's does
    /// at `d / scale` (`ReadModel::distance_scale`).
    pub scale: f64,
}

/// `[robot]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    pub start: StartSpec,
    /// Draw a collision-free random start position and heading per trial.
    #[serde(default)]
    pub random_start: bool,
    /// Start headings to cycle through over the trials (degrees), e.g. seed 002's four.
    #[serde(default)]
    pub start_headings_deg: Vec<f64>,
    #[serde(default)]
    pub drive: DiffDriveParams,
}

/// `start = { x, y, theta_deg }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartSpec {
    pub x: f64,
    pub y: f64,
    #[serde(default)]
    pub theta_deg: f64,
}

/// `[goal]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalSpec {
    pub x: f64,
    pub y: f64,
    /// Reached when the true position is within this distance, metres.
    pub tolerance_m: f64,
    /// Draw a random goal per trial (inside the area, off obstacles).
    #[serde(default)]
    pub random: bool,
}

/// `[sensors]`: model parameter overrides (any omitted field keeps its default).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    #[serde(default)]
    pub uhf: Option<UhfModel>,
    #[serde(default)]
    pub hf: Option<HfModel>,
    #[serde(default)]
    pub xbee: Option<XbeeModel>,
    #[serde(default)]
    pub xbee_range_bearing: Option<RangeBearingNoise>,
    #[serde(default)]
    pub emitter: Option<EmitterModel>,
    #[serde(default)]
    pub scanner: Option<RangeScanner>,
}

/// `[params]`: pipeline settings taken from the seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PipelineParams {
    /// Seed 000: number of exploration steps before navigation.
    #[serde(default)]
    pub exploration_steps: Option<usize>,
    /// Seed 000: maximum navigation steps before a trial counts as failed.
    #[serde(default)]
    pub navigation_steps: Option<usize>,
    /// Seed 000 Table 4: action duration, seconds.
    #[serde(default)]
    pub action_duration_s: Option<f64>,
    /// Seed 002: readings per on-the-spot turn (8, one per 45°).
    #[serde(default)]
    pub readings_per_turn: Option<usize>,
    /// Seed 003: reflector sweep steps per revolution (40 × 9°).
    #[serde(default)]
    pub sweep_steps: Option<usize>,
    /// Seed 003: driving time between two reflector sweeps, seconds (the robot stops to
    /// sweep; 3 s when absent).
    #[serde(default)]
    pub sweep_every_s: Option<f64>,
    /// Seed 003: sweeps taken standing at the start pose before driving (8 when absent).
    #[serde(default)]
    pub start_sweeps: Option<usize>,
    /// Seed 003: waypoint switching distance ρ_min, metres.
    #[serde(default)]
    pub waypoint_switch_m: Option<f64>,
    /// Seed 003: number of filter iterations.
    #[serde(default)]
    pub iterations: Option<usize>,
    /// Seed 001: particle count.
    #[serde(default)]
    pub particles: Option<usize>,
    /// Seed 001: occupancy grid cell, metres.
    #[serde(default)]
    pub grid_cell_m: Option<f64>,
    /// Seed 001 particle filter: distance offset `c_r`, metres (the seed's 1 m when absent).
    /// For experiments beyond the seed's constants.
    #[serde(default)]
    pub range_offset_m: Option<f64>,
    /// Seed 001 particle filter: angle offset `c_θ`, degrees (the seed's 15° when absent).
    #[serde(default)]
    pub angle_offset_deg: Option<f64>,
}

/// A loaded, validated scenario.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub spec: ScenarioSpec,
    pub world: World,
    /// The file it was loaded from.
    pub path: PathBuf,
}

/// Removes every `null` member of the objects in `v` (options left unset), recursively.
fn drop_nulls(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(map) => {
            map.retain(|_, m| !m.is_null());
            map.values_mut().for_each(drop_nulls);
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(drop_nulls),
        _ => {}
    }
}

fn invalid(path: &Path, text: &str, key: &str, message: impl Into<String>) -> SimError {
    SimError::Invalid {
        path: path.to_path_buf(),
        line: find_key_line(text, key),
        key: key.to_string(),
        message: message.into(),
    }
}

impl Scenario {
    /// Reads, parses and validates a scenario file (and its world file).
    pub fn load(path: &Path) -> Result<Scenario, SimError> {
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Scenario::from_toml_str(&text, path)
    }

    /// Parses and validates scenario TOML; `path` locates a relative `world_file`.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Scenario, SimError> {
        let spec: ScenarioSpec = toml::from_str(text).map_err(|e| from_toml(path, text, &e))?;
        let world = match (&spec.world_file, &spec.world) {
            (Some(f), None) => {
                let wp = path.parent().unwrap_or_else(|| Path::new(".")).join(f);
                World::load(&wp)?
            }
            (None, Some(w)) => World::resolve(w, text, path)?,
            _ => {
                return Err(invalid(
                    path,
                    text,
                    "world_file",
                    "give exactly one of `world_file` or `[world]`",
                ))
            }
        };
        let s = Scenario {
            spec,
            world,
            path: path.to_path_buf(),
        };
        s.validate(text)?;
        Ok(s)
    }

    fn validate(&self, text: &str) -> Result<(), SimError> {
        let p = &self.path;
        let sp = &self.spec;
        if sp.name.trim().is_empty() {
            return Err(invalid(p, text, "name", "must not be empty"));
        }
        // Every key written must be one the pipeline's trial acts on.
        let table: toml::Table = toml::from_str(text).map_err(|e| from_toml(p, text, &e))?;
        for key in crate::keys::written(&table) {
            if !crate::keys::is_acting(sp.pipeline, &key) {
                return Err(invalid(
                    p,
                    text,
                    &key,
                    crate::keys::why_not(sp.pipeline, &key),
                ));
            }
        }
        // Every number written in its range (a key without one at least finite). This covers
        // every single-key bound (noise, sizes, counts, `dt_s`, `trials`, the HF model,
        // `mismatch.scale`, `sweep_every_s`); what a file leaves out takes a valid default.
        // The checks below relate keys to each other and to the world.
        for (key, v) in crate::keys::numbers(&table) {
            let why = match crate::keys::range_of(&key) {
                Some(r) if !r.contains(v) => r.requirement(),
                None if !v.is_finite() => "must be a finite number".to_string(),
                _ => continue,
            };
            return Err(invalid(p, text, &key, format!("{v}: {why}")));
        }
        if let Some(r) = &sp.seed_reference {
            if crate::published::for_scenario(r).is_none() {
                return Err(invalid(
                    p,
                    text,
                    "seed_reference",
                    format!("`{r}` is not a seed scenario with published numbers"),
                ));
            }
        }
        if !(sp.duration_s.is_finite() && sp.duration_s >= sp.dt_s) {
            return Err(invalid(p, text, "duration_s", "must be at least dt_s"));
        }
        // The lock-step trials step at the emulated Pioneer's SIP period; only the snapshot
        // trial takes its action duration from `dt_s`.
        if sp.pipeline != Pipeline::Snapshot && (sp.dt_s - SIP_PERIOD_S).abs() > 1e-9 {
            return Err(invalid(
                p,
                text,
                "dt_s",
                format!(
                    "the {} trial steps at the emulated Pioneer's SIP period: dt_s must be {SIP_PERIOD_S}",
                    crate::keys::pipeline_name(sp.pipeline)
                ),
            ));
        }
        let st = sp.robot.start;
        let r = sp.robot.drive.body_radius;
        if !sp.robot.random_start
            && (!self.in_area(st.x, st.y) || self.world.disk_collides(&Point::new(st.x, st.y), r))
        {
            return Err(invalid(
                p,
                text,
                "start",
                "start must be inside the area and clear of walls",
            ));
        }
        if let Some(g) = sp.goal {
            if !(self.in_area(g.x, g.y) && g.tolerance_m.is_finite() && g.tolerance_m > 0.0) {
                return Err(invalid(
                    p,
                    text,
                    "goal",
                    "goal must be inside the area with a positive tolerance",
                ));
            }
            if !g.random && self.world.inside_obstacle(&Point::new(g.x, g.y)) {
                return Err(invalid(
                    p,
                    text,
                    "goal",
                    format!("({}, {}) is inside an obstacle", g.x, g.y),
                ));
            }
        }
        // The emitter trials home on the world's emitter and judge arrival at the goal: the
        // two must be one place.
        if let (Pipeline::EmitterPreliminary | Pipeline::EmitterFull, Some(g), Some(e)) =
            (sp.pipeline, sp.goal, &self.world.emitter)
        {
            let d = (g.x - e.position.x).hypot(g.y - e.position.y);
            if g.random || d > g.tolerance_m {
                return Err(invalid(
                    p,
                    text,
                    "goal",
                    format!(
                        "the {} trial's goal is the emitter at ({}, {}); this goal is {} \
                         (give the emitter's position, not random)",
                        crate::keys::pipeline_name(sp.pipeline),
                        e.position.x,
                        e.position.y,
                        if g.random {
                            "random".to_string()
                        } else {
                            format!("{d:.2} m from it, beyond its {} m tolerance", g.tolerance_m)
                        }
                    ),
                ));
            }
        }
        let needs_goal = matches!(
            sp.pipeline,
            Pipeline::Snapshot | Pipeline::EmitterPreliminary | Pipeline::EmitterFull
        );
        if needs_goal && sp.goal.is_none() {
            return Err(invalid(
                p,
                text,
                "goal",
                format!(
                    "the {} trial needs a [goal] (what counts as arrival)",
                    crate::keys::pipeline_name(sp.pipeline)
                ),
            ));
        }
        if let Some(w) = sp.waypoints.iter().find(|w| !self.in_area(w[0], w[1])) {
            return Err(invalid(
                p,
                text,
                "waypoints",
                format!("{w:?} is outside the area"),
            ));
        }
        if let Some(w) = sp
            .waypoints
            .iter()
            .find(|w| self.world.inside_obstacle(&Point::new(w[0], w[1])))
        {
            return Err(invalid(
                p,
                text,
                "waypoints",
                format!("{w:?} is inside an obstacle"),
            ));
        }
        match sp.pipeline {
            Pipeline::Snapshot if self.world.uhf_tags.is_empty() => {
                Err(invalid(p, text, "pipeline", "snapshot needs [uhf_tags]"))
            }
            Pipeline::HfInit if self.world.hf_tags.is_empty() => {
                Err(invalid(p, text, "pipeline", "hf-init needs [hf_grid]"))
            }
            Pipeline::EkfSlam if self.world.beacons.is_empty() || sp.waypoints.is_empty() => {
                Err(invalid(
                    p,
                    text,
                    "pipeline",
                    "ekf-slam needs [[xbee_beacons]] and waypoints",
                ))
            }
            Pipeline::EmitterPreliminary | Pipeline::EmitterFull
                if self.world.emitter.is_none() =>
            {
                Err(invalid(
                    p,
                    text,
                    "pipeline",
                    "emitter pipelines need [emitter]",
                ))
            }
            _ => Ok(()),
        }
    }

    fn in_area(&self, x: f64, y: f64) -> bool {
        x.is_finite()
            && y.is_finite()
            && x >= self.world.area_min.x
            && x <= self.world.area_max.x
            && y >= self.world.area_min.y
            && y <= self.world.area_max.y
    }

    /// The key of [`crate::published`] whose numbers the report may show: the scenario's
    /// `seed_reference`, if the scenario is that seed's own experiment, i.e. its
    /// [`Scenario::fingerprint`] equals the one recorded for the seed's file (a copy with
    /// another world, noise or setting gets none). `Err` carries the reason they are withheld.
    pub fn published_key(&self) -> Result<Option<&'static str>, String> {
        let Some(r) = &self.spec.seed_reference else {
            return Ok(None);
        };
        let Some(p) = crate::published::for_scenario(r) else {
            return Err(format!("`{r}` has no published numbers"));
        };
        let f = self.fingerprint();
        if f == p.fingerprint {
            Ok(Some(p.scenario))
        } else {
            Err(format!(
                "this scenario is not {r}'s own experiment (fingerprint {f:016x}, the seed's \
                 file {:016x}): its published numbers are not shown",
                p.fingerprint
            ))
        }
    }

    /// A 64-bit FNV-1a hash of what the experiment is: the resolved world and every scenario
    /// setting except its name, description, source, seed reference, base seed and trial
    /// count. Two files describing the same experiment have the same fingerprint. The settings
    /// are hashed as canonical JSON without the options a file leaves unset, so a new optional
    /// key does not change the fingerprint of files that do not use it.
    #[must_use]
    pub fn fingerprint(&self) -> u64 {
        let mut spec = self.spec.clone();
        spec.name.clear();
        spec.description.clear();
        spec.source.clear();
        spec.seed_reference = None;
        spec.seed = 0;
        spec.trials = 1;
        spec.world = None;
        spec.world_file = None;
        let mut settings = serde_json::to_value(&spec).unwrap_or(serde_json::Value::Null);
        drop_nulls(&mut settings);
        let text = format!("{settings}\n{:?}", self.world);
        text.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        })
    }

    /// Seed of trial `i` (base seed + i).
    #[must_use]
    pub fn trial_seed(&self, trial: usize) -> u64 {
        self.spec.seed.wrapping_add(trial as u64)
    }

    /// Start pose of trial `i`: the fixed start (with `start_headings_deg` cycled), or a
    /// seeded random collision-free pose when `random_start` is set.
    #[must_use]
    pub fn start_pose(&self, trial: usize) -> Pose2 {
        let st = self.spec.robot.start;
        let heading = self
            .spec
            .robot
            .start_headings_deg
            .get(trial % self.spec.robot.start_headings_deg.len().max(1))
            .copied()
            .unwrap_or(st.theta_deg);
        if !self.spec.robot.random_start {
            return Pose2::new(st.x, st.y, heading.to_radians());
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.trial_seed(trial) ^ 0x5354_4152_5421);
        let (x, y) = self.random_free_point(&mut rng).unwrap_or((st.x, st.y));
        Pose2::new(
            x,
            y,
            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
        )
    }

    /// Goal of trial `i` (seeded random when `goal.random`), if the scenario has one.
    #[must_use]
    pub fn goal(&self, trial: usize) -> Option<Point> {
        let g = self.spec.goal?;
        if !g.random {
            return Some(Point::new(g.x, g.y));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.trial_seed(trial) ^ 0x474F_414C);
        let (x, y) = self.random_free_point(&mut rng).unwrap_or((g.x, g.y));
        Some(Point::new(x, y))
    }

    fn random_free_point(&self, rng: &mut ChaCha8Rng) -> Option<(f64, f64)> {
        let r = self.spec.robot.drive.body_radius;
        let (lo, hi) = (self.world.area_min, self.world.area_max);
        if hi.x - lo.x <= 2.0 * r || hi.y - lo.y <= 2.0 * r {
            return None;
        }
        (0..10_000).find_map(|_| {
            let x = rng.random_range(lo.x + r..hi.x - r);
            let y = rng.random_range(lo.y + r..hi.y - r);
            (!self.world.disk_collides(&Point::new(x, y), r)).then_some((x, y))
        })
    }

    /// Number of simulation steps per trial.
    #[must_use]
    pub fn steps(&self) -> usize {
        // Validated: duration ≥ dt > 0, both finite.
        (self.spec.duration_s / self.spec.dt_s).round().max(1.0) as usize
    }

    /// UHF model with the scenario's overrides.
    #[must_use]
    pub fn uhf_model(&self) -> UhfModel {
        self.spec.sensors.uhf.unwrap_or_default()
    }
    /// HF model with the scenario's overrides.
    #[must_use]
    pub fn hf_model(&self) -> HfModel {
        self.spec.sensors.hf.unwrap_or_default()
    }
    /// XBee RSSI model with the scenario's overrides.
    #[must_use]
    pub fn xbee_model(&self) -> XbeeModel {
        self.spec.sensors.xbee.unwrap_or_default()
    }
    /// XBee range/bearing noise (seed 003 Table 3.1 by default).
    #[must_use]
    pub fn xbee_range_bearing(&self) -> RangeBearingNoise {
        self.spec.sensors.xbee_range_bearing.unwrap_or_default()
    }
    /// Emitter model with the scenario's overrides.
    #[must_use]
    pub fn emitter_model(&self) -> EmitterModel {
        self.spec.sensors.emitter.unwrap_or_default()
    }
    /// Range scanner with the scenario's overrides.
    #[must_use]
    pub fn scanner(&self) -> RangeScanner {
        self.spec.sensors.scanner.unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: &str = r#"
name = "t"
pipeline = "ekf-slam"
duration_s = 10.0
dt_s = 0.1
trials = 3
seed = 5
waypoints = [[2.0, 2.0], [2.0, 7.0]]

[robot]
start = { x = 1.0, y = 1.0 }
random_start = false

[world]
area = { min = [0.0, 0.0], max = [9.0, 9.0] }
xbee_beacons = [{ x = 0.0, y = 3.5, address = "0013A20040000001", ni = "beacon1" }]
"#;

    #[test]
    fn inline_world_loads_and_trial_seeds_step() {
        let s = Scenario::from_toml_str(S, Path::new("s.toml")).unwrap();
        assert_eq!(s.steps(), 100);
        assert_eq!(s.trial_seed(2), 7);
        assert_eq!(s.start_pose(1), Pose2::new(1.0, 1.0, 0.0));
        assert_eq!(s.xbee_range_bearing().sigma_r, 2.0);
    }

    #[test]
    fn random_start_is_seeded_and_clear() {
        let s = Scenario::from_toml_str(
            &S.replace("random_start = false", "random_start = true"),
            Path::new("s.toml"),
        )
        .unwrap();
        let a = s.start_pose(0);
        assert_eq!(a, s.start_pose(0));
        assert_ne!(a, s.start_pose(1));
        assert!(!s.world.disk_collides(&Point::new(a.x, a.y), 0.2));
    }

    #[test]
    fn validation_errors_name_key_and_line() {
        let e =
            Scenario::from_toml_str(&S.replace("trials = 3", "trials = 0"), Path::new("s.toml"))
                .unwrap_err();
        assert!(
            matches!(e, SimError::Invalid { line: 6, ref key, .. } if key == "trials"),
            "{e}"
        );
        let e = Scenario::from_toml_str(
            &S.replace("[2.0, 7.0]]", "[2.0, 17.0]]"),
            Path::new("s.toml"),
        )
        .unwrap_err();
        assert!(
            matches!(e, SimError::Invalid { line: 8, ref key, .. } if key == "waypoints"),
            "{e}"
        );
        let e = Scenario::from_toml_str(
            &S.replace("pipeline = \"ekf-slam\"", "pipeline = \"ekf\""),
            Path::new("s.toml"),
        )
        .unwrap_err();
        assert!(
            matches!(e, SimError::Toml { line: 3, ref key, .. } if key == "pipeline"),
            "{e}"
        );
    }
}
