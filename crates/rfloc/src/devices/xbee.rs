//! XBee radio in a turning reflector: on request, one antenna sweep (the stepper turns the
//! reflector stop by stop, one `ND` round per stop), reported as a [`DeviceEvent::Sweep`].
//!
//! Captures: each sweep is framed by two marks in the radio's capture, `mark sweep start
//! heading_rad=…` and `mark sweep end antenna_rad=a0,a1,…` (the angle reached at each stop, in
//! the order of the sweep's `ND` requests), so that `rfloc replay` can rebuild the sweeps from
//! the recorded `ND` rounds.
//!
//! The task owns both the radio link and the antenna rotator (the GPIO stepper device of the
//! robot file, or a simulated one): a sweep needs both, in lock step. A lost radio link is
//! reopened with back-off; the rotator is kept across reconnections so its step count (the
//! antenna's zero) survives.

use std::time::Duration;

use rfloc_bearing::{RssiProbe as SweepProbe, ScanConfig, ScanError, ScanRunner};
use rfloc_stepper::gpio::{open_gpio_stepper, GpioStepperConfig, LineRef};
use rfloc_stepper::{AntennaRotator, SimulatedStepper, StepperConfig, StepperError, StepperHandle};
use rfloc_transport::CaptureSink;
use rfloc_xbee::{ClientConfig, NdLayoutHint, XBeeClient, XBeeError};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::mpsc;

use crate::config::{StepperSettings, XbeeSettings};
use crate::daemon::DeviceContext;
use crate::devices::retry_later;
use crate::events::{DeviceEvent, SweptBeacon};
use crate::message::DeviceState;

/// A request for one sweep: the robot stands still with this odometry heading (radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepRequest {
    pub heading_rad: f64,
}

/// Where the antenna rotator comes from.
#[derive(Debug)]
pub enum AntennaSource {
    /// The robot's stepper on Linux GPIO, opened by the task.
    Gpio(StepperSettings),
    /// A pin-less rotator (simulation: the emulated radio reads its angle).
    Simulated(SimulatedStepper),
}

/// What the XBee device task needs besides its link.
#[derive(Debug)]
pub struct SweepSetup {
    pub antenna: AntennaSource,
    pub scan: ScanConfig,
}

/// The antenna rotator in use.
pub enum Antenna {
    Gpio(StepperHandle),
    Simulated(SimulatedStepper),
}

impl AntennaRotator for Antenna {
    type Error = StepperError;

    async fn move_to(&mut self, angle_rad: f64) -> Result<f64, StepperError> {
        match self {
            Antenna::Gpio(h) => h.move_to(angle_rad).await,
            Antenna::Simulated(s) => s.move_to(angle_rad).await,
        }
    }

    fn angle(&self) -> f64 {
        match self {
            Antenna::Gpio(h) => h.angle(),
            Antenna::Simulated(s) => s.angle(),
        }
    }
}

/// The stepper settings of a robot file as the stepper crate's configuration.
fn stepper_config(s: &StepperSettings) -> (GpioStepperConfig, StepperConfig) {
    let line = |name: &str| match name.parse::<u32>() {
        Ok(offset) => LineRef::Offset(offset),
        Err(_) => LineRef::Name(name.to_string()),
    };
    let gpio = GpioStepperConfig {
        chip: s.chip.clone().into(),
        step: line(&s.step_line),
        dir: line(&s.dir_line),
        enable: s.enable_line.as_deref().map(line),
        consumer: "rflocd".into(),
    };
    let motion = StepperConfig {
        full_steps_per_rev: s.steps_per_rev,
        microsteps: s.microsteps,
        gear_ratio: s.gear_ratio,
        invert_direction: s.invert_direction,
        ..StepperConfig::default()
    };
    (gpio, motion)
}

/// Opens the rotator `source` describes. A GPIO stepper that cannot be opened leaves its
/// settings in `source` for the next attempt.
fn open_antenna(source: &mut Option<AntennaSource>) -> Result<Option<Antenna>, StepperError> {
    match source.take() {
        None => Ok(None),
        Some(AntennaSource::Simulated(s)) => Ok(Some(Antenna::Simulated(s))),
        Some(AntennaSource::Gpio(settings)) => {
            let (gpio, motion) = stepper_config(&settings);
            match open_gpio_stepper(&gpio, motion).and_then(StepperHandle::spawn) {
                Ok(handle) => Ok(Some(Antenna::Gpio(handle))),
                Err(e) => {
                    *source = Some(AntennaSource::Gpio(settings));
                    Err(e)
                }
            }
        }
    }
}

/// The radio as the sweep's RSSI probe: one `ND` round per stop, each beacon's RSSI from the
/// RSSI byte of its `ND` record, beacon id = 64-bit address.
pub struct NdRssiProbe<T> {
    client: XBeeClient<T>,
    /// `ND` records that could not be parsed, summed over rounds.
    pub rejected_records: u64,
}

impl<T> NdRssiProbe<T> {
    /// Wraps a connected client.
    pub fn new(client: XBeeClient<T>) -> Self {
        Self {
            client,
            rejected_records: 0,
        }
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> NdRssiProbe<T> {
    /// Bytes the XBee codec dropped while resynchronising.
    #[must_use]
    pub fn dropped_bytes(&self) -> u64 {
        self.client.stats().decode.dropped_bytes
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> SweepProbe for NdRssiProbe<T> {
    type Error = XBeeError;

    async fn rssi_all(&mut self) -> Result<Vec<(u64, f64)>, XBeeError> {
        let round = self.client.discover().await?;
        self.rejected_records += round.rejected.len() as u64;
        Ok(round
            .nodes
            .iter()
            .filter_map(|n| n.rssi_dbm().map(|dbm| (n.address.0, dbm)))
            .collect())
    }
}

/// Per-beacon results of a sweep report that the filter can use.
pub fn swept_beacons(report: &rfloc_bearing::SweepReport) -> Vec<SweptBeacon> {
    report
        .beacons
        .iter()
        .filter_map(|(id, r)| match r {
            Ok(b) => Some(SweptBeacon {
                id: *id,
                peak_rssi_dbm: b.peak_rssi_dbm,
                bearing_rad: b.bearing_rad,
                bearing_variance_rad2: b.bearing_variance_rad2,
            }),
            Err(why) => {
                tracing::debug!(beacon = format!("{id:016X}"), reason = %why, "beacon not estimated from this sweep");
                None
            }
        })
        .collect()
}

fn client_config(settings: &XbeeSettings) -> ClientConfig {
    ClientConfig {
        mode: settings.mode(),
        nd_layout: NdLayoutHint::Auto,
        discovery_margin: Duration::from_millis(500),
        ..ClientConfig::default()
    }
}

pub(super) async fn run(
    ctx: DeviceContext,
    settings: XbeeSettings,
    setup: Option<SweepSetup>,
    mut requests: mpsc::Receiver<SweepRequest>,
) {
    let Some(SweepSetup { antenna, scan }) = setup else {
        ctx.status(
            DeviceState::Closed,
            "no antenna rotator (stepper device) for the sweep",
        )
        .await;
        return;
    };
    let nt = Duration::from_secs_f64(settings.discovery_timeout_s);
    let mut source = Some(antenna);
    let mut rotator: Option<Antenna> = None;
    let mut attempt = 0u32;
    while !ctx.stop.is_cancelled() {
        ctx.status(DeviceState::Connecting, "opening radio and antenna")
            .await;
        if rotator.is_none() {
            match open_antenna(&mut source) {
                Ok(a) => rotator = a,
                Err(e) => {
                    if !retry_later(&ctx, &mut attempt, format!("antenna: {e}")).await {
                        return;
                    }
                    continue;
                }
            }
        }
        let (io, capture) = match ctx.open_link_recorded().await {
            Ok(opened) => opened,
            Err(e) => {
                if !retry_later(&ctx, &mut attempt, format!("xbee link: {e:#}")).await {
                    return;
                }
                continue;
            }
        };
        let mut client = XBeeClient::new(io, client_config(&settings));
        let setup = tokio::select! {
            () = ctx.stop.cancelled() => return,
            r = client.set_node_discovery_timeout(nt) => r,
        };
        if let Err(e) = setup {
            if !retry_later(&ctx, &mut attempt, format!("setting NT: {e}")).await {
                return;
            }
            continue;
        }
        let Some(antenna) = rotator.take() else {
            ctx.status(DeviceState::Closed, "antenna rotator lost")
                .await;
            return;
        };
        let mut runner = match ScanRunner::new(antenna, NdRssiProbe::new(client), scan) {
            Ok(r) => r,
            Err(e) => {
                ctx.status(DeviceState::Closed, format!("sweep plan: {e}"))
                    .await;
                return;
            }
        };
        attempt = 0;
        ctx.status(DeviceState::Connected, "radio and antenna ready")
            .await;
        let link_lost = serve_sweeps(&ctx, &mut runner, &mut requests, capture.as_ref()).await;
        let (antenna, probe) = runner.into_parts();
        rotator = Some(antenna);
        if probe.rejected_records > 0 {
            tracing::warn!(
                rejected = probe.rejected_records,
                "ND records rejected on this link"
            );
        }
        if !link_lost {
            break;
        }
        if !retry_later(&ctx, &mut attempt, "radio stopped answering").await {
            break;
        }
    }
    if let Some(Antenna::Gpio(handle)) = rotator {
        match handle.shutdown().await {
            Ok(steps) => tracing::info!(steps, "antenna stepper disabled"),
            Err(e) => tracing::warn!(error = %e, "antenna stepper shutdown"),
        }
    }
    ctx.status(DeviceState::Closed, "stopped").await;
}

/// Runs sweeps on request until the daemon stops (false) or the radio stops answering (true).
async fn serve_sweeps<T: AsyncRead + AsyncWrite + Unpin + Send>(
    ctx: &DeviceContext,
    runner: &mut ScanRunner<Antenna, NdRssiProbe<T>>,
    requests: &mut mpsc::Receiver<SweepRequest>,
    capture: Option<&CaptureSink>,
) -> bool {
    loop {
        let request = tokio::select! {
            () = ctx.stop.cancelled() => return false,
            r = requests.recv() => match r {
                Some(r) => r,
                None => return false,
            },
        };
        let heading = request.heading_rad;
        if let Some(c) = capture {
            c.event(&sweep_start_mark(heading));
        }
        let scanned = tokio::select! {
            () = ctx.stop.cancelled() => return false,
            r = runner.scan(move || heading) => r,
        };
        // The sweep's time is its end mark's, so a replay of the capture gives the pipeline
        // the same time the daemon did.
        let t = match capture {
            Some(c) => {
                let angles: Vec<f64> = match &scanned {
                    Ok(r) => r.sweep.samples.iter().map(|s| s.antenna_rad).collect(),
                    Err(_) => Vec::new(),
                };
                c.event(&sweep_end_mark(&angles))
            }
            None => ctx.clock.now(),
        };
        let (result, lost) = match scanned {
            Ok(r) => (Ok(swept_beacons(&r.report)), false),
            Err(e) => {
                tracing::warn!(error = %e, "sweep abandoned");
                let lost = matches!(e, ScanError::Probe { .. });
                (Err(e.to_string()), lost)
            }
        };
        let event = DeviceEvent::Sweep {
            device: ctx.device.name.clone(),
            t,
            result,
        };
        if ctx.events.send(event).await.is_err() {
            return false;
        }
        if lost {
            return true;
        }
    }
}

/// `mark sweep start heading_rad=…` (text after `ev `). Angles are printed in the shortest form
/// that reads back to the same `f64`, so a replay computes with exactly the live values.
fn sweep_start_mark(heading_rad: f64) -> String {
    format!("mark sweep start heading_rad={heading_rad}")
}

/// `mark sweep end antenna_rad=a0,a1,…`; no angles for an abandoned sweep.
fn sweep_end_mark(angles: &[f64]) -> String {
    let list: Vec<String> = angles.iter().map(|a| format!("{a}")).collect();
    format!("mark sweep end antenna_rad={}", list.join(","))
}

/// A sweep mark of a capture (the text after `mark `).
#[derive(Debug, Clone, PartialEq)]
pub enum SweepMark {
    Start { heading_rad: f64 },
    End { antenna_rad: Vec<f64> },
}

impl SweepMark {
    /// Parses `sweep start heading_rad=…` / `sweep end antenna_rad=…`; `None` for other marks
    /// or a malformed number (a damaged capture).
    #[must_use]
    pub fn parse(text: &str) -> Option<SweepMark> {
        if let Some(rest) = text.strip_prefix("sweep start heading_rad=") {
            return rest
                .trim()
                .parse()
                .ok()
                .map(|h| SweepMark::Start { heading_rad: h });
        }
        let rest = text.strip_prefix("sweep end antenna_rad=")?.trim();
        if rest.is_empty() {
            return Some(SweepMark::End {
                antenna_rad: Vec::new(),
            });
        }
        let angles: Result<Vec<f64>, _> = rest.split(',').map(str::parse::<f64>).collect();
        angles
            .ok()
            .map(|antenna_rad| SweepMark::End { antenna_rad })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweep_marks_round_trip() {
        let start = sweep_start_mark(1.25);
        let end = sweep_end_mark(&[0.0, 0.15708, -3.0]);
        assert_eq!(
            SweepMark::parse(start.strip_prefix("mark ").unwrap()),
            Some(SweepMark::Start { heading_rad: 1.25 })
        );
        assert_eq!(
            SweepMark::parse(end.strip_prefix("mark ").unwrap()),
            Some(SweepMark::End {
                antenna_rad: vec![0.0, 0.15708, -3.0]
            })
        );
        assert_eq!(
            SweepMark::parse("sweep end antenna_rad="),
            Some(SweepMark::End {
                antenna_rad: Vec::new()
            })
        );
        assert_eq!(SweepMark::parse("sweep end antenna_rad=1,x"), None);
        assert_eq!(SweepMark::parse("side 0"), None);
    }

    #[test]
    fn stepper_lines_by_name_or_offset() {
        let s = StepperSettings {
            chip: "/dev/gpiochip1".into(),
            step_line: "P8_11".into(),
            dir_line: "17".into(),
            enable_line: None,
            steps_per_rev: 200,
            microsteps: 4,
            gear_ratio: 2.0,
            invert_direction: true,
        };
        let (gpio, motion) = stepper_config(&s);
        assert_eq!(gpio.step, LineRef::Name("P8_11".into()));
        assert_eq!(gpio.dir, LineRef::Offset(17));
        assert_eq!(gpio.enable, None);
        assert_eq!(motion.full_steps_per_rev, 200);
        assert_eq!(motion.microsteps, 4);
        assert!((motion.gear_ratio - 2.0).abs() < 1e-12 && motion.invert_direction);
    }

    #[test]
    fn a_missing_gpio_chip_gives_the_settings_back() {
        let s = StepperSettings {
            chip: "/nonexistent/gpiochip9".into(),
            step_line: "1".into(),
            dir_line: "2".into(),
            enable_line: None,
            steps_per_rev: 200,
            microsteps: 1,
            gear_ratio: 1.0,
            invert_direction: false,
        };
        let mut source = Some(AntennaSource::Gpio(s));
        match open_antenna(&mut source) {
            Err(StepperError::Gpio(msg)) => assert!(msg.contains("gpiochip9"), "{msg}"),
            Err(e) => panic!("unexpected error {e}"),
            Ok(_) => panic!("opened a chip that does not exist"),
        }
        assert!(
            matches!(&source, Some(AntennaSource::Gpio(back)) if back.chip == "/nonexistent/gpiochip9"),
            "settings kept for the next attempt"
        );
    }
}
