//! Per-robot configuration: strict TOML with errors that name the file, line and key.

use std::fmt;
use std::path::{Path, PathBuf};

use rfloc_transport::LinkConfig;
use serde::Deserialize;

/// The whole robot file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    pub robot: RobotSection,
    #[serde(default, rename = "device")]
    pub devices: Vec<DeviceConfig>,
    pub estimator: EstimatorConfig,
    #[serde(default)]
    pub pose: PoseOutputConfig,
    #[serde(default)]
    pub log: LogConfig,
    #[serde(default)]
    pub state: StateConfig,
    /// Present in simulation configs: devices are emulated on ptys and loopback sockets.
    pub simulation: Option<SimulationConfig>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    pub name: String,
    #[serde(default = "default_frame")]
    pub frame_id: String,
    #[serde(default = "default_child_frame")]
    pub child_frame_id: String,
}

fn default_frame() -> String {
    "map".into()
}
fn default_child_frame() -> String {
    "base_link".into()
}

/// One device: a name, how to reach it, and its driver settings.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceConfig {
    pub name: String,
    /// Absent only for GPIO devices (stepper) and in simulation configs, where the daemon
    /// attaches an emulator.
    pub link: Option<LinkConfig>,
    /// Seconds without data before the device counts as stale and poses degrade. Default 3 s;
    /// 60 s for a sweeping XBee radio, which speaks only when the pipeline asks for a sweep.
    pub stale_after_s: Option<f64>,
    pub driver: DriverConfig,
}

impl DeviceConfig {
    /// [`DeviceConfig::stale_after_s`] with its per-driver default.
    #[must_use]
    pub fn stale_after(&self) -> f64 {
        self.stale_after_s.unwrap_or(match &self.driver {
            DriverConfig::Xbee(x) if x.role == XbeeRole::Sweep => 60.0,
            _ => 3.0,
        })
    }
}

/// Driver settings, tagged by `kind`.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum DriverConfig {
    Aria(AriaSettings),
    Kts(KtsSettings),
    Alien(AlienSettings),
    Xbee(XbeeSettings),
    Urg(UrgSettings),
    #[allow(dead_code)] // validated; the GPIO stepper is driven by the EKF-SLAM pipeline only
    Stepper(StepperSettings),
}

impl DriverConfig {
    #[must_use]
    pub fn kind(&self) -> &'static str {
        match self {
            DriverConfig::Aria(_) => "aria",
            DriverConfig::Kts(_) => "kts",
            DriverConfig::Alien(_) => "alien",
            DriverConfig::Xbee(_) => "xbee",
            DriverConfig::Urg(_) => "urg",
            DriverConfig::Stepper(_) => "stepper",
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AriaSettings {
    /// Seconds without a command before a PULSE keeps the robot's watchdog fed.
    #[serde(default = "default_pulse")]
    pub pulse_period_s: f64,
    /// Switch the sonar ring on and publish its ranges as range scans (for a pipeline that
    /// maps obstacles, on a robot without a laser).
    #[serde(default)]
    pub sonar: bool,
}
fn default_pulse() -> f64 {
    1.0
}

/// A Hokuyo URG laser range finder (SCIP 2.0), scanned with `GD` every `scan_period_s`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UrgSettings {
    /// Seconds between scans.
    #[serde(default = "default_scan_period")]
    pub scan_period_s: f64,
    /// Adjacent steps merged into one value (1 = all 682 steps of a URG-04LX).
    #[serde(default = "default_cluster")]
    pub cluster: u8,
    /// The scanner's position ahead of the robot's centre of rotation, metres.
    #[serde(default)]
    pub mount_offset_m: f64,
}
fn default_scan_period() -> f64 {
    0.2
}
fn default_cluster() -> u8 {
    1
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KtsSettings {
    #[serde(default = "default_scan_command")]
    pub scan_command: String,
    /// Seconds of silence after which the client sends `AT` and restarts scanning.
    #[serde(default = "default_silence")]
    pub resync_after_s: f64,
}
fn default_scan_command() -> String {
    "AT+Scan=AC,RSSI".into()
}
fn default_silence() -> f64 {
    2.0
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlienSettings {
    #[serde(default = "default_alien_user")]
    pub username: String,
    /// File holding the password (first line). Relative paths are taken from
    /// `$CREDENTIALS_DIRECTORY` first (systemd `LoadCredential=`), then the config's folder.
    pub password_file: Option<PathBuf>,
    /// Reads averaged into one snapshot.
    #[serde(default = "default_reads")]
    pub reads_per_snapshot: u32,
}
fn default_alien_user() -> String {
    "alien".into()
}
fn default_reads() -> u32 {
    3
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct XbeeSettings {
    /// 1 (unescaped) or 2 (escaped).
    #[serde(default = "default_api_mode")]
    pub api_mode: u8,
    /// Node discovery timeout in seconds (`NT`).
    #[serde(default = "default_nt")]
    pub discovery_timeout_s: f64,
    /// What the radio is for: `sweep` (in the turning reflector, `ND` rounds per stop; seed
    /// 003) or `emitter_receiver` (one of four fixed reflectors, polling the emitter's RSSI;
    /// seed 001).
    #[serde(default)]
    pub role: XbeeRole,
    /// `emitter_receiver`: which reflector the radio sits behind.
    pub antenna: Option<AntennaSide>,
    /// `emitter_receiver`: the emitter radio's 64-bit address (16 hex digits).
    pub emitter: Option<String>,
    /// `emitter_receiver`: seconds between RSSI polls.
    #[serde(default = "default_poll_period")]
    pub poll_period_s: f64,
}
fn default_poll_period() -> f64 {
    0.2
}

/// What an XBee radio of the robot does.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum XbeeRole {
    /// Antenna sweeps on the pipeline's request.
    #[default]
    Sweep,
    /// RSSI of the emitter's replies, polled (remote `DB` to the emitter, then local `DB`).
    EmitterReceiver,
}

/// The four fixed reflectors of the emitter-homing robot, 90° apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AntennaSide {
    Front,
    Left,
    Back,
    Right,
}

impl XbeeSettings {
    /// The radio's API mode (`api_mode` 1: unescaped, else escaped).
    #[must_use]
    pub fn mode(&self) -> rfloc_xbee::ApiMode {
        if self.api_mode == 1 {
            rfloc_xbee::ApiMode::Unescaped
        } else {
            rfloc_xbee::ApiMode::Escaped
        }
    }

    /// The emitter's address of an `emitter_receiver`, parsed.
    #[must_use]
    pub fn emitter_address(&self) -> Option<u64> {
        self.emitter
            .as_deref()
            .and_then(|a| u64::from_str_radix(a.trim_start_matches("0x"), 16).ok())
    }
}
fn default_api_mode() -> u8 {
    2
}
fn default_nt() -> f64 {
    2.0
}

/// The GPIO stepper that turns the XBee radio's reflector. Lines are given by name (as
/// `gpioinfo` lists them) or by offset on the chip.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepperSettings {
    pub chip: String,
    pub step_line: String,
    pub dir_line: String,
    pub enable_line: Option<String>,
    /// Full steps per motor revolution.
    pub steps_per_rev: u32,
    /// Microsteps per full step set on the driver.
    #[serde(default = "default_microsteps")]
    pub microsteps: u32,
    /// Motor revolutions per antenna revolution.
    #[serde(default = "default_gear")]
    pub gear_ratio: f64,
    /// Swap the DIR level so that positive angles turn counter-clockwise seen from above.
    #[serde(default)]
    pub invert_direction: bool,
}
fn default_microsteps() -> u32 {
    1
}
fn default_gear() -> f64 {
    1.0
}

/// Which estimator pipeline runs, with its parameters.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "pipeline", rename_all = "lowercase", deny_unknown_fields)]
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
    /// Side of the square map centred on the start, metres.
    #[serde(default = "default_map_side")]
    pub map_side_m: f64,
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
    /// Tag table: UID (hex) → grid position in metres.
    #[serde(default, rename = "tag")]
    pub tags: Vec<GridTag>,
}
impl Default for HfGridSettings {
    fn default() -> Self {
        Self {
            pitch_m: default_pitch(),
            antenna_offset_m: default_offset(),
            tags: Vec::new(),
        }
    }
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
            sweep_timeout_s: default_sweep_timeout(),
            range_sigma_m: default_range_sigma(),
            rssi_sigma_db: default_rssi_sigma(),
            bearing_floor_deg: default_bearing_floor(),
            beacon_init_max_std_m: default_beacon_init_std(),
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

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridTag {
    pub uid: String,
    pub x: f64,
    pub y: f64,
}

/// Where poses go.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseOutputConfig {
    /// TCP listen address for JSON lines (None: no TCP server).
    #[serde(default = "default_pose_tcp")]
    pub tcp: Option<String>,
    /// Unix socket path for JSON lines.
    pub unix: Option<PathBuf>,
    /// Also print each pose as a JSON line on stdout.
    #[serde(default)]
    pub stdout: bool,
    /// Fraction digits for metres (radians get two more).
    #[serde(default = "default_precision")]
    pub precision: usize,
    /// Per-client queue length before a slow client is dropped.
    #[serde(default = "default_client_queue")]
    pub client_queue: usize,
}

fn default_pose_tcp() -> Option<String> {
    Some("127.0.0.1:2948".into())
}
fn default_precision() -> usize {
    4
}
fn default_client_queue() -> usize {
    64
}

impl Default for PoseOutputConfig {
    fn default() -> Self {
        Self {
            tcp: default_pose_tcp(),
            unix: None,
            stdout: false,
            precision: default_precision(),
            client_queue: default_client_queue(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogConfig {
    /// `error`, `warn`, `info`, `debug`, `trace`, or a tracing filter directive.
    #[serde(default = "default_level")]
    pub level: String,
    /// `text` (journald-friendly, no colours, no timestamps under systemd) or `full`.
    #[serde(default = "default_format")]
    pub format: String,
}
fn default_level() -> String {
    "info".into()
}
fn default_format() -> String {
    "text".into()
}
impl Default for LogConfig {
    fn default() -> Self {
        Self {
            level: default_level(),
            format: default_format(),
        }
    }
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateConfig {
    /// Folder for learned maps and persisted state (systemd `StateDirectory=`).
    pub dir: Option<PathBuf>,
    /// Folder to record captures of every device link into (`record` sets it too).
    pub capture_dir: Option<PathBuf>,
}

/// Simulation section: the daemon starts emulators and attaches devices to them.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationConfig {
    /// Simulated seconds per wall second.
    #[serde(default = "default_time_scale")]
    pub time_scale: f64,
    /// Seed for every random source of the simulation.
    #[serde(default)]
    pub seed: u64,
    /// Simulated seconds to run (None: until stopped).
    pub duration_s: Option<f64>,
    /// Motion script the daemon drives: `turn` (360° in place, then stop) or `square`.
    #[serde(default = "default_motion")]
    pub motion: String,
    /// Start pose of the simulated robot (metres, degrees).
    #[serde(default)]
    pub start: [f64; 3],
    /// Scenario file whose world (XBee beacons) and sensor models the emulated XBee radio
    /// uses, relative to the robot file. Needed when the robot has an XBee device.
    pub scenario: Option<PathBuf>,
    /// Relative σ of each wheel's ground speed per emulator substep (10 ms); 0 = no slip.
    #[serde(default)]
    pub slip_sigma: f64,
}
fn default_time_scale() -> f64 {
    1.0
}
fn default_motion() -> String {
    "turn".into()
}

/// A configuration error, formatted as `file:line:column: key `a.b`: message`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigError {
    pub file: String,
    pub line: Option<usize>,
    pub column: Option<usize>,
    pub key: Option<String>,
    pub message: String,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.column {
                write!(f, ":{c}")?;
            }
        }
        write!(f, ": ")?;
        if let Some(k) = &self.key {
            write!(f, "key `{k}`: ")?;
        }
        write!(f, "{}", self.message)
    }
}

impl std::error::Error for ConfigError {}

impl RobotConfig {
    /// Reads, parses and checks a robot file; `check_devices = false` skips checks of device
    /// nodes and credential files (for validating a robot's file on another machine).
    pub fn load_with(path: &Path, check_devices: bool) -> Result<Self, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            file: file.clone(),
            line: None,
            column: None,
            key: None,
            message: format!("cannot read: {e}"),
        })?;
        let cfg = Self::parse(&text, &file)?;
        cfg.check(&text, &file, path.parent(), check_devices)?;
        Ok(cfg)
    }

    /// Parses TOML text; errors carry line, column and the key at the error.
    pub fn parse(text: &str, file: &str) -> Result<Self, ConfigError> {
        toml::from_str::<RobotConfig>(text).map_err(|e| {
            let message = e.message().trim().to_string();
            let (line, column, key) = match e.span() {
                Some(span) => {
                    let first = locate(text, span.start);
                    // Tagged tables report unknown fields at the table header: point at the field.
                    match first
                        .0
                        .and_then(|l| unknown_field_offset(text, &message, l))
                    {
                        Some(offset) => locate(text, offset),
                        None => first,
                    }
                }
                None => (None, None, None),
            };
            ConfigError {
                file: file.to_string(),
                line,
                column,
                key,
                message,
            }
        })
    }

    /// Semantic checks that TOML types cannot express.
    pub fn check(
        &self,
        text: &str,
        file: &str,
        base: Option<&Path>,
        check_devices: bool,
    ) -> Result<(), ConfigError> {
        let err = |key: &str, message: String| {
            // The whole key: `device[i].…` is looked for from that device's table on.
            let (line, column) = find_key(text, key);
            ConfigError {
                file: file.to_string(),
                line,
                column,
                key: Some(key.to_string()),
                message,
            }
        };
        let mut names = std::collections::HashSet::new();
        for (i, d) in self.devices.iter().enumerate() {
            if !names.insert(d.name.as_str()) {
                return Err(err(
                    &format!("device[{i}].name"),
                    format!("duplicate device name {:?}", d.name),
                ));
            }
            if !(d.stale_after().is_finite() && d.stale_after() > 0.0) {
                return Err(err(
                    &format!("device[{i}].stale_after_s"),
                    "must be a positive number of seconds".into(),
                ));
            }
            match (&d.link, &self.simulation) {
                (None, None) if !matches!(d.driver, DriverConfig::Stepper(_)) => {
                    return Err(err(
                        &format!("device[{i}].link"),
                        format!(
                            "device {:?} has no link (only simulation configs may omit it)",
                            d.name
                        ),
                    ))
                }
                (Some(LinkConfig::Serial(s)), None)
                    if check_devices && !Path::new(&s.path).exists() =>
                {
                    return Err(err(
                        &format!("device[{i}].link.path"),
                        format!("serial device {} does not exist", s.path),
                    ));
                }
                (Some(LinkConfig::Tcp(t)), _) if !t.address.contains(':') => {
                    return Err(err(
                        &format!("device[{i}].link.address"),
                        format!("{:?} is not host:port", t.address),
                    ));
                }
                _ => {}
            }
            if let DriverConfig::Alien(a) = &d.driver {
                if let Some(p) = &a.password_file {
                    if check_devices && resolve_credential(p, base).is_none() {
                        return Err(err(
                            &format!("device[{i}].driver.password_file"),
                            format!("password file {} not found (looked in $CREDENTIALS_DIRECTORY and next to the config)", p.display()),
                        ));
                    }
                }
            }
            if let DriverConfig::Xbee(x) = &d.driver {
                if !matches!(x.api_mode, 1 | 2) {
                    return Err(err(
                        &format!("device[{i}].driver.api_mode"),
                        "must be 1 or 2".into(),
                    ));
                }
                if !(0.1..=25.5).contains(&x.discovery_timeout_s) {
                    return Err(err(
                        &format!("device[{i}].driver.discovery_timeout_s"),
                        "must be in [0.1, 25.5] seconds (NT)".into(),
                    ));
                }
                if x.role == XbeeRole::EmitterReceiver {
                    if x.antenna.is_none() {
                        return Err(err(
                            &format!("device[{i}].driver.role"),
                            "an emitter_receiver needs antenna = front, left, back or right".into(),
                        ));
                    }
                    if x.emitter_address().is_none() {
                        return Err(err(
                            &format!("device[{i}].driver.emitter"),
                            format!(
                                "an emitter_receiver needs the emitter's 64-bit address in hex, not {:?}",
                                x.emitter
                            ),
                        ));
                    }
                    if !(x.poll_period_s.is_finite() && x.poll_period_s >= 0.01) {
                        return Err(err(
                            &format!("device[{i}].driver.poll_period_s"),
                            "must be at least 0.01 s".into(),
                        ));
                    }
                }
            }
            if let DriverConfig::Urg(u) = &d.driver {
                let valid = u.scan_period_s.is_finite()
                    && u.scan_period_s >= 0.05
                    && (1..=99).contains(&u.cluster)
                    && u.mount_offset_m.is_finite();
                if !valid {
                    return Err(err(
                        &format!("device[{i}].driver"),
                        "scan_period_s must be at least 0.05 s, cluster 1 to 99, mount_offset_m finite"
                            .into(),
                    ));
                }
            }
            if let DriverConfig::Stepper(st) = &d.driver {
                if st.steps_per_rev == 0
                    || st.microsteps == 0
                    || !(st.gear_ratio.is_finite() && st.gear_ratio > 0.0)
                {
                    return Err(err(
                        &format!("device[{i}].driver"),
                        "steps_per_rev and microsteps must be ≥ 1 and gear_ratio positive".into(),
                    ));
                }
            }
        }
        for need in self.estimator.required_drivers() {
            if !self.devices.iter().any(|d| d.driver.kind() == *need) {
                return Err(err(
                    "estimator.pipeline",
                    format!(
                        "pipeline {:?} needs a device with driver kind {:?}",
                        self.estimator.name(),
                        need
                    ),
                ));
            }
        }
        if let Some(addr) = &self.pose.tcp {
            if addr.parse::<std::net::SocketAddr>().is_err() {
                return Err(err(
                    "pose.tcp",
                    format!("{addr:?} is not an ip:port address"),
                ));
            }
        }
        if let EstimatorConfig::Ekfslam(e) = &self.estimator {
            if !matches!(e.measurement.as_str(), "range" | "rssi") {
                return Err(err(
                    "estimator.measurement",
                    format!("{:?} is not range or rssi", e.measurement),
                ));
            }
            if !(e.sweep_step_deg > 0.0 && e.sweep_step_deg <= 90.0) {
                return Err(err(
                    "estimator.sweep_step_deg",
                    "must be in (0, 90] degrees".into(),
                ));
            }
            for (key, value) in [
                ("sweep_every_s", e.sweep_every_s),
                ("sweep_timeout_s", e.sweep_timeout_s),
                ("range_sigma_m", e.range_sigma_m),
                ("rssi_sigma_db", e.rssi_sigma_db),
                ("beacon_init_max_std_m", e.beacon_init_max_std_m),
                ("waypoint_switch_m", e.waypoint_switch_m),
                ("max_speed_mps", e.max_speed_mps),
                ("path_loss_exponent", e.path_loss_exponent),
            ] {
                if !(value.is_finite() && value > 0.0) {
                    return Err(err(
                        &format!("estimator.{key}"),
                        format!("must be a positive number, not {value}"),
                    ));
                }
            }
            for (key, value) in [
                ("bearing_floor_deg", e.bearing_floor_deg),
                ("odometry_trans_per_m", e.odometry_trans_per_m),
                ("odometry_rot_per_rad", e.odometry_rot_per_rad),
                ("odometry_rot_per_m", e.odometry_rot_per_m),
            ] {
                if !(value.is_finite() && value >= 0.0) {
                    return Err(err(
                        &format!("estimator.{key}"),
                        format!("must be zero or positive, not {value}"),
                    ));
                }
            }
            if let Some(w) = &e.wheel_slip {
                if !(w.relative_sigma.is_finite()
                    && w.relative_sigma >= 0.0
                    && w.track_m.is_finite()
                    && w.track_m > 0.0
                    && w.interval_s.is_finite()
                    && w.interval_s > 0.0)
                {
                    return Err(err(
                        "estimator.wheel_slip",
                        "relative_sigma ≥ 0, track_m > 0 and interval_s > 0 are needed".into(),
                    ));
                }
            }
            if !(e.p_ref_dbm.is_finite()
                && e.start.iter().all(|v| v.is_finite())
                && e.waypoints.iter().flatten().all(|v| v.is_finite()))
            {
                return Err(err(
                    "estimator",
                    "p_ref_dbm, start and waypoints must be finite numbers".into(),
                ));
            }
        }
        if let EstimatorConfig::Emitter(e) = &self.estimator {
            for (key, value) in [
                ("path_loss_exponent", e.path_loss_exponent),
                ("grid_cell_m", e.grid_cell_m),
                ("map_side_m", e.map_side_m),
                ("control_period_s", e.control_period_s),
                ("reading_window_s", e.reading_window_s),
                ("obstacle_distance_m", e.obstacle_distance_m),
                ("arrival_distance_m", e.arrival_distance_m),
                ("drive_speed_mps", e.drive_speed_mps),
            ] {
                if !(value.is_finite() && value > 0.0) {
                    return Err(err(
                        &format!("estimator.{key}"),
                        format!("must be a positive number, not {value}"),
                    ));
                }
            }
            if !(e.a1_dbm_at_1m.is_finite() && e.start.iter().all(|v| v.is_finite())) {
                return Err(err(
                    "estimator",
                    "a1_dbm_at_1m and start must be finite numbers".into(),
                ));
            }
            if e.particles == 0 {
                return Err(err("estimator.particles", "must be at least 1".into()));
            }
            let mut sides = Vec::new();
            for d in &self.devices {
                if let DriverConfig::Xbee(x) = &d.driver {
                    if x.role == XbeeRole::EmitterReceiver {
                        sides.extend(x.antenna);
                    }
                }
            }
            for side in [
                AntennaSide::Front,
                AntennaSide::Left,
                AntennaSide::Back,
                AntennaSide::Right,
            ] {
                if sides.iter().filter(|s| **s == side).count() != 1 {
                    return Err(err(
                        "estimator.pipeline",
                        format!("pipeline \"emitter\" needs exactly one XBee with role = \"emitter_receiver\" and antenna = {:?}", format!("{side:?}").to_lowercase()),
                    ));
                }
            }
        }
        if let EstimatorConfig::Snapshot(s) = &self.estimator {
            if !matches!(s.clustering.as_str(), "kmedoids" | "threshold") {
                return Err(err(
                    "estimator.clustering",
                    format!("{:?} is not kmedoids or threshold", s.clustering),
                ));
            }
            if s.goal.is_some() && (s.survey.is_none() || s.tag_map.is_none()) {
                return Err(err(
                    "estimator.goal",
                    "driving to a goal needs estimator.survey and estimator.tag_map".into(),
                ));
            }
            if s.goal.iter().flatten().any(|v| !v.is_finite())
                || !(s.goal_radius_m > 0.0 && s.goal_radius_m.is_finite())
                || !(s.action_duration_s > 0.0 && s.action_duration_s.is_finite())
                || !(s.drive_duration_s > 0.0 && s.drive_duration_s.is_finite())
            {
                return Err(err(
                    "estimator",
                    "goal, goal_radius_m, action_duration_s and drive_duration_s must be finite (durations and radius > 0)".into(),
                ));
            }
            match (&s.survey, &s.tag_map) {
                (Some(_), None) => {
                    return Err(err(
                        "estimator.survey",
                        "needs estimator.tag_map as well (the tag map localises, the survey proposes poses)".into(),
                    ))
                }
                (None, Some(_)) => {
                    return Err(err(
                        "estimator.tag_map",
                        "needs estimator.survey as well (the tag map localises, the survey proposes poses)".into(),
                    ))
                }
                _ => {}
            }
        }
        if !matches!(self.log.format.as_str(), "text" | "full") {
            return Err(err(
                "log.format",
                format!("{:?} is not text or full", self.log.format),
            ));
        }
        if let Some(sim) = &self.simulation {
            if !(sim.time_scale.is_finite() && sim.time_scale > 0.0 && sim.time_scale <= 1000.0) {
                return Err(err("simulation.time_scale", "must be in (0, 1000]".into()));
            }
            if !(sim.slip_sigma.is_finite() && (0.0..1.0).contains(&sim.slip_sigma)) {
                return Err(err("simulation.slip_sigma", "must be in [0, 1)".into()));
            }
            let has_xbee = self
                .devices
                .iter()
                .any(|d| matches!(d.driver, DriverConfig::Xbee(_)));
            match &sim.scenario {
                None if has_xbee => {
                    return Err(err(
                        "simulation.scenario",
                        "an emulated XBee radio needs a scenario file with beacons".into(),
                    ))
                }
                Some(p) if check_devices => {
                    let path = base.map_or_else(|| p.clone(), |b| b.join(p));
                    if let Err(e) = rfloc_sim::Scenario::load(&path) {
                        return Err(err("simulation.scenario", format!("{e}")));
                    }
                }
                _ => {}
            }
            if !matches!(sim.motion.as_str(), "turn" | "square" | "still") {
                return Err(err(
                    "simulation.motion",
                    format!("{:?} is not one of turn, square, still", sim.motion),
                ));
            }
        }
        Ok(())
    }
}

/// Finds a credential file: `$CREDENTIALS_DIRECTORY/<name>` first, then relative to the config.
#[must_use]
pub fn resolve_credential(path: &Path, base: Option<&Path>) -> Option<PathBuf> {
    if path.is_absolute() {
        return path.exists().then(|| path.to_path_buf());
    }
    if let Some(dir) = std::env::var_os("CREDENTIALS_DIRECTORY") {
        let p = Path::new(&dir).join(path);
        if p.exists() {
            return Some(p);
        }
    }
    let p = base.map_or_else(|| path.to_path_buf(), |b| b.join(path));
    p.exists().then_some(p)
}

/// Line, column (1-based) and dotted key at a byte offset of TOML text.
fn locate(text: &str, offset: usize) -> (Option<usize>, Option<usize>, Option<String>) {
    let before = text.get(..offset.min(text.len())).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before
        .rsplit('\n')
        .next()
        .map_or(1, |l| l.chars().count() + 1);
    let mut table = String::new();
    let mut device_index: Option<usize> = None;
    let mut devices_seen = 0usize;
    for l in before.lines() {
        let t = l.trim();
        if t.starts_with("[[") {
            table = t.trim_matches(|c| c == '[' || c == ']').trim().to_string();
            if table == "device" {
                device_index = Some(devices_seen);
                devices_seen += 1;
            }
        } else if t.starts_with('[') {
            table = t.trim_matches(|c| c == '[' || c == ']').trim().to_string();
        }
    }
    let current_line = text.lines().nth(line - 1).unwrap_or("");
    let key_here = current_line
        .split_once('=')
        .map(|(k, _)| k.trim().to_string())
        .filter(|k| !k.starts_with('['));
    let mut parts = Vec::new();
    if !table.is_empty() {
        let t = match (device_index, table.strip_prefix("device")) {
            (Some(i), Some(rest)) => format!("device[{i}]{rest}"),
            _ => table,
        };
        parts.push(t);
    }
    if let Some(k) = key_here {
        parts.push(k);
    }
    let key = (!parts.is_empty()).then(|| parts.join("."));
    (Some(line), Some(column), key)
}

/// Line and column of a dotted key such as `device[1].link.path`: the search starts after the
/// matching `[[device]]` header and tries the last segment first, then its parents (so a key
/// inside an inline table is found on the inline table's line).
fn find_key(text: &str, key: &str) -> (Option<usize>, Option<usize>) {
    let segments: Vec<&str> = key.split('.').collect();
    let mut start_line = 0usize;
    if let Some(first) = segments.first() {
        if let Some(idx) = first
            .strip_prefix("device[")
            .and_then(|r| r.strip_suffix(']'))
            .and_then(|n| n.parse::<usize>().ok())
        {
            let mut seen = 0usize;
            for (i, l) in text.lines().enumerate() {
                if l.trim() == "[[device]]" {
                    if seen == idx {
                        start_line = i;
                        break;
                    }
                    seen += 1;
                }
            }
        }
    }
    for seg in segments.iter().rev() {
        let bare = seg.split('[').next().unwrap_or(seg);
        for (i, l) in text.lines().enumerate().skip(start_line) {
            let t = l.trim_start();
            let at_start = t
                .strip_prefix(bare)
                .is_some_and(|r| r.trim_start().starts_with('='));
            let inline = l
                .find(&format!(" {bare} ="))
                .or_else(|| l.find(&format!("{{{bare} =")));
            if at_start {
                return (Some(i + 1), Some(l.len() - t.len() + 1));
            }
            if let Some(col) = inline {
                return (Some(i + 1), Some(col + 2));
            }
        }
    }
    (None, None)
}

/// For `unknown field `x``, the line where `x =` appears at or after `from_line` (1-based).
fn unknown_field_offset(text: &str, message: &str, from_line: usize) -> Option<usize> {
    let rest = message.strip_prefix("unknown field `")?;
    let name = rest.split('`').next()?;
    let mut offset = 0usize;
    for (i, l) in text.split_inclusive('\n').enumerate() {
        if i + 1 >= from_line {
            let t = l.trim_start();
            if t.strip_prefix(name)
                .is_some_and(|r| r.trim_start().starts_with('='))
            {
                return Some(offset + (l.len() - t.len()));
            }
        }
        offset += l.len();
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[robot]
name = "agv-1"

[[device]]
name = "hf"
link = { kind = "tcp", address = "127.0.0.1:9000" }
[device.driver]
kind = "kts"

[estimator]
pipeline = "hfgrid"
"#;

    #[test]
    fn good_config_parses_and_checks() {
        let cfg = RobotConfig::parse(GOOD, "good.toml").unwrap();
        cfg.check(GOOD, "good.toml", None, true).unwrap();
        assert_eq!(cfg.devices.len(), 1);
        assert_eq!(cfg.pose.tcp.as_deref(), Some("127.0.0.1:2948"));
    }

    #[test]
    fn unknown_key_names_file_line_and_key() {
        let text = GOOD.replace("kind = \"kts\"", "kind = \"kts\"\nscan_rate = 3");
        let e = RobotConfig::parse(&text, "bad.toml").unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("bad.toml:10:"), "{s}");
        assert!(s.contains("scan_rate"), "{s}");
        assert_eq!(e.key.as_deref(), Some("device[0].driver.scan_rate"));
    }

    #[test]
    fn wrong_type_names_the_key() {
        let text = GOOD.replace("name = \"agv-1\"", "name = 7");
        let e = RobotConfig::parse(&text, "bad.toml").unwrap_err();
        assert_eq!(e.line, Some(3));
        assert_eq!(e.key.as_deref(), Some("robot.name"));
        assert!(e.message.contains("invalid type"), "{e}");
    }

    #[test]
    fn missing_serial_path_is_a_semantic_error() {
        let text = GOOD.replace(
            "link = { kind = \"tcp\", address = \"127.0.0.1:9000\" }",
            "link = { kind = \"serial\", path = \"/dev/rfloc-does-not-exist\", baud = 115200 }",
        );
        let cfg = RobotConfig::parse(&text, "bad.toml").unwrap();
        let e = cfg.check(&text, "bad.toml", None, true).unwrap_err();
        assert_eq!(e.line, Some(7));
        assert!(e.to_string().contains("/dev/rfloc-does-not-exist"), "{e}");
    }

    #[test]
    fn a_survey_without_a_tag_map_names_the_key_and_line() {
        let text = format!(
            "{}\n[[device]]\nname = \"base\"\nlink = {{ kind = \"tcp\", address = \"127.0.0.1:9001\" }}\n[device.driver]\nkind = \"aria\"\n",
            GOOD.replace("kind = \"kts\"", "kind = \"alien\"")
                .replace(
                    "pipeline = \"hfgrid\"",
                    "pipeline = \"snapshot\"\nsurvey = \"survey.json\""
                )
        );
        let cfg = RobotConfig::parse(&text, "uhf.toml").unwrap();
        let e = cfg.check(&text, "uhf.toml", None, false).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("estimator.survey"), "{e}");
        assert!(e.line.is_some(), "{e}");
        assert!(e.to_string().starts_with("uhf.toml:"), "{e}");
        assert!(e.to_string().contains("tag_map"), "{e}");
        let both = text.replace(
            "survey = \"survey.json\"",
            "survey = \"survey.json\"\ntag_map = \"tag-map.json\"",
        );
        let cfg = RobotConfig::parse(&both, "uhf.toml").unwrap();
        cfg.check(&both, "uhf.toml", None, false).unwrap();
    }

    /// The emitter robot of `config/sim-emitter.toml`, checked as a simulation config.
    fn emitter_robot() -> String {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/sim-emitter.toml");
        std::fs::read_to_string(path).unwrap()
    }

    #[test]
    fn emitter_receivers_are_checked_with_their_device_line() {
        let text = emitter_robot();
        let cfg = RobotConfig::parse(&text, "em.toml").unwrap();
        cfg.check(&text, "em.toml", None, false).unwrap();
        let Some(DriverConfig::Xbee(x)) = cfg.devices.get(3).map(|d| &d.driver) else {
            panic!("device 3 is not an XBee");
        };
        assert_eq!(
            (x.role, x.antenna, x.emitter_address()),
            (
                XbeeRole::EmitterReceiver,
                Some(AntennaSide::Back),
                Some(0x0013_A200_41E0_E001)
            )
        );
        // A bad address on the third receiver: the error points at that device's line.
        let bad = text.replacen(
            "antenna = \"back\"\nemitter = \"0013A20041E0E001\"",
            "antenna = \"back\"\nemitter = \"not-hex\"",
            1,
        );
        assert_ne!(bad, text);
        let cfg = RobotConfig::parse(&bad, "em.toml").unwrap();
        let e = cfg.check(&bad, "em.toml", None, false).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("device[3].driver.emitter"), "{e}");
        let line = bad
            .lines()
            .position(|l| l.contains("not-hex"))
            .map(|i| i + 1);
        assert_eq!(e.line, line, "{e}");
        // Two receivers behind the front reflector and none behind the left one.
        let twice = text.replacen("antenna = \"left\"", "antenna = \"front\"", 1);
        let cfg = RobotConfig::parse(&twice, "em.toml").unwrap();
        let e = cfg.check(&twice, "em.toml", None, false).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("estimator.pipeline"), "{e}");
        assert!(e.message.contains("antenna = \"front\""), "{e}");
        // A receiver without its reflector.
        let none = text.replacen("antenna = \"right\"\n", "", 1);
        let cfg = RobotConfig::parse(&none, "em.toml").unwrap();
        let e = cfg.check(&none, "em.toml", None, false).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("device[4].driver.role"), "{e}");
        let line = none
            .lines()
            .enumerate()
            .filter(|(_, l)| l.starts_with("role ="))
            .nth(3)
            .map(|(i, _)| i + 1);
        assert_eq!(e.line, line, "the fourth receiver's role line: {e}");
        // A non-positive control period.
        let period = text.replace(
            "obstacle_distance_m = 0.4",
            "obstacle_distance_m = 0.4\ncontrol_period_s = 0.0",
        );
        let cfg = RobotConfig::parse(&period, "em.toml").unwrap();
        let e = cfg.check(&period, "em.toml", None, false).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("estimator.control_period_s"), "{e}");
    }

    #[test]
    fn pipeline_without_its_device_is_rejected() {
        let text = GOOD.replace("pipeline = \"hfgrid\"", "pipeline = \"odometry\"");
        let cfg = RobotConfig::parse(&text, "bad.toml").unwrap();
        let e = cfg.check(&text, "bad.toml", None, true).unwrap_err();
        assert!(
            e.to_string()
                .contains("needs a device with driver kind \"aria\""),
            "{e}"
        );
    }
}
