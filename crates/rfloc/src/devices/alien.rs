//! Alien ALR-9900 task: a reconnecting session (login, setup, keepalive), polled for snapshots
//! averaged over the configured number of reads.
//!
//! The password comes from `password_file` (looked up in `$CREDENTIALS_DIRECTORY` first, so a
//! systemd `LoadCredential=` works, then next to the robot file), or the reader's factory
//! default when none is configured. It is never logged.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use rfloc_alien::{AlienConfig, AlienSession, Backoff, Connector, ReaderSetup, SnapshotReader};
use rfloc_transport::Transport;

use crate::config::{resolve_credential, AlienSettings};
use crate::daemon::DeviceContext;
use crate::devices::pause;
use crate::events::DeviceEvent;
use crate::message::DeviceState;

/// Seconds between two snapshot polls on a real robot.
const POLL_PERIOD_S: f64 = 0.5;

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
        // Average `reads` polls: mean RSS of each tag over the polls that saw it.
        let mut sums: BTreeMap<String, (f64, u32)> = BTreeMap::new();
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
                    for (id, rss) in s.id_rss() {
                        let e = sums.entry(id.to_string()).or_insert((0.0, 0));
                        e.0 += rss;
                        e.1 += 1;
                    }
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
        let tags = sums
            .into_iter()
            .map(|(id, (sum, n))| (id, sum / f64::from(n)))
            .collect();
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
