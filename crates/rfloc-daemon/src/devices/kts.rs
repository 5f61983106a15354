//! KTS RFIDM1356 HF reader: open, start scanning, forward tag events, reconnect.

use std::time::Duration;

use rfloc_kts::{KtsClient, KtsConfig};
use serde::Deserialize;

use crate::config::Checks;
use crate::devices::{retry_later, CheckEnv, DeviceContext, Driver};
use crate::events::{DeviceEvent, DeviceState};
use crate::simulation::BoxFuture;

/// How often a link's error counters are reported (when they changed).
const COUNTER_PERIOD: Duration = Duration::from_secs(10);

/// `kind = "kts"`: the HF floor-tag reader on a UART.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KtsSettings {
    #[serde(default = "default_scan_command")]
    pub scan_command: String,
    /// Seconds of silence after which the client sends `AT` and restarts scanning.
    #[serde(default = "default_silence")]
    pub resync_after_s: f64,
}

fn default_scan_command() -> String {
    "AT+Scan=AC,RSSI".into()
}

fn default_silence() -> f64 {
    2.0
}

impl Default for KtsSettings {
    fn default() -> Self {
        Self {
            scan_command: default_scan_command(),
            resync_after_s: default_silence(),
        }
    }
}

/// The HF reader driver.
pub struct Kts;

impl Driver for Kts {
    const KIND: &'static str = "kts";
    const CAPTURES: &'static [&'static str] = &["kts-rfidm1356"];
    type Settings = KtsSettings;

    fn check(settings: &KtsSettings, c: &mut Checks<'_, '_>, _env: &CheckEnv<'_>) {
        c.range("resync_after_s", settings.resync_after_s, 0.1, 3600.0, " s");
        if !settings.scan_command.starts_with("AT") || settings.scan_command.contains(['\r', '\n'])
        {
            c.error(
                "scan_command",
                format!("{:?} is not one AT command line", settings.scan_command),
            );
        }
    }

    fn for_capture(_capture: &str) -> Option<KtsSettings> {
        Some(KtsSettings::default())
    }

    fn run(settings: KtsSettings, ctx: DeviceContext) -> BoxFuture<'static, ()> {
        Box::pin(run(ctx, settings))
    }
}

async fn run(ctx: DeviceContext, settings: KtsSettings) {
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
            // A replay ends where its recording does; silence there is not the reader's.
            silence_timeout: (!ctx.replaying()).then(|| {
                crate::time::seconds(settings.resync_after_s.max(0.1) / ctx.time_scale.max(1e-6))
            }),
            ..KtsConfig::default()
        };
        let mut client = KtsClient::spawn(io, config, ctx.clock.clone());
        let Some(mut events) = client.take_events() else {
            return;
        };
        if let Err(e) = client.start_scan().await {
            // The old link is closed before the back-off: a serial port stays locked while open.
            drop(events);
            client.close().await;
            if !retry_later(&ctx, &mut attempt, format!("start scan: {e}")).await {
                return;
            }
            continue;
        }
        attempt = 0;
        ctx.status(DeviceState::Connected, "scanning").await;
        let mut summary = tokio::time::interval(COUNTER_PERIOD);
        let mut reported = 0u64;
        loop {
            tokio::select! {
                _ = summary.tick() => {
                    // Errors on the link: counted in the DEVICE line, summarised in the log.
                    let s = client.stats();
                    let errors = s.codec.malformed + s.codec.control_bytes_dropped + s.codec.overflow_bytes_dropped + s.events_dropped;
                    if errors != reported {
                        reported = errors;
                        ctx.status_with_counters(DeviceState::Connected, "scanning", vec![
                            ("lines", s.codec.lines),
                            ("malformed_lines", s.codec.malformed),
                            ("control_bytes_dropped", s.codec.control_bytes_dropped),
                            ("overlong_bytes_dropped", s.codec.overflow_bytes_dropped),
                            ("events_dropped", s.events_dropped),
                        ]).await;
                    }
                }
                () = ctx.stop.cancelled() => {
                    let _ = tokio::time::timeout(Duration::from_millis(500), client.stop_scan()).await;
                    ctx.status(DeviceState::Closed, "stopped").await;
                    return;
                }
                ev = events.recv() => {
                    let Some(ev) = ev else { break };
                    if let Some(out) = DeviceEvent::from_tag_event(&ctx.device.name, &ev) {
                        if !ctx.send(out).await {
                            return;
                        }
                    }
                }
            }
        }
        let stats = client.stats();
        tracing::warn!(?stats, "HF reader link closed; reconnecting");
        drop(events);
        client.close().await;
        if !retry_later(&ctx, &mut attempt, "link closed").await {
            return;
        }
    }
}
