//! XBee radio behind one of the emitter-homing robot's four fixed reflectors (seed 001): every
//! `poll_period_s` a remote `DB` to the emitter radio makes it answer, and the receiver's local
//! `DB` gives the RSSI it measured on that answer. Each poll is one
//! [`DeviceEvent::EmitterRss`] (`None` when the emitter did not answer).
//!
//! A link that fails three polls in a row is reopened with back-off.

use std::time::Duration;

use rfloc_xbee::{Address64, ClientConfig, NdLayoutHint, RssiSource, XBeeClient};

use crate::devices::xbee::XbeeSettings;
use crate::devices::{retry_later, DeviceContext};
use crate::events::{AntennaSide, DeviceEvent, DeviceState};

/// Failed polls in a row after which the link is reopened.
const FAILED_POLLS_BEFORE_RECONNECT: u32 = 3;

fn client_config(settings: &XbeeSettings, time_scale: f64) -> ClientConfig {
    let scale = |d: Duration| crate::time::seconds(d.as_secs_f64() / time_scale.max(1.0));
    ClientConfig {
        mode: settings.mode(),
        nd_layout: NdLayoutHint::Auto,
        rssi_source: RssiSource::LocalDbAfterRemote,
        // A poll that waits longer than a few periods is stale anyway.
        response_timeout: scale(Duration::from_millis(500)),
        remote_timeout: scale(Duration::from_secs(1)),
        ..ClientConfig::default()
    }
}

pub(super) async fn run(ctx: DeviceContext, settings: XbeeSettings) {
    let (Some(antenna), Some(emitter)) = (settings.antenna, settings.emitter_address()) else {
        ctx.status(
            DeviceState::Closed,
            "emitter receiver without antenna or emitter address",
        )
        .await;
        return;
    };
    let period = crate::time::seconds(settings.poll_period_s / ctx.time_scale.max(1e-6));
    let mut attempt = 0u32;
    while !ctx.stop.is_cancelled() {
        ctx.status(DeviceState::Connecting, "opening radio").await;
        let io = match ctx.open_link().await {
            Ok(io) => io,
            Err(e) => {
                if !retry_later(&ctx, &mut attempt, format!("xbee link: {e:#}")).await {
                    return;
                }
                continue;
            }
        };
        let mut client = XBeeClient::new(io, client_config(&settings, ctx.time_scale));
        ctx.status(DeviceState::Connected, "polling the emitter")
            .await;
        attempt = 0;
        if poll(&ctx, &mut client, antenna, Address64(emitter), period).await {
            break;
        }
        if !retry_later(&ctx, &mut attempt, "radio stopped answering").await {
            break;
        }
    }
    ctx.status(DeviceState::Closed, "stopped").await;
}

/// Polls until the daemon stops (true) or the radio fails [`FAILED_POLLS_BEFORE_RECONNECT`]
/// polls in a row (false: reconnect).
async fn poll<T>(
    ctx: &DeviceContext,
    client: &mut XBeeClient<T>,
    antenna: AntennaSide,
    emitter: Address64,
    period: Duration,
) -> bool
where
    T: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send,
{
    let mut failures = 0u32;
    let mut ticker = tokio::time::interval(period);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            () = ctx.stop.cancelled() => return true,
            _ = ticker.tick() => {}
        }
        let reading = tokio::select! {
            () = ctx.stop.cancelled() => return true,
            r = client.node_rssi(emitter) => r,
        };
        let dbm = match reading {
            Ok(dbm) => {
                failures = 0;
                dbm
            }
            Err(e) => {
                failures += 1;
                tracing::warn!(error = %e, failures, "emitter RSSI poll failed");
                if failures >= FAILED_POLLS_BEFORE_RECONNECT {
                    return false;
                }
                continue;
            }
        };
        let event = DeviceEvent::EmitterRss {
            device: ctx.device.name.clone(),
            t: ctx.clock.now(),
            antenna,
            dbm,
        };
        if !ctx.send(event).await {
            return true;
        }
    }
}
