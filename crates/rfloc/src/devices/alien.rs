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

use std::sync::Arc;
use std::time::Duration;

use rfloc_alien::{AlienConfig, AlienSession, Backoff, Connector, ReaderSetup, SnapshotReader};
use rfloc_snapshot::{AverageConfig, AverageTagSet, Snapshot, TagId};
use rfloc_transport::Transport;

use crate::config::{resolve_credential, AlienSettings};
use crate::daemon::DeviceContext;
use crate::devices::pause;
use crate::events::DeviceEvent;
use crate::message::DeviceState;

/// Seconds between two snapshot polls on a real robot.
const POLL_PERIOD_S: f64 = 0.5;

/// The capture mark written after each averaged snapshot.
pub fn snapshot_mark(reads: usize) -> String {
    format!("mark snapshot reads={reads}")
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
    let text = std::fs::read_to_string(&path)
        .map_err(|e| format!("cannot read password file {}: {e}", path.display()))?;
    Ok(text
        .lines()
        .next()
        .unwrap_or_default()
        .trim_end()
        .to_string())
}

pub(super) async fn run(ctx: DeviceContext, settings: AlienSettings) {
    let password = match password(&ctx, &settings) {
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
    let mut session = AlienSession::new(
        connector,
        config,
        ReaderSetup::project(),
        ctx.clock.clone(),
        Backoff::default(),
    );
    let period = Duration::from_secs_f64(POLL_PERIOD_S / ctx.time_scale.max(1e-6));
    let reads = settings.reads_per_snapshot.max(1);
    let mut connected = false;
    ctx.status(DeviceState::Connecting, "login").await;
    while !ctx.stop.is_cancelled() {
        // Average `reads` polls.
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
            tracing::warn!(error = %e, "UHF read failed; the session reconnects");
            connected = false;
            ctx.status(DeviceState::Reconnecting, e.to_string()).await;
            if !pause(&ctx, period).await {
                return;
            }
            continue;
        }
        if !connected {
            connected = true;
            ctx.status(
                DeviceState::Connected,
                format!("polling, {reads} read(s) per snapshot"),
            )
            .await;
        }
        let tags = average_reads(&polls);
        if let Some(c) = ctx.capture() {
            c.event(&snapshot_mark(polls.len()));
        }
        if ctx
            .events
            .send(DeviceEvent::UhfSnapshot {
                device: ctx.device.name.clone(),
                t,
                tags,
            })
            .await
            .is_err()
        {
            return;
        }
        if !pause(&ctx, period).await {
            break;
        }
    }
    ctx.status(DeviceState::Closed, "stopped").await;
}
