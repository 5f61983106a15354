//! One task per device: open the link, run the driver, forward events, reconnect with back-off.

use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::config::{DriverConfig, XbeeRole};
use crate::daemon::DeviceContext;
use crate::message::DeviceState;

mod alien;
mod aria;
mod kts;
mod urg;
mod xbee;
mod xbee_receiver;

pub use alien::{average_reads, parse_snapshot_mark, snapshot_mark};
pub(crate) use aria::sonar_beams;
pub(crate) use urg::scan_beams as urg_scan_beams;
pub use xbee::{swept_beacons, AntennaSource, NdRssiProbe, SweepMark, SweepRequest, SweepSetup};

/// A velocity command for the base: (m/s, rad/s).
pub type MotionSender = mpsc::Sender<(f64, f64)>;

/// A running device task and the channels other parts of the daemon use to command it.
pub struct SpawnedDevice {
    pub task: JoinHandle<()>,
    /// For a mobile base.
    pub motion: Option<MotionSender>,
    /// For a radio that sweeps a turning antenna.
    pub sweeps: Option<mpsc::Sender<SweepRequest>>,
}

/// Spawns the task of one device. An XBee radio takes `sweep` (its antenna rotator and scan
/// settings); a stepper has no task of its own (the radio's task drives it).
pub fn spawn(ctx: DeviceContext, span: tracing::Span, sweep: Option<SweepSetup>) -> SpawnedDevice {
    let plain = |task| SpawnedDevice {
        task,
        motion: None,
        sweeps: None,
    };
    match ctx.device.driver.clone() {
        DriverConfig::Aria(s) => {
            let (tx, rx) = mpsc::channel(16);
            SpawnedDevice {
                task: tokio::spawn(aria::run(ctx, s, rx).instrument(span)),
                motion: Some(tx),
                sweeps: None,
            }
        }
        DriverConfig::Kts(s) => plain(tokio::spawn(kts::run(ctx, s).instrument(span))),
        DriverConfig::Alien(s) => plain(tokio::spawn(alien::run(ctx, s).instrument(span))),
        DriverConfig::Urg(s) => plain(tokio::spawn(urg::run(ctx, s).instrument(span))),
        DriverConfig::Xbee(s) if s.role == XbeeRole::EmitterReceiver => {
            plain(tokio::spawn(xbee_receiver::run(ctx, s).instrument(span)))
        }
        DriverConfig::Xbee(s) => {
            let (tx, rx) = mpsc::channel(1);
            SpawnedDevice {
                task: tokio::spawn(xbee::run(ctx, s, sweep, rx).instrument(span)),
                motion: None,
                sweeps: Some(tx),
            }
        }
        DriverConfig::Stepper(_) => plain(tokio::spawn(
            async move {
                ctx.status(DeviceState::Connected, "driven by the XBee sweep task")
                    .await;
            }
            .instrument(span),
        )),
    }
}

/// Pioneer client settings for a base running `time_scale` times faster than wall time. Periods
/// and timeouts are scaled; the link-loss and handshake timeouts keep their wall-time floors
/// (`rfloc_aria::ClientConfig::scaled`).
#[must_use]
pub fn scaled_base_config(
    clock: rfloc_transport::SharedClock,
    pulse_period_s: f64,
    time_scale: f64,
) -> rfloc_aria::ClientConfig {
    rfloc_aria::ClientConfig {
        pulse_period: Duration::from_secs_f64(pulse_period_s.max(0.05)),
        clock: Some(clock),
        ..rfloc_aria::ClientConfig::default()
    }
    .scaled(time_scale)
}

/// After a failed connection step: reports `Reconnecting` with `detail` (and logs it), waits the
/// back-off of `attempt` and counts the attempt. False when the daemon stops meanwhile.
pub(crate) async fn retry_later(
    ctx: &DeviceContext,
    attempt: &mut u32,
    detail: impl Into<String>,
) -> bool {
    let detail = detail.into();
    tracing::warn!(attempt = *attempt, detail = %detail, "device not ready; retrying after back-off");
    ctx.status(DeviceState::Reconnecting, detail).await;
    let go_on = pause(ctx, crate::daemon::backoff(*attempt)).await;
    *attempt += 1;
    go_on
}

/// Waits `d` or until the daemon stops; false when stopping.
pub(crate) async fn pause(ctx: &DeviceContext, d: Duration) -> bool {
    tokio::select! {
        () = ctx.stop.cancelled() => false,
        () = tokio::time::sleep(d) => true,
    }
}
