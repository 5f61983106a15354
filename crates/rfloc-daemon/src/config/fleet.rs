//! `[fleet]`: the robot as a VDA 5050 vehicle of a fleet manager, over an MQTT broker.

use std::path::PathBuf;

use serde::Deserialize;

use super::diag::Checks;

/// `[fleet]`: where the broker is and who the robot is on it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FleetConfig {
    /// The MQTT broker, `host:port`.
    pub broker: String,
    /// First topic level (`uagv` in the specification's examples).
    #[serde(default = "default_interface")]
    pub interface_name: String,
    /// Second topic level: the protocol's major version, `v2` (VDA 5050 2.x).
    #[serde(default = "default_major")]
    pub major_version: String,
    /// `manufacturer` of every header and third topic level.
    pub manufacturer: String,
    /// `serialNumber` of every header and fourth topic level.
    pub serial_number: String,
    /// `mapId` of the robot's positions (default: `[robot] frame_id`).
    #[serde(default)]
    pub map_id: Option<String>,
    /// MQTT client id (default: `rfloc-` and the serial number).
    #[serde(default)]
    pub client_id: Option<String>,
    /// Connect with TLS; the broker's certificate is checked against `ca_file`.
    #[serde(default)]
    pub tls: bool,
    /// PEM file of the certificate authorities the broker's certificate must chain to.
    #[serde(default)]
    pub ca_file: Option<PathBuf>,
    /// MQTT user name.
    #[serde(default)]
    pub username: Option<String>,
    /// A file whose first line is the MQTT password. Relative paths are looked up in
    /// `$CREDENTIALS_DIRECTORY` first (systemd `LoadCredential=`), then next to the robot file.
    #[serde(default)]
    pub password_file: Option<PathBuf>,
    /// MQTT keep-alive, seconds; the broker publishes the last will (`CONNECTIONBROKEN`) after
    /// 1.5 times this without a packet.
    #[serde(default = "default_keep_alive")]
    pub keep_alive_s: f64,
    /// Longest time between two `state` messages, seconds (the specification's limit is 30).
    #[serde(default = "default_state_interval")]
    pub state_interval_s: f64,
    /// Most `visualization` messages per second (0: none). They follow the pose rate below it.
    #[serde(default = "default_visualization_hz")]
    pub visualization_hz: f64,
    /// A node counts as reached within this distance when the order sets no
    /// `allowedDeviationXY`, metres.
    #[serde(default = "default_node_tolerance")]
    pub node_tolerance_m: f64,
    /// Heading tolerance on a node with a `theta` when the order sets none, radians.
    #[serde(default = "default_node_tolerance_rad")]
    pub node_tolerance_rad: f64,
    /// Battery voltage reported as 0 % charge (the base's SIPs give the voltage).
    #[serde(default = "default_battery_empty")]
    pub battery_empty_v: f64,
    /// Battery voltage reported as 100 % charge.
    #[serde(default = "default_battery_full")]
    pub battery_full_v: f64,
}

fn default_interface() -> String {
    "uagv".into()
}
fn default_major() -> String {
    "v2".into()
}
fn default_keep_alive() -> f64 {
    10.0
}
fn default_state_interval() -> f64 {
    30.0
}
fn default_visualization_hz() -> f64 {
    10.0
}
fn default_node_tolerance() -> f64 {
    0.25
}
fn default_node_tolerance_rad() -> f64 {
    0.35
}
fn default_battery_empty() -> f64 {
    11.0
}
fn default_battery_full() -> f64 {
    12.8
}

/// A topic level: not empty, none of `/ + # $` (MQTT wildcards and separators).
fn topic_level_ok(level: &str) -> bool {
    !level.is_empty() && !level.contains(['/', '+', '#', '$']) && !level.contains(char::is_control)
}

impl FleetConfig {
    /// The MQTT client id.
    #[must_use]
    pub fn client_id(&self) -> String {
        self.client_id
            .clone()
            .unwrap_or_else(|| format!("rfloc-{}", self.serial_number))
    }

    /// The broker's host and port.
    #[must_use]
    pub fn broker_host_port(&self) -> Option<(String, u16)> {
        let (host, port) = self.broker.rsplit_once(':')?;
        let host = host.trim_start_matches('[').trim_end_matches(']');
        let port: u16 = port.parse().ok()?;
        (!host.is_empty() && port != 0).then(|| (host.to_string(), port))
    }

    pub(crate) fn check(&self, c: &mut Checks<'_, '_>, env: &crate::devices::CheckEnv<'_>) {
        if self.broker_host_port().is_none() {
            c.error(
                "broker",
                format!(
                    "{:?} is not host:port (a port from 1 to 65535)",
                    self.broker
                ),
            );
        }
        for (key, value) in [
            ("interface_name", &self.interface_name),
            ("manufacturer", &self.manufacturer),
            ("serial_number", &self.serial_number),
        ] {
            if !topic_level_ok(value) {
                c.error(
                    key,
                    format!("{value:?} is not a topic level (not empty, none of / + # $)"),
                );
            }
        }
        if self.major_version != "v2" {
            c.error(
                "major_version",
                format!(
                    "{:?} is not supported: rfloc speaks VDA 5050 2.1.0 (\"v2\")",
                    self.major_version
                ),
            );
        }
        if let Some(map) = &self.map_id {
            if map.is_empty() {
                c.error("map_id", "must not be empty");
            }
        }
        if let Some(id) = &self.client_id {
            if id.is_empty() || id.len() > 256 {
                c.error("client_id", "must be 1 to 256 characters");
            }
        }
        match (&self.username, &self.password_file) {
            (None, Some(_)) => c.error("password_file", "needs fleet.username"),
            (Some(u), _) if u.is_empty() => c.error("username", "must not be empty"),
            _ => {}
        }
        if let (Some(p), true) = (&self.password_file, env.check_files) {
            match crate::config::resolve_credential(p, env.config_dir) {
                None => c.error(
                    "password_file",
                    format!(
                        "password file {} not found (looked in $CREDENTIALS_DIRECTORY and next to the config)",
                        p.display()
                    ),
                ),
                Some(path) => {
                    if let Err(e) = read_password(&path) {
                        c.error("password_file", e);
                    }
                }
            }
        }
        match (&self.ca_file, self.tls) {
            (Some(_), false) => c.error("ca_file", "is only used with tls = true"),
            (None, true) => c.error(
                "tls",
                "needs fleet.ca_file: the certificate authorities to check the broker against",
            ),
            (Some(p), true) if env.check_files => {
                let path = env.config_dir.map_or_else(|| p.clone(), |d| d.join(p));
                if !path.is_file() {
                    c.error(
                        "ca_file",
                        format!("CA file {} does not exist", path.display()),
                    );
                }
            }
            _ => {}
        }
        c.range("keep_alive_s", self.keep_alive_s, 5.0, 600.0, " s");
        c.range("state_interval_s", self.state_interval_s, 1.0, 30.0, " s");
        c.range("visualization_hz", self.visualization_hz, 0.0, 50.0, " Hz");
        c.range("node_tolerance_m", self.node_tolerance_m, 0.01, 10.0, " m");
        c.range(
            "node_tolerance_rad",
            self.node_tolerance_rad,
            0.01,
            std::f64::consts::PI,
            " rad",
        );
        c.range("battery_empty_v", self.battery_empty_v, 1.0, 100.0, " V");
        c.range("battery_full_v", self.battery_full_v, 1.0, 100.0, " V");
        if self.battery_full_v <= self.battery_empty_v {
            c.error("battery_full_v", "must be above battery_empty_v");
        }
    }
}

/// The first line of a password file (not empty).
///
/// # Errors
/// The file cannot be read or its first line is empty; the message never holds the password.
pub fn read_password(path: &std::path::Path) -> Result<String, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read password file {}: {e}", path.display()))?;
    let line = text.lines().next().unwrap_or("").trim_end_matches('\r');
    if line.is_empty() {
        return Err(format!(
            "password file {} has an empty first line",
            path.display()
        ));
    }
    Ok(line.to_string())
}

#[cfg(test)]
mod tests {
    use crate::config::RobotConfig;

    const BASE: &str = "[robot]\nname = \"r\"\n\n[[device]]\nname = \"base\"\nlink = { kind = \"serial\", path = \"/dev/null\", baud = 9600 }\n[device.driver]\nkind = \"aria\"\n\n[estimator]\npipeline = \"odometry\"\n";

    fn parse(fleet: &str) -> Result<RobotConfig, String> {
        RobotConfig::parse(&format!("{BASE}\n{fleet}"), "robot.toml", None)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn a_fleet_section_parses_with_its_defaults() {
        let cfg = parse("[fleet]\nbroker = \"127.0.0.1:1883\"\nmanufacturer = \"acme\"\nserial_number = \"r7\"\n").unwrap();
        let f = cfg.fleet.unwrap();
        assert_eq!(f.interface_name, "uagv");
        assert_eq!(f.major_version, "v2");
        assert_eq!(f.client_id(), "rfloc-r7");
        assert_eq!(f.broker_host_port(), Some(("127.0.0.1".into(), 1883)));
        assert!((f.state_interval_s - 30.0).abs() < 1e-12);
        assert!(parse("").unwrap().fleet.is_none());
    }

    #[test]
    fn fleet_errors_name_their_keys_and_lines() {
        let e = parse("[fleet]\nbroker = \"nowhere\"\nmanufacturer = \"ac/me\"\nserial_number = \"\"\nmajor_version = \"v3\"\nstate_interval_s = 60.0\nvisualization_hz = -1.0\npassword_file = \"pw\"\ntls = true\nbattery_empty_v = 13.0\n").unwrap_err();
        for needle in [
            "robot.toml:14:1: key `fleet.broker`: \"nowhere\" is not host:port",
            "robot.toml:15:1: key `fleet.manufacturer`",
            "robot.toml:16:1: key `fleet.serial_number`",
            "robot.toml:17:1: key `fleet.major_version`",
            "robot.toml:18:1: key `fleet.state_interval_s`: must be a number from 1 to 30 s",
            "robot.toml:19:1: key `fleet.visualization_hz`",
            "robot.toml:20:1: key `fleet.password_file`: needs fleet.username",
            "robot.toml:21:1: key `fleet.tls`: needs fleet.ca_file",
            "key `fleet.battery_full_v`: must be above battery_empty_v",
        ] {
            assert!(e.contains(needle), "{needle:?} not in\n{e}");
        }
        let e = parse(
            "[fleet]\nbroker = \"h:1\"\nmanufacturer = \"a\"\nserial_number = \"s\"\nspeed = 3\n",
        )
        .unwrap_err();
        assert!(e.contains("key `fleet.speed`"), "{e}");
        let e = parse("[fleet]\nmanufacturer = \"a\"\nserial_number = \"s\"\n").unwrap_err();
        assert!(e.contains("broker"), "{e}");
    }

    #[test]
    fn the_password_file_is_checked_and_never_printed() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("pw"), "s3cret\n").unwrap();
        std::fs::write(dir.path().join("empty"), "\n").unwrap();
        let text = |file: &str| {
            format!("{BASE}\n[fleet]\nbroker = \"h:1\"\nmanufacturer = \"a\"\nserial_number = \"s\"\nusername = \"u\"\npassword_file = \"{file}\"\n")
        };
        let opts = crate::config::LoadOptions {
            check_files: true,
            extensions: &[],
            for_replay: true,
        };
        let ok =
            RobotConfig::load_text(&text("pw"), "robot.toml", Some(dir.path()), &opts).unwrap();
        let p = ok.fleet.unwrap().password_file.unwrap();
        let found = crate::config::resolve_credential(&p, Some(dir.path())).unwrap();
        assert_eq!(super::read_password(&found).unwrap(), "s3cret");
        for (file, needle) in [("empty", "empty first line"), ("missing", "not found")] {
            let e = RobotConfig::load_text(&text(file), "robot.toml", Some(dir.path()), &opts)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("key `fleet.password_file`") && e.contains(needle),
                "{e}"
            );
            assert!(!e.contains("s3cret"));
        }
    }
}
