//! The settings applied after login, and re-applied after every reconnect.

/// Seed 000's custom format (appendix "Scan Visible Tags Function"). It parses
/// unambiguously here because the literal after `%i` contains non-hex letters, but it carries
/// no count or antenna and only a time of day.
pub const SEED000_CUSTOM_FORMAT: &str = "IDK %i RSSI %m TIME %t;";

/// The project's custom format: `key=value;` pairs, packed hex ID, no `,` and no spaces inside
/// values except between date and time, every field followed by `;`.
pub const PROJECT_CUSTOM_FORMAT: &str = "id=%k;rssi=%m;count=%r;ant=%a;disc=%d %t;last=%D %T;";

/// One setup step.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SetupCommand {
    /// Sent as `Key = Value` (the G05 shortcut form the seed uses).
    Set { key: String, value: String },
    /// The reader clock: sent as `{key}={now}` (or `{key} = {now}` when `spaced`), with the time
    /// from the client's time source (`YYYY/MM/DD hh:mm:ss`).
    Time { key: String, spaced: bool },
    /// Any command, verbatim (e.g. `TagListFormat=Custom` as the seed writes it).
    Raw(String),
}

/// The settings to apply after login.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReaderSetup {
    pub commands: Vec<SetupCommand>,
}

fn set(key: &str, value: &str) -> SetupCommand {
    SetupCommand::Set {
        key: key.to_string(),
        value: value.to_string(),
    }
}

impl ReaderSetup {
    /// The project setup: the seed's settings with [`PROJECT_CUSTOM_FORMAT`].
    /// `PersistTime = -1` (as the seed's reconnect path), `NetworkTimeout = 65535` (seed),
    /// `TagListMillis = ON`, the custom format, `TagListFormat = Custom`, then the clock.
    #[must_use]
    pub fn project() -> Self {
        Self {
            commands: vec![
                set("PersistTime", "-1"),
                set("NetworkTimeout", "65535"),
                set("TagListMillis", "ON"),
                set("TagListCustomFormat", PROJECT_CUSTOM_FORMAT),
                set("TagListFormat", "Custom"),
                SetupCommand::Time {
                    key: "Time".to_string(),
                    spaced: true,
                },
            ],
        }
    }

    /// Seed 000's main script, verbatim: `PersistTime = 0`, `NetworkTimeout = 65535`,
    /// `TagListCustomFormat = IDK %i RSSI %m TIME %t;`, `TagListFormat=Custom`, `time=…`.
    #[must_use]
    pub fn seed000() -> Self {
        Self {
            commands: vec![
                set("PersistTime", "0"),
                set("NetworkTimeout", "65535"),
                set("TagListCustomFormat", SEED000_CUSTOM_FORMAT),
                SetupCommand::Raw("TagListFormat=Custom".to_string()),
                SetupCommand::Time {
                    key: "time".to_string(),
                    spaced: false,
                },
            ],
        }
    }

    /// The `NetworkTimeout` this setup sets, if any (seconds).
    #[must_use]
    pub fn network_timeout(&self) -> Option<u64> {
        self.commands.iter().find_map(|c| match c {
            SetupCommand::Set { key, value } if key.eq_ignore_ascii_case("NetworkTimeout") => {
                value.trim().parse().ok()
            }
            _ => None,
        })
    }
}

impl SetupCommand {
    /// The command text, with `now` as the reader time.
    #[must_use]
    pub fn text(&self, now: &str) -> String {
        match self {
            SetupCommand::Set { key, value } => format!("{key} = {value}"),
            SetupCommand::Time { key, spaced: true } => format!("{key} = {now}"),
            SetupCommand::Time { key, spaced: false } => format!("{key}={now}"),
            SetupCommand::Raw(s) => s.clone(),
        }
    }
}

/// Splits a set command (`set K = V`, `K = V`, `K=V`) into key and value.
#[must_use]
pub fn split_set(cmd: &str) -> Option<(&str, &str)> {
    let c = cmd.trim();
    let c = match c.get(..4) {
        Some(p) if p.eq_ignore_ascii_case("set ") => c.get(4..).unwrap_or_default(),
        _ => c,
    };
    let (k, v) = c.split_once('=')?;
    Some((k.trim(), v.trim()))
}
