//! Pioneer base (ARIA protocol): connect (handshake), forward odometry, apply the pipeline's
//! velocity requests, reconnect. With `sonar = true` the sonar ring is switched on and its
//! latest ranges go out as a [`DeviceEvent::RangeScan`] after every SIP that brought new ones.

use std::io;

use rfloc_aria::{client::ConnectFuture, AriaClient};
use rfloc_transport::Transport;
use serde::Deserialize;

use crate::config::Checks;
use crate::devices::{retry_later, CheckEnv, DeviceContext, Driver};
use crate::events::{DeviceEvent, DeviceState, ScanBeam};
use crate::pipeline::Request;
use crate::simulation::BoxFuture;

/// `kind = "aria"`: a Pioneer P3-DX class base on a serial link.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AriaSettings {
    /// Seconds without a command before a PULSE keeps the robot's watchdog fed.
    #[serde(default = "default_pulse")]
    pub pulse_period_s: f64,
    /// Switch the sonar ring on and publish its ranges as range scans (for a pipeline that
    /// maps obstacles, on a robot without a laser).
    #[serde(default)]
    pub sonar: bool,
}

fn default_pulse() -> f64 {
    1.0
}

impl Default for AriaSettings {
    fn default() -> Self {
        Self {
            pulse_period_s: default_pulse(),
            sonar: false,
        }
    }
}

/// The Pioneer base driver.
pub struct Aria;

impl Driver for Aria {
    const KIND: &'static str = "aria";
    const CAPTURES: &'static [&'static str] = &["pioneer-aria"];
    type Settings = AriaSettings;

    fn check(settings: &AriaSettings, c: &mut Checks<'_, '_>, _env: &CheckEnv<'_>) {
        // The robot's watchdog trips after 2 s without a command.
        c.range("pulse_period_s", settings.pulse_period_s, 0.05, 1.9, " s");
    }

    fn for_capture(_capture: &str) -> Option<AriaSettings> {
        // Sonar on: a recording without sonar readings gives no scans either way.
        Some(AriaSettings {
            sonar: true,
            ..AriaSettings::default()
        })
    }

    fn handles(_settings: &AriaSettings, request: &Request) -> bool {
        matches!(request, Request::Velocity { .. })
    }

    fn run(settings: AriaSettings, ctx: DeviceContext) -> BoxFuture<'static, ()> {
        Box::pin(run(ctx, settings))
    }
}

/// Odometry updates queued between the client task and this task before the client waits.
const ODOMETRY_QUEUE: usize = 256;

async fn run(ctx: DeviceContext, settings: AriaSettings) {
    let mut commands = ctx.commands().await;
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
            odometry_queue: ODOMETRY_QUEUE,
            ..super::scaled_base_config(ctx.clock.clone(), settings.pulse_period_s, ctx.time_scale)
        };
        let client = tokio::select! {
            () = ctx.stop.cancelled() => return,
            c = AriaClient::connect(connector, config) => c,
        };
        let mut client = match client {
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
        let Some(mut odometry) = client.take_odometry_queue() else {
            return;
        };
        let mut observer = SipObserver::new(settings.sonar);
        let mut link = client.link_state();
        let mut summary = tokio::time::interval(std::time::Duration::from_secs(10));
        let mut reported = 0u64;
        loop {
            tokio::select! {
                _ = summary.tick() => {
                    // Errors on the link: counted in the DEVICE line, summarised in the log.
                    let s = client.stats();
                    let errors = s.dropped_bytes + s.bad_checksums + s.malformed_packets;
                    if errors != reported {
                        reported = errors;
                        ctx.status_with_counters(DeviceState::Connected, format!("robot {}", client.identity().name), vec![
                            ("sips", s.sips),
                            ("dropped_bytes", s.dropped_bytes),
                            ("bad_checksums", s.bad_checksums),
                            ("malformed_packets", s.malformed_packets),
                        ]).await;
                    }
                }
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
                o = odometry.recv() => {
                    let Some(o) = o else { break };
                    ctx.resources.note_battery(o.battery_v);
                    for ev in observer.observe(ctx.name(), &o) {
                        if !ctx.send(ev).await {
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
                        rfloc_aria::LinkState::Connecting if ctx.links_exhausted() => {
                            // A replay ends with its recording: drain what was decoded.
                            while let Ok(o) = odometry.try_recv() {
                                for ev in observer.observe(ctx.name(), &o) {
                                    let _ = ctx.send(ev).await;
                                }
                            }
                            ctx.status(DeviceState::Closed, "end of recording").await;
                            return;
                        }
                        rfloc_aria::LinkState::Connecting => ctx.status(DeviceState::Reconnecting, "link lost; reconnecting").await,
                        rfloc_aria::LinkState::Connected(id) => ctx.status(DeviceState::Connected, format!("robot {}", id.name)).await,
                        rfloc_aria::LinkState::Closed => break,
                    }
                }
                cmd = next_command(&mut commands) => {
                    if let Some(Request::Velocity { v, w }) = cmd {
                        // The client task may be waiting for room in the odometry queue before
                        // it takes the command: keep draining it meanwhile.
                        let command = client.set_velocity(v, w);
                        tokio::pin!(command);
                        loop {
                            tokio::select! {
                                r = &mut command => {
                                    if let Err(e) = r {
                                        tracing::warn!(error = %e, "velocity command failed");
                                    }
                                    break;
                                }
                                o = odometry.recv() => {
                                    let Some(o) = o else { break };
                                    ctx.resources.note_battery(o.battery_v);
                                    for ev in observer.observe(ctx.name(), &o) {
                                        if !ctx.send(ev).await {
                                            return;
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        if !retry_later(&ctx, &mut attempt, "client closed").await {
            return;
        }
    }
}

/// The next pipeline request, or never once the request channel closed.
pub(crate) async fn next_command(commands: &mut crate::devices::CommandQueue) -> Option<Request> {
    match commands.recv().await {
        Some(r) => Some(r),
        None => std::future::pending().await,
    }
}

/// Turns each SIP's odometry into observations: the odometry itself, a wheel stall when one
/// begins, the sonar ring when it brought new ranges, the bumpers when they change.
#[derive(Debug)]
pub struct SipObserver {
    sonar: bool,
    stalled: bool,
    bumpers: (bool, bool),
}

impl SipObserver {
    /// An observer; `sonar` publishes the ring's ranges.
    #[must_use]
    pub fn new(sonar: bool) -> Self {
        Self {
            sonar,
            stalled: false,
            bumpers: (false, false),
        }
    }

    /// The observations of one SIP.
    pub fn observe(&mut self, device: &str, o: &rfloc_aria::Odometry) -> Vec<DeviceEvent> {
        let mut out = vec![DeviceEvent::Odometry {
            device: device.to_string(),
            t: o.time,
            pose: o.pose,
            v: o.v,
            w: o.w,
        }];
        let stalled_now = o.left_stall || o.right_stall;
        if stalled_now && !self.stalled {
            out.push(DeviceEvent::WheelStall {
                device: device.to_string(),
                t: o.time,
            });
        }
        self.stalled = stalled_now;
        if self.sonar && o.sonar.updated != 0 {
            out.push(DeviceEvent::RangeScan {
                device: device.to_string(),
                t: o.time,
                beams: sonar_beams(&o.sonar),
            });
        }
        let bumpers_now = (o.front_bumpers != 0, o.rear_bumpers != 0);
        if bumpers_now != self.bumpers {
            self.bumpers = bumpers_now;
            out.push(DeviceEvent::Bumpers {
                device: device.to_string(),
                t: o.time,
                front: bumpers_now.0,
                rear: bumpers_now.1,
            });
        }
        out
    }
}

/// The sonar ring's latest ranges as a scan centred on the robot: each disc's echo point (or
/// the point at the end of its reach, for no echo) seen from the centre of rotation. A sonar
/// cone is about 15° wide; the scan keeps only its axis.
pub fn sonar_beams(ring: &rfloc_aria::SonarRing) -> Vec<ScanBeam> {
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
