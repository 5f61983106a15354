//! Alien ALR-9900 task: a reconnecting session (login, setup, keepalive), polled for snapshots
//! averaged over the configured number of reads ([`average_reads`], the seed's rule).
//!
//! The password comes from `password_file` (looked up in `$CREDENTIALS_DIRECTORY` first, so a
//! systemd `LoadCredential=` works, then next to the robot file), or the reader's factory
//! default when none is configured. It is never logged, and never written to the link's
//! capture (recorded as `<redacted>`).
//!
//! Captures: each averaged snapshot is followed by `mark snapshot reads=N`, so that a replay
//! groups the recorded tag lists exactly as the task did.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use rfloc_alien::{AlienConfig, AlienSession, Backoff, Connector, ReaderSetup, SnapshotReader};
use rfloc_snapshot::{AverageConfig, AverageTagSet, Snapshot, TagId};
use rfloc_transport::replay::ReplayMode;
use rfloc_transport::Transport;
use serde::Deserialize;

use crate::config::{resolve_credential, Checks};
use crate::devices::{pause, CheckEnv, DeviceContext, Driver};
use crate::events::{DeviceEvent, DeviceState};
use crate::simulation::BoxFuture;

/// `kind = "alien"`: an Alien ALR-9900 UHF reader on its telnet port.
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

/// The UHF reader driver.
pub struct Alien;

impl Driver for Alien {
    const KIND: &'static str = "alien";
    const CAPTURES: &'static [&'static str] = &["alien-alr9900"];
    type Settings = AlienSettings;

    fn check(settings: &AlienSettings, c: &mut Checks<'_, '_>, env: &CheckEnv<'_>) {
        c.count(
            "reads_per_snapshot",
            u64::from(settings.reads_per_snapshot),
            1,
            100,
        );
        if settings.username.is_empty() || settings.username.contains(['\r', '\n']) {
            c.error("username", "must be one non-empty line");
        }
        if let Some(p) = &settings.password_file {
            if env.check_files && resolve_credential(p, env.config_dir).is_none() {
                c.error(
                    "password_file",
                    format!("password file {} not found (looked in $CREDENTIALS_DIRECTORY and next to the config)", p.display()),
                );
            }
        }
    }

    fn replay_mode(_settings: &AlienSettings) -> ReplayMode {
        ReplayMode::RequestResponse
    }

    fn for_capture(_capture: &str) -> Option<AlienSettings> {
        // Each recorded tag list is one snapshot unless the recording marks its averaging.
        Some(AlienSettings {
            username: default_alien_user(),
            password_file: None,
            reads_per_snapshot: 1,
        })
    }

    fn run(settings: AlienSettings, ctx: DeviceContext) -> BoxFuture<'static, ()> {
        Box::pin(run(ctx, settings))
    }
}

/// Seconds between two snapshot polls on a real robot.
const POLL_PERIOD_S: f64 = 0.5;

/// The capture mark written after each averaged snapshot.
pub fn snapshot_mark(reads: usize) -> String {
    format!("snapshot reads={reads}")
}

/// The number of reads of a `snapshot reads=N` mark (text after `mark `).
#[must_use]
pub fn parse_snapshot_mark(text: &str) -> Option<usize> {
    text.trim().strip_prefix("snapshot reads=")?.parse().ok()
}

/// Averages tag lists read at one place (seed 000's `scanNetTags`): the tags of the read that
/// saw the most, each with its mean RSS over the reads that saw it. IDs are hex EPCs; others
/// are dropped.
#[must_use]
pub fn average_reads(reads: &[Vec<(String, f64)>]) -> Vec<(String, f64)> {
    let snapshots: Vec<Snapshot> = reads
        .iter()
        .map(|r| {
            Snapshot::from_reads(
                r.iter()
                    .filter_map(|(id, rss)| Some((TagId::from_hex(id)?, *rss))),
            )
        })
        .collect();
    let config = AverageConfig {
        tag_set: AverageTagSet::LargestRead,
        threshold: f64::NEG_INFINITY,
    };
    Snapshot::average(&snapshots, &config)
        .iter()
        .map(|(id, rss)| (id.to_string(), rss))
        .collect()
}

fn password(ctx: &DeviceContext, settings: &AlienSettings) -> Result<String, String> {
    let Some(file) = &settings.password_file else {
        tracing::warn!("no password_file configured: using the reader's factory default password");
        return Ok("password".into());
    };
    let path = resolve_credential(file, ctx.config_dir.as_deref())
        .ok_or_else(|| format!("password file {} not found", file.display()))?;
    if let Some(w) = crate::config::secret_file_warning(&path) {
        tracing::warn!("{w}");
    }
    let text = std::fs::read_to_string(&path)
        .map_err(|e| format!("cannot read password file {}: {e}", path.display()))?;
    Ok(text
        .lines()
        .next()
        .unwrap_or_default()
        .trim_end()
        .to_string())
}

async fn run(ctx: DeviceContext, settings: AlienSettings) {
    // A replay sends what the capture holds in place of the password.
    let password = match password(&ctx, &settings).or_else(|e| {
        if ctx.replaying() {
            Ok(String::from_utf8_lossy(rfloc_transport::REDACTED).into_owned())
        } else {
            Err(e)
        }
    }) {
        Ok(p) => p,
        Err(e) => {
            tracing::error!(error = %e, "UHF reader not started");
            ctx.status(DeviceState::Closed, e).await;
            return;
        }
    };
    if let Err(e) = ctx.redact(&password) {
        tracing::error!(error = %e, "UHF reader not started: its capture cannot be opened");
        ctx.status(DeviceState::Closed, e.to_string()).await;
        return;
    }
    let config = AlienConfig {
        username: settings.username.clone(),
        password,
        ..AlienConfig::default()
    };
    let opener = ctx.clone();
    let connector: Connector<Transport> = Arc::new(move || {
        let c = opener.clone();
        Box::pin(async move {
            c.open_link()
                .await
                .map_err(|e| std::io::Error::other(format!("{e:#}")))
        })
    });
    // Jitter seeded by the device's name: readers of one robot do not retry in step.
    let name = ctx.device.name.clone();
    let mut session = AlienSession::new(
        connector,
        config,
        ReaderSetup::project(),
        ctx.clock.clone(),
        Backoff::default().with_seed_from(&name),
    )
    .with_auth_backoff(Backoff::authentication().with_seed_from(&name));
    let period = Duration::from_secs_f64(POLL_PERIOD_S / ctx.time_scale.max(1e-6));
    // A replay averages as many reads per snapshot as the recording marks.
    let mut recorded_reads: std::collections::VecDeque<usize> = ctx
        .recorded_marks()
        .iter()
        .filter_map(|m| parse_snapshot_mark(m))
        .collect();
    let configured = settings.reads_per_snapshot.max(1);
    let mut connected = false;
    ctx.status(DeviceState::Connecting, "login").await;
    while !ctx.stop.is_cancelled() {
        // Average `reads` polls.
        let reads = recorded_reads
            .pop_front()
            .map_or(configured, |n| u32::try_from(n).unwrap_or(configured));
        let mut polls: Vec<Vec<(String, f64)>> = Vec::with_capacity(reads as usize);
        let mut t = 0.0;
        let mut failed = None;
        for _ in 0..reads {
            let snap = tokio::select! {
                () = ctx.stop.cancelled() => return,
                s = session.read_snapshot() => s,
            };
            match snap {
                Ok(s) => {
                    t = s.t;
                    polls.push(
                        s.id_rss()
                            .into_iter()
                            .map(|(id, rss)| (id.to_string(), rss))
                            .collect(),
                    );
                }
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        if let Some(e) = failed {
            if ctx.links_exhausted() {
                ctx.status(DeviceState::Closed, "end of recording").await;
                return;
            }
            connected = false;
            // Error text from the session is redacted (no password, no control characters).
            if e.is_auth_failure() {
                // The session waits out its authentication back-off before the next login.
                tracing::error!(error = %e, "UHF reader refused the login");
                ctx.status(DeviceState::Failed, e.to_string()).await;
            } else {
                tracing::warn!(error = %e, "UHF read failed; the session reconnects");
                ctx.status(DeviceState::Reconnecting, e.to_string()).await;
            }
            if !pause(&ctx, period).await {
                return;
            }
            continue;
        }
        if !connected {
            connected = true;
            ctx.status(
                DeviceState::Connected,
                format!("polling, {configured} read(s) per snapshot"),
            )
            .await;
        }
        let tags = average_reads(&polls);
        ctx.mark(&snapshot_mark(polls.len()));
        let snapshot = DeviceEvent::UhfSnapshot {
            device: ctx.device.name.clone(),
            t,
            tags,
        };
        if !ctx.send(snapshot).await {
            return;
        }
        if !pause(&ctx, period).await {
            break;
        }
    }
    ctx.status(DeviceState::Closed, "stopped").await;
}
