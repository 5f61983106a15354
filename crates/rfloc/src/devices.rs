//! One task per device: open the link, run the driver, forward events, reconnect with back-off.

use std::io;
use std::time::Duration;

use rfloc_aria::{client::ConnectFuture, AriaClient, ClientConfig};
use rfloc_kts::{KtsClient, KtsConfig, TagEventKind};
use rfloc_transport::Transport;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::config::{AriaSettings, DriverConfig, KtsSettings};
use crate::daemon::{backoff, DeviceContext};
use crate::events::DeviceEvent;
use crate::message::DeviceState;

/// A velocity command for the base: (m/s, rad/s).
pub type MotionSender = mpsc::Sender<(f64, f64)>;

/// Spawns the task of one device. Returns the task and, for a mobile base, a motion sender.
pub fn spawn(ctx: DeviceContext, span: tracing::Span) -> (JoinHandle<()>, Option<MotionSender>) {
    match ctx.device.driver.clone() {
        DriverConfig::Aria(s) => {
            let (tx, rx) = mpsc::channel(16);
            (
                tokio::spawn(aria_task(ctx, s, rx).instrument(span)),
                Some(tx),
            )
        }
        DriverConfig::Kts(s) => (tokio::spawn(kts_task(ctx, s).instrument(span)), None),
        other => {
            let kind = other.kind();
            (
                tokio::spawn(
                    async move {
                        tracing::error!(
                            driver = kind,
                            "driver not wired into the daemon yet; device ignored"
                        );
                        ctx.status(
                            DeviceState::Closed,
                            format!("driver {kind} not available in this build"),
                        )
                        .await;
                    }
                    .instrument(span),
                ),
                None,
            )
        }
    }
}

/// Waits `d` or until the daemon stops; false when stopping.
async fn pause(ctx: &DeviceContext, d: Duration) -> bool {
    tokio::select! {
        () = ctx.stop.cancelled() => false,
        () = tokio::time::sleep(d) => true,
    }
}

async fn aria_task(
    ctx: DeviceContext,
    settings: AriaSettings,
    mut motion: mpsc::Receiver<(f64, f64)>,
) {
    let mut attempt = 0u32;
    while !ctx.stop.is_cancelled() {
        ctx.status(DeviceState::Connecting, "handshake").await;
        let opener = ctx.clone();
        let connector = move || -> ConnectFuture<Transport> {
            let c = opener.clone();
            Box::pin(async move {
                c.open_link()
                    .await
                    .map_err(|e| io::Error::other(format!("{e:#}")))
            })
        };
        let config = ClientConfig {
            pulse_period: Duration::from_secs_f64(settings.pulse_period_s.max(0.05)),
            clock: Some(ctx.clock.clone()),
            ..ClientConfig::default()
        }
        .scaled(ctx.time_scale);
        let client = tokio::select! {
            () = ctx.stop.cancelled() => return,
            c = AriaClient::connect(connector, config) => c,
        };
        let client = match client {
            Ok(c) => c,
            Err(e) => {
                ctx.status(DeviceState::Reconnecting, format!("{e}")).await;
                tracing::warn!(error = %e, attempt, "pioneer connect failed");
                if !pause(&ctx, backoff(attempt)).await {
                    return;
                }
                attempt += 1;
                continue;
            }
        };
        attempt = 0;
        ctx.status(
            DeviceState::Connected,
            format!("robot {}", client.identity().name),
        )
        .await;
        let mut odom = client.odometry();
        let mut link = client.link_state();
        loop {
            tokio::select! {
                () = ctx.stop.cancelled() => {
                    if let Err(e) = client.stop().await {
                        tracing::warn!(error = %e, "STOP on shutdown failed");
                    }
                    if let Err(e) = client.shutdown().await {
                        tracing::warn!(error = %e, "CLOSE on shutdown failed");
                    }
                    ctx.status(DeviceState::Closed, "stopped").await;
                    return;
                }
                changed = odom.changed() => {
                    if changed.is_err() {
                        break;
                    }
                    let o = odom.borrow_and_update().clone();
                    let ev = DeviceEvent::Odometry { device: ctx.device.name.clone(), t: o.time, pose: o.pose, v: o.v, w: o.w };
                    if ctx.events.send(ev).await.is_err() {
                        return;
                    }
                }
                changed = link.changed() => {
                    if changed.is_err() {
                        break;
                    }
                    let state = link.borrow_and_update().clone();
                    match state {
                        rfloc_aria::LinkState::Connecting => ctx.status(DeviceState::Reconnecting, "link lost; reconnecting").await,
                        rfloc_aria::LinkState::Connected(id) => ctx.status(DeviceState::Connected, format!("robot {}", id.name)).await,
                        rfloc_aria::LinkState::Closed => break,
                    }
                }
                cmd = motion.recv() => {
                    let Some((v, w)) = cmd else { continue };
                    if let Err(e) = client.set_velocity(v, w).await {
                        tracing::warn!(error = %e, "velocity command failed");
                    }
                }
            }
        }
        ctx.status(DeviceState::Reconnecting, "client closed").await;
        if !pause(&ctx, backoff(attempt)).await {
            return;
        }
        attempt += 1;
    }
}

async fn kts_task(ctx: DeviceContext, settings: KtsSettings) {
    let mut attempt = 0u32;
    while !ctx.stop.is_cancelled() {
        ctx.status(DeviceState::Connecting, "opening").await;
        let io = match ctx.open_link().await {
            Ok(io) => io,
            Err(e) => {
                ctx.status(DeviceState::Reconnecting, format!("{e:#}"))
                    .await;
                if !pause(&ctx, backoff(attempt)).await {
                    return;
                }
                attempt += 1;
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
            tracing::warn!(error = %e, "start scan failed");
            ctx.status(DeviceState::Reconnecting, format!("start scan: {e}"))
                .await;
            if !pause(&ctx, backoff(attempt)).await {
                return;
            }
            attempt += 1;
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
                    if let TagEventKind::Seen { rssi: Some(r) } = ev.kind {
                        let clamp = |v: i32| u8::try_from(v.clamp(0, 255)).unwrap_or(0);
                        let out = DeviceEvent::HfTag {
                            device: ctx.device.name.clone(),
                            t: ev.t,
                            uid: ev.uid.to_string(),
                            rssi: clamp(r.main),
                            rssi_second: clamp(r.aux.unwrap_or(r.main)),
                        };
                        if ctx.events.send(out).await.is_err() {
                            return;
                        }
                    }
                }
            }
        }
        let stats = client.stats();
        tracing::warn!(?stats, "HF reader link closed; reconnecting");
        ctx.status(DeviceState::Reconnecting, "link closed").await;
        if !pause(&ctx, backoff(attempt)).await {
            return;
        }
        attempt += 1;
    }
}
