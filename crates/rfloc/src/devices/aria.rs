//! Pioneer base task: connect (handshake), forward odometry, apply motion commands, reconnect.
//! With `sonar = true` the sonar ring is switched on and its latest ranges go out as a
//! [`DeviceEvent::RangeScan`] after every SIP that brought new ones.

use std::io;

use rfloc_aria::{client::ConnectFuture, AriaClient};
use rfloc_transport::Transport;
use tokio::sync::mpsc;

use crate::config::AriaSettings;
use crate::daemon::DeviceContext;
use crate::devices::retry_later;
use crate::events::{DeviceEvent, ScanBeam};
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
        let config = rfloc_aria::ClientConfig {
            sonar: settings.sonar,
            ..super::scaled_base_config(ctx.clock.clone(), settings.pulse_period_s, ctx.time_scale)
        };
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
                    if settings.sonar && o.sonar.updated != 0 {
                        let ev = DeviceEvent::RangeScan { device: ctx.device.name.clone(), t: o.time, beams: sonar_beams(&o.sonar) };
                        if ctx.events.send(ev).await.is_err() {
                            return;
                        }
                    }
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

/// The sonar ring's latest ranges as a scan centred on the robot: each disc's echo point (or
/// the point at the end of its reach, for no echo) seen from the centre of rotation. A sonar
/// cone is about 15° wide; the scan keeps only its axis.
pub(crate) fn sonar_beams(ring: &rfloc_aria::SonarRing) -> Vec<ScanBeam> {
    ring.readings()
        .map(|(disc, range)| {
            let echo = range < rfloc_aria::NO_ECHO_M - 0.01;
            let (fx, fy) = disc.echo_point(rfloc_aria::NO_ECHO_M);
            let (x, y) = disc.echo_point(range.min(rfloc_aria::NO_ECHO_M));
            let reach = fx.hypot(fy);
            ScanBeam {
                angle_rad: y.atan2(x),
                range_m: if echo { x.hypot(y) } else { reach },
                max_range_m: reach,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sonar_echoes_are_seen_from_the_centre_of_rotation() {
        let mut ring = rfloc_aria::SonarRing::p3dx();
        let sip = rfloc_aria::MotorSip {
            sonar: vec![
                rfloc_aria::SonarReading {
                    number: 3,
                    range: 1000,
                },
                rfloc_aria::SonarReading {
                    number: 11,
                    range: 5000,
                },
            ],
            ..rfloc_aria::MotorSip::default()
        };
        ring.update(&sip, &rfloc_aria::ConversionFactors::P3DX_SH);
        let beams = sonar_beams(&ring);
        assert_eq!(beams.len(), 2);
        // Disc 3 at (166, 27) mm looking 10° left: echo at 1 m from the disc.
        let (ex, ey) = (
            0.166 + 10f64.to_radians().cos(),
            0.027 + 10f64.to_radians().sin(),
        );
        assert!((beams[0].range_m - ex.hypot(ey)).abs() < 1e-9);
        assert!((beams[0].angle_rad - ey.atan2(ex)).abs() < 1e-9);
        assert!(beams[0].range_m < beams[0].max_range_m);
        // Disc 11 looking back (−170°), no echo: the beam reaches its end.
        assert!((beams[1].range_m - beams[1].max_range_m).abs() < 1e-12);
        assert!(beams[1].angle_rad.abs() > 170f64.to_radians() - 0.05);
    }
}
