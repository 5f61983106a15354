//! The daemon's own sections: `[robot]`, `[pose]`, `[log]`, `[state]`.

use std::path::PathBuf;

use serde::Deserialize;

use super::diag::Checks;

/// `[robot]`: its name and frames.
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
    /// Clients served at once (TCP and Unix together); more are turned away.
    #[serde(default = "default_max_clients")]
    pub max_clients: usize,
    /// A file whose first line is the token TCP clients must send first
    /// (`?AUTH={"token":"…"};`). Relative paths are looked up in `$CREDENTIALS_DIRECTORY` first
    /// (systemd `LoadCredential=`), then next to the robot file.
    #[serde(default)]
    pub token_file: Option<PathBuf>,
    /// TCP clients allowed to connect: addresses or networks (`192.168.10.0/24`). Empty: any
    /// client that can reach the listening address.
    #[serde(default)]
    pub allow: Vec<String>,
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
fn default_max_clients() -> usize {
    32
}

impl Default for PoseOutputConfig {
    fn default() -> Self {
        Self {
            tcp: default_pose_tcp(),
            unix: None,
            stdout: false,
            precision: default_precision(),
            client_queue: default_client_queue(),
            max_clients: default_max_clients(),
            token_file: None,
            allow: Vec::new(),
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

impl PoseOutputConfig {
    pub(crate) fn check(&self, c: &mut Checks<'_, '_>, env: &crate::devices::CheckEnv<'_>) {
        let guarded = self.token_file.is_some() || !self.allow.is_empty();
        if let Some(addr) = &self.tcp {
            match addr.parse::<std::net::SocketAddr>() {
                Err(_) => c.error("tcp", format!("{addr:?} is not an ip:port address")),
                Ok(a) if !a.ip().is_loopback() && !guarded => c.error(
                    "tcp",
                    format!("{addr} is reachable from other hosts and the stream has no access control: listen on 127.0.0.1, or set pose.token_file or pose.allow"),
                ),
                Ok(_) => {}
            }
        }
        for (i, a) in self.allow.iter().enumerate() {
            if crate::server::AllowRule::parse(a).is_none() {
                c.error(
                    &format!("allow[{i}]"),
                    format!("{a:?} is not an address or address/prefix"),
                );
            }
        }
        if let Some(p) = &self.token_file {
            if env.check_files {
                match crate::config::resolve_credential(p, env.config_dir) {
                    None => c.error("token_file", format!("token file {} not found (looked in $CREDENTIALS_DIRECTORY and next to the config)", p.display())),
                    Some(path) => {
                        if let Err(e) = crate::server::read_token(&path) {
                            c.error("token_file", e);
                        }
                    }
                }
            }
        }
        if let (Some(p), true) = (&self.unix, env.check_files) {
            let parent = p.parent().filter(|d| !d.as_os_str().is_empty());
            if parent.is_some_and(|d| !d.is_dir()) {
                c.error(
                    "unix",
                    format!("the folder of {} does not exist", p.display()),
                );
            }
            if let Ok(m) = std::fs::symlink_metadata(p) {
                use std::os::unix::fs::FileTypeExt;
                if !m.file_type().is_socket() {
                    c.error(
                        "unix",
                        format!(
                            "{} exists and is not a socket; rfloc will not replace it",
                            p.display()
                        ),
                    );
                }
            }
        }
        c.count("precision", self.precision as u64, 1, 9);
        c.count("client_queue", self.client_queue as u64, 1, 100_000);
        c.count("max_clients", self.max_clients as u64, 1, 1024);
    }
}

impl LogConfig {
    pub(crate) fn check(&self, c: &mut Checks<'_, '_>) {
        c.one_of("format", &self.format, &["text", "full"]);
        if tracing_subscriber_filter_is_invalid(&self.level) {
            c.error(
                "level",
                format!(
                    "{:?} is not a log level (error, warn, info, debug, trace) or filter directive",
                    self.level
                ),
            );
        }
    }
}

/// Not a level or a `target=level,…` list with a level in every directive. (The logger would
/// take a bare word such as `loud` as a target name and log nothing at all.)
fn tracing_subscriber_filter_is_invalid(level: &str) -> bool {
    const LEVELS: &[&str] = &["off", "error", "warn", "info", "debug", "trace"];
    let every_directive_has_a_level = level.split(',').all(|d| {
        let lvl = d.rsplit_once('=').map_or(d, |(_, l)| l).trim();
        LEVELS.contains(&lvl.to_ascii_lowercase().as_str())
    });
    level.trim().is_empty()
        || !every_directive_has_a_level
        || tracing_subscriber::EnvFilter::try_new(level).is_err()
}

/// `[supervision]`: how devices are reconnected and restarted, and when the daemon gives up on
/// one (the systemd watchdog then restarts the service).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupervisionConfig {
    /// First wait before reconnecting a link or restarting a device task, seconds.
    #[serde(default = "default_backoff_initial")]
    pub backoff_initial_s: f64,
    /// Longest such wait, seconds.
    #[serde(default = "default_backoff_max")]
    pub backoff_max_s: f64,
    /// Spread of each wait, a fraction of it.
    #[serde(default = "default_backoff_jitter")]
    pub backoff_jitter: f64,
    /// A device down longer than this (its task ended, or it delivered nothing past its
    /// `stale_after_s`) stops the systemd watchdog, seconds.
    #[serde(default = "default_max_down")]
    pub max_down_s: f64,
}

fn default_backoff_initial() -> f64 {
    0.5
}

fn default_backoff_max() -> f64 {
    30.0
}

fn default_backoff_jitter() -> f64 {
    0.2
}

fn default_max_down() -> f64 {
    60.0
}

impl Default for SupervisionConfig {
    fn default() -> Self {
        Self {
            backoff_initial_s: default_backoff_initial(),
            backoff_max_s: default_backoff_max(),
            backoff_jitter: default_backoff_jitter(),
            max_down_s: default_max_down(),
        }
    }
}

impl SupervisionConfig {
    pub(crate) fn check(&self, c: &mut Checks<'_, '_>) {
        c.range(
            "backoff_initial_s",
            self.backoff_initial_s,
            0.01,
            3600.0,
            " s",
        );
        c.range("backoff_max_s", self.backoff_max_s, 0.01, 86_400.0, " s");
        if self.backoff_max_s < self.backoff_initial_s {
            c.error("backoff_max_s", "must not be below backoff_initial_s");
        }
        c.range("backoff_jitter", self.backoff_jitter, 0.0, 0.9, "");
        c.range("max_down_s", self.max_down_s, 1.0, 86_400.0, " s");
    }

    /// The back-off policy.
    #[must_use]
    pub fn backoff(&self) -> crate::devices::Backoff {
        crate::devices::Backoff {
            initial_s: self.backoff_initial_s,
            max_s: self.backoff_max_s,
            jitter: self.backoff_jitter,
        }
    }
}

/// `[foxglove]`: a live view of the robot for Foxglove (its WebSocket protocol).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FoxgloveConfig {
    /// Where to serve it, e.g. `127.0.0.1:8765` (none: no live view). Loopback only: the
    /// protocol has no access control; reach it from elsewhere through a tunnel.
    pub listen: Option<String>,
}

impl FoxgloveConfig {
    pub(crate) fn check(&self, c: &mut Checks<'_, '_>) {
        if let Some(addr) = &self.listen {
            match addr.parse::<std::net::SocketAddr>() {
                Err(_) => c.error("listen", format!("{addr:?} is not an ip:port address")),
                Ok(a) if !a.ip().is_loopback() => c.error(
                    "listen",
                    format!("{addr} is reachable from other hosts and the Foxglove protocol has no access control: listen on 127.0.0.1 and tunnel (ssh -L)"),
                ),
                Ok(_) => {}
            }
        }
    }
}
