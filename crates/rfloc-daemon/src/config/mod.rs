//! The robot file: strict TOML, parsed section by section from the parser's span tree, every
//! error reported at once as `file:line:col: key …`.
//!
//! - [`diag`]: errors located by spans, and the range checks every section uses;
//! - [`sections`]: `[robot]`, `[pose]`, `[log]`, `[state]`;
//! - [`fleet`]: `[fleet]`, the robot as a VDA 5050 vehicle over MQTT;
//! - [`estimator`]: `[estimator]`, one settings type per pipeline;
//! - each device's `[device.driver]` is parsed and checked by its kind in the driver registry
//!   ([`crate::devices::REGISTRY`]), next to the driver.
//!
//! A section this build does not implement itself (`[simulation]`, from the lab) is checked by a
//! [`SectionCheck`] the binary passes in; without one it is an error.

mod diag;
mod estimator;
mod fleet;
mod sections;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rfloc_transport::LinkConfig;
use serde::Deserialize;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

pub use diag::{
    Checks, ConfigError, ConfigErrors, Diagnostics, Node, SectionCheck, SectionContext,
};
pub use estimator::{
    EkfSlamSettings, EmitterSettings, EstimatorConfig, GridTag, HfGridSettings, SnapshotSettings,
    WheelSlipSettings, PIPELINES,
};
pub use fleet::{read_password, FleetConfig};
pub use sections::{
    FoxgloveConfig, LogConfig, PoseOutputConfig, RobotSection, StateConfig, SupervisionConfig,
};

pub use crate::devices::alien::AlienSettings;
pub use crate::devices::aria::AriaSettings;
pub use crate::devices::kts::KtsSettings;
pub use crate::devices::stepper::StepperSettings;
pub use crate::devices::urg::UrgSettings;
pub use crate::devices::xbee::{XbeeRole, XbeeSettings};
pub use crate::events::AntennaSide;

use crate::devices::{CheckEnv, DeviceDriver};

/// The whole robot file.
#[derive(Debug, Clone)]
pub struct RobotConfig {
    pub robot: RobotSection,
    pub devices: Vec<DeviceConfig>,
    pub estimator: EstimatorConfig,
    pub pose: PoseOutputConfig,
    pub log: LogConfig,
    pub state: StateConfig,
    pub supervision: SupervisionConfig,
    pub foxglove: FoxgloveConfig,
    /// `[fleet]`: a VDA 5050 fleet manager over MQTT, when the robot has one.
    pub fleet: Option<FleetConfig>,
    /// Present in simulation configs: devices are emulated (by the lab) on ptys and loopback
    /// sockets. The daemon only knows that the section is there.
    pub simulation: bool,
    /// The file it came from.
    pub source: Arc<ConfigSource>,
}

/// Where a robot file came from: its name, text and folder.
#[derive(Debug, Clone)]
pub struct ConfigSource {
    pub file: String,
    pub text: String,
    pub dir: Option<PathBuf>,
}

/// One device: a name, how to reach it, and its driver.
#[derive(Debug, Clone)]
pub struct DeviceConfig {
    pub name: String,
    /// Absent only for GPIO devices (stepper) and in simulation configs, where the lab attaches
    /// an emulator.
    pub link: Option<LinkConfig>,
    /// Seconds without data before the device counts as stale and poses degrade (default per
    /// kind: 3 s; 60 s for a sweeping XBee radio, which speaks only when asked).
    pub stale_after_s: Option<f64>,
    pub driver: DeviceDriver,
}

impl DeviceConfig {
    /// [`DeviceConfig::stale_after_s`] with its per-kind default.
    #[must_use]
    pub fn stale_after(&self) -> f64 {
        self.stale_after_s
            .unwrap_or_else(|| self.driver.stale_after_s())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DeviceCommon {
    name: String,
    link: Option<LinkConfig>,
    stale_after_s: Option<f64>,
}

/// How much of the file's world `load` checks.
#[derive(Clone, Copy)]
pub struct LoadOptions<'a> {
    /// Device nodes, credential and map files must exist here (false: validate for another
    /// machine).
    pub check_files: bool,
    /// Sections implemented outside the daemon (the lab's `[simulation]`).
    pub extensions: &'a [&'a dyn SectionCheck],
    /// Loading a recorded session's robot file for a replay: links are not opened.
    pub for_replay: bool,
}

impl Default for LoadOptions<'_> {
    fn default() -> Self {
        Self {
            check_files: true,
            extensions: &[],
            for_replay: false,
        }
    }
}

/// The sections the daemon itself reads.
const SECTIONS: &[&str] = &[
    "robot",
    "device",
    "estimator",
    "pose",
    "log",
    "state",
    "supervision",
    "foxglove",
    "fleet",
];

impl RobotConfig {
    /// Reads, parses and checks a robot file.
    pub fn load(path: &Path, opts: &LoadOptions<'_>) -> Result<Self, ConfigErrors> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| {
            ConfigErrors(vec![ConfigError {
                file: file.clone(),
                line: None,
                column: None,
                key: None,
                message: format!("cannot read: {e}"),
            }])
        })?;
        Self::load_text(&text, &file, path.parent(), opts)
    }

    /// Parses and checks robot file text (`dir`: where relative paths in it start).
    pub fn load_text(
        text: &str,
        file: &str,
        dir: Option<&Path>,
        opts: &LoadOptions<'_>,
    ) -> Result<Self, ConfigErrors> {
        let (root, syntax) = DeTable::parse_recoverable(text);
        let root: Node<'_> = Spanned::new(root.span(), DeValue::Table(root.into_inner()));
        let mut diag = Diagnostics::new(file, text, &root);
        for e in syntax {
            diag.at_span(e.span(), None, e.message().trim().to_string());
        }
        let cfg = if diag.is_clean() {
            let parts = parse_root(&mut diag, dir, opts);
            parts.check(&mut diag, opts, dir);
            parts.assemble(text, file, dir)
        } else {
            None
        };
        diag.finish()?;
        cfg.ok_or_else(|| {
            ConfigErrors(vec![ConfigError {
                file: file.to_string(),
                line: None,
                column: None,
                key: None,
                message: "not a robot file".into(),
            }])
        })
    }

    /// Parses robot file text with no checks of the world outside it (tests, embedded files).
    pub fn parse(text: &str, file: &str, dir: Option<&Path>) -> Result<Self, ConfigErrors> {
        Self::load_text(
            text,
            file,
            dir,
            &LoadOptions {
                check_files: false,
                extensions: &[],
                for_replay: true,
            },
        )
    }

    /// A device by name.
    #[must_use]
    pub fn device(&self, name: &str) -> Option<&DeviceConfig> {
        self.devices.iter().find(|d| d.name == name)
    }
}

/// The sections of a file as far as they parsed: each is checked on its own, so that one bad
/// section does not hide the errors of the others.
struct Parts {
    robot: Option<RobotSection>,
    devices: Option<Vec<DeviceConfig>>,
    estimator: Option<EstimatorConfig>,
    pose: Option<PoseOutputConfig>,
    log: Option<LogConfig>,
    state: Option<StateConfig>,
    supervision: Option<SupervisionConfig>,
    foxglove: Option<FoxgloveConfig>,
    /// `Some(None)`: no `[fleet]` section; `None`: one that did not parse.
    fleet: Option<Option<FleetConfig>>,
    simulation: bool,
}

impl Parts {
    /// Semantic checks that TOML types cannot express.
    fn check(&self, diag: &mut Diagnostics<'_>, opts: &LoadOptions<'_>, dir: Option<&Path>) {
        let env = CheckEnv {
            check_files: opts.check_files,
            config_dir: dir,
            simulated: self.simulation,
        };
        if let Some(devices) = &self.devices {
            check_devices(devices, diag, &env, opts);
        }
        if let Some(estimator) = &self.estimator {
            if let Some(devices) = &self.devices {
                for need in estimator.required_drivers() {
                    if !devices.iter().any(|d| d.driver.kind() == *need) {
                        diag.error(
                            "estimator.pipeline",
                            format!(
                                "pipeline {:?} needs a device with driver kind {:?}",
                                estimator.name(),
                                need
                            ),
                        );
                    }
                }
                if let EstimatorConfig::Emitter(_) = estimator {
                    check_emitter_receivers(devices, diag);
                }
            }
            let est_env = estimator::EstimatorEnv {
                config_dir: dir,
                state_dir: self.state.as_ref().and_then(|s| s.dir.as_deref()),
                check_files: opts.check_files,
            };
            estimator.check(&mut Checks::new(diag, "estimator"), &est_env);
        }
        if let Some(pose) = &self.pose {
            pose.check(&mut Checks::new(diag, "pose"), &env);
        }
        if let Some(log) = &self.log {
            log.check(&mut Checks::new(diag, "log"));
        }
        if let Some(s) = &self.supervision {
            s.check(&mut Checks::new(diag, "supervision"));
        }
        if let Some(f) = &self.foxglove {
            f.check(&mut Checks::new(diag, "foxglove"));
        }
        if let Some(Some(f)) = &self.fleet {
            f.check(&mut Checks::new(diag, "fleet"), &env);
        }
    }

    fn assemble(self, text: &str, file: &str, dir: Option<&Path>) -> Option<RobotConfig> {
        Some(RobotConfig {
            robot: self.robot?,
            devices: self.devices?,
            estimator: self.estimator?,
            pose: self.pose?,
            log: self.log?,
            state: self.state?,
            supervision: self.supervision?,
            foxglove: self.foxglove?,
            fleet: self.fleet?,
            simulation: self.simulation,
            source: Arc::new(ConfigSource {
                file: file.to_string(),
                text: text.to_string(),
                dir: dir.map(Path::to_path_buf),
            }),
        })
    }
}

fn check_devices(
    devices: &[DeviceConfig],
    diag: &mut Diagnostics<'_>,
    env: &CheckEnv<'_>,
    opts: &LoadOptions<'_>,
) {
    let mut names = std::collections::HashSet::new();
    for (i, d) in devices.iter().enumerate() {
        let mut c = Checks::new(diag, format!("device[{i}]"));
        if !names.insert(d.name.as_str()) {
            c.error("name", format!("duplicate device name {:?}", d.name));
        }
        if d.name.is_empty()
            || !d
                .name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch))
            || d.name.starts_with('.')
        {
            c.error(
                "name",
                format!(
                    "{:?} is not a device name (letters, digits, - _ .; it names the capture file)",
                    d.name
                ),
            );
        }
        c.positive("stale_after_s", d.stale_after(), 86_400.0, " s");
        check_link(d, &mut c, env, opts);
        d.driver.check(&mut c.nested("driver"), env);
    }
}

fn check_emitter_receivers(devices: &[DeviceConfig], diag: &mut Diagnostics<'_>) {
    let sides: Vec<AntennaSide> = devices
        .iter()
        .filter_map(|d| d.driver.settings::<crate::devices::xbee::Xbee>())
        .filter(|x| x.role == XbeeRole::EmitterReceiver)
        .filter_map(|x| x.antenna)
        .collect();
    for side in [
        AntennaSide::Front,
        AntennaSide::Left,
        AntennaSide::Back,
        AntennaSide::Right,
    ] {
        if sides.iter().filter(|s| **s == side).count() != 1 {
            diag.error(
                "estimator.pipeline",
                format!(
                    "pipeline \"emitter\" needs exactly one XBee with role = \"emitter_receiver\" and antenna = {:?}",
                    side.as_str()
                ),
            );
        }
    }
}

fn check_link(
    d: &DeviceConfig,
    c: &mut Checks<'_, '_>,
    env: &CheckEnv<'_>,
    opts: &LoadOptions<'_>,
) {
    match &d.link {
        None if d.driver.needs_link() && !env.simulated && !opts.for_replay => c.error(
            "link",
            format!(
                "device {:?} has no link (only simulation configs may omit it)",
                d.name
            ),
        ),
        Some(LinkConfig::Serial(s))
            if env.check_files && !env.simulated && !Path::new(&s.path).exists() =>
        {
            c.error(
                "link.path",
                format!("serial device {} does not exist", s.path),
            );
        }
        Some(LinkConfig::Tcp(t)) if !t.address.contains(':') => {
            c.error("link.address", format!("{:?} is not host:port", t.address))
        }
        _ => {}
    }
}

fn parse_root<'i>(diag: &mut Diagnostics<'i>, dir: Option<&Path>, opts: &LoadOptions<'_>) -> Parts {
    let root = diag.root();
    let mut parts = Parts {
        robot: None,
        devices: None,
        estimator: None,
        pose: None,
        log: None,
        state: None,
        supervision: None,
        foxglove: None,
        fleet: None,
        simulation: false,
    };
    let Some(table) = diag::table(root) else {
        return parts;
    };
    let mut simulation = false;
    for (key, node) in table {
        let name = key.get_ref().as_ref();
        if SECTIONS.contains(&name) {
            continue;
        }
        match opts.extensions.iter().find(|x| x.section() == name) {
            Some(ext) => {
                simulation |= name == "simulation";
                let ctx = SectionContext {
                    dir,
                    check_files: opts.check_files,
                };
                ext.check(node, diag, &ctx);
            }
            None if name == "simulation" => {
                simulation = true;
                if !opts.for_replay {
                    diag.error(
                        "simulation",
                        "this rfloc was built without the simulator (cargo feature `lab`)",
                    );
                }
            }
            None => diag.error(
                name,
                format!("unknown section; expected one of {}", SECTIONS.join(", ")),
            ),
        }
    }
    let robot = match diag::get(root, "robot") {
        Some(n) => diag.deserialize::<RobotSection>("robot", n),
        None => {
            diag.error("robot", "missing: [robot] with name = \"…\"");
            None
        }
    };
    let estimator = match diag::get(root, "estimator") {
        Some(n) => EstimatorConfig::parse(n, diag),
        None => {
            diag.error("estimator", "missing: [estimator] with pipeline = \"…\"");
            None
        }
    };
    let pose = match diag::get(root, "pose") {
        Some(n) => diag.deserialize::<PoseOutputConfig>("pose", n),
        None => Some(PoseOutputConfig::default()),
    };
    let log = match diag::get(root, "log") {
        Some(n) => diag.deserialize::<LogConfig>("log", n),
        None => Some(LogConfig::default()),
    };
    let state = match diag::get(root, "state") {
        Some(n) => diag.deserialize::<StateConfig>("state", n),
        None => Some(StateConfig::default()),
    };
    parts.foxglove = match diag::get(root, "foxglove") {
        Some(n) => diag.deserialize::<FoxgloveConfig>("foxglove", n),
        None => Some(FoxgloveConfig::default()),
    };
    parts.supervision = match diag::get(root, "supervision") {
        Some(n) => diag.deserialize::<SupervisionConfig>("supervision", n),
        None => Some(SupervisionConfig::default()),
    };
    parts.fleet = match diag::get(root, "fleet") {
        Some(n) => diag.deserialize::<FleetConfig>("fleet", n).map(Some),
        None => Some(None),
    };
    parts.devices = parse_devices(diag, root);
    parts.robot = robot;
    parts.estimator = estimator;
    parts.pose = pose;
    parts.log = log;
    parts.state = state;
    parts.simulation = simulation;
    parts
}

fn parse_devices<'i>(diag: &mut Diagnostics<'i>, root: &Node<'i>) -> Option<Vec<DeviceConfig>> {
    let Some(list) = diag::get(root, "device") else {
        return Some(Vec::new());
    };
    let DeValue::Array(items) = list.get_ref() else {
        diag.error("device", "must be an array of tables ([[device]])");
        return None;
    };
    let mut devices = Vec::new();
    let mut ok = true;
    for (i, item) in items.iter().enumerate() {
        let path = format!("device[{i}]");
        let common = diag.deserialize::<DeviceCommon>(&path, &diag::without(item, "driver"));
        let driver = match diag::get(item, "driver") {
            Some(node) => parse_driver(diag, &format!("{path}.driver"), node),
            None => {
                diag.error(
                    &format!("{path}.driver"),
                    "missing: [device.driver] with kind = \"…\"",
                );
                None
            }
        };
        match (common, driver) {
            (Some(c), Some(driver)) => devices.push(DeviceConfig {
                name: c.name,
                link: c.link,
                stale_after_s: c.stale_after_s,
                driver,
            }),
            _ => ok = false,
        }
    }
    ok.then_some(devices)
}

fn parse_driver<'i>(
    diag: &mut Diagnostics<'i>,
    path: &str,
    node: &Node<'i>,
) -> Option<DeviceDriver> {
    let kinds = crate::devices::kind_names().join(", ");
    let Some(kind) = diag::get(node, "kind").and_then(diag::string) else {
        diag.error(&format!("{path}.kind"), format!("missing: one of {kinds}"));
        return None;
    };
    let Some(entry) = crate::devices::kind(kind) else {
        diag.error(
            &format!("{path}.kind"),
            format!("{kind:?} is not a device kind; expected one of {kinds}"),
        );
        return None;
    };
    entry.parse(path, &diag::without(node, "kind"), diag)
}

/// A warning when a secret file (a password, a token) can be read by others than its owner and
/// group; `None` when its permissions are right (or it came through systemd credentials).
#[must_use]
pub fn secret_file_warning(path: &Path) -> Option<String> {
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(path).ok()?.permissions().mode();
    (mode & 0o004 != 0).then(|| {
        format!(
            "{} is readable by every user (mode {:o}); make it 0600 or 0640, or hand it over with systemd LoadCredential=",
            path.display(),
            mode & 0o777
        )
    })
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
