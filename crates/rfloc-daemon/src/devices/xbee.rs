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

use std::collections::VecDeque;
use std::time::Duration;

use rfloc_bearing::{RssiProbe as SweepProbe, ScanConfig, ScanError, ScanRunner};
use rfloc_stepper::gpio::{open_gpio_stepper, GpioStepperConfig, LineRef};
use rfloc_stepper::{AntennaRotator, SimulatedStepper, StepperConfig, StepperError, StepperHandle};
use rfloc_transport::replay::ReplayMode;
use rfloc_xbee::{ClientConfig, NdLayoutHint, XBeeClient, XBeeError};
use serde::Deserialize;
use tokio::io::{AsyncRead, AsyncWrite};

use crate::config::Checks;
use crate::devices::stepper::StepperSettings;
use crate::devices::{retry_later, CheckEnv, DeviceContext, Driver};
use crate::events::{AntennaSide, DeviceEvent, DeviceState, SweptBeacon};
use crate::pipeline::Request;
use crate::simulation::BoxFuture;

/// `kind = "xbee"`: an XBee radio in API mode, either in the turning reflector (`role =
/// "sweep"`, seed 003) or behind one of four fixed reflectors (`role = "emitter_receiver"`,
/// seed 001).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct XbeeSettings {
    /// 1 (unescaped) or 2 (escaped).
    #[serde(default = "default_api_mode")]
    pub api_mode: u8,
    /// Node discovery timeout in seconds (`NT`).
    #[serde(default = "default_nt")]
    pub discovery_timeout_s: f64,
    /// What the radio is for: `sweep` (in the turning reflector, `ND` rounds per stop; seed
    /// 003) or `emitter_receiver` (one of four fixed reflectors, polling the emitter's RSSI;
    /// seed 001).
    #[serde(default)]
    pub role: XbeeRole,
    /// `emitter_receiver`: which reflector the radio sits behind.
    pub antenna: Option<AntennaSide>,
    /// `emitter_receiver`: the emitter radio's 64-bit address (16 hex digits).
    pub emitter: Option<String>,
    /// `emitter_receiver`: seconds between RSSI polls.
    #[serde(default = "default_poll_period")]
    pub poll_period_s: f64,
}

fn default_poll_period() -> f64 {
    0.2
}

fn default_api_mode() -> u8 {
    2
}

fn default_nt() -> f64 {
    2.0
}

/// What an XBee radio of the robot does.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum XbeeRole {
    /// Antenna sweeps on the pipeline's request.
    #[default]
    Sweep,
    /// RSSI of the emitter's replies, polled (remote `DB` to the emitter, then local `DB`).
    EmitterReceiver,
}

impl XbeeSettings {
    /// The radio's API mode (`api_mode` 1: unescaped, else escaped).
    #[must_use]
    pub fn mode(&self) -> rfloc_xbee::ApiMode {
        if self.api_mode == 1 {
            rfloc_xbee::ApiMode::Unescaped
        } else {
            rfloc_xbee::ApiMode::Escaped
        }
    }

    /// The emitter's address of an `emitter_receiver`, parsed.
    #[must_use]
    pub fn emitter_address(&self) -> Option<u64> {
        self.emitter
            .as_deref()
            .and_then(|a| u64::from_str_radix(a.trim_start_matches("0x"), 16).ok())
    }

    fn for_mode(api_mode: u8) -> Self {
        Self {
            api_mode,
            discovery_timeout_s: default_nt(),
            role: XbeeRole::Sweep,
            antenna: None,
            emitter: None,
            poll_period_s: default_poll_period(),
        }
    }
}

/// The XBee radio driver.
pub struct Xbee;

impl Driver for Xbee {
    const KIND: &'static str = "xbee";
    const CAPTURES: &'static [&'static str] = &["xbee-api2", "xbee-api1"];
    type Settings = XbeeSettings;

    fn check(x: &XbeeSettings, c: &mut Checks<'_, '_>, _env: &CheckEnv<'_>) {
        if !matches!(x.api_mode, 1 | 2) {
            c.error("api_mode", "must be 1 or 2");
        }
        c.range(
            "discovery_timeout_s",
            x.discovery_timeout_s,
            0.1,
            25.5,
            " s (NT)",
        );
        if x.role == XbeeRole::EmitterReceiver {
            if x.antenna.is_none() {
                c.error(
                    "role",
                    "an emitter_receiver needs antenna = front, left, back or right",
                );
            }
            if x.emitter_address().is_none() {
                c.error(
                    "emitter",
                    format!(
                        "an emitter_receiver needs the emitter's 64-bit address in hex, not {:?}",
                        x.emitter
                    ),
                );
            }
            c.range("poll_period_s", x.poll_period_s, 0.01, 60.0, " s");
        }
    }

    fn capture_name(x: &XbeeSettings) -> &'static str {
        if x.api_mode == 1 {
            "xbee-api1"
        } else {
            "xbee-api2"
        }
    }

    fn stale_after_s(x: &XbeeSettings) -> f64 {
        // A sweeping radio speaks only when the pipeline asks for a sweep.
        match x.role {
            XbeeRole::Sweep => 60.0,
            XbeeRole::EmitterReceiver => 3.0,
        }
    }

    fn replay_mode(_x: &XbeeSettings) -> ReplayMode {
        ReplayMode::RequestResponse
    }

    fn for_capture(capture: &str) -> Option<XbeeSettings> {
        match capture {
            "xbee-api1" => Some(XbeeSettings::for_mode(1)),
            "xbee-api2" => Some(XbeeSettings::for_mode(2)),
            _ => None,
        }
    }

    fn handles(x: &XbeeSettings, request: &Request) -> bool {
        x.role == XbeeRole::Sweep && matches!(request, Request::Sweep { .. })
    }

    fn run(settings: XbeeSettings, ctx: DeviceContext) -> BoxFuture<'static, ()> {
        match settings.role {
            XbeeRole::Sweep => Box::pin(run(ctx, settings)),
            XbeeRole::EmitterReceiver => Box::pin(super::xbee_receiver::run(ctx, settings)),
        }
    }
}

/// Where the antenna rotator comes from.
#[derive(Debug)]
pub enum AntennaSource {
    /// The robot's stepper on Linux GPIO, opened by the task.
    Gpio(StepperSettings),
    /// A pin-less rotator (simulation: the emulated radio reads its angle).
    Simulated(SimulatedStepper),
    /// The angles a recording reached, stop after stop (replay).
    Recorded(VecDeque<f64>),
}

/// The antenna rotator in use.
pub enum Antenna {
    Gpio(StepperHandle),
    Simulated(SimulatedStepper),
    Recorded { angles: VecDeque<f64>, at: f64 },
}

impl AntennaRotator for Antenna {
    type Error = StepperError;

    async fn move_to(&mut self, angle_rad: f64) -> Result<f64, StepperError> {
        match self {
            Antenna::Gpio(h) => h.move_to(angle_rad).await,
            Antenna::Simulated(s) => s.move_to(angle_rad).await,
            Antenna::Recorded { angles, at } => {
                // Past the recording, the antenna would be where it was asked to go.
                *at = angles.pop_front().unwrap_or(angle_rad);
                Ok(*at)
            }
        }
    }

    fn angle(&self) -> f64 {
        match self {
            Antenna::Gpio(h) => h.angle(),
            Antenna::Simulated(s) => s.angle(),
            Antenna::Recorded { at, .. } => *at,
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
        Some(AntennaSource::Recorded(angles)) => Ok(Some(Antenna::Recorded { angles, at: 0.0 })),
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

/// The sweep settings the task uses: the robot file's estimator gives them when the pipeline
/// has them (step, path-loss model, antenna pattern).
fn scan_config(ctx: &DeviceContext) -> ScanConfig {
    ctx.resources
        .scan
        .lock()
        .ok()
        .and_then(|s| *s)
        .unwrap_or_default()
}

async fn run(ctx: DeviceContext, settings: XbeeSettings) {
    let Some(antenna) = ctx.resources.take_antenna() else {
        ctx.status(
            DeviceState::Closed,
            "no antenna rotator (stepper device) for the sweep",
        )
        .await;
        return;
    };
    let mut requests = ctx.commands().await;
    let scan = scan_config(&ctx);
    let nt = crate::time::seconds(settings.discovery_timeout_s);
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
        let io = match ctx.open_link().await {
            Ok(io) => io,
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
        let link_lost = serve_sweeps(&ctx, &mut runner, &mut requests).await;
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
    requests: &mut crate::devices::CommandQueue,
) -> bool {
    loop {
        let request = tokio::select! {
            () = ctx.stop.cancelled() => return false,
            r = requests.recv() => match r {
                Some(r) => r,
                None => return false,
            },
        };
        let Request::Sweep {
            heading_rad: heading,
        } = request
        else {
            continue;
        };
        ctx.mark(&sweep_start_mark(heading));
        let scanned = tokio::select! {
            () = ctx.stop.cancelled() => return false,
            r = runner.scan(move || heading) => r,
        };
        let angles: Vec<f64> = match &scanned {
            Ok(r) => r.sweep.samples.iter().map(|s| s.antenna_rad).collect(),
            Err(_) => Vec::new(),
        };
        ctx.mark(&sweep_end_mark(&angles));
        // The sweep's time: its last bytes read from the radio.
        let t = ctx.clock.now();
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
        if !ctx.send(event).await {
            return false;
        }
        if lost {
            return true;
        }
    }
}

/// `sweep start heading_rad=…` (a capture's `mark` text). Angles are printed in the shortest form
/// that reads back to the same `f64`, so a replay computes with exactly the live values.
fn sweep_start_mark(heading_rad: f64) -> String {
    format!("sweep start heading_rad={heading_rad}")
}

/// `sweep end antenna_rad=a0,a1,…`; no angles for an abandoned sweep.
fn sweep_end_mark(angles: &[f64]) -> String {
    let list: Vec<String> = angles.iter().map(|a| format!("{a}")).collect();
    format!("sweep end antenna_rad={}", list.join(","))
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
            SweepMark::parse(&start),
            Some(SweepMark::Start { heading_rad: 1.25 })
        );
        assert_eq!(
            SweepMark::parse(&end),
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
