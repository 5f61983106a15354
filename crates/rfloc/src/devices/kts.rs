//! KTS HF reader task: open, start scanning, forward tag events, reconnect.

use std::time::Duration;

use rfloc_kts::{KtsClient, KtsConfig};

use crate::config::KtsSettings;
use crate::daemon::DeviceContext;
use crate::devices::retry_later;
use crate::events::DeviceEvent;
use crate::message::DeviceState;

pub(super) async fn run(ctx: DeviceContext, settings: KtsSettings) {
    let mut attempt = 0u32;
    while !ctx.stop.is_cancelled() {
        ctx.status(DeviceState::Connecting, "opening").await;
        let io = match ctx.open_link().await {
            Ok(io) => io,
            Err(e) => {
                if !retry_later(&ctx, &mut attempt, format!("{e:#}")).await {
                    return;
                }
                continue;
            }
        };
        let config = KtsConfig {
            scan_command: settings.scan_command.clone(),
            silence_timeout: Some(Duration::from_secs_f64(
                settings.resync_after_s.max(0.1) / ctx.time_scale.max(1e-6),
            )),
            ..KtsConfig::default()
        };
        let mut client = KtsClient::spawn(io, config, ctx.clock.clone());
        let Some(mut events) = client.take_events() else {
            return;
        };
        if let Err(e) = client.start_scan().await {
            if !retry_later(&ctx, &mut attempt, format!("start scan: {e}")).await {
                return;
            }
            continue;
        }
        attempt = 0;
        ctx.status(DeviceState::Connected, "scanning").await;
        loop {
            tokio::select! {
                () = ctx.stop.cancelled() => {
                    let _ = tokio::time::timeout(Duration::from_millis(500), client.stop_scan()).await;
                    ctx.status(DeviceState::Closed, "stopped").await;
                    return;
                }
                ev = events.recv() => {
                    let Some(ev) = ev else { break };
                    if let Some(out) = DeviceEvent::from_tag_event(&ctx.device.name, &ev) {
                        if ctx.events.send(out).await.is_err() {
                            return;
                        }
                    }
                }
            }
        }
        let stats = client.stats();
        tracing::warn!(?stats, "HF reader link closed; reconnecting");
        if !retry_later(&ctx, &mut attempt, "link closed").await {
            return;
        }
    }
}
