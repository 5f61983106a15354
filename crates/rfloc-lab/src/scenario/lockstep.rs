//! The emulated Pioneer in lock-step: simulated time moves only when the trial asks for a tick,
//! and every tick is taken only after the emulator has handled every command the driver wrote.
//!
//! Why this is race-free over a real pty, where the kernel delivers bytes whenever it likes:
//! - the barrier of a tick is the number of bytes the driver's `Recorder` has seen accepted by
//!   the pty (the capture sink's `tx_bytes`), read after the trial's last command returned;
//!   the emulator ticks only once it has read and handled at least that many bytes;
//! - the driver writes only what the trial asks for: its wall-time keep-alive (PULSE) is off
//!   and the link timeout is far beyond any step, so no byte lands at a time chosen by the
//!   scheduler (the robot's 2 s watchdog is simulated time and the trial feeds it);
//! - after a tick the trial waits until the driver has decoded that tick's SIP and has read
//!   every byte the emulator wrote ([`read_all`]) before it does anything else; the
//!   emulator publishes its new time before it writes the SIP, so every record of a capture
//!   carries the simulated time at which its bytes were sent.
//!
//! The captures use the sink's coalescing: reads (writes) at one simulated time are one record,
//! whatever chunks the pty delivered them in.
//!
//! Used by the seed 001 (emitter), seed 002 (hf-init) and seed 003 (ekf-slam) trials.

use std::time::Duration;

use anyhow::Context;
use rfloc_aria::{AriaClient, ClientConfig, EmulatorHandle, EmulatorState, Odometry, StepControl};
use rfloc_transport::{CaptureSink, SharedClock};

/// How long one lock-step exchange (a tick: barrier, simulation, SIP decoded; an emulated
/// reader's scan or reply) may take in wall time before the trial gives up.
pub(crate) const STEP_TIMEOUT: Duration = Duration::from_secs(10);

/// Waits until the driver recorded in `sink` has read `target` bytes (everything its emulator
/// wrote). A driver may act on a message before its last byte is read (a line is complete at
/// `\r`, its `\n` comes later); the clock must not move before that byte is read, or the
/// capture would stamp it with a later time in some runs.
///
/// # Errors
/// The bytes do not come within [`STEP_TIMEOUT`], or more came than were written.
pub async fn read_all(sink: &CaptureSink, target: u64) -> anyhow::Result<()> {
    tokio::time::timeout(STEP_TIMEOUT, async {
        while sink.rx_bytes() < target {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    })
    .await
    .context("the driver did not read everything its emulator wrote")?;
    anyhow::ensure!(
        sink.rx_bytes() == target,
        "link not in step: {} bytes read, {target} written",
        sink.rx_bytes()
    );
    Ok(())
}

/// The Pioneer driver's settings for a lock-step emulator: no keep-alive on wall time (the
/// trial commands the robot often enough for its watchdog, which runs on simulated time), a
/// link timeout no step comes near (the trial has its own), timestamps on `clock`.
#[must_use]
pub fn driver_config(clock: SharedClock) -> ClientConfig {
    ClientConfig {
        pulse_period: Duration::from_secs(24 * 3600),
        link_timeout: Duration::from_secs(24 * 3600),
        sync_timeout: Duration::from_secs(5),
        close_linger: Duration::from_millis(100),
        clock: Some(clock),
        ..ClientConfig::default()
    }
}

/// The Pioneer driver and the lock-step emulator behind it.
pub struct LockstepBase {
    client: AriaClient,
    control: StepControl,
    sink: CaptureSink,
    robot: EmulatorHandle,
}

impl LockstepBase {
    /// Wraps a connected driver, the emulator's step control and handle, and the capture sink
    /// the driver's link is recorded into (its byte counts are the barrier).
    #[must_use]
    pub fn new(
        client: AriaClient,
        control: StepControl,
        robot: EmulatorHandle,
        sink: CaptureSink,
    ) -> Self {
        Self {
            client,
            control,
            sink,
            robot,
        }
    }

    /// The driver.
    #[must_use]
    pub fn client(&self) -> &AriaClient {
        &self.client
    }

    /// The emulator's current state (simulated time, ground truth).
    #[must_use]
    pub fn state(&self) -> EmulatorState {
        self.robot.state()
    }

    /// VEL and RVEL through the driver; returns once both are written.
    ///
    /// # Errors
    /// The driver's error.
    pub async fn set_velocity(&self, v: f64, w: f64) -> anyhow::Result<()> {
        self.client
            .set_velocity(v, w)
            .await
            .context("commanding the base")
    }

    /// One SIP period: the emulator handles everything written so far, simulates 100 ms and
    /// sends its SIP; returns the driver's odometry from that SIP and the emulator's state.
    ///
    /// # Errors
    /// A step or SIP that does not come within [`STEP_TIMEOUT`], a stopped emulator or
    /// driver, or bytes on the link the driver did not read.
    pub async fn tick(&self) -> anyhow::Result<(Odometry, EmulatorState)> {
        let barrier = self.sink.tx_bytes();
        let state = tokio::time::timeout(STEP_TIMEOUT, self.control.advance(1, barrier))
            .await
            .context("the emulated Pioneer did not take its step")??;
        let mut odometry = self.client.odometry();
        let o = *tokio::time::timeout(
            STEP_TIMEOUT,
            odometry.wait_for(|o| o.seq >= state.sips_sent),
        )
        .await
        .context("no SIP from the emulated Pioneer")?
        .context("the Pioneer driver stopped")?;
        read_all(&self.sink, state.tx_bytes).await?;
        anyhow::ensure!(
            o.seq == state.sips_sent,
            "Pioneer link not in step: SIP {} of {}",
            o.seq,
            state.sips_sent
        );
        Ok((o, state))
    }

    /// Stops the robot and closes the driver (STOP, CLOSE).
    pub async fn shutdown(self) {
        if let Err(e) = self.client.shutdown().await {
            tracing::warn!(error = %e, "Pioneer client shutdown");
        }
    }
}
