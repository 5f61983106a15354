//! One task per device: open the link, run the driver, forward events, reconnect with back-off.

use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::config::DriverConfig;
use crate::daemon::DeviceContext;
use crate::message::DeviceState;

mod alien;
mod aria;
mod kts;

/// A velocity command for the base: (m/s, rad/s).
pub type MotionSender = mpsc::Sender<(f64, f64)>;

/// Spawns the task of one device. Returns the task and, for a mobile base, a motion sender.
pub fn spawn(ctx: DeviceContext, span: tracing::Span) -> (JoinHandle<()>, Option<MotionSender>) {
    match ctx.device.driver.clone() {
        DriverConfig::Aria(s) => {
            let (tx, rx) = mpsc::channel(16);
            (
                tokio::spawn(aria::run(ctx, s, rx).instrument(span)),
                Some(tx),
            )
        }
        DriverConfig::Kts(s) => (tokio::spawn(kts::run(ctx, s).instrument(span)), None),
        DriverConfig::Alien(s) => (tokio::spawn(alien::run(ctx, s).instrument(span)), None),
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

/// Pioneer client settings for a base running `time_scale` times faster than wall time. Periods
/// and timeouts are scaled, but the link-loss and handshake timeouts keep a floor in wall time
/// (1 s and 0.5 s): a scaled 100 ms would declare the link lost whenever the machine is busy.
#[must_use]
pub fn scaled_base_config(
    clock: rfloc_transport::SharedClock,
    pulse_period_s: f64,
    time_scale: f64,
) -> rfloc_aria::ClientConfig {
    let mut config = rfloc_aria::ClientConfig {
        pulse_period: Duration::from_secs_f64(pulse_period_s.max(0.05)),
        clock: Some(clock),
        ..rfloc_aria::ClientConfig::default()
    }
    .scaled(time_scale);
    config.link_timeout = config.link_timeout.max(Duration::from_secs(1));
    config.sync_timeout = config.sync_timeout.max(Duration::from_millis(500));
    config
}

/// Waits `d` or until the daemon stops; false when stopping.
pub(crate) async fn pause(ctx: &DeviceContext, d: Duration) -> bool {
    tokio::select! {
        () = ctx.stop.cancelled() => false,
        () = tokio::time::sleep(d) => true,
    }
}
