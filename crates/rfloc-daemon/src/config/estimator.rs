//! `[estimator]`: which pipeline runs, with its parameters and their checks.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::diag::{get, string, without, Checks, Diagnostics, Node};

/// Which estimator pipeline runs, with its parameters (`pipeline = "…"` selects it).
#[derive(Debug, Clone)]
pub enum EstimatorConfig {
    /// Wheel odometry only (no absolute fix): pose mode is `degraded`.
    Odometry,
    /// HF floor grid: initial pose from a 360° turn, then tracking.
    Hfgrid(HfGridSettings),
    /// XBee beacons: EKF-SLAM with range and bearing from the rotating antenna.
    Ekfslam(EkfSlamSettings),
    /// UHF tag snapshots: learned states, histogram filter, MDP navigation.
    Snapshot(SnapshotSettings),
    /// One RF emitter homed with four fixed receivers, a particle filter, an occupancy grid
    /// and A* (seed 001).
    Emitter(EmitterSettings),
}

/// The pipeline names, as `pipeline = "…"` takes them.
pub const PIPELINES: &[&str] = &["odometry", "hfgrid", "ekfslam", "snapshot", "emitter"];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NoSettings {}

impl EstimatorConfig {
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            EstimatorConfig::Odometry => "odometry",
            EstimatorConfig::Hfgrid(_) => "hfgrid",
            EstimatorConfig::Ekfslam(_) => "ekfslam",
            EstimatorConfig::Snapshot(_) => "snapshot",
            EstimatorConfig::Emitter(_) => "emitter",
        }
    }

    /// Driver kinds this pipeline needs.
    #[must_use]
    pub fn required_drivers(&self) -> &'static [&'static str] {
        match self {
            EstimatorConfig::Odometry => &["aria"],
            EstimatorConfig::Hfgrid(_) => &["kts"],
            EstimatorConfig::Ekfslam(_) => &["aria", "xbee", "stepper"],
            EstimatorConfig::Snapshot(_) => &["aria", "alien"],
            EstimatorConfig::Emitter(_) => &["aria", "xbee"],
        }
    }

    /// The pipeline `name` with its default parameters (a replay without a robot file).
    #[must_use]
    pub fn named(name: &str) -> Option<Self> {
        Some(match name {
            "odometry" => EstimatorConfig::Odometry,
            "hfgrid" => EstimatorConfig::Hfgrid(HfGridSettings::default()),
            "ekfslam" => EstimatorConfig::Ekfslam(EkfSlamSettings::default()),
            "snapshot" => EstimatorConfig::Snapshot(SnapshotSettings::default()),
            _ => return None,
        })
    }

    /// Parses `[estimator]`: `pipeline` selects the settings type.
    pub(crate) fn parse<'i>(node: &Node<'i>, diag: &mut Diagnostics<'i>) -> Option<Self> {
        let Some(pipeline) = get(node, "pipeline") else {
            diag.error(
                "estimator.pipeline",
                format!("missing: one of {}", PIPELINES.join(", ")),
            );
            return None;
        };
        let Some(name) = string(pipeline) else {
            diag.error("estimator.pipeline", "must be a string");
            return None;
        };
        let rest = without(node, "pipeline");
        let path = "estimator";
        Some(match name {
            "odometry" => {
                diag.deserialize::<NoSettings>(path, &rest)?;
                EstimatorConfig::Odometry
            }
            "hfgrid" => EstimatorConfig::Hfgrid(diag.deserialize(path, &rest)?),
            "ekfslam" => EstimatorConfig::Ekfslam(diag.deserialize(path, &rest)?),
            "snapshot" => EstimatorConfig::Snapshot(diag.deserialize(path, &rest)?),
            "emitter" => EstimatorConfig::Emitter(diag.deserialize(path, &rest)?),
            other => {
                diag.error(
                    "estimator.pipeline",
                    format!("{other:?} is not one of {}", PIPELINES.join(", ")),
                );
                return None;
            }
        })
    }

    /// Range checks of the parameters (keys under `estimator`).
    pub(crate) fn check(&self, c: &mut Checks<'_, '_>, env: &EstimatorEnv<'_>) {
        match self {
            EstimatorConfig::Odometry => {}
            EstimatorConfig::Hfgrid(h) => check_hfgrid(h, c, env),
            EstimatorConfig::Ekfslam(e) => check_ekfslam(e, c),
            EstimatorConfig::Snapshot(s) => check_snapshot(s, c, env),
            EstimatorConfig::Emitter(e) => check_emitter(e, c),
        }
    }
}

/// What estimator checks may look at.
pub(crate) struct EstimatorEnv<'a> {
    /// Folder of the robot file (tag map files are relative to it).
    pub config_dir: Option<&'a Path>,
    /// The `[state] dir` learned files are read from.
    pub state_dir: Option<&'a Path>,
    /// Whether files must exist here.
    pub check_files: bool,
}

fn check_hfgrid(h: &HfGridSettings, c: &mut Checks<'_, '_>, env: &EstimatorEnv<'_>) {
    c.range("pitch_m", h.pitch_m, 0.01, 10.0, " m");
    c.range("antenna_offset_m", h.antenna_offset_m, -1.0, 1.0, " m");
    c.range("rssi_distance_scale", h.rssi_distance_scale, 0.2, 5.0, "");
    for (i, t) in h.tags.iter().enumerate() {
        let mut tc = c.nested(&format!("tag[{i}]"));
        if t.uid.trim().is_empty()
            || t.uid.trim().len() > 16
            || u64::from_str_radix(t.uid.trim(), 16).is_err()
        {
            tc.error(
                "uid",
                format!("{:?} is not a tag UID (16 hex digits)", t.uid),
            );
        }
        tc.range("x", t.x, -1e5, 1e5, " m");
        tc.range("y", t.y, -1e5, 1e5, " m");
    }
    if let Some(field) = &h.tag_field {
        if crate::pipeline::builtin_tag_field(field).is_none() {
            c.error(
                "tag_field",
                format!("{field:?} is not a built-in field (seed002-test)"),
            );
        }
    }
    if let Some(path) = &h.tag_map {
        let full = env
            .config_dir
            .map_or_else(|| path.clone(), |d| d.join(path));
        if env.check_files {
            if let Err(e) = crate::pipeline::load_tag_map(&full) {
                c.error("tag_map", e);
            }
        }
    }
    if h.tags.is_empty() && h.tag_map.is_none() && h.tag_field.is_none() {
        c.error(
            "pipeline",
            "pipeline \"hfgrid\" needs the floor's tags: [[estimator.tag]] entries, tag_map = \"file\" (CSV uid,x,y or TOML) or tag_field = \"seed002-test\"",
        );
    }
}

fn check_ekfslam(e: &EkfSlamSettings, c: &mut Checks<'_, '_>) {
    c.one_of("measurement", &e.measurement, &["range", "rssi"]);
    c.range("sweep_step_deg", e.sweep_step_deg, 0.1, 90.0, "°");
    c.positive("sweep_every_s", e.sweep_every_s, 3600.0, " s");
    c.count("start_sweeps", u64::from(e.start_sweeps), 1, 1000);
    c.positive("sweep_timeout_s", e.sweep_timeout_s, 3600.0, " s");
    c.positive("range_sigma_m", e.range_sigma_m, 1000.0, " m");
    c.positive("rssi_sigma_db", e.rssi_sigma_db, 100.0, " dB");
    c.positive(
        "beacon_init_max_std_m",
        e.beacon_init_max_std_m,
        1000.0,
        " m",
    );
    c.positive(
        "beacon_init_max_relative_std",
        e.beacon_init_max_relative_std,
        10.0,
        "",
    );
    c.count(
        "beacon_init_relax_after_views",
        e.beacon_init_relax_after_views as u64,
        0,
        10_000,
    );
    c.positive("waypoint_switch_m", e.waypoint_switch_m, 100.0, " m");
    c.positive("max_speed_mps", e.max_speed_mps, 2.0, " m/s");
    c.positive("path_loss_exponent", e.path_loss_exponent, 10.0, "");
    c.range("bearing_floor_deg", e.bearing_floor_deg, 0.0, 180.0, "°");
    c.range(
        "odometry_trans_per_m",
        e.odometry_trans_per_m,
        0.0,
        10.0,
        "",
    );
    c.range(
        "odometry_rot_per_rad",
        e.odometry_rot_per_rad,
        0.0,
        10.0,
        "",
    );
    c.range(
        "odometry_rot_per_m",
        e.odometry_rot_per_m,
        0.0,
        10.0,
        " rad/m",
    );
    c.range("p_ref_dbm", e.p_ref_dbm, -150.0, 30.0, " dBm");
    if let Some(w) = &e.wheel_slip {
        let mut wc = c.nested("wheel_slip");
        wc.range("relative_sigma", w.relative_sigma, 0.0, 1.0, "");
        wc.positive("track_m", w.track_m, 10.0, " m");
        wc.positive("interval_s", w.interval_s, 60.0, " s");
    }
    for (i, v) in e.start.iter().enumerate() {
        c.range(&format!("start[{i}]"), *v, -1e6, 1e6, "");
    }
    for (i, w) in e.waypoints.iter().enumerate() {
        for v in w {
            c.range(&format!("waypoints[{i}]"), *v, -1e6, 1e6, " m");
        }
    }
}

fn check_snapshot(s: &SnapshotSettings, c: &mut Checks<'_, '_>, env: &EstimatorEnv<'_>) {
    c.one_of("clustering", &s.clustering, &["kmedoids", "threshold"]);
    c.count("states", s.states as u64, 1, 100_000);
    if s.goal.is_some() && (s.survey.is_none() || s.tag_map.is_none()) {
        c.error(
            "goal",
            "driving to a goal needs estimator.survey and estimator.tag_map",
        );
    }
    if let Some(g) = &s.goal {
        for v in g {
            c.range("goal", *v, -1e6, 1e6, " m");
        }
    }
    c.positive("goal_radius_m", s.goal_radius_m, 1000.0, " m");
    c.positive("action_duration_s", s.action_duration_s, 3600.0, " s");
    c.positive("drive_duration_s", s.drive_duration_s, 3600.0, " s");
    match (&s.survey, &s.tag_map) {
        (Some(_), None) => c.error(
            "survey",
            "needs estimator.tag_map as well (the tag map localises, the survey proposes poses)",
        ),
        (None, Some(_)) => c.error(
            "tag_map",
            "needs estimator.survey as well (the tag map localises, the survey proposes poses)",
        ),
        _ => {}
    }
    if env.check_files && !(s.survey.is_some() ^ s.tag_map.is_some()) {
        // Every file the run will read, loaded and checked as the run would.
        let dir = env.state_dir;
        let key = if s.survey.is_some() {
            "survey"
        } else {
            "database"
        };
        if let Err(e) = crate::pipeline::load_learned_check(s, dir) {
            c.error(
                key,
                format!(
                    "{e} (learned state in [state] dir; learn it with `rfloc sim` or a survey run)"
                ),
            );
        }
    }
}

fn check_emitter(e: &EmitterSettings, c: &mut Checks<'_, '_>) {
    c.positive("path_loss_exponent", e.path_loss_exponent, 10.0, "");
    c.positive("grid_cell_m", e.grid_cell_m, 10.0, " m");
    c.positive("map_side_m", e.map_side_m, 10_000.0, " m");
    c.positive("map_max_side_m", e.map_max_side_m, 10_000.0, " m");
    c.positive("control_period_s", e.control_period_s, 60.0, " s");
    c.positive("reading_window_s", e.reading_window_s, 3600.0, " s");
    c.positive("obstacle_distance_m", e.obstacle_distance_m, 100.0, " m");
    c.positive("arrival_distance_m", e.arrival_distance_m, 100.0, " m");
    c.positive("drive_speed_mps", e.drive_speed_mps, 2.0, " m/s");
    c.positive("arrival_max_sigma_m", e.arrival_max_sigma_m, 1000.0, " m");
    if let Some(v) = e.receiver_sensitivity_dbm {
        c.range("receiver_sensitivity_dbm", v, -150.0, 30.0, " dBm");
    }
    c.range("a1_dbm_at_1m", e.a1_dbm_at_1m, -150.0, 30.0, " dBm");
    for (i, v) in e.start.iter().enumerate() {
        c.range(&format!("start[{i}]"), *v, -1e6, 1e6, "");
    }
    c.count("particles", e.particles as u64, 1, 1_000_000);
    if e.map_side_m / e.grid_cell_m > 8_000.0 {
        c.error(
            "map_side_m",
            "more than 8000 cells a side: use a larger grid_cell_m",
        );
    }
    if e.map_max_side_m / e.grid_cell_m > 8_000.0 {
        c.error(
            "map_max_side_m",
            "more than 8000 cells a side (64e6 cells): use a larger grid_cell_m",
        );
    }
}

/// Parameters of the emitter-homing pipeline (seed 001; its constants where it gives them).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmitterSettings {
    /// Start pose of the robot (metres, degrees); the pose is the start composed with odometry.
    #[serde(default)]
    pub start: [f64; 3],
    /// `A1`: mean RSS of the four receivers with the emitter at 1 m, dBm (from a calibration).
    pub a1_dbm_at_1m: f64,
    /// `A2`: path-loss exponent of that calibration.
    #[serde(default = "default_a2")]
    pub path_loss_exponent: f64,
    /// Particles of the emitter filter (seed: 1000).
    #[serde(default = "default_particles")]
    pub particles: usize,
    /// The seed's full system (occupancy grid and A*); false runs its preliminary one.
    #[serde(default = "default_true")]
    pub full_system: bool,
    /// Occupancy grid cell side, metres (seed: 0.2).
    #[serde(default = "default_cell")]
    pub grid_cell_m: f64,
    /// Initial side of the square map centred on the start, metres. The map is not limited to
    /// it: it grows (in chunks of 32 cells) to hold every scan and the emitter estimate, up to
    /// `map_max_side_m`. (Before maps grew, this was the map's fixed size.)
    #[serde(default = "default_map_side")]
    pub map_side_m: f64,
    /// Largest map the growth may reach, as the side of a square of the same cell count,
    /// metres (default 400 m: 4 million cells of 20 cm; never less than `map_side_m`).
    #[serde(default = "default_map_max_side")]
    pub map_max_side_m: f64,
    /// Seconds between control steps (filter update and command).
    #[serde(default = "default_control_period")]
    pub control_period_s: f64,
    /// Receiver readings older than this at a control step are not combined, seconds.
    #[serde(default = "default_reading_window")]
    pub reading_window_s: f64,
    /// Avoid obstacles closer than this to the laser, metres (seed: 0.2 from the body).
    #[serde(default = "default_obstacle")]
    pub obstacle_distance_m: f64,
    /// Stop this close to the estimate, metres (seed: 0.5).
    #[serde(default = "default_arrival")]
    pub arrival_distance_m: f64,
    /// Forward speed, m/s.
    #[serde(default = "default_drive_speed")]
    pub drive_speed_mps: f64,
    /// Arrival is declared only while the filtered estimate's spread (square root of its
    /// covariance's largest eigenvalue) is at most this, metres; nearer a vaguer estimate the
    /// robot turns on the spot and keeps measuring.
    #[serde(default = "default_arrival_sigma")]
    pub arrival_max_sigma_m: f64,
    /// A receiver whose poll went unanswered reads as this level (its sensitivity, dBm) when
    /// at least two of the four heard the emitter; unset: a step needs all four readings.
    #[serde(default)]
    pub receiver_sensitivity_dbm: Option<f64>,
    /// Seed of the particle filter's generator.
    #[serde(default)]
    pub seed: u64,
}
fn default_a2() -> f64 {
    2.0
}
fn default_particles() -> usize {
    1000
}
fn default_true() -> bool {
    true
}
fn default_cell() -> f64 {
    0.2
}
fn default_map_side() -> f64 {
    12.0
}
fn default_arrival_sigma() -> f64 {
    1.0
}
fn default_map_max_side() -> f64 {
    400.0
}
fn default_control_period() -> f64 {
    0.2
}
fn default_reading_window() -> f64 {
    0.5
}
fn default_obstacle() -> f64 {
    0.4
}
fn default_arrival() -> f64 {
    0.3
}
fn default_drive_speed() -> f64 {
    0.3
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HfGridSettings {
    /// Tag pitch in metres (seed 002: 0.10).
    #[serde(default = "default_pitch")]
    pub pitch_m: f64,
    /// Antenna offset behind the robot centre in metres (seed 002: 0.10).
    #[serde(default = "default_offset")]
    pub antenna_offset_m: f64,
    /// Tag table: UID (hex) → grid position in metres (`[[estimator.tag]]`).
    #[serde(default, rename = "tag")]
    pub tags: Vec<GridTag>,
    /// Tag table in a file, relative to the robot file: CSV with a `uid,x,y` header, or TOML
    /// with `[[tag]]` entries like the robot file's.
    #[serde(default)]
    pub tag_map: Option<PathBuf>,
    /// A built-in tag field by name: `seed002-test` is seed 002's nine test tags (the field the
    /// simulator's HF reader emulates). Only for simulations and for that test floor.
    #[serde(default)]
    pub tag_field: Option<String>,
    /// Scale of the reader's RSSI-to-distance calibration: every band edge of seed 002's
    /// table is multiplied by this (1: the table as measured).
    #[serde(default = "default_one")]
    pub rssi_distance_scale: f64,
}
impl Default for HfGridSettings {
    fn default() -> Self {
        Self {
            pitch_m: default_pitch(),
            antenna_offset_m: default_offset(),
            tags: Vec::new(),
            tag_map: None,
            tag_field: None,
            rssi_distance_scale: 1.0,
        }
    }
}

fn default_one() -> f64 {
    1.0
}

fn default_pitch() -> f64 {
    0.10
}
fn default_offset() -> f64 {
    0.10
}

/// Parameters of the XBee EKF-SLAM pipeline (seed 003 Table 3.1 defaults).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EkfSlamSettings {
    /// Received power at 1 m (dBm).
    #[serde(default = "default_p_ref")]
    pub p_ref_dbm: f64,
    /// Path-loss exponent.
    #[serde(default = "default_eta")]
    pub path_loss_exponent: f64,
    /// `range` (metres from the path-loss model) or `rssi` (dB, unbiased).
    #[serde(default = "default_measurement")]
    pub measurement: String,
    /// Sweep step of the antenna (degrees; seed 003: 9).
    #[serde(default = "default_step")]
    pub sweep_step_deg: f64,
    /// Waypoints to drive through, metres (map frame). Empty: the pipeline never moves the
    /// base and sweeps whenever the base has stood still for a second.
    #[serde(default)]
    pub waypoints: Vec<[f64; 2]>,
    /// Pose of the robot in the map frame when the daemon starts: x, y (m), heading (deg).
    #[serde(default)]
    pub start: [f64; 3],
    /// Driving time between two sweeps, seconds (the robot stops to sweep).
    #[serde(default = "default_sweep_every")]
    pub sweep_every_s: f64,
    /// Sweeps taken standing at the start pose before driving (with waypoints). The start is
    /// the one pose the filter knows exactly, so these bearings fix the map's frame; each one
    /// averages the bearing errors that differ from sweep to sweep (fast fading, people
    /// moving), not the static multipath of one spot.
    #[serde(default = "default_start_sweeps")]
    pub start_sweeps: u32,
    /// A sweep not reported within this many seconds is given up and driving resumes.
    #[serde(default = "default_sweep_timeout")]
    pub sweep_timeout_s: f64,
    /// σ of a range derived from RSSI, metres (seed 003 Table 3.1: 2).
    #[serde(default = "default_range_sigma")]
    pub range_sigma_m: f64,
    /// σ of a peak RSSI reading, dB (shadowing and fast fading; seed 003 Table 4.1: ≈ 3.16).
    #[serde(default = "default_rssi_sigma")]
    pub rssi_sigma_db: f64,
    /// Added in quadrature to the fitted bearing's σ, degrees (antenna pattern mismatch).
    #[serde(default = "default_bearing_floor")]
    pub bearing_floor_deg: f64,
    /// The directional antenna's calibrated gain pattern: each sweep's bearing and level are
    /// fitted with it over all stops (`{ kind = "cosine_power", exponent, back_lobe_db }` or
    /// `{ kind = "parabolic", hpbw_rad, front_to_back_db }`). Without it, a parabola through
    /// the strongest stops.
    #[serde(default)]
    pub antenna_pattern: Option<rfloc_bearing::GainPattern>,
    /// A beacon first seen is mapped once its triangulated position's largest σ is below
    /// this, metres.
    #[serde(default = "default_beacon_init_std")]
    pub beacon_init_max_std_m: f64,
    /// The views of a beacon not yet mapped carry the sweep's RSSI (or range) as well as its
    /// bearing, and the delayed initialisation triangulates from both (false: bearings only).
    #[serde(default)]
    pub beacon_init_with_range: bool,
    /// Once a beacon not yet mapped has this many views, it is also mapped when its
    /// triangulated position's largest σ is at most `beacon_init_max_relative_std` times its
    /// distance (far beacons seen from a short stretch of route; 0: never).
    #[serde(default)]
    pub beacon_init_relax_after_views: usize,
    /// The relative σ bound of `beacon_init_relax_after_views` (dimensionless).
    #[serde(default = "default_relative_std")]
    pub beacon_init_max_relative_std: f64,
    /// Keep each view's robot pose in the filter state until the beacon is mapped, so it enters
    /// the map with its cross-covariances to those poses (false: the views' poses are taken as
    /// exact and the beacon is attached to the current pose).
    #[serde(default)]
    pub beacon_init_pose_copies: bool,
    /// Waypoint switching distance ρ_min, metres.
    #[serde(default = "default_waypoint_switch")]
    pub waypoint_switch_m: f64,
    /// Cruise speed, m/s.
    #[serde(default = "default_max_speed")]
    pub max_speed_mps: f64,
    /// Odometry translation error per metre travelled (σ, dimensionless).
    #[serde(default = "default_odometry_trans")]
    pub odometry_trans_per_m: f64,
    /// Odometry heading error per radian turned (σ, dimensionless).
    #[serde(default = "default_odometry_rot")]
    pub odometry_rot_per_rad: f64,
    /// Odometry heading error per metre travelled (σ, rad/m).
    #[serde(default = "default_odometry_rot_per_m")]
    pub odometry_rot_per_m: f64,
    /// Wheel-slip odometry model; when given it replaces the three `odometry_*` σ above.
    pub wheel_slip: Option<WheelSlipSettings>,
}

/// Odometry error as wheel slip: relative σ of each wheel's travel per interval.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelSlipSettings {
    /// Relative σ of one wheel's travel per interval.
    pub relative_sigma: f64,
    /// Wheel track, metres.
    pub track_m: f64,
    /// Interval of one draw, seconds.
    pub interval_s: f64,
    /// σ of an additive error of the driven speed, m/s, on every increment in which the
    /// wheels turned (seed 003 Table 3.1's σ_v; default 0).
    #[serde(default)]
    pub sigma_v_mps: f64,
    /// σ of an additive error of the turn rate, rad/s, likewise (Table 3.1's σ_ω; default 0).
    #[serde(default)]
    pub sigma_omega_rps: f64,
}
fn default_relative_std() -> f64 {
    0.25
}
fn default_odometry_rot_per_m() -> f64 {
    0.01
}
impl Default for EkfSlamSettings {
    fn default() -> Self {
        Self {
            p_ref_dbm: default_p_ref(),
            path_loss_exponent: default_eta(),
            measurement: default_measurement(),
            sweep_step_deg: default_step(),
            waypoints: Vec::new(),
            start: [0.0; 3],
            sweep_every_s: default_sweep_every(),
            start_sweeps: default_start_sweeps(),
            sweep_timeout_s: default_sweep_timeout(),
            range_sigma_m: default_range_sigma(),
            rssi_sigma_db: default_rssi_sigma(),
            bearing_floor_deg: default_bearing_floor(),
            beacon_init_max_std_m: default_beacon_init_std(),
            beacon_init_relax_after_views: 0,
            beacon_init_max_relative_std: default_relative_std(),
            beacon_init_with_range: false,
            beacon_init_pose_copies: false,
            antenna_pattern: None,
            waypoint_switch_m: default_waypoint_switch(),
            max_speed_mps: default_max_speed(),
            odometry_trans_per_m: default_odometry_trans(),
            odometry_rot_per_rad: default_odometry_rot(),
            odometry_rot_per_m: default_odometry_rot_per_m(),
            wheel_slip: None,
        }
    }
}

fn default_sweep_every() -> f64 {
    3.0
}
fn default_start_sweeps() -> u32 {
    1
}
fn default_sweep_timeout() -> f64 {
    120.0
}
fn default_range_sigma() -> f64 {
    2.0
}
fn default_rssi_sigma() -> f64 {
    3.16
}
fn default_bearing_floor() -> f64 {
    3.0
}
fn default_beacon_init_std() -> f64 {
    0.5
}
fn default_waypoint_switch() -> f64 {
    0.3
}
fn default_max_speed() -> f64 {
    0.3
}
fn default_odometry_trans() -> f64 {
    0.02
}
fn default_odometry_rot() -> f64 {
    0.02
}
fn default_p_ref() -> f64 {
    -29.0
}
fn default_eta() -> f64 {
    2.0
}
fn default_measurement() -> String {
    "range".into()
}
fn default_step() -> f64 {
    9.0
}

/// Parameters of the UHF snapshot pipeline (seed 000).
// `clustering` and `states` describe how the database was learned; they are validated, and
// the learner (`rfloc sim`) is where they act.
#[allow(dead_code)]
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SnapshotSettings {
    /// Learned database (states, transition matrices), relative to `[state] dir`.
    #[serde(default = "default_database")]
    pub database: PathBuf,
    /// Exploration survey (snapshots with odometry poses), relative to `[state] dir`. With
    /// `tag_map`, the pipeline localises on the tag map instead of the database.
    #[serde(default)]
    pub survey: Option<PathBuf>,
    /// Learned tag positions with their reader model, relative to `[state] dir`.
    #[serde(default)]
    pub tag_map: Option<PathBuf>,
    /// Seed of the tag-map particle filter's random draws (replays repeat exactly).
    #[serde(default)]
    pub seed: u64,
    /// Drive to this point of the map (x, y in metres) on the tag map, one seed action at a
    /// time; needs `survey` and `tag_map`. Without it the pipeline only localises.
    #[serde(default)]
    pub goal: Option<[f64; 2]>,
    /// The robot stops when a steady fix is within this distance of the goal, metres.
    #[serde(default = "default_goal_radius")]
    pub goal_radius_m: f64,
    /// One seed action's duration in Table 4's units, as the survey was driven, seconds.
    #[serde(default = "default_action_duration")]
    pub action_duration_s: f64,
    /// Time the base takes to drive one action, seconds.
    #[serde(default = "default_drive_duration")]
    pub drive_duration_s: f64,
    /// `kmedoids` or `threshold`.
    #[serde(default = "default_clustering")]
    pub clustering: String,
    /// Number of states for k-medoids.
    #[serde(default = "default_states")]
    pub states: usize,
}
impl Default for SnapshotSettings {
    fn default() -> Self {
        Self {
            database: default_database(),
            survey: None,
            tag_map: None,
            seed: 0,
            goal: None,
            goal_radius_m: default_goal_radius(),
            action_duration_s: default_action_duration(),
            drive_duration_s: default_drive_duration(),
            clustering: default_clustering(),
            states: default_states(),
        }
    }
}
fn default_goal_radius() -> f64 {
    0.2
}
fn default_action_duration() -> f64 {
    0.1
}
fn default_drive_duration() -> f64 {
    0.5
}
fn default_database() -> PathBuf {
    PathBuf::from("snapshot-db.json")
}
fn default_clustering() -> String {
    "kmedoids".into()
}
fn default_states() -> usize {
    60
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridTag {
    pub uid: String,
    pub x: f64,
    pub y: f64,
}
