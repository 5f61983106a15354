//! Pioneer base task: connect (handshake), forward odometry, apply motion commands, reconnect.

use std::io;

use rfloc_aria::{client::ConnectFuture, AriaClient};
use rfloc_transport::Transport;
use tokio::sync::mpsc;

use crate::config::AriaSettings;
use crate::daemon::DeviceContext;
use crate::devices::retry_later;
use crate::events::DeviceEvent;
use crate::message::DeviceState;

pub(super) async fn run(
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
        let config =
            super::scaled_base_config(ctx.clock.clone(), settings.pulse_period_s, ctx.time_scale);
        let client = tokio::select! {
            () = ctx.stop.cancelled() => return,
            c = AriaClient::connect(connector, config) => c,
        };
        let client = match client {
            Ok(c) => c,
            Err(e) => {
                if !retry_later(&ctx, &mut attempt, format!("pioneer connect: {e}")).await {
                    return;
                }
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
        let mut stalled = false;
        let mut bumpers = (false, false);
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
                    let o = *odom.borrow_and_update();
                    let ev = DeviceEvent::Odometry { device: ctx.device.name.clone(), t: o.time, pose: o.pose, v: o.v, w: o.w };
                    if ctx.events.send(ev).await.is_err() {
                        return;
                    }
                    let stalled_now = o.left_stall || o.right_stall;
                    if stalled_now && !stalled {
                        let ev = DeviceEvent::WheelStall { device: ctx.device.name.clone(), t: o.time };
                        if ctx.events.send(ev).await.is_err() {
                            return;
                        }
                    }
                    stalled = stalled_now;
                    let bumpers_now = (o.front_bumpers != 0, o.rear_bumpers != 0);
                    if bumpers_now != bumpers {
                        bumpers = bumpers_now;
                        let ev = DeviceEvent::Bumpers { device: ctx.device.name.clone(), t: o.time, front: bumpers.0, rear: bumpers.1 };
                        if ctx.events.send(ev).await.is_err() {
                            return;
                        }
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
        if !retry_later(&ctx, &mut attempt, "client closed").await {
            return;
        }
    }
}
