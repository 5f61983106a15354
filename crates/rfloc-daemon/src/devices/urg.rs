//! Hokuyo URG laser range finder task: laser on, one `GD` scan every `scan_period_s`, each as
//! a [`DeviceEvent::RangeScan`]; laser off on shutdown; reconnect with back-off.

use std::time::Duration;

use rfloc_transport::replay::ReplayMode;
use rfloc_urg::{Scan, UrgClient, UrgConfig, UrgGeometry};
use serde::Deserialize;

use crate::config::Checks;
use crate::devices::{retry_later, CheckEnv, DeviceContext, Driver};
use crate::events::{DeviceEvent, DeviceState, ScanBeam};
use crate::simulation::BoxFuture;

/// `kind = "urg"`: a Hokuyo URG laser range finder (SCIP 2.0), scanned with `GD` every
/// `scan_period_s`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UrgSettings {
    /// Seconds between scans.
    #[serde(default = "default_scan_period")]
    pub scan_period_s: f64,
    /// Adjacent steps merged into one value (1 = all 682 steps of a URG-04LX).
    #[serde(default = "default_cluster")]
    pub cluster: u8,
    /// The scanner's position ahead of the robot's centre of rotation, metres.
    #[serde(default)]
    pub mount_offset_m: f64,
}

fn default_scan_period() -> f64 {
    0.2
}

fn default_cluster() -> u8 {
    1
}

impl Default for UrgSettings {
    fn default() -> Self {
        Self {
            scan_period_s: default_scan_period(),
            cluster: default_cluster(),
            mount_offset_m: 0.0,
        }
    }
}

/// The laser driver.
pub struct Urg;

impl Driver for Urg {
    const KIND: &'static str = "urg";
    const CAPTURES: &'static [&'static str] = &["hokuyo-urg"];
    type Settings = UrgSettings;

    fn check(settings: &UrgSettings, c: &mut Checks<'_, '_>, _env: &CheckEnv<'_>) {
        c.range("scan_period_s", settings.scan_period_s, 0.05, 60.0, " s");
        c.count("cluster", u64::from(settings.cluster), 1, 99);
        c.range("mount_offset_m", settings.mount_offset_m, -2.0, 2.0, " m");
    }

    fn replay_mode(_settings: &UrgSettings) -> ReplayMode {
        ReplayMode::RequestResponse
    }

    fn replay_skips_unknown(_settings: &UrgSettings) -> bool {
        // SCIP commands are fixed text: a recording made before the handshake (SCIP2.0, VV,
        // PP) holds none of it, and the scans still line up.
        true
    }

    fn for_capture(_capture: &str) -> Option<UrgSettings> {
        Some(UrgSettings::default())
    }

    fn run(settings: UrgSettings, ctx: DeviceContext) -> BoxFuture<'static, ()> {
        Box::pin(run(ctx, settings))
    }
}

/// Failed scans in a row after which the link is reopened.
const FAILED_SCANS_BEFORE_RECONNECT: u32 = 3;

/// The client settings for a robot file's scanner. The reply time-out is wall time: a
/// sensor answers in wall time however fast a simulation runs.
fn client_config(settings: &UrgSettings) -> UrgConfig {
    UrgConfig {
        geometry: UrgGeometry::default(),
        cluster: settings.cluster,
        reply_timeout: Duration::from_secs(1),
    }
}

/// A scan as beams seen from the robot's centre of rotation (the scanner `mount_offset_m`
/// ahead of it); no echo reads as the sensor's full reach.
pub fn scan_beams(scan: &Scan, geometry: &UrgGeometry, mount_offset_m: f64) -> Vec<ScanBeam> {
    let reach = f64::from(geometry.max_mm) / 1000.0;
    scan.beams(geometry)
        .map(|(angle, range)| {
            let to_centre = |r: f64| {
                let (x, y) = (mount_offset_m + r * angle.cos(), r * angle.sin());
                (y.atan2(x), x.hypot(y))
            };
            let (far_angle, far) = to_centre(reach);
            match range {
                Some(r) => {
                    let (a, d) = to_centre(r);
                    ScanBeam {
                        angle_rad: a,
                        range_m: d,
                        max_range_m: far,
                    }
                }
                None => ScanBeam {
                    angle_rad: far_angle,
                    range_m: far,
                    max_range_m: far,
                },
            }
        })
        .collect()
}

async fn run(ctx: DeviceContext, settings: UrgSettings) {
    let period = crate::time::seconds(settings.scan_period_s / ctx.time_scale.max(1e-6));
    let mut attempt = 0u32;
    while !ctx.stop.is_cancelled() {
        ctx.status(DeviceState::Connecting, "opening scanner").await;
        let io = match ctx.open_link().await {
            Ok(io) => io,
            Err(e) => {
                if !retry_later(&ctx, &mut attempt, format!("{e:#}")).await {
                    return;
                }
                continue;
            }
        };
        // SCIP2.0, VV and PP: the sensor says what it is and its scan geometry.
        let connected = tokio::select! {
            () = ctx.stop.cancelled() => return,
            r = UrgClient::connect(io, client_config(&settings)) => r,
        };
        let mut client = match connected {
            Ok((client, info)) => {
                let model = info
                    .parameters
                    .iter()
                    .find(|(k, _)| k == "MODL")
                    .map_or("unknown model", |(_, v)| v.as_str());
                tracing::info!(model, geometry = ?client.geometry(), "scanner identified");
                client
            }
            Err(e) => {
                if !retry_later(&ctx, &mut attempt, format!("handshake: {e}")).await {
                    return;
                }
                continue;
            }
        };
        let geometry = client.geometry();
        let on = tokio::select! {
            () = ctx.stop.cancelled() => return,
            r = client.laser_on() => r,
        };
        if let Err(e) = on {
            if !retry_later(&ctx, &mut attempt, format!("laser on: {e}")).await {
                return;
            }
            continue;
        }
        attempt = 0;
        ctx.status(DeviceState::Connected, "scanning").await;
        let mut ticker = tokio::time::interval(period);
        ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut failures = 0u32;
        let stopped = loop {
            tokio::select! {
                () = ctx.stop.cancelled() => break true,
                _ = ticker.tick() => {}
            }
            let scanned = tokio::select! {
                () = ctx.stop.cancelled() => break true,
                r = client.scan() => r,
            };
            match scanned {
                Ok(scan) => {
                    failures = 0;
                    let event = DeviceEvent::RangeScan {
                        device: ctx.device.name.clone(),
                        t: ctx.clock.now(),
                        beams: scan_beams(&scan, &geometry, settings.mount_offset_m),
                    };
                    if !ctx.send(event).await {
                        break true;
                    }
                }
                Err(e) => {
                    failures += 1;
                    tracing::warn!(error = %e, failures, "laser scan failed");
                    if failures >= FAILED_SCANS_BEFORE_RECONNECT {
                        break false;
                    }
                }
            }
        };
        if stopped {
            if let Err(e) = client.laser_off().await {
                tracing::warn!(error = %e, "laser off on shutdown failed");
            }
            break;
        }
        if !retry_later(&ctx, &mut attempt, "scanner stopped answering").await {
            break;
        }
    }
    ctx.status(DeviceState::Closed, "stopped").await;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beams_are_seen_from_the_centre_of_rotation() {
        let scan = Scan {
            start_step: 384,
            end_step: 385,
            cluster: 1,
            timestamp_ms: 0,
            ranges_mm: vec![1000, 0],
        };
        let g = UrgGeometry::default();
        let beams = scan_beams(&scan, &g, 0.1);
        // Straight ahead, 1 m from a scanner 0.1 m ahead of the centre.
        assert!((beams[0].range_m - 1.1).abs() < 1e-12 && beams[0].angle_rad.abs() < 1e-12);
        assert!((beams[0].max_range_m - 5.7).abs() < 1e-12);
        // No echo: the full reach.
        assert!((beams[1].range_m - beams[1].max_range_m).abs() < 1e-12);
    }
}
