//! The daemon's XBee sweep probe ([`rfloc_daemon::devices::NdRssiProbe`]: one `ND` round per antenna
//! stop, each beacon's RSSI from the RSSI byte of its `ND` record, id = 64-bit address) with the
//! lock-step trial's clock.
//!
//! Simulated time passes during a sweep: the probe spreads the sweep's ticks of the lock-step
//! Pioneer evenly over its rounds (40 stops and 20 ticks: one tick after every second round),
//! feeding the robot's watchdog with a stop command before each, so the capture shows the
//! rounds at the times they would take and the robot's SIPs in between.

use std::sync::Arc;

use rfloc_bearing::RssiProbe;
use rfloc_xbee::XBeeError;

use super::rig::{XBeeLink, XBeeLinkIo};
use crate::scenario::lockstep::LockstepBase;

/// [`RssiProbe`] over `ND` rounds of an [`XBeeLink`] that ticks the lock-step base.
pub struct NdRssiProbe {
    rounds_probe: rfloc_daemon::devices::NdRssiProbe<XBeeLinkIo>,
    base: Arc<LockstepBase>,
    /// Rounds per sweep and ticks per sweep.
    rounds_per_sweep: u64,
    ticks_per_sweep: u64,
    /// Rounds and ticks of the current sweep so far.
    rounds: u64,
    ticks: u64,
}

impl NdRssiProbe {
    /// Wraps a connected XBee driver; a sweep of `rounds_per_sweep` rounds takes
    /// `ticks_per_sweep` ticks of `base`.
    #[must_use]
    pub fn new(
        link: XBeeLink,
        base: Arc<LockstepBase>,
        rounds_per_sweep: u64,
        ticks_per_sweep: u64,
    ) -> Self {
        Self {
            rounds_probe: rfloc_daemon::devices::NdRssiProbe::new(link),
            base,
            rounds_per_sweep: rounds_per_sweep.max(1),
            ticks_per_sweep,
            rounds: 0,
            ticks: 0,
        }
    }

    /// Bytes the XBee codec dropped while resynchronising.
    #[must_use]
    pub fn dropped_bytes(&self) -> u64 {
        self.rounds_probe.dropped_bytes()
    }

    /// `ND` records that could not be parsed, summed over rounds.
    #[must_use]
    pub fn rejected_records(&self) -> u64 {
        self.rounds_probe.rejected_records
    }

    /// Starts counting a new sweep.
    pub fn begin_sweep(&mut self) {
        self.rounds = 0;
        self.ticks = 0;
    }

    /// Takes the ticks of the current sweep that are still due (all of them at the end).
    ///
    /// # Errors
    /// As [`LockstepBase::tick`].
    pub async fn finish_sweep(&mut self) -> anyhow::Result<()> {
        self.catch_up(self.ticks_per_sweep).await
    }

    async fn catch_up(&mut self, due: u64) -> anyhow::Result<()> {
        while self.ticks < due {
            self.base.set_velocity(0.0, 0.0).await?;
            self.base.tick().await?;
            self.ticks += 1;
        }
        Ok(())
    }
}

impl RssiProbe for NdRssiProbe {
    type Error = XBeeError;

    async fn rssi_all(&mut self) -> Result<Vec<(u64, f64)>, XBeeError> {
        let round = self.rounds_probe.rssi_all().await;
        self.rounds += 1;
        let due =
            (self.rounds * self.ticks_per_sweep / self.rounds_per_sweep).min(self.ticks_per_sweep);
        self.catch_up(due)
            .await
            .map_err(|e| XBeeError::Io(std::io::Error::other(format!("{e:#}"))))?;
        round
    }
}
